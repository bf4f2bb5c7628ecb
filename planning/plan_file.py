"""Reading a plan file strictly, and the stamp `rbp check --stamp` leaves on a verified plan.

Python's json reads `NaN`, `Infinity` and numbers too large for a float (`1e999`, read as inf)
without a word, and JSON Schema's "number" lets them through: here each is refused when the
file is read, naming the field, so none reaches numpy. The stamp (`verified`) is the SHA-256 of
the plan's canonical JSON without the stamp, with the verifier's version: a consumer that finds
a matching stamp need not verify again, and any edit to the file makes the stamp stale. It
guards against mistakes and stale files, not against forgery: anyone can compute it.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from planning.plan_model import BODY_SPEED, MAX_STEP_GAP, TURN_SPEED, Plan
from rb_drake.errors import RbpInputError, field_path
from rb_drake.input_files import InputFileError, load_json, read_text

# bump when the rules change: older stamps then no longer count (3: rule between; 4: rule
# between on the smooth path `rbp simulate` follows; 5: rule between tests the paths of the
# boom ends and body corners between checked configurations for rock; 6: rule collision at a
# step finds rock wholly inside the body)
VERIFIER = "rbp-verify/6"


class PlanFileError(RbpInputError):
    """A plan file that cannot be used: `field` (path in the file) and `reason`."""

    def __init__(self, field: str, reason: str, file: str | None = None):
        super().__init__(reason, file=file, field=field)
        self.field = field


_SCENARIO_FORMAT = re.compile(r"^format:\s*['\"]?reachbot-scenario/", re.MULTILINE)
# A plan rbp writes opens with its format: read from there, a wrong one is refused before the
# rest is parsed (json reads 30 MB in 1.3 s; the schema took 11 s to refuse it afterwards).
# Over this, a schema error is named by the compiled validator (jsonschema walks the whole
# plan: about 0.6 s a megabyte).
QUICK_SCHEMA_ABOVE_CHARS = 1_000_000
_LEADING_FORMAT = re.compile(r'\ufeff?\s*\{\s*"format"\s*:\s*("(?:[^"\\]|\\.){0,200}")')


class _Bad:
    """Stands in for a non-finite number while the file is parsed, to locate it afterwards."""

    def __init__(self, text: str):
        self.text = text


def _float(text: str) -> float | _Bad:
    value = float(text)
    return value if math.isfinite(value) else _Bad(text)


def parse_plan_text(text: str) -> Any:
    """The JSON value of `text`; raises PlanFileError naming the first non-finite number's
    field, and json.JSONDecodeError for text that is not JSON."""
    bad_numbers: list[_Bad] = []  # the walk naming a bad number's field runs only for one

    def number(text: str) -> float | _Bad:
        value = _float(text)
        if isinstance(value, _Bad):
            bad_numbers.append(value)
        return value

    def constant(text: str) -> _Bad:
        bad_numbers.append(_Bad(text))
        return bad_numbers[-1]

    try:
        # Numbers are parsed by json's C code first (a Python call per number took a third of
        # the time); only a document holding a non-finite one is parsed again to name it.
        data = load_json(text, parse_constant=constant)
        if not bad_numbers and not _all_finite(data):
            data = load_json(text, parse_constant=constant, parse_float=number)
    except InputFileError as e:
        raise PlanFileError(e.field, e.reason) from None
    found = _find_bad(data, "") if bad_numbers else None
    if found is not None:
        field, bad = found
        raise PlanFileError(field or "(top level)", f"must be a finite number, got {bad.text}")
    return data


def _all_finite(data: Any) -> bool:
    """Whether no number of a parsed document is infinite (json reads 1e999 as inf), checked
    by json's C encoder, which refuses them."""
    try:
        json.dumps(data, allow_nan=False)
    except ValueError:
        return False
    return True


