"""Planner configurations as plain data, for YAML files and the plan file's provenance.

`config_to_dict` writes any configuration dataclass (`PipelineConfig` and the dataclasses it
nests) with `dataclasses.asdict`, infinities as the strings "inf" / "-inf" (JSON has no
infinity). `config_from_dict` reads one back, generically over the dataclass's fields and their
type hints (nested dataclasses, bool, int, float, str, tuples, `X | None`), on top of a base
configuration: keys left out keep the base's values. A mistake raises `ConfigError` naming the
file, the dotted key and the reason: unknown keys (with the known ones), wrong types, and
values outside the field's range (`planning.config_ranges`: what no type can say).
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from planning.config_ranges import SECTIONS, describe, field_problem, unknown_key
from rb_drake.errors import RbpInputError, key_text
from rb_drake.scenario import ScenarioError, read_yaml_file

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")  # a configuration dataclass


class ConfigError(ScenarioError):
    """A configuration refused: `source` (file), `field` (dotted key) and `reason`, as a
    scenario's mistakes are reported."""


def config_to_dict(config: Any) -> dict[str, Any]:
    """Every field of a configuration dataclass, nested ones as mappings, JSON-safe."""
    return _plain(_fields(config))


def _fields(value: Any) -> Any:
    """`dataclasses.asdict` without its deep copy: a value no reader takes (a generator for a
    tuple, a lock) is left for `config_from_dict` to name, where asdict's copy ended in
    "TypeError: cannot pickle 'generator' object" (rbp.plan checks a config this way)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _fields(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, dict):
        return {k: _fields(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_fields(v) for v in value]
    return value


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, float) and math.isinf(value):
        return "inf" if value > 0 else "-inf"
    if getattr(value, "ndim", 0) and hasattr(value, "tolist"):  # a numpy array, as a list
        return _plain(value.tolist())
    if hasattr(value, "item") and not isinstance(value, str):  # numpy scalars
        return _plain(value.item())
    return value


def config_from_dict(cls: type[T], data: Any, source: str, base: T | None = None,
                     prefix: str = "") -> T:
    """`base` (default `cls()`) with the keys of `data` replaced, checked against cls's fields."""
    base = cls() if base is None else base
    where = prefix or "(top level)"
    if not isinstance(data, dict):
        raise ConfigError(source, where, f"expected a mapping, got {describe(data)}")
    if not prefix and SECTIONS.get(cls.__name__) == "" and (found := unknown_key(data)):
        # a whole file's keys before its values, as `rbp plan` checks them before its imports:
        # the same first problem named either way
        raise ConfigError(source, *found)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    hints = typing.get_type_hints(cls)
    changes = {}
    for key, value in data.items():
        field = f"{prefix}.{key}" if prefix else str(key)
        if key not in fields:
            name = f"{prefix}.{key_text(key)}" if prefix else key_text(key)
            raise ConfigError(source, name, f"unknown key; expected one of {sorted(fields)}")
        changes[key] = _convert(value, hints[key], source, field, getattr(base, key))
        problem = field_problem(cls, key, changes[key])  # planning.config_ranges
        if problem:
            raise ConfigError(source, field, problem)
    try:
        return dataclasses.replace(base, **changes)
    except RbpInputError as e:  # a dataclass that checks its own values (RepairConfig)
        field = e.field or where
        if prefix and e.field:  # its field as a file gives it ("footstep.segments.commit") or
            # its own name (LatticeConfig's "angle_step_deg"), under `prefix`: a plan's
            # "provenance.config.footstep.segments" named "...segments.footstep.segments.commit"
            section = SECTIONS.get(cls.__name__, "")
            name = e.field.removeprefix(section) if section else e.field
            field = f"{prefix}.{name}"
        raise ConfigError(source, field, e.reason) from None


def _convert(value: Any, tp: Any, source: str, field: str, current: Any) -> Any:
    def fail(expected: str) -> ConfigError:
        return ConfigError(source, field, f"expected {expected}, got {describe(value)}")

    if isinstance(tp, type) and dataclasses.is_dataclass(tp):  # a hint: a class, not an instance
        return config_from_dict(tp, value, source, base=current, prefix=field)
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        options = [a for a in args if a is not type(None)]
        if len(options) == 1:  # X | None: X's own error, with its field
            return _convert(value, options[0], source, field, current)
        reasons = []
        for option in options:
            try:
                return _convert(value, option, source, field, current)
            except ConfigError as e:
                reasons.append(e.reason)
        raise ConfigError(source, field, " or ".join(reasons)) if reasons else fail("a value")
    if origin is typing.Literal:
        if value not in args:
            raise fail(f"one of {list(args)}")
        return value
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise fail("a list")
        if len(args) == 2 and args[1] is Ellipsis:
            kinds = [args[0]] * len(value)
        elif len(value) != len(args):
            raise fail(f"a list of {len(args)}")
        else:
            kinds = list(args)
        return tuple(_convert(v, k, source, f"{field}[{i}]", None)
                     for i, (v, k) in enumerate(zip(value, kinds, strict=True)))
    if tp is bool:
        if not isinstance(value, bool):
            raise fail("true or false")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise fail("an integer")
        return value
    if tp is float:
        if isinstance(value, str) and value.strip().lower() in ("inf", "+inf", "-inf"):
            return float(value)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail("a number")
        try:
            number = float(value)
        except OverflowError:  # an integer beyond the float range
            raise fail("a number within the float range") from None
        if math.isnan(number):
            raise fail("a number (not nan)")
        return number
    if tp is str:
        if not isinstance(value, str):
            raise fail("a string")
        return value
    return value  # a type this reader does not know: taken as written


def checked_config(config: T, source: str = "config") -> T:
    """`config` (a configuration dataclass built in Python) held to the ranges a file's values
    are (`config_from_dict`): rbp.plan(PipelineConfig(dt=0.0)) failed only after the search;
    a PipelineConfig's `dt` long enough for its seed's steps, as `rbp plan` checks it."""
    from planning.config_ranges import speed_problem

    checked = config_from_dict(type(config), config_to_dict(config), source)
    if hasattr(checked, "dt") and hasattr(checked, "seed") and (
            problem := speed_problem(checked)):
        raise ConfigError(source, "dt", problem)
    return checked


def load_config(path: str | Path, cls: type[T], base: T | None = None) -> T:
    """Read a YAML configuration file on top of `base`; raises ConfigError."""
    data = read_yaml_file(path, ConfigError)
    return config_from_dict(cls, {} if data is None else data, str(path), base=base)
