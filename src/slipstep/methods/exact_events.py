"""Exact event-driven dynamics (method ``events``, issue 28; equations in docs/exact_events.md).

Between two contact-state changes the paper's piecewise-linear laws make the system linear
with constant coefficients. In the contact state S (stick sliders w fixed):

    M a + C v + K_S x = F_S(t, w),   K_S = K + A^T K(S) A,
    F_S = f_c - A^T (K(S) g + s(S, w)) + sum_h Re[(F_h + A^T K(S) B P_h) exp(i Omega_h t)]

(physics.md 3: f = K(S) q + s(S, w), q = A x - B p(t) + g; F_h = Fc - i Fs and P_h the complex
amplitudes of the harmonic forces and motions). Its exact solution over a phase from t0:

    z(t) = z_p(t) + Re[ Phi exp(Lambda (t - t0)) eta0 ],     eta0 = Phi^-1 (z(t0) - z_p(t0))

with z = (x, v), the first-order matrix [[0, I], [-M^-1 K_S, -M^-1 C]] = Phi Lambda Phi^-1
(complex modal form), the particular solution x_p(t) = x_c + Re sum_h X_h exp(i Omega_h t),
K_S x_c = the constant load, (K_S - Omega_h^2 M + i Omega_h C) X_h = the harmonic amplitude.
The eigendecomposition, the factorisations and the margins' modal coefficients are computed
once per contact state and cached (:class:`StateModel`, keyed by the state's bytes).

The state holds while every margin of the state table stays >= 0 (per contact in contact
v >= 0, lifted -v >= 0; per direction in stick mu k_n v -/+ k_t (u - w) >= 0, in slip+/-
+/-(k_t du/dt - /+ ...) = k_t dw/dt (sign) >= 0, the slider moving with the force). The first
zero of a margin on the exact solution is found by kernels/exact_events.py (sampling at a
safe sub-step, bracket, Illinois to round-off). At the event the sliders take their
value (slip: w = u - T / k_t, lift-off: w = u), and the contacts whose margins vanish there
choose their new state by the sign of a second-order Taylor prediction of their trial force
and gap a short probe time ahead (state-independent: forces, hence accelerations, are
continuous at a switch), the rate-independent rule "stick when stick can hold". A run of
more than MAX_FLIPS switches at one instant, or more than ``max_events`` in the run, stops
with status EVENT_CAP naming the time and the contact.

A contact state whose K_S is singular (a free rigid mode: a damper in lift-off, a body with
no structural stiffness in slip), whose first-order matrix is defective or whose dynamic
stiffness is singular at an excitation frequency (resonance) has no such modal form: its
phases are marched by the exponential of the augmented autonomous system (Van Loan,
:class:`AugmentedPhase`), exact as well, with the same margins and root finding in Python.

Refused (InputError): the friction circle ('3d-circle'), tabulated loads or motions, ramps,
the banded backend, a singular mass matrix.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from slipstep.methods.blas import one_blas_thread
from slipstep.errors import SolverError, Status
from slipstep.kernels import exact_events as KE
from slipstep.kernels.codes import LIFT, SLIP_NEG, SLIP_POS, STATE_NAMES, STICK
from slipstep.methods.plan import RunPlan, plan_run
from slipstep.model.system import System

#: margin tolerance, relative to the margin's scale (force: mu k_n L + k_t L; gap: L; rate: force / time scale)
MARGIN_RTOL = 1e-12
#: sampling sub-step h = SAMPLE_FACTOR / omega_max (omega_max: the fastest term of the phase)
SAMPLE_FACTOR = 0.5
#: the Taylor probe of the state choice at an event, in units of h
PROBE_FACTOR = 1e-5
#: roots within TOGETHER_FACTOR h of the first are one event
TOGETHER_FACTOR = 1e-9
#: switches at one instant (phases shorter than TOGETHER_FACTOR h) before EVENT_CAP
MAX_FLIPS = 20
#: default cap on the events of a run, per excitation period (or per millisecond without a period)
EVENTS_PER_PERIOD = 10_000

# margin kinds
K_CONTACT, K_LIFT, K_STICK_POS, K_STICK_NEG, K_SLIP_POS, K_SLIP_NEG = range(6)


# ---------------------------------------------------------------------------------------
# the system's arrays
# ---------------------------------------------------------------------------------------
class Model:
    """The arrays of a compiled system the exact march reads, and its excitation as complex
    harmonics over the union of force and motion frequencies: F(t) = f_c + Re sum_h F_h
    exp(i Omega_h t), p(t) = Re sum_h P_h exp(i Omega_h t)."""

    def __init__(self, cs, system: System | None = None):
        self.cs = cs
        self.contact_names = list(system.contact_names) if system is not None else None
        self.direction_names = list(system.direction_names()) if system is not None else None
        self.M, self.C, self.K, self.A, self.B, self.g = cs.M, cs.C, cs.K, cs.A, cs.B, cs.g
        self.n, self.nq, self.nd, self.nc = cs.M.shape[0], cs.A.shape[0], cs.kt.shape[0], cs.normal_row.shape[0]
        self.mk = cs.law_par[:, 1] * cs.law_par[:, 0]  # mu k_n per contact
        self.kn = cs.law_par[:, 0]
        self.kt = np.asarray(cs.kt, float)
        self.trow, self.nrow = np.asarray(cs.tangential_row), np.asarray(cs.normal_row)
        self.owner = np.asarray(cs.direction_contact)
        self.first, self.ndir = np.asarray(cs.first_direction), np.asarray(cs.n_directions)
        freqs = sorted(set(np.round(np.concatenate([cs.force_frequency, cs.motion_frequency]), 12).tolist()))
        self.omega = 2 * np.pi * np.array([f for f in freqs if f != 0.0], float)
        H, m = self.omega.size, cs.B.shape[1]
        self.f_const = np.array(cs.constant_force, float)
        self.p_const = np.zeros(m)
        self.F = np.zeros((H, self.n), complex)
        self.P = np.zeros((H, m), complex)
        for what, freq, sin_c, cos_c in (
            ("F", cs.force_frequency, cs.force_sin, cs.force_cos),
            ("P", cs.motion_frequency, cs.motion_sin, cs.motion_cos),
        ):
            for k, f in enumerate(np.asarray(freq, float)):
                if round(f, 12) == 0.0:  # cos(0 t) = 1: a constant
                    (self.f_const if what == "F" else self.p_const)[:] += cos_c[:, k]
                    continue
                h = int(np.argmin(np.abs(self.omega - 2 * np.pi * f)))
                getattr(self, what)[h] += cos_c[:, k] - 1j * sin_c[:, k]
        self.length = float(cs.length_scale) if cs.length_scale > 0 else 1.0
        self.PB = self.P @ self.B.T  # (H, nq): the motions' harmonic amplitudes in q
        self.q_const = self.g - self.B @ self.p_const
        self.states: dict[bytes, StateModel] = {}

    def motion(self, t: np.ndarray, order: int = 0) -> np.ndarray:
        """d^order p / dt^order at the times t, shape (len(t), m)."""
        t = np.atleast_1d(np.asarray(t, float))
        out = np.zeros((t.size, self.B.shape[1]))
        if order == 0:
            out += self.p_const
        if self.omega.size:
            e = np.exp(1j * np.outer(t, self.omega)) * (1j * self.omega) ** order
            out += (e @ self.P).real
        return out

    def force(self, t: np.ndarray) -> np.ndarray:
        """f_e(t), shape (len(t), n)."""
        t = np.atleast_1d(np.asarray(t, float))
        out = np.zeros((t.size, self.n)) + self.f_const
        if self.omega.size:
            out += (np.exp(1j * np.outer(t, self.omega)) @ self.F).real
        return out

    def state_model(self, state: np.ndarray) -> "StateModel":
        """The cached :class:`StateModel` of a contact state (nd int8 codes)."""
        key = np.asarray(state, np.int8).tobytes()
        sm = self.states.get(key)
        if sm is None:
            sm = self.states[key] = StateModel.build(self, np.asarray(state, np.int8).copy())
        return sm

    def law_matrix(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(K(S) (nq, nq), Sw (nq, nd)): f = K(S) q + Sw w in the state S (physics.md 3)."""
        KS, Sw = np.zeros((self.nq, self.nq)), np.zeros((self.nq, self.nd))
        for c in range(self.nc):
            d0, nr = self.first[c], self.nrow[c]
            if state[d0] == LIFT:
                continue
            KS[nr, nr] = self.kn[c]
            for d in range(d0, d0 + self.ndir[c]):
                tr = self.trow[d]
                if state[d] == STICK:
                    KS[tr, tr] = self.kt[d]
                    Sw[tr, d] = -self.kt[d]
                else:
                    KS[tr, nr] = self.mk[c] if state[d] == SLIP_POS else -self.mk[c]
        return KS, Sw


