"""The Python side of the condensed sparse backend (kernels/sparse.py, issue 26):
``linear_solver = "sparse"``.

- :func:`factorise`: the factorisation of Lin0 = Lin + kfac A^T K(stick) A for one step size
  (a :class:`slipstep.kernels.sparse.SparseFactor`): the DOFs the contacts see (B) ordered
  last, the others in the fill-reducing order of SuperLU's own factorisation of their block,
  then SuperLU's LU of the whole matrix in that order (no further pivoting: Lin0 is symmetric
  positive definite); the trailing dense blocks F = L_BB^-1 A_B^T and G0 = A_B U_BB^-1 F.
  Factorisations are kept per (structure, contacts, step size) (:func:`factor_of`), so the
  twins of the accuracy rule, the periods of a steady-state search and the points of an FRF
  at one step size factorise once.
- :class:`SparseMarcher`: the :class:`slipstep.methods.marcher.Marcher` of a sparse plan (its
  workspace a SparseWorkspace, its kernel kernels.sparse.sparse_march); before each march it
  prepares the factorisation of a last step shorter than the nominal one.
- :func:`static_equilibrium_workspace`: the workspace of the static preload (Lin = K).
- :func:`omega2_stick`: omega_max^2 of full stick for T_min (ARPACK on K_eff x = lambda M x).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from slipstep.model.contact import without_piecewise_linear_form
from slipstep.errors import InputError
from slipstep.kernels import march as K
from slipstep.kernels import sparse as KS
from slipstep.methods.step_rule import step_rule_of

#: the state cache holds at most about this many bytes of condensed LUs (nq x nq per slot)
STATE_CACHE_BYTES = 2e8
#: factorisations kept per structure (nominal, last step, preload and a twin's)
FACTORS_KEPT = 4


@dataclass
class Timing:
    """Seconds spent in the backend's set-up (for benchmarks): ordering + factorisation and
    the dense contact-space blocks, summed over the factorisations made."""

    factorise_s: float = 0.0
    blocks_s: float = 0.0
    factorisations: int = 0


TIMING = Timing()


def matrices(cs) -> tuple:
    """(M, C, K) of a sparse compiled system as scipy CSR (the user's DOF order)."""
    return cs.matrices


def stick_stiffness(cs) -> sp.csr_matrix:
    """A^T K(stick) A (sparse): k_n on the normal rows, k_t on the tangential rows."""
    nq = cs.A_ptr.shape[0] - 1
    k = np.zeros(nq)
    k[np.asarray(cs.normal_row)] = np.asarray(cs.kn)
    k[np.asarray(cs.tangential_row)] = np.asarray(cs.kt)
    A = gather_matrix(cs)
    return (A.T @ sp.diags(k) @ A).tocsr()


def gather_matrix(cs) -> sp.csr_matrix:
    """A (nq x n) as scipy CSR from the compiled CSR arrays."""
    nq, n = cs.A_ptr.shape[0] - 1, cs.AT_ptr.shape[0] - 1
    return sp.csr_matrix((cs.A_val, cs.A_idx, cs.A_ptr), shape=(nq, n))


def lin_matrix(cs, settings: K.MarchSettings, dt: float, inertia: bool) -> sp.csc_matrix:
    """Lin0 = Lin + kfac A^T K(stick) A (module docstring) for the step dt; Lin = c_m M +
    c_c C + c_k K with the scheme's coefficients (kernels/march.py), quasi-static Lin = K."""
    M, C, Kst = matrices(cs)
    if inertia:
        a0, c1, *_ = K.newmark_coefficients(settings.beta, settings.gamma, dt)
        am, af = settings.alpha_m, settings.alpha_f
        lin = (1.0 - am) * a0 * M + (1.0 - af) * c1 * C + (1.0 - af) * Kst
        kfac = 1.0 - af
    else:
        lin, kfac = Kst, 1.0
    return _pruned((lin + kfac * stick_stiffness(cs)).tocsr()).tocsc(), kfac


#: an entry a_ij of Lin0 below PRUNE_RTOL sqrt(|a_ii a_jj|) is round-off (see :func:`_pruned`)
PRUNE_RTOL = 1e-14


def _pruned(X: sp.csr_matrix) -> sp.csr_matrix:
    """X without the entries that are zero but for round-off, |a_ij| < PRUNE_RTOL sqrt(|a_ii
    a_jj|) (couplings that cancel in an FE assembly come out as 0 or 1e-19 by the order of the
    sums): the fill-reducing order depends on the pattern alone, and one such entry in a row
    can double the fill of the LU. The change to the matrix is below its round-off."""
    X = X.copy()
    d = np.sqrt(np.abs(X.diagonal()))
    rows = np.repeat(np.arange(X.shape[0]), np.diff(X.indptr))
    small = np.abs(X.data) < PRUNE_RTOL * d[rows] * d[X.indices]
    if small.any():
        X.data[small] = 0.0
        X.eliminate_zeros()
    return X


def factorise(cs, settings: K.MarchSettings, dt: float, inertia: bool) -> KS.SparseFactor:
    """The SparseFactor of Lin0 for the step dt (module docstring)."""
    start = time.perf_counter()
    lin, kfac = lin_matrix(cs, settings, dt, inertia)
    n = lin.shape[0]
    A = gather_matrix(cs)
    bset = np.unique(A.indices)
    perm = _elimination_order(cs, lin, bset)
    lu = sla.splu(
        lin[perm][:, perm].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
    )
    if not (np.array_equal(lu.perm_c, np.arange(n)) and np.array_equal(lu.perm_r, np.arange(n))):
        raise RuntimeError("SuperLU reordered a matrix given in its elimination order")  # not seen: a guard
    TIMING.factorise_s += time.perf_counter() - start
    TIMING.factorisations += 1
    start = time.perf_counter()
    L, U = lu.L, lu.U  # (built by scipy on each access: once)
    L.sort_indices()
    U.sort_indices()
    _check_diagonals(L, U)
    diag = U.data[U.indptr[1:] - 1].copy()
    if not np.all(np.isfinite(diag)) or np.any(np.abs(diag) <= settings.singular_rtol * abs(lin).max()):
        raise InputError("structure", "the step matrix is singular", "clamp the structure or add stiffness/mass")
    nb = bset.size
    off = n - nb
    LBB = _trailing_block(L, off)
    UBB = _trailing_block(U, off)
    AB = np.ascontiguousarray(A[:, bset].toarray())
    from scipy.linalg import solve_triangular

    F = np.ascontiguousarray(solve_triangular(LBB, AB.T, lower=True, unit_diagonal=True))
    G0 = np.ascontiguousarray(AB @ solve_triangular(UBB, F, lower=False))
    TIMING.blocks_s += time.perf_counter() - start
    i32 = lambda a: np.ascontiguousarray(a, dtype=np.int32)  # noqa: E731
    i64 = lambda a: np.ascontiguousarray(a, dtype=np.int64)  # noqa: E731
    f64 = lambda a: np.ascontiguousarray(a, dtype=np.float64)  # noqa: E731
    return KS.SparseFactor(
        key=np.array([dt, 1.0 if inertia else 0.0, kfac]),
        perm=perm,
        L_ptr=i64(L.indptr),
        L_idx=i32(L.indices),
        L_val=f64(L.data),
        U_ptr=i64(U.indptr),
        U_idx=i32(U.indices),
        U_val=f64(U.data),
        U_diag=f64(diag),
        UBB=UBB,
        F=F,
        G0=G0,
        AB=AB,
    )


def _check_diagonals(L: sp.csc_matrix, U: sp.csc_matrix) -> None:
    """The kernel's solves take the diagonal as the first entry of each column of L (sorted
    CSC) and the last of each column of U: check it (SuperLU stores them so)."""
    n = L.shape[0]
    cols = np.arange(n)
    if not (np.array_equal(L.indices[L.indptr[:-1]], cols) and np.array_equal(U.indices[U.indptr[1:] - 1], cols)):
        raise RuntimeError("the LU factors lack a stored diagonal")  # not seen: a guard


def _trailing_block(X: sp.csc_matrix, off: int) -> np.ndarray:
    """X[off:, off:] as a dense array (the columns sliced first: cheap in CSC)."""
    cols = X[:, off:].tocoo()
    keep = cols.row >= off
    out = np.zeros((X.shape[0] - off, X.shape[1] - off))
    out[cols.row[keep] - off, cols.col[keep]] = cols.data[keep]
    return out


_ORDERS: dict = {}


def _elimination_order(cs, lin: sp.csc_matrix, bset: np.ndarray) -> np.ndarray:
    """The elimination order of Lin0 (module docstring): the DOFs outside B in the order of
    :func:`_interior_order`, then B. Computed once per structure and contacts (every step size
    and the preload's K share the pattern of M, C, K and A^T A)."""
    held = (cs.matrices, cs.A_val)
    hit = _ORDERS.get("order")
    if hit is not None and all(a is b for a, b in zip(hit[0], held)):
        return hit[1]
    inner = np.setdiff1d(np.arange(lin.shape[0]), bset)
    perm = np.concatenate([inner[_interior_order(lin, inner)], bset]).astype(np.int64)
    _ORDERS["order"] = (held, perm)
    return perm


def _interior_order(lin: sp.csc_matrix, inner: np.ndarray) -> np.ndarray:
    """A fill-reducing order of the block of the DOFs the contacts do not see: SuperLU's own
    (minimum degree on A^T + A) from a factorisation of that block. SuperLU's perm_c sends
    column j to position perm_c[j]: the order (position -> column) is its inverse."""
    block = lin[inner][:, inner].tocsc()
    lu = sla.splu(block, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return np.argsort(lu.perm_c)


def factor_nnz(fac: KS.SparseFactor) -> int:
    """Entries of L and U (the per-step cost of the solves)."""
    return int(fac.L_val.size + fac.U_val.size + fac.U_diag.size)


# ---- factorisations kept per structure and step size ------------------------------------------
_FACTORS: dict = {}


def factor_of(cs, settings: K.MarchSettings, dt: float, inertia: bool) -> KS.SparseFactor:
    """The SparseFactor of (cs's structure and contacts, scheme, dt, inertia), factorised once
    and kept (the last FACTORS_KEPT)."""
    held = (cs.matrices, cs.A_val, cs.kn, cs.kt)
    scheme = (settings.beta, settings.gamma, settings.alpha_m, settings.alpha_f) if inertia else ()
    key = (*(id(x) for x in held), float(dt) if inertia else 0.0, bool(inertia), scheme)
    hit = _FACTORS.pop(key, None)
    if hit is None:
        hit = (held, factorise(cs, settings, dt, inertia))
        while len(_FACTORS) >= FACTORS_KEPT:
            _FACTORS.pop(next(iter(_FACTORS)))
    _FACTORS[key] = hit  # most recent last
    return hit[1]


def forget_factors() -> None:
    """Drop every kept factorisation, order and mass factor and zero TIMING (benchmarks: a
    set-up measured from scratch)."""
    _FACTORS.clear()
    _ORDERS.clear()
    _MASS.clear()
    TIMING.factorise_s = TIMING.blocks_s = 0.0
    TIMING.factorisations = 0


# ---- the workspace -----------------------------------------------------------------------------
def _csr(X) -> tuple:
    X = sp.csr_matrix(X)
    X.sort_indices()
    return (
        np.ascontiguousarray(X.indptr, dtype=np.int64),
        np.ascontiguousarray(X.indices, dtype=np.int32),
        np.ascontiguousarray(X.data, dtype=np.float64),
    )


def state_cache_slots(nq: int) -> int:
    """Slots of the state cache: at most STATE_CACHE_BYTES of nq x nq LUs, between 4 and 256."""
    return int(min(256, max(4, STATE_CACHE_BYTES // (8 * nq * nq + 1))))


def workspace_bytes(cs, max_state_iter: int) -> int:
    """Bytes of :func:`allocate_workspace` without the factorisation (its vectors, the CSR
    structure and the state cache)."""
    n, nq, nd = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0]
    cap = state_cache_slots(nq)
    nnz = sum(X.nnz for X in cs.matrices)
    return int(8 * (30 * n + 20 * nq + (cap + 1) * (nq * nq + 5 * nq)) + 12 * nnz + nd * (max_state_iter + 2 + cap))


def allocate_workspace(plan, main: KS.SparseFactor) -> KS.SparseWorkspace:
    """A SparseWorkspace for ``plan`` holding the factorisation ``main`` (also as ``last``)."""
    cs = plan.compiled
    n, nq, nd, m = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.B.shape[1]
    nb = main.UBB.shape[0]
    cap = state_cache_slots(nq)
    M, C, Kst = matrices(cs)
    z = lambda *shape: np.zeros(shape)  # noqa: E731
    i8 = lambda *shape: np.zeros(shape, np.int8)  # noqa: E731
    return KS.SparseWorkspace(
        x=z(n), v=z(n), a=z(n), fe=z(n), gf=z(n), w=z(nd), state=i8(nd),
        fe1=z(n), gf1=z(n), f1=z(nq), q1=z(nq), w1=z(nd), state1=i8(nd), dx=z(n), r0=z(n), p=z(m), qbase=z(nq),
        fwd=z(n), zb=z(nb), u0=z(nq), h=z(nq), t=z(nq), rhs=z(nq), sol=z(nq),
        mdiag=np.ascontiguousarray(M.diagonal(), dtype=np.float64),
        **dict(zip(("M_ptr", "M_idx", "M_val"), _csr(M))),
        **dict(zip(("C_ptr", "C_idx", "C_val"), _csr(C))),
        **dict(zip(("K_ptr", "K_idx", "K_val"), _csr(Kst))),
        main=main, last=main, owner=np.full(3, np.nan),
        keys=i8(cap, nd), used=np.zeros(cap, np.bool_), ok=np.zeros(cap + 1, np.bool_),
        m=np.zeros(cap + 1, np.int64), rows=np.zeros((cap + 1, nq), np.int64), kdiag=z(cap + 1, nq),
        kcol=np.zeros((cap + 1, nq), np.int64), koff=z(cap + 1, nq), lu=z(cap + 1, nq, nq),
        piv=np.zeros((cap + 1, nq), np.int64), lin_dt=np.full(1, np.nan),
        visited=i8(max(plan.options.max_state_iterations, 1) + 1, nd),
    )  # fmt: skip


def preload_workspace(plan, workspace: KS.SparseWorkspace | None) -> KS.SparseWorkspace:
    """The workspace of the static preload (quasi-static, Lin = K): ``workspace`` (a marcher's:
    its arrays are shared) holding the factorisation of K + A^T K(stick) A."""
    pre = factor_of(plan.compiled, plan.settings, 1.0, False)
    if workspace is None:
        return allocate_workspace(plan, pre)
    return workspace._replace(main=pre, last=pre)


# ---- the marcher -------------------------------------------------------------------------------
def check_method(method, options) -> None:
    """The sparse backend marches the piecewise-linear solve at a fixed step, dynamic (Methods
    3 and, under the 'accuracy' step rule, 2+3): refuse the rest with the reason."""
    if method.solver != K.PIECEWISE_LINEAR or method.quasi_static or method.massless:
        raise InputError(
            "linear_solver",
            f"is 'sparse', which marches the dynamic piecewise-linear methods only, not {method.name}",
            "use method piecewise-linear (Method 3), or linear_solver 'banded' / 'auto' for this method",
        )
    if options.rtol is not None:
        raise InputError(
            "rtol",
            "is set: the sparse backend factorises once per step size and marches a fixed step",
            "drop rtol (the step-doubling estimate refines the step) or use linear_solver 'banded'",
        )


def check_contacts(system) -> None:
    """The friction circle has no piecewise-linear form: refused by the sparse backend."""
    circles = without_piecewise_linear_form(system.contacts)
    if circles:
        laws = sorted({c.law for c in system.contacts if c.name in circles})
        raise InputError(
            "linear_solver",
            f"is 'sparse', whose contact-space solve needs piecewise-linear laws; {circles[:3]} use "
            f"{', '.join(map(repr, laws))}",
            "use law quasi-3d-uncoupled, or linear_solver 'banded'",
        )


def check_adaptive(plan) -> None:
    """Method 2+3 marches a fixed step only where its factor is infinite (the 'accuracy' rule
    with an unconditionally stable scheme: dt = min(max_step, stability limit))."""
    st = plan.settings
    if st is not None and st.adaptive and math.isfinite(st.step_factor):
        raise InputError(
            "step_rule",
            "is 't-min' for an adaptive method: the step would change with the contact state, and the sparse "
            "backend factorises once per step size",
            "use step_rule 'accuracy' (or method piecewise-linear)",
        )


# ---- the 'auto' rule: estimated cost per step ------------------------------------------------
#: 'auto' never takes the sparse backend below this many DOFs (the paper's cases and every
#: small model keep the dense backend and its results)
SPARSE_MIN_N = 300
#: ... nor above this many contact coordinates (G0 and a state's LU are nq x nq dense: 72 MB
#: each at 3,000, a state's factorisation up to nq^3 / 3 = 9e9 multiply-adds)
SPARSE_MAX_NQ = 3000
#: T_min by a dense eigen-solve up to this many DOFs (as the dense backend, the same value)
DENSE_EIGEN_MAX_N = 2000
#: the cost model of 'auto' (:func:`step_costs`, fitted to benchmarks/bench_backends.py, docs/sparse.md):
#: seconds of a step's fixed work on every backend (the law, the state test, the stores), ...
COST_STEP_S = 30e-6
#: ... per multiply-add of the dense, banded and contact-space kernels, ...
COST_FLOP_S = 1.0e-9
#: ... per stored entry of L + U in the sparse backend's two triangular solves per step, ...
COST_LU_ENTRY_S = 3.0e-9
#: ... and new contact states per step (a state's factorisation: n^3/3 dense, 2 n b^2 banded,
#: m^3/3 condensed with m = nq/4 rows that left stick)
NEW_STATES_PER_STEP = 0.2
#: 'auto' takes the sparse backend when its estimated cost per step is at least this many times
#: below every other backend's (the estimates are within about 3x of the measured times: a
#: closer call keeps the backend of System.compile's rule and its results)
SPARSE_GAIN = 2.0


def serves(system, method, opt) -> bool:
    """Can the sparse backend march ``method`` with ``opt`` on ``system`` (check_method,
    check_contacts; Method 2+3 only under the 'accuracy' rule, its default with a period)?"""
    try:
        check_method(method, opt)
        check_contacts(system)
    except InputError:
        return False
    return not method.adaptive or step_rule_of(method, opt, system.period) == "accuracy"


@dataclass(frozen=True)
class CostEstimate:
    """The estimated seconds per step of Method 3 on each backend for one structure and its
    contacts (:func:`step_costs`), with the numbers they come from."""

    n: int
    nq: int
    band: int  # half-bandwidth after reverse Cuthill-McKee of M + C + K + A^T A
    lu_entries: int  # the estimate of nnz(L + U) of the sparse backend (step_costs)
    seconds: dict  # backend ('direct', 'low-rank', 'banded', 'sparse') -> seconds per step


def step_costs(system) -> CostEstimate:
    """Estimated seconds per step of the piecewise-linear march (Method 3) per backend, from n,
    nq, the DOFs the contacts see nb, the entries s of M, C and K (the products of a step), and
    the reverse Cuthill-McKee order of the pattern of M + C + K + A^T A: its half-bandwidth b and
    envelope E:

        direct    t0 + c_f (5 n^2 + 2 n nq) + rho c_f n^3 / 3
        low-rank  t0 + c_f (5 n^2 + 4 n nq) + rho c_f (n nq^2 + nq^3 / 3)      (when 2 nq <= n)
        banded    t0 + c_f (3 n (2 b + 1) + 20 n) + rho c_f 2 n b^2
        sparse    t0 + c_lu 2 E + c_f (2 nq^2 + s + 2 nb nq + 20 n) + rho c_f (m^3 / 3 + 2 m^2)

    with m = nq / 4, t0 = COST_STEP_S, c_f = COST_FLOP_S, c_lu = COST_LU_ENTRY_S and rho =
    NEW_STATES_PER_STEP, and nnz(L + U) of the sparse factorisation estimated by 2 E (the fill
    of an LU in the RCM order), or where that estimate does not make the sparse backend the
    choice, by the smaller of 2 E and :func:`minimum_degree_fill` (one symbolic-sized SuperLU
    factorisation of the pattern). Cached per structure and contacts."""
    st = system.structure
    key = (id(st), *(id(c.dof_gather) for c in system.contacts))
    hit = _COSTS.get("last")
    if hit is not None and hit[0] == key and hit[1] is st:
        return hit[2]
    n = st.n_dofs
    A = sp.vstack([sp.csr_matrix(c.dof_gather) for c in system.contacts]).tocsr() if system.contacts else None
    nq = 0 if A is None else A.shape[0]
    nb = 0 if A is None else int(np.unique(A.indices).size)
    s = sum(sp.csr_matrix(X).nnz for X in (st.mass, st.damping, st.stiffness))
    P = _pattern(st)
    if A is not None:
        P = (P + abs(A.T) @ abs(A)).tocsr()
    band, envelope = rcm_profile(P)
    t0, cf, rho = COST_STEP_S, COST_FLOP_S, NEW_STATES_PER_STEP
    m = nq / 4.0
    seconds = {
        "direct": t0 + cf * (5.0 * n * n + 2.0 * n * nq) + rho * cf * n**3 / 3.0,
        "banded": t0 + cf * (3.0 * n * (2 * band + 1) + 20.0 * n) + rho * cf * 2.0 * n * band**2,
    }
    if 0 < nq and 2 * nq <= n:
        seconds["low-rank"] = t0 + cf * (5.0 * n * n + 4.0 * n * nq) + rho * cf * (n * nq * nq + nq**3 / 3.0)
    sparse_rest = t0 + cf * (2.0 * nq * nq + s + 2.0 * nb * nq + 20.0 * n) + rho * cf * (m**3 / 3.0 + 2.0 * m * m)
    lu_entries = 2 * envelope
    others = min(seconds.values())
    if n >= SPARSE_MIN_N and SPARSE_GAIN * (sparse_rest + COST_LU_ENTRY_S * lu_entries) > others:
        lu_entries = min(lu_entries, minimum_degree_fill(P))  # the envelope does not decide: the real fill
    seconds["sparse"] = sparse_rest + COST_LU_ENTRY_S * lu_entries
    est = CostEstimate(n, nq, band, int(lu_entries), seconds)
    _COSTS["last"] = (key, st, est)
    return est


def minimum_degree_fill(P: sp.csr_matrix) -> int:
    """nnz(L + U) of SuperLU's factorisation of a matrix of the symmetric pattern P in the
    minimum-degree order on A^T + A (the sparse backend's order; it puts the contact DOFs
    last, which changes the fill little): the graph Laplacian of P plus the identity, symmetric
    positive definite, factorised without pivoting."""
    X = sp.csr_matrix((-np.ones(P.nnz), P.indices, P.indptr), shape=P.shape)
    X.setdiag(0.0)
    X.eliminate_zeros()
    X = (X + sp.diags(1.0 - np.asarray(X.sum(axis=1)).ravel())).tocsc()
    lu = sla.splu(X, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    return int(lu.L.nnz + lu.U.nnz)


_COSTS: dict = {}


def rcm_profile(P: sp.csr_matrix) -> tuple[int, int]:
    """(half-bandwidth, envelope) of the symmetric pattern P in the reverse Cuthill-McKee order:
    max |i - j| and sum_i (i - min {j <= i: P_ij != 0}) + n."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    order = reverse_cuthill_mckee(P, symmetric_mode=True)
    inverse = np.empty_like(order)
    inverse[order] = np.arange(order.size)
    coo = P.tocoo()
    r, c = inverse[coo.row], inverse[coo.col]
    band = int(np.abs(r - c).max(initial=0))
    first = np.arange(P.shape[0])
    np.minimum.at(first, r, c)
    return band, int((np.arange(P.shape[0]) - first).sum() + P.shape[0])


def auto_choice(system, method, opt) -> tuple[bool, str]:
    """linear_solver 'auto': (take the sparse backend?, why). The sparse backend when the
    structure (sparse or dense input matrices: their pattern counts) has at least SPARSE_MIN_N
    DOFs, the contacts at most SPARSE_MAX_NQ coordinates, the method is one it serves, and its
    estimated cost per step (:func:`step_costs`) is SPARSE_GAIN times below every other
    backend's; otherwise the rule of System.compile (banded for a narrow band, else low-rank or
    direct)."""
    s = system.structure
    if s.n_dofs < SPARSE_MIN_N:
        return False, f"auto: {s.n_dofs} DOFs < {SPARSE_MIN_N} (dense backend for small models)"
    if not system.contacts:
        return False, "auto: no contacts"
    if not serves(system, method, opt):
        return False, f"auto: the sparse backend does not march {method.name}"
    nq = sum(c.dof_gather.shape[0] for c in system.contacts)
    if nq > SPARSE_MAX_NQ:
        return False, f"auto: {nq} contact coordinates > {SPARSE_MAX_NQ} (dense nq x nq blocks)"
    est = step_costs(system)
    costs = ", ".join(f"{b} {t * 1e6:.3g}" for b, t in sorted(est.seconds.items(), key=lambda bt: bt[1]))
    others = min(t for b, t in est.seconds.items() if b != "sparse")
    take = SPARSE_GAIN * est.seconds["sparse"] <= others
    why = f"estimated us per step {costs} (n {est.n}, nq {est.nq}, band {est.band})"
    if not take and est.seconds["sparse"] < others:
        why += f"; sparse less than {SPARSE_GAIN:g}x below the next"
    return take, f"auto: {why}"


def auto_chooses(system, method, opt) -> bool:
    """linear_solver 'auto' takes the sparse backend (:func:`auto_choice`)."""
    return auto_choice(system, method, opt)[0]


def backend_reason(system, method, opt, backend: str) -> str:
    """Why the plan of (system, method, opt) runs on ``backend`` (the result attribute
    ``linear_solver_reason``): the option the user gave, or the reason of :func:`auto_choice`."""
    if opt.linear_solver != "auto":
        return f"given: linear_solver {opt.linear_solver!r}"
    reason = auto_choice(system, method, opt)[1]
    if backend == "sparse":
        return reason
    if system.structure.sparse and backend in ("dense", "low-rank", "banded"):
        return f"{reason}; then System.compile's rule: {'banded (narrow band)' if backend == 'banded' else backend}"
    return reason


def _pattern(structure) -> sp.csr_matrix:
    """|M| + |C| + |K| as CSR (dense input matrices: their non-zero entries)."""
    P = abs(sp.csr_matrix(structure.mass)) + abs(sp.csr_matrix(structure.damping))
    return (P + abs(sp.csr_matrix(structure.stiffness))).tocsr()


def structure_bandwidth(structure) -> int:
    """The bandwidth of M + C + K after reverse Cuthill-McKee."""
    return rcm_profile(_pattern(structure))[0]


def effective_stiffness(cs, state) -> sp.csr_matrix:
    """K + A^T K(S) A, sparse (kernels.contact.contact_stiffness: the stick tangent for a state
    without a constant one)."""
    nq = cs.A_ptr.shape[0] - 1
    Kd = np.zeros((nq, nq))
    from slipstep.kernels.contact import contact_stiffness
    from slipstep.kernels.settings import contact_table

    nrow, lcode, lpar, fdir, ndir, trow, kt = contact_table(cs)
    contact_stiffness(
        nrow,
        lcode,
        lpar,
        fdir,
        ndir,
        trow,
        kt,
        np.eye(nq),
        np.asarray(state, np.int8),
        np.empty(0),
        np.empty(0),
        1.0,
        Kd,
    )
    A = gather_matrix(cs)
    return (matrices(cs)[2] + A.T @ sp.csr_matrix(Kd) @ A).tocsr()


def omega2(cs, state) -> float:
    """omega_max^2 = max |eig(M^-1 (K + K_D(S)))|: the dense backend's eigen-solve up to
    DENSE_EIGEN_MAX_N DOFs, else ARPACK (Lanczos on the pencil, M^-1 by a sparse LU)."""
    from slipstep.methods import eigen

    M = matrices(cs)[0]
    Keff = effective_stiffness(cs, state)
    if M.shape[0] <= DENSE_EIGEN_MAX_N:
        return float(abs(eigen.largest_eigenvalue(M.toarray(), Keff.toarray())))
    minv = sla.LinearOperator(M.shape, matvec=mass_factor(cs).solve, dtype=float)
    value = sla.eigsh(Keff, k=1, M=M, Minv=minv, which="LM", tol=1e-8, return_eigenvectors=False)
    return float(abs(value[0]))


_MASS: dict = {}


def mass_factor(cs):
    """SuperLU of M (kept for the last structure: the consistent starts and T_min)."""
    M = matrices(cs)[0]
    hit = _MASS.get("M")
    if hit is None or hit[0] is not M:
        hit = (M, sla.splu(M.tocsc(), permc_spec="MMD_AT_PLUS_A"))
        _MASS["M"] = hit
    return hit[1]


def mass_solve(cs, rhs: np.ndarray) -> np.ndarray:
    """M^-1 rhs (the consistent acceleration)."""
    return mass_factor(cs).solve(np.ascontiguousarray(rhs, dtype=float))


def last_step(t_start: float, t_end: float, dt: float) -> float:
    """The step size of the last step of sparse_march from t_start to t_end (the kernel's own
    loop: kernels.sparse.last_step)."""
    return float(KS.last_step(float(t_start), float(t_end), float(dt)))


def is_sparse_plan(plan) -> bool:
    """Does ``plan`` march on the sparse backend?"""
    return plan.backend == "sparse"
