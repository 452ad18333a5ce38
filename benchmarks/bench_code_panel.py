"""The Code panel's figures: what the page downloads, and how soon a program drives the robot.

It starts ONE real ``websim serve`` and this machine's Chromium (``/usr/bin/chromium``, headless,
through Playwright), and measures:

* **download**: the bytes on the wire (gzip, as served) of the robot's page as it loads (the
  panel closed: nothing of the editor or of Python), then of opening the panel (the editor,
  CodeMirror) and of Python's runtime (Pyodide: fetched only when the panel opens);
* **to the first /cmd_vel**: until the first ``/cmd_vel`` the program publishes reaches a
  rosbridge client on the same server, for a program that connects and publishes at once, in
  Python and in JavaScript, the program already in the editor (saved by this browser) and the
  panel open (as the page left it):
    - ``cold``: from opening the page in a new browser profile (an empty HTTP cache), Run
      clicked as soon as it shows (Python: the runtime's download and WebAssembly compile
      included);
    - ``warm cache``: the same, from opening the page again in that profile (the files and
      the compiled WebAssembly in its cache);
    - ``loaded``: from the click on Run, in a page where a program already ran (Python
      loaded; JavaScript: each run a new worker).

Each is measured ``--runs`` times (default 3; a new profile each for ``cold``) and the median
printed with the range. Loopback only; it asserts nothing.

    python benchmarks/bench_code_panel.py
    python benchmarks/bench_code_panel.py --runs 5
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from websockets.sync.client import connect

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_server import running_server

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]

PROGRAMS = {
    "python": ("import os\nimport roslibpy\n\n"
               "ros = roslibpy.Ros(host=os.environ['WEBSIM_URL'])\nros.run()\n"
               "roslibpy.Topic(ros, '/cmd_vel', 'geometry_msgs/msg/Twist').publish("
               "roslibpy.Message({'linear': {'x': 0.0, 'y': 0.0, 'z': 0.0}, "
               "'angular': {'x': 0.0, 'y': 0.0, 'z': 0.0}}))\n"
               "import time\ntime.sleep(0.5)\n"),
    "javascript": ("const ROSLIB = require('roslib');\n"
                   "const ros = new ROSLIB.Ros({ url: process.env.WEBSIM_URL });\n"
                   "ros.on('connection', () => {\n"
                   "  new ROSLIB.Topic({ ros, name: '/cmd_vel', messageType: "
                   "'geometry_msgs/msg/Twist' }).publish(new ROSLIB.Message({ linear: "
                   "{ x: 0, y: 0, z: 0 }, angular: { x: 0, y: 0, z: 0 } }));\n"
                   "  setTimeout(() => ros.close(), 500);\n});\n"),
}


class CommandWatch:
    """A rosbridge client that notes when each /cmd_vel arrives (monotonic s)."""

    def __init__(self, url: str) -> None:
        self._stack = ExitStack()
        self._socket = self._stack.enter_context(connect(url, max_size=None))
        self._socket.send(json.dumps({"op": "subscribe", "topic": "/cmd_vel"}))
        self.arrivals: list[float] = []
        self._lock = threading.Lock()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        try:
            for frame in self._socket:
                if json.loads(frame).get("op") == "publish":
                    with self._lock:
                        self.arrivals.append(time.monotonic())
        except Exception:
            pass

    def first_after(self, since: float, timeout_s: float = 120.0) -> float:
        """Seconds from ``since`` to the first /cmd_vel that arrived after it."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self._lock:
                found = [t for t in self.arrivals if t >= since]
            if found:
                return found[0] - since
            time.sleep(0.005)
        raise TimeoutError("no /cmd_vel from the program")

    def close(self) -> None:
        """Close its socket."""
        self._stack.close()


@contextmanager
def chromium() -> Iterator[Any]:
    from playwright.sync_api import sync_playwright
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                             args=CHROMIUM_ARGS)
        try:
            yield browser
        finally:
            browser.close()


def open_panel(page: Any, url: str) -> None:
    """Open the page and its Code panel (a page that had it open opens it by itself)."""
    page.goto(url)
    page.wait_for_selector('#conn-status[data-status="connected"]', timeout=30000)
    page.wait_for_selector(".cm-content, #code-open:not([disabled])", timeout=60000)
    if page.is_visible("#code-open") and page.is_enabled("#code-open"):
        page.click("#code-open")
    page.wait_for_selector(".cm-content", timeout=60000)


