"""The plan file's JSON Schema, generated from the model (`planning.plan_model`).

Each dataclass of the model becomes a closed object (`additionalProperties: false`): its fields
are its properties, those without a default are required, and a field's type gives its JSON
type (`float` a number, `X | None` also null, a tuple an array, a part a `$ref`); a field's
`metadata["schema"]` adds bounds and a description, and a class's `EXTRA` conditions between
fields (a reach phase's anchors). The scenario and robot are rb_drake's formats, checked in full
by `scenario_from_dict` when a plan's scenario is rebuilt; their outline is written here.

`python -m planning.plan_schema_gen` rewrites `planning/plan_schema.json`; tests/test_plan.py
fails when the committed file differs from `generate()`.
"""

from __future__ import annotations

import dataclasses
import enum
import json
import types
import typing
from pathlib import Path
from typing import Any, Literal

from planning import plan_model
from planning.plan_model import COORDINATE, FORMATS, MAX_FORCE, Part, Phase, Plan

SCHEMA_FILE = Path(__file__).with_name("plan_schema.json")

ROBOT_KEYS = ("body_size", "body_mass", "shoulders", "shoulder_directions_deg",
              "shoulder_range_deg", "boom_length", "boom_tension", "shoulder_torque_max",
              "gripper_mass", "boom_linear_density", "attach_failure", "p_min")
ROBOT = {
    "type": "object",
    "description": "every robot parameter (rb_drake.params.RobotParams.to_dict)",
    "required": list(ROBOT_KEYS),
    "additionalProperties": False,
    "properties": {
        "body_size": {"$ref": "#/$defs/vec2"},
        "body_mass": {"type": "number", "exclusiveMinimum": 0},
        "shoulders": {"type": "array", "items": {"$ref": "#/$defs/vec2"}, "minItems": 4,
                      "maxItems": 4},
        "shoulder_directions_deg": {"$ref": "#/$defs/vec4"},
        "shoulder_range_deg": {"type": "number"},
        "boom_length": {"$ref": "#/$defs/vec2"},
        "boom_tension": {"$ref": "#/$defs/vec2"},
        "shoulder_torque_max": {"type": "number", "minimum": 0},
        "gripper_mass": {"type": "number", "minimum": 0},
        "boom_linear_density": {"type": "number", "minimum": 0},
        "attach_failure": {"type": "number", "minimum": 0, "exclusiveMaximum": 1},
        "p_min": {"type": "number", "exclusiveMinimum": 0, "maximum": 1},
        "max_pull_angle_deg": {"type": "number", "exclusiveMinimum": 0, "maximum": 90},
    },
}
SCENARIO = {
    "type": "object",
    "description": "the cave (rb_drake.scenario, format reachbot-scenario/1); its robot is the "
                   "plan's `robot` (reachbot-plan/1 kept a copy here, `robot`)",
    "required": ["format", "name", "gravity", "walls", "anchors", "start", "goal"],
    "additionalProperties": False,
    "properties": {
        "format": {"const": "reachbot-scenario/1"},
        "name": {"type": "string"},
        "gravity": {"$ref": "#/$defs/vec2"},
        "robot": {"type": "object", "description": "reachbot-plan/1 only: a copy of the "
                  "plan's robot (the verifier's rule `robot`)"},
        "walls": {"type": "array", "items": {"type": "array", "items": {"$ref": "#/$defs/vec2"}}},
        "anchors": {
            "type": "array",
            "items": {
                "type": "object",
                "required": ["id", "position", "normal", "limit", "sigma"],
                "additionalProperties": False,
                "properties": {
                    "id": {"type": "string"},
                    "position": {"$ref": "#/$defs/vec2"},
                    "normal": {"$ref": "#/$defs/vec2"},
                    "limit": {"type": "object"},
                    "sigma": {"type": "object"},
                },
            },
        },
        "start": {"type": "object"},
        "goal": {"type": "object"},
    },
}
COMMON = {
    "vec2": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
    "vec4": {"type": "array", "items": {"type": "number"}, "minItems": 4, "maxItems": 4},
    "maybe4": {"type": "array", "items": {"type": ["number", "null"]}, "minItems": 4,
               "maxItems": 4},
    "force4": {"type": "array", "items": {"type": ["number", "null"], "minimum": -MAX_FORCE,
                                          "maximum": MAX_FORCE}, "minItems": 4, "maxItems": 4},
    "point": {"type": "array", "items": COORDINATE, "minItems": 2, "maxItems": 2},
}
SCALARS = {float: "number", int: "integer", str: "string", bool: "boolean"}


