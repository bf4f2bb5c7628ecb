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
