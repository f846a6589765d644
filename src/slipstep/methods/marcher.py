"""The march itself (docs/architecture.md, "Marcher and Segment"): a :class:`Marcher` owns
the workspace, the output rows and the compiled kernel entry of one plan, and has one verb,

    segment = marcher.advance(state, t_end)     # march from state (at state.t) to t_end

which returns a :class:`Segment`: the status, the end state, a read-only view of the rows
written (valid until the next advance), a copy of the counters and the kernel time. A marcher
is reused across the marches of one layout (the periods of a steady-state search, the Newton
iterations of shooting, the points of an FRF: :meth:`Marcher.retarget`): no allocation and no
type dispatch per march.

The kernel: the one its method names (registry.Method.kernel: the event-driven march of
kernels/events.py, the quasi-static march of Method 4 of kernels/quasi_static.py or the implicit
march of kernels/march.py), a function of the structure backend giving the numba kernel
``kernel(args, st)`` on the packed arguments (kernels/arguments.py: the arrays unboxed once).
"""

from __future__ import annotations

import pkgutil
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from slipstep.errors import Status
from slipstep.kernels import march as K
from slipstep.kernels.arguments import KernelArguments, pack_arguments
from slipstep.kernels.events import event_arguments
from slipstep.methods.live import call_kernel
from slipstep.methods import compile_ahead
from slipstep.methods import save as SV
from slipstep.methods.buffers import allocate_outputs, allocate_workspace, reset_cache, reset_outputs, saved_rows
from slipstep.methods.divergence import check_divergence
from slipstep.methods.plan import RunPlan
from slipstep.methods.registry import Method
from slipstep.methods.start import consistent_start
from slipstep.methods.state import State
from slipstep.model.system import to_user_order


def march_kernel(method: Method):
    """The kernel entry that marches ``method`` after the preload (Method.kernel, loaded): a
    function of the structure backend (kernels.structure_ops codes) giving the numba kernel
    ``kernel(args, st)`` (e.g. kernels.march.implicit_kernel). ValueError for a method with a
    runner of its own (Method.kernel None: ``events``)."""
    if method.kernel is None:
        raise ValueError(f"method {method.name!r} has no march kernel (a runner of its own)")
    return pkgutil.resolve_name(method.kernel)


class Trace(NamedTuple):
    """Read-only views of the output rows a march wrote (kernels.march.Outputs: the saved
    rows, in the user's DOF order as saved; methods/save.py), and its step count."""

    t: np.ndarray
    dt: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    q: np.ndarray
    f: np.ndarray
    w: np.ndarray
    state: np.ndarray
    solves: np.ndarray
    step: np.ndarray
    n_steps: int


@dataclass(frozen=True)
class Segment:
    """The result of one :meth:`Marcher.advance`: status (errors.Status), end_state (State at
    the last step done), trace (:class:`Trace`, valid until the next advance), counters (a copy
    of the kernel counters, kernels/codes.py C_*), kernel_time_s [s]."""

    status: Status
    end_state: State
    trace: Trace
    counters: np.ndarray
    kernel_time_s: float


