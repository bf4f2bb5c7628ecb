"""Collision of the body square and the booms with the cave's rock polygons, vectorised.

Rock is a set of closed polygons. A segment collides when it crosses a polygon edge or lies
inside a polygon; the body collides when an edge of its square crosses rock, when it lies inside
rock, or when rock lies inside it. A boom may touch rock only at its own anchor, so boom segments
are checked from the shoulder to a point `ANCHOR_CLEARANCE` short of the anchor; a free gripper
only within ANCHOR_CLEARANCE of its own anchors (`free_clearance`, feasibility.reach_world).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from rb_drake.params import NUM_BOOMS

if TYPE_CHECKING:
    from rb_drake.edge_index import EdgeIndex

ANCHOR_CLEARANCE = 0.02  # m; a boom's last 2 cm, at its gripper, may touch the rock it grasps.
CLEARANCE_PAIRS = 1 << 20  # tips x anchors measured at once by `free_clearance`
INDEX_EDGES = 2048  # rock of more edges finds a segment's edges in a quadtree (edge_index), not
#                     by testing all in the batch's box: drawn caves have up to 50,000 edges ...
DENSE_PAIRS = 1 << 16  # ... unless a batch's segments x edges in its box are this few (a body's
#                        four sides: one pass over the edges costs less than the quadtree's)


CONTAINS_PAIRS = 1 << 19  # points x edges tested at once by `Rock.contains` (a few arrays of
#                          this many floats: 600 points in 4,000 small rocks took 163 MB)


def free_clearance(anchor_positions: np.ndarray, tips: np.ndarray) -> np.ndarray:
    """How far short of a FREE gripper at each of `tips` (..., 2) its boom is checked for rock:
    ANCHOR_CLEARANCE - d, clipped to [0, ANCHOR_CLEARANCE], d the distance to the nearest of
    `anchor_positions`: in a reach phase the gripper's own two (feasibility.reach_world).

    A held boom may touch rock in its last ANCHOR_CLEARANCE, the rock its gripper grasps. A free
    gripper grasps nothing: only where it takes or leaves an anchor may it touch that anchor's
    rock, so the boom is exempt only where it lies within ANCHOR_CLEARANCE of an anchor (its
    last ANCHOR_CLEARANCE - d); mid-reach (d >= ANCHOR_CLEARANCE) it is checked to its tip, and
    at an anchor (d = 0) it is a held boom's rule. A NaN tip (no free gripper): ANCHOR_CLEARANCE.
    The one rule of feasibility.check_poses, the kernel, rbp check's `collision` and SCP."""
    pts = np.asarray(tips, dtype=float)
    flat = pts.reshape(-1, 2)
    out = np.full(len(flat), ANCHOR_CLEARANCE)
    finite = np.flatnonzero(np.isfinite(flat).all(axis=1))
    if not len(finite):
        return out.reshape(pts.shape[:-1])
    out[finite] = 0.0
    anchors = np.asarray(anchor_positions, dtype=float).reshape(-1, 2)
    # only anchors within ANCHOR_CLEARANCE of the tips' box can shorten a tip's check
    lo = flat[finite].min(axis=0) - ANCHOR_CLEARANCE
    hi = flat[finite].max(axis=0) + ANCHOR_CLEARANCE
    near = anchors[np.all((anchors >= lo) & (anchors <= hi), axis=1)]
    if len(near):
        size = max(1, CLEARANCE_PAIRS // len(near))
        for k in range(0, len(finite), size):
            rows = finite[k:k + size]
            d = np.linalg.norm(flat[rows, None, :] - near[None, :, :], axis=2).min(axis=1)
            out[rows] = np.clip(ANCHOR_CLEARANCE - d, 0.0, ANCHOR_CLEARANCE)
    return out.reshape(pts.shape[:-1])


def boom_clearances(anchor_positions: np.ndarray, P: int, free_boom: int | None,
                    free_tip: np.ndarray | None) -> np.ndarray:
    """Per pose and boom (P, 4), how far short of its tip each boom is checked for rock:
    ANCHOR_CLEARANCE for a held boom, `free_clearance` for the free one at `free_tip`
    ((2,) or (P, 2))."""
    out = np.full((P, NUM_BOOMS), ANCHOR_CLEARANCE)
    if free_boom is not None and free_tip is not None:
        tips = np.broadcast_to(np.asarray(free_tip, dtype=float).reshape(-1, 2), (P, 2))
        out[:, free_boom] = free_clearance(anchor_positions, tips)
    return out


class Rock:
    """The cave's rock polygons packed as edge arrays for vectorised tests."""

    def __init__(self, polygons: Sequence[np.ndarray]):
        self.polygons = [np.asarray(p, dtype=float) for p in polygons]
        if self.polygons:
            self.edge_start = np.concatenate(self.polygons)
            self.edge_end = np.concatenate([np.roll(p, -1, axis=0) for p in self.polygons])
            self.vertex = np.array([p[0] for p in self.polygons])  # one vertex per polygon
            # which polygon each edge belongs to (edges are grouped by polygon, in order), for
            # parity counts by group: an (edges x polygons) indicator took 384 MB for a cave
            # of 4,000 small rocks
            self.edge_owner = np.repeat(np.arange(len(self.polygons)),
                                        [len(p) for p in self.polygons])
            self.edge_lo = np.minimum(self.edge_start, self.edge_end)
            self.edge_hi = np.maximum(self.edge_start, self.edge_end)
            self._index: EdgeIndex | None = None  # built at the first segment test
        else:
            self.edge_start = self.edge_end = np.zeros((0, 2))
            self.vertex = np.zeros((0, 2))
            self.edge_lo = self.edge_hi = np.zeros((0, 2))

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Whether each point (shape (..., 2)) lies inside some polygon (even-odd rule)."""
        pts = np.asarray(points, dtype=float)
        flat = pts.reshape(-1, 2)
        if not self.polygons or not len(flat):
            return np.zeros(pts.shape[:-1], dtype=bool)
        # Even-odd rule for every polygon at once: count, per polygon, the edges that a ray
        # from the point towards +x crosses. Only edges that reach the points' band of y and
        # lie partly right of the leftmost point can be crossed.
        lo, hi = flat.min(axis=0), flat.max(axis=0)
        near = ((self.edge_hi[:, 1] >= lo[1]) & (self.edge_lo[:, 1] <= hi[1])
                & (self.edge_hi[:, 0] >= lo[0]))
        count = int(np.count_nonzero(near))
        if len(flat) > 1 and len(flat) * count > CONTAINS_PAIRS:  # in chunks of points
            size = max(1, CONTAINS_PAIRS // count)
            return np.concatenate([self.contains(flat[i:i + size])
                                   for i in range(0, len(flat), size)]).reshape(pts.shape[:-1])
        x, y = flat[:, 0:1], flat[:, 1:2]
        e0, e1 = self.edge_start[near], self.edge_end[near]
        x0, y0 = e0[None, :, 0], e0[None, :, 1]
        x1, y1 = e1[None, :, 0], e1[None, :, 1]
        straddle = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            x_cross = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        if not straddle.shape[1]:
            return np.zeros(pts.shape[:-1], dtype=bool)
        # crossings per polygon: the near edges stay grouped by polygon, so sum each group
        owner = self.edge_owner[near]
        groups = np.flatnonzero(np.r_[True, owner[1:] != owner[:-1]])
        crossings = np.add.reduceat((straddle & (x < x_cross)).astype(np.int32), groups, axis=1)
        inside = (crossings % 2 == 1).any(axis=1)
        return inside.reshape(pts.shape[:-1])

    def segments_hit(self, a: np.ndarray, b: np.ndarray, inside: bool = True) -> np.ndarray:
        """Whether each segment a -> b (shapes (..., 2)) crosses an edge or lies inside rock.
        `inside=False` skips the second test, for segments known to start outside rock."""
        a = np.asarray(a, dtype=float)
        b = np.asarray(b, dtype=float)
        shape = np.broadcast_shapes(a.shape, b.shape)[:-1]
        a2 = np.broadcast_to(a, (*shape, 2)).reshape(-1, 2)
        b2 = np.broadcast_to(b, (*shape, 2)).reshape(-1, 2)
        # Only edges whose bounding box meets the batch's can be hit: the robot spans a few
        # metres of a cave that may be tens of metres long.
        lo = np.minimum(a2.min(axis=0), b2.min(axis=0)) if len(a2) else np.zeros(2)
        hi = np.maximum(a2.max(axis=0), b2.max(axis=0)) if len(a2) else np.zeros(2)
        near = np.all((self.edge_hi >= lo) & (self.edge_lo <= hi), axis=1)
        hit: np.ndarray  # (I,): numpy types ndarray.any(axis=) as maybe a scalar
        if len(near) > INDEX_EDGES and len(a2) * np.count_nonzero(near) > DENSE_PAIRS:
            hit = self._indexed_hits(a2, b2)
        else:
            hit = np.any(_segments_cross(a2, b2, self.edge_start[near], self.edge_end[near]),
                         axis=1)
        if inside:
            hit |= self.contains(a2)
        return hit.reshape(shape)

    def _indexed_hits(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """segments_hit's crossing test, on the pairs the edge quadtree finds (the same test
        on fewer pairs: every pair that can meet is among them)."""
        from rb_drake.edge_index import EdgeIndex

        if self._index is None:
            self._index = EdgeIndex(self.edge_start, self.edge_end)
        seg, edge = self._index.candidates(a, b)
        meet = _pairs_cross(a[seg], b[seg], self.edge_start[edge], self.edge_end[edge])
        hit = np.zeros(len(a), dtype=bool)
        hit[seg[meet]] = True
        return hit

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point to the nearest rock edge, shape points.shape[:-1]."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        e = self.edge_end - self.edge_start
        rel = pts[:, None, :] - self.edge_start[None]
        t = np.clip(np.sum(rel * e, -1) / np.maximum(np.sum(e * e, -1), 1e-300), 0.0, 1.0)
        closest = self.edge_start[None] + t[..., None] * e[None]
        d = np.linalg.norm(pts[:, None, :] - closest, axis=-1).min(axis=1)
        return d.reshape(np.asarray(points).shape[:-1])


def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


def _segments_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Proper or touching intersection of segments a_i b_i with c_j d_j, shape (I, J)."""
    ax, ay = a[:, 0:1], a[:, 1:2]
    bx, by = b[:, 0:1], b[:, 1:2]
    cx, cy = c[None, :, 0], c[None, :, 1]
    dx, dy = d[None, :, 0], d[None, :, 1]
    o1 = _orient(ax, ay, bx, by, cx, cy)
    o2 = _orient(ax, ay, bx, by, dx, dy)
    o3 = _orient(cx, cy, dx, dy, ax, ay)
    o4 = _orient(cx, cy, dx, dy, bx, by)
    return (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~((o1 == 0) & (o2 == 0))


def _pairs_cross(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """_segments_cross for the pairs a_k b_k, c_k d_k, shape (K,)."""
    o1 = _orient(*a.T, *b.T, *c.T)
    o2 = _orient(*a.T, *b.T, *d.T)
    o3 = _orient(*c.T, *d.T, *a.T)
    o4 = _orient(*c.T, *d.T, *b.T)
    return (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~((o1 == 0) & (o2 == 0))


MIN_EDGE = 1e-12  # m: a shorter edge joins a repeated vertex


def polygon_is_simple(poly: np.ndarray) -> tuple[bool, str]:
    """Whether a closed polygon is simple (no two non-adjacent edges meet); the reason if not."""
    poly = np.asarray(poly, dtype=float)
    n = len(poly)
    if n < 3:
        return False, f"needs at least 3 vertices, has {n}"
    q = np.roll(poly, -1, axis=0)
    if np.any(np.linalg.norm(q - poly, axis=1) < MIN_EDGE):
        return False, "has a repeated vertex (an edge of zero length)"
    bad = _first_crossing(poly, q)
    if bad is not None:
        return False, f"edges {bad[0]} and {bad[1]} intersect (the polygon crosses itself)"
    area = 0.5 * np.sum(poly[:, 0] * q[:, 1] - q[:, 0] * poly[:, 1])
    if abs(area) < 1e-12:
        return False, "has zero area"
    return True, ""


def _first_crossing(start: np.ndarray, end: np.ndarray,
                    block: int = 1 << 20) -> tuple[int, int] | None:
    """The first pair (i < j, by i then j) of non-adjacent edges start -> end of a closed
    polygon that meet, or None. A sweep along the axis on which the edges' extents overlap
    least tests only the pairs whose bounding boxes meet, `block` pairs at a time: the n x n
    test took 3.2 s and 1.2 GB for 5,000 vertices, and walls may have 50,000."""
    n = len(start)
    lo, hi = np.minimum(start, end), np.maximum(start, end)
    sweeps = []
    for axis in (0, 1):
        order = np.argsort(lo[:, axis], kind="stable")
        # edges at sorted positions p + 1 .. stop[p] - 1 start before edge order[p] ends
        stop = np.searchsorted(lo[order, axis], hi[order, axis], side="right")
        sweeps.append((axis, order, stop - np.arange(n) - 1))
    axis, order, counts = min(sweeps, key=lambda sweep: int(sweep[2].sum()))
    other = 1 - axis
    best: tuple[int, int] | None = None
    total = np.cumsum(counts)
    first = 0
    while first < n:
        last = max(first + 1, int(np.searchsorted(total, total[first] - counts[first] + block,
                                                  side="right")))
        c = counts[first:last]
        p = np.repeat(np.arange(first, last), c)
        offset = np.arange(len(p)) - np.repeat(np.cumsum(c) - c, c)
        a, b = order[p], order[p + 1 + offset]
        keep = (lo[b, other] <= hi[a, other]) & (lo[a, other] <= hi[b, other])
        gap = np.abs(a - b)
        keep &= (gap > 1) & (gap != n - 1)  # adjacent edges share a vertex
        a, b = a[keep], b[keep]
        o1 = _orient(*start[a].T, *end[a].T, *start[b].T)
        o2 = _orient(*start[a].T, *end[a].T, *end[b].T)
        o3 = _orient(*start[b].T, *end[b].T, *start[a].T)
        o4 = _orient(*start[b].T, *end[b].T, *end[a].T)
        meet = (o1 * o2 <= 0) & (o3 * o4 <= 0) & ~((o1 == 0) & (o2 == 0))
        if np.any(meet):
            i, j = np.minimum(a[meet], b[meet]), np.maximum(a[meet], b[meet])
            k = np.lexsort((j, i))[0]
            if best is None or (int(i[k]), int(j[k])) < best:
                best = (int(i[k]), int(j[k]))
        first = last
    return best


def signed_area(poly: np.ndarray) -> float:
    poly = np.asarray(poly, dtype=float)
    q = np.roll(poly, -1, axis=0)
    return float(0.5 * np.sum(poly[:, 0] * q[:, 1] - q[:, 0] * poly[:, 1]))
