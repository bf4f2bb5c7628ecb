"""What the two searches on the pose lattice share: the complete (and anytime) search
`planning.complete` and the fewest-regrasp search within a success probability
`planning.constrained`.

Both search the same graph (module doc of `planning.complete`): a vertex is a 4-stance with one
connected component of its feasible lattice poses, an edge a regrasp through a lattice pose.
Here are that graph's vocabulary (`Vertex`), what one scenario's searches decide once and keep
(`LatticeMemo`), their result (`CompleteResult`) and the steps both take the same way: a
stance's components (`stance_components`), a vertex's goal pose (`goal_pose_of`), an edge's most
robust poses (`best_poses`), and the kernel's thread count held for a whole search
(`threads_held`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Iterator
from typing import Any, NamedTuple

import networkx as nx
import numpy as np

from planning.astar import SearchResult
from planning.bounded_cache import BoundedCache, MemoryPool, array_bytes, release_free_heap
from planning.compact_keys import KeyCodec, mixed_radix, split_radix
from planning.components import Component, StanceComponents
from planning.lattice import LatticeConfig, poses_of, span_problem, unpack
from planning.lattice_moves import (
    LatticeTransition,
    MoveTable,
    lattice_transition,
    move_dict,
    pack_moves,
    pack_transition,
    unpack_moves,
    unpack_transition,
)
from planning.search_outcome import Quality, Stop
from rb_drake.errors import RbpInputError
from rb_drake.kernel.threads import held_kernel_threads
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario

Stance4 = tuple[str, str, str, str]
Vertex = tuple[Stance4, int]  # (stance, component)
ALTERNATIVES = 32  # transition poses kept per edge of the path, best first


def stance4(ids: Iterable[str]) -> Stance4:
    """Four anchor ids, one per boom, as a Stance4 (a ValueError for any other number)."""
    a, b, c, d = ids
    return a, b, c, d


# The memo's cap, MiB: with what a search keeps per vertex outside it, a search of 100,000
# vertices peaks under 2 GB (docs/benchmarks.md, session 21), one per core of a 24 GB machine
DEFAULT_MEMORY_MB = 768.0
# The process beyond the memo's cap: rbp and its libraries (about 250 MiB) and the search's own
# structures (about 6 kB a vertex on the 20 m crevasse: 100,000 vertices in 1681 MiB in all).
# Past cap + this, the memo gives way (1.75 GiB in all by default, under issue 31's 2 GB).
PROCESS_HEADROOM_MB = 1024.0
CACHES = ("components", "transitions", "moves")  # the memo's caches, sharing one cap


# What an entry holds besides its arrays' bytes (numpy headers, tuples, dict slots), measured by
# tracemalloc on a 5 m rockfall at 3 and 20 anchors a metre (a move table's entry: 210-231
# bytes; a transition: about 606; a stance's components: about 5,200): counted with them, so
# that the memo's cap bounds what it really holds (its arrays alone were 83 % of it at 20
# anchors a metre, where rows are short)
MOVE_ENTRY_BYTES = 220
TRANSITION_BYTES = 600
COMPONENTS_BYTES = 5200


def _transition_bytes(tr: LatticeTransition) -> int:
    return array_bytes(tr) + TRANSITION_BYTES


def _moves_bytes(table: MoveTable) -> int:
    return sum(rows.nbytes for rows in table.values()) + MOVE_ENTRY_BYTES * len(table)


class LatticeMemo:
    """Stance components and transitions already decided on one scenario (same lattice), in
    at most `memory_mb` MiB (None: no cap): past it the least recently used are dropped and
    decided again when asked for, with the same answers (`planning.bounded_cache`)."""

    def __init__(self, config: LatticeConfig | None = None,
                 memory_mb: float | None = DEFAULT_MEMORY_MB) -> None:
        self.config = config  # the lattice all of it was decided on
        self._scn: Scenario | None = None
        self._ignore_grasps = False
        self.pool = MemoryPool()
        # a stance's dropped components keep their seeds: a list of ints, 36 bytes each
        self.components: BoundedCache[tuple, StanceComponents] = BoundedCache(
            lambda sc: sc.nbytes + COMPONENTS_BYTES, self._components_again, lambda sc: sc.seeds,
            pool=self.pool, name="components", grows=True, pack=StanceComponents.packed,
            unpack=self._components_unpacked, version=lambda sc: len(sc.seeds),
            tombstone_size=lambda seeds: 56 + 36 * len(seeds))
        # transitions and move tables are dropped to their keys alone, kept compact
        self.transitions: BoundedCache[tuple, LatticeTransition] = BoundedCache(
            _transition_bytes, self._transition_again, pool=self.pool, name="transitions",
            pack=pack_transition, unpack=lambda _key, blob: unpack_transition(blob),
            codec=KeyCodec(self._transition_code, self._transition_key))
        self.moves: BoundedCache[Vertex, MoveTable] = BoundedCache(
            _moves_bytes, self._moves_again,
            pool=self.pool, name="moves", pack=pack_moves,
            unpack=lambda _vertex, blob: unpack_moves(blob),
            codec=KeyCodec(self._vertex_code, self._vertex_key))
        self.set_memory(memory_mb)

    def set_memory(self, memory_mb: float | None) -> None:
        """Cap what it holds at `memory_mb` MiB (None: no cap), and hold the whole process
        within that cap plus PROCESS_HEADROOM_MB by lowering it while the search's own
        structures grow (`MemoryPool.process_budget`)."""
        self.memory_mb = memory_mb
        self.pool.cap_bytes = None if memory_mb is None else float(memory_mb) * 2.0 ** 20
        self.pool.process_budget = (None if memory_mb is None
                                    else (float(memory_mb) + PROCESS_HEADROOM_MB) * 2.0 ** 20)
        if memory_mb is not None:
            release_free_heap()  # what earlier work freed is not this search's to count

    def move_table(self, vertex: Vertex) -> MoveTable:
        """Vertex (stance, component)'s moves: (boom, anchor index) -> its `move_rows`."""
        table = self.moves.get(vertex)
        if table is None:
            table = self.moves[vertex] = self._moves_again(vertex, None)
        return table

    def bind(self, scn: Scenario, cfg: LatticeConfig, ignore_grasps: bool) -> None:
        """Serve searches of `scn` on lattice `cfg`: what it drops is decided again there."""
        if problem := span_problem(scn, cfg):  # its indices would wrap onto other poses
            raise RbpInputError(problem, field="footstep.lattice.position_step")
        if self.config is None:
            self.config = cfg
        elif self.config != cfg:
            raise ValueError(f"a memo of lattice {self.config} cannot serve lattice {cfg}")
        if self._scn is not None and (not same_world(self._scn, scn)
                                      or self._ignore_grasps != ignore_grasps):
            raise ValueError("a memo serves the searches of one scenario (its start and goal "
                             "may differ), with or without grasps, not both")
        self._scn, self._ignore_grasps = scn, ignore_grasps

    def stats(self) -> dict[str, dict[str, float]]:
        """What each cache holds, held at most, dropped and rebuilt (`BoundedCache.stats`)."""
        return {"pool": self.pool.stats()} | {name: getattr(self, name).stats()
                                             for name in CACHES}

    def _bound(self) -> tuple[Scenario, LatticeConfig]:
        if self._scn is None or self.config is None:
            raise RuntimeError("a memo drops entries only once bound to a scenario")
        return self._scn, self.config

    def _rows(self) -> tuple[dict[str, int], int]:
        scn, _cfg = self._bound()
        return scn.anchor_index, len(scn.anchors)

    def _vertex_code(self, vertex: Vertex) -> int:
        """(stance, component) as an exact integer: the component, then the anchors' rows."""
        rows, n = self._rows()
        stance, comp = vertex
        return mixed_radix([comp] + [rows[a] for a in stance], [n] * len(stance))

    def _vertex_key(self, code: int) -> Vertex:
        scn, _cfg = self._bound()
        comp, a, b, c, d = split_radix(code, [len(scn.anchors)] * NUM_BOOMS)
        ids = [anchor.id for anchor in (scn.anchors[r] for r in (a, b, c, d))]
        return (ids[0], ids[1], ids[2], ids[3]), comp

    def _transition_code(self, key: tuple) -> int:
        """(stance, component, boom, anchor) as an exact integer."""
        rows, n = self._rows()
        stance, comp, boom, anchor = key
        return mixed_radix([self._vertex_code((stance, comp)), boom, rows[anchor]],
                           [NUM_BOOMS, n])

    def _transition_key(self, code: int) -> tuple:
        scn, _cfg = self._bound()
        vertex, boom, row = split_radix(code, [NUM_BOOMS, len(scn.anchors)])
        stance, comp = self._vertex_key(vertex)
        return stance, comp, boom, scn.anchors[row].id

    def _components_again(self, stance: tuple, seeds: list[int]) -> StanceComponents:
        scn, cfg = self._bound()
        return StanceComponents.replay(scn, stance, cfg, self._ignore_grasps, seeds)

    def _components_unpacked(self, stance: tuple, blob: bytes) -> StanceComponents:
        scn, cfg = self._bound()
        return StanceComponents.unpacked(scn, stance, cfg, self._ignore_grasps, blob)

    def _moves_again(self, vertex: Vertex, _: object) -> MoveTable:
        scn, _cfg = self._bound()
        stance, comp = vertex
        return move_dict(scn, self.components[stance].components[comp], stance)

    def _transition_again(self, key: tuple, _: object) -> LatticeTransition:
        scn, _cfg = self._bound()
        stance, comp, boom, anchor = key
        lat = self.components[stance].components[comp]
        return lattice_transition(scn, lat, stance, boom, anchor, self._ignore_grasps)