def _def_name(cls: type) -> str:
    return cls.__name__.lower()


def _type_schema(tp: Any, extra: dict[str, Any]) -> dict[str, Any]:
    """The schema of a field's type; `extra` (the field's metadata) may replace the items or
    the whole schema by a `ref` to a definition."""
    ref = extra.pop("ref", None)
    if ref is not None:
        return {"$ref": f"#/$defs/{ref}"}
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        inner = [a for a in args if a is not type(None)]
        schema = _type_schema(inner[0], extra)
        if "$ref" in schema or "enum" in schema:  # an optional part: null only if nullable
            return schema
        if extra.pop("nullable", True):  # a required X | None; optional ones are absent
            schema["type"] = [schema["type"], "null"]
        return schema
    if origin is Literal:
        return {"enum": list(args)}
    if isinstance(tp, type) and issubclass(tp, enum.StrEnum):  # the file holds its strings
        return {"enum": [member.value for member in tp]}
    if origin is tuple:
        items = extra.pop("items", None) or _type_schema(args[0], {})
        return {"type": "array", "items": items}
    if origin is dict:
        return {"type": "object"}
    if isinstance(tp, type) and issubclass(tp, Part):
        return {"$ref": f"#/$defs/{_def_name(tp)}"}
    return {"type": SCALARS[tp]}


def object_schema(cls: type[Part]) -> dict[str, Any]:
    """The closed object schema of one part of the model."""
    hints = typing.get_type_hints(cls, vars(plan_model))
    schema: dict[str, Any] = {"type": "object"}
    description = getattr(cls, "DESCRIPTION", None)
    if description:
        schema["description"] = description
    required, properties = [], {}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.metadata.get("file") is False:
            continue
        extra = dict(f.metadata.get("schema", {}))
        extra.setdefault("nullable", f.default is dataclasses.MISSING)  # optional: absent
        prop = _type_schema(hints[f.name], extra)
        extra.pop("nullable", None)
        if "$ref" in prop and extra:  # draft 7 ignores a $ref's siblings: wrap it
            prop = {"allOf": [prop]}
        prop.update(extra)
        properties[f.name] = prop
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(f.name)
    schema["required"] = required
    schema["additionalProperties"] = False
    schema["properties"] = properties
    schema.update(getattr(cls, "EXTRA", {}))
    return schema


def _parts(cls: type[Part], seen: dict[str, type[Part]]) -> None:
    hints = typing.get_type_hints(cls, vars(plan_model))
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        for tp in (hints[f.name], *typing.get_args(hints[f.name])):
            for t in (tp, *typing.get_args(tp)):
                if isinstance(t, type) and issubclass(t, Part) and _def_name(t) not in seen:
                    seen[_def_name(t)] = t
                    _parts(t, seen)


def generate() -> dict[str, Any]:
    """The plan file's JSON Schema (draft 2020-12) from the model."""
    top = object_schema(Plan)
    parts: dict[str, type[Part]] = {}
    _parts(Plan, parts)
    defs = dict(COMMON) | {"robot": ROBOT, "scenario": SCENARIO}
    defs |= {name: object_schema(cls) for name, cls in sorted(parts.items())}
    assert "phase" in defs and parts["phase"] is Phase
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "reachbot-plan",
            "title": "ReachBot plan",
            "description": top.pop("description"),
            **top,
            "$comment": f"generated from planning/plan_model.py by planning/plan_schema_gen.py; "
                        f"formats {', '.join(FORMATS)}",
            "$defs": defs}


def schema_text() -> str:
    return json.dumps(generate(), indent=1) + "\n"


def main() -> None:
    SCHEMA_FILE.write_text(schema_text())
    print(f"wrote {SCHEMA_FILE}")


if __name__ == "__main__":
    main()
