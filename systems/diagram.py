"""A plan file executed as a Drake diagram: plan source, tension controller, the robot's
plant, grasp monitor, stochastic grasp failures and loggers, run by a `Simulator`.

    PlanSource ──desired state, feed-forward tensions, free limb, stance──┐
        │                                                                 ▼
        │         body state (x, y, phi, rates) ─────────────────▶ TensionController
        │                  ▲                   tip push ◀── LimbController │ tensions
        ▼                  │                                 │ free joints ▼
    AnchorLoadMonitor ◀── MultibodyPlant ◀── generalized force = -T on each prismatic joint
        │ probability      (reaction forces, state)            + the free limb's joints
        ▼
    GraspFailures (drawn strengths: latches the first failure)          loggers

Where each system lives: `PlanSource` and `PlanTrajectory` (how plan phases become
trajectories) in `systems.trajectory`; `TensionController`, `LimbController`, `BoomForces` and
the statics they share in `systems.control`; `AnchorLoadMonitor`, `GraspMonitor` and
`GraspFailures` in `systems.monitors`. This module composes them (`ClimbSimulator`) and keeps
a run's samples (`SimulationRecord`).

The plant (`plant="full"`, the default) is rb_drake's whole robot (`build_plant` with
`hold_tips`): the body on its planar joint, per boom a passive revolute shoulder, a prismatic
boom and a tip carrying the gripper, discrete (PLANT_TIME_STEP) with the SAP solver. Every
attached tip is held at its anchor by a ball constraint, switched per phase; an attached boom's
tension T is its prismatic joint's force -T, so the constraint turns it into the boom's pull
on the body at the shoulder. The free boom of a reach phase follows the planned tip
(`LimbController`); its mass (boom_linear_density times its planned length, half at the tip
and half at the shoulder: the weight and moments of the model's uniform boom) is updated every
BOOM_MASS_PERIOD, and anchored booms are massless as in the model (the grippers' weight the
anchors carry; the body is lighter by the 10 g arm links at its shoulders, so the robot weighs
what the model's weighs). In a release or attach ramp (`planning.ramps`) the ramped boom's mass
and the share of its limb its joints hold follow the plan's share every RAMP_MASS_PERIOD, and a
gripper opens or closes only on a boom pulling at most RELEASE_TENSION (`_gripper_may_switch`).
The monitor (`AnchorLoadMonitor`) reads each anchored boom's pull on its gripper from the
plant's joint reaction forces.

`plant="body"` is the body alone on a planar joint (continuous): `BoomForces` applies each
attached boom's tension along its unit vector (as the generalized force of the planar joint)
and, in a reach phase, the free limb's weight (`geometry.limb_load`), as the statics do;
`GraspMonitor` takes the tension along shoulder -> anchor. The two agree where the plan moves
slowly; the full plant adds the free limb's inertia (0.2 kg at 1.5 m: ten times the body's
moment of inertia about its shoulder), which the quasi-static plan does not see.

The controller is a feedthrough system, evaluated once per plant step (the discrete plant
samples its input), and the stance switches at the phase boundaries, where `ClimbSimulator.run`
switches the holds between `AdvanceTo` calls. `GraspFailures` latches the first failure, which
stops the simulation.

Python `LeafSystem`s are never freed in pydrake 1.51 (STACK.md section 5), so `ClimbSimulator`
builds its diagram once per scenario; the plan and the draws are abstract parameters of the
context, set before each run, so one diagram serves every plan (including replans) on a cave.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import PlanarJoint, SpatialInertia
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import Context, DiagramBuilder, EventStatus
from pydrake.systems.primitives import Adder, LogVectorOutput, MatrixGain

from planning.ramps import RELEASE_TENSION
from rb_drake import geometry
from rb_drake.errors import RbpInputError
from rb_drake.params import NUM_BOOMS
from rb_drake.plant import ARM_MASS, BODY_THICKNESS, ReachBotPlant, build_plant
from rb_drake.scenario import Scenario
from systems.control import BoomForces, ControlGains, LimbController, TensionController
from systems.holdings import StrengthDraws
from systems.monitors import AnchorLoadMonitor, Cause, Failure, GraspFailures, GraspMonitor
from systems.plan_source import PlanSource
from systems.trajectory import PlanTrajectory


class SimulationError(RuntimeError):
    """The simulation's solver failed (a plan flown with `--no-verify` that was made for
    another cave, say): where, as phase, kind and time, and the solver's first line."""

    def __init__(self, phase: int, kind: str, time: float, reason: str):
        self.phase, self.kind, self.time, self.reason = phase, kind, time, reason
        super().__init__(f"the simulation failed in phase {phase} ({kind}) at t = {time:.2f} s: "
                         f"{reason}")


