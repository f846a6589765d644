"""The method advisor (paper Sections 4.2 and 5.1, Eq. 8-9): which method suits a case, and why.

Quantities reported:

* Inertia-to-centrifugal ratio (paper Eq. 9), independent of the damper mass:
      rho = omega^2 x_d / (Omega^2 R),  omega = 2 pi f,  Omega = 2 pi rpm / 60
  and the frequency where rho reaches ``rho_limit`` (5 %):
      f_5% = sqrt(rho_limit Omega^2 R / x_d) / (2 pi)
  (3600 rpm, R = 0.5 m, x_d = 0.1 um: 30 kHz). Below it the damper's inertia is negligible
  and the quasi-static method (Method 4) applies.
* Per contact state S (kernels/codes.py STATE_NAMES, per direction; a coupled slip of the
  friction-circle law is analysed with its stiffest, stick, tangent): the
  eigenvalues lambda of M^-1 (K + K_D(S)), internal frequencies sqrt(lambda) / 2 pi and
  T_min = 2 pi / sqrt(max |lambda|) (paper Eq. 8); the Newmark average-acceleration step
  limit dt = T_min / pi and the steps per period it implies (full stick: the fixed step of
  Methods 1 and 3; per state: the adaptive step of Method 2).
* Singular states: K + K_D(S) has a zero eigenvalue (|lambda| < 1e-9 max |lambda|): no
  quasi-static equilibrium (all lifted off, or a mechanism); skipped for T_min, reported.
* Flutter (physics.md 8): in slip K_D is non-symmetric and lambda can be complex
  (|Im lambda| > 1e-6 max |lambda|): an undamped dynamic run grows an oscillation while the
  state lasts. Criterion: a flutter-prone state MATTERS when the case visits it; the
  visited states are those of a short quasi-static run and a short dynamic run
  (Method 3, which also enters the transient states the ringing produces). Complex
  states among all other combinations are listed separately as not visited: they are
  usually kinematically inadmissible for the loading (e.g. for the paper's wedge in gross
  slip the two faces always slip in opposite directions, so "all three slip+" cannot be
  reached), so the paper case is free of flutter in every state it visits, while the
  variant with mu = 0.5 at all points visits flutter-prone states and is reported.

* Quasi-static DOFs inside a dynamic structure (method quasi-static-dofs, issue 11): when
  some DOFs are held by contacts only (a damper between blades) and others are not, the
  damper's internal frequencies with the blades fixed (paper Remark 2) are compared with the
  excitation: when they are at least 5 times above it and 1 kHz away (Remark 3: the damper
  then acts only as a spring coupling, its ringing carries no physics) and, when given, the
  inertia ratio of Eq. 9 is below ``rho_limit``, the damper's DOFs can be treated without
  inertia while the blades stay dynamic; T_min then comes from the condensed dynamic part.
  Method 4 for the whole system is not recommended when such a dynamic part exists.

All state combinations are enumerated when their number is at most ``max_states``
(lift-off is per contact: prod_c (1 + 3^{directions of c}) combinations), else only the
visited ones.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from slipstep.errors import InputError, SolverError
from slipstep.methods import step_control as SC
from slipstep.methods.schemes import newmark
from slipstep.model.contact import COUPLED_SLIP_CODES
from slipstep.kernels.codes import LIFT, SLIP_COUPLED, SLIP_NEG, SLIP_POS, STATE_NAMES, STICK


def rpm_to_rad_s(rpm: float) -> float:
    """Omega [rad/s] = 2 pi rpm / 60."""
    return 2 * math.pi * rpm / 60.0


def inertia_ratio(
    frequency_Hz: float, displacement_amplitude_m: float, rotor_speed_rpm: float, radius_m: float
) -> float:
    """rho = omega^2 x_d / (Omega^2 R) (paper Eq. 9), dimensionless."""
    w = 2 * math.pi * frequency_Hz
    W = rpm_to_rad_s(rotor_speed_rpm)
    return w * w * displacement_amplitude_m / (W * W * radius_m)


def inertia_limit_frequency(
    displacement_amplitude_m: float, rotor_speed_rpm: float, radius_m: float, rho_limit: float = 0.05
) -> float:
    """f [Hz] at which rho reaches rho_limit: sqrt(rho_limit Omega^2 R / x_d) / (2 pi)."""
    for name, v in (
        ("displacement_amplitude_m", displacement_amplitude_m),
        ("rotor_speed_rpm", rotor_speed_rpm),
        ("radius_m", radius_m),
        ("rho_limit", rho_limit),
    ):
        if not (v > 0 and math.isfinite(v)):
            raise InputError(name, f"is {v}", "give a positive finite value")
    W = rpm_to_rad_s(rotor_speed_rpm)
    return math.sqrt(rho_limit * W * W * radius_m / displacement_amplitude_m) / (2 * math.pi)


@dataclass
class StateInfo:
    """Eigen-analysis of one contact state."""

    state: tuple[int, ...]
    frequencies_Hz: list[float]  # sqrt(Re lambda)/2pi of the non-zero eigenvalues, ascending
    t_min_s: float  # 2 pi / sqrt(max |lambda|) (inf if all zero)
    singular: bool
    complex_eigenvalues: bool
    max_imag_ratio: float  # max |Im lambda| / max |lambda|
    visited: bool = False

    def label(self, names: list[str]) -> str:
        return ", ".join(f"{n}={STATE_NAMES[s]}" for n, s in zip(names, self.state))


def analyse_state(cs, state) -> StateInfo:
    """Eigenvalues of M^-1 (K + K_D(S)) for one state; see the module docstring."""
    st = np.asarray(state, np.int8)
    ev = np.asarray(SC.state_eigenvalues(cs, st), complex)
    big = float(np.abs(ev).max(initial=0.0))
    singular = big == 0 or float(np.abs(ev).min()) < 1e-9 * big
    imag = float(np.abs(ev.imag).max(initial=0.0)) / big if big > 0 else 0.0
    nz = ev[np.abs(ev) > 1e-9 * big] if big > 0 else ev[:0]
    freqs = sorted(float(np.sqrt(abs(lam.real)) / (2 * math.pi)) for lam in nz)
    t_min = SC.t_min_of(big)
    return StateInfo(tuple(int(s) for s in st), freqs, t_min, bool(singular), imag > 1e-6, imag)


def enumerate_states(cs, max_states: int = 4096) -> list[tuple[int, ...]] | None:
    """All state combinations (lift-off shared by a contact's directions), or None when
    there are more than ``max_states``."""
    per_contact = []
    total = 1
    for c in range(cs.kn.shape[0]):
        nd = int(cs.n_directions[c])
        if int(cs.law[c]) in COUPLED_SLIP_CODES:  # the directions share every state
            opts = [(s,) * nd for s in (LIFT, STICK, SLIP_COUPLED)]
        else:
            opts = [(LIFT,) * nd] + list(itertools.product((STICK, SLIP_POS, SLIP_NEG), repeat=nd))
        per_contact.append(opts)
        total *= len(opts)
        if total > max_states:
            return None
    return [tuple(s for part in combo for s in part) for combo in itertools.product(*per_contact)]


def _visited(system, periods: float, notes: list[str]) -> tuple[set, dict]:
    """Visited states of a short quasi-static and a short Method-3 run, and run facts."""
    from slipstep.methods.simulation import run

    visited, facts = set(), {}
    for method, key in (("quasi-static", "quasi_static"), ("piecewise-linear", "dynamic")):
        try:
            ds = run(system, method, periods=periods)
        except (SolverError, InputError) as err:
            notes.append(f"the short {method} run could not be made ({err}); its states are not included")
            continue
        S = ds["contact_state"].values
        visited |= {tuple(int(v) for v in row) for row in np.unique(S, axis=0)}
        facts[key] = {
            "status": ds.attrs.get("status"),
            "steps": int(ds.attrs.get("steps", 0)),
            "states_visited": int(np.unique(S, axis=0).shape[0]),
        }
        if ds.attrs.get("status") != "OK":
            notes.append(f"the short {method} run stopped early: {ds.attrs.get('status_message')}")
    return visited, facts


@dataclass
class Advice:
    """The advisor's findings; ``text()`` is the plain-words report, ``to_dict()`` the data."""

    case: str
    directions: list[str]
    excitation_Hz: list[float]
    period_s: float | None
    rotor_speed_rpm: float | None
    radius_m: float | None
    displacement_amplitude_m: float | None
    inertia_ratio: float | None
    inertia_limit_Hz: float | None
    stick_t_min_s: float
    fixed_dt_s: float
    fixed_steps_per_period: int | None
    adaptive_steps_per_period_estimate: float | None
    states_enumerated: bool
    states: list[StateInfo]
    flutter_visited: list[tuple[int, ...]]
    flutter_not_visited: list[tuple[int, ...]]
    singular_states: list[tuple[int, ...]]
    singular_visited: list[tuple[int, ...]]
    recommendation: str
    reasons: list[str]
    notes: list[str] = field(default_factory=list)
    runs: dict = field(default_factory=dict)
    rho_limit: float = 0.05
    massless: dict | None = None  # the quasi-static-dofs analysis (module docstring), None if not applicable

    @property
    def flutter_free(self) -> bool:
        """True when no visited state has complex eigenvalues (module docstring)."""
        return not self.flutter_visited

    def to_dict(self) -> dict:
        d = asdict(self)
        d["flutter_free"] = self.flutter_free
        return d

    def _label(self, s) -> str:
        return "(" + ", ".join(f"{n}={STATE_NAMES[v]}" for n, v in zip(self.directions, s)) + ")"

    def text(self) -> str:
        """The report in plain words, with units."""
        L = [f"Method advice for case '{self.case}'"]
        if self.excitation_Hz:
            L.append(
                f"Excitation: {', '.join(f'{f:g} Hz' for f in self.excitation_Hz)}"
                + (f" (period {self.period_s * 1e3:.4g} ms)" if self.period_s else "")
            )
        if self.inertia_limit_Hz is not None:
            rho = "n/a" if self.inertia_ratio is None else f"{self.inertia_ratio:.3g}"
            L.append(
                f"Inertia vs centrifugal load (paper Eq. 9): rho = omega^2 x_d / (Omega^2 R) = "
                f"{rho} at the excitation; rho reaches {self.rho_limit:.0%} only at "
                f"{self.inertia_limit_Hz / 1e3:.4g} kHz (Omega = {self.rotor_speed_rpm:g} rpm, "
                f"R = {self.radius_m:g} m, x_d = {self.displacement_amplitude_m * 1e6:g} um)."
            )
        else:
            L.append("Inertia vs centrifugal load (Eq. 9): not evaluated (give rotor speed, radius and displacement).")
        capped = self.fixed_dt_s < self.stick_t_min_s / math.pi * (1 - 1e-9)
        L.append(
            f"Full stick: T_min = {self.stick_t_min_s * 1e6:.4g} us, T_min/pi = "
            f"{self.stick_t_min_s / math.pi * 1e6:.4g} us; fixed Newmark step "
            f"{self.fixed_dt_s * 1e6:.4g} us"
            + (" (accuracy cap: 50 steps per period)" if capped else "")
            + (f", {self.fixed_steps_per_period} steps per period" if self.fixed_steps_per_period else "")
        )
        if self.adaptive_steps_per_period_estimate:
            L.append(
                f"Adaptive step (Method 2) over the visited states: about "
                f"{self.adaptive_steps_per_period_estimate:.0f} steps per period"
            )
        L.append(
            f"Contact states analysed: {len(self.states)} "
            f"({'all combinations' if self.states_enumerated else 'visited states only'}); per visited state:"
        )
        for s in self.states:
            if s.visited:
                f = ", ".join(f"{v / 1e3:.3g}" for v in s.frequencies_Hz)
                tag = " SINGULAR (no quasi-static equilibrium)" if s.singular else ""
                tag += " COMPLEX EIGENVALUES (flutter)" if s.complex_eigenvalues else ""
                L.append(
                    f"  {self._label(s.state)}: f = [{f}] kHz, T_min = {s.t_min_s * 1e6:.4g} us, "
                    f"dt = {s.t_min_s / math.pi * 1e6:.4g} us{tag}"
                )
        if self.flutter_visited:
            L.append(
                "FLUTTER: the case visits state(s) whose M^-1 (K + K_D) has complex eigenvalues "
                "(friction-induced flutter; an undamped dynamic run grows an oscillation while they last): "
                + "; ".join(self._label(s) for s in self.flutter_visited)
            )
        else:
            L.append("Flutter: free of flutter in every state it visits (no complex eigenvalues).")
        if self.flutter_not_visited:
            L.append(
                f"  ({len(self.flutter_not_visited)} other state combination(s) have complex eigenvalues but "
                "are not visited by this loading: " + "; ".join(self._label(s) for s in self.flutter_not_visited) + ")"
            )
        if self.singular_states:
            L.append(
                f"States without a quasi-static equilibrium (K + K_D singular): {len(self.singular_states)}"
                + (
                    ", of which visited: " + "; ".join(self._label(s) for s in self.singular_visited)
                    if self.singular_visited
                    else ", none visited"
                )
            )
        if self.massless is not None:
            q = self.massless
            L.append(
                f"Quasi-static DOFs (held by contacts only): {', '.join(q['dofs'])}; their internal frequencies "
                f"with the rest fixed: {', '.join(f'{v / 1e3:.3g}' for v in q['internal_Hz'])} kHz; T_min of "
                f"the dynamic part {q['t_min_s'] * 1e6:.4g} us against {self.stick_t_min_s * 1e6:.4g} us "
                f"(step x{q['step_gain']:.3g}); method quasi-static-dofs "
                + ("applies" if q["applies"] else "does not apply")
                + f": {q['why']}"
            )
        L.append(f"Recommendation: {self.recommendation}")
        L += [f"  - {r}" for r in self.reasons]
        L += [f"Note: {n}" for n in self.notes]
        return "\n".join(L)


def advise(
    system,
    rotor_speed_rpm: float | None = None,
    radius_m: float | None = None,
    displacement_amplitude_m: float | None = None,
    rho_limit: float = 0.05,
    max_states: int = 4096,
    periods: float = 2.0,
    run_cases: bool = True,
) -> Advice:
    """Analyse ``system`` and recommend a method (module docstring). ``run_cases``: make the
    short quasi-static and Method-3 runs that find the visited states (else: full stick
    and, when enumerated, every state are treated as candidates but none as visited)."""
    from slipstep.post.filtering import excitation_frequencies
    from slipstep.model.system import System

    if not isinstance(system, System):
        raise InputError("system", f"is a {type(system).__name__}", "build a slipstep.System or load a case")
    cs = system.compile_dense("the advice")
    names = system.direction_names()
    nd = cs.kt.shape[0]
    notes: list[str] = []
    fe = [float(f) for f in excitation_frequencies(system)]
    period = system.period
    stick = analyse_state(cs, (1,) * nd)
    # the steps Simulation takes (methods/step_control.py): dt = T_min/pi (the Newmark default's
    # convergence limit, paper 4.2), capped for accuracy at max_step (default period / 50)
    factor = newmark().step_limit_factor
    max_step = SC.default_max_step(period, factor * stick.t_min_s)
    fixed_dt = min(factor * stick.t_min_s, max_step)
    fixed_n = SC.whole_step_count(period, fixed_dt) if period and math.isfinite(fixed_dt) else None

    rho = f5 = None
    given = [v is not None for v in (rotor_speed_rpm, radius_m, displacement_amplitude_m)]
    if any(given) and not all(given):
        raise InputError(
            "rotor_speed_rpm/radius_m/displacement_amplitude_m",
            "only some of the three are given",
            "give all three for the inertia check of paper Eq. 9, or none",
        )
    if all(given):
        f5 = inertia_limit_frequency(displacement_amplitude_m, rotor_speed_rpm, radius_m, rho_limit)
        if fe:
            rho = inertia_ratio(max(fe), displacement_amplitude_m, rotor_speed_rpm, radius_m)

    visited, runs = _visited(system, periods, notes) if run_cases else (set(), {})
    combos = enumerate_states(cs, max_states)
    enumerated = combos is not None
    if combos is None:
        notes.append(f"more than {max_states} state combinations: only the visited states are analysed")
        combos = sorted(visited | {(1,) * nd})
    infos = []
    for st in combos:
        info = analyse_state(cs, st)
        info.visited = st in visited
        infos.append(info)
    flutter_v = [i.state for i in infos if i.complex_eigenvalues and i.visited]
    flutter_nv = [i.state for i in infos if i.complex_eigenvalues and not i.visited]
    singular = [i.state for i in infos if i.singular]
    singular_v = [i.state for i in infos if i.singular and i.visited]

    adaptive_n = None
    if period and runs.get("quasi_static"):
        # the quasi-static path: time share of each visited state x its step count
        from slipstep.methods.simulation import run as _run

        ds = _run(system, "quasi-static", periods=1)
        S = ds["contact_state"].values[1:]
        dt = np.diff(ds["time"].values)
        lookup = {i.state: i for i in infos}
        n = 0.0
        for row, h in zip(S, dt):
            info = lookup.get(tuple(int(v) for v in row)) or analyse_state(cs, row)
            limit = factor * info.t_min_s if math.isfinite(info.t_min_s) and not info.singular else max_step
            n += h / min(limit, max_step)
        adaptive_n = n * period / float(dt.sum())

    reasons: list[str] = []
    partial = _massless_analysis(system, cs, stick.t_min_s, fe, rho, rho_limit)
    if partial is not None and partial["applies"]:
        rec = "quasi-static-dofs (Method 3+4: the contact-held DOFs without inertia, the rest dynamic)"
        reasons.append(partial["why"])
        reasons.append(
            f"the step is then set by the dynamic part: T_min {partial['t_min_s'] * 1e6:.4g} us instead of "
            f"{stick.t_min_s * 1e6:.4g} us, and there is no ringing to filter"
        )
    elif f5 is not None and fe and max(fe) < f5 / 2 and not singular_v and partial is None:
        rec = "quasi-static (Method 4)"
        reasons.append(
            f"the excitation ({max(fe):g} Hz) is far below {f5 / 1e3:.3g} kHz, where inertia reaches "
            f"{rho_limit:.0%} of the centrifugal load (rho = {rho:.2g})"
        )
        reasons.append("no visited state lacks a quasi-static equilibrium")
        reasons.append("it needs about 300 steps per period whatever the contact stiffness, with no ringing to filter")
    else:
        rec = "dynamic: piecewise-linear Newmark (Method 3)"
        if f5 is None:
            reasons.append(
                "the inertia check (Eq. 9) was not possible: give rotor speed, radius and displacement "
                "amplitude to see whether the quasi-static method applies"
            )
        elif fe and max(fe) >= f5 / 2:
            reasons.append(
                f"the excitation ({max(fe):g} Hz) is close to or above {f5 / 1e3:.3g} kHz, where inertia "
                f"reaches {rho_limit:.0%} of the centrifugal load: inertia matters"
            )
        if singular_v:
            reasons.append(
                "some visited states have no quasi-static equilibrium (mechanism or lift-off): the "
                "quasi-static method would stop there"
            )
        reasons.append(
            "Method 3 needs about one solve per step (paper case: 1.2) and reproduces Method 1's "
            "solution; the adaptive step (2+3) saves steps in slip and lift-off, but each saved step "
            "is paid back in re-factorisations and redone steps (paper case: 222 against 221 solves "
            "per period), so use it when slip or lift-off dominates the period"
        )
    if flutter_v:
        reasons.append(
            "flutter-prone states are visited: expect growing oscillations in undamped dynamic runs; "
            "add damping or check the friction coefficients"
        )
    if fe and stick.frequencies_Hz:
        low = min(
            (i.frequencies_Hz[0] for i in infos if i.visited and i.frequencies_Hz and not i.singular),
            default=stick.frequencies_Hz[0],
        )
        if partial is not None:  # an assembly: the structure's low modes are physics, the ringing is the damper's
            low = min(partial["internal_Hz"], default=low)
        if low < 5 * max(fe):
            reasons.append(
                f"the lowest internal frequency of the visited states ({low / 1e3:.3g} kHz) is within a "
                "factor 5 of the excitation: the ringing cannot be filtered safely (paper Remark 3)"
            )
    return Advice(
        system.name,
        names,
        fe,
        period,
        rotor_speed_rpm,
        radius_m,
        displacement_amplitude_m,
        rho,
        f5,
        stick.t_min_s,
        fixed_dt,
        fixed_n,
        adaptive_n,
        enumerated,
        infos,
        flutter_v,
        flutter_nv,
        singular,
        singular_v,
        rec,
        reasons,
        notes,
        runs,
        rho_limit,
        partial,
    )


def _massless_analysis(system, cs, t_min_stick: float, fe: list[float], rho, rho_limit: float) -> dict | None:
    """Whether the contact-held DOFs can be quasi-static inside the dynamic rest (module
    docstring); None when there are no such DOFs or nothing else."""
    from slipstep.methods import massless as ML

    idx = ML.contact_held_dofs(system)
    if idx.size == 0 or idx.size == cs.M.shape[0]:
        return None
    dofs = [system.structure.dof_names[i] for i in idx]
    stick = np.ones(cs.kt.shape[0], np.int8)
    internal = [float(f) for f in ML.internal_frequencies(cs, stick, idx)]
    try:
        t_min = SC.state_t_min(ML.inertia_free(cs, idx), stick)
    except InputError:
        return {
            "dofs": dofs,
            "internal_Hz": internal,
            "t_min_s": math.nan,
            "step_gain": math.nan,
            "applies": False,
            "why": "the contacts do not hold those DOFs in full stick (no quasi-static equilibrium)",
        }
    fmax = max(fe) if fe else None
    low = min(internal) if internal else math.inf
    if fmax is None:
        applies, why = False, "the case has no harmonic excitation to compare the internal frequencies with"
    elif low < 5 * fmax or low - fmax < 1000.0:
        applies, why = (
            False,
            (
                f"their lowest internal frequency ({low / 1e3:.3g} kHz) is within a factor 5 or 1 kHz "
                f"of the excitation ({fmax:g} Hz): their dynamics couple with the structure's "
                "(paper Remark 3), keep their inertia"
            ),
        )
    elif rho is not None and rho >= rho_limit:
        applies, why = (
            False,
            (
                f"their inertia reaches {rho:.2g} of the centrifugal load at the excitation "
                f"(paper Eq. 9, limit {rho_limit:.0%})"
            ),
        )
    else:
        applies = True
        why = (
            f"their lowest internal frequency ({low / 1e3:.3g} kHz) is far above the excitation ({fmax:g} Hz): "
            "they act mainly as a spring coupling (paper Remark 3); their inertia adds the ringing and forces "
            "small against the contact forces (a few % of the friction forces can still shift a resonant "
            "amplitude by a few %: compare with a dynamic run at the peak)"
            + ("" if rho is None else f"; inertia ratio {rho:.2g} < {rho_limit:.0%} (paper Eq. 9)")
            + "; treat them without inertia"
        )
    return {
        "dofs": dofs,
        "internal_Hz": internal,
        "t_min_s": float(t_min),
        "step_gain": float(t_min / t_min_stick),
        "applies": applies,
        "why": why,
    }
