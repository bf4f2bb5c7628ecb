"""Settings read from the environment, checked: a malformed value is one clear error naming
the variable, never a traceback from deep inside a search. Light to import (the command line
checks them before any work)."""

from __future__ import annotations

import os

from rb_drake.errors import RbpInputError

MAX_THREADS = 4096


def threads_setting() -> int | None:
    """RBP_THREADS as a whole number of threads from 1 to MAX_THREADS (None: not set)."""
    value = os.environ.get("RBP_THREADS", "").strip()
    if not value:
        return None
    try:
        threads = int(value)
    except ValueError:
        threads = 0
    if not 1 <= threads <= MAX_THREADS:
        raise RbpInputError(f"must be a whole number of threads from 1 to {MAX_THREADS}, "
                            f"got {value!r}", field="RBP_THREADS (environment)")
    return threads


def threads_adapt_setting() -> bool:
    """RBP_THREADS_ADAPT: whether the kernels drop to the cores other processes leave free
    (`rb_drake.kernel.free_cores`; "1", the default) or always use every allowed thread ("0":
    for measuring a fixed thread count)."""
    value = os.environ.get("RBP_THREADS_ADAPT", "").strip()
    if value not in ("", "0", "1"):
        raise RbpInputError(f"must be 0 or 1, got {value!r}", field="RBP_THREADS_ADAPT "
                            "(environment)")
    return value != "0"