@dataclass
class StateModel:
    """Everything of one contact state that does not depend on the phase (cached per state):
    K_S, the modal form Lambda, Phi, Phi^-1, the particular solution's parts
    (x_c = xc0 + Xw w; X_h), the margins (kinds, owners, q-rows Lq and qdot-rows Ld, the
    slider part Ew w), their modal rows E = (Lq A Phi_x + Ld A Phi_v) and harmonic rows,
    tolerances and the sampling sub-step h."""

    state: np.ndarray
    status: Status
    KS: np.ndarray
    Sw: np.ndarray
    KS_loc: np.ndarray = None
    QX: np.ndarray = None  # (H, nq) complex: A X_h
    lam: np.ndarray = None
    Phi: np.ndarray = None
    Phi_inv: np.ndarray = None
    xc0: np.ndarray = None
    Xw: np.ndarray = None
    X: np.ndarray = None  # (H, n) complex
    kinds: np.ndarray = None
    owners: np.ndarray = None
    Lq: np.ndarray = None
    Ld: np.ndarray = None
    Ew: np.ndarray = None
    E: np.ndarray = None
    bh: np.ndarray = None  # (nm, H) complex
    tol: np.ndarray = None
    h: float = math.nan
    problem: str = ""

    modal: bool = True  # False: the augmented exponential of :class:`AugmentedPhase` (Van Loan)
    G: np.ndarray = None  # (N, N) the augmented generator without the sliders' part (N = 2n + 1 + 2H)
    Gw: np.ndarray = None  # (n, nd) the sliders' part of its constant column (the v rows)
    Qz: np.ndarray = None  # (nq, N): q = Qz zeta
    Qdz: np.ndarray = None  # (nq, N): dq/dt = Qdz zeta
    Lz: np.ndarray = None  # (nm, N): the margins over zeta without the sliders' part (Ew w)

    @classmethod
    def build(cls, model: Model, state: np.ndarray) -> "StateModel":
        KS_loc, Sw = model.law_matrix(state)
        A, n = model.A, model.n
        KS = model.K + A.T @ KS_loc @ A
        sm = cls(state, Status.OK, KS, Sw, KS_loc)
        if not np.all(np.isfinite(KS)):
            sm.status, sm.problem = Status.NON_FINITE, "K + A^T K(S) A is not finite"
            return sm
        sm._margin_rows(model)
        Minv = np.linalg.inv(model.M)
        first = np.block([[np.zeros((n, n)), np.eye(n)], [-Minv @ KS, -Minv @ model.C]])
        why = sm._modal(model, first)
        if why:  # a free rigid mode, a defective matrix or a resonance: the augmented exponential
            sm.modal, sm.problem = False, why
            sm._augmented(model, Minv)
            lam = np.linalg.eigvals(first)
        else:
            lam = sm.lam
        scale = max(np.abs(lam).max(initial=0.0), model.omega.max(initial=0.0), 1e-300)
        sm.h = SAMPLE_FACTOR / scale
        sm._tolerances(model, scale)
        return sm

    def _modal(self, model: Model, first: np.ndarray) -> str:
        """The modal form (module docstring); '' when it holds, else why not."""
        A, n, KS, KS_loc = model.A, model.n, self.KS, self.KS_loc
        if np.linalg.cond(KS) > 1e11:  # particular solution: K_S x_c = f_c - A^T (K(S)(g - B p_c) + Sw w)
            return "K + A^T K(S) A is singular (a free rigid mode)"
        rhs0 = model.f_const - A.T @ (KS_loc @ model.q_const)
        both = np.linalg.solve(KS, np.column_stack([rhs0, -A.T @ self.Sw]))
        self.xc0, self.Xw = both[:, 0], both[:, 1:]
        self.X = np.zeros((model.omega.size, n), complex)
        for h, om in enumerate(model.omega):
            D = KS - om**2 * model.M + 1j * om * model.C
            if np.linalg.cond(D) > 1e13:
                return f"the excitation at {om / 2 / np.pi:g} Hz is at a resonance of the state"
            self.X[h] = np.linalg.solve(D, model.F[h] + A.T @ (KS_loc @ (model.B @ model.P[h])))
        # eigenvectors of the balanced matrix D^-1 Q_S D, D = diag(I, omega_s I): x and v / omega_s
        # of one size, so that cond(Phi_s) measures defectiveness, not the units of v
        n2 = first.shape[0] // 2
        omega_s = max(math.sqrt(np.abs(first[n2:, :n2]).sum(axis=1).max(initial=0.0)), 1e-300)
        d = np.concatenate([np.ones(n2), np.full(n2, omega_s)])
        lam, Phi_s = np.linalg.eig(first * d[None, :] / d[:, None])
        if np.linalg.cond(Phi_s) > 1e8:
            return "the first-order matrix is defective"
        Phi = Phi_s * d[:, None]
        self.lam, self.Phi, self.Phi_inv = lam, Phi, np.linalg.inv(Phi_s) / d[None, :]
        self.QX = self.X @ A.T
        self.E = np.ascontiguousarray(self.Lq @ A @ Phi[:n] + self.Ld @ A @ Phi[n:])
        qh = self.QX - model.PB  # (H, nq): harmonic amplitudes of q
        self.bh = np.ascontiguousarray((qh @ self.Lq.T + (1j * model.omega)[:, None] * (qh @ self.Ld.T)).T)
        return ""

    def _augmented(self, model: Model, Minv: np.ndarray) -> None:
        """The autonomous augmented system zeta = (x, v, 1, cos W_h t, sin W_h t, ...),
        d zeta/dt = G zeta (Van Loan), exact for any K_S, C (rigid modes, defective matrices,
        resonance); q = Qz zeta, dq/dt = Qdz zeta, the margins Lz zeta + Ew w."""
        A, B, n, H = model.A, model.B, model.n, model.omega.size
        N = 2 * n + 1 + 2 * H
        G, Qz, Qdz = np.zeros((N, N)), np.zeros((model.nq, N)), np.zeros((model.nq, N))
        G[:n, n : 2 * n] = np.eye(n)
        G[n : 2 * n, :n], G[n : 2 * n, n : 2 * n] = -Minv @ self.KS, -Minv @ model.C
        G[n : 2 * n, 2 * n] = Minv @ (model.f_const - A.T @ (self.KS_loc @ model.q_const))
        Qz[:, :n], Qz[:, 2 * n], Qdz[:, n : 2 * n] = A, model.q_const, A
        for h, om in enumerate(model.omega):
            ic, js = 2 * n + 1 + 2 * h, 2 * n + 2 + 2 * h
            amp = model.F[h] + A.T @ (self.KS_loc @ (B @ model.P[h]))  # Re[amp e^{iWt}] = Re amp cos - Im amp sin
            G[n : 2 * n, ic], G[n : 2 * n, js] = Minv @ amp.real, -Minv @ amp.imag
            G[ic, js], G[js, ic] = -om, om
            P = model.P[h]
            Qz[:, ic], Qz[:, js] = -B @ P.real, B @ P.imag
            Qdz[:, ic], Qdz[:, js] = om * (B @ P.imag), om * (B @ P.real)
        self.G, self.Gw, self.Qz, self.Qdz = G, Minv @ (-A.T @ self.Sw), Qz, Qdz
        self.Lz = self.Lq @ Qz + self.Ld @ Qdz

    def _margin_rows(self, model: Model) -> None:
        """The margins of the state table as rows over (q, qdot, w) (module docstring)."""
        rows = []  # (kind, owner, {q row: coef}, {qdot row: coef}, {direction: coef})
        st = self.state
        for c in range(model.nc):
            d0, nr, mk = model.first[c], model.nrow[c], model.mk[c]
            if st[d0] == LIFT:
                rows.append((K_LIFT, c, {nr: -1.0}, {}, {}))
                continue
            rows.append((K_CONTACT, c, {nr: 1.0}, {}, {}))
            for d in range(d0, d0 + model.ndir[c]):
                tr, kt = model.trow[d], model.kt[d]
                if st[d] == STICK:
                    rows.append((K_STICK_POS, d, {nr: mk, tr: -kt}, {}, {d: kt}))
                    rows.append((K_STICK_NEG, d, {nr: mk, tr: kt}, {}, {d: -kt}))
                elif st[d] == SLIP_POS:
                    rows.append((K_SLIP_POS, d, {}, {tr: kt, nr: -mk}, {}))
                else:
                    rows.append((K_SLIP_NEG, d, {}, {tr: -kt, nr: -mk}, {}))
        nm = len(rows)
        self.kinds = np.array([r[0] for r in rows], np.int64)
        self.owners = np.array([r[1] for r in rows], np.int64)
        self.Lq, self.Ld, self.Ew = np.zeros((nm, model.nq)), np.zeros((nm, model.nq)), np.zeros((nm, model.nd))
        for j, (_, _, lq, ld, ew) in enumerate(rows):
            for k, v in lq.items():
                self.Lq[j, k] += v
            for k, v in ld.items():
                self.Ld[j, k] += v
            for k, v in ew.items():
                self.Ew[j, k] += v

    def _tolerances(self, model: Model, scale: float) -> None:
        L, tol = model.length, np.empty(self.kinds.size)
        for j, (kind, owner) in enumerate(zip(self.kinds, self.owners)):
            if kind in (K_CONTACT, K_LIFT):
                tol[j] = MARGIN_RTOL * L
            else:
                force = (model.mk[model.owner[owner]] + model.kt[owner]) * L
                tol[j] = MARGIN_RTOL * force * (scale if kind in (K_SLIP_POS, K_SLIP_NEG) else 1.0)
        self.tol = tol

    def x_const(self, w: np.ndarray) -> np.ndarray:
        return self.xc0 + self.Xw @ w

    def particular(self, model: Model, t: np.ndarray, xc: np.ndarray, order: int = 0) -> np.ndarray:
        """d^order x_p / dt^order at the times t, shape (len(t), n)."""
        t = np.atleast_1d(np.asarray(t, float))
        out = np.zeros((t.size, model.n)) + (xc if order == 0 else 0.0)
        if model.omega.size:
            out += ((np.exp(1j * np.outer(t, model.omega)) * (1j * model.omega) ** order) @ self.X).real
        return out


