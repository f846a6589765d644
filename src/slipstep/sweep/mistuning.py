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

with the blade j and the frequency f of the maximum, and the same for the two linear limits of
the FRF (contacts stuck, contacts removed: the ring without dampers), each against the tuned
ring's own limit. The tuned ring (every delta 0, the other parameters at the case's values)
is computed once per sweep (per combination of the other parameters) by the client.
"""

from __future__ import annotations

import math

import numpy as np

from slipstep.errors import InputError

LEVEL, SAMPLE = "level", "sample"  # the two store coordinates of a mistuning parameter: <name>_level, <name>_sample

MISTUNING_FIELDS: dict[str, tuple[str, str]] = {
    "peak_blade_amplitude": ("m or rad (see frf response_unit)", "largest blade amplitude over blades and frequencies"),
    "peak_frequency_Hz": ("Hz", "frequency of the largest blade amplitude"),
    "peak_blade": ("1", "blade of the largest amplitude (1-based, in blade order)"),
    "amplification_factor": ("1", "largest blade amplitude / the tuned assembly's"),
    "linear_stuck_peak_amplitude": ("m or rad (see frf response_unit)", "largest blade amplitude, contacts stuck"),
    "linear_stuck_amplification_factor": ("1", "largest stuck-contact amplitude / the tuned assembly's"),
    "linear_free_peak_amplitude": (
        "m or rad (see frf response_unit)",
        "largest blade amplitude, contacts removed (no dampers)",
    ),
    "linear_free_amplification_factor": ("1", "largest amplitude without dampers / the tuned assembly's"),
    "mistuning_rms": ("1", "root mean square of the case's blade deltas"),
    "mistuning_max_abs": ("1", "largest |delta_j| of the case"),
}
# summary field of the peak -> (FRF variable, field of its amplification factor)
PEAKS = {
    "peak_blade_amplitude": ("amplitude", "amplification_factor"),
    "linear_stuck_peak_amplitude": ("linear_stuck_amplitude", "linear_stuck_amplification_factor"),
    "linear_free_peak_amplitude": ("linear_free_amplitude", "linear_free_amplification_factor"),
}
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
    each PEAKS variable; NaN (blade -1) where the FRF holds no finite value, and for a linear
    limit whose largest value lies on the first or last frequency of the grid: its resonance is
    outside the grid (the grid is set around the damped response; the stuck ring resonates
    higher), so that value is no peak and its amplification factor would mean nothing (the
    Whitehead limit bounds peak ratios, not ratios of grid-edge values)."""
    cols = [responses.index(r) for r in blade_dofs]
    f = np.asarray(frequencies, float)
    out = {}
    for field, (name, _) in PEAKS.items():
        a = np.asarray(frf.get(name, np.full((f.size, len(responses)), np.nan)), float)[:, cols]
        if not np.isfinite(a).any():
            out[field] = (math.nan, math.nan, -1)
            continue
        i, j = np.unravel_index(np.nanargmax(a), a.shape)
        if name.startswith("linear_") and f.size > 2 and i in (0, f.size - 1):
            out[field] = (math.nan, math.nan, -1)
            continue
        out[field] = (float(a[i, j]), float(f[i]), int(j) + 1)
    return out


def summary_of(frf: dict, cfg: dict, mistuning: dict, reference: dict | None) -> dict:
    """The MISTUNING_FIELDS (but the delta statistics) of one case from its FRF arrays and the
    tuned reference {peak field: A_peak(tuned)} (None: the amplification factors are NaN)."""
    p = peaks(frf, cfg["frequencies_Hz"], list(cfg["responses"]), mistuning["responses"])
    out = {}
    for field, (amp, freq, blade) in p.items():
        out[field] = amp
        tuned = (reference or {}).get(field, math.nan)
        out[PEAKS[field][1]] = amp / tuned if tuned and math.isfinite(tuned) else math.nan
    out["peak_frequency_Hz"], out["peak_blade"] = p["peak_blade_amplitude"][1:]
    return out


def reference_key(parameters, values) -> tuple:
    """The values of the parameters other than the mistuning (the tuned reference's identity)."""
    return tuple(float(v) for p, v in zip(parameters, values) if p.mistuning is None)


def reference_for(references, parameters, values) -> dict | None:
    key = list(reference_key(parameters, values))
    return next((r for r in references if r["values"] == key), None)