def set_program(page: Any, language: str) -> None:
    if page.input_value("#code-language") != language:
        page.select_option("#code-language", language)
        while not page.evaluate("() => document.querySelector('#code-filename').textContent")\
                .endswith(".py" if language == "python" else ".js"):
            time.sleep(0.02)
    page.evaluate("(t) => window.websim.code.panel.editor.setText(t)", PROGRAMS[language])


def run_to_command(page: Any, watch: CommandWatch) -> float:
    """Click Run; seconds until the program's first /cmd_vel reached the bridge's client."""
    page.wait_for_selector("#code-run:not([disabled])", timeout=60000)
    started = time.monotonic()
    page.click("#code-run")
    delay = watch.first_after(started)
    page.wait_for_selector('#code-state[data-state="exited"], #code-state[data-state="crashed"]',
                           timeout=60000)
    return delay


def download_sizes(browser: Any, url: str) -> dict[str, int]:
    """Bytes on the wire: the page, then the editor, then Python's runtime."""
    context = browser.new_context()
    received: list[tuple[str, int]] = []

    def finished(request: Any) -> None:
        sizes = request.sizes()
        received.append((request.url, sizes["responseBodySize"] + sizes["responseHeadersSize"]))

    context.on("requestfinished", finished)
    page = context.new_page()
    page.goto(url)
    page.wait_for_selector('#conn-status[data-status="connected"]', timeout=30000)
    page.wait_for_load_state("networkidle")
    page_bytes = sum(size for _, size in received)
    received.clear()
    page.click("#code-open")
    page.wait_for_selector(".cm-content", timeout=60000)
    set_program(page, "python")
    page.wait_for_selector("#code-run:not([disabled])", timeout=60000)
    page.click("#code-run")  # Python's runtime loads (it began when the panel opened)
    page.wait_for_selector('#code-state[data-state="exited"]', timeout=120000)
    page.wait_for_load_state("networkidle")
    runtime = sum(size for address, size in received if "/node_modules/pyodide/" in address)
    editor = sum(size for address, size in received if "/node_modules/pyodide/" not in address)
    context.close()
    return {"page": page_bytes, "panel": editor, "python": runtime}


SAVED = """(program) => {
  localStorage.setItem('websim.codeOpen:/', '1');
  localStorage.setItem('websim.code.language:/', program.language);
  localStorage.setItem(`websim.code:/:${program.language}`,
    JSON.stringify({ text: program.text, savedAt: Date.now() }));
}"""
"""A profile whose page had its panel open and this program saved (code-card.js, code-store.js)."""


def from_opening(page: Any, url: str, watch: CommandWatch) -> float:
    """Seconds from opening the page to the program's first /cmd_vel, Run clicked when shown."""
    started = time.monotonic()
    page.goto(url)
    page.wait_for_selector(".cm-content", timeout=120000)
    page.click("#code-run")
    delay = watch.first_after(started)
    page.wait_for_selector('#code-state[data-state="exited"], #code-state[data-state="crashed"]',
                           timeout=60000)
    return delay


def measure(browser: Any, url: str, watch: CommandWatch, language: str,
            runs: int) -> dict[str, list[float]]:
    times: dict[str, list[float]] = {"cold": [], "warm cache": [], "loaded": []}
    program = {"language": language, "text": PROGRAMS[language]}
    for _ in range(runs):
        context = browser.new_context()  # a new profile: an empty HTTP cache
        context.add_init_script(f"({SAVED})({json.dumps(program)})")
        page = context.new_page()
        times["cold"].append(from_opening(page, url, watch))
        times["loaded"].append(run_to_command(page, watch))
        page.close()
        again = context.new_page()
        times["warm cache"].append(from_opening(again, url, watch))
        context.close()
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per case (default 3)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-code-") as folder, \
            running_server(Path(folder)) as server, chromium() as browser:
        url = f"http://127.0.0.1:{server.http_port}/"
        watch = CommandWatch(f"ws://127.0.0.1:{server.ws_port}/")
        try:
            sizes = download_sizes(browser, url)
            print(f"download (bytes on the wire, gzip): page {sizes['page'] / 1e6:.2f} MB; "
                  f"opening the Code panel adds the editor {sizes['panel'] / 1e6:.2f} MB and "
                  f"Python's runtime {sizes['python'] / 1e6:.2f} MB "
                  f"(page with Python: {sum(sizes.values()) / 1e6:.2f} MB)", flush=True)
            for language in ("python", "javascript"):
                times = measure(browser, url, watch, language, args.runs)
                for case, values in times.items():
                    print(f"{language:10s} to the first /cmd_vel, {case:10s}: median "
                          f"{statistics.median(values):.2f} s (range {min(values):.2f}-"
                          f"{max(values):.2f} s, {len(values)} runs)", flush=True)
        finally:
            watch.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
