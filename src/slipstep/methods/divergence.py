"""The divergence test of a dynamic march: a march whose stored energy grows beyond
everything its loads supplied has diverged (an unstable step, a fluttering state), even when
every step converged.
"""

from __future__ import annotations

import numpy as np

from slipstep.errors import Status
from slipstep.kernels.codes import C_FAIL_STEP, C_STEPS
from slipstep.model.excitation import evaluate_compiled, force_signal, motion_signal
from slipstep.model.system import is_sparse, quadratic_form, structure_matrix


def energy_diverged(out, n_steps: int, cs, fe: np.ndarray, motion: np.ndarray) -> int:
    """The first output point where the stored energy has grown beyond everything the loads
    supplied (no source), 0 if it never does:

        E(t) - E(0) > 2 max_{s <= t} max(W(s), 0) + 10 (E(0) + 1e-12 J)   for some t

    E = 1/2 v^T M v + 1/2 x^T K x + contact elastic energy (1/2 N^2/k_n + 1/2 T^2/k_t),
    W = int f_e . dx - int f . B dp (trapezoid rule). A dissipative march has
    E(t) - E(0) <= W(t); an unstable scheme grows exponentially past any such bound."""
    k = n_steps + 1
    x, v = out.x[:k], out.v[:k]
    f = out.f[:k]
    if cs.banded:  # banded backend (issue 10): the quadratic forms on the band, in the kernel's DOF order
        from slipstep.kernels.banded import band_quadratic_forms

        x, v = x[:, cs.dof_order], v[:, cs.dof_order]  # saved columns are in the user's order

        E = np.empty(k)
        ek = np.empty(k)
        band_quadratic_forms(cs.Mb, cs.kl, cs.ku, np.ascontiguousarray(v), E)
        band_quadratic_forms(cs.Kb, cs.kl, cs.ku, np.ascontiguousarray(x), ek)
        E = 0.5 * (E + ek)
    else:  # dense, or the sparse backend's CSR matrices (the user's DOF order)
        M, K = (structure_matrix(cs, "M"), structure_matrix(cs, "K")) if is_sparse(cs) else (cs.M, cs.K)
        E = 0.5 * quadratic_form(M, v) + 0.5 * quadratic_form(K, x)
    nrow, trow = np.asarray(cs.normal_row), np.asarray(cs.tangential_row)
    if nrow.size:
        E = E + 0.5 * (f[:, nrow] ** 2 / cs.kn).sum(axis=1) + 0.5 * (f[:, trow] ** 2 / cs.kt).sum(axis=1)
    W = np.concatenate([[0.0], np.cumsum(0.5 * ((fe[1:] + fe[:-1]) * np.diff(x, axis=0)).sum(axis=1))])
    if cs.B.shape[1]:
        fb = f @ cs.B
        W = W - np.concatenate([[0.0], np.cumsum(0.5 * ((fb[1:] + fb[:-1]) * np.diff(motion[:k], axis=0)).sum(axis=1))])
    budget = 2.0 * np.maximum.accumulate(np.maximum(W, 0.0)) + 10.0 * (E[0] + 1e-12)
    over = ~(E - E[0] <= budget)  # NaN counts as over
    return int(np.argmax(over)) if np.any(over) else 0


def check_divergence(status: Status, cs, out, save_plan=None) -> Status:
    """DIVERGED when an OK dynamic march's stored energy grew beyond what its loads supplied
    (:func:`energy_diverged`; the step of the first such point lands in out.counters
    [C_FAIL_STEP]), else ``status``. Needs every DOF and contact at every step (``save_plan``
    None or saving all): otherwise the status is returned as it is (NON_FINITE still is one)."""
    plan = save_plan
    if plan is not None and not (plan.all_dofs and plan.all_contacts and plan.every_step):
        return status
    if status == Status.OK:
        n = int(out.counters[C_STEPS])
        t = out.t[: n + 1]
        fe = evaluate_compiled(force_signal(cs), t) + cs.constant_force
        p = evaluate_compiled(motion_signal(cs), t)
        first = energy_diverged(out, n, cs, fe, p)
        if first:
            out.counters[C_FAIL_STEP] = first
            return Status.DIVERGED
    return status
