"""Many LiDARs' beams against walls and discs at once: only the beams that can hit a shape.

Every laser at a tick casts ``n`` beams, beam ``i`` at ``angle_min + i * increment`` (a full
turn). A wall (a segment) or a disc seen from a laser covers an arc of directions: only the
beams in that arc can hit it. So, for every laser and every shape within ``range_max``, this
finds the arc, takes the beams in it (one more on each side, so rounding never drops a beam
that touches), and intersects exactly those (laser, beam, shape) triples with the same
formulas as the one-shape-at-a-time path, in numpy; each beam keeps its nearest hit. For a
maze seen from a robot that is a few hundred triples instead of ``n`` times every wall, and
the other robots of a crowded world add a few beams each, not ``n``.

Formulas, with o the laser, d a beam's direction:

* wall a..b, e = b - a: t = ((a - o) x e) / (d x e), a hit if t >= 0, |d x e| is not ~0 (a
  wall seen edge-on shows no surface, as pymunk says) and a, b lie on either side of the ray
  (d x (a - o) and d x (b - o) of opposite signs, or zero);
* disc of centre c and radius r, w = c - o: along = w . d, outside = |w|^2 - r^2,
  t = along - sqrt(along^2 - outside); a laser inside a disc reads 0 (as pymunk).

All arrays are float64; angles are radians, distances metres, in the ``map`` frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from physics import raycast_kernel

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

PARALLEL_EPS = 1e-12
"""|d x e| below this counts as parallel: pymunk reports no hit for a zero-thickness wall seen
edge-on, and so does this path."""

MARGIN_BEAMS = 1
"""Beams added on each side of a shape's arc: the arc's ends are rounded twice (atan2, the
division by the increment), so a beam just touching a shape's edge is still tried."""

DENSE_MAX_PAIRS = 64
"""Up to this many (laser, shape) pairs every beam is tried on every shape (``_dense``);
beyond, only the beams of each shape's arc (fewer numpy calls against fewer products)."""

CULL_MIN_DEPTH = 2.0
"""Where the discs' arcs cover every laser's turn more than this many times over on average
(a crowd: each beam crosses several discs), they are cast nearest first and a disc hidden
behind nearer hits is left out (``_discs``); where they cover less (robots scattered over a
large floor), hardly any is hidden and casting every (laser, beam, disc) triple is cheaper
than the bookkeeping."""

NEAR_DISCS = (4, 12)
"""The tiers of each laser's discs by nearness: its 4 nearest are cast, then of its next 8 the
ones not hidden behind what those hit, then of the rest the ones still not hidden."""

WIDE_ARC_RAD = math.pi - 1e-6
"""A wall whose arc is this wide (the laser on its line, between its ends) is tried on every
beam: which half of the turn it covers is not decidable from its ends' directions."""


@dataclass(frozen=True)
class Walls:
    """A world's walls, with what every cast of them needs made once.

    Attributes:
        a: each wall's first end, (W, 2) (m).
        b: each wall's second end, (W, 2) (m).
        edge: b - a, (W, 2) (m).
        rows: per wall (e_y, -e_x), then (a_y, -a_x), then (b_y, -b_x): (3W, 2); the laser's
            position moves the last two (``moves``), so the three cross products of a beam
            with them are one matrix product.
        moves: which rows move with the laser, (3W, 1): 0 for the edges, 1 for the ends.
        a_cross_e: a x e per wall, (W, 1).
    """

    a: FloatArray
    b: FloatArray
    edge: FloatArray
    rows: FloatArray
    moves: FloatArray
    a_cross_e: FloatArray

    @classmethod
    def of(cls, a: FloatArray, b: FloatArray) -> Walls:
        """The walls from ``a[i]`` to ``b[i]``."""
        a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 2)
        b = np.ascontiguousarray(b, dtype=np.float64).reshape(-1, 2)
        e = b - a
        rows = np.concatenate([np.stack((e[:, 1], -e[:, 0]), axis=1),
                               np.stack((a[:, 1], -a[:, 0]), axis=1),
                               np.stack((b[:, 1], -b[:, 0]), axis=1)]).reshape(-1, 2)
        moves = np.concatenate([np.zeros((len(a), 1)), np.ones((2 * len(a), 1))])
        return cls(a, b, e, rows, moves, (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0])[:, None])

    def __len__(self) -> int:
        return len(self.a)


