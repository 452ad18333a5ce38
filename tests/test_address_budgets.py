"""Budgets per person, not per connection (issue 20, section 3), against a real ``websim serve``.

The attacker's sockets are bound to 127.0.0.2 before connecting, the healthy clients' to
127.0.0.1: the server sees two machines. Each attack must leave the healthy clients at their
rate (or let them in) and give the attacker a clear refusal (an HTTP status and a reason).
Behind a proxy, the client is who the proxy says only when the proxy is trusted
(``--trusted-proxy``).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import Iterator
from typing import Any

import pytest
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from rosbridge.core.limits import AddressBudgets, ClientLimits, TrustedProxies

from server_process import ADMIN_TOKEN, ServerProcess, start_server
from ws_clients import OdomListener

ATTACKER = "127.0.0.2"
HEALTHY = "127.0.0.1"
TWIST = {"linear": {"x": 0.1, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}


async def open_from(url: str, source: str, headers: dict[str, str] | None = None
                    ) -> ClientConnection | tuple[int, str]:
    """A WebSocket from ``source``, or the (status, body) it was refused with."""
    try:
        return await connect(url, local_addr=(source, 0), additional_headers=headers,
                             open_timeout=10, ping_interval=None)
    except InvalidStatus as refused:
        return refused.response.status_code, refused.response.body.decode().strip()


async def close_all(connections: list[Any]) -> None:
    async def close(connection: ClientConnection) -> None:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(connection.close(), 2)
    await asyncio.gather(*(close(c) for c in connections if isinstance(c, ClientConnection)))


@pytest.fixture(scope="module")
def server() -> Iterator[ServerProcess]:
    running = start_server(["--class", "6", "--max-connections-per-address", "100",
                            "--max-rate-per-address", "600"])
    yield running
    running.stop()


def robot_url(server: ServerProcess, name: str) -> str:
    return f"ws://127.0.0.1:{server.ws_port}/robots/{name}"


def test_idle_sockets_of_one_address_leave_room_for_the_robots_owner(
        server: ServerProcess) -> None:
    """More sockets from one address than it may hold on a robot: the rest get 429 with the
    reason, and the owner, from another address, connects and gets /odom."""
    per_robot = ClientLimits().address_max_robot_connections

    async def attack() -> None:
        url = robot_url(server, "robot02")
        attempts: list[Any] = []
        for _ in range(2):  # 35 at a time
            attempts += await asyncio.gather(*(open_from(url, ATTACKER) for _ in range(35)))
        try:
            admitted = [a for a in attempts if isinstance(a, ClientConnection)]
            refused = {a for a in attempts if isinstance(a, tuple)}
            assert len(admitted) == per_robot
            assert refused == {(429, f"at most {per_robot} connections from one address to "
                                     "one robot")}
            async with OdomListener(url) as owner:
                await asyncio.sleep(1.0)
                assert len(owner.stamps_s) >= 10
            # the address's cap on the whole server: 100 with this server's flag
            more = list(await asyncio.gather(*(open_from(robot_url(server, "robot03"),
                                                         ATTACKER) for _ in range(40))))
            attempts += more
            assert sum(isinstance(a, ClientConnection) for a in more) == 100 - per_robot
            assert {a for a in more if isinstance(a, tuple)} == {
                (429, "at most 100 connections from one address (websim serve "
                      "--max-connections-per-address raises it)")}
        finally:
            await close_all(attempts)
    asyncio.run(attack())


def test_a_flood_from_one_address_leaves_other_robots_at_their_rate(
        server: ServerProcess) -> None:
    """30 connections of one address, each within its own rate, share the address's budget:
    their frames wait (nobody is closed), and the other robots' clients keep 20 Hz."""
    async def attack() -> None:
        frame = json.dumps({"op": "publish", "topic": "/cmd_vel", "msg": TWIST})
        flooders = [await open_from(robot_url(server, "robot01"), ATTACKER) for _ in range(30)]
        assert all(isinstance(f, ClientConnection) for f in flooders)
        closed: list[str] = []

        async def flood(connection: ClientConnection) -> None:
            try:
                while True:
                    await connection.send(frame)
                    await asyncio.sleep(1 / 150)
            except ConnectionClosed as error:
                closed.append(str(error))

        async def drain(connection: ClientConnection) -> None:
            with contextlib.suppress(ConnectionClosed):
                async for _ in connection:
                    pass

        listeners = [OdomListener(robot_url(server, f"robot0{k}")) for k in (4, 5, 6)]
        for listener in listeners:
            await listener.__aenter__()
        tasks = [asyncio.create_task(flood(f)) for f in flooders if isinstance(f, ClientConnection)]
        tasks += [asyncio.create_task(drain(f)) for f in flooders
                  if isinstance(f, ClientConnection)]
        try:
            await asyncio.sleep(1.0)
            marks = [listener.mark() for listener in listeners]
            await asyncio.sleep(4.0)
            for listener, mark in zip(listeners, marks, strict=True):
                rate_hz, gap_s = listener.rate_since(mark)
                assert gap_s < 0.5, f"a healthy client waited {gap_s:.2f} s"
                assert rate_hz >= 19.0, f"a healthy client at {rate_hz:.1f} Hz"
            assert not closed, closed
        finally:
            for task in tasks:
                task.cancel()
            for listener in listeners:
                await listener.__aexit__(None, None, None)
            await close_all(flooders)
    asyncio.run(attack())


