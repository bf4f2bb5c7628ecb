"""Robot parameters: the one source of truth for ReachBot's geometry, masses and limits.

Units are SI (m, kg, N, N m); angles are stored in radians inside the dataclass and in degrees
in files (the `*_deg` names), because people write degrees.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from rb_drake.errors import RbpInputError

NUM_BOOMS = 4


@dataclasses.dataclass(frozen=True)
class RobotParams:
    """Planar ReachBot: a square body with four extendable booms.

    Boom i leaves the body at shoulder i (body frame), with its equilibrium direction
    `shoulder_directions[i]` and a range of +-`shoulder_range` about it.
    """

    body_size: tuple[float, float] = (0.30, 0.30)
    body_mass: float = 2.0
    shoulders: tuple[tuple[float, float], ...] = (
        (0.15, 0.15),
        (-0.15, 0.15),
        (-0.15, -0.15),
        (0.15, -0.15),
    )
    shoulder_directions_deg: tuple[float, ...] = (45.0, 135.0, 225.0, 315.0)
    shoulder_range_deg: float = 45.0
    boom_length: tuple[float, float] = (0.01, 2.0)
    boom_tension: tuple[float, float] = (0.5, 50.0)
    shoulder_torque_max: float = 5.0
    gripper_mass: float = 0.10
    boom_linear_density: float = 0.12
    attach_failure: float = 0.01
    p_min: float = 0.95
    # The planner's limit on a grasp's pull angle |psi| (a grasp must be pulled at less than
    # this from its normal). The model gives P = 0 from 90 deg on, a cliff: a plan that holds a
    # grasp at 89.99 deg is executed past 90 deg by the slightest tracking error. The margin
    # below 90 deg is docs/model.md's "Pull-angle margin".
    max_pull_angle_deg: float = 88.0

    # Derived arrays, for the vectorised kernels.
    @property
    def shoulder_array(self) -> np.ndarray:
        """Shoulder positions in the body frame, shape (4, 2)."""
        return np.asarray(self.shoulders, dtype=float)

    @property
    def shoulder_directions(self) -> np.ndarray:
        """Equilibrium directions in radians, shape (4,)."""
        return np.radians(np.asarray(self.shoulder_directions_deg, dtype=float))

    @property
    def shoulder_range(self) -> float:
        return math.radians(self.shoulder_range_deg)

    @property
    def max_pull_angle(self) -> float:
        """The planner's pull-angle limit in radians: feasible grasps have |psi| < this."""
        return math.radians(self.max_pull_angle_deg)

    @functools.cached_property
    def max_reach(self) -> float:
        """The farthest an anchor can be from the body centre: longest boom plus shoulder offset."""
        return self.boom_length[1] + float(np.max(np.linalg.norm(self.shoulder_array, axis=1)))

    @property
    def log_p_min(self) -> float:
        """r_min: the smallest allowed configuration robustness, log(p_min)."""
        return math.log(self.p_min)

    def to_dict(self) -> dict[str, Any]:
        """The resolved parameters with the names used in scenario and plan files."""
        return {
            "body_size": list(self.body_size),
            "body_mass": self.body_mass,
            "shoulders": [list(s) for s in self.shoulders],
            "shoulder_directions_deg": list(self.shoulder_directions_deg),
            "shoulder_range_deg": self.shoulder_range_deg,
            "boom_length": list(self.boom_length),
            "boom_tension": list(self.boom_tension),
            "shoulder_torque_max": self.shoulder_torque_max,
            "gripper_mass": self.gripper_mass,
            "boom_linear_density": self.boom_linear_density,
            "attach_failure": self.attach_failure,
            "p_min": self.p_min,
            "max_pull_angle_deg": self.max_pull_angle_deg,
        }

    def replace(self, **changes: Any) -> RobotParams:
        return dataclasses.replace(self, **changes)


class ParamError(RbpInputError):
    """A robot parameter override is malformed. `field` is its name inside `robot:`."""

    def __init__(self, field: str, reason: str):
        super().__init__(reason, field=field)


# Physically meaningful magnitudes of robot parameters (docs/formats.md): beyond them a value is
# a typo, and refusing it at reading keeps overflow out of the statics.
MAX_SIZE = 100.0      # m: body sides, shoulder offsets
# m: boom length. ReachBot's are a few metres; the search's cost grows with the area in reach
# (demo-shaft: 2 m 2.7 s and 0.3 GB, 5 m 15 s and 0.36 GB, 10 m 32 s and 0.5 GB, 20 m past
# 60 s and 1 GB), so a longer boom is refused rather than left to run for minutes.
MAX_BOOM = 5.0
MAX_FORCE = 1e6       # N: boom tension; N m: shoulder torque
MAX_MASS = 1e6        # kg: body and gripper; kg/m: boom density
# kg: the simulator's four shoulder links (0.01 kg each) ride on the body, whose own mass is
# the rest; a body of 0.03 kg was simulated with negative inertia (Drake warned, 8 lines)
MIN_BODY_MASS = 0.1
MAX_DEGREES = 1e4     # shoulder directions


