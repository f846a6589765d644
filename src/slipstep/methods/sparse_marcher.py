"""The :class:`slipstep.methods.marcher.Marcher` of a plan on the condensed sparse backend
(methods/sparse.py, kernels/sparse.py): ``Marcher(plan)`` returns one for such a plan. The
verb and its results are the Marcher's; what differs is the workspace (a SparseWorkspace
holding the factorisations of the nominal step and of a shorter last step, prepared before
each march) and the kernel (kernels.sparse.sparse_march: :func:`sparse_kernel`). The state cache of the condensed
factorisations is kept across marches of one factorisation (its entries depend on the
contact state and the step size alone)."""

from __future__ import annotations

import numpy as np

from slipstep.kernels import sparse as KS
from slipstep.methods import sparse as SB
from slipstep.methods.buffers import allocate_outputs
from slipstep.methods.marcher import KernelEntry, Marcher, Segment, same_layout
from slipstep.methods.plan import RunPlan
from slipstep.methods.start import consistent_start
from slipstep.methods.state import State


class SparseMarcher(Marcher):
    """A Marcher on the sparse backend (module docstring)."""

    def __init__(self, plan: RunPlan):
        cs = plan.compiled
        self.plan = plan
        self.ws = SB.allocate_workspace(plan, SB.factor_of(cs, plan.settings, KS.nominal_step(plan.settings), True))
        self.out = allocate_outputs(cs, plan.capacity, plan.options.max_memory, plan.save_plan, plan.t_end)
        nq = cs.A.shape[0]
        self.q0, self.f0 = np.zeros(nq), np.zeros(nq)
        self.settings = plan.settings
        self.kernel = sparse_kernel
        self.entry = KernelEntry(packed=False)
        self._event_arguments = None

    def advance(self, state: State, t_end: float | None = None, kernel=None) -> Segment:
        """Marcher.advance, the factorisations of the march's step sizes prepared first."""
        t_end = state.t + self.plan.t_end if t_end is None else t_end
        self.prepare(state.t, t_end)
        return super().advance(state, t_end, kernel)

    def prepare(self, t_start: float, t_end: float) -> None:
        """Hold the factorisations of the nominal step and of the last step of a march from
        t_start to t_end (the nominal one when the last step is nominal: kernels.sparse.last_step)."""
        cs, st = self.plan.compiled, self.settings
        dt = KS.nominal_step(st)
        main = SB.factor_of(cs, st, dt, True)
        dt_last = SB.last_step(t_start, t_end, dt)
        last = main if abs(dt_last - dt) <= 1e-12 * dt else SB.factor_of(cs, st, dt_last, True)
        if self.ws.main is not main or self.ws.last is not last:
            self.ws = self.ws._replace(main=main, last=last)

    def load(self, state: State) -> None:
        """Write ``state`` into the workspace and q0, f0 (a state without its force terms is
        completed first: start.consistent_start)."""
        if state.terms is None:
            state = consistent_start(self.plan, state.x, state.v, state.w, state.contact_state, state.t, state.a)
        ws, terms = self.ws, state.terms
        for dst, src in zip((ws.x, ws.v, ws.a, ws.fe, ws.gf), (state.x, state.v, state.a, terms.fe, terms.gf)):
            dst[:] = src
        ws.w[:] = state.w
        ws.state[:] = state.contact_state
        self.q0[:], self.f0[:] = terms.q, terms.f

    def retarget(self, plan: RunPlan) -> None:
        """March ``plan`` from now on (Marcher.retarget; the factorisations follow its step at
        the next advance)."""
        if not same_layout(self.plan, plan) or not SB.is_sparse_plan(plan):
            raise ValueError("retarget: the plan has another array layout (build a new Marcher)")
        self.out = allocate_outputs(plan.compiled, plan.capacity, plan.options.max_memory, plan.save_plan, plan.t_end)
        self.plan, self.settings = plan, plan.settings


def sparse_kernel(backend: int):
    """The kernel entry of a sparse plan: kernels.sparse.sparse_march (one backend), called on the
    argument tuple itself (not packed: KernelEntry(packed=False))."""
    return KS.sparse_march
