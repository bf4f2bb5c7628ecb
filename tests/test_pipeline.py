"""The full pipeline on the bundled demo cave: footsteps, seeds, SCP, the plan file."""

from __future__ import annotations

import numpy as np
import pytest

from planning.check import check_plan
from planning.figures import animate_plan, phase_figure
from planning.footsteps import FootstepMemo, plan_footsteps
from planning.pipeline import (
    PipelineConfig,
    failed_move,
    motion_summary,
    phase_motions,
    plan_climb,
)
from planning.plan import build_motion_plan, validate
from planning.plan_model import Plan, plan_dict, plan_of
from rb_drake.scenario import Scenario, bundled_caves, load_scenario

TOL = 1e-9


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


@pytest.fixture(scope="module")
def footsteps(demo):
    fp = plan_footsteps(demo)
    assert fp.success, fp.reason
    return fp


@pytest.fixture(scope="module")
def motions(demo, footsteps):
    motions, failure = phase_motions(demo, footsteps, PipelineConfig())
    assert failure == "", failure
    return motions


@pytest.fixture(scope="module")
def plan(demo, footsteps, motions):
    timing = {"footstep": footsteps.seconds, "total": footsteps.seconds}
    built = build_motion_plan(demo, footsteps, motions, "rbp", timing, PipelineConfig().dt)
    assert isinstance(built, Plan) and all(p.motion is not None for p in built.phases)
    return plan_dict(built)  # the tests below read the plan as its file holds it


def test_plan_verifies_from_scratch(plan):
    validate(plan)
    assert plan["success"], plan["reason"]
    problems = check_plan(plan)
    assert problems == [], "\n".join(problems[:10])


def test_phases_alternate_and_connect(demo, plan, footsteps):
    phases = plan["phases"]
    assert len(phases) == 2 * len(footsteps.steps) + 1, f"{len(phases)} phases"
    for k, phase in enumerate(phases):
        assert phase["kind"] == ("body" if k % 2 == 0 else "reach"), f"phase {k}"
        assert len(phase["steps"]) >= 2, f"phase {k} has {len(phase['steps'])} steps"
    for k in range(len(phases) - 1):
        end = np.array(phases[k]["steps"][-1]["pose"])
        start = np.array(phases[k + 1]["steps"][0]["pose"])
        assert np.allclose(end, start, atol=1e-9), f"phases {k}->{k + 1}: {end} vs {start}"
    first = np.array(phases[0]["steps"][0]["pose"])
    assert np.allclose(first, demo.start_pose, atol=1e-9), f"starts at {first}"
    last = np.array(phases[-1]["steps"][-1]["pose"])
    goal_gap = np.linalg.norm(last[:2] - np.array(demo.goal_position))
    assert goal_gap <= demo.goal_tolerance + 1e-9, f"ends {goal_gap:.3f} m from the goal"


def test_reach_tips_run_anchor_to_anchor(demo, plan):
    for k, phase in enumerate(plan["phases"]):
        if phase["kind"] != "reach":
            continue
        tips = np.array([s["free_tip"] for s in phase["steps"]])
        a = demo.anchor_positions[demo.anchor_index[phase["from_anchor"]]]
        b = demo.anchor_positions[demo.anchor_index[phase["to_anchor"]]]
        assert np.allclose(tips[0], a, atol=1e-9), f"phase {k}: tip starts at {tips[0]}, not {a}"
        assert np.allclose(tips[-1], b, atol=1e-9), f"phase {k}: tip ends at {tips[-1]}, not {b}"


def test_time_steps_are_uniform_and_increasing(plan):
    dt = plan["time_step"]
    for k, phase in enumerate(plan["phases"]):
        t = np.array([s["t"] for s in phase["steps"]])
        assert np.allclose(np.diff(t), dt, atol=1e-5), f"phase {k}: steps {np.diff(t)}"
        motion = [s for s in phase["steps"] if "ramp" not in s]  # before a release ramp
        last, dwell = motion[-2:]
        assert {**last, "t": 0} == {**dwell, "t": 0}, f"phase {k} does not end with a dwell"
    for k in range(len(plan["phases"]) - 1):
        end = plan["phases"][k]["steps"][-1]["t"]
        start = plan["phases"][k + 1]["steps"][0]["t"]
        assert abs(start - end) < 1e-9, f"phase {k + 1} starts at {start}, phase {k} ends {end}"


def test_scp_never_worse_than_its_seed(plan):
    rows = motion_summary(plan_of(plan))
    assert len(rows) == len(plan["phases"]), "a phase without a motion record"
    for r in rows:
        assert r["min"] >= r["seed_min"] - TOL, (
            f"phase {r['phase']}: SCP minimum P {r['min']} below the seed's {r['seed_min']}")
    # (The mean may dip slightly: SCP maximises sum log P less smoothness and dynamics
    # penalties, and guarantees the merit and the minimum, not the mean.)


def test_motion_records_align_with_steps(plan):
    for k, phase in enumerate(plan["phases"]):
        n = len(phase["steps"])
        motion = phase["motion"]
        for key in ("seed_p_success", "seed_tension", "seed_effort", "effort"):
            assert len(motion[key]) == n, f"phase {k}: {key} has {len(motion[key])} of {n}"


def test_scp_improves_some_phase(plan):
    rows = motion_summary(plan_of(plan))
    gains = [r["mean"] - r["seed_mean"] for r in rows]
    assert max(gains) > 1e-4, f"SCP raised no phase's mean probability: gains {gains}"


