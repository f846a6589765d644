"""The two linear limits of a friction-damped response, solved in the frequency domain.

Contacts removed: the structure alone, (K - w^2 M + i w C) X = F(w).
Every contact stuck: the contact springs added as in full stick, K_D = A^T K(stick) A
(paper Eq. 7; a contact open at the static preload stays open), and the prescribed motions
act through them, (K + K_D - w^2 M + i w C) X = F(w) + A^T K(stick) B P(w).

Phasors follow the excitation's sine convention: a sin(w t + phi) = Im(a e^{i phi} e^{i w t}),
so x(t) = sum over the excitation frequencies of Im(X e^{i w t}). The amplitude reported is
half the peak-to-peak range of x(t) over one fundamental period: |X| for a single harmonic,
sampled at 4096 points per period otherwise.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import xarray as xr

from slipstep.model.retune import retune
from slipstep.kernels.codes import LIFT, STICK
from slipstep.methods.plan import plan_run
from slipstep.methods.start import static_equilibrium
from slipstep.model.system import System


def _phasors(signal, n_components: int) -> dict[float, np.ndarray]:
    out: dict[float, np.ndarray] = {}
    if signal is None:
        return out
    for h in signal.harmonics:
        out.setdefault(h.frequency, np.zeros(n_components, complex))
        out[h.frequency] = out[h.frequency] + h.amplitude * np.exp(1j * h.phase)
    return out


def stuck_state(system: System) -> np.ndarray:
    """STICK for every direction of a contact closed at the static preload, LIFT otherwise."""
    plan = plan_run(system, "quasi-static", periods=1.0, steps_per_period=2)
    cs = plan.compiled
    closed = static_equilibrium(plan).terms.q[cs.normal_row] > 0.0
    return np.where(closed[cs.direction_contact], STICK, LIFT).astype(np.int8)


def _stuck_stiffness(cs, state: np.ndarray) -> np.ndarray:
    """diag K(stick) over the local rows (nq,): k_t on the tangential and k_n on the normal
    row of every contact not lifted off in ``state``, 0 for a contact open at the preload."""
    ks = np.zeros(cs.A.shape[0])
    for c in range(cs.kn.shape[0]):
        if state[cs.first_direction[c]] == LIFT:
            continue
        ks[cs.normal_row[c]] = cs.kn[c]
        for d in range(cs.first_direction[c], cs.first_direction[c] + cs.n_directions[c]):
            ks[cs.tangential_row[d]] = cs.kt[d]
    return ks


def _limit_matrices(system: System, stuck: bool, state: np.ndarray | None = None):
    """(K, M, C, loads, sparse) of a linear limit: K with K_D added when ``stuck``, the load
    phasors {excitation frequency [Hz]: (n,) complex} (the forces, and for ``stuck`` the
    prescribed motions acting through the stuck contacts), ``sparse`` for a structure whose
    matrices stay scipy sparse (factorised per frequency)."""
    cs = system.compile_for_frequency_domain()
    s = system.structure
    sparse_structure = cs.M.shape[1] == 0
    M, C, K = (sp.csc_matrix(X) for X in (s.mass, s.damping, s.stiffness)) if sparse_structure else (cs.M, cs.C, cs.K)
    n = cs.M.shape[0]
    forces = _phasors(system.excitation.force, n)
    motions = _phasors(system.excitation.motion, cs.B.shape[1]) if stuck else {}
    if stuck:
        state = stuck_state(system) if state is None else state
        ks = _stuck_stiffness(cs, np.asarray(state, np.int8))
        A = sp.csr_matrix(cs.A)
        KD = A.T @ sp.diags(ks) @ A  # K_D = A^T K(stick) A (paper Eq. 7)
        K = (K + KD).tocsc() if sparse_structure else K + KD.toarray()
        motion_force = cs.A.T @ (ks[:, None] * cs.B)
    loads = {}
    for f in sorted(set(forces) | set(motions)):
        rhs = forces.get(f, np.zeros(n, complex)).astype(complex)
        if f in motions:
            rhs = rhs + motion_force @ motions[f]
        loads[f] = rhs
    return K, M, C, loads, sparse_structure


def _amplitude(X: dict, period: float | None, n: int) -> np.ndarray:
    """Half the peak-to-peak range over one period of x(t) = sum_f Im(X_f e^{i 2 pi f t})."""
    if len(X) == 0:
        return np.zeros(n)
    if len(X) == 1:
        return np.abs(next(iter(X.values())))
    t = np.linspace(0.0, period, 4096, endpoint=False)
    x = sum(np.imag(np.outer(np.exp(2j * np.pi * f * t), Xf)) for f, Xf in X.items())
    return 0.5 * np.ptp(x, axis=0)


def linear_response(system: System, stuck: bool, state: np.ndarray | None = None) -> tuple[dict, np.ndarray]:
    """Phasors X(w) per excitation frequency and the half peak-to-peak amplitude per DOF of
    the linear limit (``stuck``: every contact stuck in ``state``, default :func:`stuck_state`;
    else the contacts removed). A sparse structure is solved by a sparse LU per frequency."""
    K, M, C, loads, sparse_structure = _limit_matrices(system, stuck, state)
    solve = spla.spsolve if sparse_structure else np.linalg.solve
    X = {}
    for f, rhs in loads.items():
        w = 2 * np.pi * f
        X[f] = solve(K - w * w * M + 1j * w * C, rhs)
    return X, _amplitude(X, system.period, M.shape[0])


class LinearLimit:
    """One linear limit of ``system`` (``stuck`` as in :func:`linear_response`) at any
    fundamental frequency f [Hz]: the excitation retuned to f (slipstep.model.retune: every
    excitation frequency f_h becomes (f_h / f_1) f, amplitudes and phases kept), so
    ``amplitude(f)`` equals ``linear_response(retune(system, f), stuck, state)[1]`` with the
    matrices assembled once. ``K``, ``M``, ``C``: the limit's matrices (dense, or scipy sparse
    when ``sparse``)."""

    def __init__(self, system: System, stuck: bool, state: np.ndarray | None = None):
        self.K, self.M, self.C, loads, self.sparse = _limit_matrices(system, stuck, state)
        f1 = system.excitation.fundamental_frequency
        self.loads = {} if f1 is None else {f / f1: rhs for f, rhs in loads.items()}  # {multiple f_h / f_1: phasor}
        self.n = self.M.shape[0]

    def amplitude(self, frequency_hz: float) -> np.ndarray:
        """The half peak-to-peak amplitude per DOF at the fundamental ``frequency_hz``."""
        f = float(frequency_hz)
        solve = spla.spsolve if self.sparse else np.linalg.solve
        X = {}
        for m, rhs in self.loads.items():
            w = 2 * np.pi * m * f
            X[m * f] = solve(self.K - w * w * self.M + 1j * w * self.C, rhs)
        return _amplitude(X, 1.0 / f, self.n)


def linear_limits(system: System, frequencies, responses=None) -> xr.Dataset:
    """``linear_free_amplitude`` and ``linear_stuck_amplitude`` over (frequency, response) on
    the grid ``frequencies`` [Hz] (the excitation retuned to each, slipstep.model.retune)."""
    freqs = np.atleast_1d(np.asarray(frequencies, float))
    names = list(system.structure.dof_names)
    responses = names if responses is None else list(responses)
    idx = [names.index(r) for r in responses]
    state = stuck_state(system) if system.contacts else None
    free = np.zeros((freqs.size, len(idx)))
    stuck = np.zeros_like(free)
    for i, f in enumerate(freqs):
        s = retune(system, f)
        free[i] = linear_response(s, False)[1][idx]
        stuck[i] = linear_response(s, True, state)[1][idx] if state is not None else free[i]
    units = "m or rad (see response_unit)"
    return xr.Dataset(
        {
            "linear_free_amplitude": (("frequency", "response"), free, {"units": units}),
            "linear_stuck_amplitude": (("frequency", "response"), stuck, {"units": units}),
        },
        coords={"frequency": ("frequency", freqs, {"units": "Hz"}), "response": responses},
    )
