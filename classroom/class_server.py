"""The WebSocket front of a class: ``ws://HOST:9090/robots/NAME`` is robot NAME.

``ws://HOST:9090/`` with the instructor's token is the instructor's view of every robot, its
names under ``/NAME/`` (``instructor_view.py``). Inside a robot's URL everything is as on the
real robot (``/cmd_vel``, ``/odom``, ``/scan``, the
parameter services, ``/reset_simulation``, un-namespaced), so a student's code for their
robot works on the real robot with only the URL changed. The admin token rules every robot;
each robot's own token rules that robot only. A connection with neither may watch a robot
(subscribe, list, call read-only services) but not change it (``may_drive``), unless the
class was started with ``--open-drive``. In an open class, the first connection to a name it
enrols is handed that robot (``Classroom.claim``): its page asks ``/websim/token`` once and
keeps the token.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Callable
from typing import Any

from classroom.instructor_view import InstructorView
from classroom.registry import ROBOT_NAME, Classroom
from physics import ConfigError
from ros_nodes.robot_interface import ROBOTS_PREFIX
from rosbridge.core.limits import ClientLimits, OriginPolicy
from rosbridge.transport.connection import Hub
from rosbridge.transport.front import Destination, WebSocketFront
from rosbridge.transport.writers import Pace

ROOT_REFUSAL = ("this server hosts a class: connect to ws://HOST:PORT/robots/NAME for robot "
                "NAME (ws://HOST:PORT/ is the instructor's view of every robot: it needs "
                "the instructor's token)")

NO_NAME_REFUSAL = ("this address names no robot: a robot is at /robots/NAME, NAME as your "
                   "instructor's links give it")


def class_view_limits(limits: ClientLimits, robots: int) -> ClientLimits:
    """A client's ``limits`` sized for a view of ``robots`` robots (the instructor's).

    Per robot: 8 messages/s and 8 subscriptions more, 64 KiB more of queue; half a core of
    handling time (a second of burst). The address budgets do not apply to it.
    """
    return dataclasses.replace(
        limits, max_rate=limits.max_rate + 8.0 * robots,
        max_subscriptions=limits.max_subscriptions + 8 * robots,
        max_queued_bytes=limits.max_queued_bytes + (64 << 10) * robots,
        max_replies=limits.max_replies + 8 * robots,
        handling_share=max(limits.handling_share, 0.5),
        handling_burst_s=max(limits.handling_burst_s, 1.0))


class ClassServer(WebSocketFront):
    """Many robots behind one WebSocket port, routed by path.

    Args:
        classroom: the robots (its clock is the front's: uptime, client budgets).
        admin_token: the instructor's secret, admin on every robot.
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).
        open_drive: every connection may drive any robot (``--open-drive``), as before
            robots had owners; parameters and pausing still need a token.
    """

    def __init__(self, classroom: Classroom, admin_token: str,
                 limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None, *, open_drive: bool = False) -> None:
        super().__init__(admin_token, limits, origins, classroom.clock)
        self.classroom = classroom
        self.owns: Callable[[str], bool] | None = None
        """For a worker behind nginx: whether a name is routed to it (its own robots); the
        worker makes no other (a decoy of a classmate's robot). None: every name."""
        self.open_drive = open_drive

    def route(self, path: str) -> tuple[Destination, str | None] | str:
        """``/robots/NAME`` (a trailing slash allowed) is robot NAME; nothing else is a robot.

        Makes the robot if it is to be made (enrolled in an open class, or a worker's robot
        first routed here): called once the handshake was accepted (``find`` before).
        """
        found = self.find(path)
        if isinstance(found, str):
            return found
        _, name = found
        try:
            host = self.classroom.get(name or "")
        except ConfigError as error:  # a robot that cannot be made (no room in an arena)
            return str(error)
        if host is None:
            return self.why_unknown(name or "")
        return Destination(host.bridge, self.classroom.pace(name or "")), name

    def find(self, path: str) -> tuple[Destination | None, str | None] | str:
        """Robot NAME of ``/robots/NAME``, made by nobody.

        Returns:
            (host, name), host None for a robot ``route`` would make; or why there is none.
        """
        if not path.startswith(ROBOTS_PREFIX):
            return ROOT_REFUSAL
        name = path[len(ROBOTS_PREFIX):].rstrip("/")
        host = self._hosted(name)
        if host is not None:
            return host, name
        if not self.classroom.knows(name):
            return self.why_unknown(name)
        if self.owns is not None and not self.owns(name):
            return (f"robot '{name[:40]}' is not this worker's: the proxy routes it to "
                    "another (ws://HOST:PORT/robots/NAME)")
        if name not in self.classroom.students and \
                len(self.classroom) >= self.classroom.max_robots:
            return self.why_unknown(name)
        return None, name

    def _hosted(self, name: str) -> Destination | None:
        for hosted, host in self.classroom:
            if hosted == name:
                return Destination(host.bridge, self.classroom.pace(name))
        return None

    def why_unknown(self, name: str) -> str:
        """Why there is no robot ``name``, as a student is told.

        None named, an invalid name, a full class, an unknown one. Never the names close to
        theirs: those are classmates' (``log_hint``: the instructor's log has them).
        """
        if not name:
            return NO_NAME_REFUSAL
        if not ROBOT_NAME.fullmatch(name):
            return (f"'{name[:40]}' is not a robot name (1 to 32 of a-z, 0-9, _ and -); "
                    "your instructor's links give your robot's")
        if self.classroom.open_class and len(self.classroom) >= self.classroom.max_robots:
            return f"the class is full ({self.classroom.max_robots} robots)"
        return (f"no robot named '{name[:40]}' in this class; your instructor's links give "
                "your robot's name")

    def log_hint(self, path: str) -> str:
        """For the instructor's log: the names close to a refused ``/robots/NAME``'s.

        The closest names, case aside first (``Alice``: ``alice``); empty when none is.
        """
        if not path.startswith(ROBOTS_PREFIX):
            return ""
        name = path[len(ROBOTS_PREFIX):].rstrip("/")
        names = list(self.classroom.students) + [hosted for hosted, _ in self.classroom]
        close = closest_names(name, names) if name else []
        return f" (names close to it: {', '.join(close)})" if close else ""

    def admit(self, name: str | None, address: str) -> tuple[int, str] | None:
        """A new name in an open class spends one of its address's enrolments.

        Past ``address_enrolments`` it is refused (HTTP 429); a roster's robot made on first
        use spends none.
        """
        if name is None or name in self.classroom.students:
            return None
        if not self.addresses.of(address).enrol():
            return 429, (f"too many new robots from one address (at most "
                         f"{self.limits.address_enrolments}, then "
                         f"{self.limits.address_enrolments_per_s:g}/s); try again later")
        return None

    def root_limits(self) -> ClientLimits:
        """The instructor's root view: one client for the whole class, sized for it.

        Its message rate, subscriptions, handling time and queue scale with the class's
        robots (the dashboard subscribes to three topics per robot at once), so it is never
        throttled as a student is.
        """
        return class_view_limits(self.limits, max(len(self.classroom),
                                                  self.classroom.max_robots))

    def root_view(self, path: str, token: str | None) -> tuple[Hub, Pace] | None:
        """The instructor's view of every robot, at ``/`` with the instructor's token.

        Its pace is the class's shared one: above real time no robot waits for it (a view of
        the whole class that cannot keep up gets the newest of each topic).
        """
        if path.startswith(ROBOTS_PREFIX) or not self.is_admin_token(token):
            return None
        return InstructorView(self.classroom), self.classroom.driver.shared

    def wrong_root_token(self, path: str, token: str | None) -> str | None:
        """A token at the instructor's root that is not the instructor's: 403, not 404."""
        if token and not path.startswith(ROBOTS_PREFIX):
            return ("wrong instructor token: ws://HOST:PORT/ is the instructor's view of "
                    "every robot: it needs the instructor's token (websim serve's "
                    "--admin-token; its banner prints the dashboard's link)")
        return None

    def robot_admin(self, name: str | None, token: str | None) -> bool:
        """A robot's own token is admin on that robot.

        So is the first connection to a name an open class enrolled (it is handed the
        token: ``/websim/token``).
        """
        return name is not None and (self.classroom.is_robot_token(name, token)
                                     or self.classroom.claim(name))

    def may_drive(self, name: str | None, is_admin: bool) -> bool:
        """Only the robot's owner (its token) and the instructor change it (or all: open_drive)."""
        return self.open_drive or is_admin

    async def run_ticks(self) -> None:
        """Tick every robot forever."""
        await self.classroom.run_ticks()

    def health(self, full: bool = True) -> dict[str, Any]:
        """The class: totals, and each robot's own report under ``robots``.

        ``full`` False (public, without the instructor's token): counts only, no robot's
        name (``robots`` and ``degraded_robots`` left out).
        """
        driver = self.classroom.driver
        robots = {name: host.health(driver.report(self.classroom.world(name)))
                  for name, host in self.classroom}
        degraded = [name for name, report in robots.items() if report["status"] != "ok"]
        report = {
            "status": "degraded" if degraded else "ok",
            "degraded_robots": degraded,
            "degraded_count": len(degraded),
            "uptime_s": self._uptime_s(),
            "ticks_due": max((report["ticks_due"] for report in robots.values()),
                             default=driver.shared.ticks_due()),
            "robot_count": len(robots),
            "paused_robots": sum(1 for report in robots.values() if report["paused"]),
            "clients": sum(report["clients"] for report in robots.values()),
            "queued_bytes": sum(report["queued_bytes"] for report in robots.values()),
            "tick_jitter_p99_ms": max((report["tick_jitter_p99_ms"]
                                       for report in robots.values()), default=0.0),
            "tick_delivery_p99_ms": max((report["tick_delivery_p99_ms"]
                                         for report in robots.values()), default=0.0),
            "robots": robots,
        }
        if not full:
            del report["robots"], report["degraded_robots"]
        return report


def closest_names(name: str, names: list[str], most: int = 3) -> list[str]:
    """The robot names ``name`` was likely meant to be, at most ``most``.

    The same name but for case first, then the closest by spelling (``difflib``).
    """
    lowered = name.lower()
    same_case_aside = [known for known in names if known == lowered]
    near = difflib.get_close_matches(lowered, names, n=most, cutoff=0.6)
    return list(dict.fromkeys(same_case_aside + near))[:most]
