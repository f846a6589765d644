"""Indices of the kernels' counters array and their status codes (mirrors slipstep.errors.Status)."""

# counters
# C_PROGRESS: steps done so far, updated by the kernel every step (read live by the progress bar);
# C_STOP: set to 1 by another thread to stop the march at the next step (status INTERRUPTED).
C_STEPS, C_SOLVES, C_FACTORISATIONS, C_LAW_CALLS, C_REDOS, C_FALLBACKS, C_STATE_CHANGES, C_FAIL_STEP, C_N_VISITED, \
    C_PROGRESS, C_STOP = range(11)
N_COUNTERS = 11
# status
OK, NOT_CONVERGED, STATE_CYCLING, SINGULAR, CAPACITY, NON_FINITE, INTERRUPTED, DIVERGED = 0, 1, 2, 3, 4, 5, 6, 7
# step solvers of kernels.march (here so that the method registry needs no numba import)
MODIFIED_NEWTON, FULL_NEWTON, PIECEWISE_LINEAR = 0, 1, 2
