"""Energy balance of a result (physics.md section 1): where the work of the loads goes.

Equation of motion (paper Eq. 1) with q = A x - B p + g and the local contact force f
(the contact acts on the structure with -A^T f):

    M a + C v + K x + A^T f = f_e(t)

Dot it with v = dx/dt and use A v = dq/dt + B dp/dt:

    d/dt (1/2 v^T M v + 1/2 x^T K x) + v^T C v + f . dq/dt = f_e . v - f . B dp/dt

In contact, T = k_t (u - w) in stick AND in slip (slip: w = u - T / k_t), so with the
contact elastic energy E_c = 1/2 k_n v^2 + sum_d 1/2 k_t (u_d - w_d)^2 (0 in lift-off):

    f . dq/dt = dE_c/dt + sum_d T_d dw_d/dt

Integrated from the first stored time t_0 to t, the balance reads

    W_ext + W_mot = dE_kin + dE_el + dE_c + D_damp + D_fric

    E_kin  = 1/2 v^T M v                   kinetic energy (0 for quasi-static results)
    E_el   = 1/2 x^T K x                   structural elastic energy
    E_c    = sum_c 1/2 k_n v_c^2 + sum_d 1/2 k_t (u_d - w_d)^2   (v_c > 0 only)
    D_damp = int (C v) . dx                damping dissipation (>= 0)
    D_fric = sum_d int T_d dw_d            friction dissipation (>= 0)
    W_ext  = int f_e . dx                  work of the external forces (constant + varying)
    W_mot  = -int f . B dp                 work of the prescribed motions (the platforms)

Every integral is the trapezoid rule over the stored points, int F dy ~
sum 1/2 (F_n + F_{n+1}) (y_{n+1} - y_n). Along a Newmark average-acceleration trajectory
(beta = 1/4, gamma = 1/2) this discrete balance is EXACT for any piecewise-linear
contact law (x_{n+1} - x_n = dt/2 (v_n + v_{n+1}), v_{n+1} - v_n = dt/2 (a_n + a_{n+1})
make the kinetic and elastic terms telescope), up to the solver's convergence tolerance;
except on a step that crosses v = 0 (lift-off or re-contact). There the scheme's work of
the normal force is the trapezoid 1/2 (N_n + N_{n+1}) (v_{n+1} - v_n), while the normal
force is piecewise linear in v (N = k_n max(v, 0)): split at the crossing v = 0 the exact
work is the change of 1/2 k_n max(v, 0)^2. Their difference, the work the time
discretisation does at the crossing,

    W_cross = sum over crossing steps of [1/2 k_n (v+_{n+1}^2 - v+_n^2) - 1/2 (N_n + N_{n+1}) (v_{n+1} - v_n)]
            = sum of -1/2 k_n v_n v_{n+1}    (v+ = max(v, 0); > 0: energy the step created)

is booked as its own term (``crossing_work``, O(dt) per crossing, vanishing as dt -> 0), and
the balance W_ext + W_mot + W_cross = dE_kin + dE_el + dE_c + D_damp + D_fric closes to the
solver tolerance on those steps too. For quasi-static results the balance holds with
E_kin = D_damp = 0 (and W_cross = 0 up to the trapezoid of the static path). HHT / generalised-alpha steps do not satisfy it
exactly (their numerical dissipation appears as the residual).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from slipstep.model.excitation import compile_signal, evaluate_compiled
from slipstep.model.system import quadratic_form

_UNITS = "J"

_LONG_NAMES = {
    "kinetic": "kinetic energy 1/2 v^T M v",
    "elastic": "structural elastic energy 1/2 x^T K x",
    "contact_elastic": "contact elastic energy 1/2 k_n v^2 + 1/2 k_t (u - w)^2",
    "damping_dissipation": "cumulative damping dissipation int (C v) . dx",
    "friction_dissipation": "cumulative friction dissipation sum_d int T_d dw_d",
    "external_work": "cumulative work of the external forces int f_e . dx",
    "motion_work": "cumulative work of the prescribed motions -int f . B dp",
    "crossing_work": "cumulative work of the time discretisation on steps crossing v = 0 (exact split minus trapezoid)",
    "balance_residual": "W_ext + W_mot + W_cross - (dE_kin + dE_el + dE_c + D_damp + D_fric)",
}


def require_saved(ds: xr.Dataset, needs, what: str) -> None:
    """Refuse (InputError naming ``save``) a result that did not save what ``what`` needs:
    'all_dofs', 'all_contacts', 'every_step' (slipstep.output.results.saved)."""
    from slipstep.errors import InputError
    from slipstep.output.results import saved

    labels = {"all_dofs": "every DOF", "all_contacts": "every contact", "every_step": "every step"}
    missing = [labels[n] for n in needs if not saved(ds, n)]
    if missing:
        raise InputError(
            "save",
            f"of this result is {ds.attrs.get('save')!r}: {what} needs {' and '.join(missing)}",
            "run again with save='all' (command line: --save-dofs all --save-contacts all --save-every 1)",
        )


def _cumtrapz(F: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Cumulative trapezoid of sum_j F_j dy_j along axis 0 (F, y: (nt, k) or (nt,))."""
    F = F.reshape(F.shape[0], -1)
    y = y.reshape(y.shape[0], -1)
    inc = 0.5 * ((F[1:] + F[:-1]) * np.diff(y, axis=0)).sum(axis=1)
    return np.concatenate([[0.0], np.cumsum(inc)])


