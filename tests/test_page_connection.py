"""The student page in a real headless Chromium against a real ``websim serve``: it loads
from this server alone, finds its bridge (``?ws=``, else its server's config.json), says when
the bridge or robot.json is missing, and reconnects after a server restart.
"""

from __future__ import annotations

from typing import Any
from urllib.parse import quote, urlsplit

from page_helpers import (
    Bridge,
    needs_browser,
    open_page,
    page_url,
    screenshot,
    wait_connected,
    wait_for_odom_in_page,
    wait_until_still,
    x_of,
)

from server_process import ServerProcess, free_port, start_server, wait_for


@needs_browser
def test_page_loads_locally_without_errors_and_connects(server: ServerProcess,
                                                        bridge: Bridge, browser: Any) -> None:
    admin = Bridge(server.admin_ws_url)
    limit = admin.call("/virtual_robot/set_parameters", {"parameters": [
        {"name": "max_linear_mps", "value": {"type": 3, "double_value": 0.45}}]})
    assert limit["values"]["results"][0]["successful"] is True
    context = browser.new_context(viewport={"width": 1280, "height": 860},
                                  device_scale_factor=2)
    try:
        page, log = open_page(context, page_url(server))
        wait_connected(page)
        wait_for_odom_in_page(page)
        page.wait_for_function(  # the speed slider is bounded by the robot's own limit
            "document.querySelector('#speed-linear').max === '0.45'", timeout=10000)
        assert page.input_value("#ws-url") == server.ws_url  # ?ws= honoured
        assert page.is_hidden("#fatal")
        assert page.is_hidden("#view-message")
        canvas = page.evaluate(
            "(() => { const c = document.querySelector('#view'), r = c.getBoundingClientRect();"
            " return [c.width, r.width, c.height, r.height]; })()")
        # HiDPI: the backing store has devicePixelRatio (2) pixels per CSS pixel.
        assert canvas[0] == round(2 * canvas[1]) and canvas[2] == round(2 * canvas[3])
        screenshot(page, "main-connected.png")
        assert log.console_errors == [] and log.page_errors == []
        assert any(url.endswith("/node_modules/uplot/dist/uPlot.esm.js") for url in log.requests)
        assert f"{server.http_url}/robot.json" in log.requests
        assert log.foreign_requests() == []
    finally:
        context.close()
        admin.call("/virtual_robot/set_parameters", {"parameters": [
            {"name": "max_linear_mps", "value": {"type": 3, "double_value": 0.5}}]})
        admin.close()


@needs_browser
def test_dead_bridge_shows_a_message_and_the_default_url(server: ServerProcess,
                                                         browser: Any) -> None:
    context = browser.new_context()
    try:
        dead = f"ws://127.0.0.1:{free_port()}"
        page, log = open_page(context, f"{server.http_url}/?ws={dead}")
        page.wait_for_selector('#conn-status[data-status="error"]', timeout=10000)
        message = page.wait_for_selector("#view-message:not([hidden])", timeout=5000)
        assert f"Cannot reach the bridge at {dead}." in message.text_content()
        assert page.is_hidden("#fatal") and page.is_visible("#view")
        assert log.page_errors == []
        screenshot(page, "main-dead-bridge.png", full_page=False)
        page.goto(f"{server.http_url}/")
        # The field is filled once config.json and robot.json have loaded: without ?ws=, the
        # bridge of the server that served the page (its config.json), not 9090.
        page.wait_for_function("document.querySelector('#ws-url').value !== ''", timeout=5000)
        assert page.input_value("#ws-url") == server.ws_url
    finally:
        context.close()


@needs_browser
def test_ws_parameter_and_reconnect_after_a_server_restart(browser: Any) -> None:
    first = start_server()
    ws_port, http_port = first.ws_port, first.http_port
    second: ServerProcess | None = None
    context = browser.new_context()
    try:
        page, _ = open_page(context, page_url(first))
        wait_connected(page)
        wait_for_odom_in_page(page)
        first.stop()
        page.wait_for_selector('#conn-status:is([data-status="closed"], [data-status="error"])',
                               timeout=10000)
        second = start_server(ws_port=ws_port, http_port=http_port)
        wait_connected(page, timeout_s=20)
        back_ms = page.evaluate("performance.now()")
        page.wait_for_function(  # odometry flows again: the subscriptions came back
            "t => window.websim.state.odomAtMs > t", arg=back_ms, timeout=10000)
        check = Bridge(second.ws_url)
        try:
            check.subscribe("/odom")
            page.keyboard.down("ArrowUp")  # and the page's publisher works on the new bridge
            wait_for(lambda: check.messages("/odom")
                     and x_of(check.messages("/odom")[-1]) > 0.05, what="motion after restart")
            page.keyboard.up("ArrowUp")
            wait_until_still(check)
        finally:
            check.close()
    finally:
        context.close()
        first.stop()
        if second is not None:
            second.stop()


@needs_browser
def test_a_page_without_ws_drives_the_robot_of_the_server_that_served_it(browser: Any) -> None:
    """Two servers on one host, neither on 9090: each page dials its own server's bridge
    (config.json, filled by that server), and its Admin link keeps a ?ws= it was given."""
    first, second = start_server(), start_server()
    context = browser.new_context()
    watch_first, watch_second = Bridge(first.ws_url), Bridge(second.ws_url)
    try:
        watch_first.subscribe("/odom")
        watch_second.subscribe("/odom")
        page, log = open_page(context, f"{second.http_url}/")
        wait_connected(page)
        page.keyboard.down("ArrowUp")
        wait_for(lambda: watch_second.messages("/odom")
                 and x_of(watch_second.messages("/odom")[-1]) > 0.05, what="second robot moving")
        page.keyboard.up("ArrowUp")
        assert watch_first.messages("/odom") and abs(x_of(watch_first.messages("/odom")[-1])) \
            < 1e-6, "the page drove the other server's robot"
        page.goto(page_url(first))  # given a ?ws=: the Admin link keeps it
        wait_connected(page)
        page.click("nav a")
        page.wait_for_url("**/admin?ws=*", timeout=10000)
        assert urlsplit(page.url).query == f"ws={quote(first.ws_url, safe='')}"
        assert not log.page_errors, log.page_errors
    finally:
        watch_first.close()
        watch_second.close()
        context.close()
        first.stop()
        second.stop()


@needs_browser
def test_pages_without_robot_json_say_so_and_guess_nothing(server: ServerProcess,
                                                           browser: Any) -> None:
    context = browser.new_context()
    context.route(f"{server.http_url}/robot.json",
                  lambda route: route.fulfill(status=404, body="missing"))
    try:
        for path in ("/", "/admin"):
            page, log = open_page(context, page_url(server, path))
            banner = page.wait_for_selector("#fatal:not([hidden])", timeout=10000)
            assert "robot.json" in (banner.text_content() or ""), path
            assert "HTTP 404" in (banner.text_content() or ""), path
            assert [url for url in log.requests if url.startswith("ws")] == [], path
            assert log.page_errors == [], path
    finally:
        context.close()