# ---------------------------------------------------------------------------------------
# phases and the march
# ---------------------------------------------------------------------------------------
@dataclass
class Phase:
    """One linear phase: the state model, its start t0 and end t1 [s], the sliders w of the
    phase, the constant particular solution x_c and the modal initial condition eta0."""

    sm: StateModel
    t0: float
    t1: float
    w: np.ndarray
    xc: np.ndarray
    eta0: np.ndarray

    @classmethod
    def start(cls, model: Model, sm: StateModel, t0: float, x0, v0, w) -> "Phase":
        xc = sm.x_const(w)
        eh = np.exp(1j * model.omega * t0)
        zp = np.concatenate([xc + (eh @ sm.X).real, ((eh * 1j * model.omega) @ sm.X).real])
        eta0 = sm.Phi_inv @ (np.concatenate([x0, v0]) - zp)
        return cls(sm, float(t0), math.inf, np.array(w, float), xc, eta0)

    def point(self, model: Model, t: float) -> tuple:
        """(x, v, a, q, qd, qdd) at one time t: the DOFs and q = A x - B p + g with its rates."""
        sm, n, om = self.sm, model.n, model.omega
        ek = np.exp(sm.lam * (t - self.t0)) * self.eta0
        y = sm.Phi @ ek
        e0 = np.exp(1j * om * t)
        e1, e2 = e0 * (1j * om), e0 * (-(om**2))
        x = y[:n].real + self.xc + (e0 @ sm.X).real
        v = y[n:].real + (e1 @ sm.X).real
        a = (sm.Phi[n:] @ (ek * sm.lam)).real + (e2 @ sm.X).real
        A = model.A
        q = A @ y[:n].real + A @ self.xc + (e0 @ (sm.QX - model.PB)).real + model.q_const
        qd = A @ v - (e1 @ model.PB).real
        qdd = A @ a - (e2 @ model.PB).real
        return x, v, a, q, qd, qdd

    def dofs(self, model: Model, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, v, a) at the times t (each (len(t), n)): the exact solution of the phase."""
        t = np.atleast_1d(np.asarray(t, float))
        n, sm = model.n, self.sm
        e = np.exp(np.outer(t - self.t0, sm.lam)) * self.eta0
        x = (e @ sm.Phi[:n].T).real + sm.particular(model, t, self.xc, 0)
        v = (e @ sm.Phi[n:].T).real + sm.particular(model, t, self.xc, 1)
        a = ((e * sm.lam) @ sm.Phi[n:].T).real + sm.particular(model, t, self.xc, 2)
        return x, v, a

    def margin_coefficients(self, model: Model):
        """(a, c0): the margins' modal coefficients and constants for this phase's start."""
        sm = self.sm
        c0 = sm.Lq @ (model.A @ self.xc + model.q_const) + sm.Ew @ self.w
        return np.ascontiguousarray(sm.E * self.eta0[None, :]), c0

    def first_crossing(self, model: Model, tau_max: float, together: float, roots: np.ndarray) -> tuple:
        """(status, tau, j) of kernels.exact_events.first_crossing over (0, tau_max]."""
        a, c0 = self.margin_coefficients(model)
        sm = self.sm
        return KE.first_crossing(sm.lam, a, c0, model.omega, sm.bh, self.t0, tau_max, sm.h, sm.tol, together, roots)


@dataclass
class AugmentedPhase:
    """A phase whose state has no modal form (a free rigid mode, a defective matrix, a
    resonance): zeta(t) = expm(G (t - t0)) zeta0 on the augmented system of
    :meth:`StateModel._augmented` (Van Loan), exact for any K_S and C. Its margins are
    L zeta(t) (L = Lz with the sliders' part); their first crossing is found as in
    kernels/exact_events.py (sampling at h by the one-step propagator expm(G h), a crossing
    below -tol or a dip, the root by Brent's method on L expm(G tau) zeta0), in Python: a
    fallback for the few phases that need it."""

    sm: StateModel
    t0: float
    t1: float
    w: np.ndarray
    G: np.ndarray
    L: np.ndarray
    zeta0: np.ndarray

    @classmethod
    def start(cls, model: Model, sm: StateModel, t0: float, x0, v0, w) -> "AugmentedPhase":
        n = model.n
        G, L = sm.G.copy(), sm.Lz.copy()
        G[n : 2 * n, 2 * n] += sm.Gw @ w
        L[:, 2 * n] += sm.Ew @ w
        harmonics = np.ravel(np.column_stack([np.cos(model.omega * t0), np.sin(model.omega * t0)]))
        zeta0 = np.concatenate([x0, v0, [1.0], harmonics])
        return cls(sm, float(t0), math.inf, np.array(w, float), G, L, zeta0)

    def zeta(self, t: float) -> np.ndarray:
        from scipy.linalg import expm

        return expm(self.G * (t - self.t0)) @ self.zeta0

    def point(self, model: Model, t: float) -> tuple:
        """(x, v, a, q, qd, qdd) at one time t."""
        n, sm = model.n, self.sm
        z = self.zeta(t)
        dz = self.G @ z
        return z[:n], z[n : 2 * n], dz[n : 2 * n], sm.Qz @ z, sm.Qdz @ z, sm.Qdz @ dz

    def dofs(self, model: Model, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, v, a) at the times t (each (len(t), n))."""
        n = model.n
        z = np.array([self.zeta(tk) for tk in np.atleast_1d(np.asarray(t, float))])
        dz = z @ self.G.T
        return z[:, :n], z[:, n : 2 * n], dz[:, n : 2 * n]

    def first_crossing(self, model: Model, tau_max: float, together: float, roots: np.ndarray) -> tuple:
        """(status, tau, j) as kernels.exact_events.first_crossing (class docstring)."""
        from scipy.linalg import expm

        sm, G, L = self.sm, self.G, self.L
        roots[:] = -1.0
        if roots.size == 0:
            return KE.NO_CROSSING, tau_max, -1
        step = expm(G * sm.h)
        z = self.zeta0
        m0, d0 = L @ z, L @ (G @ z)
        lo, n_int = 0.0, max(int(math.ceil(tau_max / sm.h)), 1)
        for i in range(1, n_int + 1):
            hi = tau_max if i == n_int else i * sm.h
            z = step @ z if i < n_int else expm(G * hi) @ self.zeta0
            m1, d1 = L @ z, L @ (G @ z)
            for j in range(roots.size):
                roots[j] = self._root(j, lo, m0[j], d0[j], hi, m1[j], d1[j], sm.tol[j])
            if np.any(roots >= 0.0):
                first = roots[roots >= 0.0].min()
                roots[roots > first + together] = -1.0
                return KE.CROSSING, float(first), int(np.argmin(np.where(roots >= 0.0, roots, np.inf)))
            m0, d0, lo = m1, d1, hi
        return KE.NO_CROSSING, tau_max, -1

    def _root(self, j, lo, m_lo, d_lo, hi, m_hi, d_hi, tol) -> float:
        """The first root of margin j in [lo, hi] below -tol, or -1 (kernels/exact_events._root_in)."""
        from scipy.linalg import expm
        from scipy.optimize import brentq

        def m(tau, shift=0.0):
            return float(self.L[j] @ (expm(self.G * tau) @ self.zeta0)) - shift

        def d(tau):
            return float(self.L[j] @ (self.G @ (expm(self.G * tau) @ self.zeta0)))

        xtol = 4 * np.finfo(float).eps * (abs(self.t0) + abs(hi)) + 1e-300
        rtol = 4 * np.finfo(float).eps
        if m_hi < -tol:
            if m_lo > 0.0:
                return brentq(m, lo, hi, xtol=xtol, rtol=rtol)
            if m_lo + tol > 0.0:
                return brentq(m, lo, hi, args=(-tol,), xtol=xtol, rtol=rtol)
            return lo
        if d_lo < 0.0 < d_hi and m_lo > 0.0:
            t_min = brentq(d, lo, hi, xtol=xtol, rtol=rtol)
            if m(t_min) < -tol:
                return brentq(m, lo, t_min, xtol=xtol, rtol=rtol)
        return -1.0


def contact_quantities(model: Model, state: np.ndarray, x, v, a, t, w_phase):
    """(q, qd, qdd, f, w) at the times t of a phase in ``state`` with the stick sliders
    ``w_phase``: q = A x - B p + g and its rates, the law's forces f = K(S) q + Sw w and the
    sliders (stick: w_phase; slip: u - T / k_t; lift-off: u)."""
    A, B = model.A, model.B
    q = x @ A.T - model.motion(t, 0) @ B.T + model.g
    qd = v @ A.T - model.motion(t, 1) @ B.T
    qdd = a @ A.T - model.motion(t, 2) @ B.T
    KS, Sw = model.law_matrix(state)
    f = q @ KS.T + (Sw @ w_phase)[None, :]
    u = q[:, model.trow]
    T = f[:, model.trow]
    w = np.where(state == STICK, w_phase[None, :], u - T / model.kt)
    return q, qd, qdd, f, w


@dataclass
class Trajectory:
    """The exact march: its phases (each valid on [t0, t1]), the event times and the contact
    of each event, status and message, and :meth:`evaluate` at any times."""

    model: Model
    phases: list = field(default_factory=list)
    event_times: list = field(default_factory=list)
    event_contacts: list = field(default_factory=list)
    status: Status = Status.OK
    message: str = ""
    t_end: float = 0.0
    wall_time_s: float = 0.0

    @property
    def events(self) -> int:
        return len(self.event_times)

    def evaluate(self, t) -> dict:
        """x, v, a, q, f, w, state at the times t (sorted, within the march): the phase
        holding each time evaluated exactly there."""
        with one_blas_thread():
            return self._evaluate(np.atleast_1d(np.asarray(t, float)))

    def _evaluate(self, t: np.ndarray) -> dict:
        model = self.model
        starts = np.array([p.t0 for p in self.phases])
        which = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.phases) - 1)
        n, nq, nd = model.n, model.nq, model.nd
        out = {
            "x": np.empty((t.size, n)),
            "v": np.empty((t.size, n)),
            "a": np.empty((t.size, n)),
            "q": np.empty((t.size, nq)),
            "qd": np.empty((t.size, nq)),
            "f": np.empty((t.size, nq)),
            "w": np.empty((t.size, nd)),
            "state": np.empty((t.size, nd), np.int8),
        }
        for k in np.unique(which):
            idx = np.nonzero(which == k)[0]
            ph = self.phases[k]
            x, v, a = ph.dofs(model, t[idx])
            q, qd, _, f, w = contact_quantities(model, ph.sm.state, x, v, a, t[idx], ph.w)
            for key, val in (("x", x), ("v", v), ("a", a), ("q", q), ("qd", qd), ("f", f), ("w", w)):
                out[key][idx] = val
            out["state"][idx] = ph.sm.state
        return out