class KernelEntry:
    """One runner's call of a march kernel: the packed arguments (kernels/arguments.py, built
    when first seen and again only when the runner replaces one of its arrays) and the compiled
    overload of the kernel (after the first call: no type dispatch). ``packed`` False: the
    kernel takes the argument tuple itself (the condensed sparse march)."""

    def __init__(self, packed: bool = True):
        self.packed_call = packed
        self.packed = None  # (sys, ws, out, q0, f0, their KernelArguments)
        self.kernel = None  # (dispatcher, compiled entry, layout)

    def packed_arguments(self, args: tuple) -> tuple:
        """(KernelArguments, settings) of the kernel arguments (sys, settings, ws, out, q0, f0)."""
        sys, settings, ws, out, q0, f0 = args
        held = (sys, ws, out, q0, f0)
        if self.packed is None or any(a is not b for a, b in zip(self.packed, held)):
            self.packed = (*held, pack_arguments(*held))
        return self.packed[-1], settings

    def call(self, dispatcher, args: tuple, out: K.Outputs, times: np.ndarray, t_end: float, progress: bool):
        """Reset the outputs, call the numba kernel ``dispatcher`` on ``args`` (sys, settings, ws,
        out, q0, f0), packed unless the entry is not (live.call_kernel: interruptible, with a
        progress bar when asked); (Status, kernel time [s])."""
        out.counters[:] = 0
        reset_outputs(out)
        if self.packed_call:
            args = self.packed_arguments(args)
        layout = args[0]._type if self.packed_call else None  # a new KernelArguments may hold other layouts
        known = self.kernel is not None and self.kernel[0] is dispatcher and self.kernel[2] == layout
        kernel = self.kernel[1] if known else dispatcher
        cap = int(out.plan[K.S_CAPACITY])
        status, kernel_time = call_kernel(kernel, args, out.counters, times, t_end, cap + 1, progress)
        if not known:
            self.kernel = (dispatcher, compiled_entry(dispatcher, args), layout)
        return Status(status), kernel_time


#: backend name -> the class path of the Marcher subclass that marches it (loaded when a plan of
#: that backend is marched; the subclass stands on this module)
BACKEND_MARCHERS: dict[str, str] = {"sparse": "slipstep.methods.sparse_marcher.SparseMarcher"}


def backend_marcher(backend: str) -> type | None:
    """The Marcher subclass of ``backend`` (BACKEND_MARCHERS), None for the base class's own."""
    path = BACKEND_MARCHERS.get(backend)
    if path is None:
        return None
    import importlib

    module, name = path.rsplit(".", 1)
    return getattr(importlib.import_module(module), name)


