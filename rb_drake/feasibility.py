"""Pose feasibility in a stance: kinematic limits, collisions, statics and probability.

`check_poses` is vectorised over poses and reports the first failing test per pose (a reason
code and the boom concerned); `diagnose_pose` explains one pose in words, listing every problem.
"""

from __future__ import annotations

from enum import IntEnum
from typing import NamedTuple, Protocol

import numpy as np

from rb_drake import geometry
from rb_drake.collision import Rock, boom_clearances
from rb_drake.errors import apart
from rb_drake.params import NUM_BOOMS, RobotParams
from rb_drake.stance import Stance
from rb_drake.statics import Allocation, StaticsProblem, allocate, null_vector, statics_problem


class World(Protocol):
    """What feasibility needs of a scenario (read-only, as a frozen Scenario's fields are)."""

    @property
    def robot(self) -> RobotParams: ...

    @property
    def rock(self) -> Rock: ...

    @property
    def gravity_vector(self) -> np.ndarray: ...

    @property
    def anchor_positions(self) -> np.ndarray: ...  # (A, 2): a free gripper may touch rock
    #                                                   near these (`reach_world`)


class ReachWorld(NamedTuple):
    """A World in which a reach phase's configurations are checked (`reach_world`)."""

    robot: RobotParams
    rock: Rock
    gravity_vector: np.ndarray
    anchor_positions: np.ndarray  # (2, 2): the free gripper's own anchors


def reach_world(world: World, tips: np.ndarray | None) -> World:
    """`world` for a reach phase whose free gripper follows `tips` (N, 2): it may touch rock
    only near its OWN anchors, the one it leaves and the one it reaches, where its path starts
    and ends (rule reach-ends). Near any anchor of the cave, a gripper passing a rock nub that
    carries an unrelated anchor crossed it unseen. `world` itself when `tips` is None."""
    path = None if tips is None else np.asarray(tips, dtype=float).reshape(-1, 2)
    if path is None or not len(path):
        return world
    ends = path[[0, -1]]
    return ReachWorld(world.robot, world.rock, world.gravity_vector, ends)


class Reason(IntEnum):
    """Why a pose is infeasible, in the order the tests are applied."""

    FEASIBLE = 0
    BOOM_LENGTH = 1
    SHOULDER_ANGLE = 2
    BODY_COLLISION = 3
    BOOM_COLLISION = 4
    PULL_ANGLE = 5
    SHOULDER_TORQUE = 6
    SINGULAR = 7
    STATICS = 8
    PROBABILITY = 9


REASON_TEXT = {
    Reason.FEASIBLE: "feasible",
    Reason.BOOM_LENGTH: "boom length out of range",
    Reason.SHOULDER_ANGLE: "shoulder angle out of range",
    Reason.BODY_COLLISION: "body collides with rock",
    Reason.BOOM_COLLISION: "boom collides with rock",
    Reason.PULL_ANGLE: "grasp pulled at max_pull_angle_deg or more from its normal",
    Reason.SHOULDER_TORQUE: "free limb's shoulder torque over the limit",
    Reason.SINGULAR: "the booms nearly meet in one point: the stance cannot resist disturbances",
    Reason.STATICS: "no tensions within bounds balance the load",
    Reason.PROBABILITY: "probability of success below p_min",
}


# The smallest singular value of the attached booms' wrench matrix, its moment row divided by the
# shoulders' distance from the centre (so that every entry is about one). Where the booms'
# lines nearly meet in one point it tends to zero and the tensions that hold the body swing by
# tens of newtons for millimetres of error or millinewtons of inertia: a plan through such a
# configuration is statically exact and dynamically fragile (simulation found tensions jumping
# from 13 to 25 N at a condition number of 2000). Plans of healthy stances stay above 0.1.
MIN_CONDITIONING = 0.03


def wrench_conditioning(robot: RobotParams, A: np.ndarray, attached: np.ndarray) -> np.ndarray:
    """Per pose, the scaled smallest singular value of the attached booms' wrench matrix
    (A: (P, 3, 4)), see MIN_CONDITIONING."""
    scale = np.array([1.0, 1.0, 1.0 / float(np.linalg.norm(robot.shoulder_array, axis=1).max())])
    M = A[:, :, attached] * scale[:, None]
    return np.linalg.svd(M, compute_uv=False)[:, -1]


class PoseCheck(NamedTuple):
    feasible: np.ndarray       # (P,) bool
    reason: np.ndarray         # (P,) Reason codes (first failure)
    boom: np.ndarray           # (P,) boom concerned, -1 where not one boom
    allocation: Allocation     # tensions and probabilities at every pose
    lengths: np.ndarray        # (P, 4)
    shoulder_angles: np.ndarray  # (P, 4)
    problem: StaticsProblem    # the equilibrium equations at every pose

    @property
    def probability(self) -> np.ndarray:
        return np.exp(self.allocation.robustness)


