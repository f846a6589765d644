"""Indices of the kernels' counters array and their status codes (mirrors slipstep.errors.Status)."""

# counters
C_STEPS, C_SOLVES, C_FACTORISATIONS, C_LAW_CALLS, C_REDOS, C_FALLBACKS, C_STATE_CHANGES, C_FAIL_STEP, C_N_VISITED = range(9)
N_COUNTERS = 9
# status
OK, NOT_CONVERGED, STATE_CYCLING, SINGULAR, CAPACITY, NON_FINITE, INTERRUPTED, DIVERGED = 0, 1, 2, 3, 4, 5, 6, 7