def same_world(a: Scenario, b: Scenario) -> bool:
    """Whether two scenarios share what a memo's lattice work depends on (rock, anchors, robot,
    gravity): searches of one cave to different goals or from different starts may share it."""
    return a is b or (a.walls is b.walls and a.anchors is b.anchors and a.robot == b.robot
                      and tuple(a.gravity) == tuple(b.gravity))


class SearchGraph:
    """The moves a lattice search evaluated and found to hold: (vertex, child) -> the least
    cost it found for the edge (the child a stance, or a vertex where the search knows its
    component), in one dict. A networkx graph kept about 1.3 kB a vertex of a long search (its
    node and adjacency dicts); this keeps about 0.25 kB. `as_networkx()` for analysis."""

    __slots__ = ("costs",)

    def __init__(self) -> None:
        self.costs: dict[tuple, float] = {}

    def add(self, u: Vertex, v: tuple, cost: float = math.inf) -> None:
        """Edge u -> v, its cost the least of `cost` and what it had."""
        old = self.costs.get((u, v))
        if old is None or cost < old:
            self.costs[u, v] = cost

    def update(self, other: SearchGraph) -> None:
        for (u, v), cost in other.costs.items():
            self.add(u, v, cost)

    def __len__(self) -> int:
        return len(self.costs)

    def edges(self) -> Iterator[tuple[Vertex, tuple, float]]:
        """(u, v, cost) for each edge."""
        for (u, v), cost in self.costs.items():
            yield u, v, cost

    def as_networkx(self) -> nx.DiGraph:
        """The edges as a networkx DiGraph, each with its cost, boom and anchor."""
        graph = nx.DiGraph()
        for (u, v), cost in self.costs.items():
            child = v if isinstance(v[0], str) else v[0]
            j = next((i for i, (a, b) in enumerate(zip(u[0], child, strict=True)) if a != b), -1)
            graph.add_edge(u, v, cost=cost, boom=j, anchor=child[j] if j >= 0 else None)
        return graph


