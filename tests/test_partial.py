"""`rbp plan --partial` (issue 29): when no route reaches the goal, the climb to the expanded
stance nearest it, flown through the pipeline, verified as a partial plan and never as a
success.

blocked-shaft (a bundled cave with no route: its search expands 32 vertices in seconds) and
demo-shaft under a budget of a few expansions are the no-route cases."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest

from planning.complete import complete_search
from planning.complete_config import CompleteConfig
from planning.lattice_search import LatticeMemo
from planning.pipeline import PipelineConfig
from planning.plan_model import Partial, Plan
from planning.search_cost import centroid_distance, edge_cost
from planning.search_outcome import Stop
from rb_drake.errors import RbpInputError
from rb_drake.scenario import Scenario, bundled_caves, load_scenario

DIST_TOL = 1e-12  # m: the same measure, recomputed


@pytest.fixture(scope="module")
def blocked() -> Scenario:
    return load_scenario(bundled_caves()["blocked-shaft"])


SEARCHES: list = []  # the footstep plans behind the `plan` fixture


@pytest.fixture(scope="module")
def plan(blocked: Scenario) -> Plan:
    """The partial plan of blocked-shaft, seeds without SCP (fast; SCP changes no rule)."""
    from rbp.api import plan as make

    SEARCHES.clear()
    return make(blocked, PipelineConfig(optimise=False), partial=True,
                footsteps_done=SEARCHES.append)


def _nearest_property(scn: Scenario, result) -> None:
    """The partial route ends in the expanded vertex nearest the goal, starts at the start,
    moves one boom per edge and costs what its edges cost."""
    near = result.partial
    assert near is not None, "a failed search asked for a partial route returned none"
    expanded = {v for v, _ in result.expanded}
    best = min(centroid_distance(scn, v[0]) for v in expanded)
    assert near.path[-1] in expanded, "the partial route ends in a vertex never expanded"
    assert abs(near.goal_distance - best) <= DIST_TOL, (
        f"the route ends {near.goal_distance} m from the goal, the nearest expanded vertex "
        f"is {best} m")
    assert abs(centroid_distance(scn, near.path[-1][0]) - near.goal_distance) <= DIST_TOL
    assert near.path[0][0] == tuple(scn.start_stance), "the route does not start at the start"
    cost = 0.0
    for (a, _), (b, _), pose in zip(near.path[:-1], near.path[1:], near.poses, strict=True):
        moved = [j for j in range(4) if a[j] != b[j]]
        assert len(moved) == 1, f"an edge {a} -> {b} moves booms {moved}, not one"
        cost += edge_cost(scn, a, moved[0], b[moved[0]], pose)
    assert math.isclose(cost, near.cost, rel_tol=1e-9, abs_tol=1e-12), (cost, near.cost)
    assert len(near.alternatives) == len(near.poses) == len(near.probabilities)


def test_partial_route_is_to_the_nearest_expanded_vertex_no_route(blocked: Scenario) -> None:
    plain = complete_search(blocked, CompleteConfig(), memo=LatticeMemo())
    asked = complete_search(blocked, CompleteConfig(), memo=LatticeMemo(), partial=True)
    assert not asked.success and asked.stop == Stop.NOROUTE, asked.reason
    assert plain.partial is None, "a search not asked for a partial route returned one"
    # asking for it changes no decision of the search
    assert (plain.stop, plain.expansions, plain.transitions_tested) == \
        (asked.stop, asked.expansions, asked.transitions_tested)
    assert [v for v, _ in plain.expanded] == [v for v, _ in asked.expanded]
    _nearest_property(blocked, asked)
    assert len(asked.partial.path) > 1, "blocked-shaft's start stance can move"


def test_partial_route_on_a_budget_stop() -> None:
    scn = load_scenario(bundled_caves()["demo-shaft"])
    result = complete_search(scn, CompleteConfig(max_expansions=6), memo=LatticeMemo(),
                             partial=True)
    assert not result.success and result.stop == Stop.BUDGET, result.reason
    _nearest_property(scn, result)


def test_partial_plan_verifies_as_partial(blocked: Scenario, plan: Plan) -> None:
    from planning.check import check_plan

    assert not plan.success, "a partial plan claims success"
    assert plan.partial is not None, "no partial climb on blocked-shaft"
    problems = check_plan(plan)
    assert problems == [], problems
    last = plan.phases[-1]
    assert last.kind == "body" and tuple(last.stance) == plan.partial.reached_stance
    assert abs(plan.partial.goal_distance_m
               - centroid_distance(blocked, plan.partial.reached_stance)) <= DIST_TOL
    assert plan.partial.goal_distance_m < plan.partial.start_distance_m, (
        "blocked-shaft's partial climb gets no nearer the goal than its start")
    assert plan.regrasps >= 1 and plan.p_path is not None and 0 < plan.p_path <= 1
    # every configuration is on a trajectory (the pipeline's motions), not the footstep stage
    assert all(p.motion is not None for p in plan.phases)
    # the footstep search's nearest expanded stance (its motions all flown: not cut short),
    # as the failure's reason names it
    assert SEARCHES and not SEARCHES[0].success  # the first search, then the climb's
    last = SEARCHES[-1].partial
    assert last is not None and tuple(last.stances[-1]) == plan.partial.reached_stance, (
        "the search picture would draw another route than the climb's")
    nearest = min(centroid_distance(blocked, tuple(e.stance)) for e in SEARCHES[0].explored)
    assert abs(plan.partial.goal_distance_m - nearest) <= DIST_TOL, (
        f"the plan ends {plan.partial.goal_distance_m} m from the goal, the nearest stance the "
        f"search expanded is {nearest} m")
    assert f"nearest stance reached is {nearest:.2f} m" in plan.reason


def _rules(plan: Plan) -> set[str]:
    from planning.check import verify_plan

    return {p.rule for p in verify_plan(plan)}


def test_a_partial_plan_never_passes_as_a_success(plan: Plan) -> None:
    assert plan.partial is not None
    claimed = plan.replace(success=True, reason="")
    assert "goal" in _rules(claimed), "a partial plan that claims success passed"
    # the same climb, no longer marked partial, claiming success: it ends short of the goal
    assert "goal" in _rules(claimed.replace(partial=None))


def test_a_partial_plan_must_say_where_it_ends(plan: Plan) -> None:
    part = plan.partial
    assert part is not None
    nearer = dataclasses.replace(part, goal_distance_m=part.goal_distance_m * 0.5)
    assert "goal" in _rules(plan.replace(partial=nearer)), "a false distance passed"
    other = dataclasses.replace(part, reached_stance=tuple(plan.phases[0].stance))
    assert "goal" in _rules(plan.replace(partial=other)), "a false final stance passed"
    # a partial climb that stops on a reach phase (a boom in the air)
    cut = plan.replace(phases=plan.phases[:-1], regrasps=plan.regrasps)
    assert "phase-order" in _rules(cut)


def test_partial_round_trips_through_the_file(plan: Plan, tmp_path: Path) -> None:
    from planning.plan import write_plan
    from planning.plan_file import read_plan

    path = write_plan(plan, tmp_path / "partial.json")
    data = json.loads(path.read_text())
    assert data["success"] is False and set(data["partial"]) == {
        "reached_stance", "goal_distance_m", "start_distance_m"}
    assert read_plan(path).partial == plan.partial
    assert isinstance(read_plan(path).partial, Partial)


def test_cli_partial_exit_status_and_check(tmp_path: Path) -> None:
    from rbp import cli

    out = tmp_path / "p.json"
    assert cli.main(["plan", "blocked-shaft", "--partial", "--no-scp", "--no-pictures", "-q",
                     "-o", str(out)]) == 1, "a partial plan is not a success: exit status 1"
    data = json.loads(out.read_text())
    assert data["success"] is False and data["partial"]["goal_distance_m"] >= 0
    assert cli.main(["check", "-q", str(out)]) == 0, "the partial plan does not verify"
    again = tmp_path / "again.json"  # --from-plan makes a partial plan again partial
    assert cli.main(["plan", "--from-plan", str(out), "--no-pictures", "-q",
                     "-o", str(again)]) == 1
    assert json.loads(again.read_text())["partial"] == data["partial"]


def test_partial_refused_where_it_cannot_be_flown(blocked: Scenario) -> None:
    from rbp.api import plan as make

    with pytest.raises(RbpInputError, match="whole pipeline"):
        make(blocked, partial=True, footsteps_only=True)
    with pytest.raises(RbpInputError, match="whole pipeline"):
        make(blocked, partial=True, planner="naive")


@pytest.mark.parametrize("flag", ["--footsteps-only", "--planner=naive"])
def test_cli_partial_refused_in_one_line_before_planning(tmp_path: Path, flag: str,
                                                         capsys) -> None:
    from rbp import cli

    out = tmp_path / "p.json"
    assert cli.main(["plan", "blocked-shaft", "--partial", flag, "--no-pictures", "-q",
                     "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--partial" in err[0], err
    assert not out.exists(), "a refused run wrote a plan"


def test_a_motion_failure_cuts_the_climb_to_the_last_stance_reached(blocked: Scenario,
                                                                   monkeypatch) -> None:
    """Where a phase's motion fails (here: made to fail at the second reach), the partial climb
    stops in the last stance its motions reach, on a body phase, and still verifies."""
    from planning import pipeline
    from planning.check import check_plan
    from planning.footsteps import plan_footsteps

    cfg = PipelineConfig(optimise=False, motion_retries=0)
    fp = plan_footsteps(blocked, cfg.footstep, partial=True)
    assert fp.partial is not None and len(fp.partial.steps) >= 2, "blocked-shaft's route"
    real = pipeline.phase_motions

    def failing(*args, **kwargs):
        motions, _ = real(*args, **kwargs)
        return motions[:4], "reach phase 3: made to fail"  # body, reach, body, reach

    monkeypatch.setattr(pipeline, "phase_motions", failing)
    plan = pipeline.partial_climb(blocked, fp, cfg)
    assert plan.partial is not None and not plan.success
    assert plan.partial.reached_stance == tuple(fp.partial.stances[1]), plan.partial
    assert plan.regrasps == 1 and plan.phases[-1].kind == "body"
    assert "made to fail" in plan.reason
    assert abs(plan.partial.goal_distance_m
               - centroid_distance(blocked, tuple(fp.partial.stances[1]))) <= DIST_TOL
    problems = check_plan(plan)
    assert problems == [], problems


def test_the_experiment_script_runs_and_counts(tmp_path: Path) -> None:
    """experiments/partial_climbs.py on one benchmark cave without a route (crevasse-30, a
    short search): its row and summary agree with the plan it made."""
    from experiments.partial_climbs import main, no_route_caves

    assert ("crevasse", 30) in no_route_caves(), "crevasse-30 is labelled as having no route"
    out = tmp_path / "partial.json"
    assert main(["--seeds", "30", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    (row,) = data["caves"]
    assert (row["kind"], row["seed"], row["success"]) == ("crevasse", 30, False), row
    assert row["partial"] and row["verified"] and row["start_can_move"], row
    assert row["goal_distance_m"] <= row["start_distance_m"] + DIST_TOL, row
    summary = data["summary"]
    assert (summary["caves"], summary["partial_written"], summary["partial_verified"]) == \
        (1, 1, 1), summary
