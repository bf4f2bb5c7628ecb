"""The compiled feasibility kernel (rb_drake.kernel) against the numpy reference.

`score_poses` must reproduce `check_poses(..., full=True)` followed by `violation`: the same
feasibility and first-failure reason at every pose, and robustness, log-probabilities, tensions
and violation within VALUE_RTOL (relative) plus VALUE_ATOL, with non-finite entries (NaN tensions,
-inf robustness) in the same places. Measured on these cases with 5000 poses each (310,000
poses): feasibility and reasons identical everywhere; |kernel - numpy| / (|numpy| + 1e-12) at
most 2e-12 for robustness, 3e-11 for log P (in the far tail, log P ~ -1e-226, where log Phi
amplifies the tension's last bits), 2e-11 for tensions, 4e-11 for the violation.

Cases, per cave (three bundled, one generated, and the test shaft made hard: a rock across the
body's edge, a pebble on a boom's line, a weak shoulder and an anchor normal turned into the
wall, so that every Reason occurs): the start 4-stance, each boom's 3-stance with its gripper
at its anchor and scattered around it, the naive baseline's view (grasps ignored), and, where
`find_transition` finds a move among the first candidates, its old and new 4-stances as one
per-row stance and its 3-stance with per-row tips; poses sampled near the start pose and near
the transition pose, some close, some far.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import zlib
from collections import Counter
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from conftest import build_shaft
from kernel_helpers import pack_stances
from scipy.special import erfcx, log_ndtr
from transition_reference import score_reference

from planning import transition, transition_score
from planning.footsteps import candidate_moves, edge_rng
from planning.lattice_kernels import lattice_move_table, lattice_reach_rows, reach_violation
from planning.transition import find_transition
from planning.transition_score import NaiveWorld, score_configurations
from rb_drake.feasibility import Reason, check_poses, violation
from rb_drake.generate import generate_cave
from rb_drake.grasp import mills_ratio
from rb_drake.kernel import special
from rb_drake.kernel.allocation import NEWTON_STEPS
from rb_drake.kernel.layout import robot_params
from rb_drake.kernel.pose_kernel import score_kernel
from rb_drake.kernel.scoring import KernelCheck, score_poses, score_rows
from rb_drake.scenario import Scenario, load_scenario
from rb_drake.stance import Stance
from rb_drake.statics import allocate

ROOT = Path(__file__).resolve().parents[1]
VALUE_RTOL = 1e-9
VALUE_ATOL = 1e-12   # N, log P and violation units; for values that are zero in one path
SPECIAL_RTOL = 1e-13
POSES_PER_CASE = 500


def _hard_shaft() -> tuple[Scenario, Stance]:
    """The conftest shaft with a rock across the body's right edge at the start pose, a pebble
    on boom 0's line, a 0.3 N m shoulder, and a stance whose a1 normal points into the wall."""
    rock = [[0.1, 0.9], [0.4, 0.9], [0.4, 1.1], [0.1, 1.1]]
    pebble = [[0.6, 1.5], [0.7, 1.5], [0.7, 1.7], [0.6, 1.7]]
    scn = build_shaft(robot={"shoulder_torque_max": 0.3}, extra_walls=[rock, pebble])
    stance = scn.stance(scn.start_stance)
    normals = stance.normals.copy()
    normals[1] = [-1.0, 0.0]
    return scn, stance._replace(normals=normals)


CAVES = {
    "demo-shaft": lambda: load_scenario(ROOT / "rb_drake/data/caves/demo-shaft.yaml"),
    "demo-crevasse": lambda: load_scenario(ROOT / "rb_drake/data/caves/demo-crevasse.yaml"),
    "wide-shaft": lambda: load_scenario(ROOT / "tests/data/wide-shaft.yaml"),
    "rockfall-3": lambda: generate_cave("rockfall", 3),
    "hard-shaft": lambda: _hard_shaft()[0],
}


class Case(NamedTuple):
    label: str
    world: object
    stance: Stance
    poses: np.ndarray
    tip: np.ndarray | None
    ignore_grasps: bool


