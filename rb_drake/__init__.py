"""The robot, its grasps, statics and scenarios (the lowest layer; docs/architecture.md)."""

import os as _os

# numba's OpenMP threads spin for a few milliseconds after each parallel region (libgomp's
# default), which makes a second thread pay on an idle machine, and takes the CPU from the
# working thread when another process holds a core. Where the machine's CPU counters can be
# read, the kernels drop to the cores other processes leave free (rb_drake.kernel.free_cores),
# so the spinning is kept; elsewhere the threads wait passively (issue 32). OpenMP reads the
# variable when it starts, so it is set before numba is imported anywhere; a value the user
# set is kept.
if not _os.path.exists("/proc/stat"):
    _os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
