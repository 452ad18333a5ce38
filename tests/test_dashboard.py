"""The instructor's dashboard (``/class``) in a real headless Chromium against a real class.

``websim serve --class N`` runs the class; the page opens the instructor's root connection
(``ws://HOST:PORT/?token=...``, every robot under ``/NAME/``). What the robots did is driven
and checked from outside the page: raw WebSocket clients drive a robot as a student would,
and ``/healthz`` says which robots are paused. The page's modules are unit-tested under Node
(``tests/web/class-*.test.mjs``, run by test_page_modules.py with the others).

As in the test_page_*.py files, the servers listen on free ports, so the browser is answered a
``config.json`` naming the test server's bridge, as an instructor's would: the token goes only
to the page's own server. Screenshots go to ``test-artifacts/`` (gitignored).
"""

from __future__ import annotations

import contextlib
import csv
import itertools
import json
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeoutError
from websockets.sync.client import ClientConnection, connect

from chromium import skip_reason
from server_process import ADMIN_TOKEN, ServerProcess, start_server, wait_for

ROOT = Path(__file__).resolve().parent.parent
WEB_DIR = ROOT / "web-interface"
ROBOT = json.loads((WEB_DIR / "robot.json").read_text())
"""The robot description the page loads (every robot of a class shares its topic names)."""
ARTIFACTS = ROOT / "test-artifacts"
LIBRARIES = [WEB_DIR / "node_modules" / path for path in (
    "roslib/build/roslib.min.js", "uplot/dist/uPlot.esm.js")]
CLASS_SIZE = 12
NAMES = [f"robot{i:02d}" for i in range(1, CLASS_SIZE + 1)]
VIEWPORT = {"width": 1280, "height": 800}

MIN_FPS = 20
"""The grid of 40 must draw faster than this. A loose bound on purpose: it holds on a loaded
2-core machine running the 40-robot server beside the browser (an idle one gives about 60)."""

BROWSER_SKIP = skip_reason(LIBRARIES)
needs_browser = pytest.mark.skipif(BROWSER_SKIP is not None, reason=BROWSER_SKIP or "")

CARD_FIELDS = """(name) => {
    const card = document.querySelector(`[data-robot="${name}"]`);
    if (!card) return null;
    const fields = {};
    for (const el of card.querySelectorAll('[data-field]')) fields[el.dataset.field] =
        el.hidden ? '' : el.textContent;
    return fields;
}"""
"""A card's fields (speed, pose, driver, held...) as shown; a hidden one reads ''."""

FRAME_RATE = """(durationMs) => new Promise((resolve) => {
    let frames = 0;
    let first = null;
    const step = (now) => {
        if (first === null) first = now;
        else frames += 1;
        if (now - first < durationMs) requestAnimationFrame(step);
        else resolve(frames / ((now - first) / 1000));
    };
    requestAnimationFrame(step);
})"""
"""Animation frames per second over ``durationMs``, counted by requestAnimationFrame."""


# --- Raw rosbridge clients: a student on a robot, the instructor at the root ---------------

class Client:
    """A rosbridge v2 client on one WebSocket, without a reader thread: it sends, and
    ``call()`` reads until the answer comes (skipping whatever else arrives)."""

    def __init__(self, url: str) -> None:
        self._stack = contextlib.ExitStack()
        self._ws: ClientConnection = self._stack.enter_context(connect(url, max_size=None))
        self._ids = itertools.count()

    def send(self, **msg: Any) -> None:
        self._ws.send(json.dumps(msg))

    def drive(self, linear_mps: float, angular_rps: float = 0.0, topic: str | None = None) -> None:
        cmd_vel = ROBOT["topics"]["cmd_vel"]
        self.send(op="publish", topic=topic or cmd_vel["name"], type=cmd_vel["type"],
                  msg={"linear": {"x": linear_mps}, "angular": {"z": angular_rps}})

    def call(self, service: str, args: dict[str, Any] | None = None,
             timeout_s: float = 5.0) -> dict[str, Any]:
        call_id = f"call:{next(self._ids)}"
        self.send(op="call_service", id=call_id, service=service, args=args or {})
        deadline = time.monotonic() + timeout_s
        while True:
            message = json.loads(self._ws.recv(timeout=max(0.0, deadline - time.monotonic())))
            if message.get("op") == "service_response" and message.get("id") == call_id:
                return dict(message)

    def close(self) -> None:
        self._stack.close()