class Compared(NamedTuple):
    case: Case
    kernel: KernelCheck
    reference: KernelCheck


def _reference_check(world, stance: Stance, poses: np.ndarray, free_tip: np.ndarray | None,
                     ignore_grasps: bool) -> KernelCheck:
    """What score_poses stands for: check_poses(full=True) and violation, in numpy."""
    check = check_poses(world, stance, poses, free_tip, full=True, ignore_grasps=ignore_grasps)
    v = violation(world, stance, poses, check, free_tip, ignore_grasps)
    a = check.allocation
    return KernelCheck(check.feasible, check.reason, a.robustness, a.log_probs, a.tensions, v)


def _rng(*key: object) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(repr(key).encode()))


def _around(rng: np.random.Generator, pose: np.ndarray, n: int) -> np.ndarray:
    """Poses near `pose`: a third within centimetres, the rest within decimetres."""
    near = n // 3
    spread = np.vstack([np.tile([0.02, 0.02, 0.03], (near, 1)),
                        np.tile([0.25, 0.25, 0.35], (n - near, 1))])
    return pose + rng.normal(0.0, 1.0, (n, 3)) * spread


def _transition(scn: Scenario) -> tuple[tuple[str, ...], int, str, np.ndarray] | None:
    """A feasible move from the start stance (the first candidate found), with its pose."""
    stance = tuple(scn.start_stance)
    start = np.asarray(scn.start_pose, dtype=float)
    for j, anchor in candidate_moves(scn, stance, start, per_boom=2):
        tr = find_transition(scn, stance, j, anchor, edge_rng(0, stance, j, anchor), guess=start)
        if tr.feasible:
            return stance, j, anchor, tr.pose
    return None


def _cases(name: str, scn: Scenario) -> list[Case]:
    rng = _rng(name)
    n = POSES_PER_CASE
    s4 = _hard_shaft()[1] if name == "hard-shaft" else scn.stance(scn.start_stance)
    start = np.asarray(scn.start_pose, dtype=float)
    cases = [Case("start 4-stance", scn, s4, _around(rng, start, n), None, False)]
    for j in range(4):
        s3 = s4.without(j)
        cases.append(Case(f"3-stance free {j}, tip at anchor", scn, s3, _around(rng, start, n),
                          s4.positions[j], False))
        tips = s4.positions[j] + rng.normal(0.0, 0.4, (n, 2))
        cases.append(Case(f"3-stance free {j}, tips scattered", scn, s3,
                          _around(rng, start, n), tips, False))
    cases.append(Case("start 4-stance, grasps ignored", NaiveWorld(scn), s4,
                      _around(rng, start, n), None, True))
    move = _transition(scn) if name != "hard-shaft" else None
    if move is not None:
        old, j, anchor, pose = move
        s_old, s_three, s_new = transition.transition_stances(scn, old, j, anchor)
        second = rng.uniform(size=n) < 0.5
        mixed = Stance.mix(s_old, s_new, second)
        tips = np.where(second[:, None], s_new.positions[j], s_old.positions[j])
        for ignore in (False, True):
            world = NaiveWorld(scn) if ignore else scn
            cases.append(Case(f"transition 4-stances mixed (ignore {ignore})", world, mixed,
                              _around(rng, pose, n), None, ignore))
            cases.append(Case(f"transition 3-stance, per-row tips (ignore {ignore})", world,
                              s_three, _around(rng, pose, n), tips, ignore))
    return cases


@pytest.fixture(scope="module")
def scenarios() -> dict[str, Scenario]:
    return {name: make() for name, make in CAVES.items()}


@pytest.fixture(scope="module")
def compared(scenarios: dict[str, Scenario]) -> dict[str, list[Compared]]:
    out = {}
    for name, scn in scenarios.items():
        out[name] = [Compared(c, score_poses(c.world, c.stance, c.poses, c.tip,
                                                c.ignore_grasps),
                              _reference_check(c.world, c.stance, c.poses, c.tip,
                                               c.ignore_grasps))
                     for c in _cases(name, scn)]
    return out


