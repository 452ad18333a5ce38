"""One run of a program in the browser's worker: its environment, its end, its errors' lines.

``js/code-python-worker.js`` calls ``run_program`` for each Run, in the same interpreter: the
program runs as ``__main__`` in a namespace of its own, with ``os.environ`` holding what
``websim grade`` would give it (``WEBSIM_URL`` and the assignment's ``WEBSIM_<NAME>``),
``sys.argv`` its file's name, and websim_browser's loop on the page's sockets. The result says
how it ended (``exited`` with its status, ``stopped`` by the page, ``crashed`` with the
traceback and the line of the program where it happened).
"""

from __future__ import annotations

import linecache
import os
import sys
import traceback
from pathlib import Path
from typing import Any

import websim_browser

ENV_PREFIX = "WEBSIM_"


class BrowserTransport:
    """websim_browser's Transport on the worker's side (``websim_transport``, a JS module)."""

    def __init__(self) -> None:
        import websim_transport  # registered by the worker: pyodide.registerJsModule
        self._js = websim_transport

    def open(self, url: str) -> int:
        """Ask the page to open a socket (to its robot)."""
        return int(self._js.open(url))

    def send(self, socket: int, text: str) -> None:
        """Have the page send a frame."""
        self._js.send(socket, text)

    def close(self, socket: int) -> None:
        """Have the page close a socket."""
        self._js.close(socket)

    def wait(self, timeout_s: float) -> list[tuple[int, str, str]]:
        """The frames the page wrote into the ring (``js/code-ring.js``)."""
        return [(int(socket), str(kind), str(data))
                for socket, kind, data in self._js.wait(timeout_s).to_py()]

    def pause(self, timeout_s: float) -> None:
        """Block without taking frames."""
        self._js.pause(timeout_s)


def program_line(error: BaseException, filename: str) -> int | None:
    """The line of ``filename`` nearest where ``error`` was raised, if it passed there."""
    line = None
    for frame in traceback.extract_tb(error.__traceback__):
        if frame.filename == filename:
            line = frame.lineno
    if line is None and isinstance(error, SyntaxError) and error.filename == filename:
        line = error.lineno
    return line


def described(error: BaseException, filename: str) -> str:
    """The traceback as Python prints it, without this runner's own frames."""
    frames = traceback.extract_tb(error.__traceback__)
    first = next((index for index, frame in enumerate(frames) if frame.filename == filename),
                 len(frames))
    lines = ["Traceback (most recent call last):\n"] if frames[first:] else []
    lines += traceback.format_list(frames[first:])
    lines += traceback.format_exception_only(type(error), error)
    return "".join(lines).rstrip("\n")


def run_program(source: str, filename: str, env: dict[str, str], argv: list[str],
                transport: websim_browser.Transport | None = None) -> dict[str, Any]:
    """Run ``source`` as ``__main__``; how it ended.

    Returns:
        ``status`` (``exited``, ``stopped``, ``crashed``), ``code`` (the exit status),
        ``text`` (the traceback of a crash) and ``line`` (the program's line of it).
    """
    path = Path(filename).name or "main.py"
    home = Path(os.environ.get("HOME", "."))
    file = home / path
    file.write_text(source, encoding="utf-8")  # tracebacks quote its lines
    linecache.checkcache()
    for name in [name for name in os.environ if name.startswith(ENV_PREFIX)]:
        del os.environ[name]
    os.environ.update(env)
    sys.argv = list(argv) or [path]
    loop = websim_browser.install(transport or BrowserTransport(),
                                  report=lambda error: _report(error, path))
    namespace: dict[str, Any] = {"__name__": "__main__", "__file__": path,
                                 "__builtins__": __builtins__}
    result: dict[str, Any] = {"status": "exited", "code": 0, "text": "", "line": None}
    try:
        code = compile(source, path, "exec")
        exec(code, namespace)
    except SystemExit as end:
        status = end.code
        if status is None or isinstance(status, int):
            result["code"] = status or 0
        else:  # sys.exit("message"): printed, status 1
            print(status, file=sys.stderr)
            result["code"] = 1
    except KeyboardInterrupt:
        result.update(status="stopped", code=130)
    except BaseException as error:  # the program's own: reported with its line
        result.update(status="crashed", code=1, text=described(error, path),
                      line=program_line(error, path))
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        for socket in list(loop._handlers):
            loop.close(socket)
        namespace.clear()
    return result


def _report(error: BaseException, filename: str) -> None:
    """A callback raised: printed (the run goes on, as under roslibpy's reactor)."""
    print(f"Exception in a callback (the program goes on):\n{described(error, filename)}",
          file=sys.stderr)
