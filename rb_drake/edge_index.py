"""A quadtree of a rock's edges, for `collision.Rock.segments_hit` on rock of many edges.

Testing every segment against every edge in the batch's bounding box costs segments x edges:
an imported outline of 45,000 vertices took over a minute to import. Here edges are entered
in the cells of a fine grid they pass through, and a segment descends a pyramid of coarser
grids from the top, keeping only the cells that hold some edge and that it passes through;
the edges of the finest cells it keeps are its candidates (every edge it can meet among them),
tested exactly as before. The work per segment follows the rock near its path, not the rock.
"""

from __future__ import annotations

import numpy as np

MAX_LEVELS = 24   # the finest cell is at least the rock's extent / FANOUT**24
FANOUT = 2        # a cell's children a side (4: half the levels, but 124 MB, not 104, on
#                   the probe's 8,000-vertex outline for no time saved)

_CHILD_X, _CHILD_Y = (c.ravel() for c in np.meshgrid(np.arange(FANOUT), np.arange(FANOUT)))


class EdgeIndex:
    """Edges start[k] -> end[k] (E, 2) by the finest-grid cells they pass through."""

    def __init__(self, start: np.ndarray, end: np.ndarray):
        length = np.linalg.norm(end - start, axis=1)
        lo = np.minimum(start.min(axis=0), end.min(axis=0))
        extent = float(max(np.max(np.maximum(start.max(axis=0), end.max(axis=0)) - lo), 1e-9))
        # cells about an edge long (the median), but never so fine that the edges' pieces
        # outnumber 4 per edge, nor beyond MAX_LEVELS halvings of the extent
        cell = max(float(np.median(length)), float(length.sum()) / (4 * len(length)),
                   extent / FANOUT ** MAX_LEVELS)
        self.levels = max(1, int(np.ceil(np.log(extent / cell) / np.log(FANOUT))) + 1)
        self.cell = cell
        self.eps = 1e-9 * max(1.0, extent)  # cells are closed and widened by this much
        self.origin = lo - cell
        cells, owner = _cells_passed(self, start, end)
        key = self._key(cells)
        order = np.lexsort((owner, key))
        key, owner = key[order], owner[order]
        keep = np.ones(len(key), dtype=bool)
        keep[1:] = (key[1:] != key[:-1]) | (owner[1:] != owner[:-1])
        self.key, self.edge = key[keep], owner[keep]
        self.edges = len(start)
        # the occupied cells of each coarser level (level l: cells FANOUT**l fine cells wide)
        self.occupied = [np.unique(self.key)]
        for level in range(1, self.levels + 1):
            self.occupied.append(np.unique(self._key(cells // FANOUT ** level)))

    @staticmethod
    def _key(cells: np.ndarray) -> np.ndarray:
        return (cells[:, 0].astype(np.int64) << 32) | cells[:, 1].astype(np.int64)

    def candidates(self, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pairs (segment i, edge j), i into a/b (I, 2), of every edge a segment may meet."""
        top = self.levels
        size = self.cell * FANOUT ** top
        # the whole rock is in top cells 0..1 (clipped as floats: a far point overflows no int)
        lo = np.clip(np.floor((np.minimum(a, b) - self.eps - self.origin) / size), 0, 2)
        hi = np.clip(np.floor((np.maximum(a, b) + self.eps - self.origin) / size), -1, 1)
        lo, hi = lo.astype(np.int64), hi.astype(np.int64)
        seg, cx, cy = [], [], []
        for dx in (0, 1):
            for dy in (0, 1):
                ok = (lo[:, 0] <= dx) & (dx <= hi[:, 0]) & (lo[:, 1] <= dy) & (dy <= hi[:, 1])
                seg.append(np.flatnonzero(ok))
                cx.append(np.full(int(ok.sum()), dx))
                cy.append(np.full(int(ok.sum()), dy))
        s, x, y = np.concatenate(seg), np.concatenate(cx), np.concatenate(cy)
        for level in range(top, -1, -1):
            s, x, y = self._passed(a, b, s, x, y, level)
            if level:  # each kept cell's FANOUT x FANOUT children
                s = np.repeat(s, FANOUT ** 2)
                x = FANOUT * np.repeat(x, FANOUT ** 2) + np.tile(_CHILD_X, len(x))
                y = FANOUT * np.repeat(y, FANOUT ** 2) + np.tile(_CHILD_Y, len(y))
        key = self._key(np.stack([x, y], 1))
        first = np.searchsorted(self.key, key, side="left")
        count = np.searchsorted(self.key, key, side="right") - first
        pair_seg = np.repeat(s, count)
        at = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
        pair_edge = self.edge[np.repeat(first, count) + at]
        n = self.edges
        pair = np.sort(pair_seg * n + pair_edge)  # a pair found in several cells, once
        pair = pair[np.concatenate([pair[:1] == pair[:1], pair[1:] != pair[:-1]])]
        return pair // n, pair % n

    def _passed(self, a: np.ndarray, b: np.ndarray, s: np.ndarray, x: np.ndarray,
                y: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The (segment, cell) pairs whose cell at `level` holds an edge and meets the segment
        (its box widened by eps: a conservative test)."""
        occ = self.occupied[level]
        key = self._key(np.stack([x, y], 1))
        at = np.minimum(np.searchsorted(occ, key), len(occ) - 1)
        keep = occ[at] == key
        s, x, y = s[keep], x[keep], y[keep]
        size = self.cell * FANOUT ** level
        x0 = self.origin[0] + x * size - self.eps
        y0 = self.origin[1] + y * size - self.eps
        x1, y1 = x0 + size + 2 * self.eps, y0 + size + 2 * self.eps
        pa, pb = a[s], b[s]
        keep = ((np.minimum(pa[:, 0], pb[:, 0]) <= x1) & (np.maximum(pa[:, 0], pb[:, 0]) >= x0)
                & (np.minimum(pa[:, 1], pb[:, 1]) <= y1) & (np.maximum(pa[:, 1], pb[:, 1]) >= y0))
        # the segment's line separates no corner from the others: the box meets the line
        d = pb - pa
        side = [d[:, 0] * (cy - pa[:, 1]) - d[:, 1] * (cx - pa[:, 0])
                for cx, cy in ((x0, y0), (x1, y0), (x0, y1), (x1, y1))]
        above = np.all([v > 0 for v in side], axis=0)
        below = np.all([v < 0 for v in side], axis=0)
        keep &= ~above & ~below
        return s[keep], x[keep], y[keep]


def _cells_passed(index: EdgeIndex, start: np.ndarray,
                  end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The finest cells (ix, iy) each edge passes through (widened by eps) and their edges:
    each edge cut into pieces no longer than a cell, each piece in the (at most 2 x 2) cells
    its bounding box covers (three a side where the widening reaches over a cell's edge)."""
    length = np.linalg.norm(end - start, axis=1)
    pieces = np.maximum(1, np.ceil(length / index.cell).astype(np.int64))
    owner = np.repeat(np.arange(len(start)), pieces)
    step = np.arange(len(owner)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    t0 = (step / pieces[owner])[:, None]
    t1 = ((step + 1) / pieces[owner])[:, None]
    d = (end - start)[owner]
    p0, p1 = start[owner] + t0 * d, start[owner] + t1 * d
    lo = np.floor((np.minimum(p0, p1) - index.eps - index.origin) / index.cell).astype(np.int64)
    hi = np.floor((np.maximum(p0, p1) + index.eps - index.origin) / index.cell).astype(np.int64)
    cells, owners = [], []
    span = int((hi - lo).max()) if len(lo) else 0  # 1, or 2 with the widening
    for dx in range(span + 1):
        for dy in range(span + 1):
            ok = (lo[:, 0] + dx <= hi[:, 0]) & (lo[:, 1] + dy <= hi[:, 1])
            cells.append(lo[ok] + [dx, dy])
            owners.append(owner[ok])
    return np.concatenate(cells), np.concatenate(owners)
