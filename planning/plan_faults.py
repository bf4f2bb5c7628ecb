"""A catalogue of single faults to inject into a valid plan, for mutation testing of the verifier.

Each fault class (`FAULTS`, documented in docs/formats.md) takes a valid plan and a random
generator and returns a `Fault`: the damaged copy, the verifier rules that must reject it
(`rules`: at least one of them must be reported) and where (`phase`, None when the fault is
not local), or None when the class does not apply to this plan. Faults are made large enough to
be real faults, well above the verifier's tolerances: a moved pose jumps at least 3x the plan's
step limit, a shifted time moves at least 0.01 s (tolerance 1e-6 s) or, without a time step,
past its neighbour; a recorded value changes by at least 1e-4 (relative tolerance 1e-9); a
moved goal ends at least 0.1 m beyond the goal disc; a truncated climb is only kept if it
ends at least 0.1 m outside the goal. `bad-number` writes NaN or Infinity into one number of
the file, which must be refused when the file is read (rule `number`).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from planning import between_faults
from planning.plan import score_plan
from planning.plan_model import Plan
from planning.verify_climb import step_limits
from rb_drake.errors import field_path

# The faults damage plan files (NaN in a number, a robot under `scenario`, steps out of
# order), much of which the typed model (planning.plan_model) cannot hold: they work on the
# plan-file object, the dict a plan file parses to.
PlanFile = dict[str, Any]
Rng = np.random.Generator


def rescore(plan: PlanFile) -> None:
    """Set the summary of a (schema-valid) damaged plan file from its configurations."""
    scored = score_plan(Plan.from_dict(plan), plan["robot"]["attach_failure"])
    plan.update(p_path=scored.p_path, p_grasps=scored.p_grasps, p_min=scored.p_min,
                regrasps=scored.regrasps)


class Fault(NamedTuple):
    kind: str
    plan: PlanFile
    rules: frozenset[str]  # a verifier that rejects it reports at least one of these
    phase: int | None      # the phase a local fault is in (its problem names it or a neighbour)
    what: str              # in words, for messages
    bad_number: bool = False  # plan holds NaN or inf: it must be refused when read
    step: int | None = None   # the step a fault is at, where its rule must name it exactly


def _phase(plan: PlanFile, rng: Rng, min_steps: int = 1) -> int | None:
    ks = [k for k, p in enumerate(plan["phases"]) if len(p["steps"]) >= min_steps]
    return int(rng.choice(ks)) if ks else None


def step_removed(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng, 2)
    if k is None:
        return None
    out = copy.deepcopy(plan)
    n = int(rng.integers(len(out["phases"][k]["steps"])))
    del out["phases"][k]["steps"][n]
    return Fault("step-removed", out, frozenset({"time-order", "phase-join", "start", "goal",
                                                  "reach-ends", "recorded-value"}),
                 k, f"phases[{k}] step {n} deleted")


def step_duplicated(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    steps = out["phases"][k]["steps"]
    n = int(rng.integers(len(steps)))
    steps.insert(n, copy.deepcopy(steps[n]))
    return Fault("step-duplicated", out, frozenset({"time-order"}), k,
                 f"phases[{k}] step {n} duplicated")


def phase_duplicated(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    out["phases"].insert(k, copy.deepcopy(out["phases"][k]))
    return Fault("phase-duplicated", out, frozenset({"phase-order"}), None,
                 f"phases[{k}] duplicated")


def steps_reversed(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng, 2)
    if k is None:
        return None
    out = copy.deepcopy(plan)
    out["phases"][k]["steps"].reverse()
    return Fault("steps-reversed", out, frozenset({"time-order"}), k,
                 f"phases[{k}] steps reversed")


def step_replaced(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng, 2)
    if k is None:
        return None
    out = copy.deepcopy(plan)
    steps = out["phases"][k]["steps"]
    n = int(rng.integers(len(steps) - 1))
    m = int(rng.integers(n + 1, len(steps)))
    steps[n] = copy.deepcopy(steps[m])
    return Fault("step-replaced", out, frozenset({"time-order"}), k,
                 f"phases[{k}] step {n} replaced by step {m}")


def step_moved(plan: PlanFile, rng: Rng) -> Fault | None:
    """A pose moved (or turned), its tensions and values left: a jump, or a wrong statics."""
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    steps = out["phases"][k]["steps"]
    n = int(rng.integers(len(steps)))
    lim = step_limits(plan)
    pose = steps[n]["pose"]
    if rng.random() < 0.5:
        d = (3.0 + rng.random()) * lim["step"]
        a = rng.uniform(0, 2 * math.pi)
        pose[0] += d * math.cos(a)
        pose[1] += d * math.sin(a)
        what = f"moved {d:.3f} m"
    else:
        d = (3.0 + rng.random()) * lim["turn_step"] * rng.choice([-1.0, 1.0])
        pose[2] += d
        what = f"turned {d:.3f} rad"
    return Fault("step-moved", out, frozenset({"continuity", "statics", "phase-join", "start",
                                                "kinematics", "collision"}),
                 k, f"phases[{k}] step {n} {what}")


def time_changed(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    steps = out["phases"][k]["steps"]
    n = int(rng.integers(len(steps)))
    t = steps[n]["t"]
    if "time_step" in plan and "motion" in plan["phases"][k]:
        new = t + rng.uniform(0.01, 2.0) * rng.choice([-1.0, 1.0])
    elif n > 0:  # end poses only: any increasing times are valid; go back past the one before
        new = steps[n - 1]["t"] - rng.uniform(0.0, 2.0)
    else:
        new = t + rng.uniform(0.01, 2.0)  # a phase's first time joins the phase before
    steps[n]["t"] = max(0.0, new)  # the schema refuses negative times
    if abs(steps[n]["t"] - t) < 0.01:
        return None
    return Fault("time-changed", out, frozenset({"time-order", "phase-join", "start"}), k,
                 f"phases[{k}] step {n} t {t} -> {steps[n]['t']}")


def start_moved(plan: PlanFile, rng: Rng) -> Fault | None:
    out = copy.deepcopy(plan)
    start = out["scenario"]["start"]
    if rng.random() < 0.7:
        d = rng.uniform(0.05, 2.0)
        a = rng.uniform(0, 2 * math.pi)
        start["pose"][0] += d * math.cos(a)
        start["pose"][1] += d * math.sin(a)
        what = f"start pose moved {d:.3f} m"
    else:
        ids = [a["id"] for a in out["scenario"]["anchors"] if a["id"] not in start["stance"]]
        if not ids:
            return None
        i = int(rng.integers(4))
        start["stance"][i] = str(rng.choice(ids))
        what = f"start stance boom {i} -> {start['stance'][i]}"
    return Fault("start-moved", out, frozenset({"start"}), None, what)


def goal_moved(plan: PlanFile, rng: Rng) -> Fault | None:
    out = copy.deepcopy(plan)
    end = np.array(plan["phases"][-1]["steps"][-1]["pose"][:2]) if plan["phases"] else None
    if end is None or not plan["success"]:
        return None
    from rb_drake.collision import Rock

    goal = out["scenario"]["goal"]
    rock = Rock([np.asarray(w, dtype=float) for w in plan["scenario"]["walls"]])
    for _ in range(20):  # a goal in free space: one in rock is refused as a bad scenario
        d = goal["tolerance"] + rng.uniform(0.1, 3.0)
        a = rng.uniform(0, 2 * math.pi)
        position = [float(end[0] + d * math.cos(a)), float(end[1] + d * math.sin(a))]
        if not rock.contains(np.array([position]))[0]:
            goal["position"] = position
            return Fault("goal-moved", out, frozenset({"goal"}), None,
                         f"goal moved {d:.2f} m from the last pose")
    return None


ROBOT_EDITS = ("body_mass", "gripper_mass", "boom_linear_density", "shoulder_torque_max",
               "p_min", "attach_failure", "boom_tension", "boom_length")


def robot_edited(plan: PlanFile, rng: Rng) -> Fault | None:
    """One parameter of the robot under `scenario` (or, half the time, at the top level)
    changed by 10 % to 100 %, so the two robots differ."""
    out = copy.deepcopy(plan)
    block = out["scenario"].setdefault("robot", copy.deepcopy(plan["robot"]))
    target = block if rng.random() < 0.5 else out["robot"]
    name = str(rng.choice(ROBOT_EDITS))
    base = target.get(name, plan["robot"][name])
    factor = rng.uniform(1.1, 2.0) if name not in ("p_min", "attach_failure") else rng.uniform(
        0.5, 0.9)
    value = [v * factor for v in base] if isinstance(base, list) else base * factor
    if value == base:  # a zero scaled stays zero
        value = [v + 1.0 for v in base] if isinstance(base, list) else base + 0.1
    target[name] = value
    side = "scenario.robot" if target is block else "robot"
    return Fault("robot-edited", out, frozenset({"robot"}), None, f"{side}.{name} {base} -> "
                 f"{value}")


def value_changed(plan: PlanFile, rng: Rng) -> Fault | None:
    """One recorded per-step value (a grasp's P, P, shoulder torque, effort, a tension)."""
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    phase = out["phases"][k]
    n = int(rng.integers(len(phase["steps"])))
    step = phase["steps"][n]
    choices = ["p_grasp", "p_success", "tension"]
    if "shoulder_torque" in step:
        choices.append("shoulder_torque")
    if "motion" in phase:
        choices.append("effort")
    name = str(rng.choice(choices))
    rules = frozenset({"recorded-value"})
    key: int | str
    if name in ("p_grasp", "tension"):
        i = int(rng.choice([i for i, v in enumerate(step[name]) if v is not None]))
        holder, key = step[name], i
        if name == "tension":
            rules = frozenset({"statics"})
    elif name == "effort":
        holder, key = phase["motion"]["effort"], n
    else:
        holder, key = step, name
    old = holder[key]
    delta = max(1e-4, 1e-3 * abs(old)) * rng.uniform(1.0, 100.0)
    new = old - delta if name.startswith("p_") and old + delta > 1.0 else old + delta
    if name.startswith("p_"):
        new = min(max(new, 0.0), 1.0)
    holder[key] = float(new)
    if abs(new - old) < 1e-6:
        return None
    return Fault("value-changed", out, rules, k, f"phases[{k}] step {n} {name} {old} -> {new}")


def summary_edited(plan: PlanFile, rng: Rng) -> Fault | None:
    if not plan["success"]:
        return None
    out = copy.deepcopy(plan)
    name = str(rng.choice(["p_path", "p_min", "p_grasps", "regrasps"]))
    if name == "regrasps":
        out[name] += int(rng.choice([-1, 1]))
        if out[name] < 0:
            out[name] = 1
    else:
        old = out[name]
        out[name] = old - 1e-3 if old > 0.5 else old + 1e-3
    return Fault("summary-edited", out, frozenset({"summary"}), None,
                 f"{name} {plan[name]} -> {out[name]}")


def phases_truncated(plan: PlanFile, rng: Rng) -> Fault | None:
    """The first phases kept, the summary recomputed: a climb that stops short of the goal."""
    if not plan["success"] or len(plan["phases"]) < 2:
        return None
    goal = np.array(plan["scenario"]["goal"]["position"])
    tol = plan["scenario"]["goal"]["tolerance"]
    cuts = [m for m in range(1, len(plan["phases"]))
            if np.linalg.norm(np.array(plan["phases"][m - 1]["steps"][-1]["pose"][:2]) - goal)
            > tol + 0.1]
    if not cuts:
        return None
    m = int(rng.choice(cuts))
    out = copy.deepcopy(plan)
    out["phases"] = out["phases"][:m]
    rescore(out)
    return Fault("phases-truncated", out, frozenset({"goal", "phase-order"}), None,
                 f"only the first {m} of {len(plan['phases'])} phases kept")


def anchor_swapped(plan: PlanFile, rng: Rng) -> Fault | None:
    k = _phase(plan, rng)
    out = copy.deepcopy(plan)
    stance = out["phases"][k]["stance"]
    booms = [i for i, a in enumerate(stance) if a is not None]
    ids = [a["id"] for a in out["scenario"]["anchors"] if a["id"] not in stance]
    if not ids:
        return None
    i = int(rng.choice(booms))
    stance[i] = str(rng.choice(ids))
    return Fault("anchor-swapped", out, frozenset({"stance", "start"}), k,
                 f"phases[{k}] boom {i} on {stance[i]}")


def _number_paths(value: Any, path: tuple = ()) -> list[tuple]:
    if isinstance(value, bool):
        return []
    if isinstance(value, int | float):
        return [path]
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list) else ())
    return [p for key, item in items for p in _number_paths(item, (*path, key))]