def test_an_open_class_enrols_a_bounded_number_of_names_per_address() -> None:
    """One address enrolling names as fast as it can gets 429 after its budget; another
    address still enrols; a refused handshake (another site's Origin) enrols nothing."""
    running = start_server(["--class", "1", "--open-class", "--max-robots", "200"])
    try:
        async def enrol() -> None:
            base = f"ws://127.0.0.1:{running.ws_port}/robots/"
            results = []
            limits = ClientLimits()
            started_s = time.monotonic()
            for k in range(limits.address_enrolments + 3):
                result = await open_from(f"{base}name{k:03d}", ATTACKER)
                results.append(result)
                await close_all([result])
            refilled = int((time.monotonic() - started_s) * limits.address_enrolments_per_s)
            statuses = [r[0] if isinstance(r, tuple) else 101 for r in results]
            # the budget, and what refilled meanwhile (a loaded machine enrols slowly)
            assert limits.address_enrolments <= statuses.count(101) <= \
                limits.address_enrolments + refilled
            assert statuses[-1] == 429 and "too many new robots" in str(results[-1])
            mine = await open_from(f"{base}healthyname", HEALTHY)
            assert isinstance(mine, ClientConnection)
            await close_all([mine])
            count = running.health()["robot_count"]
            other_site = await open_from(f"{base}decoyname", HEALTHY,
                                         {"Origin": "http://evil.example"})
            assert isinstance(other_site, tuple) and other_site[0] == 403
            assert running.health()["robot_count"] == count
            assert "decoyname" not in running.health()["robots"]
        asyncio.run(enrol())
    finally:
        running.stop()


def test_behind_a_trusted_proxy_the_forwarded_address_is_the_client() -> None:
    """From a trusted proxy, X-Real-IP names the client (each student their own budget);
    from anyone else the header is ignored (a client cannot pose as many)."""
    running = start_server(["--class", "2", "--trusted-proxy", f"{ATTACKER}/32",
                            "--max-connections-per-address", "2"])
    try:
        async def connect_as() -> None:
            url = f"ws://127.0.0.1:{running.ws_port}/robots/robot01"
            opened = []
            for forwarded in ("10.1.0.1", "10.1.0.1", "10.1.0.2", "10.1.0.2"):
                opened.append(await open_from(url, ATTACKER, {"X-Real-IP": forwarded}))
            assert all(isinstance(o, ClientConnection) for o in opened)
            third = await open_from(url, ATTACKER, {"X-Real-IP": "10.1.0.1"})
            assert isinstance(third, tuple) and third[0] == 429
            # not a proxy: its header is its own claim, and it is one address
            spoofed = [await open_from(url, HEALTHY, {"X-Real-IP": f"10.2.0.{k}"})
                       for k in range(3)]
            assert [isinstance(s, ClientConnection) for s in spoofed] == [True, True, False]
            await close_all(opened + spoofed)
        asyncio.run(connect_as())
    finally:
        running.stop()


def test_trusted_proxies_read_the_forwarded_headers_only_from_proxies() -> None:
    proxies = TrustedProxies.parse(["10.0.0.0/24", "::1"])
    assert proxies.client("10.0.0.5", "192.0.2.7", None) == "192.0.2.7"
    assert proxies.client("10.0.0.5", None, "6.6.6.6, 192.0.2.8, 10.0.0.9") == "192.0.2.8"
    assert proxies.client("192.0.2.1", "6.6.6.6", "6.6.6.6") == "192.0.2.1"
    assert proxies.client("10.0.0.5", "not an address", None) == "10.0.0.5"
    assert TrustedProxies().client("10.0.0.5", "192.0.2.7", None) == "10.0.0.5"
    with pytest.raises(ValueError):
        TrustedProxies.parse(["nginx.local"])


def test_address_budgets_count_connections_and_forget_idle_addresses() -> None:
    now = [0.0]
    limits = ClientLimits(address_max_connections=2, address_max_robot_connections=1,
                          max_connections=3)
    budgets = AddressBudgets(limits, lambda: now[0])
    assert budgets.refusal("a", "r1") is None
    budgets.opened("a", "r1")
    assert budgets.refusal("a", "r1") == (429, "at most 1 connections from one address to "
                                               "one robot")
    budgets.opened("a", "r2")
    status, reason = budgets.refusal("a", "r3") or (0, "")
    assert status == 429 and "--max-connections-per-address" in reason
    budgets.opened("b", "r1")
    assert budgets.refusal("c", "r1") == (503, "this server holds at most 3 connections at "
                                               "once; try again later")
    for address, robot in (("a", "r1"), ("a", "r2"), ("b", "r1")):
        budgets.closed(address, robot)
    assert budgets.connections == 0
    budget = budgets.of("a")
    budget.charge(1 << 20, 0.0)
    assert budget.wait_s() == 0.0  # within the byte burst
    for _ in range(int(limits.address_max_rate) + 10):
        budget.charge(10, 0.0)
    assert budget.wait_s() > 0.0 and not budget.idle()
    now[0] += 60.0
    assert budget.idle()


