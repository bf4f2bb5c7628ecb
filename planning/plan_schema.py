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
    absolute_path: list[str | int]


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
            return QuickError(e.message.removeprefix(e.name or "").strip(),
                              [int(p) if p.isdigit() else p for p in e.path[1:]])
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


def _is_integer_schema(sub: dict[str, Any]) -> bool:
    kinds = sub.get("type")
    return kinds == "integer" or (isinstance(kinds, list) and "integer" in kinds)


@functools.cache
def _cached_schema() -> dict[str, Any]:
    return schema()


def _has_integer(sub: Any, seen: frozenset[str] = frozenset()) -> bool:
    """Whether a part of the schema holds an integer field somewhere (`float_integer` walks
    only those parts: not the steps' numbers)."""
    if isinstance(sub, list):
        return any(_has_integer(s, seen) for s in sub)
    if not isinstance(sub, dict):
        return False
    ref = sub.get("$ref", "")
    if ref.startswith("#/$defs/"):
        name = ref.removeprefix("#/$defs/")
        return name not in seen and _has_integer(_cached_schema()["$defs"][name], seen | {name})
    return _is_integer_schema(sub) or any(_has_integer(v, seen) for v in sub.values())


_HAS_INTEGER: dict[int, bool] = {}  # by id() of a part of _cached_schema(), which lives on


def float_integer(plan: Any) -> tuple[list[Any], float] | None:
    """The path and value of the first float (2.0) where the schema asks for an integer, in a
    plan that follows the schema: JSON Schema's "integer" is any number with no fraction, so
    jsonschema and fastjsonschema accept 2.0, which then failed as an index (issue 28, F1)."""
    defs = _cached_schema()["$defs"]

    def walk(value: Any, sub: Any, path: list[Any]) -> tuple[list[Any], float] | None:
        if not isinstance(sub, dict):
            return None
        if id(sub) not in _HAS_INTEGER:
            _HAS_INTEGER[id(sub)] = _has_integer(sub)
        if not _HAS_INTEGER[id(sub)]:
            return None
        ref = sub.get("$ref", "")
        if ref.startswith("#/$defs/"):
            return walk(value, defs[ref.removeprefix("#/$defs/")], path)
        if _is_integer_schema(sub) and isinstance(value, float):
            return path, value
        parts = [sub] + [sub[k] for k in ("then", "else") if isinstance(sub.get(k), dict)]
        for part in parts:
            if isinstance(value, dict):
                props = part.get("properties", {})
                for key, item in value.items():
                    inner = props.get(key, part.get("additionalProperties"))
                    found = walk(item, inner, [*path, key])
                    if found is not None:
                        return found
            elif isinstance(value, list) and isinstance(part.get("items"), dict):
                for n, item in enumerate(value):
                    found = walk(item, part["items"], [*path, n])
                    if found is not None:
                        return found
        return None

    return walk(plan, _cached_schema(), [])