def bad_number(plan: PlanFile, rng: Rng) -> Fault | None:
    """NaN, Infinity or -Infinity in one number of the file (write it with allow_nan=True)."""
    out = copy.deepcopy(plan)
    paths = _number_paths(out)
    path = paths[int(rng.integers(len(paths)))]
    holder = out
    for key in path[:-1]:
        holder = holder[key]
    holder[path[-1]] = float(rng.choice([math.nan, math.inf, -math.inf]))
    field = field_path(path)
    return Fault("bad-number", out, frozenset({"number"}), None, f"{field} = "
                 f"{holder[path[-1]]}", bad_number=True)


def _ramps(plan: PlanFile) -> list[tuple[int, list[int]]]:
    """(phase, the indices of its ramp steps) of every release and attach ramp."""
    out = []
    for k, phase in enumerate(plan["phases"]):
        marked = [n for n, s in enumerate(phase["steps"]) if "ramp" in s]
        lead = [n for n in marked if n < len(phase["steps"]) // 2]
        trail = [n for n in marked if n >= len(phase["steps"]) // 2]
        out += [(k, run) for run in (lead, trail) if run]
    return out


def ramp_removed(plan: PlanFile, rng: Rng) -> Fault | None:
    """A release or attach ramp taken out, everything after it moved earlier by its length
    and the phase's motion record kept one entry per step: a gripper that opens (or closes)
    on a loaded boom, with time, joins and records all in order."""
    ramps = _ramps(plan)
    if not ramps:
        return None
    k, run = ramps[int(rng.integers(len(ramps)))]
    out = copy.deepcopy(plan)
    phase = out["phases"][k]
    times = [s["t"] for s in phase["steps"]]
    lead = run[0] == 0
    span = times[run[-1] + 1] - times[0] if lead else times[-1] - times[run[0] - 1]
    phase["steps"] = [s for n, s in enumerate(phase["steps"]) if n not in run]
    motion = phase.get("motion")
    if motion is not None:
        for name in ("seed_p_success", "seed_tension", "seed_effort", "effort"):
            motion[name] = [v for n, v in enumerate(motion[name]) if n not in run]
    later = phase["steps"] if lead else []
    for other in out["phases"][k + 1:]:
        later = later + other["steps"]
    for step in later:
        step["t"] = round(step["t"] - span, 6)
    rescore(out)
    return Fault("ramp-removed", out, frozenset({"release", "attach"}), k,
                 f"phases[{k}]: the {'attach' if lead else 'release'} ramp (steps {run}) "
                 "removed")


def release_loaded(plan: PlanFile, rng: Rng) -> Fault | None:
    """The ramped boom still pulls (1 to 5 N more) when its gripper opens or closes."""
    ramps = _ramps(plan)
    if not ramps:
        return None
    k, run = ramps[int(rng.integers(len(ramps)))]
    out = copy.deepcopy(plan)
    n = run[0] if run[0] == 0 else run[-1]  # the contact: the attach's first, release's last
    step = out["phases"][k]["steps"][n]
    j = step["ramp"]["boom"]
    step["tension"][j] += float(rng.uniform(1.0, 5.0))
    return Fault("release-loaded", out, frozenset({"release", "attach", "statics",
                                                   "recorded-value"}), k,
                 f"phases[{k}] step {n}: boom {j} pulls {step['tension'][j]:.2f} N at its "
                 "gripper's contact")


def between_cut(plan: PlanFile, rng: Rng) -> Fault | None:
    """One step replaced by another valid configuration so that the motion to or from it
    leaves feasibility while every step holds (`planning.between_faults`)."""
    return _between_fault("between-cut", between_faults.between_cut(plan, rng))


def between_smooth(plan: PlanFile, rng: Rng) -> Fault | None:
    """Two steps replaced by an excursion to the edge of feasibility and part of the way back:
    every step and the straight motion between them hold, the smooth path through them does
    not (`planning.between_faults.between_excursion`)."""
    return _between_fault("between-smooth", between_faults.between_excursion(plan, rng))


def _between_fault(kind: str, made: tuple[PlanFile, int, int, str] | None) -> Fault | None:
    """A `planning.between_faults` damage (plan, phase, step, words) as a Fault of rule
    between, its summary rescored; None when none was made."""
    if made is None:
        return None
    out, k, n, what = made
    rescore(out)
    return Fault(kind, out, frozenset({"between"}), k, what, step=n)


FAULTS: dict[str, Callable[[PlanFile, Rng], Fault | None]] = {
    "step-removed": step_removed,
    "step-duplicated": step_duplicated,
    "steps-reversed": steps_reversed,
    "step-replaced": step_replaced,
    "step-moved": step_moved,
    "time-changed": time_changed,
    "phase-duplicated": phase_duplicated,
    "phases-truncated": phases_truncated,
    "anchor-swapped": anchor_swapped,
    "start-moved": start_moved,
    "goal-moved": goal_moved,
    "robot-edited": robot_edited,
    "value-changed": value_changed,
    "summary-edited": summary_edited,
    "bad-number": bad_number,
    "ramp-removed": ramp_removed,
    "release-loaded": release_loaded,
    "between-cut": between_cut,
    "between-smooth": between_smooth,
}


def random_fault(plan: PlanFile, rng: Rng, kind: str | None = None) -> Fault:
    """One fault of class `kind` (or of a random applicable class) in `plan`."""
    kinds = [kind] if kind is not None else list(FAULTS)
    for _ in range(100):
        fault = FAULTS[str(rng.choice(kinds))](plan, rng)
        if fault is not None:
            return fault
    raise ValueError(f"no fault of {kinds} applies to this plan")


class Verdict(NamedTuple):
    rules: frozenset[str]  # the rules the verifier (or the reader) reported
    right_rule: bool       # one of the fault's rules among them
    located: bool          # for a local fault: a problem of a right rule names its phase (+-1;
    #                        exactly, and its step, when the fault gives one)

    @property
    def rejected(self) -> bool:
        return bool(self.rules)


def judge(fault: Fault) -> Verdict:
    """What the verifier makes of a fault: the plan as `rbp check` reads and verifies it
    (the file text, so that bad numbers meet the reader)."""
    import json

    import jsonschema

    from planning.check import verify_plan
    from planning.plan_file import PlanFileError, parse_plan_text
    from planning.plan_schema import validate
    from rb_drake.scenario import ScenarioError

    try:
        plan = parse_plan_text(json.dumps(fault.plan))  # NaN and Infinity as Python writes them
        validate(plan)
    except PlanFileError:
        return Verdict(frozenset({"number"}), "number" in fault.rules, True)
    except jsonschema.ValidationError:
        return Verdict(frozenset({"schema"}), "schema" in fault.rules, True)
    try:
        problems = verify_plan(plan)
    except ScenarioError:
        return Verdict(frozenset({"scenario"}), "scenario" in fault.rules, True)
    rules = frozenset(p.rule for p in problems)
    located = fault.phase is None or any(
        p.rule in fault.rules and p.phase is not None and abs(p.phase - fault.phase) <= 1
        and (fault.step is None or (p.phase == fault.phase and p.step == fault.step))
        for p in problems)
    return Verdict(rules, bool(rules & fault.rules), located)
