"""``physics.raycast.cast`` compiled: the same beams, shapes and formulas, in loops numba compiles.

Optional, and asked for: ``pip install 'websim[fast]'`` (numba, about 210 MB on disk with
llvmlite; wheels for x86-64 and arm64, the Raspberry Pi 4B included), then
``WEBSIM_RAYCAST=numba`` in the environment of ``websim serve``, ``websim grade``, a benchmark.
It costs memory: numba and LLVM add about 130 MB to the process's RSS (measured: 39 MB -> 156
MB for one robot in the maze), so it is not taken just because numba is installed. It pays
where scans are most of the work: a scan in the maze 4x faster, a headless run 2.8x, an
arena's scan pass 2.4x. Compiled once per machine and kept (numba's cache, beside this file or
in ``NUMBA_CACHE_DIR``): a process loads it in about 0.3 s; the first compiles it in about 1 s.

Per laser, each wall and disc in reach gives the arc of beams that can hit it (as numpy's arc
path: ``MARGIN_BEAMS`` more on each side, a wall whose arc is ``WIDE_ARC_RAD`` wide tried on
every beam, a laser inside a disc reads 0 on every beam); each beam of the arc is intersected
with the formulas of ``physics.raycast`` and keeps its nearest hit. The loops need none of
numpy's culling (tiers of discs): a beam's test costs nanoseconds here, not a numpy call.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from physics.validation import ConfigError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

RAYCAST_ENV = "WEBSIM_RAYCAST"
"""Which cast: ``numpy`` (or unset: the path every install has) or ``numba`` (compiled; an
error where numba is not installed)."""

CHOICES = ("numpy", "numba")

Kernel = Callable[..., None]
_loaded: list[Kernel | None] = []


def kernel() -> Kernel | None:
    """The compiled cast (``_cast`` below, jitted and loaded) if asked for, else None: numpy.

    Resolved once per process, at the first LiDAR made (``physics.lidar.Lidar``), so a
    server pays the load at start and not on its first scan tick.

    Raises:
        ConfigError: ``WEBSIM_RAYCAST`` is none of ``CHOICES``, or ``numba`` without numba.
    """
    if not _loaded:
        choice = os.environ.get(RAYCAST_ENV, "").strip().lower() or "numpy"
        if choice not in CHOICES:
            raise ConfigError(f"{RAYCAST_ENV}={choice!r}: expected one of {', '.join(CHOICES)}")
        compiled = _compile() if choice == "numba" else None
        if compiled is None and choice == "numba":
            raise ConfigError(f"{RAYCAST_ENV}=numba, but numba is not installed "
                              "(pip install 'websim[fast]')")
        _loaded.append(compiled)
    return _loaded[0]


def chosen() -> str:
    """Which cast this process uses, for a benchmark's header: ``numba 0.61.0`` or ``numpy``."""
    if kernel() is None:
        return "numpy"
    import numba
    return f"numba {numba.__version__}"


def _compile() -> Kernel | None:
    """``_cast`` compiled and called once (numba compiles, or loads its cache, on a first call)."""
    try:
        import numba
    except ImportError:
        return None
    try:
        jitted: Kernel = numba.njit(cache=True, nogil=True, error_model="numpy")(_cast)
    except RuntimeError:  # no cache directory it may write: compiled in every process
        jitted = numba.njit(cache=False, nogil=True, error_model="numpy")(_cast)
    one = np.zeros((1, 2))
    jitted(np.full((1, 4), np.inf), one, np.zeros(1), np.ones(4), np.zeros(4), 0.0, 1.0, 1.0,
           one, one, one, np.ones(1), np.full(1, -1, dtype=np.intp), 1, 3.0, 1e-12)
    return jitted


