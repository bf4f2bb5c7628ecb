"""`rbp plan --min-success P`: the fewest-regrasp route whose predicted success is at least P
(planning.constrained), held against the complete search's proven optimum on the demo cave
with a coarse lattice (5 cm x 5 deg; the code is the same at any resolution)."""

from __future__ import annotations

import json
import math

import pytest

import planning.complete as complete_module
from planning.complete import complete_search
from planning.complete_config import AnytimeConfig, CompleteConfig
from planning.constrained import constrained_search
from planning.lattice import LatticeConfig
from rb_drake.scenario import Scenario, bundled_caves, load_scenario

COARSE = LatticeConfig(position_step=0.05, angle_step_deg=5.0)
EXHAUSTIVE = AnytimeConfig(improve_factor=None)


@pytest.fixture(scope="module")
def demo() -> Scenario:
    return load_scenario(bundled_caves()["demo-shaft"])


@pytest.fixture(scope="module")
def optimal(demo: Scenario):
    """The most robust route (lowest search cost), proved."""
    found = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0,
                                                      anytime=EXHAUSTIVE))
    assert found.success and found.quality == "optimal"
    return found


@pytest.fixture(scope="module")
def fewest(demo: Scenario) -> int:
    """The fewest regrasps of any route: A* with every edge costing the same."""
    patch = pytest.MonkeyPatch()
    patch.setattr(complete_module, "edge_cost", lambda scn, *args: 0.01)
    try:
        found = complete_search(demo, CompleteConfig(COARSE, heuristic_weight=1.0,
                                                      anytime=EXHAUSTIVE))
    finally:
        patch.undo()
    assert found.success and found.quality == "optimal"
    return len(found.path) - 1


def end_terms(scn: Scenario, found) -> float:
    """What the constrained search adds to a route's edges: -r of the start configuration and
    of the last stance at the route's goal pose (the plan's p_path takes both)."""
    from rb_drake.feasibility import check_poses

    start = check_poses(scn, scn.stance(tuple(scn.start_stance)),
                        [scn.start_pose]).allocation.robustness[0]
    goal = check_poses(scn, scn.stance(found.path[-1][0]),
                       [found.goal_pose]).allocation.robustness[0]
    return max(0.0, -float(start)) + max(0.0, -float(goal))


@pytest.fixture(scope="module")
def tight(demo: Scenario, optimal):
    """P just below the optimum's predicted success, its start and goal configurations too."""
    p = math.exp(-(optimal.cost + end_terms(demo, optimal))) * (1 - 1e-6)
    return p, constrained_search(demo, p, CompleteConfig(COARSE))


@pytest.fixture(scope="module")
def loose(demo: Scenario):
    return constrained_search(demo, 1e-6, CompleteConfig(COARSE))


def test_just_below_the_optimum_finds_a_route_within_p(optimal, tight) -> None:
    p, found = tight
    assert found.success, found.reason
    assert found.cost <= -math.log(p) * (1 + 1e-12), "the route misses the success asked for"
    assert len(found.path) - 1 <= len(optimal.path) - 1, (
        "the most robust route also reaches P, so the fewest-regrasp one has at most its "
        "regrasps")


def test_above_the_optimum_is_a_proof_of_no_route(demo: Scenario, optimal) -> None:
    # every route's edges cost at least the optimum's, and its end terms are not negative
    p = math.exp(-optimal.cost) * (1 + 1e-6)
    found = constrained_search(demo, p, CompleteConfig(COARSE))
    assert not found.success and found.stop == "noroute", (
        f"no route can beat the proven optimum, yet: {found.stop} {found.reason}")
    from rb_drake.errors import as_given

    assert as_given(p) in found.reason, f"the reason does not name P as given: {found.reason}"


def test_a_loose_p_gives_the_fewest_regrasps(demo: Scenario, loose, fewest: int) -> None:
    assert loose.success
    assert len(loose.path) - 1 == fewest, (
        f"{len(loose.path) - 1} regrasps where the unconstrained fewest is {fewest}")
    # the edges' costs and the end terms add up to the reported cost
    total = sum(loose.graph.costs[u, v]
                for u, v in zip(loose.path[:-1], loose.path[1:], strict=True))
    assert total + end_terms(demo, loose) == pytest.approx(loose.cost, rel=1e-6)


def test_regrasps_never_fall_as_p_rises(loose, tight) -> None:
    _, found = tight
    assert len(loose.path) - 1 <= len(found.path) - 1, "more regrasps for a looser P"
    assert loose.cost >= found.cost - 1e-12 or len(loose.path) < len(found.path), (
        "with as many regrasps, the looser search should have found the cheaper route too")


def test_the_plans_p_path_is_at_least_the_success_asked_for() -> None:
    """A route's edges score its transition poses; the footstep plan's p_path also takes the
    start configuration and the goal pose. Without them in the cost, `--min-success 0.978` on
    this cave answered a 2-regrasp route with exp(-cost) 0.9801 and p_path 0.9765 ("success");
    now the route is one whose p_path reaches P, and exp(-cost) never exceeds p_path."""
    from planning.footsteps import FootstepConfig, plan_footsteps
    from planning.plan import build_plan
    from rbp.api import generate_scenario

    cave = generate_scenario("shaft", seed=3, length=(3.5, 4.0))
    for p in (0.978, 0.9):
        fp = plan_footsteps(cave, FootstepConfig(min_success=p))
        assert fp.success, f"P {p}: {fp.reason}"
        plan = build_plan(cave, fp, "rbp")
        assert plan.p_path is not None and plan.p_path >= p, (
            f"P {p}: the plan's p_path {plan.p_path} misses the success asked for")
        assert math.exp(-fp.cost) <= plan.p_path * (1 + 1e-9), (
            f"P {p}: exp(-cost) {math.exp(-fp.cost)} promises more than p_path {plan.p_path}")


def test_cli_min_success_is_recorded(tmp_path) -> None:
    """The flag reaches the search and the plan file (a budget stop, to keep it short: the
    searches above test what it finds)."""
    from cli_helpers import run_rbp

    out = tmp_path / "plan.json"
    run = run_rbp("plan", "demo-shaft", "--footsteps-only", "--no-pictures", "--min-success",
                  "0.5", "--max-expansions", "3", "-o", str(out), cwd=tmp_path)
    assert run.returncode != 0 and "predicted success >= 0.5" in run.stdout + run.stderr, (
        run.stdout + run.stderr)
    plan = json.loads(out.read_text())
    assert plan["search"]["min_success"] == 0.5 and plan["search"]["stop"] == "budget"
    assert plan["search"]["expansions"] <= 4


@pytest.mark.parametrize("args, field", [(["--min-success", "1.5"], "--min-success"),
                                         (["--min-success", "0"], "--min-success"),
                                         (["--min-success", "0.9", "--thorough"],
                                          "--min-success")])
def test_bad_min_success_gets_one_line(tmp_path, args: list[str], field: str) -> None:
    from cli_helpers import run_rbp

    out = tmp_path / "plan.json"
    run = run_rbp("plan", "demo-shaft", *args, "-o", str(out), cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and field in lines[0], run.stderr
    assert not out.exists()