def energy_balance(traj: Trajectory, nodes: int = 16, t_from: float | None = None, t_to: float | None = None) -> dict:
    """The energy balance of a march, every term integrated on the exact solution by
    Gauss-Legendre quadrature (``nodes`` points per sub-interval of at most 2 h of each phase):

        E(t_end) - E(t_0) = W_in - D_visc - D_fric,
        E = v^T M v / 2 + x^T K x / 2 + sum k_n v_n^2 / 2 (closed contacts) + sum T^2 / (2 k_t),
        W_in = int f_e . v - f . B dp/dt,   D_visc = int v^T C v,   D_fric = int sum T dw/dt

    (dot the equation of motion with v; the contact power f . dq/dt splits into the springs'
    stored power and the sliders' T dw/dt). Returns the terms [J] (``friction_per_direction``:
    D_fric per tangential direction) and ``residual``, the
    left side minus the right, which an exact solution makes zero to round-off. ``t_from``,
    ``t_to``: the window [s] (default the whole march)."""
    model = traj.model
    lo = traj.phases[0].t0 if t_from is None else float(t_from)
    hi = min(traj.phases[-1].t1, traj.t_end) if t_to is None else float(t_to)
    xg, wg = np.polynomial.legendre.leggauss(nodes)
    w_in = d_visc = 0.0
    d_fric = np.zeros(model.nd)
    for ph in traj.phases:
        t0, t1 = max(ph.t0, lo), min(ph.t1, traj.t_end, hi)
        if t1 <= t0:
            continue
        m = max(int(math.ceil((t1 - t0) / (2 * ph.sm.h))), 1)
        edges = np.linspace(t0, t1, m + 1)
        half = 0.5 * np.diff(edges)
        t = (0.5 * (edges[:-1] + edges[1:])[:, None] + half[:, None] * xg[None, :]).ravel()
        wt = (half[:, None] * wg[None, :]).ravel()
        x, v, a = ph.dofs(model, t)
        q, qd, _, f, _ = contact_quantities(model, ph.sm.state, x, v, a, t, ph.w)
        p_in = np.einsum("ij,ij->i", model.force(t), v) - np.einsum("ij,ij->i", f, model.motion(t, 1) @ model.B.T)
        p_visc = np.einsum("ij,jk,ik->i", v, model.C, v)
        wdot = np.zeros((t.size, model.nd))
        for d in range(model.nd):
            c, st = model.owner[d], ph.sm.state[d]
            if st in (SLIP_POS, SLIP_NEG):
                sign = 1.0 if st == SLIP_POS else -1.0
                wdot[:, d] = qd[:, model.trow[d]] - sign * model.mk[c] * qd[:, model.nrow[c]] / model.kt[d]
        w_in += wt @ p_in
        d_visc += wt @ p_visc
        d_fric += wt @ (f[:, model.trow] * wdot)
    e0, e1 = stored_energy(traj, lo), stored_energy(traj, hi)
    return {
        "input_work": w_in,
        "viscous_dissipation": d_visc,
        "friction_dissipation": float(d_fric.sum()),
        "friction_per_direction": d_fric,
        "stored_energy_change": e1 - e0,
        "residual": (e1 - e0) - (w_in - d_visc - float(d_fric.sum())),
    }


