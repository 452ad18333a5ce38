"""Which files of the web folder are published: one allow-list for the page server and the wheel.

No dependency beyond the standard library: ``setup.py`` reads this file at build time (the
wheel carries exactly the files the page server publishes), and ``websim.http_server``
serves by it.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterator
from fnmatch import fnmatch
from pathlib import Path

TOP_LEVEL_FILES = ("*.html", "favicon.svg", "config.json")
"""Files published from the top of the web folder: the pages (also a page copied there, as
``examples/roslibjs_page.html`` says; the Docker image copies ``*.html`` too), the icon and
the site's settings. ``robot.json`` is not a file here: it is answered live."""

PUBLISHED_TREES = ("css", "js", "node_modules/roslib/build", "node_modules/nipplejs/dist",
                   "node_modules/uplot/dist")
"""Folders published with everything below them: the pages' own styles and modules, and the
built files of the libraries the pages load (``index.html``, ``admin.html``, ``js/vendor.js``),
not the libraries' sources or package files."""

CONTENT_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".json": "application/json",
    ".map": "application/json",
    ".svg": "image/svg+xml",
    ".png": "image/png",
    ".ico": "image/x-icon",
    ".woff2": "font/woff2",
}
"""The only file types published, with their MIME types (not the system's mime.types, which
differ between machines: module scripts must be a JavaScript type or the browser refuses)."""

SEGMENT = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]*")
"""One path segment of a published file: no dotfile, ``.``, ``..``, empty segment (a
directory's trailing slash), backslash, NUL or other oddity."""


def published(relative: str) -> bool:
    """Whether a path relative to the web folder is on the allow-list (by name only)."""
    segments = relative.split("/")
    if not all(SEGMENT.fullmatch(segment) for segment in segments):
        return False
    if os.path.splitext(relative)[1] not in CONTENT_TYPES:
        return False
    if len(segments) == 1:
        return any(fnmatch(relative, pattern) for pattern in TOP_LEVEL_FILES)
    return any(relative.startswith(tree + "/") for tree in PUBLISHED_TREES)


def published_files(web_dir: Path) -> Iterator[str]:
    """Every published file of ``web_dir``: relative, ``/``-separated, sorted.

    Symlinks and names off the allow-list are skipped.
    """
    found = []
    for path in web_dir.rglob("*"):
        if path.is_file() and not path.is_symlink():
            relative = path.relative_to(web_dir).as_posix()
            if published(relative):
                found.append(relative)
    yield from sorted(found)
