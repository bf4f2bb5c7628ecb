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
from pathlib import Path
from typing import Any

from planning.plan_model import Plan
from rb_drake.errors import RbpInputError
from rb_drake.input_files import InputFileError, load_json, read_text

# bump when the rules change: older stamps then no longer count (3: rule between; 4: rule
# between on the smooth path `rbp simulate` follows)
VERIFIER = "rbp-verify/4"


class PlanFileError(RbpInputError):
    """A plan file that cannot be used: `field` (path in the file) and `reason`."""

    def __init__(self, field: str, reason: str):
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


_SCENARIO_FORMAT = re.compile(r"^format:\s*['\"]?reachbot-scenario/", re.MULTILINE)


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
    try:
        data = load_json(text, parse_constant=_Bad, parse_float=_float)
    except InputFileError as e:
        raise PlanFileError(e.field, e.reason) from None
    found = _find_bad(data, "")
    if found is not None:
        field, bad = found
        raise PlanFileError(field or "(top level)", f"must be a finite number, got {bad.text}")
    return data


def _find_bad(value: Any, path: str) -> tuple[str, _Bad] | None:
    if isinstance(value, _Bad):
        return path, value
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        sub = f"{path}[{key}]" if isinstance(key, int) else (f"{path}.{key}" if path else key)
        found = _find_bad(item, sub)
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
    return validated(plan)


def validated(plan: Any) -> dict[str, Any]:
    """A parsed plan checked against the schema; raises PlanFileError with the field."""
    from planning.plan_schema import schema_error

    error = schema_error(plan)
    if error is not None:
        field = "/".join(str(p) for p in error.absolute_path) or "(top level)"
        raise PlanFileError(field, error.message)
    return plan


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
