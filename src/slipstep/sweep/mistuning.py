"""Random blade mistuning of an assembly in a sweep, and the amplification statistics of its
forced response.

A mistuning parameter (slipstep.sweep.spec.Mistuning) gives every case a level and a sample
number; the case's blade deltas are

    delta_j = level * u_kj,   blade j's stiffness K_j -> (1 + delta_j) K_j

(every modal frequency of blade j times sqrt(1 + delta_j)), with u_k the unit draw of sample k:
u_kj ~ N(0, 1) (normal: level = standard deviation), u_kj ~ U(-1, 1) (uniform: level =
half-width) from ``numpy.random.default_rng([seed, k])`` (sample k is reproducible alone: it
does not depend on the number of samples or levels), or u_k = deltas[k] as given (list: level
= scale). The same u_k at every level (common random numbers: the amplitude-level curves are
smooth). The deltas are written into the case dictionary, so the case hash covers them: a
[chain] case takes them as ``chain.mistuning``, an assembly without a chain as each named
blade substructure's ``mistuning`` key.

Per case, from its FRF (slipstep.frequency.frf, the sweep's [outputs.frf]) at the blades'
response DOF x_j (default: the engine-order force's DOF of each blade):

    A_peak = max_j max_f A_j(f),   amplification_factor = A_peak / A_peak(tuned)

with the blade j and the frequency f of the maximum on the FRF's grid, and the same for the
two linear limits (contacts stuck, contacts removed: the ring without dampers), each against
the tuned ring's own limit. A linear limit's resonance is narrow (light damping) and falls
between grid points, or beside the band (the stuck ring resonates above the damped response,
the ring without dampers below), so its peak is not read off the grid: the limit's modes in
the band widened by its width on each side are found (eigenvalues of (K, M)) and the peak near
each refined (:func:`linear_peak`). The tuned ring (every delta 0, the other parameters at the case's values)
is computed once per sweep (per combination of the other parameters) by the client.
"""

from __future__ import annotations

import math

import numpy as np

from slipstep.errors import InputError

LEVEL, SAMPLE = "level", "sample"  # the two store coordinates of a mistuning parameter: <name>_level, <name>_sample

AMPLITUDE_UNIT = "m or rad (see frf response_unit)"
MISTUNING_FIELDS: dict[str, tuple[str, str]] = {
    "peak_blade_amplitude": (AMPLITUDE_UNIT, "largest blade amplitude over blades and grid frequencies"),
    "peak_frequency_Hz": ("Hz", "frequency of the largest blade amplitude"),
    "peak_blade": ("1", "blade of the largest amplitude (1-based, in blade order)"),
    "amplification_factor": ("1", "largest blade amplitude / the tuned assembly's"),
    "linear_stuck_peak_amplitude": (
        AMPLITUDE_UNIT,
        "largest resonance peak of the blade amplitudes near [f_min, f_max] (the band widened by its width "
        "each side), contacts stuck (refined off the grid)",
    ),
    "linear_stuck_peak_frequency_Hz": ("Hz", "frequency of the largest stuck-contact blade amplitude"),
    "linear_stuck_peak_blade": ("1", "blade of the largest stuck-contact amplitude (1-based)"),
    "linear_stuck_amplification_factor": ("1", "largest stuck-contact amplitude / the tuned assembly's"),
    "linear_free_peak_amplitude": (
        AMPLITUDE_UNIT,
        "largest resonance peak of the blade amplitudes near [f_min, f_max] (the band widened by its width "
        "each side), contacts removed (no dampers; refined off the grid)",
    ),
    "linear_free_peak_frequency_Hz": ("Hz", "frequency of the largest blade amplitude without dampers"),
    "linear_free_peak_blade": ("1", "blade of the largest amplitude without dampers (1-based)"),
    "linear_free_amplification_factor": ("1", "largest amplitude without dampers / the tuned assembly's"),
    "mistuning_rms": ("1", "root mean square of the case's blade deltas"),
    "mistuning_max_abs": ("1", "largest |delta_j| of the case"),
}
# summary field of the peak -> (FRF variable, its amplification factor, its frequency, its blade)
PEAKS = {
    "peak_blade_amplitude": ("amplitude", "amplification_factor", "peak_frequency_Hz", "peak_blade"),
    "linear_stuck_peak_amplitude": (
        "linear_stuck_amplitude",
        "linear_stuck_amplification_factor",
        "linear_stuck_peak_frequency_Hz",
        "linear_stuck_peak_blade",
    ),
    "linear_free_peak_amplitude": (
        "linear_free_amplitude",
        "linear_free_amplification_factor",
        "linear_free_peak_frequency_Hz",
        "linear_free_peak_blade",
    ),
}
LIMITS = {"linear_stuck_peak_amplitude": True, "linear_free_peak_amplitude": False}  # peak field -> stuck
MODES = 24  # the modes of a linear limit nearest the FRF band whose peaks are refined (linear_peak)
WHITEHEAD = "(1 + sqrt(N)) / 2"  # the largest amplification factor of a linear ring of N blades (Whitehead 1966)


