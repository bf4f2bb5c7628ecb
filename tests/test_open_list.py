"""The complete search's open list: moves held as one entry per vertex (`MoveGroup`) pop in
exactly the order of one entry per move, and the search graph keeps each edge's least cost."""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np
import pytest

from planning.lattice_search import SearchGraph
from planning.open_list import DeferredMoves, Entry, MoveGroup, rekeyed
from rb_drake.scenario import bundled_caves, load_scenario


@pytest.fixture(scope="module")
def demo():
    return load_scenario(bundled_caves()["demo-shaft"])


def _key(child: tuple) -> float:
    """A heuristic of coarse values, so that ties between f are common and tie numbers
    decide."""
    return float(sum(ord(c) for a in child for c in a) % 4) * 0.25


def _groups(demo, rng: np.random.Generator, vertices: int) -> list[tuple]:
    """Random vertices of the demo's start stance with random moves: (vertex, g, moves),
    each move's f = g + _key(child) as the search keys them."""
    stance = tuple(demo.start_stance)
    tie = itertools.count()
    out = []
    for v in range(vertices):
        g = float(rng.uniform(0, 1))
        moves = []
        for _ in range(int(rng.integers(1, 12))):
            j, k = int(rng.integers(0, 4)), int(rng.integers(0, len(demo.anchors)))
            child = tuple(demo.anchors[k].id if i == j else a for i, a in enumerate(stance))
            moves.append((g + _key(child), next(tie), j, k, float(rng.uniform(0, 2))))
        out.append(((stance, v), g, moves))
    return out


def test_groups_pop_in_the_order_of_one_entry_per_move(demo) -> None:
    rng = np.random.default_rng(7)
    groups = _groups(demo, rng, 40)
    single = []  # one entry per move, as the search had them
    for vertex, g, moves in groups:
        for f, tie, j, k, _ in moves:
            heapq.heappush(single, (f, tie, g, Entry.MOVE, None, (vertex, j, demo.anchors[k].id)))
    grouped: list = []
    for vertex, g, moves in groups:
        heapq.heappush(grouped, MoveGroup(vertex, g, list(moves), _key).entry(demo, Entry.MOVES))
    popped = []
    while grouped:
        entry = heapq.heappop(grouped)
        group = entry[5]
        move = group.pop(demo, Entry.MOVE)
        if len(group):
            heapq.heappush(grouped, group.entry(demo, Entry.MOVES))
        assert move[:2] == entry[:2], "a group's entry is keyed by its first waiting move"
        popped.append(move)
    expected = [heapq.heappop(single) for _ in range(len(single))]
    assert len(popped) == len(expected) > 100
    for got, want in zip(popped, expected, strict=True):
        assert got[:4] == want[:4], f"popped {got[:4]}, one entry per move pops {want[:4]}"
        assert got[5] == want[5], f"move {got[5]} where one entry per move pops {want[5]}"
        vertex, j, anchor = got[5]
        child = got[4]
        assert child[j] == anchor and all(child[i] == vertex[0][i] for i in range(4) if i != j)


def test_least_and_rekey_cover_exactly_the_waiting_moves(demo) -> None:
    rng = np.random.default_rng(3)
    (vertex, g, moves), = _groups(demo, rng, 1)
    stance = vertex[0]
    for i in range(3):  # with large tie numbers: a wide group's codes
        child = tuple(demo.anchors[i].id if n == i % 4 else a for n, a in enumerate(stance))
        moves.append((g + _key(child), 10_000 + i, i % 4, i, float(i)))
    group = MoveGroup(vertex, g, list(moves), _key)
    order = sorted(moves)
    for n in range(len(order)):
        want = min(g + m[4] for m in order[n:])
        assert group.least() == pytest.approx(want, abs=1e-15), f"least after {n} pops"
        group.pop(demo, Entry.MOVE)
    assert group.least() == math.inf and len(group) == 0
    # keyed again: each f = g + key(child), sorted again, ties kept
    group = MoveGroup(vertex, g, list(moves), _key)
    entry = rekeyed(demo, group.entry(demo, Entry.MOVES), lambda child: 0.0,
                    lambda child: 1.0)
    assert entry[0] == pytest.approx(g) and entry[1] == min(m[1] for m in moves), (
        "with a constant key the first move is the one with the least tie number")
    assert group.least() == pytest.approx(g + 1.0), "the bounds are taken again too"


def test_deferred_moves_come_back_as_they_were_popped(demo) -> None:
    rng = np.random.default_rng(11)
    popped = []
    for vertex, g, moves in _groups(demo, rng, 10):
        group = MoveGroup(vertex, g, list(moves), _key)
        while len(group):
            popped.append(group.pop(demo, Entry.MOVE))
    store = DeferredMoves()
    bounds = rng.uniform(0, 3, len(popped))
    for entry, b in zip(popped, bounds, strict=True):
        store.add(entry, demo.anchor_index[entry[5][2]], float(b))
    assert len(store) == len(popped) > 20
    assert store.entries(demo, Entry.MOVE) == popped, "a deferred move came back changed"
    want = min(e[2] + b for e, b in zip(popped, bounds, strict=True))
    assert store.least == pytest.approx(want, abs=1e-15)
    store.clear()
    assert len(store) == 0 and store.least == math.inf


def test_search_graph_keeps_each_edges_least_cost(demo) -> None:
    stance = tuple(demo.start_stance)
    child = (demo.anchors[0].id, *stance[1:])
    graph = SearchGraph()
    graph.add((stance, 0), child)
    assert graph.costs[(stance, 0), child] == math.inf, "an edge not yet scored costs inf"
    graph.add((stance, 0), child, 2.0)
    graph.add((stance, 0), child, 3.0)
    other = SearchGraph()
    other.add((stance, 0), child, 1.5)
    other.add((stance, 1), (child, 0), 4.0)
    graph.update(other)
    assert dict(graph.costs) == {((stance, 0), child): 1.5, ((stance, 1), (child, 0)): 4.0}
    nxg = graph.as_networkx()
    assert nxg.number_of_edges() == 2
    data = nxg.edges[(stance, 0), child]
    assert (data["boom"], data["anchor"], data["cost"]) == (0, child[0], 1.5)