def stored_energy(traj: Trajectory, t: float) -> float:
    """E(t) of :func:`energy_balance`: kinetic, structural strain and contact springs [J]."""
    model = traj.model
    r = traj.evaluate([t])
    x, v, q, f = r["x"][0], r["v"][0], r["q"][0], r["f"][0]
    closed = r["state"][0][model.first] != LIFT
    normal = 0.5 * np.sum(np.where(closed, model.kn * q[model.nrow] ** 2, 0.0))
    return float(0.5 * v @ model.M @ v + 0.5 * x @ model.K @ x + normal + 0.5 * np.sum(f[model.trow] ** 2 / model.kt))


def select_states(model: Model, state, q, qd, qdd, w, contacts, directions, delta) -> np.ndarray:
    """The new states of the listed contacts (normal and every direction) and directions at an
    event: by the sign of the gap and of the trial force against the limit a probe time
    ``delta`` ahead, from their second-order Taylor expansions (q, qd, qdd: state-independent at
    a switch). Stick wins when it can hold; a contact that closes starts with w = u (T* = 0)."""
    new = np.array(state, np.int8)
    ahead = q + qd * delta + 0.5 * qdd * delta**2
    chosen = {int(d) for d in directions}
    for c in contacts:
        d0, nd = model.first[c], model.ndir[c]
        closed = ahead[model.nrow[c]] > 0.0
        if not closed:
            new[d0 : d0 + nd] = LIFT
            continue
        if state[d0] == LIFT:
            new[d0 : d0 + nd] = STICK
        chosen.update(range(d0, d0 + nd))
    for d in sorted(chosen):
        c = model.owner[d]
        if new[d] == LIFT:
            continue
        limit = model.mk[c] * ahead[model.nrow[c]]
        trial = model.kt[d] * (ahead[model.trow[d]] - w[d])
        new[d] = SLIP_POS if trial > limit else (SLIP_NEG if trial < -limit else STICK)
    return new


