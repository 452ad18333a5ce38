"""roslib for Node: the npm packages a graded JavaScript controller requires, and where they are.

A controller run with ``node`` is promised roslib 1.4.1 (``require('roslib')``) whatever the
install. A checkout has it in ``web-interface/node_modules`` (``npm ci``, the committed lock);
a wheel carries roslib and its dependency closure (by that lock, no dev dependencies) in
``websim/_share/node_modules``, beside the page's folder, not in it: the page server publishes
only ``websim/_share/web-interface`` by its allow-list (``websim.web_files``), so these files
are never served. The wheel's folder holds the lock's entries of what it carries
(``.package-lock.json``), so both folders are read the same way (``roslib_closure``).

No dependency beyond the standard library: ``setup.py`` reads this file at build time.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from fnmatch import fnmatch
from pathlib import Path

LOCK_FILE = ".package-lock.json"
"""npm's record of what it installed in a ``node_modules`` folder (its hidden lockfile)."""

CHECKOUT_NODE_MODULES = Path(__file__).resolve().parent.parent / "web-interface" / "node_modules"
"""roslib for Node in a checkout of websim (``npm ci`` in web-interface/)."""

WHEEL_FOLDER = "node_modules"
"""The folder of ``websim/_share`` holding roslib for Node in a wheel."""

WHEEL_NODE_MODULES = Path(__file__).resolve().parent / "_share" / WHEEL_FOLDER
"""roslib for Node in an installed wheel (``setup.py`` copies it there)."""

LEFT_OUT = ("*.d.ts", "*.d.mts", "*.d.cts", "*.map", "*.png")
"""Files of the closure a wheel leaves out, which Node never loads: TypeScript's declarations
(all of ``@types/*`` and ``undici-types``, runtime dependencies of engine.io by npm's account),
source maps (for debuggers) and images (pngparse's test files: roslib decodes the PNGs it
receives, never a file). With them the wheel's share of roslib would be 3x larger (1.8 MB
against 0.6 MB compressed); licences and read-me files stay."""


def has_roslib(modules: Path) -> bool:
    """Whether the ``node_modules`` folder ``modules`` holds roslib."""
    return (modules / "roslib" / "package.json").is_file()


def node_modules_found() -> tuple[str, ...]:
    """The folders of Node modules a controller gets when none are given.

    The checkout's when it has roslib (``npm ci`` in web-interface/), else the wheel's.
    """
    for modules in (CHECKOUT_NODE_MODULES, WHEEL_NODE_MODULES):
        if has_roslib(modules):
            return (str(modules),)
    return ()


def roslib_modules() -> Path | None:
    """The folder whose roslib and dependencies a submission can be given a copy of, or None.

    The first of ``node_modules_found()`` that has npm's record of them (``LOCK_FILE``).
    """
    for folder in node_modules_found():
        if (Path(folder) / LOCK_FILE).is_file():
            return Path(folder)
    return None


def roslib_closure(modules: Path) -> list[str]:
    """The packages roslib needs, itself included, by npm's lock (``.package-lock.json``).

    Only the runtime dependencies (a lock entry's ``dependencies`` list no
    ``devDependencies``), followed from each package and from the copies npm nested in it
    (``engine.io/node_modules/ws``: another version), which are part of their package's folder.
    """
    lock = json.loads((modules / LOCK_FILE).read_text())["packages"]
    names: list[str] = []
    todo = ["roslib"]
    while todo:
        name = todo.pop()
        key = f"node_modules/{name}"
        if name in names or key not in lock:
            continue
        names.append(name)
        for entry, package in lock.items():
            if entry == key or entry.startswith(f"{key}/node_modules/"):
                todo.extend(package.get("dependencies", {}))
    return sorted(names)


def closure_lock(modules: Path) -> str:
    """``modules``'s lock (``LOCK_FILE``) with only roslib's closure: the wheel's record."""
    lock = json.loads((modules / LOCK_FILE).read_text())
    closure = [f"node_modules/{name}" for name in roslib_closure(modules)]
    lock["packages"] = {key: entry for key, entry in lock["packages"].items()
                        if any(key == top or key.startswith(f"{top}/") for top in closure)}
    return json.dumps(lock, indent=2, sort_keys=True) + "\n"


def carried_files(modules: Path) -> Iterator[str]:
    """The files of roslib's closure a wheel carries: relative to ``modules``, sorted.

    Every file of each package (its nested ``node_modules`` included) but ``LEFT_OUT``'s;
    symlinks are skipped.
    """
    found = []
    for name in roslib_closure(modules):
        for path in (modules / name).rglob("*"):
            if path.is_file() and not path.is_symlink() and \
                    not any(fnmatch(path.name, pattern) for pattern in LEFT_OUT):
                found.append(path.relative_to(modules).as_posix())
    yield from sorted(found)
