"""Running a course program in the browser: one thread, its frames delivered while it waits.

In the browser (Pyodide in a Web Worker) a program has one thread, and while it runs the
worker's own event loop does not: a program in the course's style (callbacks, then a loop that
publishes and calls ``time.sleep``, or a ``threading.Event`` wait) would never see a message.
So the waiting itself delivers them: the page's thread owns the WebSockets and writes every
frame that arrives into a shared ring (``js/code-ring.js``); ``time.sleep``, the waits of
``threading`` (``Event.wait``, ``Condition.wait``, hence ``queue.Queue.get``) and roslibpy's
own blocking calls (``Ros.run``, ``run_forever``, a blocking ``Service.call``) take the
frames out of the ring as they come and run the callbacks, until their time is up. On CPython
under roslibpy the callbacks run on the reactor's thread while the program sleeps; here they
run inside its sleep, in the order the frames came.

A callback that itself sleeps or waits blocks, without running other callbacks (as roslibpy's
reactor thread would be blocked): frames wait in the ring meanwhile. A program that never
waits (``while True: pass``) receives nothing, and the page's Stop ends it.

``install(transport)`` makes this thread's blocking calls deliver ``transport``'s frames; the
browser's transport is the worker's (``js/code-python-worker.js``), a test's may be a real
WebSocket client, so the same program runs under this module on CPython too.
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import threading
import time
import traceback
from collections.abc import Callable
from typing import Any, Protocol

MAX_WAIT_S = 0.5
"""The longest a wait blocks in the transport at once: then the loop looks at its timers and
its deadline again (a program's own check of the time stays as precise as its sleeps)."""

MAX_STATUS_NOTES = 20
"""Distinct rosbridge status messages printed per run (a refusal repeated at 10 Hz is
printed once)."""


class Transport(Protocol):
    """The WebSockets a program's connections use, owned by someone who keeps reading them.

    Frames come back from ``wait`` as ``(socket, kind, data)``: ``kind`` is ``open``,
    ``message`` (``data`` the frame's text), ``close`` or ``error`` (``data`` why).
    """

    def open(self, url: str) -> int:
        """Start opening a WebSocket to ``url``; its number (its ``open`` comes later)."""

    def send(self, socket: int, text: str) -> None:
        """Send a text frame on an open socket (dropped if it is not open)."""

    def close(self, socket: int) -> None:
        """Close a socket (its ``close`` frame may still come)."""

    def wait(self, timeout_s: float) -> list[tuple[int, str, str]]:
        """The frames that arrived, waiting up to ``timeout_s`` for the first (0: none)."""

    def pause(self, timeout_s: float) -> None:
        """Block ``timeout_s`` without taking frames (a callback sleeping)."""


class Handler(Protocol):
    """What a socket's owner is told of it."""

    def on_open(self) -> None:
        """The socket opened."""

    def on_message(self, text: str) -> None:
        """A text frame arrived."""

    def on_close(self, reason: str) -> None:
        """The socket closed (or could not open)."""


class Loop:
    """The program's event loop, run whenever the program waits.

    Args:
        transport: the program's sockets.
        clock: monotonic seconds (``time.monotonic``).
        report: told of an exception a callback raised (the run goes on, as under
            roslibpy, where the reactor logs it); default: the traceback on stderr.
    """

    def __init__(self, transport: Transport, clock: Callable[[], float] = time.monotonic,
                 report: Callable[[BaseException], None] | None = None) -> None:
        self.transport = transport
        self.clock = clock
        self.report = report or (lambda error: traceback.print_exception(error))
        self.thread = threading.get_ident()
        self._handlers: dict[int, Handler] = {}
        self._timers: list[tuple[float, int, Callable[[], Any]]] = []
        self._order = itertools.count()
        self._in_callback = 0
        self._status_notes: set[str] = set()

    def open(self, url: str, handler: Handler) -> int:
        """Open a socket to ``url`` whose frames go to ``handler``; its number."""
        socket = self.transport.open(url)
        self._handlers[socket] = handler
        return socket

    def send(self, socket: int, text: str) -> None:
        """Send a text frame."""
        self.transport.send(socket, text)

    def close(self, socket: int) -> None:
        """Close a socket; its handler hears no more."""
        self._handlers.pop(socket, None)
        self.transport.close(socket)

    def call_later(self, delay_s: float, callback: Callable[[], Any]) -> None:
        """Run ``callback`` once the program waits, ``delay_s`` from now at the earliest."""
        heapq.heappush(self._timers, (self.clock() + max(0.0, delay_s), next(self._order),
                                      callback))

    def note_status(self, text: str) -> None:
        """Print a rosbridge status message once (a refusal says why a command did nothing)."""
        if text in self._status_notes or len(self._status_notes) >= MAX_STATUS_NOTES:
            return
        self._status_notes.add(text)
        print(f"rosbridge: {text}", file=__import__("sys").stderr)

    def run_until(self, deadline_s: float | None = None,
                  done: Callable[[], bool] = lambda: False) -> bool:
        """Deliver frames and timers until ``done()`` or the deadline (None: no deadline).

        Returns:
            ``done()`` at the end: False when the deadline came first.
        """
        if self._in_callback:  # a callback blocks: nothing else runs meanwhile
            while not done():
                left = MAX_WAIT_S if deadline_s is None else deadline_s - self.clock()
                if left <= 0:
                    return False
                self.transport.pause(min(left, MAX_WAIT_S))
            return True
        while True:
            if done():
                return True
            now = self._run_due_timers()
            if done():
                return True
            if deadline_s is not None and now >= deadline_s:
                return False
            wait_s = MAX_WAIT_S if deadline_s is None else min(MAX_WAIT_S, deadline_s - now)
            if self._timers:
                wait_s = min(wait_s, max(0.0, self._timers[0][0] - now))
            for socket, kind, data in self.transport.wait(wait_s):
                self._deliver(socket, kind, data)

    def _run_due_timers(self) -> float:
        now = self.clock()
        while self._timers and self._timers[0][0] <= now:
            _, _, callback = heapq.heappop(self._timers)
            self._call(callback)
            now = self.clock()
        return now

    def _deliver(self, socket: int, kind: str, data: str) -> None:
        handler = self._handlers.get(socket)
        if handler is None:
            return
        if kind == "message":
            self._call(lambda: handler.on_message(data))
        elif kind == "open":
            self._call(handler.on_open)
        else:
            self._handlers.pop(socket, None)
            self._call(lambda: handler.on_close(data))

    def _call(self, callback: Callable[[], Any]) -> None:
        """Run a callback; an exception is reported and the program goes on."""
        self._in_callback += 1
        try:
            callback()
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as error:
            self.report(error)
        finally:
            self._in_callback -= 1


_installed: list[Loop] = []
_originals: dict[str, Any] = {}


def current() -> Loop:
    """The loop ``install`` made (RuntimeError before)."""
    if not _installed:
        raise RuntimeError("websim_browser.install(transport) was not called")
    return _installed[-1]


def install(transport: Transport, *, clock: Callable[[], float] = time.monotonic,
            report: Callable[[BaseException], None] | None = None) -> Loop:
    """Make the calling thread's blocking calls deliver ``transport``'s frames.

    ``time.sleep`` and ``threading.Condition.wait`` (so ``Event.wait``, ``Queue.get``,
    ``Semaphore.acquire`` with a timeout...) run the loop until their time is up; in other
    threads (a test's WebSocket reader) they stay what they were. A second call replaces
    the loop (a new run in the same interpreter).
    """
    loop = Loop(transport, clock, report)
    if not _originals:
        _patch_time(clock)
        _patch_condition(clock)
    _installed[:] = [loop]
    return loop


def uninstall() -> None:
    """Put ``time.sleep`` and ``threading.Condition.wait`` back as they were."""
    _installed.clear()
    if "sleep" in _originals:
        time.sleep = _originals.pop("sleep")
    if "wait" in _originals:
        threading.Condition.wait = _originals.pop("wait")  # type: ignore[method-assign]


def real_sleep(seconds: float) -> None:
    """Sleep without delivering anything (what ``time.sleep`` was before ``install``)."""
    _originals.get("sleep", time.sleep)(seconds)


def _patch_time(clock: Callable[[], float]) -> None:
    original = _originals["sleep"] = time.sleep

    def sleep(seconds: float) -> None:
        loop = _installed[-1] if _installed else None
        if loop is None or threading.get_ident() != loop.thread:
            original(seconds)
            return
        if seconds < 0:
            raise ValueError("sleep length must be non-negative")
        loop.run_until(clock() + float(seconds))

    time.sleep = sleep


def _patch_condition(clock: Callable[[], float]) -> None:
    original = _originals["wait"] = threading.Condition.wait

    def wait(self: Any, timeout: float | None = None) -> bool:
        loop = _installed[-1] if _installed else None
        if loop is None or threading.get_ident() != loop.thread:
            return bool(original(self, timeout))
        if not self._is_owned():
            raise RuntimeError("cannot wait on un-acquired lock")
        waiter = threading._allocate_lock()  # type: ignore[attr-defined]
        waiter.acquire()
        self._waiters.append(waiter)
        saved = self._release_save()
        notified = False
        try:
            deadline = None if timeout is None else clock() + max(0.0, float(timeout))
            notified = loop.run_until(deadline, lambda: not waiter.locked())
            return notified
        finally:
            self._acquire_restore(saved)
            if not notified:
                with contextlib.suppress(ValueError):
                    self._waiters.remove(waiter)

    threading.Condition.wait = wait  # type: ignore[method-assign]