def _assert_close(name: str, label: str, got: np.ndarray, want: np.ndarray) -> None:
    finite = np.isfinite(want)
    assert np.array_equal(np.isnan(got), np.isnan(want)), f"{label}: {name} NaN pattern differs"
    assert np.array_equal(got[~finite & ~np.isnan(want)], want[~finite & ~np.isnan(want)]), (
        f"{label}: {name} infinities differ")
    assert np.isfinite(got[finite]).all(), f"{label}: {name} non-finite where numpy is finite"
    err = np.abs(got[finite] - want[finite])
    bound = VALUE_RTOL * np.abs(want[finite]) + VALUE_ATOL
    worst = int(np.argmax(err - bound)) if err.size else 0
    assert np.all(err <= bound), (
        f"{label}: {name} differs by {err[worst]:.3e} at value {want[finite][worst]:.6e} "
        f"(allowed {bound[worst]:.3e})")


@pytest.mark.parametrize("cave", list(CAVES))
def test_same_feasibility_and_reasons(compared: dict[str, list[Compared]], cave: str) -> None:
    for c in compared[cave]:
        label = f"{cave}, {c.case.label}"
        differ = np.flatnonzero(c.kernel.reason != c.reference.reason)
        assert not len(differ), (
            f"{label}: reasons differ at {len(differ)} of {len(c.case.poses)} poses, first "
            f"pose {c.case.poses[differ[0]]}: kernel {Reason(int(c.kernel.reason[differ[0]]))!r}"
            f" numpy {Reason(int(c.reference.reason[differ[0]]))!r}")
        assert np.array_equal(c.kernel.feasible, c.reference.feasible), f"{label}: feasible"
        assert c.kernel.feasible.dtype == bool and c.kernel.reason.dtype.kind == "i", label


@pytest.mark.parametrize("cave", list(CAVES))
def test_values_agree(compared: dict[str, list[Compared]], cave: str) -> None:
    for c in compared[cave]:
        label = f"{cave}, {c.case.label}"
        for name in ("robustness", "log_probs", "tensions", "violation"):
            _assert_close(name, label, getattr(c.kernel, name), getattr(c.reference, name))
        assert np.all(c.kernel.violation[c.kernel.feasible] == 0.0), f"{label}: violation"
        assert np.all(c.kernel.violation[~c.kernel.feasible] >= 1e-6), f"{label}: violation"


def test_samples_cover_every_reason_and_feasible_poses(
        compared: dict[str, list[Compared]]) -> None:
    """Every test of check_poses decides some pose, so the comparison covers every branch."""
    counts: Counter[int] = Counter()
    for cases in compared.values():
        for c in cases:
            counts.update(c.reference.reason.tolist())
    missing = [r.name for r in Reason if counts[int(r)] < 3]
    assert not missing, f"reasons decided at fewer than 3 poses: {missing} (counts {counts})"
    total = sum(counts.values())
    assert total >= 20000, f"only {total} poses compared"
    moving = [cave for cave, cases in compared.items()
              if any(c.case.label.startswith("transition") for c in cases)]
    assert len(moving) >= 3, f"transition cases only in {moving}"


def test_results_depend_only_on_each_pose(compared: dict[str, list[Compared]]) -> None:
    """Repeated calls are bit-identical, and a pose scores the same in any batch."""
    for cave in ("demo-crevasse", "hard-shaft"):
        for c in compared[cave]:
            again = score_poses(c.case.world, c.case.stance, c.case.poses, c.case.tip,
                                   c.case.ignore_grasps)
            for name, a, b in zip(KernelCheck._fields, again, c.kernel, strict=True):
                np.testing.assert_array_equal(a, b, err_msg=f"{c.case.label}: {name} changed")
            rows = _rng(cave, c.case.label).permutation(len(c.case.poses))[:37]
            stance = c.case.stance.take(rows)
            tip = c.case.tip if c.case.tip is None or c.case.tip.ndim == 1 else c.case.tip[rows]
            part = score_poses(c.case.world, stance, c.case.poses[rows], tip,
                                  c.case.ignore_grasps)
            for name, a, b in zip(KernelCheck._fields, part, c.kernel, strict=True):
                if b is None:  # release_r: only asked for by the lattice search
                    assert a is None, name
                    continue
                np.testing.assert_array_equal(a, b[rows], err_msg=f"{c.case.label}: {name} "
                                              "depends on the other poses of the batch")