class CompleteResult(NamedTuple):
    """A lattice search's result: the route as vertices and the transition poses between them,
    or why there is none (`stop`, `reason`), with what the search explored."""

    success: bool
    stop: Stop
    reason: str
    path: list[Vertex]
    poses: list[np.ndarray]        # transition pose per edge
    probabilities: list[np.ndarray]  # the four configurations' P per edge
    goal_pose: np.ndarray | None
    expansions: int
    transitions_tested: int
    expanded: list[tuple[Vertex, np.ndarray]]   # (vertex, pose reached at), in order
    frontier: list[tuple[Vertex, np.ndarray]]
    graph: SearchGraph
    # per edge, its most robust lattice poses in the component entered, best first (the
    # first is `poses`'): others for the pipeline where the gripper's path fails at the first
    alternatives: list[np.ndarray] | None = None
    cost: float = math.nan         # the route's cost (planning.search_cost)
    lower_bound: float = math.nan  # the optimal cost is at least this (anytime search)
    first_cost: float = math.nan   # the first route's cost (anytime search)
    # (seconds, best cost, lower bound, expansions) each time either improved (anytime search)
    history: list[tuple[float, float, float, int]] | None = None
    quality: Quality = Quality.FIRST
    # a failed search asked for it (`complete_search(partial=True)`): the route to the expanded
    # vertex nearest the goal
    partial: PartialRoute | None = None


