"""rbp: robust climbing plans for ReachBot. The Python API (see `rbp.api`):

    import rbp

    cave = rbp.load_scenario("demo-shaft")   # or rbp.generate_scenario("shaft", seed=3)
    # or rbp.import_scenario("section.geojson"): a cave from a drawing or a mesh of rock
    plan = rbp.plan(cave)                    # rbp.PipelineConfig(...) to configure it
    assert rbp.check(plan) == []
    rbp.write_plan(plan, "climb.json")
    print(rbp.simulate(plan, trials=1000).monte_carlo.rate)
    rbp.draw(plan, "climb.png")
    view = rbp.meshcat(plan)                 # the climb replayed in Meshcat: open view.url

Every name is loaded on first use, so `import rbp` imports neither Drake nor numba (the
command line, `rbp`, starts fast).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from planning.footsteps import FootstepConfig
    from planning.pipeline import PipelineConfig
    from planning.plan_model import Plan
    from rb_drake.errors import RbpError, RbpInputError
    from rb_drake.generate import CaveConfig
    from rb_drake.scenario import Scenario
    from rbp.api import (
        MeshcatView,
        SimulationResult,
        bundled_caves,
        check,
        draw,
        generate_scenario,
        import_scenario,
        load_scenario,
        meshcat,
        plan,
        read_plan,
        simulate,
        write_plan,
    )

# name -> the module that defines it, imported when the name is first used
_LAZY = {
    **{name: "rbp.api" for name in (
        "MeshcatView", "SimulationResult", "bundled_caves", "check", "draw",
        "generate_scenario", "import_scenario", "load_scenario", "meshcat", "plan",
        "read_plan", "simulate", "write_plan")},
    "Scenario": "rb_drake.scenario",
    "CaveConfig": "rb_drake.generate",
    "Plan": "planning.plan_model",
    "PipelineConfig": "planning.pipeline",
    "FootstepConfig": "planning.footsteps",
    "RbpError": "rb_drake.errors",
    "RbpInputError": "rb_drake.errors",
}

__all__ = [  # the same names as _LAZY (a literal, for linters and type checkers)
    "CaveConfig", "FootstepConfig", "MeshcatView", "PipelineConfig", "Plan", "RbpError",
    "RbpInputError", "Scenario", "SimulationResult", "bundled_caves", "check", "draw",
    "generate_scenario", "import_scenario", "load_scenario", "meshcat", "plan", "read_plan",
    "simulate", "write_plan"]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'rbp' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # found here from now on
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
