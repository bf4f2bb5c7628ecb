"""`rbp check`'s verdict on a plan: the verifier's rules (`planning.check.check_plan`, whose rule
`between` verifies the straight motion `rbp rig-run` executes and the smooth path `rbp
simulate` follows) and, for a motion plan that passes them, how far that smooth path strays
from the straight motion (`systems.trajectory`), with a problem past `DEPARTURE_LIMIT`.
`rbp check`, `rbp simulate`, `rbp rig-run` and `rbp.check` share it.
"""

from __future__ import annotations

from typing import Any


def smooth_path_check(plan: Any, source: str = "") -> tuple[list[str], float | None]:
    """What `rbp check` adds to `planning.check.check_plan` for a motion plan that passes it:
    how far `rbp simulate`'s smooth path through the steps strays from the straight motion
    rule `between` verified (`systems.trajectory.PlanTrajectory.departure`, in resolutions),
    and a problem when it strays further than DEPARTURE_LIMIT. ([], None) for a plan without
    motion (a footstep plan, a failed one)."""
    from planning.plan_model import plan_of

    model = plan_of(plan)
    if model.time_step is None or not model.phases:
        return [], None
    from systems.trajectory import PlanError, PlanTrajectory, plan_scenario

    try:
        traj = PlanTrajectory(model, plan_scenario(model, source))
    except PlanError as e:
        return [f"phases: between: rbp simulate cannot run the plan: {e}"], None
    problem = traj.departure_problem()
    return ([problem] if problem else []), traj.departure


def plan_problems(plan: Any, source: str = "", progress: Any = None
                  ) -> tuple[list[str], float | None]:
    """`rbp check`'s verdict: `check_plan`'s problems, then, when there are none, the smooth
    path's departure (`smooth_path_check`); and that departure (None: not measured)."""
    from planning.check import check_plan

    problems = check_plan(plan, source, progress=progress)
    if problems:
        return problems, None
    return smooth_path_check(plan, source)