def march(model: Model, t0: float, x0, v0, w0, state0, t_end: float, max_events: int) -> Trajectory:
    """The exact march from (x0, v0, w0) at t0 to t_end (module docstring), BLAS on one thread."""
    with one_blas_thread():
        return _march(model, t0, x0, v0, w0, state0, t_end, max_events)


def _march(model: Model, t0: float, x0, v0, w0, state0, t_end: float, max_events: int) -> Trajectory:
    start = time.perf_counter()
    traj = Trajectory(model, t_end=float(t_end))
    x, v, w = np.array(x0, float), np.array(v0, float), np.array(w0, float)
    state = np.array(state0, np.int8)
    # the state at the start: every contact chosen as at an event
    sm = model.state_model(state)
    h = sm.h if sm.status == Status.OK else 1.0 / max(model.omega.max(initial=1.0), 1.0)
    a = _acceleration(model, state, x, v, w, t0)
    q, qd, qdd = _local(model, x, v, a, t0)
    w = np.where(state == LIFT, q[model.trow], w)
    state = select_states(model, state, q, qd, qdd, w, range(model.nc), range(model.nd), PROBE_FACTOR * h)
    t, flips = float(t0), 0
    roots = np.empty(2 * model.nd + model.nc)
    while True:
        sm = model.state_model(state)
        if sm.status != Status.OK:
            traj.status = sm.status
            traj.message = f"{sm.problem} in the contact state {_state_text(model, state)} at t = {t:.9g} s"
            break
        phase = (Phase if sm.modal else AugmentedPhase).start(model, sm, t, x, v, w)
        traj.phases.append(phase)
        together = TOGETHER_FACTOR * sm.h
        status, tau, j = phase.first_crossing(model, t_end - t, together, roots[: sm.kinds.size])
        if status == KE.NO_CROSSING:
            phase.t1 = float(t_end)
            break
        t_new = t + tau
        phase.t1 = t_new
        x, v, a, q, qd, qdd = phase.point(model, t_new)
        u, T = q[model.trow], (sm.KS_loc @ q + sm.Sw @ phase.w)[model.trow]
        w = np.where(state == STICK, phase.w, u - T / model.kt)  # sliders at the event (lift-off: T = 0, w = u)
        hit = np.nonzero(roots[: sm.kinds.size] >= 0.0)[0]
        contacts = sorted({int(sm.owners[i]) for i in hit if sm.kinds[i] in (K_CONTACT, K_LIFT)})
        directions = sorted({int(sm.owners[i]) for i in hit if sm.kinds[i] not in (K_CONTACT, K_LIFT)})
        new = select_states(model, state, q, qd, qdd, w, contacts, directions, PROBE_FACTOR * sm.h)
        if np.array_equal(new, state):  # the probe saw no change: the margin that crossed decides
            new = _switched(model, state, int(sm.kinds[j]), int(sm.owners[j]), q, qd, w)
        who = contacts[0] if contacts else int(model.owner[directions[0]])
        traj.event_times.append(t_new)
        traj.event_contacts.append(who)
        flips = flips + 1 if tau <= together or np.array_equal(new, state) else 0
        if flips > MAX_FLIPS or len(traj.event_times) > max_events:
            traj.status = Status.EVENT_CAP
            why = f"{MAX_FLIPS} state changes at one instant" if flips > MAX_FLIPS else f"{max_events} events"
            traj.message = (
                f"{why} (chattering or an accumulation of events) at t = {t_new:.12g} s, contact "
                f"{model.contact_names[who] if model.contact_names else who}"
            )
            break
        state, t = new, t_new
    traj.wall_time_s = time.perf_counter() - start
    return traj