def _huge(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and abs(value) > _MAX_FLOAT


_MAX_FLOAT = 1.7976931348623157e308


def _find_bad(value: Any, path: str,
              bad: Callable[[Any], bool] = lambda v: isinstance(v, _Bad)) -> tuple[str, Any] | None:
    if bad(value):
        return path, value
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        sub = f"{path}[{key}]" if isinstance(key, int) else (f"{path}.{key}" if path else key)
        found = _find_bad(item, sub, bad)
        if found is not None:
            return found
    return None


def read_plan_file(path: str | Path) -> dict[str, Any]:
    """A plan file parsed and validated against the schema; raises PlanFileError with the field
    ("(file)" when it cannot be read or is not JSON) and the reason."""
    try:
        text = read_text(path)  # a regular file within the size limit (rb_drake.input_files)
    except InputFileError as e:
        raise PlanFileError(e.field, e.reason) from None
    leading = _LEADING_FORMAT.match(text)
    if leading is not None:
        try:
            _check_format(json.loads(leading.group(1)))
        except ValueError as e:
            if isinstance(e, PlanFileError):
                raise
    try:
        plan = parse_plan_text(text)
    except json.JSONDecodeError as e:
        # a scenario's YAML has `format: reachbot-scenario/1` at the start of a line; a plan
        # embeds its scenario as JSON, `"format": "reachbot-scenario/1"`
        if _SCENARIO_FORMAT.search(text[:4096]):
            raise PlanFileError("(file)", "this is a scenario (a cave), not a plan: plan it "
                                f"with `rbp plan {path}`") from None
        raise PlanFileError(f"line {e.lineno}, column {e.colno}",
                            f"not a JSON plan: {e.msg}") from None
    except RecursionError:
        raise PlanFileError("(file)", "not a JSON plan: nested too deeply") from None
    return validated(plan, quick=len(text) > QUICK_SCHEMA_ABOVE_CHARS)


def validated(plan: Any, quick: bool = False) -> dict[str, Any]:
    """A parsed plan checked against the schema; raises PlanFileError with the field (`quick`:
    the compiled validator's words, see plan_schema.schema_error)."""
    from planning.plan_schema import float_integer, schema_error

    if not isinstance(plan, dict):
        raise PlanFileError("(top level)", f"must be a JSON object, got {_kind(plan)}")
    if "format" in plan:  # before the schema, which walks the whole plan to refuse it
        _check_format(plan["format"])
    _check_scenario_size(plan.get("scenario"))
    error = schema_error(plan, quick)
    if error is not None:
        field = field_path(error.absolute_path) or "(top level)"
        raise PlanFileError(field, error.message)
    found = float_integer(plan)  # the schema's "integer" accepts 2.0
    if found is not None:
        path, value = found
        raise PlanFileError(field_path(path), f"expected an integer, got {value!r}")
    check_times(plan)
    return plan


# s: slack on the longest wait, for times rounded to 1 us and a duration rounded with them
GAP_TOL = 1e-3
# rad: the most a step turns the body (the planner's turns are the short way round; slack for
# rounding), and so the most a body move's turn counts towards its duration
MAX_STEP_TURN = math.pi + 1e-9


def check_times(plan: dict[str, Any]) -> None:
    """Refuse (PlanFileError on the step's `t`) a schema-valid plan whose step comes more than
    MAX_STEP_GAP after the step before it, in its phase or (a phase's first) the phase before's
    last, or whose first step is more than MAX_STEP_GAP from 0 s: the planner writes steps at
    most --dt apart from 0 s, and the simulator and the rig sample the plan over its time. A
    footstep plan's body phase may take longer, at its nominal speeds
    (planning.plan.build_plan), its turn counted up to MAX_STEP_TURN. Times that do not increase
    are the verifier's (rule time-order): they stretch nothing. A step turning the body more
    than MAX_STEP_TURN from the step before is refused (PlanFileError on its `pose[2]`)."""
    before: dict[str, Any] | None = None
    for k, phase in enumerate(plan["phases"]):
        for n, step in enumerate(phase["steps"]):
            if before is None and abs(step["t"]) > MAX_STEP_GAP + GAP_TOL:
                # the simulator and the rig start at 0 s: a plan shifted by 1e7 s simulated
                # its first 1e7 s of nothing (rbp simulate --no-verify ran for hours)
                raise PlanFileError(
                    f"phases[{k}].steps[{n}].t", f"the plan's first step is at {step['t']:.6g} "
                    f"s: a plan starts within {MAX_STEP_GAP:g} s of 0 s (the planner's at 0)")
            if before is not None:
                gap = step["t"] - before["t"]
                a, b = before["pose"], step["pose"]
                # a turn counts up to the most a step may turn: a footstep plan's body spinning
                # 1,500 turns at TURN_SPEED in one move passed `rbp check` (its motion
                # unverified) and `rbp simulate` ran it for an hour
                turn = min(abs(b[2] - a[2]), MAX_STEP_TURN)
                allowed = max(MAX_STEP_GAP, math.hypot(b[0] - a[0], b[1] - a[1]) / BODY_SPEED,
                              turn / TURN_SPEED)
                if gap > allowed + GAP_TOL:
                    raise PlanFileError(
                        f"phases[{k}].steps[{n}].t", f"{gap:.6g} s after the step before: steps "
                        f"are at most {MAX_STEP_GAP:g} s apart (longer only for a body move "
                        f"at {BODY_SPEED:g} m/s, or {TURN_SPEED:g} rad/s through at most a "
                        "full turn)")
                # A heading is an angle: rbp simulate's controller takes its error the short
                # way round, the rig and the verifier the turn as written. Beyond half a turn
                # they differ: a footstep move turning 3 full turns passed `rbp check` (its
                # ends the same configurations) and was simulated 180 deg off its heading.
                turn = abs(b[2] - a[2])
                if turn > MAX_STEP_TURN:
                    raise PlanFileError(
                        f"phases[{k}].steps[{n}].pose[2]", f"the body turns {turn:.6g} rad from "
                        f"the step before: a step turns it at most half a turn (pi rad), where "
                        "the turn as written is the short way round that rbp simulate takes")
            before = step


def _check_scenario_size(scenario: Any) -> None:
    """Refuse (PlanFileError on "scenario") an embedded scenario of more values than a
    scenario file may hold (`max_input_values`): the plan's own limits are a plan's, and a
    cave of 480,000 wall vertices inside a plan took seconds to refuse and half a minute to
    plan again from (`--from-plan`), where its scenario file is refused at once."""
    from rb_drake.input_files import count_values, max_input_values

    limit = max_input_values()
    if count_values(scenario, stop_after=limit) > limit:
        raise PlanFileError("scenario", f"the embedded scenario holds more than {limit:,} "
                            "values, the most a scenario file may (RBP_MAX_INPUT_VALUES "
                            "raises the limit)")


def _check_format(value: Any) -> None:
    """Refuse (PlanFileError on "format") a format the schema does not list, in its words."""
    from planning.plan_schema import plan_formats

    formats = plan_formats()
    if not isinstance(value, str) or value not in formats:
        raise PlanFileError("format", f"{value!r:.80} is not one of {formats!r}")


def _kind(value: Any) -> str:
    return {list: "an array", str: "a string", bool: "a boolean", type(None): "null"}.get(
        type(value), "a number")


def plan_from(plan: Any, what: str = "plan") -> Plan:
    """`plan` (argument `what` of the Python API) as a Plan: a Plan or a plan-file object (a
    dict) checked as a plan file is, through its JSON text (the reading limits, non-finite
    numbers, the schema, the times), so that a NaN, a bool or 10**400 is refused (PlanFileError
    naming the field) before numpy or Drake meet it (a NaN pose aborted the interpreter in
    Drake). A Plan is checked too: its fields are the caller's to replace (about 0.1 s for the
    demo plan)."""
    if isinstance(plan, Plan):
        try:
            plan = plan.to_dict()  # the form write_plan writes: checked as it will be read
        except (TypeError, ValueError, AttributeError, KeyError, RecursionError) as e:
            raise PlanFileError("(top level)", f"not a plan's values: {e}") from None
    if not isinstance(plan, dict):
        raise RbpInputError("expected a Plan (rbp.plan, rbp.read_plan) or a plan-file object "
                            f"(a dict), got {type(plan).__name__}", field=what)
    try:
        text = json.dumps(plan)  # NaN written as NaN: parse_plan_text names its field
    except (TypeError, ValueError, RecursionError) as e:  # a set, an object, 10**5000, a loop
        raise PlanFileError("(top level)", f"not a plan-file object: {e}") from None
    try:
        data = parse_plan_text(text)
    except PlanFileError as e:
        # "line 1, column N" of a text the caller never saw: name an integer past the floats
        found = _find_bad(plan, "", _huge) if (e.field or "").startswith("line ") else None
        if found is None:
            raise
        raise PlanFileError(found[0], e.reason) from None
    return Plan.from_dict(validated(data, quick=len(text) > QUICK_SCHEMA_ABOVE_CHARS))


def read_plan(path: str | Path) -> Plan:
    """A plan file as a Plan (either format; see `read_plan_file` for the errors)."""
    return Plan.from_dict(read_plan_file(path))


def content_hash(plan: dict[str, Any]) -> str:
    """SHA-256 of the plan's canonical JSON (sorted keys), without its stamp."""
    body = {k: v for k, v in plan.items() if k != "verified"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(f"{VERIFIER}\n{text}".encode()).hexdigest()


def stamp(plan: dict[str, Any]) -> dict[str, Any]:
    """The plan with the stamp of this verifier (call only on a plan that verified)."""
    return {k: v for k, v in plan.items() if k != "verified"} | {
        "verified": {"sha256": content_hash(plan), "verifier": VERIFIER}}


def has_valid_stamp(plan: dict[str, Any]) -> bool:
    """Whether the plan carries this verifier's stamp and is unchanged since."""
    mark = plan.get("verified")
    return (isinstance(mark, dict) and mark.get("verifier") == VERIFIER
            and mark.get("sha256") == content_hash(plan))
