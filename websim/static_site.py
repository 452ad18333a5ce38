"""The pages as a static site for another web server: what ``websim serve`` serves, written.

The Docker image's nginx serves the pages itself (``web-interface/nginx.conf``), and the Code
panel needs what ``websim serve`` gives every page: the editor's import map written into it
(``websim.import_map``), the security headers that make it cross-origin isolated and admit
that one inline script by its hash, and the workers' own policies (``websim.page_policy``).
``export`` writes the published files (``websim.web_files``, the one allow-list) with the map
in every page, and three nginx include files with those headers:

* ``security-headers.conf``: every header of ``SECURITY_HEADERS`` but the policy, on every
  answer that carries content;
* ``page-policy.conf``: the pages' Content-Security-Policy, with the import map's hash;
* ``worker-locations.conf``: a ``location`` per Code panel worker, served with its own
  policy instead (a worker follows the policy it is served with, not its page's);
* ``content-types.conf``: the MIME type of each published suffix and its charset, the ones
  ``websim serve`` sends (``websim.web_files.CONTENT_TYPES``), in place of the system's
  ``mime.types``, which differ between nginx versions (1.22's has no ``.mjs``: a module
  script served as ``application/octet-stream`` is refused, and Pyodide does not load).

Standard library only: the image's build stage runs it with just this folder's modules::

    python -m websim.static_site --web web-interface --out /site --nginx /etc/nginx/websim
"""

from __future__ import annotations

import argparse
import shutil
from collections.abc import Sequence
from pathlib import Path

from websim.import_map import MARKER, import_map, with_import_map
from websim.page_policy import SECURITY_HEADERS, WORKER_POLICIES, page_policy
from websim.web_files import CONTENT_TYPES, published_files

INCLUDES = ("security-headers.conf", "page-policy.conf", "worker-locations.conf",
            "content-types.conf")
"""The nginx include files ``export`` writes, in the order nginx.conf names them."""

POLICY = "Content-Security-Policy"

NOT_IN_NGINX_VALUES = frozenset('"$\\{}\n\r')
"""What a header value may not hold to be taken as it is inside nginx's double quotes: a quote,
``$`` (a variable), a backslash, a brace or a line break (semicolons are fine there)."""


def add_header(name: str, value: str) -> str:
    """One nginx ``add_header`` line, sent on every status (``always``).

    Raises:
        ValueError: ``value`` holds a character nginx would read otherwise.
    """
    if NOT_IN_NGINX_VALUES.intersection(value):
        raise ValueError(f"{name}: {value!r} cannot be written as an nginx header value")
    return f'add_header {name} "{value}" always;\n'


def security_headers() -> str:
    """``security-headers.conf``: every security header but the policy."""
    return "".join(add_header(name, value) for name, value in SECURITY_HEADERS.items()
                   if name != POLICY)


def worker_locations() -> str:
    """``worker-locations.conf``: each Code panel worker with its own policy."""
    blocks = []
    for relative, policy in sorted(WORKER_POLICIES.items()):
        lines = [add_header("Cache-Control", "no-cache"), security_headers(),
                 add_header(POLICY, policy)]
        body = "".join(f"    {line}" for text in lines for line in text.splitlines(True))
        blocks.append(f"location = /{relative} {{\n{body}}}\n")
    return "".join(blocks)


def content_types() -> str:
    """``content-types.conf``: nginx's ``types`` of the published suffixes, and their charset."""
    bare = {suffix: value.split(";")[0].strip() for suffix, value in CONTENT_TYPES.items()}
    lines = [f"    {mime} {suffix.removeprefix('.')};\n" for suffix, mime in sorted(bare.items())]
    with_charset = sorted({bare[suffix] for suffix, value in CONTENT_TYPES.items()
                           if "charset=utf-8" in value.replace(" ", "")})
    return (f"types {{\n{''.join(lines)}}}\ncharset utf-8;\n"
            f"charset_types {' '.join(with_charset)};\n")


def export(web_dir: Path, out_dir: Path, nginx_dir: Path) -> list[str]:
    """Write ``web_dir``'s published files to ``out_dir`` and the includes to ``nginx_dir``.

    Every page gets the import map where it asks for it; the pages' policy admits the map's
    script by its hash (one map, so one hash for every page). Returns the files written
    (relative to ``out_dir``).

    Raises:
        OSError: a package of the editor is not installed (``npm ci`` was not run), or a
            file cannot be read or written.
        ValueError: a package.json names no entry, or a header cannot be written for nginx.
    """
    written = []
    scripts: set[str] = set()
    for relative in published_files(web_dir):
        source = web_dir / relative
        target = out_dir / relative
        target.parent.mkdir(parents=True, exist_ok=True)
        if relative.endswith(".html"):
            page = source.read_bytes()
            if MARKER in page and not scripts:
                import_map(web_dir)  # raises: a site without its editor is not a site
            page, script = with_import_map(page, web_dir)
            target.write_bytes(page)
            if script is not None:
                scripts.add(script)
        else:
            shutil.copyfile(source, target)
        written.append(relative)
    if len(scripts) > 1:
        raise ValueError(f"the pages' import maps differ ({len(scripts)} hashes)")
    nginx_dir.mkdir(parents=True, exist_ok=True)
    policy = page_policy(next(iter(scripts), None))
    contents = (security_headers(), add_header(POLICY, policy), worker_locations(),
                content_types())
    for name, text in zip(INCLUDES, contents, strict=True):
        (nginx_dir / name).write_text(text, encoding="utf-8")
    return written


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m websim.static_site``: ``export``, or exit 2 with the reason."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--web", type=Path, required=True,
                        help="the web folder, with node_modules (npm ci)")
    parser.add_argument("--out", type=Path, required=True, help="where the site goes")
    parser.add_argument("--nginx", type=Path, required=True,
                        help="where the nginx include files go")
    args = parser.parse_args(argv)
    try:
        written = export(args.web, args.out, args.nginx)
    except (OSError, ValueError) as error:
        parser.exit(2, f"static_site: {error}\n")
    print(f"{len(written)} files in {args.out}; {', '.join(INCLUDES)} in {args.nginx}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