class Marcher:
    """The buffers and the kernel of one :class:`RunPlan` (module docstring).

    ws: the kernel workspace (kernel DOF order); out: the output rows; settings: the kernel
    settings of the next march (its t_start and t_end set by :meth:`advance`); kernel: the
    kernel entry of the plan's method (:func:`march_kernel`); q0, f0: the
    first point's contact displacements and forces; progress: draw a progress bar on stderr
    for marches longer than a second (the CLI sets it)."""

    progress = False
    #: keep the factorisations J(S) from one march to the next of the same plan (its matrices, step
    #: and scheme, so the same J(S)): the periods of a shooting Newton revisit one state sequence.
    #: Off by default, so that every run (and every timed repeat) pays for its own.
    keep_factorisations = False

    def __new__(cls, plan: RunPlan | None = None):
        """A plan on a backend with a marcher of its own (BACKEND_MARCHERS: the condensed sparse
        backend's, methods/sparse_marcher.py) gets that one."""
        own = backend_marcher(plan.backend) if cls is Marcher and plan is not None else None
        return super().__new__(own or cls)

    def __init__(self, plan: RunPlan):
        cs = plan.compiled
        self.plan = plan
        self.ws = allocate_workspace(cs, plan.options.max_state_iterations, plan.low_rank)
        self.out = allocate_outputs(cs, plan.capacity, plan.options.max_memory, plan.save_plan, plan.t_end)
        nq = cs.A.shape[0]
        self.q0, self.f0 = np.zeros(nq), np.zeros(nq)
        self.settings = plan.settings
        self.kernel = march_kernel(plan.method)
        self.entry = KernelEntry()
        self._event_arguments = None  # (compiled, ws, the event kernel's slim tuples of them)
        self._factorised_for = None  # the plan whose J(S) the workspace's cache holds (keep_factorisations)

    # -- marching -------------------------------------------------------------------------
    def advance(self, state: State, t_end: float | None = None, kernel=None) -> Segment:
        """March from ``state`` (at state.t) to ``t_end`` [s] (default state.t + plan.t_end).
        ``kernel``: another kernel entry of the same arguments (tests/test_quasi_static.py)."""
        plan = self.plan
        t_end = state.t + plan.t_end if t_end is None else t_end
        self.load(state)
        st = self.settings
        if st.t_start != state.t or st.t_end != t_end:
            st = self.settings = K.replace_settings(st, t_start=state.t, t_end=t_end)
        self.out.times[K.S_FROM] = state.t + plan.save_plan.t_from  # the last periods of this march
        dispatcher, arguments = (self.kernel if kernel is None else kernel)(st.structure), self.kernel_arguments()
        if kernel is None:
            compile_ahead.start(plan.method.kernel, dispatcher, arguments)
        status, kernel_time = self.entry.call(
            dispatcher, arguments, self.out, self._progress_times(t_end), t_end, self.progress
        )
        compile_ahead.stop()  # the kernel is compiled now
        if not plan.method.quasi_static:
            status = check_divergence(status, plan.compiled, self.out, plan.save_plan)
        n_steps = int(self.out.counters[K.C_STEPS])
        rows = saved_rows(self.out, n_steps)
        t = float(t_end) if status == Status.OK else float(self.out.t[rows - 1])
        return Segment(status, self.end_state(t), self.trace(rows, n_steps), self.out.counters.copy(), kernel_time)

    def load(self, state: State) -> None:
        """Write ``state`` into the workspace (kernel DOF order) and q0, f0; a state without
        its force terms is completed first (start.consistent_start)."""
        if state.terms is None:
            state = consistent_start(self.plan, state.x, state.v, state.w, state.contact_state, state.t, state.a)
        cs, ws, terms = self.plan.compiled, self.ws, state.terms
        order = np.asarray(cs.dof_order) if cs.banded else slice(None)
        for dst, src in zip((ws.x, ws.v, ws.a, ws.fe, ws.gf), (state.x, state.v, state.a, terms.fe, terms.gf)):
            dst[:] = src[order]
        ws.w[:] = state.w
        ws.state[:] = state.contact_state
        self.q0[:], self.f0[:] = terms.q, terms.f
        if self.keep_factorisations and self._factorised_for is self.plan:
            ws.lin_dt[0] = np.nan  # Lin is built again at the first step; the cached J(S) stay valid
        else:
            reset_cache(ws)
            self._factorised_for = self.plan

    def end_state(self, t: float) -> State:
        """A copy of the workspace's state at time t (user DOF order; quasi-static: v = a = 0)."""
        cs, ws = self.plan.compiled, self.ws
        user = lambda values: to_user_order(cs, values).copy()  # noqa: E731
        n = ws.x.shape[0]
        if self.plan.method.quasi_static:
            return State(t, user(ws.x), np.zeros(n), np.zeros(n), ws.w.copy(), ws.state.copy())
        return State(t, user(ws.x), user(ws.v), user(ws.a), ws.w.copy(), ws.state.copy())

    def trace(self, rows: int, n_steps: int) -> Trace:
        """Read-only views of the first ``rows`` output rows."""
        out = self.out
        views = []
        for name in Trace._fields[:-1]:
            view = getattr(out, name)[:rows]
            view.flags.writeable = False
            views.append(view)
        return Trace(*views, n_steps)

    def kernel_arguments(self) -> tuple:
        """The march kernel's arguments (sys, settings, ws, out, q0, f0); the event-driven kernel
        takes the slim system and workspace tuples of kernels.events.event_arguments (fewer
        arrays to unbox or pass per call)."""
        cs = self.plan.compiled
        if self.plan.method.solver != K.EVENTS:
            return (cs, self.settings, self.ws, self.out, self.q0, self.f0)
        built = self._event_arguments  # built once per (compiled, ws)
        if built is None or built[0] is not cs or built[1] is not self.ws:
            built = self._event_arguments = (cs, self.ws, event_arguments(cs, self.ws))
        sys, ws = built[2]
        return (sys, self.settings, ws, self.out, self.q0, self.f0)

    def _progress_times(self, t_end: float) -> np.ndarray:
        """The time of step k for the progress bar: row k of out.t, or k dt when rows are not steps."""
        plan, out = self.plan, self.out
        if plan.save_plan.every_step or not self.progress:
            return out.t
        cap = int(out.plan[K.S_CAPACITY])
        return self.settings.t_start + np.minimum(np.arange(cap + 1) * plan.dt, t_end)

    # -- another plan of the same layout --------------------------------------------------
    def retarget(self, plan: RunPlan) -> None:
        """March ``plan`` from now on (a new frequency, a new step): the workspace and the
        compiled entry are kept; the output rows too when they hold plan's save plan and
        capacity (else they are allocated again). Raises ValueError for another layout."""
        old, cs = self.plan, plan.compiled
        if not same_layout(old, plan):
            raise ValueError("retarget: the plan has another array layout (build a new Marcher)")
        dofs, rows, dirs, ip, times = SV.kernel_arrays(plan.save_plan, cs, plan.capacity)
        needed = SV.rows_needed(plan.save_plan, plan.capacity, 0.0, plan.t_end)
        out = self.out
        fits = (
            needed <= out.t.shape[0]
            and np.array_equal(dofs, out.dofs)
            and np.array_equal(rows, out.rows)
            and np.array_equal(dirs, out.dirs)
            and times.shape == out.times.shape
        )
        if fits:
            out.plan[:], out.times[:] = ip, times
        else:
            self.out = allocate_outputs(cs, plan.capacity, plan.options.max_memory, plan.save_plan, plan.t_end)
        if plan.compiled.M is not old.compiled.M or plan.compiled.K is not old.compiled.K:
            self.ws.tmin_used[:] = False  # T_min per state belongs to the matrices (a retune keeps them)
        self.plan, self.settings, self.kernel = plan, plan.settings, march_kernel(plan.method)