def _targets(stance: Stance, free_tip: np.ndarray | None, P: int) -> np.ndarray:
    """Each boom's tip point at each of P poses (NaN for a free boom without a tip), (P, 4, 2)."""
    targets = np.where(stance.attached[:, None], stance.positions, np.nan)
    targets = np.broadcast_to(targets, (P, 4, 2)).copy()
    j = stance.free_boom
    if j is not None and free_tip is not None:
        targets[:, j, :] = free_tip
    return targets


def check_poses(world: World, stance: Stance, poses: np.ndarray,
                free_tip: np.ndarray | None = None, full: bool = False,
                ignore_grasps: bool = False) -> PoseCheck:
    """Feasibility of each pose in `stance` (a 3-stance also needs its free gripper's position).

    Tests run cheapest first, and each runs only on the poses that passed the ones before; with
    `full` every test runs on every pose (for diagnosis), at a higher cost. `ignore_grasps`
    drops the grasp tests (pull angle, probability): the naive baseline's notion of feasible.
    """
    robot = world.robot
    poses = geometry.as_poses(poses)
    P = poses.shape[0]
    targets = _targets(stance, free_tip, P)
    problem = statics_problem(robot, world.gravity_vector, poses, stance, free_tip)
    geo = problem.geometry
    used = np.isfinite(targets[..., 0])  # booms with a tip position: attached, or the free one

    reason = np.full(P, int(Reason.FEASIBLE))
    boom = np.full(P, -1)

    def flag(bad: np.ndarray, code: Reason, rows: np.ndarray | None = None,
             which: int = -1) -> None:
        """Record `code` where a boom (bad: (n, 4)) or the pose (bad: (n,), boom `which`)
        fails first."""
        rows = np.arange(P) if rows is None else rows
        if bad.ndim == 2:
            first = np.argmax(bad, axis=1)
            bad_pose = bad.any(axis=1)
        else:
            first, bad_pose = np.full(len(rows), which), bad
        new = bad_pose & (reason[rows] == Reason.FEASIBLE)
        reason[rows[new]] = int(code)
        boom[rows[new]] = first[new]

    def survivors() -> np.ndarray:
        return np.arange(P) if full else np.flatnonzero(reason == Reason.FEASIBLE)

    lo, hi = robot.boom_length
    flag(used & ((geo.length < lo) | (geo.length > hi)), Reason.BOOM_LENGTH)
    flag(used & (np.abs(geo.shoulder_angle) > robot.shoulder_range + 1e-12),
         Reason.SHOULDER_ANGLE)
    rock = world.rock
    if rock.polygons:
        rows = survivors()
        flag(body_in_rock(robot, rock, poses[rows]), Reason.BODY_COLLISION, rows)
        rows = survivors()
        clearance = boom_clearances(world.anchor_positions, P, stance.free_boom, free_tip)
        with np.errstate(invalid="ignore"):
            end = targets[rows] - clearance[rows, :, None] * np.nan_to_num(geo.u[rows])
        # Shoulders lie on the body, which is clear of rock wherever this result counts (a
        # pose whose body collides already failed), so only edge crossings are tested.
        boom_hit = rock.segments_hit(geo.shoulders[rows], np.nan_to_num(end),
                                     inside=False) & used[rows]
        flag(boom_hit, Reason.BOOM_COLLISION, rows)

    rows = survivors()
    part = allocate(robot, world.gravity_vector, poses[rows], stance.take(rows), free_tip,
                    problem=problem.take(rows))
    alloc = Allocation(*(_scatter(v, rows, P, -np.inf if name == "robustness" else np.nan)
                         for name, v in zip(Allocation._fields, part, strict=True)))
    if not ignore_grasps:
        flag(stance.attached & ~pull_within(robot, part.pull_angles), Reason.PULL_ANGLE, rows)
    if stance.free_boom is not None:
        flag(np.abs(part.shoulder_torque) > robot.shoulder_torque_max, Reason.SHOULDER_TORQUE,
             rows, which=stance.free_boom)
    flag(~(wrench_conditioning(robot, problem.A[rows], stance.attached) >= MIN_CONDITIONING),
         Reason.SINGULAR, rows)
    flag(~part.statics_ok, Reason.STATICS, rows)
    if not ignore_grasps:
        # `not >=`: a NaN probability (no longer readable, but never a pass) fails
        flag(~(part.robustness >= robot.log_p_min), Reason.PROBABILITY, rows)
    feasible = reason == Reason.FEASIBLE
    return PoseCheck(feasible, reason, boom, alloc, geo.length, geo.shoulder_angle, problem)