def _switched(model: Model, state, kind: int, owner: int, q, qd, w) -> np.ndarray:
    """``state`` with the owner of the crossed margin switched as its kind says (stick -> slip
    of that sign, slip -> stick, contact -> lift-off, lift-off -> contact in stick)."""
    new = np.array(state, np.int8)
    if kind in (K_CONTACT, K_LIFT):
        d0, nd = model.first[owner], model.ndir[owner]
        new[d0 : d0 + nd] = LIFT if kind == K_CONTACT else STICK
    else:
        new[owner] = {K_STICK_POS: SLIP_POS, K_STICK_NEG: SLIP_NEG}.get(kind, STICK)
    return new


def _local(model: Model, x, v, a, t):
    t = np.array([t])
    q = model.A @ x - model.B @ model.motion(t, 0)[0] + model.g
    qd = model.A @ v - model.B @ model.motion(t, 1)[0]
    qdd = model.A @ a - model.B @ model.motion(t, 2)[0]
    return q, qd, qdd


def _acceleration(model: Model, state, x, v, w, t) -> np.ndarray:
    """a = M^-1 (f_e(t) - C v - K x - A^T f) with the law's force in ``state``."""
    KS, Sw = model.law_matrix(state)
    q, _, _ = _local(model, x, v, np.zeros_like(x), t)
    f = KS @ q + Sw @ w
    rhs = model.force(np.array([t]))[0] - model.C @ v - model.K @ x - model.A.T @ f
    return np.linalg.solve(model.M, rhs)


def _state_text(model: Model, state) -> str:
    names = getattr(model, "direction_names", None) or [f"d{d}" for d in range(model.nd)]
    return "(" + ", ".join(f"{nm}={STATE_NAMES[s]}" for nm, s in zip(names, state)) + ")"


# ---------------------------------------------------------------------------------------
# the run: plan, start, march, Dataset
# ---------------------------------------------------------------------------------------
def event_plan(system: System, **options) -> RunPlan:
    """plan_run of method ``events`` (refusals: plan.check_event_case, the banded backend) with
    its settings (the preload's ramp needs them); the output step is the plan's step."""
    options.setdefault("error_estimate", False)
    plan = plan_run(system, "events", **options)
    return plan if plan.settings is not None else plan.with_step(plan.dt)