class PartialRoute(NamedTuple):
    """The route, as the search reached it, to the expanded vertex nearest the goal (the
    smallest `search_cost.centroid_distance`, the failure message's measure; ties: the lowest
    cost): what `rbp plan --partial` climbs when no route reaches the goal."""

    path: list[Vertex]               # the start's vertex .. the nearest one
    poses: list[np.ndarray]          # transition pose per edge
    probabilities: list[np.ndarray]  # the four configurations' P per edge
    alternatives: list[np.ndarray]   # per edge, its most robust lattice poses, best first
    end_pose: np.ndarray             # where the body ends in the last stance (`end_pose_of`)
    cost: float                      # the route's search cost
    goal_distance: float             # m, the last stance's centroid distance from the goal


def stance_components(scn: Scenario, memo: LatticeMemo, stance: tuple, cfg: LatticeConfig,
                      ignore_grasps: bool) -> StanceComponents:
    """The components of `stance`'s feasible lattice poses, decided once per memo."""
    memo.bind(scn, cfg, ignore_grasps)
    hit = memo.components.get(stance)
    if hit is None:
        hit = memo.components[stance] = StanceComponents(scn, stance, cfg, ignore_grasps)
    return hit


def goal_pose_of(scn: Scenario, lat: Component) -> np.ndarray | None:
    """The most robust pose of component `lat` within the goal tolerance (None: none is): a
    vertex with one is a goal."""
    found = goal_pose_and_r(scn, lat)
    return None if found is None else found[0]


def goal_pose_and_r(scn: Scenario, lat: Component) -> tuple[np.ndarray, float] | None:
    """`goal_pose_of`'s pose and the 4-stance's robustness r (log P) there."""
    goal = np.asarray(scn.goal_position, dtype=float)
    lo, hi = lat.box  # no pose within the tolerance unless its bounding box is
    if float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - goal, goal - hi)))) > \
            scn.goal_tolerance:
        return None
    near = np.flatnonzero(np.linalg.norm(lat.poses[:, :2] - goal, axis=1) <= scn.goal_tolerance)
    if not len(near):
        return None
    best = near[int(np.argmax(lat.robustness[near]))]
    return lat.poses_at(np.array([best]))[0], float(lat.robustness[best])


def end_pose_of(scn: Scenario, lat: Component) -> np.ndarray:
    """Where a partial climb's body ends in component `lat`: as `goal_pose_of` picks the most
    robust pose within the goal tolerance of the goal, the most robust pose within the goal
    tolerance of the component's nearest approach to the goal (the very nearest pose lies on
    the edge of the feasible set, at p_min)."""
    poses = lat.poses
    d = np.linalg.norm(poses[:, :2] - np.asarray(scn.goal_position, dtype=float), axis=1)
    near = np.flatnonzero(d <= d.min() + scn.goal_tolerance)
    return poses[near[int(np.argmax(lat.robustness[near]))]].copy()


def best_poses(tr: LatticeTransition, pick: np.ndarray, cfg: LatticeConfig) -> tuple:
    """The transition's rows `pick`, most robust first (at most ALTERNATIVES): their lattice
    poses and the four configurations' P at the first, the edge's pose."""
    order = pick[np.argsort(-tr.worst[pick], kind="stable")[:ALTERNATIVES]]
    return poses_of(unpack(tr.keys[order], cfg.angle_count), cfg), np.exp(tr.r4[order[0]])


def threads_held(search: Callable[..., CompleteResult]) -> Callable[..., CompleteResult]:
    """The search with `kernel_threads()` read once, not at every fill and move."""
    @functools.wraps(search)
    def held(*args: Any, **kwargs: Any) -> CompleteResult:
        with held_kernel_threads():
            return search(*args, **kwargs)
    return held


def search_result(result: CompleteResult) -> SearchResult[Stance4]:
    """The result in `planning.astar`'s form, stances as nodes."""
    graph = nx.DiGraph()
    for (a, _), b, _cost in result.graph.edges():
        graph.add_edge(a, b, cost=0.0, data=None)
    return SearchResult(result.success, [v[0] for v in result.path], list(result.poses),
                        None, float("nan"), result.expansions, result.transitions_tested, graph,
                        result.reason, tuple(v[0] for v, _ in result.expanded),
                        {v[0]: p for v, p in result.expanded})