def unit_draw(m, k: int, n_blades: int) -> np.ndarray:
    """u_k: the unit deltas of sample k (module docstring)."""
    if m.distribution == "list":
        u = np.asarray(m.deltas[k], float)
        if u.size != n_blades:
            raise InputError(
                f"[[parameter]] {m.name}: deltas[{k}]", f"has {u.size} values for {n_blades} blades", "one per blade"
            )
        return u
    rng = np.random.default_rng([int(m.seed), int(k)])
    return rng.standard_normal(n_blades) if m.distribution == "normal" else rng.uniform(-1.0, 1.0, n_blades)


def deltas_of(m, level: float, k: int, n_blades: int) -> np.ndarray:
    """delta = level * u_k."""
    return float(level) * unit_draw(m, k, n_blades)


def blades_of(data: dict, m) -> list[str]:
    """The blade substructure names of an assembly case dictionary, in blade order: the chain's
    copies (blade1, blade2, ...) or the parameter's ``blades``."""
    where = f"[[parameter]] {m.name}"
    if "substructures" not in data:
        raise InputError(
            f"{where}: kind", "mistunes the blades of an assembly case", "use an assembly base case (ring)"
        )
    chain = data.get("chain")
    if chain is not None:
        if m.blades is not None:
            raise InputError(
                f"{where}: blades", "is given for a [chain] case", "remove it: the chain's blades are used"
            )
        return [f"{chain.get('blade')}{j + 1}" for j in range(int(chain.get("blades", 0)))]
    if not m.blades:
        raise InputError(
            f"{where}: blades", "is missing and the case has no [chain]", "list the blade substructures in order"
        )
    names = [s.get("name") for s in data["substructures"] if isinstance(s, dict)]
    unknown = [b for b in m.blades if b not in names]
    if unknown:
        raise InputError(f"{where}: blades", f"names unknown substructure(s) {unknown}", f"use names from {names}")
    if len(set(m.blades)) != len(m.blades):
        raise InputError(f"{where}: blades", "names a blade twice", "list each blade once")
    return list(m.blades)


def response_dofs(data: dict, m) -> list[str]:
    """The DOF of each blade whose amplitude is summarised: ``<blade>.<response>``."""
    dof = m.response
    if dof is None:
        forces = data.get("engine_order_force") or []
        if not forces:
            raise InputError(
                f"[[parameter]] {m.name}: response", "is missing and the case has no engine-order force", 'give "8.x"'
            )
        dof = forces[0].get("dof")
    return [f"{b}.{dof}" for b in blades_of(data, m)]


def apply_mistuning(data: dict, m, level: float, k: int) -> None:
    """Write the deltas of (level, sample k) into the case dictionary ``data`` (in place)."""
    blades = blades_of(data, m)
    deltas = [float(d) for d in deltas_of(m, level, k, len(blades))]
    if data.get("chain") is not None:
        data["chain"]["mistuning"] = deltas
        return
    index = {s.get("name"): s for s in data["substructures"]}
    for b, d in zip(blades, deltas):
        index[b]["mistuning"] = d


def mistuning_stats(data: dict) -> dict:
    """RMS and largest |delta| of a case dictionary's blade deltas."""
    chain = data.get("chain")
    if chain is not None:
        d = np.asarray(chain.get("mistuning") or [0.0], float)
    else:
        d = np.asarray([s["mistuning"] for s in data["substructures"] if "mistuning" in s] or [0.0], float)
    return {"mistuning_rms": float(np.sqrt(np.mean(d**2))), "mistuning_max_abs": float(np.max(np.abs(d)))}


