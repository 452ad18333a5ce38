"""One pace per robot: above real time a class's robot waits only for its own clients.

A real ``websim serve --class 2 --speed 20``: robot02 is driven by a client reading every
/odom, robot01 is watched by six tokenless clients that read in bursts (a second and a half
without reading, then all at once: phones on a busy Wi-Fi). Each robot lives in a world of
its own with its own pace: robot01 waits for its watchers (it loses none of their messages),
robot02 never does. Ticks per wall second are read from ``/healthz`` (each robot's tick count)
and compared in the same run, so the verdict does not hang on the machine's load.
"""

from __future__ import annotations

import asyncio
import json
import threading
import time
from typing import Any

import pytest

from server_process import ServerProcess, start_server, wait_for
from ws_clients import NonReader

WATCHERS = 6
READ_S = 0.2
"""How long a bursty watcher reads, all it can, ..."""
PAUSE_S = 1.5
"""... then how long it reads nothing (under the server's 2 s release: never released)."""
SAMPLE_S = 0.25
MEASURE_S = 8.0


def ticks(server: ServerProcess) -> tuple[float, int, int]:
    robots = server.health()["robots"]
    return time.monotonic(), robots["robot01"]["ticks"], robots["robot02"]["ticks"]


def per_second(samples: list[tuple[float, int, int]], robot: int) -> list[float]:
    """Ticks per wall second of robot (1 or 2) over each whole second of the samples."""
    rates = []
    start = 0
    for end in range(1, len(samples)):
        if samples[end][0] - samples[start][0] >= 1.0:
            rates.append((samples[end][robot] - samples[start][robot])
                         / (samples[end][0] - samples[start][0]))
            start = end
    return rates


def sample(server: ServerProcess, seconds: float) -> list[tuple[float, int, int]]:
    samples = [ticks(server)]
    while samples[-1][0] - samples[0][0] < seconds:
        time.sleep(SAMPLE_S)
        samples.append(ticks(server))
    return samples


def rate(samples: list[tuple[float, int, int]], robot: int) -> float:
    return (samples[-1][robot] - samples[0][robot]) / (samples[-1][0] - samples[0][0])


class Driver:
    """robot02's student: reads every /odom as it comes (a PID closing its loop)."""

    def __init__(self, server: ServerProcess) -> None:
        self.received = 0
        self._stop = asyncio.Event()
        self._thread = threading.Thread(target=asyncio.run, args=(self._run(server),),
                                        daemon=True)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread.start()

    async def _run(self, server: ServerProcess) -> None:
        from websockets.asyncio.client import connect

        self._loop = asyncio.get_running_loop()
        async with connect(f"{server.ws_url}robots/robot02", max_size=None) as ws:
            await ws.send(json.dumps({"op": "subscribe", "topic": "/odom",
                                      "queue_length": 100}))
            reading = asyncio.create_task(self._read(ws))
            await self._stop.wait()
            reading.cancel()

    async def _read(self, ws: Any) -> None:
        async for _ in ws:
            self.received += 1

    def stop(self) -> None:
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(5.0)


class BurstyWatchers:
    """robot01's watchers: no token, every topic, reading only now and then."""

    def __init__(self, server: ServerProcess) -> None:
        self.readers = [NonReader(server.ws_port, path="/robots/robot01")
                        for _ in range(WATCHERS)]
        for reader in self.readers:
            for topic in ("/odom", "/scan", "/tf", "/ground_truth", "/clock"):
                reader.send({"op": "subscribe", "topic": topic, "queue_length": 100})
        self.read_bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            until = time.monotonic() + READ_S
            while time.monotonic() < until and not self._stop.is_set():
                for reader in self.readers:
                    self.read_bytes += reader.read_available()
                time.sleep(0.005)
            self._stop.wait(PAUSE_S)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        for reader in self.readers:
            reader.close()


@pytest.mark.slow
def test_a_slow_watcher_of_one_robot_does_not_slow_another_in_a_class_at_speed() -> None:
    server = start_server(["--class", "2", "--speed", "20"])
    driver = watchers = None
    try:
        driver = Driver(server)
        wait_for(lambda: driver.received > 50, 20.0, "robot02's /odom")
        alone = sample(server, 3.0)  # robot02 with its driver; robot01 idle, nobody there
        watchers = BurstyWatchers(server)
        wait_for(lambda: watchers.read_bytes > 0, 20.0, "robot01's watchers to read")
        watched = sample(server, MEASURE_S)
        health = server.health()["robots"]
    finally:
        if watchers is not None:
            watchers.stop()
        if driver is not None:
            driver.stop()
        server.stop()
    b_alone, b_watched, a_watched = rate(alone, 2), rate(watched, 2), rate(watched, 1)
    b_seconds = per_second(watched, 2)
    figures = (f"robot02 alone {b_alone:.0f}/s, while robot01 is watched {b_watched:.0f}/s "
               f"(worst second {min(b_seconds):.0f}); robot01 {a_watched:.0f}/s")
    print(figures)
    assert b_watched >= 0.5 * b_alone, figures
    assert min(b_seconds) > 0.2 * b_alone, figures
    # robot01 keeps its watchers' pace: they hold it, lossless, and never robot02
    assert a_watched < 0.5 * b_watched, figures
    assert health["robot01"]["clients_released"] == 0, "the watchers were waited for"
    assert health["robot02"]["clients_released"] == 0
