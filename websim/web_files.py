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

PUBLISHED_TREES = ("css", "js", "python", "node_modules/roslib/build",
                   "node_modules/nipplejs/dist", "node_modules/uplot/dist")
"""Folders published with everything below them: the pages' own styles and modules, the
browser's roslibpy (``python/``: the Code panel installs it into Pyodide), and the built files of
the libraries the pages load (``index.html``, ``admin.html``, ``js/vendor.js``), not the
libraries' sources or package files."""

PYODIDE_FILES = tuple(f"node_modules/pyodide/{name}" for name in (
    "pyodide.mjs", "pyodide.asm.mjs", "pyodide.asm.wasm", "python_stdlib.zip",
    "pyodide-lock.json"))
"""Python in the browser (the Code panel, ``js/code-python-worker.js``): Pyodide's loader, its
interpreter and the standard library, fetched only when the panel opens. Not its packages (the
npm package carries none) nor its consoles and type files."""

EDITOR_FILES = tuple(f"node_modules/{name}" for name in (
    "codemirror/dist/index.js",
    "@codemirror/autocomplete/dist/index.js",
    "@codemirror/commands/dist/index.js",
    "@codemirror/lang-javascript/dist/index.js",
    "@codemirror/lang-python/dist/index.js",
    "@codemirror/language/dist/index.js",
    "@codemirror/lint/dist/index.js",
    "@codemirror/search/dist/index.js",
    "@codemirror/state/dist/index.js",
    "@codemirror/streamparser/dist/index.js",
    "@codemirror/view/dist/index.js",
    "@lezer/common/dist/index.js",
    "@lezer/highlight/dist/index.js",
    "@lezer/javascript/dist/index.js",
    "@lezer/lr/dist/index.js",
    "@lezer/python/dist/index.js",
    "@marijn/find-cluster-break/src/index.js",
    "crelt/index.js",
    "style-mod/src/style-mod.js",
    "w3c-keyname/index.js"))
"""The Code panel's editor, CodeMirror 6: each package's ES module, one file each, which the
page's import map names (``websim.import_map``, built from the packages' own package.json; a
test holds the two equal)."""

PUBLISHED_FILES = frozenset(PYODIDE_FILES + EDITOR_FILES)
"""Single files published below ``node_modules`` besides the trees."""

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
    ".wasm": "application/wasm",
    ".zip": "application/zip",
    ".py": "text/x-python; charset=utf-8",
}
"""The only file types published, with their MIME types (not the system's mime.types, which
differ between machines: module scripts must be a JavaScript type or the browser refuses)."""

SEGMENT = re.compile(r"@?[A-Za-z0-9_-][A-Za-z0-9._-]*")
"""One path segment of a published file: no dotfile, ``.``, ``..``, empty segment (a
directory's trailing slash), backslash, NUL or other oddity; an npm scope (``@codemirror``)
may start with ``@``."""


def published(relative: str) -> bool:
    """Whether a path relative to the web folder is on the allow-list (by name only)."""
    segments = relative.split("/")
    if not all(SEGMENT.fullmatch(segment) for segment in segments):
        return False
    if os.path.splitext(relative)[1] not in CONTENT_TYPES:
        return False
    if len(segments) == 1:
        return any(fnmatch(relative, pattern) for pattern in TOP_LEVEL_FILES)
    return relative in PUBLISHED_FILES or any(relative.startswith(tree + "/")
                                              for tree in PUBLISHED_TREES)


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
