"""Checks of a finished trial record's fields, for `experiments.sweep.RESULT_CHECKS`: each trial
function's module states the fields its summaries read as rules (a test and what it must be),
and a record edited or damaged since it was written ("x", 1e308, a list, missing) is refused
on resuming, naming the field, before a summary trips over it (a traceback after the sweep)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

from experiments.arguments import json_type

Rule = tuple[Callable[[Any], bool], str]  # (test of a value, what the value must be)

MAX_SECONDS = 1e9  # a stage's or a trial's seconds (31 years)
MAX_COUNT = 10**12  # expansions, runs, successes, failures
RATE_TOLERANCE = 1e-9  # a simulation's rate against successes / runs (it is written exactly so)


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _whole(value: Any, hi: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= hi


def maybe(rule: Rule) -> Rule:
    """`rule`, or null."""
    ok, what = rule
    return (lambda v: v is None or ok(v)), f"null or {what}"


BOOLEAN: Rule = (lambda v: isinstance(v, bool), "true or false")
STRING: Rule = (lambda v: isinstance(v, str), "a string")
NUMBER: Rule = (_number, "a finite number")
PROBABILITY: Rule = (lambda v: _number(v) and 0.0 <= v <= 1.0, "a number from 0 to 1")
SECONDS: Rule = (lambda v: _number(v) and 0.0 <= v <= MAX_SECONDS,
                 "a number of seconds from 0 to 1e9")
MEGABYTES: Rule = (lambda v: _number(v) and 0.0 <= v <= 1e9, "a number from 0 to 1e9")
# an error's size (metres, radians): the tables scale it (mm, degrees), so finite is not enough
MAGNITUDE: Rule = MEGABYTES
COUNT: Rule = (lambda v: _whole(v, MAX_COUNT), "a whole number from 0 to 1e12")
INTERVAL: Rule = (lambda v: isinstance(v, list) and len(v) == 2
                  and all(PROBABILITY[0](x) for x in v) and v[0] <= v[1],
                  "[low, high], numbers from 0 to 1 with low <= high")


def shown(value: Any) -> str:
    """A short, escaped rendering of a refused value (repr escapes control characters and lone
    surrogates: a record's text cannot break the error line)."""
    return repr(str(value)[:40]) if not isinstance(value, dict | list) else json_type(value)


def fields_problem(obj: Any, where: str, rules: Mapping[str, Rule],
                   optional: tuple[str, ...] = ()) -> str | None:
    """"WHERE.KEY: REASON" for the first field of `obj` (at dotted `where`) that breaks its rule
    or is missing (unless in `optional`), "WHERE: ..." when `obj` is not an object; None if
    every field holds."""
    if not isinstance(obj, dict):
        return f"{where}: expected an object, got {json_type(obj)}"
    for key, (ok, what) in rules.items():
        if key not in obj:
            if key in optional:
                continue
            return f"{where}.{key}: missing"
        if not ok(obj[key]):
            return f"{where}.{key}: must be {what}, got {shown(obj[key])}"
    return None


def stage_seconds_problem(obj: Any, where: str, required: tuple[str, ...] = (),
                          nested: Mapping[str, Callable[[Any, str], str | None]] | None = None
                          ) -> str | None:
    """A timing object's problem: every value a number of seconds (`required` keys present),
    but the keys of `nested`, checked by their own function (value, where)."""
    nested = nested or {}
    if not isinstance(obj, dict):
        return f"{where}: expected an object, got {json_type(obj)}"
    for key in required:
        if key not in obj:
            return f"{where}.{key}: missing"
    for key, value in obj.items():
        if key in nested:
            problem = nested[key](value, f"{where}.{key}")
        else:
            ok, what = SECONDS
            problem = None if ok(value) else f"{where}.{key}: must be {what}, got {shown(value)}"
        if problem is not None:
            return problem
    return None


def simulated_problem(simulated: Any, where: str, rules: Mapping[str, Rule]) -> str | None:
    """A simulation's problem ("FIELD: REASON"): its `rules`, at least one run, no more
    successes than runs, its rate successes / runs and inside its interval."""
    if (problem := fields_problem(simulated, where, rules)) is not None:
        return problem
    if simulated["runs"] < 1:
        return f"{where}.runs: must be 1 or more, got {simulated['runs']}"
    runs, successes = simulated["runs"], simulated["successes"]
    if successes > runs:
        return f"{where}.successes: more than its {runs} runs"
    # the figures draw the rate's error bars to its interval's ends (and calibration's
    # simultaneous interval is the counts'): a rate outside either makes a negative bar
    if "rate" in rules and abs(simulated["rate"] - successes / runs) > RATE_TOLERANCE:
        return (f"{where}.rate: must be successes / runs = {successes / runs:.6g}, "
                f"got {simulated['rate']}")
    if "ci95" in rules and "rate" in rules and not (
            simulated["ci95"][0] <= simulated["rate"] <= simulated["ci95"][1]):
        return f"{where}.ci95: must hold the rate {simulated['rate']}, got {simulated['ci95']}"
    return None


def simulation_problem(record: dict[str, Any], plan_rules: Mapping[str, Rule],
                       simulated_rules: Mapping[str, Rule]) -> str | None:
    """A simulation trial's record ({"plan", "simulated"}, timing): the plan's fields, and a
    successful plan's simulation (null for a failed plan)."""
    result = record["result"]
    if (problem := fields_problem(result.get("plan"), "result.plan", plan_rules)) is not None:
        return problem if "plan" in result else "result.plan: missing"
    plan = result["plan"]
    if plan["success"] and plan["p_path"] is None:
        return "result.plan.p_path: a successful plan's must be a number from 0 to 1"
    if "simulated" not in result:
        return "result.simulated: missing"
    if result["simulated"] is not None and (problem := simulated_problem(
            result["simulated"], "result.simulated", simulated_rules)) is not None:
        return problem
    if result["simulated"] is not None and plan["p_path"] is None:
        return "result.plan.p_path: a simulated plan's must be a number from 0 to 1"
    return stage_seconds_problem(record["timing"], "timing")
