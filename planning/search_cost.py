"""The footstep search's cost and heuristic: what an edge costs, and a lower bound on the rest.

Cost. The plan's success probability is p_path = prod_holdings min_t P_i(t) * (1 - p_att)^regrasps
(planning.probability). An edge (a regrasp) costs -log(1 - p_att) plus, for each boom, the worst
-log P_i over the move's four configurations at its transition pose (`boom_costs`); summed along
a path this bounds -log p_path from above (over the configurations the footstep plan knows), so
minimising it favours both few regrasps and robust grasps.

Heuristics. `DistanceHeuristic` orders the search for a first route: a regrasp moves one of
four anchors by at most 2 (L_max + |s|), so the anchors' centroid advances at most `max_step`
per regrasp, and h = -log(1 - p_att) * goal_distance / max_step estimates the regrasps left.
It is not a strict lower bound (`goal_distance` also counts a lagging anchor's distance beyond
reach, which one regrasp can remove, and a goal stance's centroid may lie beyond the goal
tolerance); the searches multiply it by their `heuristic_weight` anyway. `RegraspHeuristic` is
the admissible, consistent bound: it prunes, and proves how far a route is from the optimum.

Both searches (`planning.footsteps`' sampled one and `planning.complete`) take their cost and
heuristic from here, so a new heuristic is written once.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import csr_matrix

from planning.lattice_kernels import transition_boom_costs
from rb_drake.kernel.collision import packed_rock
from rb_drake.kernel.layout import ALL_SEGMENTS, robot_params
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.scenario import Scenario

# Stances whose heuristic values a search keeps for reuse: past it they are forgotten and
# computed again (the same values), so that a long search's caches stay within ~50 MB
CACHED_STANCES = 1 << 17


def attach_cost(robot: RobotParams) -> float:
    """-log(1 - p_att): what every regrasp costs before its grasps (at least 1e-9, so that the
    heuristic stays informative when attaching never fails)."""
    c = -math.log(1.0 - robot.attach_failure) if robot.attach_failure < 1 else 1e3
    return max(c, 1e-9)


def boom_costs(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str,
               pose: np.ndarray) -> np.ndarray:
    """Per boom, the worst -log P_i over the transition's four configurations at `pose`: old
    4-stance, 3-stance with the gripper at its old and at its new anchor, new 4-stance (a
    free boom's entry counts 0), in one compiled call (`transition_boom_costs`)."""
    table = scn.anchor_table
    free = len(table.row)
    held = [table.row[a] for a in old]
    target = table.row[new_anchor]
    rows = np.array([held, held, held], dtype=np.int64)
    rows[1, boom] = free
    rows[2, boom] = target
    return transition_boom_costs(
        np.ascontiguousarray(pose, dtype=float).reshape(3),
        robot_params(scn.robot, scn.gravity_vector), table.positions, table.normals,
        table.f_normal, table.f_lateral, table.sigma_normal, table.sigma_lateral, rows,
        np.array([held[boom], target], dtype=np.int64), *packed_rock(scn.rock), False, False,
        ALL_SEGMENTS)


def edge_cost(scn: Scenario, old: tuple[str, ...], boom: int, new_anchor: str,
              pose: np.ndarray) -> float:
    """An edge's cost: the regrasp's attach cost plus `boom_costs` at its transition pose.
    Without the grasps' probabilities (`ignore_grasps`) a pose's tensions may make -log P_i
    near the largest float: their sum is infinite, as it is meant to be, without numpy's
    overflow warning on the user's terminal."""
    with np.errstate(over="ignore"):
        total = float(boom_costs(scn, old, boom, new_anchor, pose).sum())
    return attach_cost(scn.robot) + total


def centroid_distance(scn: Scenario, stance: tuple[str, ...]) -> float:
    c = scn.anchor_positions[[scn.anchor_index[a] for a in stance]].mean(axis=0)
    return float(np.linalg.norm(c - np.asarray(scn.goal_position)))


def goal_distance(scn: Scenario, stance: tuple[str, ...]) -> float:
    """How far a stance is from one that can hold the goal pose: the centroid's distance beyond
    the goal tolerance, plus each anchor's distance beyond reach of the goal (a lagging boom
    must step before the goal can be held, however close the centroid is)."""
    pts = scn.anchor_positions[[scn.anchor_index[a] for a in stance]]
    goal = np.asarray(scn.goal_position)
    radius = scn.robot.max_reach + scn.goal_tolerance
    lag = np.maximum(0.0, np.linalg.norm(pts - goal, axis=1) - radius).sum()
    return max(0.0, centroid_distance(scn, stance) - scn.goal_tolerance) + float(lag)


class DistanceHeuristic:
    """h(stance) = -log(1 - p_att) * goal_distance / max_step, memoised per stance (module
    doc): an estimate of the cost to go that orders the first-route search (unweighted)."""

    def __init__(self, scn: Scenario) -> None:
        self.scn = scn
        self.c_attach = attach_cost(scn.robot)
        self.max_step = 2.0 * scn.robot.max_reach / 4.0
        self._distances: dict[tuple, float] = {}

    def distance(self, stance: tuple[str, ...]) -> float:
        d = self._distances.get(stance)
        if d is None:
            if len(self._distances) >= CACHED_STANCES:
                self._distances.clear()
            d = self._distances[stance] = goal_distance(self.scn, stance)
        return d

    def __call__(self, stance: tuple[str, ...]) -> float:
        return self.c_attach * self.distance(stance) / self.max_step


def boom_hop_length(robot: RobotParams) -> float:
    """The farthest one regrasp can move boom j's gripper: the old and the new anchor are both
    reached from shoulder j at the transition pose, at most L_max away, along directions within
    the shoulder range of one axis, so at most 2 * range apart; the chord of two such vectors is
    at most L_max * max(1, 2 sin(min(2 range, pi) / 2))."""
    spread = min(2.0 * robot.shoulder_range, math.pi)
    return robot.boom_length[1] * max(1.0, 2.0 * math.sin(spread / 2.0))


def hop_graph(scn: Scenario) -> csr_matrix:
    """(anchors, anchors) sparse: the relaxed graph's edges, anchors at most `boom_hop_length`
    apart (every move of a boom joins two of them), each stored with its length (an anchor's
    edge to itself is left out; two anchors at the same point get a length of 1e-12, since a
    sparse matrix's zero means no edge). Found with a k-d tree, so that memory grows with the
    edges, not with the square of the anchors (a 300 m cave holds 12,000)."""
    from scipy.spatial import cKDTree

    pts = np.asarray(scn.anchor_positions, dtype=float)
    hop = boom_hop_length(scn.robot) * (1.0 + 1e-9) + 1e-9
    pairs = cKDTree(pts).query_pairs(hop, output_type="ndarray")
    lengths = np.maximum(np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1), 1e-12)
    n = len(pts)
    rows = np.concatenate([pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([pairs[:, 1], pairs[:, 0]])
    return csr_matrix((np.concatenate([lengths, lengths]), (rows, cols)), shape=(n, n))


def hops_from(adjacent: csr_matrix, sources: np.ndarray) -> np.ndarray:
    """The fewest edges of `adjacent` (`hop_graph`) from any anchor of `sources` (bool) to each
    anchor (breadth-first; inf where none leads)."""
    hops = np.full(adjacent.shape[0], np.inf)
    frontier, level = np.flatnonzero(sources), 0
    while len(frontier):
        hops[frontier] = level
        level += 1
        reached = np.unique(adjacent[frontier].indices)
        frontier = reached[np.isinf(hops[reached])]
    return hops


ORIENTATION_CELLS = 36  # the goal pose's orientation, in cells of 10 deg (RegraspHeuristic)


def goal_targets(scn: Scenario, cells: int = ORIENTATION_CELLS) -> np.ndarray:
    """(cells, 4, anchors) bool: whether boom j may hold the anchor in a stance that holds a
    goal pose whose orientation lies in cell k, [-pi + k d, -pi + (k + 1) d], d = 2 pi / cells.

    A superset, so that a bound built on it never overestimates: at such a pose (centre c within
    the goal tolerance of G, orientation theta in the cell) boom j's shoulder s lies within
    rho = tolerance + |s_j| d / 2 of q = G + R(theta_mid) s_j, and the anchor lies in the boom's
    sector from s (length at most L_max, direction within the shoulder range of theta + d_j),
    a subset of the sector from s widened by d / 2 each side; so a - q lies within rho of that
    widened sector, and the test is a lower bound of the distance to it (the larger of the
    distances beyond L_max and to the sector's infinite cone)."""
    robot = scn.robot
    pts = scn.anchor_positions
    goal = np.asarray(scn.goal_position, dtype=float)
    step = 2.0 * math.pi / cells
    shoulders = robot.shoulder_array
    out = np.zeros((cells, 4, len(pts)), dtype=bool)
    for k in range(cells):
        mid = -math.pi + (k + 0.5) * step
        c, s = math.cos(mid), math.sin(mid)
        for j in range(NUM_BOOMS):
            q = goal + np.array([c * shoulders[j, 0] - s * shoulders[j, 1],
                                 s * shoulders[j, 0] + c * shoulders[j, 1]])
            rho = scn.goal_tolerance + float(np.linalg.norm(shoulders[j])) * step / 2.0
            v = pts - q
            r = np.linalg.norm(v, axis=1)
            off = np.arctan2(v[:, 1], v[:, 0]) - mid - robot.shoulder_directions[j]
            beyond = np.abs((off + math.pi) % (2.0 * math.pi) - math.pi) - (
                robot.shoulder_range + step / 2.0)
            to_cone = np.where(beyond <= 0.0, 0.0,
                               np.where(beyond < math.pi / 2,
                                        r * np.sin(np.clip(beyond, 0.0, math.pi / 2)), r))
            gap = np.maximum(r - robot.boom_length[1], to_cone)
            out[k, j] = gap <= rho * (1.0 + 1e-9) + 1e-7
    return out


class _CellTable:
    """min_k sum_j table[k, j, a_j] for a stance (a_0..a_3), memoised: both bounds' regrasps,
    a per-boom table over the anchors for each orientation cell of the goal."""

    def __init__(self, scn: Scenario, table: np.ndarray) -> None:
        self.table = table
        self._booms = np.arange(NUM_BOOMS)
        self._row = scn.anchor_index
        self._cache: dict[tuple, float] = {}

    def __call__(self, stance: tuple[str, ...]) -> float:
        h = self._cache.get(stance)
        if h is None:
            if len(self._cache) >= CACHED_STANCES:
                self._cache.clear()
            rows = [self._row[a] for a in stance]
            h = self._cache[stance] = float(self.table[:, self._booms, rows].sum(axis=1).min())
        return h


class RegraspHeuristic:
    """A lower bound on the cost to go from the regrasps each boom still needs.

    Relaxed graph, one per boom j: its vertices are the anchors, an edge joins two anchors at
    most `boom_hop_length` apart (every move of boom j is one of them). A route ends in a
    stance holding a goal pose of some orientation theta, where boom j's anchor is one that
    boom j reaches from there: for each cell k of orientations, the targets T_jk are
    `goal_targets`' superset of those anchors. hops_jk(a), the fewest edges from a to T_jk
    (breadth-first from the targets), is at most the regrasps boom j still needs if the route
    ends at an orientation in cell k; the booms share that orientation, and every regrasp costs
    at least -log(1 - p_att), so

        h(stance) = -log(1 - p_att) * min_k sum_j hops_jk(a_j)

    never overestimates. It is consistent too: a regrasp moves one boom along one edge, which
    changes each hops_jk by at most 1 and so the minimum by at most 1, and costs at least
    -log(1 - p_att); a stance with no cell where every boom has a path gets h = inf (no route
    passes it). The tables are computed once per scenario."""

    def __init__(self, scn: Scenario, cells: int = ORIENTATION_CELLS) -> None:
        self.scn = scn
        self.c_attach = attach_cost(scn.robot)
        adjacent = hop_graph(scn)
        targets = goal_targets(scn, cells)
        # hops[k, j, a]; boom j's tables differ between cells only through their targets
        self.hops = np.full(targets.shape, np.inf)
        for k in range(cells):
            for j in range(NUM_BOOMS):
                self.hops[k, j] = hops_from(adjacent, targets[k, j])
        self._regrasps = _CellTable(scn, self.hops)

    def regrasps(self, stance: tuple[str, ...]) -> float:
        """min_k sum_j hops_jk(a_j): the fewest regrasps the relaxed graphs allow (inf: none)."""
        return self._regrasps(stance)

    def __call__(self, stance: tuple[str, ...]) -> float:
        return self.c_attach * self.regrasps(stance)


class TravelHeuristic:
    """A lower bound on the cost to go from how far each boom's gripper must still travel.

    In `RegraspHeuristic`'s relaxed graph with each edge as long as its anchors are apart,
    travel_jk(a) is the shortest path from anchor a to boom j's targets T_jk (Dijkstra from the
    targets). Boom j's moves along a route are such a path, each move at most H =
    `boom_hop_length` long, so boom j still needs at least travel_jk(a_j) / H regrasps if the
    route ends at an orientation in cell k, and

        h(stance) = -log(1 - p_att) * min_k sum_j travel_jk(a_j) / H

    never overestimates; a regrasp moves one boom along one edge, which lowers its travel by
    at most the edge's length <= H, so h is consistent too. As a bound it is weaker than
    `RegraspHeuristic` (a path of n hops is at most n H long); as an order it is better: it
    measures the distance each boom has left, where the hop count rounds it to the most
    generous hops, and multiplied by a weight it leads the search to routes with few regrasps
    (docs/model.md, "The order of the search")."""

    def __init__(self, scn: Scenario, cells: int = ORIENTATION_CELLS) -> None:
        from scipy.sparse.csgraph import dijkstra

        self.c_attach = attach_cost(scn.robot)
        self.hop = boom_hop_length(scn.robot)
        lengths = hop_graph(scn)  # each edge its length: csgraph's convention
        targets = goal_targets(scn, cells)
        self.travel = np.full(targets.shape, np.inf)
        for k in range(cells):
            for j in range(NUM_BOOMS):
                sources = np.flatnonzero(targets[k, j])
                if len(sources):
                    self.travel[k, j] = dijkstra(lengths, directed=False, indices=sources,
                                                 min_only=True)
        self._regrasps = _CellTable(scn, self.travel / self.hop)

    def regrasps(self, stance: tuple[str, ...]) -> float:
        """min_k sum_j travel_jk(a_j) / H: the fewest regrasps the travel allows (inf: none)."""
        return self._regrasps(stance)

    def __call__(self, stance: tuple[str, ...]) -> float:
        return self.c_attach * self.regrasps(stance)
