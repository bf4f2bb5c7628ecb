"""What the complete search keeps per expanded vertex outside its memo (issue 31): its waiting
moves in 4-byte codes with no f or bound per move (`MoveGroup`), its parents without poses or
probabilities. Bounded by tracemalloc's bytes and by counts on a small dense cave, never by
time (docs/benchmarks.md, session 24: about 10 kB a vertex before on a 20 m rockfall at 20
anchors a metre)."""

from __future__ import annotations

import sys
import tracemalloc
from array import array

import numpy as np
import pytest

from planning.complete import CompleteConfig, complete_search
from planning.open_list import Entry, MoveGroup

FIRST, LAST = 100, 400  # expansions between the two snapshots
# bytes a vertex that the open list's and the search's own lines may allocate between them
# (measured 2026-11-28: 1976, of which 441 the memo's transition keys; 3034 before session 24)
OPEN_LIST_BYTES = 2400


@pytest.fixture(scope="module")
def dense():
    from experiments.common import make_cave

    return make_cave("rockfall", 5002, (5.0, 5.0), anchor_density=20.0)


class _EnoughError(Exception):
    pass


def _search_state(scn, last: int, first: int | None = None) -> dict:
    """Run the search to `last` expansions and return its locals then (and the tracemalloc
    snapshots at `first` and `last` when given)."""
    out: dict = {}

    def progress(expansions: int, *_args: object, **kwargs: object) -> None:
        if kwargs:
            return
        if expansions == first:
            out["first"] = tracemalloc.take_snapshot()
        if expansions == last:
            if first is not None:
                out["last"] = tracemalloc.take_snapshot()
            out["locals"] = dict(sys._getframe(1).f_locals)  # the search's own structures
            raise _EnoughError

    with pytest.raises(_EnoughError):
        complete_search(scn, CompleteConfig(max_expansions=None), progress=progress)
    return out


def test_waiting_moves_take_four_bytes_each_and_parents_no_arrays(dense) -> None:
    state = _search_state(dense, LAST)["locals"]
    groups = [e[5] for e in state["open_list"] if e[3] == Entry.MOVES]
    assert groups, "the search left no vertex's moves waiting"
    moves = sum(len(g.code) for g in groups)
    kept = sum(g.code.itemsize * len(g.code) + g.values.itemsize * len(g.values)
               for g in groups)
    assert all(isinstance(g, MoveGroup) and g.code.typecode == "I" for g in groups), (
        "a group's codes took 8 bytes on a cave of a few hundred anchors")
    assert kept <= 4 * moves + 32 * len(groups), (
        f"the waiting moves keep {kept / moves:.1f} bytes each in their groups' arrays: at most "
        "4 (the code) and a few runs of least bounds per group; 24 before session 24 (f, "
        "bound and code per move)")
    for vertex, value in state["parent"].items():
        assert len(value) == 3 and not any(
            isinstance(x, np.ndarray) and x.dtype.kind == "f" for x in value), (
            f"the parent of {vertex} keeps {value}: (move, rows, cost) only, the pose and P4 "
            "are found again for the route's edges")


def test_open_list_bytes_per_vertex(dense) -> None:
    tracemalloc.start(1)
    try:
        state = _search_state(dense, LAST, FIRST)
    finally:
        tracemalloc.stop()
    diff = state["last"].compare_to(state["first"], "filename")
    per_vertex = sum(d.size_diff for d in diff if d.traceback[0].filename.endswith(
        ("planning/open_list.py", "planning/complete.py"))) / (LAST - FIRST)
    assert per_vertex <= OPEN_LIST_BYTES, (
        f"the open list and the search's own dicts grew by {per_vertex:.0f} bytes a vertex "
        f"between expansions {FIRST} and {LAST} of a 5 m rockfall at 20 anchors a metre (at "
        f"most {OPEN_LIST_BYTES}, 3034 before session 24: a waiting move 4 bytes, a parent no "
        "arrays)")
    assert isinstance(state["locals"]["expanded"], list)
    assert array("I").itemsize == 4