SAMPLE_PERIOD = 0.02  # s: loggers and the failure check run at this period, on the same grid
PLANT_TIME_STEP = 1e-2  # s, the full (discrete) plant's period
BOOM_MASS_PERIOD = 0.1  # s, how often the free boom's mass follows its length (full plant)
RAMP_MASS_PERIOD = 0.02  # s, how often a ramped boom's mass follows its share (full plant)


class SimulationRecord(NamedTuple):
    """One run, sampled every SAMPLE_PERIOD (times (N,), arrays (N, ...))."""

    plan: PlanTrajectory
    times: np.ndarray
    phase: np.ndarray         # (N,) int
    state: np.ndarray         # (N, 6) x, y, phi, vx, vy, omega
    desired: np.ndarray       # (N, 6)
    tension: np.ndarray       # (N, 4) commanded = applied (0 for a free boom)
    pull_angle: np.ndarray    # (N, 4), NaN for a free boom
    force: np.ndarray         # (N, 4), NaN for a free boom
    probability: np.ndarray   # (N, 4), NaN for a free boom
    failure: Failure | None
    joints: np.ndarray | None = None  # (N, 8) theta_0, L_0, ..., theta_3, L_3 (full plant)

    def tip_positions(self) -> np.ndarray:
        """The simulated boom tips in the world, (N, 4, 2) (full plant only)."""
        if self.joints is None:
            raise ValueError("the body-only plant has no boom tips")
        robot = self.plan.scenario.robot
        return np.stack([geometry.tip_positions(robot, x[:3], j[0::2], j[1::2])
                         for x, j in zip(self.state, self.joints, strict=True)])

    @property
    def position_error(self) -> np.ndarray:
        return np.linalg.norm(self.state[:, :2] - self.desired[:, :2], axis=1)

    @property
    def heading_error(self) -> np.ndarray:
        return np.abs(geometry.wrap_angle(self.state[:, 2] - self.desired[:, 2]))

    def holding_minimum(self) -> np.ndarray:
        """min_t P_i(t) of each holding (plan.holdings order) over the recorded samples."""
        out = np.ones(len(self.plan.holdings))
        for h, hold in enumerate(self.plan.holdings):
            rows = (self.phase >= hold.first) & (self.phase <= hold.last)
            if rows.any():
                out[h] = float(np.min(self.probability[rows, hold.boom]))
        return out

    def implied_p_path(self) -> float:
        """The climb's success probability implied by the simulated forces: the product of the
        holdings' smallest P_i times (1 - attach_failure) per regrasp."""
        if self.failure is not None and self.failure.cause == "handover":
            return 0.0  # the climb could not go on
        af = self.plan.scenario.robot.attach_failure
        return float(np.prod(self.holding_minimum()) * (1.0 - af) ** self.plan.regrasps)


