"""Quasi-static DOFs inside a dynamic march: a chosen set of DOFs m (a damper's) without
inertia, the rest d (the blades) dynamic (issue 11, beyond the paper).

The chosen DOFs lose their mass and viscous damping; their rows of paper Eq. 1 become the
quasi-static equilibrium of paper Eq. 10 while the other rows keep Newmark's inertia:

    M_dd a_d + C_dd v_d + K_dd x_d + K_dm x_m + A_d^T f = f_e,d
                          K_md x_d + K_mm x_m + A_m^T f = f_e,m

In each contact state S the step's Jacobian is J(S) = [[a0 M_dd + c1 C_dd + K_dd + K_D,dd,
K_dm + K_D,dm], [K_md + K_D,md, K_mm + K_D,mm]]: eliminating x_m from it is the static
condensation of the massless DOFs per contact state (the paper's Method 4 applied to part of
the system), which the LU of J(S) does implicitly. The damper's internal modes (its mass on
the contact springs, about 10 kHz for the paper's damper) disappear, and T_min (paper Eq. 8)
comes from the dynamic part alone, on the condensed stiffness

    K*(S) = K_dd(S) - K_dm(S) K_mm(S)^-1 K_md(S),   omega^2 = eig(M_dd^-1 K*(S)).

The chosen DOFs must be inertially and viscously uncoupled from the others (M_md = 0,
C_m. = 0), so that dropping their inertia leaves the dynamic part unchanged. Their reported
velocity is dx/dt and their acceleration 0 (kernels.march). "auto" chooses the DOFs held by
contacts only: zero rows of K and C (a rigid damper's).
"""

from __future__ import annotations

import fnmatch
import math

import numpy as np

from slipstep.errors import InputError
from slipstep.kernels.contact import add_contact_stiffness
from slipstep.model.system import CompiledSystem, System


def contact_held_dofs(system: System) -> np.ndarray:
    """Indices of the DOFs with no structural stiffness or damping (zero rows of K and C)
    that a contact gathers: bodies held by contacts only (rigid dampers)."""
    s = system.structure
    gathered = np.zeros(s.n_dofs, bool)
    for c in system.contacts:
        gathered |= np.asarray(abs(c.dof_gather).sum(axis=0)).ravel() != 0
    rows = lambda X: np.asarray(abs(X).sum(axis=1)).ravel() != 0  # dense or sparse  # noqa: E731
    free = ~rows(s.stiffness) & ~rows(s.damping)
    return np.flatnonzero(free & gathered)


def select_massless(system: System, spec) -> np.ndarray:
    """The DOF indices named by ``spec``: 'auto' (:func:`contact_held_dofs`) or DOF names /
    shell patterns ('damper*'); checked to be uncoupled in M and C from the other DOFs."""
    s = system.structure
    names = s.dof_names
    if isinstance(spec, str) and spec == "auto":
        idx = contact_held_dofs(system)
        if idx.size == 0:
            raise InputError(
                "massless_dofs",
                "'auto' found no DOF held by contacts only (zero rows of K and C)",
                "name the DOFs to treat without inertia, e.g. massless_dofs=('damper.x_G', ...)",
            )
    else:
        patterns = [spec] if isinstance(spec, str) else list(spec)
        chosen = set()
        for p in patterns:
            hit = [i for i, n in enumerate(names) if fnmatch.fnmatchcase(n, str(p))]
            if not hit:
                raise InputError(
                    "massless_dofs",
                    f"{p!r} matches no DOF",
                    f"use DOF names or patterns such as {', '.join(names[:4])}",
                )
            chosen.update(hit)
        idx = np.array(sorted(chosen), dtype=np.int64)
    if idx.size == s.n_dofs:
        raise InputError("massless_dofs", "selects every DOF", "use the quasi-static method (Method 4) instead")
    rest = np.setdiff1d(np.arange(s.n_dofs), idx)
    Md, Cd, _ = s.dense_matrices("massless_dofs", "the quasi-static-dofs method")
    for label, A in (("mass", Md), ("damping", Cd)):
        coupled = np.abs(A[np.ix_(idx, rest)]).max(initial=0.0) if label == "mass" else np.abs(A[idx]).max(initial=0.0)
        if coupled > 0:
            raise InputError(
                "massless_dofs",
                f"are coupled to the other DOFs by the {label} matrix ({label} entries up to {coupled:.3g})",
                "choose DOFs of a body with its own mass block and no viscous damping (a damper)",
            )
    return idx


