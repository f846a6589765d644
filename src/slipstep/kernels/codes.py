"""The integer codes every kernel shares, defined here once: counters, status codes
(mirrored by slipstep.errors.Status), contact-state codes (named by STATE_NAMES, used by
results, post, advise and plots), step-solver codes (named by SOLVER_NAMES) and contact-law codes with the columns of their
parameter table (CompiledSystem.law, CompiledSystem.law_par)."""

# counters
# C_PROGRESS: steps done so far, updated by the kernel every step (read live by the progress bar);
# C_STOP: set to 1 by another thread to stop the march at the next step (status INTERRUPTED).
C_STEPS, C_SOLVES, C_FACTORISATIONS, C_LAW_CALLS, C_REDOS, C_FALLBACKS, C_STATE_CHANGES, C_FAIL_STEP, C_N_VISITED, \
    C_PROGRESS, C_STOP = range(11)
N_COUNTERS = 11
# status
OK, NOT_CONVERGED, STATE_CYCLING, SINGULAR, CAPACITY, NON_FINITE, INTERRUPTED, DIVERGED = 0, 1, 2, 3, 4, 5, 6, 7
# set by the Python layer, never by a kernel: an OK march whose outputs break a contact invariant (slipstep.invariants)
INVARIANT = 8
# the exact event-driven march (methods/exact_events.py) stopped at its cap of events (chattering, accumulation)
EVENT_CAP = 9

# contact states, one per tangential direction (a contact's directions share LIFT, STICK
# of a coupled law and SLIP_COUPLED)
LIFT = 0  # v <= 0: T = N = 0
STICK = 1  # the tangential spring holds: T = k_t (u - w)
SLIP_POS = 2  # uncoupled slip, T = +mu N (piecewise linear)
SLIP_NEG = 3  # uncoupled slip, T = -mu N (piecewise linear)
SLIP_COUPLED = 4  # coupled slip on the friction circle, |T| = mu N, direction of the trial force (not linear)
STATE_NAMES = ("lift-off", "stick", "slip+", "slip-", "slip-circle")
SLIP_STATES = (SLIP_POS, SLIP_NEG, SLIP_COUPLED)

# contact laws (kernels/laws/)
LAW_UNCOUPLED = 0  # paper: one independent spring-slider per tangential direction, |T_i| <= mu N
LAW_CIRCLE = 1  # coupled 3D: one slider in the tangent plane, |T| <= mu N (Euclidean norm)
# columns of the law parameter table (nc, N_LAW_PAR); k_t is per direction (CompiledSystem.kt)
P_KN, P_MU = 0, 1
N_LAW_PAR = 2

# step solvers of kernels.march (here so that the method registry needs no numba import), named by
# SOLVER_NAMES[code] (the result attr ``solver``, the methods page); EVENTS is not a step solver: the
# event-driven quasi-static march of kernels/events.py; EXACT_EVENTS neither: the exact event-driven
# dynamic march (methods/exact_events.py, kernels/exact_events.py)
MODIFIED_NEWTON, FULL_NEWTON, PIECEWISE_LINEAR, MODIFIED_NEWTON_STATE, EVENTS, EXACT_EVENTS = 0, 1, 2, 3, 4, 5
SOLVER_NAMES = ("modified-newton", "full-newton", "piecewise-linear", "modified-newton-state", "events", "exact-events")
