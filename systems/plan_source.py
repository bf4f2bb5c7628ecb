"""`PlanSource`, the leaf system that outputs a plan (`systems.trajectory.PlanTrajectory`) at
the current time."""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, Context, LeafSystem

from rb_drake.params import NUM_BOOMS
from systems.trajectory import FREE_LIMB_SIZE, PhaseTrajectory, PlanTrajectory

_PLAN_PLACEHOLDER = AbstractValue.Make(None)


class PlanSource(LeafSystem):
    """The plan at the current time: desired state (pose, velocity) and acceleration,
    feed-forward tensions, free limb (FREE_LIMB_FIELDS), phase index and stance. The plan is an
    abstract parameter (`set_plan`)."""

    def __init__(self):
        super().__init__()
        self._plan_index = self.DeclareAbstractParameter(_PLAN_PLACEHOLDER)
        self.DeclareVectorOutputPort("desired_state", 6, self._calc_desired)
        self.DeclareVectorOutputPort("desired_acceleration", 3, self._calc_acceleration)
        self.DeclareVectorOutputPort("feedforward_tension", NUM_BOOMS, self._calc_tension)
        self.DeclareVectorOutputPort("free_limb", FREE_LIMB_SIZE, self._calc_free_limb)
        self.DeclareVectorOutputPort("phase", 1, self._calc_phase)
        self.DeclareAbstractOutputPort("stance", lambda: AbstractValue.Make(None),
                                       self._calc_stance)

    def set_plan(self, context: Context, plan: PlanTrajectory) -> None:
        context.get_mutable_abstract_parameter(self._plan_index).set_value(plan)

    def plan(self, context: Context) -> PlanTrajectory:
        return context.get_abstract_parameter(self._plan_index).get_value()

    def _phase(self, context: Context) -> PhaseTrajectory:
        return self.plan(context).phase_at(context.get_time())

    def _calc_desired(self, context: Context, output: BasicVector) -> None:
        plan, t = self.plan(context), context.get_time()
        output.SetFromVector(np.concatenate([plan.pose.value(t).ravel(),
                                             plan.velocity.value(t).ravel()]))

    def _calc_acceleration(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.plan(context).acceleration.value(context.get_time()).ravel())

    def _calc_tension(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self._phase(context).tension.value(context.get_time()).ravel())

    def _calc_free_limb(self, context: Context, output: BasicVector) -> None:
        output.SetFromVector(self.plan(context).carried_limb(context.get_time()))

    def _calc_phase(self, context: Context, output: BasicVector) -> None:
        output.SetAtIndex(0, self.plan(context).phase_index(context.get_time()))

    def _calc_stance(self, context: Context, output: AbstractValue) -> None:
        output.set_value(self._phase(context).stance)