def same_layout(a: RunPlan, b: RunPlan) -> bool:
    """Do two plans march arrays of the same shapes (the same workspace fits both)?"""
    return (
        _shapes(a.compiled) == _shapes(b.compiled)
        and a.low_rank == b.low_rank
        and a.options.max_state_iterations == b.options.max_state_iterations
    )


def _shapes(cs) -> tuple:
    """The array shapes of a compiled system that the workspace and the kernel types depend on."""
    return (
        cs.M.shape,
        cs.A.shape,
        cs.kt.shape,
        cs.B.shape,
        cs.force_frequency.shape,
        cs.motion_frequency.shape,
        bool(cs.banded),
        int(cs.kl),
        int(cs.ku),
    )


def compiled_entry(dispatcher, args):
    """The compiled overload of a numba dispatcher for these argument types, callable without
    the per-call type dispatch (about 6 us for our tuples of arrays); the dispatcher itself
    if no such overload is found. numba.typeof of our nested tuples costs about 1.7 ms, so the
    overload is cached by :func:`_layout_key`, the part of the arguments their numba types
    depend on (a sweep's cases and the accuracy rule's pilot runs share one look-up)."""
    key = (dispatcher, _layout_key(args))
    entry = _ENTRY_CACHE.get(key)
    if entry is None:
        signature = tuple(numba.typeof(a) for a in args)
        overload = dispatcher.overloads.get(signature)
        if overload is None:
            return dispatcher
        entry = _ENTRY_CACHE[key] = overload.entry_point
    return entry


_ENTRY_CACHE: dict = {}


def _layout_key(value):
    """What the numba type of an argument is made of: per array its dtype, rank, layout and
    flags; per tuple its class and items; per scalar its Python type."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        return (value.dtype.str, value.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable, flags.aligned)
    if isinstance(value, tuple):
        return (type(value), tuple(_layout_key(item) for item in value))
    if isinstance(value, KernelArguments):
        return value._type  # its numba type: the layout of every array it holds
    return type(value)
