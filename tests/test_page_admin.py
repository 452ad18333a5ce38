"""The /admin page in a real headless Chromium: parameters changed with the token, refused
without it, and the token sent to no bridge but the page's own.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator
from typing import Any

from page_helpers import (
    ROBOT,
    Bridge,
    admin_context,
    needs_browser,
    open_page,
    screenshot,
    wait_connected,
    wait_for_odom_in_page,
)
from websockets.sync.server import Request, ServerConnection, serve

from server_process import ADMIN_TOKEN, ServerProcess, free_port, wait_for


@contextlib.contextmanager
def recording_listener() -> Iterator[tuple[str, list[str]]]:
    """A plain WebSocket server on a free port: records the path (with its query) of every
    handshake and holds each connection open, answering nothing. Yields (its URL, the paths)."""
    paths: list[str] = []

    def record(connection: ServerConnection, request: Request) -> None:
        paths.append(request.path)

    def hold(connection: ServerConnection) -> None:
        for _ in connection:
            pass

    port = free_port()
    with serve(hold, "127.0.0.1", port, process_request=record) as listener:
        thread = threading.Thread(target=listener.serve_forever, daemon=True)
        thread.start()
        try:
            yield f"ws://127.0.0.1:{port}/", paths
        finally:
            listener.shutdown()
            thread.join(timeout=5)


def runtime_parameters() -> list[dict[str, Any]]:
    return [spec for spec in ROBOT["parameters"] if spec["runtime"]]


@needs_browser
def test_admin_changes_mass_with_the_token(server: ServerProcess, bridge: Bridge,
                                           browser: Any) -> None:
    context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
    try:
        page, log = open_page(context, f"{server.http_url}/admin?token={ADMIN_TOKEN}")
        wait_connected(page)
        assert "token" not in page.url  # stored, then taken out of the address bar
        assert page.evaluate("sessionStorage.getItem('websim.adminToken')") == ADMIN_TOKEN
        assert f"{server.ws_url}?token={ADMIN_TOKEN}" in log.requests  # its own bridge got it
        assert page.is_visible('#token-state[data-kind="ok"]')
        page.wait_for_selector("#params-form[data-loaded]")
        # The form is robot.json's runtime parameters, each bounded by its range.
        fields = page.eval_on_selector_all("[data-param]", """inputs => inputs.map(
            (input) => [input.dataset.param, input.min ?? '', input.max ?? ''])""")
        assert [name for name, _, _ in fields] == [s["name"] for s in runtime_parameters()]
        for (_, low, high), spec in zip(fields, runtime_parameters(), strict=True):
            assert (float(low) if low else None) == spec["minimum"], spec["name"]
            assert (float(high) if high else None) == spec["maximum"], spec["name"]
        assert page.input_value("#param-mass_kg") == "1.2"
        assert page.input_value("#param-mode") == "kinematic"
        # Out of range: the browser refuses it, and nothing is sent.
        page.evaluate("""() => {
            const connection = window.websim.connection, call = connection.callService;
            window.calls = [];
            connection.callService = (name, ...rest) => {
                window.calls.push(name);
                return call.call(connection, name, ...rest);
            };
        }""")
        mass = next(s for s in runtime_parameters() if s["name"] == "mass_kg")
        page.fill("#param-mass_kg", str(mass["maximum"] * 10))
        page.click("#params-apply")
        assert page.evaluate("document.querySelector('#param-mass_kg').validity.rangeOverflow")
        assert page.evaluate("window.calls") == []
        page.fill("#param-mass_kg", "2.5")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        assert "mass_kg = 2.5" in notice.text_content()
        assert page.evaluate("window.calls")[0] == ROBOT["services"]["set_parameters"]["name"]
        assert bridge.parameter("mass_kg") == 2.5
        page.reload()  # the token is asked once per tab: it is still there
        wait_connected(page)
        assert page.is_hidden("#token-form")
        page.wait_for_selector("#params-form[data-loaded]")
        assert page.input_value("#param-mass_kg") == "2.5"
        wait_for_odom_in_page(page)
        screenshot(page, "admin.png")
        page.fill("#param-mass_kg", "1.2")
        page.click("#params-apply")
        page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        assert log.console_errors == [] and log.page_errors == []
        assert log.foreign_requests() == []
    finally:
        context.close()
    assert bridge.parameter("mass_kg") == 1.2


@needs_browser
def test_admin_without_the_token_shows_the_refusal(server: ServerProcess, bridge: Bridge,
                                                   browser: Any) -> None:
    context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
    try:
        page, _ = open_page(context, f"{server.http_url}/admin")
        wait_connected(page)
        assert page.is_visible("#token-form")
        page.wait_for_selector("#params-form[data-loaded]")
        page.fill("#param-mass_kg", "3")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="error"]', timeout=10000)
        assert "set_parameters needs admin rights" in notice.text_content()
        page.fill("#token-input", "not-the-token")  # a wrong token: refused the same way
        page.click("#token-form button[type=submit]")
        wait_connected(page)
        page.wait_for_selector("#params-form[data-loaded]")
        page.evaluate("document.querySelector('#params-notice').hidden = true")
        page.fill("#param-mass_kg", "3")
        page.click("#params-apply")
        notice = page.wait_for_selector('#params-notice[data-kind="error"]', timeout=10000)
        assert "needs admin rights" in notice.text_content()
        assert page.is_visible('#token-state[data-kind="error"]')  # says the token is wrong
        assert page.is_visible("#token-form")  # and asks again
        screenshot(page, "admin-refused.png")
    finally:
        context.close()
    assert bridge.parameter("mass_kg") == 1.2


@needs_browser
def test_admin_sends_no_token_to_a_bridge_named_by_a_link(server: ServerProcess,
                                                           browser: Any) -> None:
    with recording_listener() as (other_url, paths):
        context = admin_context(browser, server, viewport={"width": 1280, "height": 860})
        try:
            page, log = open_page(context, f"{server.http_url}/admin?token={ADMIN_TOKEN}")
            wait_connected(page)  # the instructor's tab holds the token now
            page.goto(f"{server.http_url}/admin?ws={other_url}")  # then follows a link
            wait_connected(page)
            notice = page.wait_for_selector('#token-state[data-kind="warn"]', timeout=5000)
            text = notice.text_content() or ""
            assert f"Connected to {other_url} from the link" in text
            assert "your admin token is only sent to this page's own server" in text
            assert server.ws_url in text
            page.click("#token-forget")  # a token typed into the form is not sent there either
            wait_for(lambda: len(paths) >= 2, what="the reconnect without a token")
            page.fill("#token-input", "typed-token")
            page.click("#token-form button[type=submit]")
            wait_for(lambda: len(paths) >= 3, what="the reconnect after typing a token")
            wait_connected(page)
            assert page.is_visible('#token-state[data-kind="warn"]')
            screenshot(page, "admin-linked-bridge.png")
            page.fill("#ws-url", server.ws_url)  # the own bridge, typed: it gets the token
            page.click("#connect-form button[type=submit]")
            wait_connected(page)
            page.wait_for_selector('#token-state[data-kind="ok"]', timeout=5000)
            assert f"{server.ws_url}?token=typed-token" in log.requests
        finally:
            context.close()
    assert len(paths) >= 3
    assert [path for path in paths if "token=" in path] == []
    assert [url for url in log.requests if url.startswith(other_url) and "token=" in url] == []


@needs_browser
def test_admin_sends_the_valid_changes_and_says_what_it_refused(server: ServerProcess,
                                                                bridge: Bridge,
                                                                browser: Any) -> None:
    """An out-of-range value replaces the last 'Applied' with the refusal, and a mode change
    in the same form is still sent."""
    mass = next(s for s in runtime_parameters() if s["name"] == "mass_kg")
    context = admin_context(browser, server, viewport={"width": 1280, "height": 800})
    try:
        page, log = open_page(context, f"{server.http_url}/admin?token={ADMIN_TOKEN}")
        wait_connected(page)
        page.wait_for_selector("#params-form[data-loaded]")
        page.fill("#param-mass_kg", "2.5")
        page.click("#params-apply")
        page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        too_heavy = mass["maximum"] * 10
        page.fill("#param-mass_kg", f"{too_heavy:g}")
        page.select_option("#param-mode", "dynamic")
        page.click("#params-apply")
        wait_for(lambda: bridge.parameter("mode") == "dynamic", what="the mode change sent")
        notice = page.wait_for_selector('#params-notice:not([data-kind="ok"])', timeout=10000)
        page.wait_for_function(
            "document.querySelector('#params-notice').textContent.includes('mode = dynamic')",
            timeout=10000)
        text = notice.text_content() or ""
        assert "mode = dynamic" in text and "mass_kg" in text and "not sent" in text.lower(), text
        assert f"{mass['maximum']:g}" in text, text  # the limit it broke
        assert page.input_value("#param-mass_kg") == f"{too_heavy:g}"  # kept, to correct
        assert page.get_attribute("#param-mass_kg", "aria-invalid") == "true"
        assert bridge.parameter("mass_kg") == 2.5
        screenshot(page, "admin-partly-refused.png", full_page=False)
        page.fill("#param-mass_kg", "")  # nothing valid to send: it says so
        page.click("#params-apply")
        page.wait_for_function(
            "document.querySelector('#params-notice').textContent.startsWith('Nothing sent')",
            timeout=10000)
        assert page.get_attribute("#params-notice", "data-kind") == "error"
        page.fill("#param-mass_kg", "1.2")
        page.select_option("#param-mode", "kinematic")
        page.click("#params-apply")
        page.wait_for_selector('#params-notice[data-kind="ok"]', timeout=10000)
        assert page.get_attribute("#param-mass_kg", "aria-invalid") != "true"
        assert log.page_errors == []
    finally:
        context.close()
    assert bridge.parameter("mass_kg") == 1.2
    assert bridge.parameter("mode") == "kinematic"
