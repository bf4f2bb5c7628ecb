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

import dataclasses
import functools
import math
from collections.abc import Callable, Iterable
from typing import Any, NamedTuple

import networkx as nx
import numpy as np

from planning.astar import SearchResult
from planning.components import Component, StanceComponents
from planning.lattice import LatticeConfig, poses_of, unpack
from planning.lattice_moves import LatticeTransition
from planning.search_outcome import Quality, Stop
from rb_drake.kernel.threads import held_kernel_threads
from rb_drake.scenario import Scenario

Stance4 = tuple[str, str, str, str]
Vertex = tuple[Stance4, int]  # (stance, component)
ALTERNATIVES = 32  # transition poses kept per edge of the path, best first


def stance4(ids: Iterable[str]) -> Stance4:
    """Four anchor ids, one per boom, as a Stance4 (a ValueError for any other number)."""
    a, b, c, d = ids
    return a, b, c, d


@dataclasses.dataclass
class LatticeMemo:
    """Stance components and transitions already decided on one scenario (same lattice)."""

    components: dict[tuple, StanceComponents] = dataclasses.field(default_factory=dict)
    transitions: dict[tuple, LatticeTransition] = dataclasses.field(default_factory=dict)
    config: LatticeConfig | None = None  # the lattice all of it was decided on


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
    graph: nx.DiGraph
    # per edge, its most robust lattice poses in the component entered, best first (the
    # first is `poses`'): others for the pipeline where the gripper's path fails at the first
    alternatives: list[np.ndarray] | None = None
    cost: float = math.nan         # the route's cost (planning.search_cost)
    lower_bound: float = math.nan  # the optimal cost is at least this (anytime search)
    first_cost: float = math.nan   # the first route's cost (anytime search)
    # (seconds, best cost, lower bound, expansions) each time either improved (anytime search)
    history: list[tuple[float, float, float, int]] | None = None
    quality: Quality = Quality.FIRST


def stance_components(scn: Scenario, memo: LatticeMemo, stance: tuple, cfg: LatticeConfig,
                      ignore_grasps: bool) -> StanceComponents:
    """The components of `stance`'s feasible lattice poses, decided once per memo."""
    hit = memo.components.get(stance)
    if hit is None:
        hit = memo.components[stance] = StanceComponents(scn, stance, cfg, ignore_grasps)
    return hit


def goal_pose_of(scn: Scenario, lat: Component) -> np.ndarray | None:
    """The most robust pose of component `lat` within the goal tolerance (None: none is): a
    vertex with one is a goal."""
    goal = np.asarray(scn.goal_position, dtype=float)
    lo, hi = lat.box  # no pose within the tolerance unless its bounding box is
    if float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - goal, goal - hi)))) > \
            scn.goal_tolerance:
        return None
    near = np.flatnonzero(np.linalg.norm(lat.poses[:, :2] - goal, axis=1) <= scn.goal_tolerance)
    if not len(near):
        return None
    return lat.poses_at(near[[int(np.argmax(lat.robustness[near]))]])[0]


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
    for (a, _), b in result.graph.edges():
        graph.add_edge(a, b, cost=0.0, data=None)
    return SearchResult(result.success, [v[0] for v in result.path], list(result.poses),
                        None, float("nan"), result.expansions, result.transitions_tested, graph,
                        result.reason, tuple(v[0] for v, _ in result.expanded),
                        {v[0]: p for v, p in result.expanded})
