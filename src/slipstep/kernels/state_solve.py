"""The linear solve of a step in contact state S, factorised once per state (paper Eq. 7):

    J(S) = Lin + kfac K_D(S),   K_D(S) = A^T K(S) A

Three ways, chosen once per run (MarchSettings.structure, kernels/structure_ops.py):

* banded (issue 10, the banded backend of slipstep.system): J(S) assembled in banded-LU
  storage (Lin plus the outer products of each contact's few sparse rows) and factorised by
  the banded LU of kernels/banded.py, cached per state like the direct LUs
  (:func:`factorise_banded`): O(n b^2) per state, O(n b) per solve;

* direct: the LU of the n x n J(S) per state tuple (best when the contact coordinates are
  as many as the DOFs, e.g. a rigid damper);
* low-rank (Woodbury), for structures with many more DOFs n than contact coordinates nq:
  J(S) = J0 + A^T dK(S) A with J0 = J(all stick) and dK(S) = kfac (K(S) - K(stick)) local.
  With Z = J0^-1 A^T (n x nq, once per step size) and the capacitance C(S) = I + dK(S) A Z
  (nq x nq, once per state):
      J(S)^-1 r = y - Z C(S)^-1 dK(S) A y,   y = J0^-1 r
  so a new state costs an nq x nq factorisation instead of n x n, and a solve O(n^2 + n nq).
  J(S) is singular exactly when C(S) is (J0 regular).
"""

from typing import NamedTuple

import numpy as np
from numba import njit

from slipstep.kernels.banded import band_contact_stiffness, band_lu_factor, band_to_lu_storage
from slipstep.kernels.cache import find_slot
from slipstep.kernels.codes import C_FACTORISATIONS
from slipstep.kernels.contact import STICK, contact_stiffness, coupled, delta_stiffness
from slipstep.kernels.linalg import lu_factor, lu_solve
from slipstep.kernels.lean_compiler import LeanCompiler


class LowRank(NamedTuple):
    """Arrays of the low-rank solves (tiny placeholders in direct mode). Base slots are keyed
    by the dt state (one J0 per step size); slot capb is scratch (the shortened last step)."""

    base_keys: np.ndarray  # int8 (capb, nd)
    base_used: np.ndarray  # bool (capb)
    base_ok: np.ndarray  # bool (capb + 1)
    base_lu: np.ndarray  # (capb + 1, n, n)
    base_piv: np.ndarray  # int64 (capb + 1, n)
    Z: np.ndarray  # (capb + 1, n, nq): J0^-1 A^T
    AZ: np.ndarray  # (capb + 1, nq, nq): A J0^-1 A^T
    slot_base: np.ndarray  # int64 (cap + 2): base slot of each state slot
    slot_identity: np.ndarray  # bool (cap + 2): the state is all stick, C = I
    Ay: np.ndarray  # (nq) scratch
    t: np.ndarray  # (nq) scratch
    s: np.ndarray  # (nq) scratch
    col: np.ndarray  # (n) scratch
    zc: np.ndarray  # (n) scratch