class ClimbSimulator:
    """The diagram for one scenario, built once; `run` executes a plan on it.

    `plant="full"` (the default) simulates rb_drake's whole robot (`build_plant` with
    `hold_tips`, discrete, SAP, period `time_step`): every anchored tip is held at its anchor
    by a ball constraint, the tensions drive the prismatic joints (a C++ gain), the free
    limb follows the planned tip (`LimbController`), and `AnchorLoadMonitor` reads the grasps'
    loads from the simulated joint reaction forces. `plant="body"` is the body alone on a
    planar joint (continuous), each boom's tension applied at its shoulder (`BoomForces`,
    `GraspMonitor`).

    `run` resets the context (time 0, the plan and draws as parameters, the body at the plan's
    first pose at rest unless `initial_state` is given, loggers cleared) and advances phase by
    phase, so integration steps end on the phase boundaries where the stance switches; the
    full plant's holds and free-boom mass are switched there, between `AdvanceTo` calls (the
    mass also every BOOM_MASS_PERIOD within a reach phase). Measured on the demo plan (200 s
    of climb): 11-14 s wall for the full plant at 10 ms, 10-13 s for the body plant; 5 ms
    and 2 ms steps change the implied p_path by < 2e-4 (its first 8 phases) at 2x and 4.5x.
    """

    def __init__(self, scn: Scenario, gains: ControlGains | None = None,
                 sample_period: float = SAMPLE_PERIOD, plant: str = "full",
                 time_step: float = PLANT_TIME_STEP):
        if plant not in ("full", "body"):
            raise RbpInputError(f"must be 'full' or 'body', got {plant!r}", field="plant")
        robot, g = scn.robot, scn.gravity_vector
        gains = gains or ControlGains()
        self.scenario = scn
        self.sample_period = sample_period
        self.kind = plant
        builder = DiagramBuilder()
        w, h = robot.body_size
        izz = robot.body_mass * (w**2 + h**2) / 12.0
        self.source = builder.AddSystem(PlanSource())
        self.failures = builder.AddSystem(GraspFailures(sample_period))
        src = self.source
        connect = builder.Connect
        self.robot_plant: ReachBotPlant | None = None
        if plant == "full":
            # The plant's arm links (ARM_MASS each) ride on the shoulders, which the model's
            # robot has not: its body is lighter by their mass, so the whole weighs what the
            # model's robot weighs (and, shoulders symmetric about the centre, has its moment).
            # A plant 2 % heavier than the plan loads every grasp 2 % past its plan.
            light = dataclasses.replace(robot, body_mass=robot.body_mass - NUM_BOOMS * ARM_MASS)
            rb = build_plant(light, g, time_step, hold_tips=True, live_outputs=True,
                             joint_limits=False)
            self.robot_plant = rb
            self.plant = builder.AddSystem(rb.plant)
            # the arm links ride on the shoulders: the body carries them
            self.controller = builder.AddSystem(TensionController(
                light, g, np.array([robot.body_mass] * 2 + [
                    izz + ARM_MASS * float(np.sum(np.asarray(robot.shoulders) ** 2))]),
                gains, ARM_MASS, fixed_boom_mass=True, tip_push=True))
            limb = builder.AddSystem(LimbController(rb, robot, g, gains))
            # an attached boom's tension T is its prismatic joint's force -T
            booms = np.zeros((self.plant.num_velocities(), NUM_BOOMS))
            for i, joint in enumerate(rb.booms):
                booms[joint.velocity_start(), i] = -1.0
            tensions = builder.AddSystem(MatrixGain(booms))
            total = builder.AddSystem(Adder(2, self.plant.num_velocities()))
            self.monitor = builder.AddSystem(AnchorLoadMonitor(rb, robot, g))
            connect(src.GetOutputPort("free_limb"), self.monitor.GetInputPort("free_limb"))
            full_state = self.plant.get_state_output_port()
            body_selector = builder.AddSystem(_selector(
                self.plant, rb.base.position_start() + np.arange(3),
                rb.base.velocity_start() + np.arange(3)))
            joint_selector = builder.AddSystem(_selector(self.plant, rb.q_order[3:], []))
            body_selector.set_name("body_state")
            joint_selector.set_name("joints")
            for selector in (body_selector, joint_selector):
                connect(full_state, selector.get_input_port())
            body_state, joints = body_selector.get_output_port(), joint_selector.get_output_port()
            connect(full_state, limb.GetInputPort("state"))
            connect(src.GetOutputPort("free_limb"), limb.GetInputPort("free_limb"))
            connect(src.GetOutputPort("stance"), limb.GetInputPort("stance"))
            connect(limb.GetOutputPort("tip_push"), self.controller.GetInputPort("tip_push"))
            connect(self.controller.GetOutputPort("tension"), tensions.get_input_port())
            connect(tensions.get_output_port(), total.get_input_port(0))
            connect(limb.GetOutputPort("generalized_force"), total.get_input_port(1))
            connect(total.get_output_port(), self.plant.get_applied_generalized_force_input_port())
            connect(full_state, self.monitor.GetInputPort("state"))
            connect(self.plant.get_reaction_forces_output_port(),
                    self.monitor.GetInputPort("reaction_forces"))
            limb.set_name("limb")
            tensions.set_name("boom_forces")
            total.set_name("generalized_force")
        else:
            self.plant = builder.AddSystem(MultibodyPlant(0.0))
            body = self.plant.AddRigidBody("body", SpatialInertia.SolidBoxWithMass(
                robot.body_mass, w, h, BODY_THICKNESS))
            self.plant.AddJoint(PlanarJoint("base", self.plant.world_frame(),
                                            body.body_frame()))
            self.plant.mutable_gravity_field().set_gravity_vector([g[0], g[1], 0.0])
            self.plant.Finalize()
            self.controller = builder.AddSystem(TensionController(
                robot, g, np.array([robot.body_mass, robot.body_mass, izz]), gains))
            booms = builder.AddSystem(BoomForces(robot, g))
            self.monitor = builder.AddSystem(GraspMonitor(robot))
            body_state, joints = self.plant.get_state_output_port(), None
            connect(body_state, booms.GetInputPort("state"))
            connect(self.controller.GetOutputPort("tension"), booms.GetInputPort("tension"))
            connect(src.GetOutputPort("free_limb"), booms.GetInputPort("free_limb"))
            connect(src.GetOutputPort("stance"), booms.GetInputPort("stance"))
            connect(booms.GetOutputPort("generalized_force"),
                    self.plant.get_applied_generalized_force_input_port())
            connect(body_state, self.monitor.GetInputPort("state"))
            connect(self.controller.GetOutputPort("tension"),
                    self.monitor.GetInputPort("tension"))
            booms.set_name("booms")
        self.plant.set_name("plant")
        for name, system in (("plan", self.source), ("controller", self.controller),
                             ("monitor", self.monitor), ("failures", self.failures)):
            system.set_name(name)
        ctl = self.controller
        for port in ("desired_state", "desired_acceleration", "feedforward_tension", "free_limb",
                     "stance"):
            connect(src.GetOutputPort(port), ctl.GetInputPort(port))
        connect(body_state, ctl.GetInputPort("state"))
        connect(src.GetOutputPort("stance"), self.monitor.GetInputPort("stance"))
        connect(self.monitor.GetOutputPort("grasp"), self.failures.GetInputPort("grasp"))
        connect(src.GetOutputPort("phase"), self.failures.GetInputPort("phase"))
        logged = {"phase": src.GetOutputPort("phase"), "state": body_state,
                  "desired": src.GetOutputPort("desired_state"),
                  "tension": ctl.GetOutputPort("tension"),
                  "grasp": self.monitor.GetOutputPort("grasp")}
        if joints is not None:
            logged["joints"] = joints
        self.loggers = {name: LogVectorOutput(port, builder, sample_period)
                        for name, port in logged.items()}
        self.diagram = builder.Build()
        self.diagram.set_name("climb")
        self.simulator = Simulator(self.diagram)
        self.simulator.set_monitor(self._stop_on_failure)
        self.context = self.simulator.get_mutable_context()
        self._stop = True
        self._step = time_step if plant == "full" else 1e-3  # the last step before a release
        self._last_tension: np.ndarray | None = None
        self._handover: Failure | None = None

    def _stop_on_failure(self, root: Context) -> EventStatus:
        if self._stop and self.failures.failed(self.failures.GetMyContextFromRoot(root)):
            return EventStatus.ReachedTermination(self.failures, "grasp failure")
        return EventStatus.Succeeded()

    def run(self, plan: PlanTrajectory, draws: StrengthDraws | None = None,
            initial_state: np.ndarray | None = None,
            progress: Callable[[int, int, float], None] | None = None,
            stop_on_failure: bool = True) -> SimulationRecord:
        """Execute `plan`; with `draws`, grasps fail stochastically (the run stops at the first
        failure when `stop_on_failure`). `initial_state` is the body's (x, y, phi and rates;
        the plan's first pose at rest by default; the rest of the robot follows, `place`).
        `progress(phase, phases, t)` after each phase."""
        if plan.scenario.robot != self.scenario.robot or not np.array_equal(
                plan.scenario.gravity_vector, self.scenario.gravity_vector):
            raise RbpInputError("the plan's robot or gravity differs from the simulator's")
        ctx = self.context
        self.diagram.SetDefaultContext(ctx)
        ctx.SetTime(0.0)
        self.source.set_plan(self.source.GetMyMutableContextFromRoot(ctx), plan)
        self.failures.set_draws(self.failures.GetMyMutableContextFromRoot(ctx),
                                draws if draws is not None else StrengthDraws.none(plan))
        if initial_state is None:
            initial_state = np.concatenate([plan.pose.value(plan.phases[0].start).ravel(),
                                            np.zeros(3)])
        self.place(plan, plan.phases[0].start, initial_state)
        for logger in self.loggers.values():
            logger.FindMutableLog(ctx).Clear()
        self._stop = stop_on_failure
        self.simulator.Initialize()
        ends = [p.end for p in plan.phases]
        self._handover = None
        for k, end in enumerate(ends):
            if end > ctx.get_time():
                if k > 0 and not self._gripper_may_switch(plan, k, before=True):
                    break
                if k > 0 and self.robot_plant is not None:
                    self._enter_phase(plan, k)
                if k > 0 and not self._gripper_may_switch(plan, k, before=False):
                    break
                if not self._advance(plan, k, end):
                    break
            if progress is not None:
                progress(k + 1, len(ends), ctx.get_time())
        return self._record(plan)

    def _gripper_may_switch(self, plan: PlanTrajectory, k: int, before: bool) -> bool:
        """Whether the gripper that opens (phase k a reach) or closes (phase k-1 a reach) at
        phase k's start may do so: its boom's tension at most RELEASE_TENSION, the tension
        applied over the last plant step before an opening (`before`), the one commanded for
        the first step after a closing. Otherwise the gripper stays shut (open), the climb
        cannot go on, and the run stops with a `handover` failure."""
        phases = plan.phases
        opening = phases[k].stance.free_boom is not None
        closing = phases[k - 1].stance.free_boom is not None
        if before and opening:
            j, tension = phases[k].stance.free_boom, self._last_tension
        elif not before and closing:
            j = phases[k - 1].stance.free_boom
            ctl = self.controller.GetMyContextFromRoot(self.context)
            tension = self.controller.GetOutputPort("tension").Eval(ctl)
        else:
            return True
        assert j is not None  # opening or closing: phase k or k - 1 has a free boom
        if tension is None or tension[j] <= RELEASE_TENSION:
            return True
        t = self.context.get_time()
        anchor = (phases[k - 1] if opening else phases[k]).stance.ids[j] or ""
        self._handover = Failure(t, k - 1 if opening else k, int(j), anchor, "handover",
                                 float("nan"), float(tension[j]))
        return False

    def _advance(self, plan: PlanTrajectory, k: int, end: float) -> bool:
        """Advance to `end` (`_advance_to`), keeping, when a reach phase follows, the boom
        tensions of the last plant step before it (`_gripper_may_switch`)."""
        self._last_tension = None
        if k + 1 < len(plan.phases) and plan.phases[k + 1].stance.free_boom is not None:
            last = end - self._step
            if last > self.context.get_time() + 1e-9 and not self._advance_to(plan, k, last):
                return False
            ctl = self.controller.GetMyContextFromRoot(self.context)
            self._last_tension = self.controller.GetOutputPort("tension").Eval(ctl).copy()
        return self._advance_to(plan, k, end)

    def _advance_to(self, plan: PlanTrajectory, k: int, end: float) -> bool:
        """Advance to `end` (in phase k); False when a grasp failure stopped the run. With the
        full plant in a reach phase, in steps of BOOM_MASS_PERIOD, after each of which the
        free boom's mass follows its planned length; in a release or attach ramp in steps of
        RAMP_MASS_PERIOD, the ramped boom's mass following its share."""
        phase = plan.phases[k]
        free = self.robot_plant is not None and phase.stance.free_boom is not None
        ramps = phase.ramps if self.robot_plant is not None else ()
        while True:
            t = self.context.get_time()
            in_ramp = any(t0 - 1e-9 <= t < t1 - 1e-9 for t0, t1, _ in ramps)
            if free or in_ramp:
                self._set_free_boom_mass(plan, k, t)
            stop = end
            if free:
                stop = min(end, t + BOOM_MASS_PERIOD)
            elif in_ramp:
                stop = min(end, t + RAMP_MASS_PERIOD)
            elif ramps:  # to the next ramp's start
                stop = min([end, *(t0 for t0, _, _ in ramps if t0 > t + 1e-9)])
            try:
                status = self.simulator.AdvanceTo(stop)
            except RuntimeError as e:  # the plant's solver (SAP) did not converge
                first = (str(e).strip().splitlines() or [type(e).__name__])[0]
                first = re.split(r"(?<=[a-z0-9])\. (?=[A-Z])", first)[0].rstrip(". :")
                raise SimulationError(k, "reach" if phase.stance.free_boom is not None
                                      else "body", self.context.get_time(), first) from e
            if status.reason() == status.ReturnReason.kReachedTerminationCondition:
                return False
            if stop >= end:
                return True

    def _set_free_boom_mass(self, plan: PlanTrajectory, k: int, t: float,
                            context: Context | None = None) -> None:
        """The free boom's mass at its planned length at t, half at its tip and half at its
        shoulder (the weight and moments of the uniform boom of the model); others massless."""
        masses = np.zeros(NUM_BOOMS)
        limb = plan.carried_limb(min(max(t, plan.phases[k].start), plan.phases[k].end - 1e-9))
        if limb[5] >= 0:
            masses[int(limb[5])] = limb[4]
        assert self.robot_plant is not None  # called for the full plant only
        self.robot_plant.set_boom_masses(
            self.plant.GetMyMutableContextFromRoot(context or self.context), masses)

    def _enter_phase(self, plan: PlanTrajectory, k: int, t: float | None = None,
                     context: Context | None = None) -> None:
        """The full plant in phase k (at its start, or at t): each attached tip held at its
        anchor, the free boom's mass (if any) at its planned length."""
        phase = plan.phases[k]
        context = context or self.context
        assert self.robot_plant is not None  # called for the full plant only
        self.robot_plant.hold_tips(self.plant.GetMyMutableContextFromRoot(context), [
            p if a else None for a, p in zip(phase.stance.attached, phase.stance.positions,
                                             strict=True)])
        self._set_free_boom_mass(plan, k, phase.start if t is None else t, context)

    def place(self, plan: PlanTrajectory, t: float, body_state: np.ndarray,
              context: Context | None = None) -> None:
        """Put the robot in the plan's configuration at time t with the body's state (pose,
        rates): the full plant in the phase at t (its holds and free-boom mass), attached tips
        on their anchors and still, the free tip on its planned position at its planned rate.
        `context`: the diagram's (the simulator's by default)."""
        context = context or self.context
        body_state = np.asarray(body_state, dtype=float)
        plant_ctx = self.plant.GetMyMutableContextFromRoot(context)
        rb = self.robot_plant
        if rb is None:
            self.plant.SetPositionsAndVelocities(plant_ctx, body_state)
            return
        k = plan.phase_index(t)
        phase = plan.phases[k]
        self._enter_phase(plan, k, t, context)
        robot = self.scenario.robot
        targets = phase.stance.positions.copy()
        tip_rates = np.zeros((NUM_BOOMS, 2))
        j = phase.stance.free_boom
        if j is not None:
            assert phase.free_tip is not None and phase.free_tip_rate is not None  # a reach phase
            targets[j] = phase.free_tip.value(t).ravel()
            tip_rates[j] = phase.free_tip_rate.value(t).ravel()
        pose, rates = body_state[:3], body_state[3:6]
        geo = geometry.boom_geometry(robot, pose, targets)
        u = geo.u[0]
        offsets = geo.shoulders[0] - pose[:2]
        d_rate = tip_rates - rates[:2] - rates[2] * np.stack([-offsets[:, 1], offsets[:, 0]],
                                                             axis=1)  # tip's less shoulder's
        length_rate = np.sum(u * d_rate, axis=1)
        angle_rate = geometry.cross2(u, d_rate) / geo.length[0] - rates[2]
        q = self.plant.GetPositions(plant_ctx)  # keeps the anchor bodies where hold_tips put them
        q[rb.q_order] = rb.canonical_q(pose, geo.shoulder_angle[0], geo.length[0])
        v = np.zeros(self.plant.num_velocities())
        v[rb.q_order] = rb.canonical_q(rates, angle_rate, length_rate)  # v = qdot here
        self.plant.SetPositions(plant_ctx, q)
        self.plant.SetVelocities(plant_ctx, v)

    def _record(self, plan: PlanTrajectory) -> SimulationRecord:
        logs = {name: logger.FindLog(self.context) for name, logger in self.loggers.items()}
        times = logs["state"].sample_times().copy()
        data = {name: log.data().T.copy() for name, log in logs.items()}
        n = min(len(times), *(len(d) for d in data.values()))
        data = {name: d[:n] for name, d in data.items()}
        state = self.failures.state(self.failures.GetMyContextFromRoot(self.context))
        failure = self._handover
        if state[0] > 0:
            k, boom = int(state[2]), int(state[3])
            failure = Failure(float(state[1]), k, boom, plan.phases[k].stance.ids[boom] or "",
                              Cause(int(state[4])).label, float(state[5]), float(state[6]))
        grasp_log = data["grasp"]
        return SimulationRecord(plan, times[:n], np.rint(data["phase"][:, 0]).astype(int),
                                data["state"], data["desired"], data["tension"],
                                grasp_log[:, :NUM_BOOMS], grasp_log[:, NUM_BOOMS:2 * NUM_BOOMS],
                                grasp_log[:, 2 * NUM_BOOMS:], failure, data.get("joints"))


def _selector(plant: MultibodyPlant, rows_q: Sequence[int] | np.ndarray,
              rows_v: Sequence[int] | np.ndarray) -> MatrixGain:
    """A (C++) gain picking entries of the plant's state [q; v]: q[rows_q], then v[rows_v]."""
    nq = plant.num_positions()
    rows = [*map(int, rows_q), *(nq + int(r) for r in rows_v)]
    D = np.zeros((len(rows), nq + plant.num_velocities()))
    D[np.arange(len(rows)), rows] = 1.0
    return MatrixGain(D)