def robot_ws_url(server: ServerProcess, name: str, token: str | None = None) -> str:
    return f"ws://127.0.0.1:{server.ws_port}/robots/{name}" + (f"?token={token}" if token
                                                                else "")


TOKENS: dict[str, str] = {}
"""The class's robot tokens, from its links file (the ``server`` fixture's)."""


@contextlib.contextmanager
def client(url: str) -> Iterator[Client]:
    opened = Client(url)
    try:
        yield opened
    finally:
        opened.close()


# --- The browser ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ServerProcess]:
    links = tmp_path_factory.mktemp("dashboard") / "links.csv"
    running = start_server(["--class", str(CLASS_SIZE), "--links", str(links)])
    TOKENS.update({row["name"]: row["token"] for row in csv.DictReader(links.open())})
    yield running
    running.stop()


@dataclass
class PageLog:
    """What a page did: WebSocket URLs opened, console errors, uncaught errors."""

    websockets: list[str] = field(default_factory=list)
    console_errors: list[str] = field(default_factory=list)
    page_errors: list[str] = field(default_factory=list)
    failed_requests: list[str] = field(default_factory=list)
    """Requests answered 4xx or 5xx (the page's /workers.json was a 404 in one process)."""


@contextlib.contextmanager
def dashboard(browser: Any, server: ServerProcess, token: str | None = ADMIN_TOKEN,
              count: int = CLASS_SIZE, init_script: str | None = None,
              viewport: dict[str, int] | None = None) -> Iterator[tuple[Any, PageLog]]:
    """/class (with ``?token=`` unless None) at 1280 x 800 (or ``viewport``) in a fresh
    context, its config.json naming ``server``'s bridge; with a token, until ``count`` cards
    show their robot's pose. ``init_script`` runs in the page before its own scripts."""
    context = browser.new_context(viewport=viewport or VIEWPORT)
    if init_script is not None:
        context.add_init_script(init_script)
    with urllib.request.urlopen(f"{server.http_url}/config.json", timeout=10) as served:
        config = {**json.loads(served.read()), "ws": server.ws_url, "adminWs": None}
    context.route(f"{server.http_url}/config.json", lambda route: route.fulfill(
        status=200, content_type="application/json", body=json.dumps(config)))
    try:
        page = context.new_page()
        log = PageLog()
        page.on("websocket", lambda websocket: log.websockets.append(websocket.url))
        page.on("console", lambda msg: log.console_errors.append(msg.text)
                if msg.type == "error" else None)
        page.on("pageerror", lambda error: log.page_errors.append(str(error)))
        page.on("response", lambda response: log.failed_requests.append(
            f"{response.status} {response.url}") if response.status >= 400 else None)
        query = "" if token is None else f"?token={token}"
        page.goto(f"{server.http_url}/class{query}")
        if token is not None:
            wait_for_cards(page, count)
        yield page, log
    finally:
        context.close()


def page_says(page: Any) -> str:
    """The page's error banner and message, for a failure's explanation."""
    return str(page.evaluate(
        "['#fatal', '#class-message'].map((s) => document.querySelector(s))"
        ".filter((el) => el && !el.hidden).map((el) => el.textContent.trim()).join(' | ')"))


def wait_in_page(page: Any, expression: str, what: str, arg: Any = None,
                 timeout_s: float = 10.0) -> None:
    """Wait until ``expression`` (a JS function of ``arg``) holds; else fail saying ``what``
    and what the page shows (its error banner, its message)."""
    try:
        page.wait_for_function(expression, arg=arg, timeout=timeout_s * 1000)
    except PlaywrightTimeoutError:
        raise AssertionError(f"timed out after {timeout_s} s waiting for {what}; the page "
                             f"says: {page_says(page) or 'nothing'}") from None