def peaks(frf: dict, frequencies, responses: list[str], blade_dofs: list[str]) -> dict:
    """{peak field: (A_peak, f_peak, blade 1-based)} of the FRF arrays (frequency, response) for
    each PEAKS variable: the largest value on the grid (an edge value too); NaN (blade -1) where
    the FRF holds no finite value."""
    cols = [responses.index(r) for r in blade_dofs]
    f = np.asarray(frequencies, float)
    out = {}
    for field, (name, *_) in PEAKS.items():
        a = np.asarray(frf.get(name, np.full((f.size, len(responses)), np.nan)), float)[:, cols]
        if not np.isfinite(a).any():
            out[field] = (math.nan, math.nan, -1)
            continue
        i, j = np.unravel_index(np.nanargmax(a), a.shape)
        out[field] = (float(a[i, j]), float(f[i]), int(j) + 1)
    return out


def limit_modes(limit, f_min: float, f_max: float, modes: int = MODES) -> tuple[np.ndarray, np.ndarray]:
    """(f_n [Hz], zeta_n) of the ``modes`` undamped modes of a linear limit
    (slipstep.steady.linear.LinearLimit) nearest the band [f_min, f_max], ascending:

        K phi = w_n^2 M phi,   phi^T M phi = 1,   zeta_n = phi^T C phi / (2 w_n)

    (the modal damping ratio of the mode's diagonal term; C need not be modal). Dense (or a
    sparse structure of at most 3 ``modes`` + 2 DOFs): scipy.linalg.eigh of (K, M), every mode.
    Sparse: scipy.sparse.linalg.eigsh by shift-invert
    about the band's centre, sigma = (2 pi (f_min + f_max) / 2)^2, the count doubled until the
    eigenvalues found (the nearest sigma) reach beyond both band edges' (or n - 2 are found).
    Zero and rigid-body modes (w_n^2 <= 0) are left out."""
    K, M, C = limit.K, limit.M, limit.C
    n = limit.n
    if limit.sparse and n > 3 * modes + 2:
        import scipy.sparse.linalg as spla

        sigma = (np.pi * (f_min + f_max)) ** 2
        k = min(max(modes, 6), n - 2)
        start = np.random.default_rng(0).standard_normal(n)  # a fixed start: a case's numbers are reproducible
        radius = max(sigma - (2 * np.pi * f_min) ** 2, (2 * np.pi * f_max) ** 2 - sigma)
        while True:  # the k eigenvalues nearest sigma: every one within max |w2 - sigma| of it
            w2, V = spla.eigsh(K, k=k, M=M, sigma=sigma, which="LM", v0=start)
            if k >= n - 2 or np.abs(w2 - sigma).max() >= radius:
                break
            k = min(2 * k, n - 2)
        V = V / np.sqrt(np.einsum("ij,ij->j", V, M @ V))  # M-normalised (eigsh's are already, up to round-off)
        CV = C @ V
    else:
        import scipy.linalg

        K, M, C = (X.toarray() if hasattr(X, "toarray") else np.asarray(X) for X in (K, M, C))
        w2, V = scipy.linalg.eigh(K, M)
        CV = C @ V
    keep = w2 > 0.0
    w2, V, CV = w2[keep], V[:, keep], CV[:, keep]
    wn = np.sqrt(w2)
    fn = wn / (2 * np.pi)
    zeta = np.einsum("ij,ij->j", V, CV) / (2 * wn)
    distance = np.maximum(f_min - fn, 0.0) + np.maximum(fn - f_max, 0.0)
    nearest = np.sort(np.argsort(distance, kind="stable")[:modes])
    return fn[nearest], zeta[nearest]


def resonance_window(f_min: float, f_max: float) -> tuple[float, float]:
    """The frequencies [Hz] whose resonances count as the band's: the band [f_min, f_max]
    widened by its own width W = f_max - f_min on each side (above 0). The FRF's band is set
    around the damped response, and the linear limits resonate beside it (the stuck ring higher,
    the ring without dampers lower), so their peaks are taken there, not on the band's edges
    (the ratio of two edge values is no amplification factor: Whitehead's limit bounds peaks)."""
    width = f_max - f_min
    return max(f_min - width, 0.0), f_max + width