def _arc_beams(lo_rad: FloatArray, width_rad: FloatArray, angle_min_rad: float,
               increment_rad: float, count: int) -> tuple[IntArray, IntArray]:
    """The first beam index (mod ``count``) and the number of beams of each arc.

    An arc starts at ``lo_rad`` (laser frame) and spans ``width_rad`` counter-clockwise.
    """
    first = np.floor((lo_rad - angle_min_rad) / increment_rad).astype(np.intp) - MARGIN_BEAMS
    spans = np.ceil(width_rad / increment_rad).astype(np.intp) + 1 + 2 * MARGIN_BEAMS
    return np.mod(first, count), np.minimum(spans, count)


def _expand(first: IntArray, spans: IntArray, count: int) -> tuple[IntArray, IntArray]:
    """For arcs of ``spans`` beams from ``first``: (the arc of each entry, its beam index)."""
    total = int(spans.sum())
    arc = np.repeat(np.arange(len(spans), dtype=np.intp), spans)
    starts = np.cumsum(spans) - spans
    offset = np.arange(total, dtype=np.intp) - np.repeat(starts, spans)
    return arc, np.mod(np.repeat(first, spans) + offset, count)


def cast(origins: FloatArray, headings: FloatArray, beam_cos: FloatArray, beam_sin: FloatArray,
         angle_min_rad: float, increment_rad: float, range_max_m: float,
         walls: Walls, disc_centre: FloatArray, disc_radius: FloatArray,
         disc_skip: IntArray | None = None) -> FloatArray:
    """The distance to the first shape along every beam of every laser, +inf if none.

    Args:
        origins: the lasers' positions, (S, 2) (m, map frame).
        headings: the lasers' yaws, (S,) (rad).
        beam_cos: cos of each beam's angle in the laser frame, (n,).
        beam_sin: sin of the same, (n,).
        angle_min_rad: the first beam's angle (rad); beams are ``increment_rad`` apart and
            ``n * increment_rad`` is a full turn.
        increment_rad: the angle between neighbouring beams (rad).
        range_max_m: farther hits read +inf (m).
        walls: the world's walls (``Walls``).
        disc_centre: each disc's centre, (K, 2) (m): obstacles and other robots.
        disc_radius: each disc's radius, (K,) (m).
        disc_skip: for each laser, the disc it never sees (its own robot's footprint), or -1;
            None: none.

    Returns:
        (S, n) distances (m).
    """
    count = len(beam_cos)
    lasers = len(origins)
    compiled = raycast_kernel.kernel()
    if compiled is not None and lasers:
        out = np.full((lasers, count), np.inf)
        skip = np.full(lasers, -1, dtype=np.intp) if disc_skip is None else disc_skip
        compiled(out, np.ascontiguousarray(origins, dtype=np.float64),
                 np.ascontiguousarray(headings, dtype=np.float64),
                 np.ascontiguousarray(beam_cos, dtype=np.float64),
                 np.ascontiguousarray(beam_sin, dtype=np.float64),
                 float(angle_min_rad), float(increment_rad), float(range_max_m), walls.a,
                 walls.b, np.ascontiguousarray(disc_centre, dtype=np.float64).reshape(-1, 2),
                 np.ascontiguousarray(disc_radius, dtype=np.float64),
                 np.ascontiguousarray(skip, dtype=np.intp), MARGIN_BEAMS, WIDE_ARC_RAD,
                 PARALLEL_EPS)
        return out
    ranges = np.full(lasers * count, np.inf)
    if lasers == 0:
        return ranges.reshape(0, count)
    cos_t = np.cos(headings)
    sin_t = np.sin(headings)
    if lasers * (len(walls) + len(disc_radius)) <= DENSE_MAX_PAIRS:
        _dense(ranges.reshape(lasers, count), origins, cos_t, sin_t, beam_cos, beam_sin,
               walls, disc_centre, disc_radius, disc_skip)
    else:
        if len(walls):
            _walls(ranges, origins, cos_t, sin_t, headings, beam_cos, beam_sin, angle_min_rad,
                   increment_rad, range_max_m, walls.a, walls.b)
        if len(disc_radius):
            _discs(ranges, origins, cos_t, sin_t, headings, beam_cos, beam_sin, angle_min_rad,
                   increment_rad, range_max_m, disc_centre, disc_radius, disc_skip)
    ranges[ranges > range_max_m] = np.inf
    return ranges.reshape(lasers, count)