def wait_for_cards(page: Any, count: int, timeout_s: float = 20.0) -> None:
    """``count`` cards, each showing its robot's pose and its first status."""
    wait_in_page(page, """(count) => {
            const cards = document.querySelectorAll('.robot-card');
            return cards.length === count && [...cards].every((card) =>
                card.querySelector('[data-field=pose]').textContent !== '–'
                && card.querySelector('[data-field=clients]').textContent !== '–');
        }""", f"{count} cards showing their robots", arg=count, timeout_s=timeout_s)


def card(page: Any, name: str) -> dict[str, str]:
    fields = page.evaluate(CARD_FIELDS, name)
    assert fields is not None, f"no card for {name}"
    return dict(fields)


def screenshot(page: Any, name: str, full_page: bool = True) -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / name
    page.screenshot(path=str(path), full_page=full_page)
    return path


# --- Tests ---------------------------------------------------------------------------------

def test_the_root_connection_lists_the_class(server: ServerProcess) -> None:
    """What the dashboard stands on: the instructor's root connection and /websim/robots."""
    with client(server.admin_ws_url) as root:
        answer = root.call("/websim/robots")
    assert answer["result"] is True, answer
    assert answer["values"]["names"] == NAMES


@needs_browser
def test_every_robot_has_a_card_and_the_card_of_a_driven_robot_says_who(
        server: ServerProcess, browser: Any) -> None:
    with dashboard(browser, server) as (page, log):
        names = page.eval_on_selector_all(".robot-card", "cards => cards.map(c => c.dataset.robot)")
        assert names == NAMES
        assert "token=" not in page.url  # taken into sessionStorage, out of the address bar
        assert log.websockets == [f"ws://127.0.0.1:{server.ws_port}/?token={ADMIN_TOKEN}"]
        assert card(page, "robot01")["name"] == "robot01"
        assert page.get_attribute('[data-robot="robot05"] [data-field=open]', "href") == \
            "/robots/robot05/"

        with client(robot_ws_url(server, "robot03", TOKENS["robot03"])) as student:
            student.drive(0.2)

            def robot03_driven() -> dict[str, str] | None:
                shown = card(page, "robot03")
                driven = (float(shown["speed"]) > 0
                          and shown["driver"].startswith("driving: 127.0.0.1:"))
                return shown if driven else None

            driven = wait_for(robot03_driven, timeout_s=10.0, what="robot03's card to show it")
            assert driven["speed"] == "0.20"
            assert driven["driver"].endswith(" s ago)")
            for name in NAMES:
                if name != "robot03":
                    shown = card(page, name)
                    assert (shown["speed"], shown["driver"]) == ("0.00", "driving: none"), name

        page.click('[data-robot="robot03"] [data-action=reset]')

        def robot03_back() -> bool:
            shown = card(page, "robot03")
            return shown["speed"] == "0.00" and shown["pose"] == "0.00, 0.00, 0°"

        wait_for(robot03_back, timeout_s=10.0, what="robot03's card to show the reset")
        assert card(page, "robot03")["error"] == ""
        screenshot(page, "dashboard-12.png", full_page=False)
        assert log.console_errors == [] and log.page_errors == []
        assert log.failed_requests == [], "one process answers /workers.json itself"


@needs_browser
def test_reset_all_asks_for_a_second_click_before_it_resets_every_robot(
        server: ServerProcess, browser: Any) -> None:
    with dashboard(browser, server) as (page, log):
        with client(robot_ws_url(server, "robot02", TOKENS["robot02"])) as student:
            student.drive(0.3)
            wait_for(lambda: float(card(page, "robot02")["pose"].split(",")[0]) > 0.1,
                     timeout_s=10.0, what="robot02 to drive off")
            student.drive(0.0)
        page.click("#all-reset")
        assert page.text_content("#all-reset") == f"Reset all {CLASS_SIZE} robots? Click again"
        page.wait_for_timeout(1000)  # the one click did nothing
        assert float(card(page, "robot02")["pose"].split(",")[0]) > 0.1
        page.click("#all-reset")
        wait_for(lambda: card(page, "robot02")["pose"] == "0.00, 0.00, 0°", timeout_s=10.0,
                 what="robot02's card to show the reset")
        assert page.text_content("#all-notice") == f"reset {CLASS_SIZE} robots"
        assert page.text_content("#all-reset") == "Reset all"
        assert log.console_errors == [] and log.page_errors == []