def test_special_functions_match_scipy() -> None:
    z = np.concatenate([np.linspace(-60.0, 40.0, 20001), -np.logspace(-8, 1.7, 500),
                        np.logspace(-8, 1.6, 500), [0.0, -1.0, 1.0]])
    got = np.array([special.log_ndtr(v) for v in z])
    want = log_ndtr(z)
    normal = np.abs(want) >= 1e-300  # below, both are subnormal or zero
    rel = np.abs(got - want)[normal] / np.abs(want[normal])
    assert rel.max() <= SPECIAL_RTOL, (
        f"log_ndtr: relative error {rel.max():.2e} at z = {z[normal][np.argmax(rel)]}")
    assert np.abs(got - want)[~normal].max(initial=0.0) <= 1e-300, "log_ndtr far tail"
    assert np.array_equal(got == 0.0, want == 0.0), "log_ndtr rounds to 0 elsewhere than scipy"
    x = np.linspace(-26.6, 60.0, 20001)
    got = np.array([special.erfcx(v) for v in x])
    rel = np.abs(got - erfcx(x)) / erfcx(x)
    assert rel.max() <= SPECIAL_RTOL, f"erfcx: relative error {rel.max():.2e}"
    assert special.erfcx(-27.0) == math.inf and erfcx(-27.0) == math.inf, "erfcx overflow"
    got = np.array([special.mills_ratio(v) for v in z])
    want = mills_ratio(z)
    pos = want > 0
    rel = np.abs(got - want)[pos] / want[pos]
    assert rel.max() <= SPECIAL_RTOL, f"mills_ratio: relative error {rel.max():.2e}"
    assert np.all(got[~pos] == 0.0), "mills_ratio underflows where grasp.mills_ratio does"