def _local_forces(ds: xr.Dataset, cs) -> np.ndarray:
    """The stacked local force vector f (nt, nq) in the row order of q = A x - B p + g."""
    nt = ds.sizes["time"]
    f = np.zeros((nt, cs.A.shape[0]))
    f[:, np.asarray(cs.tangential_row)] = ds["tangential_force"].values
    f[:, np.asarray(cs.normal_row)] = ds["normal_force"].values
    return f


def external_force(system, t: np.ndarray) -> np.ndarray:
    """f_e(t) [N] on the DOFs, shape (nt, n): constant loads + the varying force signal."""
    n = system.n_dofs
    f0 = system.excitation.constant_force
    fe = np.tile(np.zeros(n) if f0 is None else np.asarray(f0, float), (t.size, 1))
    if system.excitation.force is not None:
        fe += evaluate_compiled(compile_signal(system.excitation.force, n), t)
    return fe


def _crossing_work(vn: np.ndarray, N: np.ndarray, kn: np.ndarray) -> np.ndarray:
    """Cumulative W_cross (see the module docstring): on each step where a contact's normal
    approach changes sign, the exact work of N = k_n max(v, 0) split at v = 0 (the change of
    1/2 k_n max(v, 0)^2) minus the scheme's trapezoid 1/2 (N_n + N_{n+1}) dv."""
    vp = np.maximum(vn, 0.0)
    trapezoid = 0.5 * (N[1:] + N[:-1]) * np.diff(vn, axis=0)
    exact = 0.5 * kn * (vp[1:] ** 2 - vp[:-1] ** 2)
    crosses = (vn[1:] > 0.0) != (vn[:-1] > 0.0)
    inc = np.where(crosses, exact - trapezoid, 0.0).sum(axis=1)
    return np.concatenate([[0.0], np.cumsum(inc)])