@needs_browser
def test_pause_all_pauses_every_robot_and_resume_all_lets_them_run(
        server: ServerProcess, browser: Any) -> None:
    with dashboard(browser, server) as (page, log):
        page.click("#all-pause")
        wait_for(lambda: server.health()["paused_robots"] == CLASS_SIZE, timeout_s=10.0,
                 what="every robot to be paused")
        wait_in_page(page, "() => [...document.querySelectorAll('[data-field=held]')]"
                     ".every((badge) => !badge.hidden && badge.textContent === 'paused')",
                     "every card's paused badge")
        assert page.text_content("#all-notice") == f"paused {CLASS_SIZE} robots"
        assert page.get_attribute('[data-robot="robot07"] [data-action=pause]',
                                  "aria-pressed") == "true"
        page.click("#all-resume")
        wait_for(lambda: server.health()["paused_robots"] == 0, timeout_s=10.0,
                 what="every robot to run again")
        wait_in_page(page, "() => [...document.querySelectorAll('[data-field=held]')]"
                     ".every((badge) => badge.hidden)", "every paused badge to go")
        assert log.console_errors == [] and log.page_errors == []


@needs_browser
def test_without_the_instructors_token_the_dashboard_asks_for_it(
        server: ServerProcess, browser: Any) -> None:
    with dashboard(browser, server, token=None) as (page, log):
        wait_in_page(page, "() => !document.querySelector('#token-card').hidden",
                     "the token form")
        assert "needs the instructor's token" in page.text_content("#class-message")
        assert log.websockets == []  # nothing is tried without a token

        page.fill("#token-input", "not-the-token")
        page.click("#token-form button[type=submit]")
        wait_in_page(page, "() => document.querySelector('#class-message').textContent"
                     ".includes('refused this token')", "the refusal to be explained")
        message = page.text_content("#class-message")
        assert "it is not the instructor's token" in message
        assert "not-the-token" not in message
        assert page.is_visible("#token-card")

        page.fill("#token-input", ADMIN_TOKEN)
        page.click("#token-form button[type=submit]")
        wait_for_cards(page, CLASS_SIZE)
        assert page.is_hidden("#token-card") and page.is_hidden("#class-message")
        assert log.page_errors == []


ASKED_AGAIN_WITHIN_S = 1.0
"""A wrong token is asked for again this soon after it was entered."""
NO_RETRY_WATCH_S = 4.0
"""How long the page is watched for a retry after a wrong token (its retries came at 0.5,
1, 2 and 4 s, then every 5 s)."""

COUNT_SOCKETS = """window.__sockets = [];
const PageWebSocket = window.WebSocket;
window.WebSocket = class extends PageWebSocket {
    constructor(url, ...rest) {
        super(url, ...rest);
        window.__sockets.push({url: String(url).replace(/token=[^&]*/, 'token=T'),
                               atMs: performance.now()});
    }
};"""
"""An init script: every WebSocket the page makes, in ``window.__sockets`` (token elided)."""


def sockets_made(page: Any) -> list[dict[str, Any]]:
    return list(page.evaluate("() => window.__sockets"))


def wrong_token_asked(page: Any) -> None:
    """The token form is shown again, saying the server refused the token, and no more."""
    wait_in_page(page, "() => !document.querySelector('#token-card').hidden",
                 "the token form again")
    message = page.text_content("#class-message")
    assert "it is not the instructor's token" in message, message
    assert page.get_attribute("#class-message", "data-kind") == "error"
    assert page.text_content("#conn-status") == "wrong token"
    assert page.evaluate("() => document.activeElement.id") == "token-input"
    assert page.is_hidden("#token-forget"), "a refused token is not kept"


