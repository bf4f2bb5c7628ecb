"""The moves of one expanded vertex, waiting in the open list as a single entry (issue 31).

An expansion finds about twenty moves, and most are never evaluated; as twenty open-list
entries (a tuple, two floats, a counter and a child stance each) they were most of what a
search kept per vertex outside the lattice memo. A batch keeps them in arrays, sorted by the
key each would have had as an entry (f, then the tie counter it was given), and puts only its
first in the open list; when that one is popped, the next goes in. Every move keeps the key
and tie it had, so the open list pops the same moves in the same order as one entry a move
would, and the search makes the same decisions.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np


class MoveBatch:
    """Moves (boom j, anchor id, child stance) of `vertex`, all at cost-so-far `g` (the
    parent's g plus the least an edge costs), in the order of their keys (f, tie)."""

    __slots__ = ("_anchor", "_boom", "_child", "_f", "_next", "_tie", "g", "vertex")

    def __init__(self, vertex: tuple, g: float, f: list[float], tie: list[int],
                 boom: list[int], anchor: list[str], child: list[tuple]) -> None:
        self.vertex, self.g = vertex, g
        self._boom = np.asarray(boom, dtype=np.int8)
        self._anchor, self._child = anchor, child
        self._f = np.asarray(f, dtype=float)
        self._tie = np.asarray(tie, dtype=np.int64)
        self._sort()

    def _sort(self) -> None:
        order = np.lexsort((self._tie, self._f))
        self._f, self._tie, self._boom = self._f[order], self._tie[order], self._boom[order]
        self._anchor = [self._anchor[i] for i in order]
        self._child = [self._child[i] for i in order]
        self._next = 0

    def __len__(self) -> int:
        """The moves not yet handed out."""
        return len(self._f) - self._next

    def entry(self, kind: int) -> tuple:
        """The open-list entry of the next move: (f, tie, g, kind, child, this batch)."""
        i = self._next
        return (float(self._f[i]), int(self._tie[i]), self.g, kind, self._child[i], self)

    def pop(self) -> tuple[int, str]:
        """The next move's (boom, anchor id); the one after it becomes next."""
        i = self._next
        self._next += 1
        return int(self._boom[i]), self._anchor[i]

    def children(self) -> Iterator[tuple]:
        """The child stances of the moves not yet handed out."""
        return iter(self._child[self._next:])

    def rekeyed(self, heuristic: Callable[[tuple], float]) -> MoveBatch:
        """The moves not yet handed out, keyed g + heuristic(child) (a new weight), same ties."""
        rest = slice(self._next, None)
        children = self._child[rest]
        return MoveBatch(self.vertex, self.g, [self.g + heuristic(c) for c in children],
                         self._tie[rest].tolist(), self._boom[rest].tolist(),
                         self._anchor[rest], children)

    @property
    def nbytes(self) -> int:
        """The bytes of its arrays and lists (not the stances and ids they share)."""
        return int(self._f.nbytes + self._tie.nbytes + self._boom.nbytes) + \
            8 * (len(self._anchor) + len(self._child))
