"""The plan file's JSON schema (`plan_schema.json`, draft 2020-12) and validation against it.

jsonschema is the reference validator, but it takes about 0.2 s on a demo plan (ten thousand
keyword checks, one Python call each), which `rbp plan` paid on writing and `rbp check` on
reading. fastjsonschema compiles the same schema to one Python function that takes about 3 ms;
it speaks draft 7, which has every keyword the schema uses (no `$ref` has siblings, where the
drafts differ). A plan the compiled function accepts is valid; one it refuses goes to
jsonschema, which raises with its path and message (or accepts it, and jsonschema decides).
`tests/test_plan_schema.py` holds the two to the same verdicts on mutated plans.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable
from importlib import resources
from typing import Any, NamedTuple


def schema() -> dict[str, Any]:
    return json.loads(resources.files("planning").joinpath("plan_schema.json").read_text())


@functools.cache
def plan_formats() -> list[str]:
    """The `format` values a plan file may have."""
    return list(schema()["properties"]["format"]["enum"])


@functools.cache
def _compiled() -> Callable[[Any], Any]:
    import fastjsonschema

    draft7 = {k: v for k, v in schema().items() if k != "$id"}  # its $id is not a URL
    draft7["$schema"] = "http://json-schema.org/draft-07/schema#"
    return fastjsonschema.compile(draft7)


class QuickError(NamedTuple):
    """The compiled validator's first error, in ValidationError's two attributes rbp uses."""

    message: str
    absolute_path: list[str]


def fast_verdict(plan: Any) -> bool:
    """Whether the compiled validator accepts `plan` (no message; see `validate`)."""
    import fastjsonschema

    try:
        _compiled()(plan)
    except fastjsonschema.JsonSchemaException:
        return False
    return True


def schema_error(plan: Any, quick: bool = False) -> Any:
    """None when `plan` follows the schema, else jsonschema's ValidationError (its path and
    message); jsonschema is imported only for a plan the compiled validator refuses. `quick`
    (for a large plan): the compiled validator's first error instead, as a QuickError, since
    jsonschema walks all of it (19 s for 30 MB with an error in its last step, against 0.5 s)."""
    import fastjsonschema

    try:
        _compiled()(plan)
        return None
    except fastjsonschema.JsonSchemaValueException as e:
        if quick:
            return QuickError(e.message.removeprefix(e.name or "").strip(), list(e.path[1:]))
    import jsonschema

    try:
        jsonschema.validate(plan, schema())
    except jsonschema.ValidationError as e:
        return e
    return None


def validate(plan: dict[str, Any]) -> None:
    """Raise jsonschema.ValidationError when `plan` does not follow the schema."""
    error = schema_error(plan)
    if error is not None:
        raise error
