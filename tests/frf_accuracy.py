"""The FRF accuracy check shared by tests/test_frf_error.py and benchmarks/bench_frf_accuracy.py:
the Jenkins oscillator of issue 24 (m 2.5 kg, k 1e7 N/m, C = 40 M, k_t 1e7 N/m, slip force
50 N, F = 100 N) by each FRF solver at its defaults, against the exact continuous periodic
orbit of tests/jenkins_reference.py (event-located stick/slip, DOP853 at rtol 1e-12).

The true error of a point is measured as its error estimate is defined
(slipstep.frequency.error_estimate): the larger of the relative errors of the friction energy
per cycle (floored at 1e-4 of the excitation work) and of the excitation work per cycle.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
from jenkins_reference import periodic_orbit_energies

JENKINS = Path(__file__).resolve().parents[1] / "examples" / "jenkins.toml"
PARAMETERS = (2.5, 100.0, 1e7, 1e7, 50.0, 100.0)  # m, c = 40 m, k, k_t, slip force, force amplitude
FREQUENCIES = tuple(float(f) for f in np.linspace(250.0, 500.0, 11))  # 25 Hz apart, resonance near 350 Hz
GUESS_STEPS = 2000  # steps per period of the shot orbit that starts the reference's Newton


def system():
    import slipstep as ss

    return ss.load_system(JENKINS)


@lru_cache(maxsize=None)
def reference(frequency: float) -> dict:
    """The exact periodic orbit at ``frequency`` [Hz], from a fine shot orbit as the guess."""
    from slipstep.frequency import retune
    from slipstep.steady import shoot

    guess = shoot(retune(system(), frequency), tolerance=1e-10, min_steps_per_period=GUESS_STEPS)
    s = guess.final_state
    return periodic_orbit_energies(*PARAMETERS, frequency, s.x[0], s.v[0], s.w[0], int(s.states[0]))


def true_error(friction: float, work: float, ref: dict) -> float:
    """The true relative error of a point's energies per cycle (module docstring)."""
    w_ref, d_ref = ref["excitation_work"], ref["friction_energy"]
    return max(abs(work - w_ref) / abs(w_ref), abs(friction - d_ref) / max(abs(d_ref), 1e-4 * abs(w_ref)))


def rows(ds) -> list[dict]:
    """One row per FRF point of ``ds`` at the reference frequencies: frequency, friction energy,
    true error, error estimate, steps per period, status, status_message."""
    out = []
    for i, f in enumerate(ds["frequency"].values):
        ref = reference(float(f))
        friction = float(ds["energy_per_cycle"].values[i].sum())
        work = float(ds["excitation_work"].values[i])
        out.append(
            {
                "frequency_Hz": float(f),
                "friction_energy_J": friction,
                "reference_J": ref["friction_energy"],
                "true_error": true_error(friction, work, ref),
                "error_estimate": float(ds["error_estimate"].values[i]),
                "steps_per_period": float(ds["steps_per_period"].values[i]),
                "status": str(ds["status"].values[i]),
                "status_message": str(ds["status_message"].values[i]),
            }
        )
    return out


def frf_at_defaults(solver: str, frequencies=FREQUENCIES, **options):
    """The FRF of the Jenkins oscillator by ``solver`` at its defaults (harmonic balance without
    continuation: at exactly the asked frequencies; no cross-check march)."""
    import warnings

    from slipstep.frequency import frf

    if solver == "hbm":
        options = {"continuation": False, "check": "none", **options}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = frf(system(), list(frequencies), solver=solver, **options)
    return ds, [w for w in caught if "rtol" in str(w.message) or "harmonics" in str(w.message)]
