"""Compiled pose feasibility: `feasibility.check_poses(..., full=True)` and `violation` in numba.

The transition and footstep searches score thousands of small batches of poses; in numpy each
batch costs a few milliseconds of per-call overhead (dozens of small array operations), whatever
its size. The kernel runs the same tests in the same order, with the same constants and
algorithms, one pose at a time in compiled code. `rb_drake.feasibility` stays the reference, and
is used everywhere else. The modules, lowest first:

- `special`: erfcx, log_ndtr, the Mills ratio (numba has no scipy.special);
- `algebra3`: 3x3 determinants and solves, the conditioning's smallest singular value;
- `layout`: the packed parameter array (`Param`), the body cache states, the packing of a robot
  and a rock into the arrays the kernels read;
- `collision`: segments and the body square against the rock's edges;
- `allocation`: the most robust tensions of a 4-stance, a free limb's load, a release's r;
- `pose_kernel`: the compiled loop that scores rows (`score_kernel`);
- `threads`: the thread count and the rows shared over threads;
- `scoring`: the Python entry points, `score_poses` and `score_rows`.
- `cache_stamp`: numba's on-disk cache entries of all of them, stamped with every kernel source.

The lattice search's compiled flood fill and moves, which call these, live beside the lattice
they serve (`planning.flood_kernel`, `planning.lattice_kernels`).

Where the numpy path calls LAPACK (determinants, 3x3 solves, the SVD of the conditioning) the
kernel uses cofactor determinants, Gaussian elimination with partial pivoting and a one-sided
Jacobi SVD; it has its own `log_ndtr` and `erfcx`, and its allocation stops the safeguarded
Newton steps once they move by less than NEWTON_EXIT, where `statics.allocate`'s remaining steps
move by rounding errors. Results differ in the last bits only: on 310,000 poses of
tests/test_feasibility_kernel.py's cases no feasibility or reason differed, and every value
agreed to 4e-11 relative (tensions 2e-11, robustness 2e-12), so a decision can flip only for a
pose within about that of a threshold.

numba's on-disk cache (`cache=True`) keys a compiled function by its own file, while its cached
code holds copies of the compiled functions it calls, from whatever module, and the values of
the globals it reads: `cache_stamp` stamps the kernels' entries with every kernel source
instead, so that none can go stale. The constants that decide (limits, MIN_CONDITIONING,
REGULARISATION, ...) reach the kernels as data (`layout.robot_params`), not as globals.
"""

from rb_drake.kernel import cache_stamp

cache_stamp.install()  # before any kernel module defines its compiled functions