def energy_balance(ds: xr.Dataset, system) -> xr.Dataset:
    """Energies (J) over time of a result ``ds`` of ``system``; see the module docstring.

    Returns a Dataset over ``time`` with kinetic, elastic, contact_elastic (state energies)
    and the cumulative damping_dissipation, friction_dissipation (also per direction as
    friction_dissipation_direction), external_work, motion_work from the first stored
    time, crossing_work (the discretisation's work on steps crossing lift-off or re-contact) and
    balance_residual = W_ext + W_mot + W_cross - (dE_kin + dE_el + dE_c + D_damp + D_fric).
    Attribute ``relative_residual``: max |balance_residual| / max(|W_ext| + |W_mot| +
    D_fric + D_damp over time).
    """
    require_saved(ds, ("all_dofs", "all_contacts", "every_step"), "the energy balance")
    cs = system.compile()
    t = ds["time"].values
    x = ds["displacement"].values
    dynamic = "velocity" in ds
    v = ds["velocity"].values if dynamic else np.zeros_like(x)
    p = ds["prescribed_motion"].values
    f = _local_forces(ds, cs)
    s = system.structure  # M, C, K in the user's DOF order (the results' order), dense or sparse
    M, C, K, B = s.mass, s.damping, s.stiffness, cs.B

    kinetic = 0.5 * quadratic_form(M, v)
    elastic = 0.5 * quadratic_form(K, x)

    u = ds["tangential_displacement"].values
    w = ds["slider"].values
    vn = ds["normal_displacement"].values
    in_contact = vn > 0.0
    kn = np.asarray(cs.kn)
    kt = np.asarray(cs.kt)
    owner = np.asarray(cs.direction_contact)
    e_normal = 0.5 * kn * np.where(in_contact, vn, 0.0) ** 2
    e_tangential = 0.5 * kt * np.where(in_contact[:, owner], u - w, 0.0) ** 2
    contact_elastic = e_normal.sum(axis=1) + e_tangential.sum(axis=1)

    T = ds["tangential_force"].values
    dw = np.diff(w, axis=0)
    fric_dir = np.vstack([np.zeros((1, w.shape[1])), np.cumsum(0.5 * (T[1:] + T[:-1]) * dw, axis=0)])
    friction = fric_dir.sum(axis=1)
    damping = _cumtrapz(np.asarray((C @ v.T).T), x) if dynamic else np.zeros(t.size)
    external = _cumtrapz(external_force(system, t), x)
    motion = -_cumtrapz(f @ B, p) if B.shape[1] else np.zeros(t.size)

    crossing = _crossing_work(vn, ds["normal_force"].values, kn)
    stored = kinetic + elastic + contact_elastic
    residual = external + motion + crossing - (stored - stored[0] + damping + friction)
    scale = np.max(np.abs(external) + np.abs(motion) + np.abs(friction) + np.abs(damping), initial=0.0)

    def var(values, name, dims=("time",)):
        return xr.Variable(dims, values, {"units": _UNITS, "long_name": _LONG_NAMES.get(name, name)})

    out = xr.Dataset(
        {
            "kinetic": var(kinetic, "kinetic"),
            "elastic": var(elastic, "elastic"),
            "contact_elastic": var(contact_elastic, "contact_elastic"),
            "damping_dissipation": var(damping, "damping_dissipation"),
            "friction_dissipation": var(friction, "friction_dissipation"),
            "friction_dissipation_direction": var(fric_dir, "friction_dissipation", ("time", "direction")),
            "external_work": var(external, "external_work"),
            "motion_work": var(motion, "motion_work"),
            "crossing_work": var(crossing, "crossing_work"),
            "balance_residual": var(residual, "balance_residual"),
        },
        coords={"time": ds["time"], "direction": ds["direction"], "direction_contact": ds["direction_contact"]},
        attrs={"relative_residual": float(np.abs(residual).max(initial=0.0) / scale) if scale > 0 else 0.0},
    )
    return out


def friction_energy_per_period(ds: xr.Dataset, period: float | None = None) -> xr.DataArray:
    """Friction energy [J] dissipated by each contact over the last ``period`` [s] of ``ds``
    (default: the run's excitation period, attribute period_s):

        D_c = sum_{d of c} int_{t_end - period}^{t_end} T_d dw_d     (trapezoid rule)

    On a non-uniform time grid the cumulative dissipation is interpolated linearly at
    t_end - period. Returns a DataArray over ``contact`` (units J).
    """
    if period is None:
        period = ds.attrs.get("period_s")
    if period is None or not np.isfinite(period) or period <= 0:
        raise ValueError("period: the result has no excitation period; pass period= (seconds)")
    require_saved(ds, ("every_step",), "the friction energy per period")
    t = ds["time"].values
    if t[-1] - t[0] < period * (1 - 1e-9):
        raise ValueError(f"period: the result lasts {t[-1] - t[0]:.6g} s, shorter than the period {period:.6g} s")
    T = ds["tangential_force"].values
    w = ds["slider"].values
    inc = 0.5 * (T[1:] + T[:-1]) * np.diff(w, axis=0)
    cum = np.vstack([np.zeros((1, w.shape[1])), np.cumsum(inc, axis=0)])
    start = t[-1] - period
    per_direction = cum[-1] - np.array([np.interp(start, t, cum[:, d]) for d in range(w.shape[1])])
    owner = ds["direction_contact"].values
    contacts = ds["contact"].values
    values = np.array([per_direction[owner == c].sum() for c in contacts])
    return xr.DataArray(
        values,
        coords={"contact": contacts},
        dims=("contact",),
        attrs={"units": _UNITS, "long_name": "friction energy dissipated over the last period"},
    )
