"""The planar ReachBot rig (paper section V-B): its scenario, a body plan for it, a simulator.

The prototype hangs a light body in a rectangular frame by four elastic booms. Each boom is
wound on a winch in the body (which sets its length and tension) and fixed at its far end to an
anchor: a single-axis load cell on a hinge. Anchors never move, so the rig runs body movements
only. `RigSimulator` stands in for the hardware: `handle(command) -> status`, and
`RigSimulatorLcm` puts it on an LCM bus.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Protocol

import numpy as np

import rb_drake
from planning.plan import BODY_SPEED, TURN_SPEED, plan_header, score_plan, validate
from planning.plan_model import Phase, plan_dict
from planning.plan_steps import allocation_step
from rb_drake import geometry
from rb_drake.feasibility import REASON_TEXT, Reason, check_poses
from rb_drake.params import RobotParams
from rb_drake.scenario import Scenario, load_scenario
from systems.reachbot_lcm import rig_command_t, rig_status_t

RIG_SCENARIO = Path(rb_drake.__file__).parent / "data" / "rig.yaml"


def load_rig_scenario() -> Scenario:
    """The rig's bundled scenario (`rb_drake/data/rig.yaml`)."""
    return load_scenario(RIG_SCENARIO)


def rig_plan(scn: Scenario, goal_pose: np.ndarray | None = None,
             num_steps: int = 11) -> dict[str, Any]:
    """A one-phase plan file: the body moves in a straight line from the start pose to the goal.

    The goal pose defaults to the scenario's goal position at the start heading; the plan's
    scenario has its goal there, so that the plan verifies (`rbp check`). Each of the
    `num_steps` evenly spaced poses carries the robust tension allocation and its probabilities
    (as `planning.plan` builds them); time stamps assume the plan file's nominal speeds. A
    stand-in for the seed + SCP body planner: the plan fails where a pose is infeasible.
    """
    start = np.asarray(scn.start_pose, dtype=float)
    goal = (np.array([*scn.goal_position, start[2]]) if goal_pose is None
            else np.asarray(goal_pose, dtype=float))
    duration = max(1.0, float(np.linalg.norm(goal[:2] - start[:2])) / BODY_SPEED,
                   abs(float(goal[2] - start[2])) / TURN_SPEED)
    s = np.linspace(0.0, 1.0, num_steps)
    poses = start + s[:, None] * (goal - start)
    stance_ids = tuple(scn.start_stance)
    check = check_poses(scn, scn.stance(stance_ids), poses, full=True)
    alloc = check.allocation
    stance = scn.stance(stance_ids)
    steps = [allocation_step(stance, alloc, k, round(float(duration * s[k]), 6), poses[k])
             for k in range(num_steps)]
    bad = np.flatnonzero(~check.feasible)
    reason = ("" if not len(bad) else f"pose {bad[0]} of the straight line: "
              f"{REASON_TEXT[Reason(check.reason[bad[0]])]}")
    goal_scn = dataclasses.replace(scn, goal_position=(float(goal[0]), float(goal[1])))
    plan = plan_header(goal_scn, "rbp", not len(bad), reason)  # the plan ends at its goal
    plan = plan.replace(phases=(Phase(kind="body", stance=stance_ids, free_boom=None,
                                      steps=tuple(steps)),))
    if plan.success:
        plan = score_plan(plan, scn.robot.attach_failure)
    out = plan_dict(plan)  # the rig's code and its callers take the plan-file object
    validate(out)
    return out


@dataclasses.dataclass(frozen=True)
class RigSimConfig:
    """The simulated rig's hardware: winch speed, boom elasticity, sensor noise (SI units)."""

    winch_speed: float = 0.5     # m/s: each winch's rate limit
    stiffness: float = 200.0     # N/m: extra tension per metre a boom is stretched
    force_noise: float = 0.05    # N: load-cell noise, standard deviation
    hinge_noise: float = 0.002   # rad: hinge-angle sensor noise, standard deviation
    seed: int = 0


