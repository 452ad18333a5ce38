"""The page's import map, built from the editor's installed npm packages, and its place in the page.

CodeMirror 6 ships ES modules that import each other by package name (``@codemirror/state``);
a browser resolves those names through an import map. Rather than retype one in the page (or
bundle), the server builds it from each package's own ``package.json`` (its ``exports``
entry for ``import``, else ``module``, else ``main``), walking the dependencies from
``EDITOR_PACKAGES``, and writes it into the page where ``MARKER`` stands. The page's
Content-Security-Policy admits that one inline script by its hash (``script_hash``), nothing
else inline.

Which files are published is ``websim.web_files.EDITOR_FILES``; a test holds the map's targets
to it.
"""

from __future__ import annotations

import base64
import hashlib
import json
from pathlib import Path
from typing import Any

EDITOR_PACKAGES = ("codemirror", "@codemirror/lang-python", "@codemirror/lang-javascript")
"""What the Code panel's editor imports (``js/code-editor.js``), with all they depend on."""

MARKER = b"<!-- websim:importmap -->"
"""Where a page wants the import map (the first thing in its ``<head>``)."""

MAX_PACKAGES = 200
"""A dependency walk longer than this is a broken node_modules, not an editor."""


def entry_point(package: dict[str, Any]) -> str:
    """The file a package's ``import`` resolves to, relative to its folder (``dist/index.js``).

    Raises:
        ValueError: the package names no ES module entry.
    """
    exports = package.get("exports")
    if isinstance(exports, dict):
        exports = exports.get(".", exports)
        if isinstance(exports, dict):
            exports = exports.get("import", exports.get("default"))
    entry = exports if isinstance(exports, str) else package.get("module") or package.get("main")
    if not isinstance(entry, str) or not entry:
        raise ValueError(f"{package.get('name')}: no ES module entry in its package.json")
    return entry.removeprefix("./")


def import_map(web_dir: Path, roots: tuple[str, ...] = EDITOR_PACKAGES) -> dict[str, Any]:
    """``{"imports": {name: "./node_modules/NAME/ENTRY"}}`` for ``roots`` and their dependencies.

    Raises:
        OSError: a package is not installed (``npm ci`` was not run).
        ValueError: a package.json is unreadable or names no entry.
    """
    modules = web_dir / "node_modules"
    imports: dict[str, str] = {}
    todo = list(roots)
    while todo:
        name = todo.pop()
        if name in imports:
            continue
        if len(imports) >= MAX_PACKAGES:
            raise ValueError(f"more than {MAX_PACKAGES} packages below {', '.join(roots)}")
        package = json.loads((modules / name / "package.json").read_text(encoding="utf-8"))
        imports[name] = f"./node_modules/{name}/{entry_point(package)}"
        todo.extend(package.get("dependencies", {}))
    return {"imports": dict(sorted(imports.items()))}


def script_hash(text: str) -> str:
    """The CSP source that admits an inline script of exactly ``text`` (``'sha256-...'``)."""
    digest = hashlib.sha256(text.encode("utf-8")).digest()
    return f"'sha256-{base64.b64encode(digest).decode()}'"


def with_import_map(page: bytes, web_dir: Path) -> tuple[bytes, str | None]:
    """``page`` with its marker replaced by the import map, and the script's CSP hash.

    A page without the marker comes back as it is (hash None); without the packages
    installed, the marker stays (the editor then says how to install them) and the hash is
    None.
    """
    if MARKER not in page:
        return page, None
    try:
        text = json.dumps(import_map(web_dir), separators=(",", ":"))
    except (OSError, ValueError):
        return page, None
    script = f'<script type="importmap">{text}</script>'.encode()
    return page.replace(MARKER, script, 1), script_hash(text)
