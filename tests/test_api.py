"""The Python API (`import rbp`, rbp/api.py) end to end: a bundled cave planned footsteps-only
and fully, checked, written and read back, simulated and drawn; a generated cave repeated by
its seed; and `import rbp` staying free of Drake and numba."""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

import pytest

import rbp
import rbp.api

ROOT = Path(__file__).resolve().parents[1]


def test_import_rbp_loads_neither_drake_nor_numba() -> None:
    code = ("import rbp, sys; rbp.__all__; "
            "print('pydrake' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT).stdout.split()
    assert out == ["False", "False"]


def test_the_surface_is_typed_and_documented() -> None:
    assert sorted(rbp.__all__) == sorted(rbp._LAZY)
    for name in rbp.__all__:
        value = getattr(rbp, name)
        assert inspect.getdoc(value), name
    for name in rbp.api.__all__:
        value = getattr(rbp.api, name)
        if inspect.isfunction(value):
            sig = inspect.signature(value)
            assert sig.return_annotation is not inspect.Signature.empty, name
            assert all(p.annotation is not inspect.Parameter.empty
                       for p in sig.parameters.values()), name
    with pytest.raises(AttributeError):
        rbp.no_such_name  # noqa: B018


@pytest.fixture(scope="module")
def demo() -> rbp.Scenario:
    return rbp.load_scenario("demo-shaft")


@pytest.fixture(scope="module")
def full_plan(demo: rbp.Scenario) -> rbp.Plan:
    return rbp.plan(demo)


def test_load_a_bundled_cave(demo: rbp.Scenario) -> None:
    assert "demo-shaft" in rbp.bundled_caves()
    assert demo.name and len(demo.anchors) >= 4
    same = rbp.load_scenario(rbp.bundled_caves()["demo-shaft"])
    assert same.to_dict() == demo.to_dict()
    with pytest.raises(rbp.RbpInputError):
        rbp.load_scenario("no-such-cave")


def test_plan_footsteps_only(demo: rbp.Scenario) -> None:
    plan = rbp.plan(demo, footsteps_only=True)
    assert isinstance(plan, rbp.Plan)
    assert plan.success, plan.reason
    assert plan.regrasps > 0 and plan.time_step is None
    assert rbp.check(plan) == []


def test_plan_check_write_read_simulate_draw(full_plan: rbp.Plan, demo: rbp.Scenario,
                                            tmp_path: Path) -> None:
    assert full_plan.success, full_plan.reason
    assert full_plan.time_step is not None  # a full plan: trajectories
    assert rbp.check(full_plan) == []
    assert rbp.check(full_plan, demo) == []
    other = rbp.load_scenario("shaft-1")
    assert any(p.startswith("scenario:") for p in rbp.check(full_plan, other))

    path = rbp.write_plan(full_plan, tmp_path / "climb.json")
    assert rbp.read_plan(path) == full_plan

    picture = rbp.draw(full_plan, tmp_path / "climb.png")
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    cave = rbp.draw(demo, tmp_path / "cave.png")
    assert cave.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    result = rbp.simulate(full_plan, trials=50, seed=1)
    assert result.success
    assert result.tracking["max_position_error"] < 0.05
    assert 0 < result.p_sim <= 1 and result.p_path == full_plan.p_path
    mc = result.monte_carlo
    assert mc is not None and mc.trials == 50 and 0 <= mc.successes <= 50
    assert result.to_json()["trials"] == 50


def test_generate_a_cave_by_seed() -> None:
    a = rbp.generate_scenario("shaft", seed=3)
    b = rbp.generate_scenario("shaft", seed=3)
    c = rbp.generate_scenario("shaft", seed=4)
    assert a.to_dict() == b.to_dict()
    assert a.to_dict() != c.to_dict()
    assert a.name == "shaft-3"
    with pytest.raises(rbp.RbpInputError):
        rbp.generate_scenario("tunnel", seed=3)
    with pytest.raises(rbp.RbpInputError):
        rbp.generate_scenario("shaft", seed=3, length=(5.0, 4.0))


def test_a_failed_plan_is_not_simulated(demo: rbp.Scenario) -> None:
    cfg = rbp.PipelineConfig(footstep=rbp.FootstepConfig(max_expansions=1,
                                                         expansions_per_metre=0.0))
    plan = rbp.plan(demo, cfg, footsteps_only=True)
    assert not plan.success
    with pytest.raises(rbp.RbpInputError):
        rbp.simulate(plan)


def test_simulate_with_replanning(full_plan: rbp.Plan) -> None:
    """`replan="retry"` (as `rbp simulate --replan retry`) continues failed trials; a few
    trials keep it short (each failed one is simulated again)."""
    with pytest.raises(rbp.RbpInputError):
        rbp.simulate(full_plan, replan="retry")  # no trials to continue
    mc = rbp.simulate(full_plan, trials=12, seed=1, replan="retry").monte_carlo
    assert mc is not None and mc.replanning is not None
    assert mc.replanning.strategy == "retry"
    assert mc.replanning.successes >= mc.successes