class RigSimulator:
    """The rig as a function of its commands: `handle(command) -> status`.

    Model: each winch moves its boom length towards the command at most `winch_speed`; the body
    sits at the pose whose shoulder-anchor distances best match the winch lengths (least
    squares, warm-started); each elastic boom pulls with its tension setpoint plus `stiffness`
    times its stretch (distance minus winch length), never pushing; load cells add Gaussian
    noise and the hinges read the boom's direction (anchor -> shoulder). The first command
    finds the rig already set to it: its winch lengths are taken as they are.
    """

    def __init__(self, robot: RobotParams, anchors: np.ndarray, start_pose: np.ndarray,
                 config: RigSimConfig = RigSimConfig()):
        self.robot = robot
        self.anchors = np.asarray(anchors, dtype=float).reshape(4, 2)
        self.config = config
        self.pose = np.asarray(start_pose, dtype=float).copy()
        self.winch: np.ndarray | None = None
        self.utime: int | None = None
        self._rng = np.random.default_rng(config.seed)

    def handle(self, command: rig_command_t) -> rig_status_t:
        target = np.asarray(command.boom_length, dtype=float)
        if self.winch is None:
            self.winch = target.copy()
        else:
            dt = max(0.0, (command.utime - self.utime) * 1e-6)
            step = self.config.winch_speed * dt
            self.winch = self.winch + np.clip(target - self.winch, -step, step)
        self.utime = command.utime
        self.pose = fit_pose(self.robot, self.anchors, self.winch, self.pose)
        geo = geometry.boom_geometry(self.robot, self.pose, self.anchors)
        stretch = geo.length[0] - self.winch
        tension = np.maximum(0.0, np.asarray(command.tension_setpoint, dtype=float)
                             + self.config.stiffness * stretch)
        hinge = np.arctan2(-geo.u[0, :, 1], -geo.u[0, :, 0])
        status = rig_status_t()
        status.utime = command.utime
        status.winch_length = self.winch.tolist()
        status.load_cell_force = (tension + self._rng.normal(0.0, self.config.force_noise, 4)
                                  ).tolist()
        status.hinge_angle = geometry.wrap_angle(
            hinge + self._rng.normal(0.0, self.config.hinge_noise, 4)).tolist()
        return status


def fit_pose(robot: RobotParams, anchors: np.ndarray, lengths: np.ndarray,
             guess: np.ndarray, iterations: int = 20, tol: float = 1e-12) -> np.ndarray:
    """The pose whose shoulder-anchor distances best match `lengths` (Gauss-Newton)."""
    pose = np.asarray(guess, dtype=float).copy()
    for _ in range(iterations):
        residual = geometry.boom_geometry(robot, pose, anchors).length[0] - lengths
        J = geometry.pose_jacobians(robot, pose, anchors).length[0]
        step = np.linalg.lstsq(J, -residual, rcond=None)[0]
        pose += step
        if np.max(np.abs(step)) < tol:
            break
    return pose


class LcmBus(Protocol):
    """What the simulator needs of an LCM instance (pydrake's DrakeLcm has it)."""

    def Subscribe(self, channel: str, handler) -> Any: ...  # noqa: N802 (Drake's name)

    def Publish(self, channel: str, buffer: bytes,  # noqa: N802
                time_sec: float | None = None) -> None: ...


class RigSimulatorLcm:
    """Puts a `RigSimulator` on a bus: every command received is answered by one status."""

    def __init__(self, simulator: RigSimulator, lcm: LcmBus, command_channel: str,
                 status_channel: str):
        self.simulator = simulator
        self.lcm = lcm
        self.status_channel = status_channel
        lcm.Subscribe(command_channel, self._on_command)

    def _on_command(self, data: bytes) -> None:
        status = self.simulator.handle(rig_command_t.decode(data))
        self.lcm.Publish(self.status_channel, status.encode())
