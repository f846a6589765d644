"""Status codes returned by the compiled kernels and the exceptions raised at the edge.

Kernels never raise: they return one of the integer codes below together with the
step at which they stopped, and keep everything computed before it. The Python layer
turns a code into a :class:`Status` with a message; it raises only if the caller asks
(``raise_on_failure=True``) or when the input itself is wrong (:class:`InputError`);
:class:`OutputError` is a failure of the environment (disk full, read-only directory).
"""

from __future__ import annotations

from enum import IntEnum


class Status(IntEnum):
    """Outcome of a time march. The integer values are what the kernels return."""

    OK = 0
    NOT_CONVERGED = 1
    STATE_CYCLING = 2
    SINGULAR = 3
    CAPACITY = 4
    NON_FINITE = 5
    INTERRUPTED = 6
    DIVERGED = 7
    INVARIANT = 8
    EVENT_CAP = 9

    @property
    def message(self) -> str:
        return _MESSAGES[self]


_MESSAGES = {
    Status.OK: "completed",
    Status.NOT_CONVERGED: (
        "the Newton iteration did not converge within the iteration cap; reduce the step "
        "ratio (--step-ratio) or raise max_iterations"
    ),
    Status.STATE_CYCLING: (
        "the contact-state iteration cycled between incompatible states; raise state_tolerance or reduce the step"
    ),
    Status.SINGULAR: (
        "the effective stiffness of the contact state is singular: no equilibrium exists "
        "(all contacts lifted off, or a mechanism). For the quasi-static method this means "
        "the case needs inertia: use a dynamic method"
    ),
    Status.CAPACITY: "the output buffer filled before the end time (adaptive step too small)",
    Status.NON_FINITE: "the solution became non-finite (NaN or inf)",
    Status.INTERRUPTED: "interrupted by the user (Ctrl-C); the steps done before it are kept",
    Status.DIVERGED: (
        "the response grew without an energy source (numerical instability): the step exceeds "
        "the scheme's stability limit; reduce the step ratio or use an unconditionally stable scheme"
    ),
    Status.INVARIANT: (
        "the march completed but its outputs break a contact invariant (named below: finite values, every row "
        "written, N >= 0, |T| <= mu N, slip along T): a solver defect, not a property of the case; the rows "
        "from the step named on cannot be trusted. Tighten state_tolerance or use method full-newton, and "
        "report the case"
    ),
    Status.EVENT_CAP: (
        "the exact event-driven march stopped at its cap of contact-state changes (chattering or an "
        "accumulation of events, named below with its time and contact); raise max_events or use a "
        "time-stepping method (piecewise-linear)"
    ),
}


class InputError(ValueError):
    """Bad user input: names the field, what is wrong, and how to fix it."""

    def __init__(self, field: str, problem: str, fix: str):
        self.field = field
        self.problem = problem
        self.fix = fix
        super().__init__(f"{field}: {problem}. Fix: {fix}")


class OutputError(RuntimeError):
    """A file could not be written or read for a reason outside the input itself: a full
    disk, a read-only directory, no permission, not enough memory (exit code 3 on the
    command line). Names the path, what happened, and what to do."""

    def __init__(self, path, problem: str, fix: str):
        self.path = str(path)
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.path}: {problem}. Fix: {fix}")


class SolverError(RuntimeError):
    """A march that stopped early, raised only on request; carries the partial result."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a march: the kernel stopped at a step boundary. A KeyboardInterrupt (a loop
    of runs stops), carrying the partial result Dataset (status INTERRUPTED) in ``result``."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result