def _cast(out: Any, origins: Any, headings: Any, beam_cos: Any, beam_sin: Any,
          angle_min_rad: float, increment_rad: float, range_max_m: float, wall_a: Any,
          wall_b: Any, centre: Any, radius: Any, skip: Any, margin_beams: int,
          wide_arc_rad: float, parallel_eps: float) -> None:  # pragma: no cover - compiled
    """Fill ``out`` (lasers x beams, +inf) with each beam's nearest hit; beyond range: +inf.

    ``skip[l]``: the disc laser ``l`` never sees (its own robot), or -1. The arguments are
    ``physics.raycast.cast``'s, the walls as their ends, the constants passed in so that one
    definition of each stays in ``physics.raycast``.
    """
    count = beam_cos.shape[0]
    dir_x = np.empty(count)
    dir_y = np.empty(count)
    reach_2 = range_max_m * range_max_m
    for laser in range(origins.shape[0]):
        ox = origins[laser, 0]
        oy = origins[laser, 1]
        heading = headings[laser]
        cos_t = np.cos(heading)
        sin_t = np.sin(heading)
        for beam in range(count):
            dir_x[beam] = cos_t * beam_cos[beam] - sin_t * beam_sin[beam]
            dir_y[beam] = sin_t * beam_cos[beam] + cos_t * beam_sin[beam]
        row = out[laser]
        for wall in range(wall_a.shape[0]):
            ax = wall_a[wall, 0] - ox
            ay = wall_a[wall, 1] - oy
            bx = wall_b[wall, 0] - ox
            by = wall_b[wall, 1] - oy
            ex = bx - ax
            ey = by - ay
            length_2 = max(ex * ex + ey * ey, parallel_eps)
            along = min(max(-(ax * ex + ay * ey) / length_2, 0.0), 1.0)
            near_x = ax + along * ex
            near_y = ay + along * ey
            if near_x * near_x + near_y * near_y > reach_2:
                continue  # no beam reaches it
            angle_a = np.arctan2(ay, ax)
            turn = np.arctan2(ax * by - ay * bx, ax * bx + ay * by)
            lo = (angle_a if turn >= 0.0 else angle_a + turn) - heading
            width = abs(turn)
            if width >= wide_arc_rad:
                first, span = 0, count
            else:
                first = int(np.floor((lo - angle_min_rad) / increment_rad)) - margin_beams
                span = min(int(np.ceil(width / increment_rad)) + 1 + 2 * margin_beams, count)
                first %= count
            numerator = ax * ey - ay * ex  # (a - o) x e
            for k in range(span):
                beam = (first + k) % count
                dx = dir_x[beam]
                dy = dir_y[beam]
                denom = ey * dx - ex * dy  # d x e
                if abs(denom) < parallel_eps:
                    continue  # edge-on: no surface
                if (ay * dx - ax * dy) * (by * dx - bx * dy) > 0.0:
                    continue  # both ends on one side of the ray
                t = numerator / denom
                if t >= 0.0 and t < row[beam]:
                    row[beam] = t
        for disc in range(centre.shape[0]):
            if disc == skip[laser]:
                continue
            wx = centre[disc, 0] - ox
            wy = centre[disc, 1] - oy
            r = radius[disc]
            reach = range_max_m + r
            distance_2 = wx * wx + wy * wy
            if distance_2 > reach * reach:
                continue
            outside = distance_2 - r * r
            if outside <= 0.0:  # the laser inside it: every beam reads 0
                for beam in range(count):
                    row[beam] = 0.0
                continue
            distance = np.sqrt(distance_2)
            half = np.arcsin(min(1.0, r / max(distance, 1e-300)))
            lo = np.arctan2(wy, wx) - half - heading
            first = int(np.floor((lo - angle_min_rad) / increment_rad)) - margin_beams
            span = min(int(np.ceil(2.0 * half / increment_rad)) + 1 + 2 * margin_beams, count)
            first %= count
            for k in range(span):
                beam = (first + k) % count
                along = wx * dir_x[beam] + wy * dir_y[beam]
                discriminant = along * along - outside
                if discriminant < 0.0:
                    continue
                t = along - np.sqrt(discriminant)
                if t >= 0.0 and t < row[beam]:
                    row[beam] = t
        for beam in range(count):
            if row[beam] > range_max_m:
                row[beam] = np.inf