@needs_browser
def test_a_wrong_token_is_asked_for_again_at_once_and_never_retried(
        server: ServerProcess, browser: Any) -> None:
    """The root refuses a wrong token at the handshake (403), which a browser shows as a close
    1006 without a reason, as it shows a server out of reach. So the page asks its server's
    /healthz?token= whether it takes the token before a socket carries it (token_accepted)."""
    wrong = "Wrong-instructor-token-2026"
    with dashboard(browser, server, token=None, init_script=COUNT_SOCKETS) as (page, log):
        wait_in_page(page, "() => !document.querySelector('#token-card').hidden",
                     "the token form")
        page.fill("#token-input", wrong)
        entered_s = time.monotonic()
        page.click("#token-form button[type=submit]")
        wrong_token_asked(page)
        asked_s = time.monotonic() - entered_s
        assert asked_s < ASKED_AGAIN_WITHIN_S, f"asked again after {asked_s:.1f} s"
        assert wrong not in page.text_content("#class-message")
        page.wait_for_timeout(NO_RETRY_WATCH_S * 1000)
        assert sockets_made(page) == [], "a token the server refuses is never tried"

        page.fill("#token-input", ADMIN_TOKEN)
        page.click("#token-form button[type=submit]")
        wait_for_cards(page, CLASS_SIZE)
        assert page.is_hidden("#token-card") and page.is_hidden("#class-message")
        assert len(sockets_made(page)) == 1
        assert log.page_errors == []


@needs_browser
def test_a_class_restarted_with_another_token_is_asked_for_it_and_not_retried(
        browser: Any) -> None:
    """The token was right, then the server restarted with another: the page's reconnect is
    refused at the handshake; it asks the server, stops and asks for the token."""
    first = start_server(["--class", "2"])
    second = None
    try:
        with dashboard(browser, first, count=2, init_script=COUNT_SOCKETS) as (page, log):
            first.stop()
            second = start_server(["--class", "2", "--admin-token", "Another-class-token-2026"],
                                  ws_port=first.ws_port, http_port=first.http_port)
            restarted_s = time.monotonic()
            wrong_token_asked(page)
            asked_s = time.monotonic() - restarted_s
            made = len(sockets_made(page))
            page.wait_for_timeout(NO_RETRY_WATCH_S * 1000)
            assert len(sockets_made(page)) == made, "retried with a token the server refuses"
            assert asked_s < 5.0 + 2.0, f"asked {asked_s:.1f} s after the restart"  # one retry
            assert log.page_errors == []
    finally:
        first.stop()
        if second is not None:
            second.stop()


@needs_browser
def test_forty_robots_draw_at_more_than_20_fps(browser: Any) -> None:
    forty = start_server(["--class", "40"])
    try:
        with dashboard(browser, forty, count=40) as (page, log), \
                client(forty.admin_ws_url) as root:
            cmd_vel = ROBOT["topics"]["cmd_vel"]["name"]
            for i in range(1, 41):  # every robot turns on the spot: every thumbnail redraws
                root.drive(0.0, 0.5 + i / 40, topic=f"/robot{i:02d}{cmd_vel}")
            wait_in_page(page, "() => [...document.querySelectorAll('[data-field=driver]')]"
                         ".every((line) => line.dataset.kind !== 'none')",
                         "every card to name its driver (the instructor)", timeout_s=15.0)
            fps = page.evaluate(FRAME_RATE, 2000)
            screenshot(page, "dashboard.png", full_page=False)  # what 1280 x 800 shows
            assert fps > MIN_FPS, f"{fps:.1f} frames per second with 40 robots"
            assert log.console_errors == [] and log.page_errors == []
    finally:
        forty.stop()