def pull_within(robot: RobotParams, psi: np.ndarray) -> np.ndarray:
    """Where a grasp's pull angle passes the planner's limit: |psi| < robot.max_pull_angle
    (NaN, a free boom's, passes). The one definition of the PULL_ANGLE test, which
    rb_drake.kernel, SCP and the verifier repeat."""
    return np.abs(np.nan_to_num(psi)) < robot.max_pull_angle


def _scatter(values: np.ndarray, rows: np.ndarray, P: int, fill: float) -> np.ndarray:
    """Values computed for `rows` placed in an array for all P poses (the rest: fill, False)."""
    if values.dtype == bool:
        out = np.zeros((P, *values.shape[1:]), dtype=bool)
    else:
        out = np.full((P, *values.shape[1:]), fill, dtype=float)
    out[rows] = values
    return out


def body_in_rock(robot: RobotParams, rock: Rock, poses: np.ndarray) -> np.ndarray:
    """Per pose (P, 3), whether the body square meets rock: an edge crossing, a corner inside
    rock, or a rock polygon wholly inside the body."""
    corners = geometry.body_corners(robot, poses)
    hit = rock.segments_hit(corners, np.roll(corners, -1, axis=1)).any(axis=1)
    return hit | rock_inside_body(rock, corners)


def rock_inside_body(rock: Rock, corners: np.ndarray) -> np.ndarray:
    """Whether some rock polygon lies entirely inside the body square (its vertex inside)."""
    # only the vertices within all the squares' box can be inside one: a grid row of bodies
    # against thousands of small polygons tested (P, W, 4) sides, 1.2 s of a 2,000-piece import
    flat = corners.reshape(-1, 2)
    finite = np.isfinite(flat)  # a NaN pose meets nothing; it must not hide the others' box
    lo = np.where(finite, flat, np.inf).min(axis=0, initial=np.inf)
    hi = np.where(finite, flat, -np.inf).max(axis=0, initial=-np.inf)
    box = np.all((rock.vertex >= lo) & (rock.vertex <= hi), axis=1)
    if not box.any():
        return np.zeros(corners.shape[0], dtype=bool)
    c = corners[:, None, :, :]             # (P, 1, 4, 2)
    v = rock.vertex[box][None, :, None, :]  # (1, W', 1, 2)
    e = np.roll(corners, -1, axis=1)[:, None] - c
    side = e[..., 0] * (v[..., 1] - c[..., 1]) - e[..., 1] * (v[..., 0] - c[..., 0])
    return (side > 0).all(axis=2).any(axis=1)


def diagnose_pose(world: World, stance: Stance, pose: np.ndarray,
                  free_tip: np.ndarray | None = None) -> list[str]:
    """Every reason `pose` is infeasible, in words with the values; [] when it is feasible."""
    robot = world.robot
    pose = np.asarray(pose, dtype=float)
    check = check_poses(world, stance, pose, free_tip, full=True)
    if check.feasible[0]:
        return []
    targets = _targets(stance, free_tip, 1)[0]
    geo = geometry.boom_geometry(robot, pose, targets)
    out: list[str] = []
    lo, hi = robot.boom_length
    rng = robot.shoulder_range_deg
    for i in range(NUM_BOOMS):
        if not np.isfinite(targets[i, 0]):
            continue
        L, th = geo.length[0, i], np.degrees(geo.shoulder_angle[0, i])
        if not lo <= L <= hi:
            out.append(f"boom {i}: length {L:.3f} m outside [{lo}, {hi}] m")
        if abs(th) > rng + 1e-9:
            out.append(f"boom {i}: shoulder angle {th:+.1f} deg outside +-{rng} deg")
    rock = world.rock
    if rock.polygons:
        if body_in_rock(robot, rock, pose[None])[0]:
            out.append("body collides with rock")
        clearance = boom_clearances(world.anchor_positions, 1, stance.free_boom, free_tip)[0]
        end = targets - clearance[:, None] * np.nan_to_num(geo.u[0])
        for i in range(NUM_BOOMS):
            if np.isfinite(targets[i, 0]) and rock.segments_hit(geo.shoulders[0, i],
                                                                 end[i])[()]:
                out.append(f"boom {i}: collides with rock")
    alloc = check.allocation
    for b in np.flatnonzero(stance.attached):
        psi = np.degrees(alloc.pull_angles[0, b])
        if not abs(psi) < robot.max_pull_angle_deg:
            out.append(f"boom {b}: anchor {stance.ids[b]} pulled at {psi:+.1f} deg from its "
                       f"normal (must be within +-{robot.max_pull_angle_deg})")
    j = stance.free_boom
    if j is not None and abs(alloc.shoulder_torque[0]) > robot.shoulder_torque_max:
        out.append(f"boom {j} (free): shoulder torque {alloc.shoulder_torque[0]:.2f} N m over "
                   f"the limit {robot.shoulder_torque_max} N m")
    kappa = float(wrench_conditioning(robot, check.problem.A, stance.attached)[0])
    if not kappa >= MIN_CONDITIONING:
        out.append(f"the booms nearly meet in one point (wrench conditioning {kappa:.4f} < "
                   f"{MIN_CONDITIONING}): small errors swing the tensions")
    if not alloc.statics_ok[0]:
        out.append(f"statics: no tensions within [{robot.boom_tension[0]}, "
                   f"{robot.boom_tension[1]}] N balance gravity at this pose")
    elif not alloc.robustness[0] >= robot.log_p_min:
        # digits enough to read below p_min (p_min 1: 0.9999999999, not 1.000)
        probs = ", ".join(f"boom {i} {apart(float(np.exp(alloc.log_probs[0, i])), robot.p_min)}"
                          for i in np.flatnonzero(stance.attached))
        out.append(f"probability {apart(float(np.exp(alloc.robustness[0])), robot.p_min)} "
                   f"below p_min {robot.p_min} ({probs})")
    if not out:  # the vectorised check failed on something the words above do not cover
        out.append(REASON_TEXT[Reason(int(check.reason[0]))])
    return out


