"""`rbp check`'s verdict on a plan: the verifier's rules (`planning.check.check_plan`, whose rule
`between` verifies the straight motion `rbp rig-run` executes and the smooth path `rbp
simulate` follows) and, for a motion plan that passes them, how far that smooth path strays
from the straight motion (`systems.trajectory`), with a problem past `DEPARTURE_LIMIT`.
`rbp check`, `rbp simulate`, `rbp rig-run` and `rbp.check` share it; `executed_motion_problems`
is what `rbp rig-run` adds for a footstep plan, whose motion `rbp check` does not verify.
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


def executed_motion_problems(plan: Any, source: str = "") -> list[str]:
    """Rule `between` on the straight motion between the steps of a footstep plan (no
    `time_step`), the motion `rbp rig-run` commands (`verify_between.step_motion`), which
    `rbp check` leaves unverified (it states end configurations only); [] for a motion plan,
    whose motion `check_plan` verifies, and for one without phases."""
    from planning.plan_model import plan_of, plan_scenario
    from planning.verify_between import between_problems
    from planning.verify_climb import Problem, locate

    model = plan_of(plan)
    if model.time_step is not None or not model.phases:
        return []
    problems: list[str] = []

    def fail(k: int, n: int, text: str) -> None:
        problems.append(str(Problem("between", text, k, n, locate(model, k, n))))

    between_problems(model.phases, plan_scenario(model, source), set(), fail)
    return problems
