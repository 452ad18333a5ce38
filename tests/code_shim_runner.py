"""Run a program under the browser's roslibpy (``web-interface/python/``) on CPython.

    python tests/code_shim_runner.py PROGRAM.py [ARG...]

The page runs a student's Python in Pyodide with ``web-interface/python/roslibpy.py`` as its
``roslibpy`` and ``websim_browser`` delivering frames while the program waits. This runs the
same two modules on CPython, with a transport of real WebSockets (``websockets``' sync
client, each socket read and written by threads of its own, never the program's), so a test
can hold the browser's roslibpy to the real one on the same programs, fast, without a
browser. ``WEBSIM_SHIM_URL``, if set, is where every ``Ros`` connects whatever it names (as
the page connects every one to its robot); otherwise the URL the program names.
"""

from __future__ import annotations

import _thread
import os
import queue
import runpy
import sys
import threading
from pathlib import Path

SHIM_DIR = Path(__file__).resolve().parent.parent / "web-interface" / "python"


class WebSocketTransport:
    """websim_browser's Transport over real WebSockets (websockets' sync client)."""

    def __init__(self, redirect: str | None) -> None:
        self._redirect = redirect
        self._frames: queue.SimpleQueue[tuple[int, str, str]] = queue.SimpleQueue()
        self._outboxes: dict[int, queue.SimpleQueue[str | None]] = {}
        self._next = 0

    def open(self, url: str) -> int:
        self._next += 1
        socket = self._next
        outbox: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        self._outboxes[socket] = outbox
        # _thread, not threading: Thread.start() waits on a Condition, which on the
        # program's thread runs the loop (websim_browser), which would take this socket's
        # first frames before its handler is known
        _thread.start_new_thread(self._run, (socket, self._redirect or url, outbox))
        return socket

    def _run(self, socket: int, url: str, outbox: queue.SimpleQueue[str | None]) -> None:
        from websockets.sync.client import connect
        try:
            connection = connect(url, max_size=None)
        except Exception as error:
            self._frames.put((socket, "close", f"cannot connect: {error}"))
            return
        with connection:
            self._frames.put((socket, "open", ""))

            def write() -> None:
                while (text := outbox.get()) is not None:
                    try:
                        connection.send(text)
                    except Exception:
                        return
                connection.close()

            threading.Thread(target=write, daemon=True).start()
            reason = "closed"
            try:
                for frame in connection:
                    self._frames.put((socket, "message", frame if isinstance(frame, str)
                                      else frame.decode()))
            except Exception as error:
                reason = str(error)
            outbox.put(None)
        self._frames.put((socket, "close", reason))

    def send(self, socket: int, text: str) -> None:
        outbox = self._outboxes.get(socket)
        if outbox is not None:
            outbox.put(text)

    def close(self, socket: int) -> None:
        outbox = self._outboxes.pop(socket, None)
        if outbox is not None:
            outbox.put(None)

    def wait(self, timeout_s: float) -> list[tuple[int, str, str]]:
        frames = []
        try:
            frames.append(self._frames.get(timeout=max(0.0, timeout_s)) if timeout_s > 0
                          else self._frames.get_nowait())
            while True:
                frames.append(self._frames.get_nowait())
        except queue.Empty:
            pass
        return frames

    def pause(self, timeout_s: float) -> None:
        import websim_browser
        websim_browser.real_sleep(timeout_s)


def main(argv: list[str]) -> int:
    """Install the shim, run the program as ``__main__``; the program's exit code."""
    sys.path.insert(0, str(SHIM_DIR))
    import websim_browser
    websim_browser.install(WebSocketTransport(os.environ.get("WEBSIM_SHIM_URL")))
    program = argv[0]
    sys.argv = list(argv)
    sys.path.insert(0, str(Path(program).resolve().parent))
    try:
        runpy.run_path(program, run_name="__main__")
    except SystemExit as end:
        code = end.code
        return code if isinstance(code, int) else (0 if code is None else 1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