@njit(cache=True, error_model="numpy", inline="always")
def state_slot(cl, cache, kd_state, nominal):
    """(slot, found): the cache slot of the factorised J(kd_state) for the current step size,
    key = (kd_state, cache.dt_state) (kernels/cache.py). A non-nominal dt (the shortened last
    step) uses scratch slot cap, a state without a piecewise-linear form (coupled slip: its
    tangent depends on the linearisation point) scratch slot cap + 1, neither cached (found
    False). A new key is entered in the table: the caller factorises into its slot
    (:func:`factorise_state`, :func:`factorise_banded`). Inlined, so that a cache hit costs
    no call of the factorisation functions and their arguments."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    key = cache.key
    nd = kd_state.shape[0]
    for d in range(nd):
        key[d] = kd_state[d]
        key[nd + d] = cache.dt_state[d]
    cap = cache.used.shape[0]
    if coupled(nrow, lcode, lpar, fdir, ndir, trow, kt, kd_state):
        return cap + 1, False
    if nominal:
        return find_slot(cache.keys, cache.used, key)
    return cap, False


@njit(cache=True, nogil=True, error_model="numpy", pipeline_class=LeanCompiler)
def factorise_state(slot, lowrank, Lin, J, kfac, A, cl, cache, kd_state, q, w_old, nominal, singular_rtol, counters):
    """Factorise the solve of J(kd_state) for the current step size into ``slot`` (from
    :func:`state_slot`, not found there): the LU of J (direct) or the low-rank update of the
    base J0 of this step size (module docstring). Returns ok, False when J(S) is singular
    (also kept in cache.ok[slot]). cl: the ContactLaw table, cache: the StateCache
    (kernels/settings.py); q, w_old: the linearisation point of a coupled slip."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    dt_state, stick, ok_flags = cache.dt_state, cache.stick, cache.ok
    lus, pivs, lr = cache.lu, cache.piv, cache.lr
    nd = kd_state.shape[0]
    n = Lin.shape[0]
    if not lowrank:
        for i in range(n):
            for j in range(n):
                J[i, j] = Lin[i, j]
        contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, kd_state, q, w_old, kfac, J)
        ok = lu_factor(J, lus[slot], pivs[slot], singular_rtol)
        ok_flags[slot] = ok
        counters[C_FACTORISATIONS] += 1
        return ok
    # ---- low rank: the base J0 = J(stick) of this step size, then C(S) ----
    nq = A.shape[0]
    capb = lr.base_used.shape[0]
    if nominal:
        b, bfound = find_slot(lr.base_keys, lr.base_used, dt_state)
    else:
        b, bfound = capb, False
    if not bfound:
        for i in range(n):
            for j in range(n):
                J[i, j] = Lin[i, j]
        contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, A, stick, q, w_old, kfac, J)
        ok0 = lu_factor(J, lr.base_lu[b], lr.base_piv[b], singular_rtol)
        lr.base_ok[b] = ok0
        counters[C_FACTORISATIONS] += 1
        if ok0:
            for r in range(nq):
                for i in range(n):
                    lr.col[i] = A[r, i]
                lu_solve(lr.base_lu[b], lr.base_piv[b], lr.col, lr.zc)
                for i in range(n):
                    lr.Z[b, i, r] = lr.zc[i]
            for r in range(nq):
                for c in range(nq):
                    acc = 0.0
                    for i in range(n):
                        acc += A[r, i] * lr.Z[b, i, c]
                    lr.AZ[b, r, c] = acc
    lr.slot_base[slot] = b
    if not lr.base_ok[b]:
        ok_flags[slot] = False
        return False
    identity = True
    for d in range(nd):
        if kd_state[d] != STICK:
            identity = False
    lr.slot_identity[slot] = identity
    if identity:
        ok_flags[slot] = True
        return True
    C = lus[slot]  # C(S) = I + dK(S) A Z, assembled in its slot and factorised in place
    for c in range(nq):
        for r in range(nq):
            lr.t[r] = lr.AZ[b, r, c]
        delta_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, kd_state, q, w_old, kfac, lr.t, lr.s)
        for r in range(nq):
            C[r, c] = lr.s[r] + (1.0 if r == c else 0.0)
    ok = lu_factor(C, C, pivs[slot], singular_rtol)
    ok_flags[slot] = ok
    counters[C_FACTORISATIONS] += 1
    return ok


@njit(cache=True, nogil=True, error_model="numpy")
def solve_low_rank(slot, cache, A, cl, kd_state, q, w_old, kfac, r, out):
    """out = J(kd_state)^-1 r by the low-rank update of ``slot`` (see the module docstring).
    In direct mode the callers use lu_solve(lus[slot], pivs[slot], r, out) instead (kept out of
    this function so that the direct hot path never touches the low-rank arrays)."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    lus, pivs, lr = cache.lu, cache.piv, cache.lr
    b = lr.slot_base[slot]
    lu_solve(lr.base_lu[b], lr.base_piv[b], r, out)
    if lr.slot_identity[slot]:
        return
    nq = A.shape[0]
    n = out.shape[0]
    for rr in range(nq):
        acc = 0.0
        for j in range(n):
            acc += A[rr, j] * out[j]
        lr.Ay[rr] = acc
    delta_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, kd_state, q, w_old, kfac, lr.Ay, lr.t)
    lu_solve(lus[slot], pivs[slot], lr.t, lr.s)
    for i in range(n):
        acc = 0.0
        for c in range(nq):
            acc += lr.Z[b, i, c] * lr.s[c]
        out[i] -= acc


@njit(cache=True, nogil=True, error_model="numpy")
def factorise_banded(slot, sys, cl, cache, Lin, kfac, kd_state, q, w_old, singular_rtol, counters):
    """:func:`factorise_state` for the banded backend: the banded LU of J(kd_state) = Lin +
    kfac A^T K(kd_state) A (Lin in band storage, A in CSR) into ``slot`` (from
    :func:`state_slot`). Returns ok."""
    nrow, lcode, lpar, fdir, ndir, trow, kt = cl
    kl, ku = sys.kl, sys.ku
    lu = cache.lu[slot]
    band_to_lu_storage(Lin, kl, ku, lu)
    band_contact_stiffness(nrow, lcode, lpar, fdir, ndir, trow, kt, sys.A_ptr, sys.A_idx, sys.A_val, kd_state, q,
                           w_old, kfac, lu, kl + ku)
    ok = band_lu_factor(lu, kl, ku, cache.piv[slot], singular_rtol)
    cache.ok[slot] = ok
    counters[C_FACTORISATIONS] += 1
    return ok