@needs_browser
def test_a_cards_token_button_shows_that_robots_token_on_request(
        server: ServerProcess, browser: Any) -> None:
    """The instructor hands a robot's token to its student from the dashboard (issue 20 §4)."""
    with dashboard(browser, server) as (page, log):
        assert TOKENS["robot04"] not in page.content(), "tokens are shown only on request"
        shown: list[tuple[str, str]] = []

        def answer(dialog: Any) -> None:  # a prompt blocks the page until it is answered
            shown.append((dialog.message, dialog.default_value))
            dialog.dismiss()

        page.on("dialog", answer)
        page.click('[data-robot="robot04"] [data-action="token"]')
        page.wait_for_function("true")  # let the call's answer and its dialog arrive
        for _ in range(100):
            if shown:
                break
            page.wait_for_timeout(100)
        assert shown, "no token box"
        message, token = shown[0]
        assert token == TOKENS["robot04"]
        assert message.startswith("robot04's token, for its student only")
        assert log.page_errors == []


BUTTONS_CUT = """() => {
    const cut = [];
    for (const button of document.querySelectorAll('.robot-actions button')) {
        const card = button.closest('.robot-card').getBoundingClientRect();
        const box = button.getBoundingClientRect();
        if (button.scrollWidth > button.clientWidth || box.left < card.left - 0.5
                || box.right > card.right + 0.5) {
            cut.push(`${button.closest('[data-robot]').dataset.robot}: ${button.textContent}`);
        }
    }
    return cut;
}"""
"""Every card button whose label does not fit it, or that sticks out of its card."""


@needs_browser
@pytest.mark.parametrize("viewport", [{"width": 1280, "height": 800},
                                      {"width": 1366, "height": 768}],
                         ids=["1280x800", "1366x768"])
def test_every_cards_buttons_show_their_whole_labels_on_a_laptop(
        server: ServerProcess, browser: Any, viewport: dict[str, int]) -> None:
    """At 1280 px the labels were cut to "R..." and "Pa...": Reset and Pause looked alike."""
    with dashboard(browser, server, viewport=viewport) as (page, log):
        assert page.evaluate(BUTTONS_CUT) == []
        labels = page.eval_on_selector_all('[data-robot="robot01"] .robot-actions button',
                                           "buttons => buttons.map(b => b.textContent)")
        assert labels == ["Reset", "Pause", "Dynamic", "Payload ×2", "Token"]
        width = page.evaluate("() => document.documentElement.scrollWidth")
        assert width <= viewport["width"], "no sideways scrolling"
        screenshot(page, f"dashboard-{viewport['width']}x{viewport['height']}.png",
                   full_page=False)
        assert log.console_errors == [] and log.page_errors == []


@needs_browser
def test_a_students_own_page_counts_as_a_student_not_as_an_admin(
        server: ServerProcess, browser: Any) -> None:
    """The dashboard counted the student's own page (the robot's token) as an admin."""
    with dashboard(browser, server) as (page, log):
        assert card(page, "robot04")["clients"] == "0", "the dashboard is not a student"
        with client(robot_ws_url(server, "robot04", TOKENS["robot04"])), \
                client(robot_ws_url(server, "robot04")):
            wait_for(lambda: card(page, "robot04")["clients"] == "2 (owner)", timeout_s=10.0,
                     what="robot04's card to count its owner and a watcher")
        assert log.console_errors == [] and log.page_errors == []


@needs_browser
def test_a_recording_that_stops_is_said_on_its_robots_card(
        tmp_path: Path, browser: Any) -> None:
    """A bag at its size limit stopped with a log line only: the dashboard says so too."""
    server = start_server(["--class", "2", "--record", str(tmp_path / "bags"),
                           "--record-max-mb", "0.01"])
    try:
        with dashboard(browser, server, count=2) as (page, log):
            wait_in_page(page, """() => [...document.querySelectorAll(
                    '[data-field=recording]')].every((line) => !line.hidden
                    && line.textContent.startsWith('recording stopped: it reached its size'))""",
                         "both cards to say their recording stopped", timeout_s=30.0)
            assert log.console_errors == [] and log.page_errors == []
    finally:
        server.stop()
    assert "recording of robot01 stopped: it reached its size limit" in "".join(server.output)
