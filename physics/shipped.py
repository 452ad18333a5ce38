"""Where the files websim ships live: the checkout's folders, or the copies a wheel carries.

Run from a checkout (or an editable install of one), ``config/``, ``worlds/`` and
``web-interface/`` are the checkout's own, so an edit shows at once. Installed from a wheel,
they are package data (``setup.py`` copies them in at build time: the robot parameters and
worlds into ``physics/_share/``, the published files of the page, its libraries included,
into ``websim/_share/``), found with ``importlib.resources``, whatever the current folder.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

CHECKOUT_DIR = Path(__file__).resolve().parent.parent
"""The folder above the ``physics`` package: a checkout's root, or site-packages."""

FROM_CHECKOUT = (CHECKOUT_DIR / "pyproject.toml").is_file() and \
    (CHECKOUT_DIR / "worlds").is_dir()
"""Whether websim runs from a checkout (not from an installed wheel)."""

SHARE = "_share"
"""The folder of a package that holds its shipped files in a wheel."""


def shipped(package: str, name: str) -> Path:
    """The shipped folder ``name`` (``config``, ``worlds``, ``web-interface``) of ``package``.

    A wheel is installed unpacked, so the folder is a real directory (the page server serves
    it from disk).
    """
    if FROM_CHECKOUT:
        return CHECKOUT_DIR / name
    return Path(str(importlib.resources.files(package) / SHARE / name))


def by_name(name_or_path: str | Path, folder: Path) -> Path:
    """The file for a path, or for a shipped file's name in ``folder`` (``"maze"``).

    A name has no suffix and no folder, and no such file exists here: ``folder/NAME.yaml``.
    """
    path = Path(name_or_path)
    if path.exists() or path.suffix or len(path.parts) > 1:
        return path
    return folder / f"{path}.yaml"
