"""The build step that makes the wheel carry what ``websim serve`` needs besides the code.

Robot parameters, worlds, the command files of ``websim compare``, the graded scenarios
(``grading``), the page with its third-party JavaScript, and roslib for Node (what a graded
JavaScript controller ``require``s), so an installed websim runs from any folder, offline.

``pyproject.toml`` holds the project's metadata; this file only adds that build step. The page's
libraries (roslib, uPlot, nipplejs) are the committed npm lock's: installed with ``npm ci`` when
``web-interface/node_modules`` is missing or older than the lock (so building needs Node then;
installing the wheel never does). Which files of the page are carried is the page server's own
allow-list (``websim/web_files.py``); roslib for Node, its dependency closure by the same lock,
goes to a folder of its own beside the page's, never published (``websim/node_roslib.py``). An
editable install copies nothing: the checkout serves.
"""

from __future__ import annotations

import runpy
import shutil
import subprocess
from collections.abc import Iterable
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
WEB_DIR = ROOT / "web-interface"
WEB_FILES = runpy.run_path(str(ROOT / "websim" / "web_files.py"))
NODE_ROSLIB = runpy.run_path(str(ROOT / "websim" / "node_roslib.py"))
EXAMPLES = ("course_snippets.py", "course_snippets.js")


def vendor_libraries() -> None:
    """``npm ci`` in web-interface/ unless its node_modules is the committed lock's already."""
    lock = WEB_DIR / "package-lock.json"
    installed = WEB_DIR / "node_modules" / ".package-lock.json"
    if installed.is_file() and installed.stat().st_mtime >= lock.stat().st_mtime:
        return
    npm = shutil.which("npm")
    if npm is None:
        raise SystemExit("building the websim wheel: the page's libraries are not installed "
                         "and npm is not on PATH: install Node, or run "
                         "'npm ci --prefix web-interface', then build again")
    subprocess.run([npm, "ci", "--omit=dev", "--ignore-scripts", "--no-audit", "--no-fund"],
                   cwd=WEB_DIR, check=True)


class BuildWithShippedFiles(build_py):
    """``build_py``, then the shipped files into ``physics/_share`` and ``websim/_share``.

    ``physics/_share``: the robot parameters, the worlds, the command files of
    ``websim compare``, the scenarios of ``grading`` and the course's snippets (the Code
    panel's examples); ``websim/_share``: the page (``web-interface``) and roslib for Node
    (``node_modules``).
    """

    def run(self) -> None:
        """Build the packages, then copy the shipped files next to them (not when editable)."""
        super().run()
        if getattr(self, "editable_mode", False):
            return
        vendor_libraries()
        build = Path(self.build_lib)
        for folder in ("config", "worlds", "examples/commands", "examples/scenarios"):
            target = build / "physics" / "_share" / folder
            target.mkdir(parents=True, exist_ok=True)
            for source in sorted((ROOT / folder).glob("*.yaml")):
                shutil.copy2(source, target / source.name)
        for example in EXAMPLES:  # the Code panel's examples (websim.code_starters)
            shutil.copy2(ROOT / "examples" / example, build / "physics" / "_share" / "examples")
        share = build / "websim" / "_share"
        copy_tree(WEB_DIR, share / "web-interface", WEB_FILES["published_files"](WEB_DIR))
        modules = WEB_DIR / "node_modules"
        node_target = share / NODE_ROSLIB["WHEEL_FOLDER"]
        copy_tree(modules, node_target, NODE_ROSLIB["carried_files"](modules))
        (node_target / NODE_ROSLIB["LOCK_FILE"]).write_text(NODE_ROSLIB["closure_lock"](modules))


def copy_tree(source: Path, target: Path, relatives: Iterable[str]) -> None:
    """``target`` holding exactly the files ``relatives`` of ``source``, nothing kept before."""
    shutil.rmtree(target, ignore_errors=True)
    for relative in relatives:
        destination = target / relative
        destination.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(source / relative, destination)


setup(cmdclass={"build_py": BuildWithShippedFiles})