def test_an_ipv6_64_is_one_address() -> None:
    """A machine or a home gets a whole /64: its addresses share one budget."""
    budgets = AddressBudgets(ClientLimits(address_max_connections=1))
    budgets.opened("2001:db8:0:1::5", "r1")
    assert budgets.refusal("2001:db8:0:1::6", "r2") is not None
    assert budgets.refusal("2001:db8:0:2::6", "r2") is None
    budgets.closed("2001:db8:0:1::5", "r1")
    assert budgets.refusal("2001:db8:0:1::6", "r2") is None


def test_a_class_of_40_behind_one_nat_address_gets_in_with_the_defaults() -> None:
    """40 students behind one address, each with a page, their code and a second tab and a
    spare (4 connections: 160), and the instructor's root view from the same address: all
    admitted at the default per-address limits."""
    running = start_server(["--class", "40"])
    try:
        async def classroom() -> None:
            opened: list[Any] = []
            try:
                for k in range(1, 41):
                    url = f"ws://127.0.0.1:{running.ws_port}/robots/robot{k:02d}"
                    opened += await asyncio.gather(*(open_from(url, ATTACKER)
                                                     for _ in range(4)))
                refused = [o for o in opened if not isinstance(o, ClientConnection)]
                assert refused == []
                root = await open_from(f"ws://127.0.0.1:{running.ws_port}/?token="
                                       f"{ADMIN_TOKEN}", ATTACKER)
                opened.append(root)
                assert isinstance(root, ClientConnection)
                assert running.health()["clients"] >= 160
            finally:
                await close_all(opened)
        asyncio.run(classroom())
    finally:
        running.stop()


SHARE = "0.002"


def test_a_crowd_from_many_addresses_on_one_robot_shares_that_robots_budget() -> None:
    """Eight connections from four addresses publish on one robot, each address far within
    its own budgets (150 messages/s of its 2000, a few % of a core of its 25 %). With the
    robot's budget set small (``--handling-share-per-robot``), only it can hold them back:
    far fewer of their messages reach the robot's watcher than they send, nobody is closed,
    and another robot's client keeps 20 Hz."""
    running = start_server(["--class", "3", "--handling-share-per-robot", SHARE])
    frame = json.dumps({"op": "publish", "topic": "/chatter", "msg": {"data": "hello"}})
    sources = [f"127.0.0.{k}" for k in (2, 3, 4, 5)]

    async def crowd() -> None:
        url = robot_url(running, "robot01")
        watcher = await connect(url, ping_interval=None)
        await watcher.send(json.dumps({"op": "subscribe", "topic": "/chatter",
                                       "type": "std_msgs/String", "queue_length": 100}))
        received = [0]

        async def watch() -> None:
            with contextlib.suppress(ConnectionClosed):
                async for message in watcher:
                    received[0] += json.loads(message).get("topic") == "/chatter"

        publishers = [await open_from(url, source) for source in sources for _ in range(2)]
        assert all(isinstance(p, ClientConnection) for p in publishers), publishers
        closed: list[str] = []
        sent = [0]

        async def publish(connection: ClientConnection) -> None:
            try:
                await connection.send(json.dumps({"op": "advertise", "topic": "/chatter",
                                                  "type": "std_msgs/String"}))
                while True:
                    await connection.send(frame)
                    sent[0] += 1
                    await asyncio.sleep(1 / 75)
            except ConnectionClosed as error:
                closed.append(str(error))

        tasks = [asyncio.create_task(watch())]
        tasks += [asyncio.create_task(publish(p)) for p in publishers
                  if isinstance(p, ClientConnection)]
        try:
            async with OdomListener(robot_url(running, "robot02")) as healthy:
                await asyncio.sleep(2.0)  # the robot's burst is spent
                mark, sent_then, received_then = healthy.mark(), sent[0], received[0]
                await asyncio.sleep(4.0)
                rate_hz, _ = healthy.rate_since(mark)
                sent_now, received_now = sent[0] - sent_then, received[0] - received_then
            print(f"sent {sent_now}, delivered {received_now} in 4 s; robot02 {rate_hz:.1f} Hz")
            assert sent_now > 1500, "the crowd did not send"
            assert received_now < sent_now / 2, (received_now, sent_now)
            assert received_now > 0, "the robot's clients are slowed, not stopped"
            assert rate_hz >= 19.0
            assert not closed, closed
        finally:
            for task in tasks:
                task.cancel()
            await close_all([*publishers, watcher])
    try:
        asyncio.run(crowd())
    finally:
        running.stop()
