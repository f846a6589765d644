"""Two periodic orbits of one blade pair at one frequency: the history of the stuck region.

The Craig-Bampton blade pair of ``bench_blade_pair.py`` (60 elements per blade, 10 modes, 50
patch points per damper face) at 0.95 times its first stuck frequency, shot (Method 3, 256
steps per period) from two starts: the static preload (the FRF's own start) and the harmonic
balance's orbit (H = 7). Both converge with Floquet multipliers inside the unit circle, with
the same amplitude, and with friction energies per cycle far apart. The sliders that stay
stuck all period are neutral directions of the period map (multiplier exactly 1, counted in
``neutral_directions``): they keep the tangential force they stuck with, so the orbits form
a family, and which part of the patch slips, and the energy, depend on how the orbit was
reached. Harmonic balance
(whose zeroth harmonic fixes one such set) is checked against the orbit from its own state,
not against the orbit from the preload.

    python benchmarks/bench_orbit_family.py
"""

import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
import bench_blade_pair as bp  # noqa: E402

import slipstep.hbm as hbm  # noqa: E402
from slipstep.frequency.response import point_values  # noqa: E402
from slipstep.model.retune import retune  # noqa: E402
from slipstep.hbm.crosscheck import hbm_initial_state  # noqa: E402
from slipstep.hbm.energy import contact_energy  # noqa: E402
from slipstep.steady import shoot  # noqa: E402


def main() -> None:
    sub = bp.reduced(bp.blade(60), 10)
    f1 = bp.stuck_frequencies(bp.pair(sub, 50, None), 1)[0]
    system = bp.pair(sub, 50, 0.9 * f1)
    f = 0.95 * f1
    tip = "blade1." + sub.points["tip"].dofs["x"]
    warnings.simplefilter("ignore")
    hb = hbm.HarmonicBalance(system, harmonics=7)
    p = hb.solve(2 * np.pi * f)
    hb.linear.at(p.omega, p.level)
    hb.aft.evaluate(p.Z, False)
    start = hbm_initial_state(hb, p)
    s = retune(system, f)
    print(
        f"blade pair, {f:.2f} Hz: {'start':>16} {'periods':>8} {'tip amp um':>11} {'E_friction J':>13} {'max |mu|':>9}"
    )
    for name, kw in (("static preload", {}), ("HBM orbit", {"initial": start})):
        st = shoot(s, method="piecewise-linear", **kw)
        v = point_values(st, s, [tip], 1)
        mu = np.abs(st.floquet_multipliers).max()
        print(
            f"{'shoot':>28} {name:>16} {st.periods:8d} {float(v['amplitude'][0]) * 1e6:11.3f}"
            f" {float(v['energy_per_cycle'].sum()):13.4e} {mu:9.4f}  {st.status}"
        )
    print(f"{'harmonic balance, H = 7':>28} {'':>16} {'':>8} {'':>11} {contact_energy(hb, p.Z, p.F).sum():13.4e}")


if __name__ == "__main__":
    main()
