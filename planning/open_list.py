"""The complete search's open list: what its entries hold (`Entry`), and the moves an
expanded vertex leaves there, held as one entry (`MoveGroup`).

The complete search (`planning.complete`) pushes every move of an expanded vertex into its open
list, keyed (f, tie), and evaluates a move only when it is popped; most are never popped. As
one tuple each (with its child stance and payload) they were the largest thing a long search
kept per vertex outside its memo: about 2.3 kB per expanded vertex, 230 MB for a search of
100,000 (docs/benchmarks.md, issue 31). `MoveGroup` keeps them in two arrays, 24 bytes a
move, sorted by (f, tie), and only its first move sits in the open list; popping it puts the
next one back. The open list then pops exactly the moves, in exactly the order, that it would
have popped with one entry per move: the search's decisions do not change.
"""

from __future__ import annotations

import math
from array import array
from collections.abc import Callable
from enum import IntEnum

import numpy as np

from planning.lattice_search import Vertex
from rb_drake.scenario import Scenario


class Entry(IntEnum):
    """What an open-list entry holds (its fourth field; the search's comment on `open_list`)."""

    REACHED = 0  # a stance reached by an evaluated move, its component not yet known
    MOVE = 1     # a move still to evaluate (its transition poses not yet computed)
    MOVES = 2    # an expanded vertex's moves still to evaluate, as one entry (`MoveGroup`)


_J_BITS, _K_BITS = 4, 24  # a move's code: tie << 28 | boom << 24 | anchor row


def _code(tie: int, boom: int, row: int) -> int:
    return (tie << (_J_BITS + _K_BITS)) | (boom << _K_BITS) | row


def _decoded(scn: Scenario, stance: tuple, code: int) -> tuple[int, int, int, str, tuple]:
    """A move's code from `stance`: its tie number, boom, anchor row, anchor id and child."""
    tie, j, k = code >> (_J_BITS + _K_BITS), (code >> _K_BITS) & 15, code & (2**_K_BITS - 1)
    anchor = scn.anchors[k].id
    return tie, j, k, anchor, tuple(anchor if i == j else a for i, a in enumerate(stance))


class MoveGroup:
    """The moves of `vertex` (a (stance, component) pair) reached at `g` (its cost plus the
    least an edge costs) still waiting in the open list, sorted by (f, tie), f = g + key(child)
    (`key`: the search's heuristic as it was when they were keyed, a pure function of the
    stance, so f is found again, the same float, when a move comes first): per move a code
    holding its tie number (less the group's first), boom and anchor row; and, for the search's
    lower bound, the least admissible bound of the child stances from each move on, as runs (it
    only rises from one move to the next, and a vertex's children's bounds differ by a regrasp
    or two).

    A code takes 4 bytes where the group's span of ties, booms and anchors fits, 8 otherwise:
    a long search's groups hold tens of moves each (about 100 at 20 anchors a metre), most of
    what it keeps per vertex outside its memo; 24 bytes a move before (f, the least bound and
    the code as 8 bytes each; docs/benchmarks.md, session 24)."""

    __slots__ = ("base", "bits", "code", "g", "key", "pos", "run", "values", "vertex")

    def __init__(self, vertex: tuple, g: float, moves: list[tuple[float, int, int, int, float]],
                 key: Callable[[tuple], float]) -> None:
        """`moves`: (f, tie, boom, anchor row, bound of the child), in any order, each f
        computed as `g + key(child)`."""
        self.vertex, self.g, self.key = vertex, g, key
        self._fill(moves)

    def _fill(self, moves: list[tuple[float, int, int, int, float]]) -> None:
        moves.sort()  # by (f, tie): the order the open list pops them in
        self.pos = 0
        self.run = 0  # the run of least bounds that holds move `pos`
        least, suffix = math.inf, []
        for m in reversed(moves):
            least = min(least, m[4])
            suffix.append(least)
        suffix.reverse()  # the least bound from each move on: it only rises
        runs = [x for i, v in enumerate(suffix) if i == 0 or v != suffix[i - 1]
                for x in (float(i), v)]
        self.values = array("d", runs)  # (first move, least bound from it on) per run
        self.base = min((m[1] for m in moves), default=0)
        row_bits = max((m[3] for m in moves), default=0).bit_length()
        boom_bits = max((m[2] for m in moves), default=0).bit_length()
        self.bits = row_bits * 8 + boom_bits  # < 256: Python's shared small ints
        codes = [((((m[1] - self.base) << boom_bits) | m[2]) << row_bits) | m[3] for m in moves]
        self.code = array("I" if max(codes, default=0) < 2**32 else "q", codes)

    def __len__(self) -> int:
        return len(self.code) - self.pos

    def move(self, scn: Scenario, n: int) -> tuple[int, int, int, str, tuple]:
        """The n-th waiting move (0: the first): its tie number, boom, anchor row, anchor id
        and child."""
        code, row_bits, boom_bits = self.code[self.pos + n], self.bits >> 3, self.bits & 7
        k = code & ((1 << row_bits) - 1)
        j = (code >> row_bits) & ((1 << boom_bits) - 1)
        offset = code >> (row_bits + boom_bits)
        anchor = scn.anchors[k].id
        stance = self.vertex[0]
        return (self.base + offset, j, k, anchor,
                tuple(anchor if i == j else a for i, a in enumerate(stance)))

    def entry(self, scn: Scenario, kind: int) -> tuple:
        """The open-list entry of the first waiting move: (f, tie, g, kind, None, self) (its
        child is found again when it is popped: 72 bytes a waiting vertex)."""
        tie, _, _, _, child = self.move(scn, 0)
        return (self.g + self.key(child), tie, self.g, kind, None, self)

    def pop(self, scn: Scenario, kind: int) -> tuple:
        """The first waiting move as one move's entry (f, tie, g, kind, child, (vertex, boom,
        anchor)), taken out of the group."""
        tie, j, _, anchor, child = self.move(scn, 0)
        f = self.g + self.key(child)
        self.pos += 1
        return (f, tie, self.g, kind, child, (self.vertex, j, anchor))

    def least(self) -> float:
        """The least g + bound over the waiting moves (inf: none wait)."""
        if not len(self):
            return math.inf
        values = self.values
        runs = len(values) // 2
        while self.run + 1 < runs and values[2 * (self.run + 1)] <= self.pos:
            self.run += 1
        return self.g + values[2 * self.run + 1]

    def rekey(self, scn: Scenario, key: Callable[[tuple], float],
              bound: Callable[[tuple], float]) -> None:
        """Each waiting move keyed again, f = g + key(child), and sorted again by (f, tie)."""
        moves = []
        for i in range(len(self)):
            tie, j, k, _, child = self.move(scn, i)
            moves.append((self.g + key(child), tie, j, k, bound(child)))
        self.key = key
        self._fill(moves)