def test_score_matches_reference_path(scenarios: dict[str, Scenario]) -> None:
    """transition._score (one compiled call for all configurations) and _score_reference
    (check_poses + violation per stance kind) on the same poses."""
    scn = scenarios["wide-shaft"]
    move = _transition(scn)
    assert move is not None, "no feasible move from the wide-shaft start"
    old, j, anchor, pose = move
    poses = _around(_rng("score"), pose, 300)
    known = np.full((len(poses), 4), np.nan)
    known[:, list(transition_score.RELEASE)] = -0.01
    for ignore in (False, True):
        for configs, given in ((transition_score.ALL, None), (transition_score.RELEASE, None),
                               (transition_score.ARRIVE, known), ((3,), None), ((1, 2), None)):
            new = None if configs == transition_score.RELEASE else anchor
            got = score_configurations(scn, old, j, new, poses, ignore, configs, given)
            want = score_reference(scn, old, j, new, poses, ignore, configs, given)
            label = f"configs {configs}, ignore_grasps {ignore}"
            np.testing.assert_array_equal(got[2], want[2], err_msg=f"{label}: failure codes")
            np.testing.assert_allclose(got[1], want[1], rtol=VALUE_RTOL, atol=VALUE_ATOL,
                                       err_msg=f"{label}: robustness")
            np.testing.assert_allclose(got[0], want[0], rtol=VALUE_RTOL, atol=VALUE_ATOL,
                                       err_msg=f"{label}: search key")
            assert (got[0] > -transition_score.VIOLATION_OFFSET).any(), f"{label}: nothing feasible"
            assert (got[0] <= -transition_score.VIOLATION_OFFSET).any(), f"{label}: all feasible"
            if configs == transition_score.ALL:
                first = set((got[2] // 10)[got[2] > 0].tolist())
                assert len(first) >= 2, f"{label}: first failures only in configurations {first}"


def test_rejects_what_check_poses_rejects(scenarios: dict[str, Scenario]) -> None:
    scn = scenarios["wide-shaft"]
    stance = scn.stance(scn.start_stance)
    pose = np.asarray(scn.start_pose, dtype=float)
    with pytest.raises(ValueError, match="free gripper"):
        score_poses(scn, stance.without(0), pose)
    with pytest.raises(ValueError, match="3 or 4 anchors"):
        score_poses(scn, stance.without(0).without(1), pose, stance.positions[0])
    empty = score_poses(scn, stance, np.zeros((0, 3)))
    assert all(len(a) == 0 for a in empty if a is not None), "no poses, no results"
    one = score_poses(scn, stance, pose)
    assert one.feasible.shape == (1,) and one.log_probs.shape == (1, 4), "a (3,) pose is P = 1"


def test_rows_of_several_stances_equal_one_call_per_stance(
        scenarios: dict[str, Scenario]) -> None:
    """score_rows with packed stances and tips gives, bit for bit, score_poses' results."""
    scn = scenarios["demo-shaft"]
    s4 = scn.stance(scn.start_stance)
    stances = (s4, s4.without(0), s4.without(3))
    tips = np.vstack([s4.positions[0], s4.positions[3] + 0.05])
    poses = _around(_rng("rows"), np.asarray(scn.start_pose, dtype=float), 60)
    P = len(poses)
    pose_row = np.tile(np.arange(P), 3)
    stance_row = np.repeat([0, 1, 2], P)
    tip_row = np.repeat([1, 0, 1], P)  # the 4-stance's tip is ignored
    got = score_rows(scn, pack_stances(*stances), tips, poses, pose_row, stance_row,
                        tip_row)
    for n, (stance, tip) in enumerate(zip(stances, (None, tips[0], tips[1]), strict=True)):
        want = score_poses(scn, stance, poses, tip)
        for name, a, b in zip(KernelCheck._fields, got, want, strict=True):
            if a is None and b is None:  # release_r, not asked for
                continue
            np.testing.assert_array_equal(a[n * P:(n + 1) * P], b,
                                          err_msg=f"stance {n}: {name} differs")
    with pytest.raises(ValueError, match="free-gripper"):
        score_rows(scn, pack_stances(*stances), np.full((1, 2), np.nan), poses,
                      pose_row, stance_row, np.zeros_like(tip_row))


def test_constants_mirror_the_reference() -> None:
    """The compiled allocation takes allocate's Newton step count (the kernel's Reason codes
    are feasibility.Reason itself)."""
    default = inspect.signature(allocate).parameters["newton_steps"].default
    assert default == NEWTON_STEPS, f"allocate takes {default} Newton steps"


def test_compiled_once(compared: dict[str, list[Compared]]) -> None:
    """Every entry point hands the kernel the same array types: one compilation serves all."""
    sigs = score_kernel.signatures
    differ = [[f"{a} / {b}" for a, b in zip(sigs[0], s, strict=True) if a != b] for s in sigs[1:]]
    assert len(sigs) == 1, f"compiled again for: {differ}"


@pytest.mark.parametrize("cave", ["demo-crevasse", "rockfall-3"])
def test_reach_violation_matches_geometry(scenarios: dict[str, Scenario], cave: str) -> None:
    """reach_violation equals geometry.reach(...).violation, and agrees exactly on which
    anchors are within reach (the search's filters test == 0)."""
    from rb_drake import geometry

    scn = scenarios[cave]
    rng = np.random.default_rng(3)
    lo, hi = scn.anchor_positions.min(axis=0) - 1.0, scn.anchor_positions.max(axis=0) + 1.0
    poses = np.column_stack([rng.uniform(lo[0], hi[0], 4000), rng.uniform(lo[1], hi[1], 4000),
                             rng.uniform(-4.0, 4.0, 4000)])
    booms = rng.integers(0, 4, len(scn.anchor_positions))
    expected = geometry.reach(scn.robot, poses, scn.anchor_positions, booms).violation
    got = reach_violation(scn.robot, poses, scn.anchor_positions, booms)
    np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12,
                               err_msg=f"{cave}: reach violation differs from geometry.reach")
    assert np.array_equal(got == 0.0, expected == 0.0), f"{cave}: reachability differs"
    assert (expected == 0.0).mean() > 0.01, f"{cave}: too few reachable pairs to compare"


def test_pull_angle_limit_decided_alike_at_its_edge(scenarios: dict[str, Scenario]) -> None:
    """robot.max_pull_angle_deg is the PULL_ANGLE test's limit in both paths: with the limit
    set 1e-9 rad above and below a pose's largest pull angle, the kernel and check_poses give
    the same reasons, feasibility and violation, and the pose passes and fails that test."""
    base = scenarios["demo-crevasse"]
    stance = base.stance(base.start_stance)
    poses = _around(_rng("pull edge"), np.asarray(base.start_pose, dtype=float), 400)
    check = check_poses(base, stance, poses, full=True)
    psi = np.abs(check.allocation.pull_angles[:, stance.attached]).max(axis=1)
    # poses whose only failure, if any, comes after the pull-angle test
    ok = np.isin(check.reason, [Reason.FEASIBLE, Reason.SINGULAR, Reason.STATICS,
                                Reason.PROBABILITY]) & np.isfinite(psi)
    picked = np.flatnonzero(ok)[:6]
    assert len(picked) >= 3, f"only {len(picked)} poses pass the tests before the pull angle"
    for k in picked:
        for side in (-1.0, 1.0):
            limit = psi[k] + side * 1e-9
            robot = base.robot.replace(max_pull_angle_deg=math.degrees(limit))
            assert robot.max_pull_angle == pytest.approx(limit, abs=1e-14)
            scn = dataclasses.replace(base, robot=robot)
            got = score_poses(scn, stance, poses)
            want = _reference_check(scn, stance, poses, None, False)
            label = f"pose {k}, limit {math.degrees(limit):.9f} deg"
            np.testing.assert_array_equal(got.reason, want.reason, err_msg=f"{label}: reasons")
            np.testing.assert_array_equal(got.feasible, want.feasible, err_msg=label)
            _assert_close("violation", label, got.violation, want.violation)
            if side < 0:
                assert want.reason[k] == Reason.PULL_ANGLE, f"{label}: not refused"
                assert got.violation[k] >= 1e-9, f"{label}: no pull-angle violation"
            else:
                assert want.reason[k] != Reason.PULL_ANGLE, f"{label}: refused inside the limit"


def test_move_table_decides_reach_as_reach_rows_at_its_edges(
        scenarios: dict[str, Scenario]) -> None:
    """lattice_move_table decides clear-cut reach without the square root or atan2: targets
    placed at the boom's length limits and at the shoulder's angle limits (and 1e-12 either
    side) from lattice poses must be answered as lattice_reach_rows answers them, pose by
    pose, and some must fall on each side."""
    from planning.lattice import SPAN, LatticeConfig, pack

    scn = scenarios["demo-crevasse"]
    cfg = LatticeConfig()
    params = robot_params(scn.robot, np.zeros(2))
    rng = _rng("move table edges")
    idx = np.column_stack([rng.integers(-40, 40, 300), rng.integers(-40, 40, 300),
                           rng.integers(-cfg.angle_count // 2, cfg.angle_count // 2, 300)])
    keys = np.unique(pack(idx, cfg.angle_count))
    poses = np.column_stack([(keys // cfg.angle_count) // SPAN - SPAN // 2,
                             (keys // cfg.angle_count) % SPAN - SPAN // 2,
                             keys % cfg.angle_count - cfg.angle_count // 2]) * np.array(
        [cfg.position_step, cfg.position_step, cfg.angle_step])
    robot = scn.robot
    for boom in range(4):
        # targets from the first pose's shoulder: at each length limit and each angle limit
        x, y, phi = poses[0]
        sx, sy = robot.shoulder_array[boom]
        px, py = x + math.cos(phi) * sx - math.sin(phi) * sy, y + math.sin(phi) * sx + math.cos(
            phi) * sy
        targets = []
        lo, hi = robot.boom_length
        for length in (lo, hi, 0.5 * (lo + hi)):
            for angle in (-robot.shoulder_range, robot.shoulder_range, 0.0):
                for nudge in (-1e-12, 0.0, 1e-12):
                    a = phi + robot.shoulder_directions[boom] + angle + nudge
                    ell = length + nudge
                    targets.append((px + ell * math.cos(a), py + ell * math.sin(a)))
        targets = np.array(targets)
        rows = np.arange(len(keys))
        starts = np.array([0, 0, 0, 0, 0])
        starts[boom + 1:] = len(keys)
        grid = (SPAN, float(cfg.position_step), float(cfg.angle_step), int(cfg.angle_count))
        got, offsets = lattice_move_table(keys, rows, starts, targets, params, *grid,
                                          np.zeros((0, 4)))
        reached = 0
        for k, (tx, ty) in enumerate(targets):
            want = lattice_reach_rows(keys, rows, float(tx), float(ty), boom, params, *grid,
                                      np.zeros((0, 4)))
            K = len(targets)
            mine = got[offsets[boom * K + k]:offsets[boom * K + k + 1]]
            np.testing.assert_array_equal(mine, want, err_msg=f"boom {boom}, target {k}")
            reached += 0 in want
        assert 0 < reached < len(targets), f"boom {boom}: edge targets all on one side"


def test_kernel_cache_stamped_with_every_kernel_source(tmp_path: Path,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """numba's cache entries of every compiled kernel, in rb_drake.kernel and beside the lattice
    in planning, are stamped with the whole kernel's sources: an edit to one module (here
    allocation's) changes the stamp of the others' (here pose_kernel's and the flood fill's),
    whose cached code holds its compiled functions."""
    import numba

    import planning.flood_kernel
    import planning.lattice_kernels
    from rb_drake import kernel
    from rb_drake.kernel import cache_stamp

    modules = [getattr(kernel, name) for name in ("special", "algebra3", "collision",
                                                   "allocation", "pose_kernel", "threads")]
    modules += [planning.flood_kernel, planning.lattice_kernels]
    dispatchers = [f for m in modules for f in vars(m).values()
                   if isinstance(f, numba.core.registry.CPUDispatcher)]
    assert len(dispatchers) > 30
    for f in dispatchers:
        assert isinstance(f._cache._impl.locator, cache_stamp.LOCATORS), f"{f.__name__} unstamped"

    copy = tmp_path / "kernel"
    copy.mkdir()
    for path in cache_stamp.KERNEL_DIR.glob("*.py"):
        (copy / path.name).write_bytes(path.read_bytes())
    monkeypatch.setattr(cache_stamp, "KERNEL_DIR", copy)
    flood_file = planning.flood_kernel.__file__
    before = [cache_stamp.source_stamp(str(copy / "pose_kernel.py")),
              cache_stamp.source_stamp(flood_file)]
    with (copy / "allocation.py").open("a") as f:
        f.write("# edited\n")
    after = [cache_stamp.source_stamp(str(copy / "pose_kernel.py")),
             cache_stamp.source_stamp(flood_file)]
    assert before[0] != after[0] and before[1] != after[1], "an edit left a stamp unchanged"


def test_numba_cache_files_are_locked_between_processes(tmp_path) -> None:
    """Saving and loading a compiled function's cache entry hold a lock on its index (two
    processes compiling one function at once could otherwise pair one's index with the other's
    code: a segmentation fault in the next process)."""
    import fcntl

    from numba.core import caching

    from rb_drake.kernel import cache_stamp

    cache_stamp.install()  # a second call changes nothing
    cache_file = caching.IndexDataCacheFile
    assert getattr(cache_file.save, "__rbp_locked__", False), "save is not wrapped"
    assert getattr(cache_file.load, "__rbp_locked__", False), "load is not wrapped"
    assert not getattr(cache_file.save.__wrapped__, "__rbp_locked__", False), "wrapped twice"
    entry = cache_file(str(tmp_path), "f-1.py311", b"stamp")
    entry.save(("sig", "target"), {"code": 1})
    assert entry.load(("sig", "target")) == {"code": 1}
    lock = tmp_path / "f-1.py311.nbi.lock"
    assert lock.exists(), "no lock file beside the index"
    with open(lock) as handle:  # nothing holds it once save and load are done
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
