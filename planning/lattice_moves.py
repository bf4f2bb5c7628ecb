"""A vertex's moves, decided on the pose lattice, for the complete search (planning.complete).

For a component of a stance's feasible lattice poses: the rows at which a boom may let go and
reach a new anchor with its segment clear of rock (`move_rows`, all of a vertex's moves at once
in `move_table`), every lattice pose that holds the whole transition (`lattice_transition`,
looked up where the new stance's components already decide it), the components the start pose
joins (`start_components`) and whether any lattice pose near the goal could hold a stance at
all (`goal_is_holdable`). Each is exact on the lattice (tests/test_complete_search.py checks
them against brute force); what it means is docs/model.md's "The complete footstep search".
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Collection, Iterator
from typing import NamedTuple

import numpy as np

from planning.components import UNKNOWN, Component, StanceComponents
from planning.lattice import SPAN, LatticeConfig, pack
from planning.lattice_kernels import (
    lattice_move_kernel,
    lattice_move_table,
    lattice_reach_rows,
    reach_violation,
)
from planning.packing import pack_arrays, unpack_arrays
from rb_drake.feasibility import body_in_rock
from rb_drake.kernel.collision import packed_rock
from rb_drake.kernel.layout import robot_params
from rb_drake.kernel.scoring import score_poses
from rb_drake.kernel.threads import kernel_threads
from rb_drake.params import NUM_BOOMS
from rb_drake.scenario import Scenario


class LatticeTransition(NamedTuple):
    """Every lattice pose of component `component` of `stance` that holds boom `boom`'s move
    to `anchor`, with the worst of the four configurations' r and each one's r."""

    keys: np.ndarray      # (E,) lattice keys (sorted)
    worst: np.ndarray     # (E,)
    r4: np.ndarray        # (E, 4) CONFIG_NAMES order
    tested: int           # lattice poses tested


def _lattice_grid(cfg: LatticeConfig) -> tuple:
    """The lattice arguments of the compiled kernels that decode keys: span, dx, dphi, n."""
    return SPAN, float(cfg.position_step), float(cfg.angle_step), int(cfg.angle_count)


def _lattice_args(scn: Scenario, cfg: LatticeConfig) -> tuple:
    """The robot and lattice arguments of the compiled reach kernels."""
    return (robot_params(scn.robot, _NO_GRAVITY), *_lattice_grid(cfg))


_NO_GRAVITY = np.zeros(2)  # the reach tests' robot parameters need none


def move_rows(scn: Scenario, lat: Component, boom: int, anchor: str) -> np.ndarray:
    """Rows of component `lat` at which boom `boom` may let go and reaches `anchor` (the reach
    test of `reach_violation`), its segment to `anchor` clear of rock (the kernel's test of
    it): the poses a transition of that move can use, decided in one compiled pass."""
    target = scn.anchor_positions[scn.anchor_index[anchor]]
    return lattice_reach_rows(lat.keys, lat.boom_release_rows(boom), float(target[0]),
                              float(target[1]), int(boom), *_lattice_args(scn, lat.lattice),
                              packed_rock(scn.rock)[0])


def lattice_transition(scn: Scenario, lat: Component, stance: tuple, boom: int, anchor: str,
                       ignore_grasps: bool = False, rows: np.ndarray | None = None,
                       arrival: StanceComponents | None = None,
                       labels: np.ndarray | None = None) -> LatticeTransition:
    """Decide boom `boom`'s move to `anchor` from component `lat` of `stance` on every lattice
    pose (see the module doc); `rows`: `move_rows`, if known. `arrival`: the new stance's
    components found so far, if any: a pose they already decide (in a component, or scored
    infeasible) is looked up, not scored again (the same answer: module doc); `labels`:
    `arrival.known_component` of the rows' keys, if known."""
    rows = move_rows(scn, lat, boom, anchor) if rows is None else rows
    tested = len(rows)
    if arrival is None or not tested:
        return _scored_transition(scn, lat, stance, boom, anchor, ignore_grasps, rows, tested)
    if labels is None:
        labels = arrival.known_component(lat.keys[rows])
    parts = [_scored_transition(scn, lat, stance, boom, anchor, ignore_grasps,
                                rows[labels == UNKNOWN], tested)]
    for c in sorted(set(labels[labels >= 0].tolist())):  # np.unique, at a tenth of its cost
        # In component c of the new stance S': feasible there, its segment to the new anchor
        # clear, and the 3-stance with the gripper at the new anchor is S''s release set of
        # this boom, decided by the flood fill with the same operations.
        src = rows[labels == c]
        comp = arrival.components[int(c)]
        at = np.searchsorted(comp.keys, lat.keys[src])
        ok = comp.release[at, boom]
        src, at = src[ok], at[ok]
        r4 = np.column_stack([lat.robustness[src], lat.release_r[src, boom],
                              comp.release_r[at, boom], comp.robustness[at]])
        parts.append(LatticeTransition(lat.keys[src], r4.min(axis=1), r4, tested))
    keys = np.concatenate([p.keys for p in parts])
    order = np.argsort(keys, kind="stable")
    return LatticeTransition(keys[order], np.concatenate([p.worst for p in parts])[order],
                             np.concatenate([p.r4 for p in parts])[order], tested)