def violation(world: World, stance: Stance, poses: np.ndarray, check: PoseCheck,
              free_tip: np.ndarray | None = None, ignore_grasps: bool = False) -> np.ndarray:
    """A continuous measure of how far each pose is from feasible (0 where feasible).

    Sums the excess over every limit, each in its natural unit scaled to about one at a
    'clear' violation: boom length (m), shoulder angle (rad), tension (per 10 N), shoulder torque
    (per limit), robustness shortfall (log P), and 1 per collision. For a 4-stance whose tension
    family leaves the bounds everywhere it takes the least violating member of the family. The
    transition search descends it to find feasible poses where random samples miss them.
    `check` must come from `check_poses(..., full=True)` on the same poses.
    """
    robot = world.robot
    poses = geometry.as_poses(poses)
    used = np.isfinite(_targets(stance, free_tip, poses.shape[0])[..., 0])
    lo, hi = robot.boom_length
    L, th = check.lengths, check.shoulder_angles
    v = np.sum(np.where(used, np.maximum(0, L - hi) + np.maximum(0, lo - L)
                        + np.maximum(0, np.abs(th) - robot.shoulder_range), 0.0), axis=1)
    v += np.isin(check.reason, (Reason.BODY_COLLISION, Reason.BOOM_COLLISION)).astype(float)
    alloc = check.allocation
    f_lo, f_hi = robot.boom_tension
    att = stance.attached
    prob = check.problem
    if att.sum() == 3:
        A3 = prob.A[:, :, att]
        det = np.linalg.det(A3)
        ok = np.abs(det) > 1e-9
        f = np.linalg.solve(np.where(ok[:, None, None], A3, np.eye(3)), prob.b[..., None])[..., 0]
        ten = np.sum(np.maximum(0, f_lo - f) + np.maximum(0, f - f_hi), axis=1)
        ten = np.where(ok, ten, 100.0)
    else:
        A = prob.A
        n = null_vector(A)
        AAt = A @ np.swapaxes(A, 1, 2)
        ok = np.abs(np.linalg.det(AAt)) > 1e-14
        fp = (np.swapaxes(A, 1, 2) @ np.linalg.solve(np.where(ok[:, None, None], AAt, np.eye(3)),
                                                     prob.b[..., None]))[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            ts = np.concatenate([(f_lo - fp) / n, (f_hi - fp) / n], axis=1)  # breakpoints
        ts = np.nan_to_num(ts, nan=0.0, posinf=0.0, neginf=0.0)
        f = fp[:, None, :] + ts[:, :, None] * n[:, None, :]           # (P, 8, 4)
        ten = np.sum(np.maximum(0, f_lo - f) + np.maximum(0, f - f_hi), axis=2).min(axis=1)
        ten = np.where(ok, ten, 100.0)
    v += ten / 10.0
    if stance.free_boom is not None:
        v += np.maximum(0, np.abs(prob.shoulder_torque) - robot.shoulder_torque_max) / max(
            robot.shoulder_torque_max, 1e-9)
    v += np.maximum(0, MIN_CONDITIONING - wrench_conditioning(robot, prob.A, att)) / (
        MIN_CONDITIONING)
    if not ignore_grasps:
        psi = np.abs(np.nan_to_num(prob.pull_angles))
        v += np.sum(np.where(att, np.maximum(0, psi - (robot.max_pull_angle - 1e-3)), 0.0),
                    axis=1)
        r = np.where(np.isfinite(alloc.robustness), alloc.robustness, robot.log_p_min - 1.0)
        v += np.where(alloc.statics_ok, np.maximum(0, robot.log_p_min - r), 0.0)
    return np.where(check.feasible, 0.0, np.maximum(v, 1e-6))