def default_max_events(plan: RunPlan) -> int:
    """EVENTS_PER_PERIOD per excitation period of the run (per millisecond without a period)."""
    unit = plan.period if plan.period else 1e-3
    return int(EVENTS_PER_PERIOD * max(plan.t_end / unit, 1.0))


class ExactEventRun:
    """One system marched by the exact event-driven method (module docstring): the plan
    (:func:`event_plan`), the static preload (methods/start.py, as every method), the march
    (:func:`march`) and the result Dataset of slipstep.output.results on the output grid (the
    save plan's ``times``, else every plan.dt from 0 to t_end; ``every`` and ``last_periods``
    thin it). ``max_events``: the cap of state changes in the run (default
    :func:`default_max_events`)."""

    progress = False  # (the CLI sets these for the step marches; a march of events has no bar and no Ctrl-C stop)
    keep_interrupted = True

    def __init__(self, system: System, max_events: int | None = None, **options):
        from slipstep.methods.start import static_equilibrium

        self.plan = event_plan(system, **options)
        self.system = system
        self.model = Model(self.plan.compiled, system)
        self.start = static_equilibrium(self.plan)
        self.max_events = default_max_events(self.plan) if max_events is None else int(max_events)
        self.trajectory: Trajectory | None = None

    @property
    def status(self) -> Status | None:
        return None if self.trajectory is None else self.trajectory.status

    def march(self) -> Status:
        s = self.start
        self.trajectory = march(self.model, s.t, s.x, s.v, s.w, s.contact_state, s.t + self.plan.t_end, self.max_events)
        return self.trajectory.status

    def output_times(self) -> np.ndarray:
        """The output grid (class docstring), cut at the time the march reached."""
        plan, save = self.plan, self.plan.save_plan
        if save.times is not None:
            grid = np.asarray(save.times, float)
        else:
            step = plan.dt * save.every
            k = int(math.floor(plan.t_end / step + 1e-9))
            grid = np.arange(k + 1) * step
            if plan.t_end - grid[-1] > 1e-9 * step:
                grid = np.append(grid, plan.t_end)
            if math.isfinite(save.t_from):
                grid = grid[grid >= save.t_from - 1e-9 * step]
        reached = self.trajectory.phases[-1].t1 if self.trajectory.phases else 0.0
        return grid[grid <= min(reached, plan.t_end) * (1 + 1e-15) + 1e-300]

    def dataset(self):
        from types import SimpleNamespace

        from slipstep.methods.accuracy import no_estimate
        from slipstep.model.excitation import evaluate_compiled, motion_signal
        from slipstep.output.results import build_dataset

        traj, plan, save = self.trajectory, self.plan, self.plan.save_plan
        if traj is None:
            raise RuntimeError("call march() first")
        t = self.output_times()
        if t.size == 0:
            t = np.zeros(1)
        rows = traj.evaluate(t)
        steps = np.diff(t, prepend=t[0])
        out = SimpleNamespace(
            t=t,
            x=rows["x"][:, save.dofs],
            v=rows["v"][:, save.dofs],
            a=rows["a"][:, save.dofs],
            q=rows["q"][:, save.rows],
            f=rows["f"][:, save.rows],
            w=rows["w"][:, save.directions],
            state=rows["state"][:, save.directions],
            solves=np.zeros(t.size, np.int64),
            dt=steps,
            step=np.arange(t.size),
            dirs=save.directions,
            rows=save.rows,
        )
        message = Status.OK.message if traj.status == Status.OK else f"{traj.status.name}: {traj.message}"
        attrs = {
            "title": f"slipstep result: {self.system.name}, events",
            "case": self.system.name,
            "method": "events",
            "paper_method": plan.method.paper_label,
            "solver": "exact-events",
            "adaptive_step": False,
            "quasi_static": False,
            "scheme": "exact",
            "status": traj.status.name,
            "status_message": message,
            "steps": len(traj.phases),
            "solves": 0,
            "iterations": 0,
            "mean_solves_per_step": 0.0,
            "factorisations": len(self.model.states),
            "law_calls": 0,
            "redone_steps": 0,
            "state_changes": traj.events,
            "events": traj.events,
            "dt_s": plan.dt,
            "t_min_s": plan.t_min_stick,
            "t_end_s": plan.t_end,
            "period_s": plan.period,
            "step_ratio": plan.options.step_ratio,
            "max_step_s": plan.max_step,
            "kernel_time_s": traj.wall_time_s,
            "length_scale_m": plan.compiled.length_scale,
            "tolerance": MARGIN_RTOL,
            "state_tolerance": plan.options.state_tolerance,
            "linear_solver": "direct",
            "step_rule": "none (exact between events)",
            **no_estimate("exact between events (no time discretisation)"),
            **save.attrs(),
        }
        if traj.status != Status.OK and traj.event_times:
            attrs["failed_at_time_s"] = traj.event_times[-1]
        motion = evaluate_compiled(motion_signal(plan.compiled), t)
        return build_dataset(
            self.system, out, t.size - 1, motion, attrs, dynamic=True, compiled=plan.compiled, plan=save
        )

    def run(self, raise_on_failure: bool = False):
        """march() + dataset() (attr wall_time_s); SolverError on failure when asked."""
        start = time.perf_counter()
        self.march()
        ds = self.dataset()
        ds.attrs["wall_time_s"] = time.perf_counter() - start
        if raise_on_failure and self.status != Status.OK:
            raise SolverError(ds.attrs["status_message"], ds)
        return ds


def run(system: System, *, raise_on_failure: bool = False, max_events: int | None = None, **options):
    """``ss.run(system, "events", ...)``: :class:`ExactEventRun` (options: RunOptions)."""
    return ExactEventRun(system, max_events=max_events, **options).run(raise_on_failure=raise_on_failure)