def inertia_free(cs: CompiledSystem, idx: np.ndarray) -> CompiledSystem:
    """The compiled system with the mass and damping rows/columns of ``idx`` set to zero."""
    M, C = cs.M.copy(), cs.C.copy()
    for A in (M, C):
        A[idx, :] = 0.0
        A[:, idx] = 0.0
    return cs._replace(M=np.ascontiguousarray(M), C=np.ascontiguousarray(C))


def massless_mask(M: np.ndarray) -> np.ndarray:
    """True where M has a zero row (a DOF without inertia)."""
    return ~np.any(M != 0.0, axis=1)


def inverse_mass(M: np.ndarray) -> np.ndarray:
    """M^-1 on the DOFs with inertia, 0 on the massless ones (M^-1 itself when M is regular)."""
    zero = massless_mask(M)
    if not zero.any():
        return np.linalg.inv(M)
    d = np.flatnonzero(~zero)
    out = np.zeros_like(M)
    out[np.ix_(d, d)] = np.linalg.inv(M[np.ix_(d, d)])
    return out


def initial_acceleration(M: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """a_0 = M_dd^-1 rhs_d on the DOFs with inertia, 0 on the massless ones."""
    zero = massless_mask(M)
    if not zero.any():
        return np.linalg.solve(M, rhs)
    d = np.flatnonzero(~zero)
    a = np.zeros_like(rhs)
    a[d] = np.linalg.solve(M[np.ix_(d, d)], rhs[d])
    return a


def check_held(Keff: np.ndarray, idx: np.ndarray) -> None:
    """Refuse a contact state in which the DOFs ``idx`` have no quasi-static equilibrium:
    K_mm(S) = (K + K_D(S))_mm singular (smallest singular value <= 1e-12 of the largest)."""
    Kmm = np.asarray(Keff)[np.ix_(idx, idx)]
    sv = np.linalg.svd(Kmm, compute_uv=False)
    if sv.size and sv.min() <= 1e-12 * max(sv.max(), 1e-300):
        raise InputError(
            "massless_dofs",
            "have no quasi-static equilibrium in this contact state "
            "(their stiffness K_mm + K_D,mm is singular: held by nothing)",
            "treat only DOFs that the contacts hold in full stick",
        )


def condensed_eigenvalues(cs: CompiledSystem, state: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Every omega^2 of the dynamic part with the DOFs ``idx`` condensed (module docstring; the
    step needs only the largest: slipstep.methods.step_control.state_t_min); raises InputError
    when K_mm(S) is singular (no quasi-static equilibrium of those DOFs)."""
    Keff = cs.K.copy()
    add_contact_stiffness(cs, np.asarray(state, np.int8), 1.0, Keff)
    check_held(Keff, idx)
    d = np.setdiff1d(np.arange(cs.K.shape[0]), idx)
    Kmm = Keff[np.ix_(idx, idx)]
    Ks = Keff[np.ix_(d, d)] - Keff[np.ix_(d, idx)] @ np.linalg.solve(Kmm, Keff[np.ix_(idx, d)])
    return np.linalg.eigvals(np.linalg.solve(cs.M[np.ix_(d, d)], Ks))


def internal_frequencies(cs: CompiledSystem, state: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Frequencies [Hz] of the chosen DOFs on the contact springs with every other DOF fixed
    (the damper's internal modes, paper Remark 2), from the system's own mass matrix."""
    Keff = cs.K.copy()
    add_contact_stiffness(cs, np.asarray(state, np.int8), 1.0, Keff)
    ev = np.linalg.eigvals(np.linalg.solve(cs.M[np.ix_(idx, idx)], Keff[np.ix_(idx, idx)]))
    return np.sort(np.sqrt(np.abs(ev.real))) / (2 * math.pi)
