"""The footstep searches' clock for their time limits: wall time less numba's compiling.

With a cold cache (a fresh install, an edited kernel, another NUMBA_CACHE_DIR) the kernels
compile, about 20 s, inside the first search that calls them. Counted against the search's
time limit, `rbp plan demo-shaft --footsteps-only --time-limit 5` gave up after one expansion
(and took 25 s) where a warm run found its route in 1 s: the same cave and options answered
otherwise on a first run. The limit is on searching; compiling is not searching, and cannot be
interrupted anyway. Times reported (a plan's `timing`, a search's `seconds`) stay wall time.
(Not in `rb_drake.kernel`: the kernels' cache entries are stamped with every module there.)
"""

from __future__ import annotations

import time

from numba.core import event

# numba's compile events nest (a kernel compiles the kernels it calls): the listener times the
# outermost only. Registered at import, before any search this module's users start.
_COMPILING = event.TimingListener()
event.register("numba:compile", _COMPILING)


def compile_seconds() -> float:
    """Seconds numba has spent compiling (or loading from its cache) since this import."""
    return _COMPILING.duration if _COMPILING.done else 0.0


def search_clock() -> float:
    """`time.perf_counter()` less `compile_seconds()`: the difference of two readings is the
    time spent searching between them, the kernels' compiling left out."""
    return time.perf_counter() - compile_seconds()
