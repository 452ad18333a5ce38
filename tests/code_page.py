"""The Code panel's tests' helpers: a page under its own headers, its editor, its program.

The pages run here as the server sends them: under their Content-Security-Policy and
cross-origin isolation (``bypass_csp`` off, unlike the other page tests, so the workers' own
policies are what lets Pyodide and a program run), with every request to another host than
the server's refused and noted (``OriginGuard``). So Playwright's ``wait_for_function`` (which
the policy forbids) is not used: conditions are polled from here (``wait_for``).
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from page_helpers import WEB_DIR

from server_process import wait_for

PYODIDE = WEB_DIR / "node_modules" / "pyodide" / "pyodide.asm.wasm"
CODEMIRROR = WEB_DIR / "node_modules" / "@codemirror" / "view" / "dist" / "index.js"

LOAD_TIMEOUT_S = 90.0
"""Python's first load: 6 MB from this machine and a WebAssembly compile, on a loaded host."""

ENDED = ("exited", "crashed", "stopped", "failed")


@dataclass
class OriginGuard:
    """Refuses (and notes) every request of a browser context to another host than ours."""

    allowed: set[str]
    refused: list[str] = field(default_factory=list)

    def route(self, route: Any) -> None:
        url = urlsplit(route.request.url)
        if url.scheme in ("data", "blob") or url.netloc in self.allowed:
            route.continue_()
        else:
            self.refused.append(route.request.url)
            route.abort()


@contextmanager
def code_context(browser: Any, http_url: str, ws_url: str, **options: Any) -> Iterator[Any]:
    """A browser context under the pages' own policies, limited to the server's origin.

    Yields it with ``context.guard`` (its ``OriginGuard``); checks at the end that nothing
    was refused.
    """
    allowed = {urlsplit(http_url).netloc, urlsplit(ws_url).netloc}
    context = browser.new_context(bypass_csp=False, accept_downloads=True, **options)
    guard = OriginGuard(allowed)
    context.route("**/*", guard.route)
    sockets: list[str] = []  # WebSockets pass no route: noted as the pages open them
    context.on("page", lambda page: page.on("websocket", lambda ws: sockets.append(ws.url)))
    context.guard = guard
    try:
        yield context
    finally:
        context.close()
    assert guard.refused == [], f"requests to other hosts: {guard.refused}"
    assert all(urlsplit(url).netloc in allowed for url in sockets), sockets


def open_code(page: Any, url: str) -> None:
    """Open ``url`` and its Code panel, once the editor shows."""
    page.goto(url)
    page.wait_for_selector('#conn-status[data-status="connected"]', timeout=15000)
    # a page that had its panel open opens it by itself; else the button does
    opened = wait_for(lambda: page.evaluate(
        "() => document.querySelector('.cm-content') ? 'editor' : "
        "(!document.querySelector('#code-open').disabled && 'button')"), timeout_s=30,
        what="the editor, or its button")
    if opened == "button":
        page.click("#code-open")
    page.wait_for_selector(".cm-content", timeout=30000)
    page.locator("#code-card").scroll_into_view_if_needed()


def choose(page: Any, selector: str, value: str) -> None:
    page.select_option(selector, value)


def set_language(page: Any, language: str) -> None:
    if page.input_value("#code-language") != language:
        page.select_option("#code-language", language)
        wait_for(lambda: page.evaluate(
            "() => document.querySelector('#code-filename').textContent").endswith(
            ".py" if language == "python" else ".js"), what=f"the editor in {language}")


def type_program(page: Any, text: str) -> None:
    """Replace the editor's text by keyboard: select all, delete, then the text as typed
    input (Playwright's insertText: the editor sees input events, as from an on-screen
    keyboard or a paste)."""
    # keyboard focus, not a click: a click at a point of the text can land on the line
    # numbers' gutter when the editor is scrolled sideways (a long starter line, the cursor
    # at its end: seen once in a whole-suite run, 30 s of retries on the gutter)
    page.focus(".cm-content")
    page.keyboard.press("Control+A")
    page.keyboard.press("Delete")
    page.keyboard.insert_text(text)
    wait_for(lambda: editor_text(page) == text, what="the program in the editor")


def editor_text(page: Any) -> str:
    return str(page.evaluate("() => window.websim.code.panel.editor.text()"))


def state(page: Any) -> str:
    return str(page.get_attribute("#code-state", "data-state"))


def output(page: Any) -> str:
    """The output pane's lines (its model: the pane draws them at the next frame)."""
    return str(page.evaluate("() => window.websim.code.panel.output.text()"))


def wait_state(page: Any, states: tuple[str, ...], timeout_s: float = 30.0) -> str:
    return str(wait_for(lambda: state(page) if state(page) in states else None,
                        timeout_s=timeout_s, what=f"the program to be {' or '.join(states)}"))


def wait_output(page: Any, text: str, timeout_s: float = 30.0) -> str:
    return str(wait_for(lambda: output(page) if text in output(page) else None,
                        timeout_s=timeout_s, what=f"'{text}' in the output"))


def run_program(page: Any) -> None:
    """Run, and wait until it runs (Python's first load included)."""
    page.click("#code-run")
    wait_for(lambda: state(page) not in ("idle", "loading") or None, timeout_s=LOAD_TIMEOUT_S,
             what="the program to start")


def problems(page: Any) -> list[dict[str, Any]]:
    """The problems the editor marks: [{line, severity, message}]."""
    return list(page.evaluate("() => window.websim.code.panel.editor.problems()"))


def grade_file(path: Path, assignment: str, out: Path, *command: str) -> dict[str, Any]:
    """``websim grade`` on a downloaded program, as its student would on a laptop."""
    result = subprocess.run([sys.executable, "-m", "websim.cli", "grade", assignment,
                             "--submission", str(path.parent), "--out", str(out), "--",
                             *command], capture_output=True, text=True, timeout=900,
                            check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    return dict(json.loads((out / "summary.json").read_text()))


def submitted(page: Any, timeout_s: float = 300.0) -> dict[str, Any]:
    """Click Submit; the graded submission as the page's server reports it."""
    page.click("#code-submit")
    wait_for(lambda: page.get_attribute("#code-grade", "data-state") in ("done", "failed"),
             timeout_s=timeout_s, what="the submission to be graded")
    return dict(page.evaluate("() => window.websim.code.panel.server.submission()"))