def _scored_transition(scn: Scenario, lat: Component, stance: tuple, boom: int, anchor: str,
                       ignore_grasps: bool, rows: np.ndarray, tested: int) -> LatticeTransition:
    """The move decided by the kernel on `rows` of `lat` (`lattice_transition`)."""
    if not len(rows):
        return LatticeTransition(np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 4)), tested)
    table = scn.anchor_table
    free = len(table.row)
    held = [table.row[a] for a in stance]
    stance_rows = np.array([held, held], dtype=np.int64)
    stance_rows[0, boom] = free  # the 3-stance, its gripper at the new anchor (tip 0)
    stance_rows[1, boom] = table.row[anchor]  # the new 4-stance
    # The 3-stance first (its tensions are unique: cheap), the new 4-stance where it holds.
    # Every segment but the freed boom's to its new anchor is the old 4-stance's, clear at
    # these poses, and that one is clear at every row of `move_rows` (the kernel's own test of
    # it), so neither configuration tests a segment again. The new 4-stance's
    # release set of this boom is the 3-stance with the gripper at the new anchor as the
    # attach ramp starts, the gripper counted unloaded (the first test, without that grasp,
    # is a necessary condition of it, and it decided the freed boom's segment).
    kept, arrive, r_new = lattice_move_kernel(
        lat.keys, np.ascontiguousarray(rows, dtype=np.int64), int(boom),
        *_lattice_grid(lat.lattice), robot_params(scn.robot, scn.gravity_vector),
        table.positions, table.normals, table.f_normal, table.f_lateral, table.sigma_normal,
        table.sigma_lateral, stance_rows, np.array([table.row[anchor], free], dtype=np.int64),
        *packed_rock(scn.rock), bool(ignore_grasps), True, 0, kernel_threads())
    r4 = np.empty((len(kept), 4))
    r4[:, 0], r4[:, 1], r4[:, 2], r4[:, 3] = (lat.robustness[kept], lat.release_r[kept, boom],
                                              arrive, r_new)
    return LatticeTransition(lat.keys[kept], r4.min(axis=1), r4, tested)


def _near_anchors(scn: Scenario, lat: Component, stance: tuple) -> np.ndarray:
    """Indices of the anchors within reach (boom length plus shoulder offset) of component
    `lat`'s bounding box, the stance's own anchors excluded: no other can be a move's."""
    pts = scn.anchor_positions
    lo, hi = lat.box
    gap = np.linalg.norm(np.maximum(0.0, np.maximum(lo - pts, pts - hi)), axis=1)
    near = gap <= scn.robot.max_reach + 1e-6
    near[[scn.anchor_index[a] for a in stance]] = False
    return np.flatnonzero(near)


def move_table(scn: Scenario, lat: Component, stance: tuple) -> list[list[tuple[int, np.ndarray]]]:
    """Per boom, every move of component `lat` that some pose can use: (anchor index, its
    `move_rows`) for each anchor that the boom reaches from a release pose with its segment
    there clear of rock, in one compiled pass over the component (`lattice_move_table`). The
    anchors the boom reaches but whose every such segment meets rock are left out: no pose
    holds their move (the 3-stance with the gripper at the new anchor tests that segment)."""
    pts = scn.anchor_positions
    near = _near_anchors(scn, lat, stance)
    if not len(near):
        return [[] for _ in range(NUM_BOOMS)]
    rows, offsets = lattice_move_table(lat.keys, lat.release_rows, lat.release_starts,
                                       np.ascontiguousarray(pts[near]),
                                       *_lattice_args(scn, lat.lattice),
                                       packed_rock(scn.rock)[0])
    K = len(near)
    at, anchors = offsets.tolist(), near.tolist()  # Python ints: numpy scalars cost 10x
    return [[(anchors[k], rows[at[j * K + k]:at[j * K + k + 1]])
             for k in range(K) if at[j * K + k + 1] > at[j * K + k]]
            for j in range(NUM_BOOMS)]


