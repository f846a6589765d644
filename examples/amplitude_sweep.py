"""Damper design curve: energy dissipated per cycle and equivalent damping of each platform
interface against the platform motion amplitude, for the paper's damper.

The quasi-static method (Method 4) gives each point in milliseconds; two points are checked
against the dynamic piecewise-linear Newmark (Method 3) after the paper's low-pass filter.

    python examples/amplitude_sweep.py [--output-dir DIR]
"""

from __future__ import annotations

import argparse
import copy
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import slipstep  # noqa: E402
from slipstep.config import CASES_DIR, build_system, parse_case, read_toml  # noqa: E402
from slipstep.io import save_figure  # noqa: E402

AMPLITUDES_UM = (1, 2, 4, 6, 8, 10, 15, 20, 25, 35, 50, 70)


def paper_with_amplitude(amplitude_um: float) -> slipstep.System:
    data = copy.deepcopy(read_toml(CASES_DIR / "paper.toml"))
    data["motion"][0]["amplitude"] = float(amplitude_um)
    return build_system(parse_case(data))


def interface_summary(ds, system):
    s = slipstep.post.loop_summary(ds, system)
    return {name: (float(s.interface_energy_J.sel(interface=name)) * 1e3,
                   float(s.interface_k_eq_N_per_m.sel(interface=name)) * 1e-6,
                   float(s.interface_zeta_eq.sel(interface=name)))
            for name in s.interface.values}


def sweep(amplitudes=AMPLITUDES_UM):
    """Rows (amplitude [um], interface, energy [mJ], k_eq [N/um], zeta_eq [-]) from Method 4."""
    rows = []
    for amp in amplitudes:
        system = paper_with_amplitude(amp)
        ds = slipstep.run(system, "quasi-static", periods=3, raise_on_failure=True)
        for name, (energy, k_eq, zeta) in interface_summary(ds, system).items():
            rows.append((amp, name, energy, k_eq, zeta))
    return rows


def check_dynamic(amplitude_um: float) -> dict:
    """Method 3, filtered, against Method 4 at one amplitude: dissipated energies [mJ] of each
    interface, (quasi-static, dynamic)."""
    system = paper_with_amplitude(amplitude_um)
    quasi = interface_summary(slipstep.run(system, "quasi-static", periods=3), system)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the filter warns only when it cannot separate the ringing
        dyn = slipstep.post.filter_dataset(slipstep.run(system, "piecewise-linear", periods=3), system)
    dynamic = interface_summary(dyn, system)
    return {name: (quasi[name][0], dynamic[name][0]) for name in quasi}


def plot(rows, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for name, marker in (("left", "o"), ("right", "s")):
        sel = [r for r in rows if r[1] == name]
        amp = [r[0] for r in sel]
        axes[0].plot(amp, [r[2] for r in sel], marker=marker, label=f"{name} interface")
        axes[1].plot(amp, [r[4] for r in sel], marker=marker, label=f"{name} interface")
    axes[0].set(xlabel="right platform amplitude [um]", ylabel="energy dissipated per cycle [mJ]",
                title="Friction dissipation (quasi-static, Method 4)")
    axes[1].set(xlabel="right platform amplitude [um]", ylabel="equivalent viscous damping ratio [-]",
                title="Equivalent damping of the interface loops")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend()
    save_figure(fig, path, dpi=130)  # atomic: a failed write keeps the previous figure
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output-dir", type=Path, default=Path("slipstep-out"))
    args = parser.parse_args()
    args.output_dir.mkdir(parents=True, exist_ok=True)
    rows = sweep()
    print(f"{'amplitude [um]':>14} {'interface':>9} {'E [mJ]':>8} {'k_eq [N/um]':>11} {'zeta_eq':>8}")
    for amp, name, energy, k_eq, zeta in rows:
        stuck = abs(energy) < 1e-9  # a closed stick loop has no area: print 0, not -0.000
        print(f"{amp:14g} {name:>9} {0.0 if stuck else energy:8.3f} {k_eq:11.3f} {0.0 if stuck else zeta:8.3f}")
    for amp in (10, 25):
        pairs = ", ".join(f"{k} {q:.3f} / {d:.3f} mJ" for k, (q, d) in check_dynamic(amp).items())
        print(f"dissipated energy at {amp} um, Method 4 / Method 3 filtered: {pairs}")
    path = args.output_dir / "amplitude_sweep.png"
    plot(rows, path)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
