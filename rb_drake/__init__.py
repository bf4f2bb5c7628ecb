"""The robot, its grasps, statics and scenarios (the lowest layer; docs/architecture.md)."""

import os as _os

# numba's OpenMP threading layer lets idle worker threads spin for a while after each parallel
# region; when another process holds a core, the spinning thread takes CPU from the one doing
# the work, and a footstep search ran 2-7x slower than on one thread (issue 32). Passive waiting
# sleeps instead. OpenMP reads the variable when it starts, so it is set before numba is
# imported anywhere; a value the user set is kept.
_os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