MoveTable = dict[tuple[int, int], np.ndarray]  # (boom, anchor index) -> its `move_rows`


def move_dict(scn: Scenario, lat: Component, stance: tuple) -> MoveTable:
    """`move_table` as one dict, boom by boom in its order: (boom, anchor index) -> rows."""
    return {(j, k): rows for j, moves in enumerate(move_table(scn, lat, stance))
            for k, rows in moves}


def pack_transition(tr: LatticeTransition) -> bytes:
    """A transition packed losslessly (`unpack_transition`; `planning.packing`)."""
    return pack_arrays([tr.keys, tr.worst, tr.r4, np.array([tr.tested], dtype=np.int64)],
                       ["delta", "plain", "plain", "plain"])


def unpack_transition(blob: bytes) -> LatticeTransition:
    """The transition `pack_transition` packed."""
    keys, worst, r4, tested = unpack_arrays(blob)
    return LatticeTransition(keys, worst, r4, int(tested[0]))


def pack_moves(table: MoveTable) -> bytes:
    """A move table packed losslessly, its order kept (`unpack_moves`; `planning.packing`)."""
    keys = np.array(list(table), dtype=np.int64).reshape(-1, 2)
    lengths = np.array([len(rows) for rows in table.values()], dtype=np.int64)
    rows = np.concatenate(list(table.values())) if table else np.zeros(0, dtype=np.int64)
    return pack_arrays([keys, lengths, rows], ["plain", "plain", "delta"])


def unpack_moves(blob: bytes) -> MoveTable:
    """The move table `pack_moves` packed, in its order (views of one array, as built)."""
    keys, lengths, rows = unpack_arrays(blob)
    ends = np.cumsum(lengths).tolist()
    starts = [0, *ends[:-1]] if ends else []
    return {(int(j), int(k)): rows[a:b]
            for (j, k), a, b in zip(keys.tolist(), starts, ends, strict=True)}


def vertex_moves(scn: Scenario, lat: Component, stance: tuple,
                 excluded: Collection[tuple[tuple, int, str]] = (),
                 table: MoveTable | None = None
                 ) -> Iterator[tuple[int, str, np.ndarray, tuple]]:
    """Every move of component `lat` of `stance` (`move_table`'s, or `table` if given) but the
    `excluded` ones (stance, boom, anchor): (boom, anchor id, its `move_rows`, the child
    stance)."""
    for (j, k), rows in (move_dict(scn, lat, stance) if table is None else table).items():
        anchor = scn.anchors[k].id
        if (stance, j, anchor) not in excluded:
            yield j, anchor, rows, tuple(anchor if i == j else a
                                         for i, a in enumerate(stance))


def start_components(scn: Scenario, lat: StanceComponents, cfg: LatticeConfig,
                     link_step: float = 0.005, cell_steps: int = 1) -> dict[int, np.ndarray]:
    """The components the start pose is joined to, each with the lattice pose it joins: a
    feasible lattice pose of a neighbouring cell (within one step in x, y and phi) whose
    straight segment from the start pose is feasible every `link_step` m or rad. With
    `cell_steps` 2^k, the corners of the cells of 2, 4, ... 2^k steps about it too (those of a
    lattice 2^k times coarser, `planning.refinement`: a finer lattice joins the start wherever
    the coarser did)."""
    start = np.asarray(scn.start_pose, dtype=float)
    out: dict[int, np.ndarray] = {}
    step = np.array([cfg.position_step, cfg.position_step, cfg.angle_step])
    unit = np.array(list(itertools.product((0, 1), repeat=3)))
    corners = []
    size = 1
    while size <= max(1, cell_steps):
        corners.append(unit * size + np.floor(start / (step * size)).astype(np.int64) * size)
        size *= 2
    keys = np.unique(pack(np.vstack(corners), cfg.angle_count))
    held = []  # (robustness, component, pose) of each feasible corner
    for key, comp in zip(keys, lat.component_of(keys), strict=True):
        if comp >= 0:
            c = lat.components[comp]
            row = int(np.searchsorted(c.keys, key))
            held.append((-float(c.robustness[row]), int(comp), c.poses_at(np.array([row]))[0]))
    stance = scn.stance(scn.start_stance)
    for _, comp, end in sorted(held, key=lambda h: h[0]):
        if comp in out:
            continue
        n = max(2, int(np.ceil(np.abs(end - start).max() / link_step)) + 1)
        link = start + np.linspace(0.0, 1.0, n)[:, None] * (end - start)
        if score_poses(scn, stance, link).feasible.all():
            out[comp] = end
    return out


