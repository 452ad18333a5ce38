"""Debian's Chromium under Playwright for the browser tests: how it starts, and when to skip.

Playwright drives ``/usr/bin/chromium`` (never a downloaded browser); each launch gets a fresh
temporary profile. A test skips, saying which piece is missing, only when Chromium, the
``playwright`` package or the npm libraries the page loads are absent.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-quic"]


def skip_reason(libraries: Sequence[Path]) -> str | None:
    """Why a browser test cannot run here, or None when Chromium and ``libraries`` are there."""
    if not Path(CHROMIUM).exists():
        return "chromium not installed (apt-get install chromium)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright not installed (pip install -e '.[test]')"
    missing = [str(path.relative_to(ROOT)) for path in libraries if not path.exists()]
    if missing:
        return f"{', '.join(missing)} missing: run npm ci in web-interface/"
    return None


@contextmanager
def launched_chromium(extra_args: Sequence[str] = ()) -> Iterator[Any]:
    """A headless Chromium (a Playwright ``Browser``), closed afterwards."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True,
                                             args=[*CHROMIUM_ARGS, *extra_args])
        try:
            yield browser
        finally:
            browser.close()