def test_motion_is_deterministic(demo, footsteps, motions):
    again, failure = phase_motions(demo, footsteps, PipelineConfig())
    assert failure == ""
    for k, (a, b) in enumerate(zip(motions, again, strict=True)):
        assert np.array_equal(a.poses, b.poses), f"phase {k} differs between runs"


def test_seeds_only_plan_verifies(demo, footsteps):
    cfg = PipelineConfig(optimise=False)
    motions, failure = phase_motions(demo, footsteps, cfg)
    assert failure == "", failure
    plan = plan_dict(build_motion_plan(demo, footsteps, motions, "rbp", {}, cfg.dt))
    assert check_plan(plan) == [], "the seeds-only plan does not verify"
    assert all(not p["motion"]["optimised"] for p in plan["phases"])


def test_naive_plan_stops_at_footsteps(demo):
    plan = plan_dict(plan_climb(demo, "naive"))
    validate(plan)
    assert all("motion" not in p for p in plan["phases"]), "naive phases hold trajectories"
    assert plan["timing"]["footstep"] > 0


def test_unknown_planner_is_refused(demo):
    with pytest.raises(ValueError, match="planner"):
        plan_climb(demo, "astar")


def test_figures(demo, plan, tmp_path):
    k = next(k for k, p in enumerate(plan["phases"]) if p["kind"] == "reach")
    fig = phase_figure(plan, k)
    lines = [line for ax in fig.axes for line in ax.get_lines()]
    assert len(lines) >= 6, f"only {len(lines)} curves in Fig. 6"
    gif = tmp_path / "climb.gif"
    small = dict(plan, phases=plan["phases"][:2])
    animate_plan(demo, small, str(gif), max_frames=4)
    data = gif.read_bytes()
    assert data[:6] in (b"GIF87a", b"GIF89a"), "not a GIF"
    assert not list(tmp_path.glob(".*.tmp")), "a temporary file was left behind"


def test_scp_raises_the_mean_where_there_is_room(plan):
    """SCP raises the mean P on most phases whose seed leaves room (mean below 1 - ROOM)."""
    rows = [r for r in motion_summary(plan_of(plan)) if r["room"]]
    assert rows, "no phase with room to improve: the test needs another cave"
    raised = [r["phase"] for r in rows if r["mean"] > r["seed_mean"] + 1e-9]
    assert len(raised) > len(rows) / 2, (
        f"SCP raised the mean on {len(raised)} of {len(rows)} phases with room: "
        f"{[(r['phase'], r['seed_mean'], r['mean']) for r in rows]}")


def test_failed_move_names_the_right_step(footsteps):
    n = len(footsteps.steps)
    for done, k in ((0, 0), (1, 0), (2, 1), (3, 1), (2 * n, n - 1)):
        stance, boom, anchor = failed_move(footsteps, done)
        step = footsteps.steps[k]
        assert (stance, boom, anchor) == (tuple(footsteps.stances[k]), step.boom,
                                          step.to_anchor), f"{done} phases done: step {k}"


def test_excluded_move_is_not_taken_and_memo_is_reused(demo, footsteps):
    """Searching again without the first move (what the pipeline does when a motion fails)
    gives a plan without it, and reuses the transitions already searched."""
    move = failed_move(footsteps, 1)
    memo = footsteps.memo
    assert isinstance(memo, FootstepMemo), type(memo)

    def decided() -> int:
        return len(memo.transitions) + len(memo.lattice.transitions)

    known = decided()
    assert known >= footsteps.transitions_tested > 0, (known, footsteps.transitions_tested)
    again = plan_footsteps(demo, exclude=[move], memo=memo)
    taken = {(tuple(st), s.boom, s.to_anchor) for st, s in zip(again.stances, again.steps,
                                                                  strict=False)}
    assert move not in taken, f"excluded move {move} taken again"
    assert again.success, again.reason
    assert again.transitions_tested < decided(), (
        f"tested {again.transitions_tested} of {decided()} transitions: the memo "
        f"({known} known) was not reused")


def test_a_failed_motion_names_the_retries_and_nulls_the_summary(demo, monkeypatch):
    """A route whose motion keeps failing ends with a reason naming each move the footstep
    search was made again without, and a failed plan has no summary: p_path, p_min and
    p_grasps all null (issue 32: p_grasps 0.71 beside a null p_path)."""
    import planning.pipeline as pipeline

    def singular(scn, fp, *args, **kwargs):
        return [], f"body phase 0 in stance {list(fp.stances[0])}: SINGULAR"

    monkeypatch.setattr(pipeline, "phase_motions", singular)
    plan = plan_climb(demo, config=PipelineConfig(motion_retries=2))
    assert not plan.success
    assert (plan.p_path, plan.p_min, plan.p_grasps) == (None, None, None), (
        f"a failed plan carries p_path {plan.p_path}, p_min {plan.p_min}, "
        f"p_grasps {plan.p_grasps}")
    reason = plan.reason
    assert "SINGULAR" in reason and "searched footsteps again 2 times" in reason, reason
    assert reason.count("boom ") == 2 and "motion_retries 2 used up" in reason, reason
    validate(plan_dict(plan))


def test_no_retry_is_said_so(demo, monkeypatch):
    import planning.pipeline as pipeline

    monkeypatch.setattr(pipeline, "phase_motions",
                        lambda scn, fp, *a, **k: ([], "body phase 0: SINGULAR"))
    plan = plan_climb(demo, config=PipelineConfig(motion_retries=0))
    assert plan.reason.endswith("no footstep search again (motion_retries 0)"), plan.reason
