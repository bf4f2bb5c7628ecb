"""Seed trajectories for the two continuous phases of a plan (paper sections IV-B and IV-C).

Body phase (a 4-stance; the body moves from one transition pose to the next): a discretised
sequence of poses, each statically feasible by `check_poses` (kinematic limits, collisions,
statics, P >= p_min). Three methods, cheapest first: the straight line (one vectorised check);
local sampling of smooth detours around it (a few vectorised rounds of growing spread, as the
paper samples locally around the straight line); OMPL's RRTConnect in SE(2) when the
neighbourhood of the line is blocked, followed by a vectorised shortcut and re-check.

Reach phase (a 3-stance; the free gripper moves from its old anchor to the new one): the tip
follows a collision-free parabolic arc (the lowest of a few heights that clears the rock). The
body holds the transition pose when that is feasible with the cantilevered limb at every tip
position; otherwise it sways: body offsets sampled around the transition pose are checked at
every tip position at once, and a shortest-path search picks the least motion that keeps every
configuration feasible and starts and ends at the transition pose.

Every returned seed has been checked configuration by configuration, starts and ends exactly at
the requested configurations and moves at most `step` (m; the tip too) and `turn_step` (rad)
between successive configurations. Poses are not wrapped: phi runs continuously from the start's
value to the goal's. Randomness comes from `seed` alone (numpy's generator and OMPL's RNG).

The code is split by phase kind: `planning.body_seeds` (the body phase), `planning.reach_seeds`
(the reach phase) and what they share, `planning.seed_common`; this module is the seeds' one
entry point, as the pipeline uses them.
"""

from __future__ import annotations

from planning.body_seeds import body_seed
from planning.reach_seeds import RETRACT_RADII, reach_seed, retract_path, tip_arc
from planning.seed_common import Seed, SeedConfig, subdivide

__all__ = ["RETRACT_RADII", "Seed", "SeedConfig", "body_seed", "reach_seed", "retract_path",
           "subdivide", "tip_arc"]
