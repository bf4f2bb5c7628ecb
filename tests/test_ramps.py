"""Release and attach ramps (planning.ramps) and eased reach phases (planning.easing) in the
planned plans of the bundled caves: every gripper opens and closes on a slack boom, statics
hold on every ramp step, no ramp lowers a grasp below its ends (so p_path covers them), and the
verifier rejects a plan without one or with a loaded release."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import pytest

from planning.check import verify_plan
from planning.easing import _progress
from planning.plan import plan_configurations
from planning.plan_faults import ramp_removed, release_loaded
from planning.plan_model import plan_of
from planning.probability import path_probability
from planning.ramps import RAMP_DURATION, RELEASE_TENSION, ramp_statics
from rb_drake.statics import STATICS_TOL
from systems.trajectory import plan_scenario

Plan = dict[str, Any]
TOL = 1e-9


def _handovers(plan: Plan):
    """(body phase, boom, its ramp's step indices from the gripper's contact outwards, the
    reach's configuration at the contact, 'release' or 'attach')."""
    phases = plan["phases"]
    for k, phase in enumerate(phases):
        if phase["kind"] != "body":
            continue
        steps = phase["steps"]
        if k + 1 < len(phases):
            j = phases[k + 1]["free_boom"]
            n = len(steps) - 1
            run = []
            while n >= 0 and steps[n].get("ramp", {}).get("boom") == j:
                run.append(n)
                n -= 1
            yield k, j, [*run, n], phases[k + 1]["steps"][0], "release"
        if k > 0:
            j = phases[k - 1]["free_boom"]
            n = 0
            run = []
            while steps[n].get("ramp", {}).get("boom") == j:
                run.append(n)
                n += 1
            yield k, j, [*run, n], phases[k - 1]["steps"][-1], "attach"


@pytest.mark.parametrize("cave", ["demo-shaft", "demo-crevasse", "rockfall-3"])
def test_every_gripper_opens_and_closes_on_a_slack_boom(cave_plans, cave: str) -> None:
    plan = cave_plans[cave]
    seen = 0
    for k, j, run, _, what in _handovers(plan):
        steps = plan["phases"][k]["steps"]
        contact = steps[run[0]]
        assert len(run) >= 2, f"{cave} phases[{k}]: no {what} ramp of boom {j}"
        assert contact["tension"][j] <= RELEASE_TENSION, (
            f"{cave} phases[{k}]: boom {j}'s planned tension {contact['tension'][j]} N at its "
            f"gripper's {what}, over {RELEASE_TENSION} N")
        assert contact["ramp"]["share"] == pytest.approx(1.0, abs=TOL)
        span = abs(steps[run[-1]]["t"] - contact["t"])
        assert span >= RAMP_DURATION - 1e-6, f"{cave} phases[{k}]: {what} ramp lasts {span} s"
        for n in run:
            np.testing.assert_allclose(steps[n]["pose"], contact["pose"], atol=TOL,
                                       err_msg=f"{cave} phases[{k}] step {n}: the body moved")
        seen += 1
    assert seen == 2 * plan["regrasps"], f"{cave}: {seen} ramps for {plan['regrasps']} regrasps"


@pytest.mark.parametrize("cave", ["demo-shaft", "rockfall-3"])
def test_statics_hold_at_every_ramp_step(cave_plans, cave: str) -> None:
    """With the share of the ramped limb on the body; at the contact the ramp is the reach's
    own configuration (the three other booms' tensions equal)."""
    plan = cave_plans[cave]
    scn = plan_scenario(plan)
    for k, j, run, reach_end, _ in _handovers(plan):
        stance = scn.stance(tuple(plan["phases"][k]["stance"]))
        for n in run[:-1]:
            step = plan["phases"][k]["steps"][n]
            prob, load, torque = ramp_statics(scn, np.array(step["pose"]), stance, j,
                                              step["ramp"]["share"])
            residual = np.abs(prob.A[0] @ np.array(step["tension"]) - load).max()
            assert residual <= STATICS_TOL, f"{cave} phases[{k}] step {n}: residual {residual}"
            assert abs(torque) <= scn.robot.shoulder_torque_max
        contact = plan["phases"][k]["steps"][run[0]]
        others = [i for i in range(4) if i != j]
        np.testing.assert_allclose(np.array(contact["tension"])[others],
                                   np.array(reach_end["tension"], dtype=float)[others],
                                   atol=1e-9, err_msg=f"{cave} phases[{k}]: contact")


@pytest.mark.parametrize("cave", ["demo-shaft", "demo-crevasse"])
def test_no_ramp_lowers_a_grasp_so_p_path_covers_them(cave_plans, cave: str) -> None:
    """Each grasp's P along a ramp stays at or above the lower of its two ends (the steps are
    convex combinations, P monotone in the grasp's own tension): p_path, over the steps, is
    the same with or without the ramp steps."""
    plan = cave_plans[cave]
    for k, _j, run, _reach_end, _ in _handovers(plan):
        steps = plan["phases"][k]["steps"]
        ends = (steps[run[-1]], steps[run[0]])
        for n in run[1:-1]:
            for i in range(4):
                p = steps[n]["p_grasp"][i]
                low = min(e["p_grasp"][i] for e in ends)
                assert p >= low - 1e-12, f"{cave} phases[{k}] step {n} boom {i}: {p} < {low}"
    steps = (s for ph in plan["phases"] for s in ph["steps"])
    without = [c for c, s in zip(plan_configurations(plan_of(plan)), steps, strict=True)
               if "ramp" not in s]
    alone = path_probability(without, plan["robot"]["attach_failure"])
    assert alone.p_path == pytest.approx(plan["p_path"], rel=1e-12), (alone.p_path,
                                                                       plan["p_path"])


def test_the_verifier_rejects_a_missing_ramp_and_a_loaded_release(cave_plans) -> None:
    plan = cave_plans["demo-shaft"]
    assert verify_plan(plan) == []
    for make, rules in ((ramp_removed, {"release", "attach"}),
                        (release_loaded, {"release", "attach"})):
        for seed in range(4):
            fault = make(plan, np.random.default_rng(seed))
            found = {p.rule for p in verify_plan(fault.plan) if p.phase == fault.phase}
            assert found & rules, f"{fault.what}: rejected by {found}, not by {rules}"


def test_a_release_without_its_last_ramp_step_is_rejected(cave_plans) -> None:
    """The last release step gone (the gripper would open at the ramp's middle, with the boom
    still pulling): rule release, at that body phase."""
    plan = copy.deepcopy(cave_plans["demo-crevasse"])
    k, _j, run, _, _ = next(h for h in _handovers(plan) if h[4] == "release")
    del plan["phases"][k]["steps"][run[0]]
    problems = [p for p in verify_plan(plan) if p.rule == "release"]
    assert problems and problems[0].phase == k, [str(p) for p in verify_plan(plan)][:5]


def test_eased_motions_start_and_stop_gently(cave_plans) -> None:
    """An eased phase's free tip (reaching) or body moves an eighth (EASE_STEPS 4) or a
    quarter (2) of a planned interval in its first and last time steps (at most that share of
    the step limit), then three times as much: the speed grows from rest over several steps
    and falls to rest the same way. Ramp steps and the final dwell stand still around it."""
    plan = cave_plans["demo-shaft"]
    limit, turn_limit = plan["limits"]["step"], plan["limits"]["turn_step"]
    eased = {"body": 0, "reach": 0}
    for k, phase in enumerate(plan["phases"]):
        ease = phase.get("motion", {}).get("eased")
        if not ease:
            continue
        steps = [s for s in phase["steps"] if "ramp" not in s][:-1]  # the motion, no dwell
        key = "free_tip" if phase["kind"] == "reach" else "pose"
        points = np.array([s[key] for s in steps])
        moves = [(np.linalg.norm(np.diff(points[:, :2], axis=0), axis=1), limit)]
        if phase["kind"] == "body":
            moves.append((np.abs(np.diff(points[:, 2])), turn_limit))
        slow = phase["motion"].get("slowed", 1)
        share = _progress((len(steps) - 1 - ease) // slow, ease, slow)[0]
        assert share == pytest.approx(1.0 / (2 * ease * slow))
        for move, lim in moves:
            for n in (0, -1):
                assert move[n] <= share * lim + 1e-12, (
                    f"phases[{k}]: move {n} {move[n]}, over {share} x {lim}")
            assert move[1] >= 2.9 * move[0] - 1e-12 and move[-2] >= 2.9 * move[-1] - 1e-12, (
                f"phases[{k}]: {move[:3]} ... {move[-3:]} does not ease in and out")
        eased[phase["kind"]] += 1
    assert eased["reach"] >= plan["regrasps"] // 2 and eased["body"] >= plan["regrasps"] // 2, (
        f"eased phases {eased} of {plan['regrasps']} regrasps")
