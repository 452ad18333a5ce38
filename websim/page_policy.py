"""What the pages may load and run: their security headers, one definition for every server.

``websim serve`` sends them on every answer (``websim.http_server``); the Docker image's nginx
sends the same, from the files ``websim.static_site`` writes at build time. Standard library
only: the image's build stage runs it without the rest of websim.
"""

from __future__ import annotations

CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data: blob:; connect-src 'self' ws: wss:; object-src 'none'; "
    "base-uri 'none'; form-action 'self'; frame-ancestors 'none'")
"""The pages load everything from this server (offline: no CDN), run no inline script, and
may be framed by nobody (a token page in another site's frame is a clickjacking target);
their WebSocket is on another port, so ``connect-src`` admits ws: and wss:. Inline styles
stay allowed: the joystick library sets them."""

SECURITY_HEADERS = {
    "Content-Security-Policy": CONTENT_SECURITY_POLICY,
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "no-referrer",
    "Cross-Origin-Opener-Policy": "same-origin",
    "Cross-Origin-Embedder-Policy": "require-corp",
    "Cross-Origin-Resource-Policy": "same-origin",
    "X-Content-Type-Options": "nosniff",
}
"""On every answer: the admin pages carry the token in their URL, which no Referer may leak.
The three Cross-Origin headers make the pages cross-origin isolated, which SharedArrayBuffer
needs (the Code panel's Python worker reads its frames from one, and Pyodide's interrupt is
one); everything the pages load is this server's own, so nothing else changes."""

WORKER_POLICIES = {
    "js/code-python-worker.js": (
        "default-src 'self'; script-src 'self' 'unsafe-eval' 'wasm-unsafe-eval'; "
        "connect-src 'self'; object-src 'none'; base-uri 'none'"),
    "js/code-js-worker.js": (
        "default-src 'self'; script-src 'self' blob:; connect-src 'self' ws: wss:; "
        "object-src 'none'; base-uri 'none'"),
}
"""The Code panel's workers' own policies (a worker follows the one it is served with, not its
page's): Pyodide compiles WebAssembly and its glue calls eval(); a JavaScript program is
loaded from a blob: URL and opens its robot's WebSocket. The page's policy stays as it is."""


def page_policy(script_source: str | None) -> str:
    """The pages' Content-Security-Policy, with one inline script admitted if given.

    ``script_source``: the script's hash source (``websim.import_map.script_hash``: the
    import map), or None.
    """
    if script_source is None:
        return CONTENT_SECURITY_POLICY
    return CONTENT_SECURITY_POLICY.replace("script-src 'self'",
                                           f"script-src 'self' {script_source}")
