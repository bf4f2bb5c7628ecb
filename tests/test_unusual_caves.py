"""Caves unlike the benchmark's (other lengths, densities, gravities and robots), where the
whole planner (`rbp plan`: footsteps, seeds, SCP, ramps) went wrong: each test the smallest
reproduction of one finding.
"""

from __future__ import annotations

import math

import numpy as np

import rbp
from planning.body_seeds import _ompl_waypoints
from planning.seeds import SeedConfig


def test_ompl_body_seed_takes_a_heading_past_pi(capfd):
    """A body turned past pi (3.18 rad on `rbp scenario generate --kind rockfall --seed 7029
    --length 8 8 --anchor-density 6`'s route) lay outside SE(2)'s yaw bounds: OMPL refused the
    start ("Skipping invalid start state (invalid bounds)", printed on the terminal) and the
    seed method failed. The same poses turned by a whole turn must plan as the poses do."""
    scn = rbp.load_scenario("demo-shaft")
    stance = scn.stance(scn.start_stance)
    base = np.array(scn.start_pose)
    goal = base + np.array([0.05, 0.08, 0.05])
    plain, why = _ompl_waypoints(scn, stance, base, goal, SeedConfig(), 7)
    assert plain is not None, why
    turn = np.array([0.0, 0.0, 2.0 * math.pi])
    for shift in (turn, -turn):
        path, why = _ompl_waypoints(scn, stance, base + shift, goal + shift, SeedConfig(), 7)
        assert path is not None, why
        np.testing.assert_array_equal(path[0], base + shift)
        np.testing.assert_array_equal(path[-1], goal + shift)
        np.testing.assert_allclose(path[:, 2], plain[:, 2] + shift[2], atol=1e-9)
    err = capfd.readouterr().err
    assert "invalid" not in err and "Error" not in err, err


def test_a_body_phase_failing_at_its_start_excludes_the_move_into_its_stance():
    """A body phase fails; the first retry excludes the move out of its stance (the body's way
    out), a second failure in the same stance the move into it (its start pose is what fails:
    generated rockfall 7029 spent its ten retries on one stance's exits)."""
    from types import SimpleNamespace

    from planning.pipeline import failed_move

    def step(boom: int, to: str) -> SimpleNamespace:
        return SimpleNamespace(boom=boom, to_anchor=to)

    stances = [("a", "b", "c", "d"), ("e", "b", "c", "d"), ("e", "f", "c", "d")]
    fp = SimpleNamespace(stances=stances, steps=[step(0, "e"), step(1, "f")])
    out = (stances[1], 1, "f")  # body phase 1 (phases done: 2) leads to the move out
    assert failed_move(fp, 2) == out
    assert failed_move(fp, 2, [out]) == (stances[0], 0, "e"), \
        "a second failure in the same stance must exclude the move into it"
    assert failed_move(fp, 1, [out]) == (stances[0], 0, "e"), "a failed reach is its own move"
    assert failed_move(fp, 0, [(stances[0], 3, "x")]) == (stances[0], 0, "e"), \
        "the first stance has no move into it"
    assert failed_move(fp, 4) == (stances[1], 1, "f"), "the last body phase: the previous move"


def test_generated_rockfall_7029_climbs():
    """`rbp scenario generate --kind rockfall --seed 7029 --length 8 8 --anchor-density 6`:
    one stance's body phase failed from its start pose in all ten retries (each excluding
    another way out); excluding the way in, the climb plans and verifies."""
    from planning.check import check_plan
    from planning.plan_model import plan_dict
    from rb_drake.generate import CaveConfig, generate_cave

    scn = generate_cave("rockfall", 7029, CaveConfig(length=(8.0, 8.0), anchor_density=6.0))
    plan = rbp.plan(scn)
    assert plan.success, plan.reason
    problems = check_plan(plan_dict(plan))
    assert problems == [], "\n".join(problems)