class DeferredMoves:
    """Moves popped before the first route that wait for it (the anytime search's INCONS
    list), in columns: a long search defers a few per expanded vertex, and as entries they
    were ~300 bytes each. `least` is the least g + bound among them, for the lower bound."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.vertices: list[tuple] = []
        self.values = array("d")  # f, g per move
        self.code = array("q")
        self.least = math.inf

    def __len__(self) -> int:
        return len(self.code)

    def add(self, entry: tuple, row: int, bound: float) -> None:
        """A popped move's entry (f, tie, g, kind, child, (vertex, boom, anchor)), its anchor's
        row and its child's bound."""
        f, tie, g, _, _, (vertex, j, _) = entry
        self.vertices.append(vertex)
        self.values.extend((f, g))
        self.code.append(_code(tie, j, row))
        self.least = min(self.least, g + bound)

    def entries(self, scn: Scenario, kind: int) -> list[tuple]:
        """The moves as open-list entries again, as they were popped."""
        out = []
        for n, vertex in enumerate(self.vertices):
            tie, j, _, anchor, child = _decoded(scn, vertex[0], self.code[n])
            out.append((self.values[2 * n], tie, self.values[2 * n + 1], kind, child,
                        (vertex, j, anchor)))
        return out


def anchor_row(scn: Scenario, anchor: str) -> int:
    """The anchor's row, as a move's code holds it (at most 2**24 anchors)."""
    k = scn.anchor_index[anchor]
    if k >= 2**_K_BITS:
        raise ValueError(f"a cave of more than {2**_K_BITS} anchors")
    return k


def rekeyed(scn: Scenario, entry: tuple, key: Callable[[tuple], float],
            bound: Callable[[tuple], float]) -> tuple:
    """An open-list entry keyed again by `key` (f = g + key(child)); a group's moves too."""
    if entry[3] == Entry.MOVES:
        entry[5].rekey(scn, key, bound)
        return entry[5].entry(scn, Entry.MOVES)
    return (entry[2] + key(entry[4]), *entry[1:])


def frontier(open_list: list, closed: dict) -> list[tuple[Vertex, np.ndarray]]:
    """The vertices reached (by an evaluated move) but never expanded, for pictures."""
    out, seen = [], set()
    for entry in open_list:
        if entry[3] == Entry.REACHED:
            vertex, _, pose = entry[5][:3]
            if vertex not in closed and vertex not in seen:
                seen.add(vertex)
                out.append((vertex, pose))
    return out