def _dense(ranges: FloatArray, origins: FloatArray, cos_t: FloatArray, sin_t: FloatArray,
           beam_cos: FloatArray, beam_sin: FloatArray, walls: Walls,
           centre: FloatArray, radius: FloatArray, skip: IntArray | None) -> None:
    """Every beam of every laser against every shape; the same formulas.

    For few lasers and shapes: numpy's cost per call, not the arithmetic, is the price there,
    and fewer calls win.
    """
    if len(origins) == 1:
        _dense_one(ranges[0], float(origins[0, 0]), float(origins[0, 1]), float(cos_t[0]),
                   float(sin_t[0]), beam_cos, beam_sin, walls, centre, radius,
                   -1 if skip is None else int(skip[0]))
        return
    dir_x = cos_t[:, None] * beam_cos - sin_t[:, None] * beam_sin  # lasers x beams
    dir_y = sin_t[:, None] * beam_cos + cos_t[:, None] * beam_sin
    count = len(walls)
    if count:
        # the three cross products d x e, d x (a - o), d x (b - o) in one matrix product
        edge = walls.edge
        shift = np.stack((origins[:, 1], -origins[:, 0]), axis=1)[:, None, :]
        rows = walls.rows[None] - walls.moves[None] * shift  # lasers x 3W x 2
        products = rows @ np.stack((dir_x, dir_y), axis=1)  # lasers x 3W x beams
        numerator = walls.a_cross_e[None, :, 0] - (origins[:, :1] * edge[None, :, 1]
                                                   - origins[:, 1:] * edge[None, :, 0])
        denom = products[:, :count]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = numerator[:, :, None] / denom
        missed = (products[:, count:2 * count] * products[:, 2 * count:] > 0.0) | \
            ~(t >= 0.0) | (np.abs(denom) < PARALLEL_EPS)
        t[missed] = np.inf
        np.minimum(ranges, t.min(axis=1), out=ranges)
    if len(radius):
        to_x = centre[None, :, 0] - origins[:, 0, None]  # lasers x discs
        to_y = centre[None, :, 1] - origins[:, 1, None]
        outside = to_x * to_x + to_y * to_y - radius[None, :] * radius[None, :]
        if skip is not None:
            own = skip >= 0
            outside[np.nonzero(own)[0], skip[own]] = np.nan  # never seen: every test fails
        along = to_x[:, :, None] * dir_x[:, None, :] + to_y[:, :, None] * dir_y[:, None, :]
        discriminant = along * along - outside[:, :, None]
        t = along - np.sqrt(np.maximum(discriminant, 0.0))
        within = (outside <= 0.0)[:, :, None]
        t = np.where(within, 0.0, t)
        hit = within | ((discriminant >= 0.0) & (t >= 0.0))
        np.minimum(ranges, np.where(hit, t, np.inf).min(axis=1), out=ranges)