def linear_peak(limit, cols, f_min: float, f_max: float, modes: int = MODES) -> tuple[float, float, int]:
    """(A_peak, f_peak [Hz], blade 1-based) of a linear limit near the band [f_min, f_max]:

        A_peak = max over the resonances f_n in the window of max over f near f_n of g(f),
        g(f) = max_j A_j(f)

    with A_j(f) the limit's blade amplitudes (LinearLimit.amplitude, columns ``cols``) and the
    window :func:`resonance_window` (the band widened by its width each side; the nearest mode
    alone when none lies there). Around each of the ``modes`` modes nearest the band in the
    window (:func:`limit_modes`: f_n, zeta_n), the maximum of g on a local grid of 33 frequencies
    over f_n +- 4 half-power widths (width 2 zeta_n f_n, at least 1e-6 f_n), then refined by
    scipy.optimize.minimize_scalar (bounded) on -g between the best local point's neighbours. A
    resonance thus counts with its true peak, wherever it lies between the FRF's grid points."""
    from scipy.optimize import minimize_scalar

    cols = np.asarray(cols, int)

    def g(f):
        return float(np.max(limit.amplitude(f)[cols]))

    fn, zeta = limit_modes(limit, f_min, f_max, modes)
    if fn.size == 0:
        return math.nan, math.nan, -1
    low, high = resonance_window(f_min, f_max)
    inside = (fn >= low) & (fn <= high)
    if not inside.any():
        inside = np.abs(fn - 0.5 * (f_min + f_max)) == np.abs(fn - 0.5 * (f_min + f_max)).min()
    best = (-math.inf, math.nan)
    for f_n, z in zip(fn[inside], zeta[inside]):
        half = 4.0 * max(2.0 * abs(z) * f_n, 1e-6 * f_n)
        grid = np.linspace(max(f_n - half, 1e-3 * f_n), f_n + half, 33)
        values = np.array([g(f) for f in grid])
        i = int(np.argmax(values))
        a, b = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        centre, scale = 0.5 * (a + b), 0.5 * (b - a)  # solved in u = (f - centre) / scale in [-1, 1]:
        # the bounded method's tolerance is relative to |u| (1.5e-8 |u|), not to |f|
        res = minimize_scalar(
            lambda u, c=centre, w=scale: -g(c + w * u), bounds=(-1.0, 1.0), method="bounded", options={"xatol": 1e-12}
        )
        candidates = [(values[i], grid[i]), (-float(res.fun), centre + scale * float(res.x))]
        best = max([best, *candidates], key=lambda c: c[0])
    amp, f = best
    blade = int(np.argmax(limit.amplitude(f)[cols])) + 1
    return float(amp), float(f), blade


def linear_peaks(system, frequencies, blade_dofs: list[str], modes: int = MODES) -> dict:
    """{linear peak field: (A_peak, f_peak, blade)} of both linear limits of ``system`` (contacts
    stuck at the static preload's state, contacts removed) near the band of the FRF's grid
    ``frequencies`` (:func:`linear_peak`); a system without contacts has one limit (both
    fields equal). NaN (blade -1) where a limit is singular."""
    from slipstep.steady.linear import LinearLimit, stuck_state

    names = list(system.structure.dof_names)
    cols = [names.index(r) for r in blade_dofs]
    f = np.asarray(frequencies, float)
    f_min, f_max = float(f.min()), float(f.max())
    state = stuck_state(system) if system.contacts else None
    out = {}
    for field, stuck in LIMITS.items():
        try:
            limit = LinearLimit(system, stuck and state is not None, state)
            out[field] = linear_peak(limit, cols, f_min, f_max, modes)
        except np.linalg.LinAlgError:
            out[field] = (math.nan, math.nan, -1)
    return out


def case_peaks(system, frf: dict, cfg: dict, blade_dofs: list[str]) -> dict:
    """{peak field: (A_peak, f_peak, blade)} of a case: the friction response's largest value
    on the FRF's grid (:func:`peaks`), the linear limits' resonance peaks near the grid's band
    refined off the grid (:func:`linear_peaks`)."""
    p = peaks(frf, cfg["frequencies_Hz"], list(cfg["responses"]), blade_dofs)
    p.update(linear_peaks(system, cfg["frequencies_Hz"], blade_dofs))
    return p


def summary_of(p: dict, reference: dict | None) -> dict:
    """The MISTUNING_FIELDS (but the delta statistics) of one case from its peaks
    (:func:`case_peaks`) and the tuned reference {peak field: A_peak(tuned)} (None: the
    amplification factors are NaN)."""
    out = {}
    for field, (amp, freq, blade) in p.items():
        _, af, freq_field, blade_field = PEAKS[field]
        tuned = (reference or {}).get(field, math.nan)
        out[field] = amp
        out[af] = amp / tuned if tuned and math.isfinite(tuned) else math.nan
        out[freq_field], out[blade_field] = freq, blade
    return out


def reference_key(parameters, values) -> tuple:
    """The values of the parameters other than the mistuning (the tuned reference's identity)."""
    return tuple(float(v) for p, v in zip(parameters, values) if p.mistuning is None)


def reference_for(references, parameters, values) -> dict | None:
    key = list(reference_key(parameters, values))
    return next((r for r in references if r["values"] == key), None)