def _number(field: str, value: Any, lo: float | None = None, hi: float | None = None,
            lo_open: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParamError(field, f"expected a number, got {type(value).__name__} {_short(value)}")
    try:
        v = float(value)
    except OverflowError:  # an integer too large for a float
        v = math.inf
    if not math.isfinite(v):
        raise ParamError(field, f"must be finite, got {_short(value)}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ParamError(field, f"must be {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and v > hi:
        raise ParamError(field, f"must be <= {hi}, got {v}")
    return v


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _vector(field: str, value: Any, n: int, bound: float) -> tuple[float, ...]:
    if not isinstance(value, list | tuple) or len(value) != n:
        raise ParamError(field, f"expected a list of {n} numbers, got {_short(value)}")
    return tuple(_number(f"{field}[{k}]", v, -bound, bound) for k, v in enumerate(value))


def _interval(field: str, value: Any, lo: float, hi: float) -> tuple[float, float]:
    a, b = _vector(field, value, 2, hi)
    if a < lo:
        raise ParamError(f"{field}[0]", f"must be >= {lo}, got {a}")
    if not a < b:
        raise ParamError(field, f"expected [min, max] with min < max, got {[a, b]}")
    return a, b


MIN_SHOULDER_GAP = 1e-3  # m: shoulders apart and off the body's centre (the statics divide by it)


def _check_shoulders(key: str, shoulders: tuple[tuple[float, ...], ...]) -> None:
    for i, (x, y) in enumerate(shoulders):
        if not math.hypot(x, y) >= MIN_SHOULDER_GAP:
            raise ParamError(f"{key}[{i}]", f"at the body's centre: a shoulder must be at least "
                             f"{MIN_SHOULDER_GAP} m from it")
        for k in range(i):
            if not math.dist(shoulders[k], (x, y)) >= MIN_SHOULDER_GAP:
                raise ParamError(f"{key}[{i}]", f"at shoulder {k}'s place: shoulders must be at "
                                 f"least {MIN_SHOULDER_GAP} m apart")


def robot_from_dict(overrides: Mapping[str, Any] | None) -> RobotParams:
    """Defaults updated by `overrides` (a scenario's `robot:` block); raises ParamError."""
    if overrides is None:
        return RobotParams()
    if not isinstance(overrides, Mapping):
        raise ParamError("robot", "expected a mapping of parameter names, got "
                         f"{_short(overrides)}")
    known = {f.name for f in dataclasses.fields(RobotParams)}
    changes: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in known:
            raise ParamError(str(key),
                             f"unknown robot parameter; known: {', '.join(sorted(known))}")
        if key == "body_size":
            w, h = _vector(key, value, 2, MAX_SIZE)
            if w <= 0 or h <= 0:
                raise ParamError(key, f"sides must be positive, got {[w, h]}")
            changes[key] = (w, h)
        elif key == "shoulders":
            if not isinstance(value, list | tuple) or len(value) != NUM_BOOMS:
                raise ParamError(key, f"expected {NUM_BOOMS} [x, y] pairs, got {_short(value)}")
            changes[key] = shoulders = tuple(_vector(f"{key}[{i}]", s, 2, MAX_SIZE)
                                             for i, s in enumerate(value))
            _check_shoulders(key, shoulders)
        elif key == "shoulder_directions_deg":
            changes[key] = _vector(key, value, NUM_BOOMS, MAX_DEGREES)
        elif key == "shoulder_range_deg":
            changes[key] = _number(key, value, 0.0, 180.0, lo_open=True)
        elif key == "boom_length":
            changes[key] = _interval(key, value, 0.0, MAX_BOOM)
        elif key == "boom_tension":
            changes[key] = _interval(key, value, 0.0, MAX_FORCE)
        elif key in ("body_mass",):
            changes[key] = _number(key, value, MIN_BODY_MASS, MAX_MASS)
        elif key == "shoulder_torque_max":
            changes[key] = _number(key, value, 0.0, MAX_FORCE)
        elif key in ("gripper_mass", "boom_linear_density"):
            changes[key] = _number(key, value, 0.0, MAX_MASS)
        elif key == "attach_failure":  # 1 would make every climb fail (p_path 0)
            changes[key] = _number(key, value, 0.0, 1.0)
            if not changes[key] < 1.0:
                raise ParamError(key, f"must be < 1 (a grasp that always fails), got {value}")
        elif key == "p_min":
            changes[key] = _number(key, value, 0.0, 1.0, lo_open=True)
        elif key == "max_pull_angle_deg":
            changes[key] = _number(key, value, 0.0, 90.0, lo_open=True)
    return RobotParams(**changes)
