"""``websim.static_site``: the pages and the nginx include files the web image's build writes.

What nginx then does with them is tests/test_deploy_nginx.py (the real nginx and Chromium);
here, the edges: a header value nginx would read otherwise is refused, a web folder without its
npm packages is one clear error (exit 2), and the types are ``websim serve``'s.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from websim import static_site
from websim.page_policy import SECURITY_HEADERS, WORKER_POLICIES
from websim.web_files import CONTENT_TYPES

WEB_DIR = Path(__file__).resolve().parent.parent / "web-interface"


@pytest.mark.parametrize("value", ['a "quoted" word', "$host", "two\nlines", "a\\b", "{x}",
                                   "\r"])
def test_a_header_value_nginx_would_read_otherwise_is_refused(value: str) -> None:
    with pytest.raises(ValueError, match="cannot be written as an nginx header value"):
        static_site.add_header("X-Test", value)


def test_the_headers_are_websim_serves_each_once() -> None:
    headers = static_site.security_headers()
    for name, value in SECURITY_HEADERS.items():
        expected = f'add_header {name} "{value}" always;'
        assert (expected in headers) == (name != static_site.POLICY), name
    workers = static_site.worker_locations()
    for worker, policy in WORKER_POLICIES.items():
        block = workers.split(f"location = /{worker} {{", 1)[1].split("}", 1)[0]
        assert block.count("Content-Security-Policy") == 1
        assert f'Content-Security-Policy "{policy}" always;' in block


def test_the_types_are_websim_serves_without_the_systems() -> None:
    types = static_site.content_types()
    for suffix, value in CONTENT_TYPES.items():
        assert f"    {value.split(';')[0]} {suffix[1:]};\n" in types, suffix
    charset_types = types.split("charset_types ", 1)[1].rstrip(";\n").split()
    assert "text/javascript" in charset_types and "application/wasm" not in charset_types


def test_a_web_folder_without_its_npm_packages_is_one_clear_error(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    web = tmp_path / "web"
    web.mkdir()
    shutil.copyfile(WEB_DIR / "index.html", web / "index.html")  # it asks for the import map
    with pytest.raises(SystemExit) as exit_:
        static_site.main(["--web", str(web), "--out", str(tmp_path / "site"),
                          "--nginx", str(tmp_path / "nginx")])
    assert exit_.value.code == 2
    error = capsys.readouterr().err
    assert error.startswith("static_site: ") and "codemirror" in error
    assert not (tmp_path / "nginx").exists()  # nothing half-written for nginx to read
