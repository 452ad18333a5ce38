"""Serve the web interface's static files and ``/healthz`` over HTTP (stdlib, in a thread).

The Docker stack serves the same files with nginx; this is the embedded equivalent, so one
``websim serve`` is the whole platform.
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable
from functools import partial
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

log = logging.getLogger("websim.http")

PAGE_ALIASES = {"/admin": "/admin.html"}
"""Clean URLs the course uses, mapped to files."""


class StaticHandler(SimpleHTTPRequestHandler):
    """Static files from one directory, plus ``GET /healthz``."""

    def __init__(self, *args: Any, health: Callable[[], dict[str, Any]],
                 **kwargs: Any) -> None:
        self._health = health
        super().__init__(*args, **kwargs)

    def do_GET(self) -> None:
        """Answer /healthz, map clean URLs, serve files."""
        path, _, query = self.path.partition("?")
        if path == "/healthz":
            body = json.dumps(self._health()).encode()
            self.send_response(200)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(body)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(body)
            return
        if path in PAGE_ALIASES:
            self.path = PAGE_ALIASES[path] + (f"?{query}" if query else "")
        super().do_GET()

    def end_headers(self) -> None:
        """Pages must always be fresh: a classroom reloads after every update."""
        self.send_header("Cache-Control", "no-cache")
        super().end_headers()

    def log_message(self, format: str, *args: Any) -> None:
        """Route access logs to logging at debug level instead of stderr."""
        log.debug("%s " + format, self.address_string(), *args)


def start_http(host: str, port: int, directory: Path,
               health: Callable[[], dict[str, Any]]) -> ThreadingHTTPServer:
    """Start serving ``directory`` on ``host:port`` in a daemon thread; raises OSError."""
    handler = partial(StaticHandler, directory=str(directory), health=health)
    server = ThreadingHTTPServer((host, port), handler)
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, name="websim-http", daemon=True).start()
    return server