def goal_disc_problem(scn: Scenario, cfg: LatticeConfig) -> str | None:
    """Why no lattice pose can reach the goal when its tolerance disc holds no lattice point
    at all (a tolerance under the lattice's step, off its points: the search's answer was "no
    route ... the body meets rock, or some boom reaches no anchor", which the sampled search
    disproved); None when it holds one. The nearest point rounds each coordinate."""
    goal, dx = np.asarray(scn.goal_position, dtype=float), cfg.position_step
    if np.linalg.norm(np.round(goal / dx) * dx - goal) <= scn.goal_tolerance:
        return None
    return (f"no route: no lattice point lies within the goal tolerance ({scn.goal_tolerance:g} "
            f"m) at {dx * 100:g} cm steps (a tolerance of {dx / math.sqrt(2.0):.4g} m always "
            "holds one): give the goal a larger tolerance, or --search sampled")


def goal_is_holdable(scn: Scenario, cfg: LatticeConfig) -> bool:
    """Whether some lattice pose within the goal tolerance could hold a stance at all: its body
    clear of rock and every boom reaching some anchor (a necessary condition for a goal vertex,
    so False proves that no route exists at the lattice's resolution)."""
    goal = np.asarray(scn.goal_position, dtype=float)
    tol, dx = scn.goal_tolerance, cfg.position_step
    near = np.flatnonzero(np.linalg.norm(scn.anchor_positions - goal, axis=1)
                          <= tol + scn.robot.max_reach + 1e-6)
    if not len(near):
        return False
    # The disc clipped to where a boom reaches some anchor: its cells grow with the cave, not
    # the tolerance (1e4 m asked for 7 TiB); then a few rows of it at a time: bounded memory.
    reach = scn.anchor_positions[near]
    lo = np.maximum(goal - tol, reach.min(axis=0) - scn.robot.max_reach)
    hi = np.minimum(goal + tol, reach.max(axis=0) + scn.robot.max_reach)
    i = np.arange(math.ceil(lo[0] / dx), math.floor(hi[0] / dx) + 1)
    k = np.arange(math.ceil(lo[1] / dx), math.floor(hi[1] / dx) + 1)
    rows = max(1, GOAL_CELLS // max(len(k), 1))
    starts = sorted(range(0, len(i), rows),  # the goal's own rows first: found sooner
                    key=lambda s: abs(i[min(s + rows, len(i)) - 1] + i[s] - 2 * goal[0] / dx))
    return any(_holdable_cells(scn, cfg, i[s:s + rows], k, near) for s in starts)


GOAL_CELLS = 100_000  # goal cells tested at once, per orientation


def _holdable_cells(scn: Scenario, cfg: LatticeConfig, i: np.ndarray, k: np.ndarray,
                    near: np.ndarray) -> bool:
    """`goal_is_holdable` on the lattice cells i x k within the goal tolerance."""
    goal, dx = np.asarray(scn.goal_position, dtype=float), cfg.position_step
    ii, kk = np.meshgrid(i, k, indexing="ij")
    cells = np.column_stack([ii.ravel(), kk.ravel()])
    cells = cells[np.linalg.norm(cells * dx - goal, axis=1) <= scn.goal_tolerance]
    if not len(cells):
        return False
    n = cfg.angle_count
    for m in range(-n // 2, n // 2):  # an orientation at a time: bounded memory
        poses = np.column_stack([cells * dx, np.full(len(cells), m * cfg.angle_step)])
        ok = np.ones(len(poses), dtype=bool)
        for j in range(NUM_BOOMS):
            v = reach_violation(scn.robot, poses, scn.anchor_positions[near],
                                np.full(len(near), j))
            ok &= (v == 0.0).any(axis=1)
        if not ok.any():
            continue
        if not scn.rock.polygons or not body_in_rock(scn.robot, scn.rock, poses[ok]).all():
            return True
    return False
