"""A vertex's moves as one open-list entry pop in the order their own entries would."""

from __future__ import annotations

import heapq
import itertools

import numpy as np

from planning.move_batch import MoveBatch

MOVE, MOVES, OTHER = 1, 2, 0


def _pops(seed: int, batched: bool) -> list[tuple]:
    """Expand 40 random 'vertices' of up to 20 moves each (keys with many ties, as weighted
    keys have), interleaved with other entries pushed and pops; the popped moves in order."""
    rng = np.random.default_rng(seed)
    tie = itertools.count()
    heap: list = []
    popped: list[tuple] = []
    for v in range(40):
        n = int(rng.integers(0, 20))
        g = float(rng.integers(0, 3))
        keys = (g + rng.integers(0, 4, n) * 0.5).tolist()  # repeated keys: ties decide
        ties = [next(tie) for _ in range(n)]
        booms = rng.integers(0, 4, n).tolist()
        anchors = [f"a{int(k)}" for k in rng.integers(0, 50, n)]
        children = [(v, i) for i in range(n)]
        if batched and n:
            batch = MoveBatch(("v", v), g, keys, ties, booms, anchors, children)
            heapq.heappush(heap, batch.entry(MOVES))
        elif not batched:
            for k, t, j, a, c in zip(keys, ties, booms, anchors, children, strict=True):
                heapq.heappush(heap, (k, t, g, MOVE, c, (("v", v), j, a)))
        heapq.heappush(heap, (float(rng.integers(0, 6)) * 0.5, next(tie), 0.0, OTHER, None, v))
        for _ in range(int(rng.integers(0, 25))):
            if not heap:
                break
            f, t, g_e, kind, child, payload = heapq.heappop(heap)
            if kind == MOVES:
                j, a = payload.pop()
                if len(payload):
                    heapq.heappush(heap, payload.entry(MOVES))
                payload = (payload.vertex, j, a)
            popped.append((f, t, g_e, child, payload))
    while heap:
        f, t, g_e, kind, child, payload = heapq.heappop(heap)
        if kind == MOVES:
            j, a = payload.pop()
            if len(payload):
                heapq.heappush(heap, payload.entry(MOVES))
            payload = (payload.vertex, j, a)
        popped.append((f, t, g_e, child, payload))
    return popped


def test_batches_pop_as_their_moves_would() -> None:
    for seed in range(20):
        single, batched = _pops(seed, False), _pops(seed, True)
        assert single == batched, f"seed {seed}: the batched open list popped another order"


def test_rekeyed_keeps_ties_and_the_moves_left() -> None:
    batch = MoveBatch(("v", 0), 1.0, [3.0, 2.0, 2.0], [10, 11, 12], [0, 1, 2], ["a", "b", "c"],
                      [("x",), ("y",), ("z",)])
    assert batch.pop() == (1, "b"), "lowest key, then lowest tie, first"
    h = {("x",): 0.5, ("y",): 9.0, ("z",): 0.25}
    again = batch.rekeyed(h.__getitem__)
    assert len(again) == 2, "a move already handed out is not handed out again"
    assert again.entry(MOVES)[:2] == (1.25, 12), again.entry(MOVES)
    assert again.pop() == (2, "c") and again.pop() == (0, "a")
    assert again.nbytes > 0