def _directions(laser: IntArray, beam: IntArray, cos_t: FloatArray, sin_t: FloatArray,
                beam_cos: FloatArray, beam_sin: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each entry's beam direction in the map frame: its laser-frame direction, rotated."""
    c, s = cos_t[laser], sin_t[laser]
    bc, bs = beam_cos[beam], beam_sin[beam]
    return c * bc - s * bs, s * bc + c * bs


def cast_one(ox: float, oy: float, theta: float, beam_cos: FloatArray, beam_sin: FloatArray,
             range_max_m: float, walls: Walls, disc_centre: FloatArray,
             disc_radius: FloatArray) -> FloatArray:
    """``cast`` of one laser at (ox, oy) with yaw ``theta``: the distances along its beams.

    What a robot alone in its world casts every scan, without the batch's bookkeeping.
    """
    ranges = np.full(len(beam_cos), np.inf)
    _dense_one(ranges, ox, oy, math.cos(theta), math.sin(theta), beam_cos, beam_sin, walls,
               disc_centre, disc_radius, -1)
    ranges[ranges > range_max_m] = np.inf
    return ranges


def _dense_one(ranges: FloatArray, ox: float, oy: float, cos_t: float, sin_t: float,
               beam_cos: FloatArray, beam_sin: FloatArray, walls: Walls, centre: FloatArray,
               radius: FloatArray, skip: int) -> None:
    """``_dense`` of one laser at (ox, oy) turned (cos_t, sin_t): the single robot's scan."""
    dir_x = cos_t * beam_cos - sin_t * beam_sin
    dir_y = sin_t * beam_cos + cos_t * beam_sin
    count = len(walls)
    if count:
        edge = walls.edge
        products = (walls.rows - walls.moves * np.array((oy, -ox))) @ np.stack((dir_x, dir_y))
        denom = products[:count]
        numerator = walls.a_cross_e - (ox * edge[:, 1:] - oy * edge[:, :1])
        with np.errstate(divide="ignore", invalid="ignore"):
            t = numerator / denom
        missed = (products[count:2 * count] * products[2 * count:] > 0.0) | ~(t >= 0.0) | \
            (np.abs(denom) < PARALLEL_EPS)
        t[missed] = np.inf
        np.minimum(ranges, t.min(axis=0), out=ranges)
    if len(radius):
        to_x = (centre[:, 0] - ox)[:, None]
        to_y = (centre[:, 1] - oy)[:, None]
        outside = to_x * to_x + to_y * to_y - (radius * radius)[:, None]
        if skip >= 0:
            outside[skip] = np.nan  # never seen: every test fails
        along = to_x * dir_x + to_y * dir_y
        discriminant = along * along - outside
        t = along - np.sqrt(np.maximum(discriminant, 0.0))
        within = outside <= 0.0
        t = np.where(within, 0.0, t)
        hit = within | ((discriminant >= 0.0) & (t >= 0.0))
        np.minimum(ranges, np.where(hit, t, np.inf).min(axis=0), out=ranges)


def _walls(ranges: FloatArray, origins: FloatArray, cos_t: FloatArray, sin_t: FloatArray,
           headings: FloatArray, beam_cos: FloatArray, beam_sin: FloatArray,
           angle_min_rad: float, increment_rad: float, range_max_m: float,
           wall_a: FloatArray, wall_b: FloatArray) -> None:
    count = len(beam_cos)
    to_a = wall_a[None, :, :] - origins[:, None, :]  # lasers x walls x 2
    to_b = wall_b[None, :, :] - origins[:, None, :]
    edge = wall_b - wall_a
    # the wall's nearest point to the laser: farther than range_max, no beam reaches it
    length_2 = np.maximum(np.einsum("ij,ij->i", edge, edge), PARALLEL_EPS)
    along = np.clip(-np.einsum("lwj,wj->lw", to_a, edge) / length_2, 0.0, 1.0)
    near_x = to_a[..., 0] + along * edge[None, :, 0]
    near_y = to_a[..., 1] + along * edge[None, :, 1]
    laser, wall = np.nonzero(near_x * near_x + near_y * near_y <= range_max_m * range_max_m)
    if not len(laser):
        return
    ax, ay = to_a[laser, wall, 0], to_a[laser, wall, 1]
    bx, by = to_b[laser, wall, 0], to_b[laser, wall, 1]
    angle_a = np.arctan2(ay, ax)
    turn = np.arctan2(ax * by - ay * bx, ax * bx + ay * by)  # from a to b, (-pi, pi]
    lo = np.where(turn >= 0.0, angle_a, angle_a + turn) - headings[laser]
    width = np.abs(turn)
    first, spans = _arc_beams(lo, width, angle_min_rad, increment_rad, count)
    spans = np.where(width >= WIDE_ARC_RAD, count, spans)
    arc, beam = _expand(first, spans, count)
    pair_laser, pair_wall = laser[arc], wall[arc]
    dx, dy = _directions(pair_laser, beam, cos_t, sin_t, beam_cos, beam_sin)
    ex, ey = edge[pair_wall, 0], edge[pair_wall, 1]
    wx, wy = ax[arc], ay[arc]
    denom = ey * dx - ex * dy  # d x e
    side_a = wy * dx - wx * dy  # d x (a - o)
    side_b = by[arc] * dx - bx[arc] * dy  # d x (b - o)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / denom
    hit = (side_a * side_b <= 0.0) & (t >= 0.0) & (np.abs(denom) >= PARALLEL_EPS)
    np.minimum.at(ranges, pair_laser[hit] * count + beam[hit], t[hit])


def _discs(ranges: FloatArray, origins: FloatArray, cos_t: FloatArray, sin_t: FloatArray,
           headings: FloatArray, beam_cos: FloatArray, beam_sin: FloatArray,
           angle_min_rad: float, increment_rad: float, range_max_m: float,
           centre: FloatArray, radius: FloatArray, skip: IntArray | None) -> None:
    """Every laser's beams on the discs in its reach, nearest first where they are many.

    In a crowd most discs are hidden behind nearer ones: where the arcs cover each laser's
    turn more than ``CULL_MIN_DEPTH`` times, each laser's discs are cast in tiers of
    nearness (``NEAR_DISCS``), and a disc of a later tier only if some beam of its arc still
    reads beyond its nearest point (``gap``, the least distance a beam can hit it at). A disc
    left out could only have given longer distances than those read, so the ranges are the
    same, to the bit.
    """
    count = len(beam_cos)
    lasers = len(origins)
    to_x = centre[None, :, 0] - origins[:, 0, None]  # lasers x discs
    to_y = centre[None, :, 1] - origins[:, 1, None]
    reach = range_max_m + radius[None, :]
    close = to_x * to_x + to_y * to_y <= reach * reach
    if skip is not None:
        own = skip >= 0
        close[np.nonzero(own)[0], skip[own]] = False
    laser, disc = np.nonzero(close)
    if not len(laser):
        return
    wx, wy = to_x[laser, disc], to_y[laser, disc]
    r = radius[disc]
    d = np.hypot(wx, wy)
    inside = d <= r
    half = np.where(inside, math.pi, np.arcsin(np.minimum(1.0, r / np.maximum(d, 1e-300))))
    lo = np.arctan2(wy, wx) - half - headings[laser]
    first, spans = _arc_beams(lo, 2.0 * half, angle_min_rad, increment_rad, count)
    spans = np.where(inside, count, spans)
    turn = (cos_t, sin_t, beam_cos, beam_sin)
    if int(spans.sum()) <= CULL_MIN_DEPTH * lasers * count:
        _DiscPairs(laser, wx, wy, r, first, spans, turn, None).cast(ranges, slice(None))
        return
    directions = (cos_t[:, None] * beam_cos - sin_t[:, None] * beam_sin,  # lasers x beams
                  sin_t[:, None] * beam_cos + cos_t[:, None] * beam_sin)
    pairs = _DiscPairs(laser, wx, wy, r, first, spans, turn, directions)
    gap = d - r
    per_laser = np.full((lasers, len(radius)), np.inf)
    per_laser[laser, disc] = gap
    nearer = np.full(len(laser), -np.inf)  # each pair's laser's previous tiers reach this far
    for nearest in (*(n for n in NEAR_DISCS if n < len(radius)), None):
        bound = np.full(len(laser), np.inf) if nearest is None else \
            np.partition(per_laser, nearest - 1, axis=1)[laser, nearest - 1]
        tier = np.nonzero((gap > nearer) & (gap <= bound))[0]
        if len(tier) and np.isfinite(nearer).any():
            # a later tier: only the discs some beam of whose arc still reads beyond them
            seen = _arc_max(ranges.reshape(lasers, count), laser[tier], first[tier], spans[tier])
            tier = tier[seen >= gap[tier]]
        pairs.cast(ranges, tier)
        nearer = bound


@dataclass(frozen=True)
class _DiscPairs:
    """(laser, disc) pairs in reach: the disc's centre from the laser, its radius, its arc."""

    laser: IntArray
    wx: FloatArray
    wy: FloatArray
    r: FloatArray
    first: IntArray
    spans: IntArray
    turn: tuple[FloatArray, FloatArray, FloatArray, FloatArray]
    """The lasers' yaws' cos and sin, (lasers,), and the beams' in the laser frame, (n,)."""
    directions: tuple[FloatArray, FloatArray] | None
    """Every laser's beam directions in the map frame, x and y, (lasers, n): made once where
    the pairs cast more than one turn of beams per laser; None: each entry turns its own."""

    def cast(self, ranges: FloatArray, which: slice | IntArray | npt.NDArray[np.bool_]) -> None:
        """Intersect the beams of the arcs of pairs ``which``; each beam keeps its nearest."""
        spans = self.spans[which]
        if not len(spans):
            return
        cos_t, sin_t, beam_cos, beam_sin = self.turn
        count = len(beam_cos)
        arc, beam = _expand(self.first[which], spans, count)
        laser = self.laser[which][arc]
        flat = laser * count + beam
        if self.directions is None:
            dx, dy = _directions(laser, beam, cos_t, sin_t, beam_cos, beam_sin)
        else:
            dx, dy = self.directions[0].ravel()[flat], self.directions[1].ravel()[flat]
        cx, cy, rr = self.wx[which][arc], self.wy[which][arc], self.r[which][arc]
        along = cx * dx + cy * dy
        outside = cx * cx + cy * cy - rr * rr
        discriminant = along * along - outside
        t = along - np.sqrt(np.maximum(discriminant, 0.0))
        within = outside <= 0.0
        t = np.where(within, 0.0, t)
        hit = within | ((discriminant >= 0.0) & (t >= 0.0))
        np.minimum.at(ranges, flat[hit], t[hit])


def _arc_max(ranges: FloatArray, laser: IntArray, first: IntArray, spans: IntArray) -> FloatArray:
    """The longest range over each arc: beams ``first`` .. ``first + spans - 1`` (mod n).

    A sparse table of maxima over the doubled rows (windows of 1, 2, 4, ... beams, up to the
    widest arc), so each arc is two lookups whatever its width.
    """
    lasers, count = ranges.shape
    level_of = np.log2(np.maximum(spans, 1)).astype(np.intp)  # floor: spans >= 1
    levels = int(level_of.max()) + 1
    table = np.empty((levels, lasers, 2 * count))
    table[0, :, :count] = ranges
    table[0, :, count:] = ranges
    for level in range(1, levels):
        width = 1 << (level - 1)
        np.maximum(table[level - 1, :, :-width], table[level - 1, :, width:],
                   out=table[level, :, :-width])
        table[level, :, -width:] = np.inf  # past the row's end: never culls
    flat = table.reshape(-1)
    row = (level_of * lasers + laser) * (2 * count) + first
    longest: FloatArray = np.maximum(flat[row], flat[row + spans - (1 << level_of)])
    return longest
