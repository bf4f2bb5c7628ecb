"""Collision tests for compiled code: `collision.Rock.segments_hit` and `contains`, and
`feasibility.rock_inside_body`, one segment or point at a time against the rock's edges, with
the rock packed once into the arrays they read (`packed_rock`).
"""

from __future__ import annotations

import math
import weakref

import numpy as np
from numba import njit

from rb_drake.collision import Rock
from rb_drake.kernel.layout import BODY_SEGMENT, REASON_BODY_COLLISION, REASON_BOOM_COLLISION
from rb_drake.params import NUM_BOOMS

_ROCK_CACHE: weakref.WeakKeyDictionary[Rock, tuple[np.ndarray, np.ndarray, np.ndarray]] = (
    weakref.WeakKeyDictionary())


def packed_rock(rock: Rock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges (E, 4: x0, y0, x1, y1), the polygon of each edge (E,) and one vertex per polygon
    (W, 2), packed once per Rock."""
    packed = _ROCK_CACHE.get(rock)
    if packed is None:
        if rock.polygons:
            edges = np.hstack([rock.edge_start, rock.edge_end])
            owner = np.repeat(np.arange(len(rock.polygons)), [len(p) for p in rock.polygons])
            vertices = np.array(rock.vertex, dtype=float)
        else:
            edges, owner, vertices = np.zeros((0, 4)), np.zeros(0, np.int64), np.zeros((0, 2))
        packed = (np.ascontiguousarray(edges, dtype=float), owner.astype(np.int64),
                  np.ascontiguousarray(vertices))
        _ROCK_CACHE[rock] = packed
    return packed



@njit(cache=True, error_model="numpy")
def _orient(ax, ay, bx, by, cx, cy):
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@njit(cache=True, error_model="numpy")
def segment_hits(ax, ay, bx, by, edges, near) -> bool:
    """Whether segment a-b crosses or touches one of the edges `near` (collision's test)."""
    lo_x, hi_x = min(ax, bx), max(ax, bx)
    lo_y, hi_y = min(ay, by), max(ay, by)
    for e in near:
        cx, cy, dx, dy = edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3]
        if (max(cx, dx) < lo_x or min(cx, dx) > hi_x or max(cy, dy) < lo_y
                or min(cy, dy) > hi_y):
            continue  # apart (collision.Rock culls the same way, per batch)
        o1 = _orient(ax, ay, bx, by, cx, cy)
        o2 = _orient(ax, ay, bx, by, dx, dy)
        o3 = _orient(cx, cy, dx, dy, ax, ay)
        o4 = _orient(cx, cy, dx, dy, bx, by)
        if o1 * o2 <= 0 and o3 * o4 <= 0 and not (o1 == 0 and o2 == 0):
            return True
    return False


@njit(cache=True, error_model="numpy")
def _inside_rock(x, y, edges, owner, near, parity) -> bool:
    """Whether point (x, y) lies inside some polygon (even-odd rule per polygon)."""
    parity[:] = 0
    for e in near:
        x0, y0, x1, y1 = edges[e, 0], edges[e, 1], edges[e, 2], edges[e, 3]
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            parity[owner[e]] ^= 1
    return parity.any()


@njit(cache=True, error_model="numpy")
def near_edges(poses, edges, reach) -> tuple[np.ndarray, np.ndarray]:
    """Edges that a body or boom at one of the poses can touch (within `reach` of a centre), and
    those a ray towards +x from a body corner can cross. Like collision.Rock's culling per
    batch, this only drops edges that cannot change a result."""
    x_lo, x_hi = poses[:, 0].min() - reach, poses[:, 0].max() + reach
    y_lo, y_hi = poses[:, 1].min() - reach, poses[:, 1].max() + reach
    hit = np.empty(edges.shape[0], dtype=np.int64)
    ray = np.empty(edges.shape[0], dtype=np.int64)
    n_hit = n_ray = 0
    for e in range(edges.shape[0]):
        ex_lo, ex_hi = min(edges[e, 0], edges[e, 2]), max(edges[e, 0], edges[e, 2])
        ey_lo, ey_hi = min(edges[e, 1], edges[e, 3]), max(edges[e, 1], edges[e, 3])
        if ey_hi >= y_lo and ey_lo <= y_hi and ex_hi >= x_lo:
            ray[n_ray] = e
            n_ray += 1
            if ex_lo <= x_hi:
                hit[n_hit] = e
                n_hit += 1
    return hit[:n_hit], ray[:n_ray]



@njit(cache=True, error_model="numpy")
def collision_code(x, y, c, s, corner_x, corner_y, cx, cy, u, tg, sh, clearance, free,
                   free_clearance, edges, owner, near_hit, near_ray, parity, vertices,
                   collide) -> int:
    """REASON_BODY_COLLISION, BOOM_COLLISION or 0 for the pose (x, y, phi = atan2(s, c)) whose
    booms run from the shoulders sh to the targets tg along u (collision.Rock's tests), testing
    the segments of `collide`'s bits only (layout.ALL_SEGMENTS). Booms are tested to
    `clearance` short of their tips, the free one (boom `free`, -1: none) to `free_clearance`
    short (collision.free_clearance)."""
    if collide & BODY_SEGMENT:
        code = body_collision(x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit,
                               near_ray, parity, vertices)
        if code:
            return code
    for i in range(NUM_BOOMS):
        if not collide & (1 << i):
            continue
        ux = u[i, 0] if math.isfinite(u[i, 0]) else 0.0
        uy = u[i, 1] if math.isfinite(u[i, 1]) else 0.0
        short = free_clearance if i == free else clearance
        ex = tg[i, 0] - short * ux
        ey = tg[i, 1] - short * uy
        if segment_hits(sh[i, 0], sh[i, 1], ex, ey, edges, near_hit):
            return REASON_BOOM_COLLISION
    return 0


@njit(cache=True, error_model="numpy")
def body_collision(x, y, c, s, corner_x, corner_y, cx, cy, edges, owner, near_hit, near_ray,
                   parity, vertices) -> int:
    """REASON_BODY_COLLISION or 0 for the body square of the pose (x, y, phi = atan2(s, c)),
    its corners (body frame: corner_x, corner_y) placed into cx, cy: an edge crossed, a corner
    inside the rock, or a whole rock polygon inside the square."""
    for q in range(4):
        cx[q] = x + (c * corner_x[q] - s * corner_y[q])
        cy[q] = y + (s * corner_x[q] + c * corner_y[q])
    for q in range(4):
        r = (q + 1) % 4
        if (segment_hits(cx[q], cy[q], cx[r], cy[r], edges, near_hit)
                or _inside_rock(cx[q], cy[q], edges, owner, near_ray, parity)):
            return REASON_BODY_COLLISION
    for v in range(vertices.shape[0]):  # a whole rock polygon inside the body square
        inside = True
        for q in range(4):
            r = (q + 1) % 4
            side = ((cx[r] - cx[q]) * (vertices[v, 1] - cy[q])
                    - (cy[r] - cy[q]) * (vertices[v, 0] - cx[q]))
            if not side > 0:
                inside = False
                break
        if inside:
            return REASON_BODY_COLLISION
    return 0

