"""Mistuning sweeps (issue 27): the blade deltas of each sample (reproducible, the asked
distribution), written into chain and chain-less assemblies, and the amplification statistics
of the FRF against a direct serial computation through slipstep.frequency.response.frf."""

from __future__ import annotations

import copy
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import slipstep as ss
from slipstep.casefile.case import CASES_DIR, read_toml
from slipstep.errors import InputError
from slipstep.sweep import SerialExecutor, SweepSpec, load_spec, make_plan, open_sweep, run_sweep, spec_from_dict
from slipstep.sweep.cases import build_case
from slipstep.sweep.spec import Mistuning, Outputs

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ring_mistuning.toml"
FAST_FRF = {  # a coarse FRF around the ring's first family (a few seconds per sweep)
    "start_Hz": 295.0,
    "stop_Hz": 325.0,
    "num": 7,
    "solver": "hbm",
    "harmonics": [1, 3],
    "check": "none",
    "adequacy": False,
}


def _spec(m: Mistuning, base="ring", frf=FAST_FRF, **kw) -> SweepSpec:
    return SweepSpec(base=base, parameters=(m,), outputs=Outputs(frf=dict(frf), time_summary=False), **kw)


def _deltas(plan, i) -> np.ndarray:
    return np.asarray(plan.case_dict(i)["chain"]["mistuning"])


def test_each_sample_is_reproducible_alone_and_scales_with_the_level():
    small = make_plan(_spec(Mistuning(levels=(0.01, 0.03), samples=3, seed=7)))
    large = make_plan(_spec(Mistuning(levels=(0.01, 0.03), samples=5, seed=7)))
    other_seed = make_plan(_spec(Mistuning(levels=(0.01, 0.03), samples=3, seed=8)))
    assert small.n_cases == 6 and large.n_cases == 10 and small.grid_shape == (2, 3)
    names = [p.name for p in small.parameters]
    assert names == ["mistuning_level", "mistuning_sample"]
    for i in range(small.n_cases):
        level, k = small.values[i]
        j = int(np.flatnonzero((large.values[:, 0] == level) & (large.values[:, 1] == k))[0])
        assert small.hashes[i] == large.hashes[j]  # sample k does not depend on the number of samples
        np.testing.assert_array_equal(_deltas(small, i), _deltas(large, j))
        assert not np.array_equal(_deltas(small, i), _deltas(other_seed, i))
        u = np.random.default_rng([7, int(k)]).standard_normal(6)  # the documented draw
        np.testing.assert_allclose(_deltas(small, i), level * u, rtol=1e-15)
    # common random numbers: the same unit draw at every level
    np.testing.assert_allclose(_deltas(small, 3), 3.0 * _deltas(small, 0), rtol=1e-14)


@pytest.mark.parametrize("distribution, key", [("normal", "std"), ("uniform", "half_width")])
def test_the_deltas_follow_the_asked_distribution(distribution, key):
    data = {
        "sweep": {"base": "ring"},
        "parameter": [{"kind": "mistuning", "distribution": distribution, key: 0.05, "samples": 400, "seed": 3}],
        "outputs": {"time_summary": False, "frf": FAST_FRF},
    }
    plan = make_plan(spec_from_dict(data))
    d = np.concatenate([_deltas(plan, i) for i in range(plan.n_cases)])  # 2,400 deltas
    assert abs(d.mean()) < 4 * 0.05 / np.sqrt(d.size)
    if distribution == "normal":
        assert abs(d.std() / 0.05 - 1) < 0.05  # std of a std estimate over 2,400: 1.4 %
    else:
        assert np.abs(d).max() <= 0.05 and np.abs(d).max() > 0.049
        assert abs(d.std() / (0.05 / np.sqrt(3)) - 1) < 0.05


def test_a_given_list_of_deltas_is_scaled_and_written_as_given():
    given = ((0.01, -0.02, 0.0, 0.03, 0.0, -0.01), (0.0, 0.0, 0.05, 0.0, 0.0, 0.0))
    plan = make_plan(_spec(Mistuning(distribution="list", levels=(1.0, 2.0), deltas=given)))
    assert plan.n_cases == 4
    for i in range(4):
        level, k = plan.values[i]
        np.testing.assert_array_equal(_deltas(plan, i), level * np.asarray(given[int(k)]))


def test_an_assembly_without_chain_takes_the_deltas_on_its_named_blades():
    """blades.toml: two blades, no [chain]; blade j's stiffness times 1 + delta_j."""
    m = Mistuning(levels=(0.04,), samples=2, seed=1, blades=("blade1", "blade2"))
    plan = make_plan(_spec(m, base="blades"))
    tuned, _ = build_case(read_toml(CASES_DIR / "blades.toml"), str(CASES_DIR))
    assert plan.outputs["mistuning"]["responses"] == ["blade1.8.x", "blade2.8.x"]
    for i in range(plan.n_cases):
        data = plan.case_dict(i)
        d = [s["mistuning"] for s in data["substructures"]]
        np.testing.assert_allclose(d, 0.04 * np.random.default_rng([1, i]).standard_normal(2), rtol=1e-15)
        system, _ = build_case(data, plan.base_dir)
        names = system.structure.dof_names
        K, Kt = (
            np.asarray(getattr(k, "toarray", lambda k=k: k)(), float)
            for k in (system.structure.stiffness, tuned.structure.stiffness)
        )
        for j, blade in enumerate(("blade1", "blade2")):
            rows = [r for r, n in enumerate(names) if n.startswith(f"{blade}.")]
            block = np.ix_(rows, rows)
            np.testing.assert_allclose(K[block], (1 + d[j]) * Kt[block], rtol=1e-14)


BAD = [
    ({"distribution": "lognormal", "std": 0.1, "samples": 2}, "distribution", "lognormal"),
    ({"std": 0.1}, "samples", "None"),
    ({"std": 0.1, "half_width": 0.1, "samples": 2}, "half_width", "not the level"),
    ({"std": -0.1, "samples": 2}, "std[0]", "-0.1"),
    ({"distribution": "list", "deltas": [[0.1, 0.0]]}, "deltas", "2 deltas for 6 blades"),
    ({"std": 0.1, "samples": 2, "blades": ["blade1"]}, "blades", "[chain]"),
    ({"std": 0.1, "samples": 2, "stdev": 1}, "stdev", "not a known key"),
]


@pytest.mark.parametrize("table, key, problem", BAD)
def test_bad_mistuning_parameters_name_the_key(table, key, problem):
    data = {
        "sweep": {"base": "ring"},
        "parameter": [{"kind": "mistuning", **table}],
        "outputs": {"time_summary": False, "frf": FAST_FRF},
    }
    with pytest.raises(InputError) as err:
        make_plan(spec_from_dict(data))
    assert key in err.value.field and problem in str(err.value)


def test_a_mistuning_sweep_needs_a_grid_an_assembly_and_an_frf():
    table = {"kind": "mistuning", "std": 0.02, "samples": 2}
    with pytest.raises(InputError, match="grid sampling"):
        spec_from_dict({"sweep": {"base": "ring", "sampling": "sobol", "samples": 2}, "parameter": [table]})
    with pytest.raises(InputError) as err:
        make_plan(spec_from_dict({"sweep": {"base": "ring"}, "parameter": [table]}))
    assert err.value.field == "[outputs.frf]"
    with pytest.raises(InputError, match="assembly"):
        make_plan(spec_from_dict({"sweep": {"base": "paper"}, "parameter": [table], "outputs": {"frf": FAST_FRF}}))


def _direct_peaks(data: dict, responses: list[str]) -> tuple:
    """(peak amplitude, its frequency, blade 1-based, linear-free peak, linear-stuck peak, the
    FRF Dataset, the System) of a case dictionary, by slipstep.frequency.response.frf directly
    (not through the sweep); the linear peaks by sweep.mistuning.linear_peaks on that system."""
    from slipstep.frequency.response import frf
    from slipstep.sweep.mistuning import linear_peaks

    system, _ = build_case(data, str(CASES_DIR))
    freqs = np.linspace(FAST_FRF["start_Hz"], FAST_FRF["stop_Hz"], FAST_FRF["num"])
    ds = frf(system, freqs, solver="hbm", harmonics=(1, 3), responses=responses, check="none", adequacy=False)
    ds = ds.isel(frequency=np.flatnonzero(ds["point_kind"].values.astype(str) == "asked")).sortby("frequency")
    a = ds["amplitude"].transpose("frequency", "response").values
    i, j = np.unravel_index(np.argmax(a), a.shape)
    lin = linear_peaks(system, freqs, responses)
    return (
        float(a[i, j]),
        float(ds["frequency"].values[i]),
        int(j) + 1,
        lin["linear_free_peak_amplitude"],
        lin["linear_stuck_peak_amplitude"],
        ds,
    )


def test_the_amplification_statistics_equal_a_direct_serial_computation(tmp_path):
    m = Mistuning(levels=(0.03, 0.08), samples=2, seed=11)
    spec = _spec(m)
    report = run_sweep(spec, tmp_path / "m.zarr", executor=SerialExecutor())
    assert report["status_counts"] == {"OK": 4}
    ds = open_sweep(tmp_path / "m.zarr")
    responses = [f"blade{j}.8.x" for j in range(1, 7)]
    ring = read_toml(CASES_DIR / "ring.toml")
    tuned = _direct_peaks(ring, responses)
    for i in range(4):
        level, k = ds["mistuning_level"].values[i], int(ds["mistuning_sample"].values[i])
        data = copy.deepcopy(ring)
        data["chain"]["mistuning"] = list(level * np.random.default_rng([11, k]).standard_normal(6))
        peak, freq, blade, free, stuck, direct = _direct_peaks(data, responses)
        assert ds["peak_blade_amplitude"].values[i] == pytest.approx(peak, rel=1e-12)
        assert ds["peak_frequency_Hz"].values[i] == freq and ds["peak_blade"].values[i] == blade
        assert ds["amplification_factor"].values[i] == pytest.approx(peak / tuned[0], rel=1e-12)
        for name, lin, ref in (("linear_free", free, tuned[3]), ("linear_stuck", stuck, tuned[4])):
            assert ds[f"{name}_peak_amplitude"].values[i] == pytest.approx(lin[0], rel=1e-12)
            assert ds[f"{name}_peak_frequency_Hz"].values[i] == pytest.approx(lin[1], rel=1e-12)
            assert ds[f"{name}_peak_blade"].values[i] == lin[2]
            assert ds[f"{name}_amplification_factor"].values[i] == pytest.approx(lin[0] / ref[0], rel=1e-12)
            # the refined peak is at least the largest value on the FRF's grid (to the FRF's round-off)
            grid_max = float(direct[f"{name}_amplitude"].max())
            assert lin[0] >= grid_max * (1 - 1e-12)
        assert ds["mistuning_rms"].values[i] == pytest.approx(np.sqrt(np.mean(np.square(data["chain"]["mistuning"]))))
    # mistuning localises the response: some sample amplifies (AF > 1) the tuned peak
    assert ds["amplification_factor"].max() > 1.0
    assert ds["amplification_factor"].attrs["units"] == "1" and ds["peak_frequency_Hz"].attrs["units"] == "Hz"
    assert ds["linear_stuck_peak_frequency_Hz"].attrs["units"] == "Hz"
    assert ds["linear_free_peak_blade"].attrs["units"] == "1"
    reference = json.loads(ds.attrs["mistuning_reference"])[0]
    assert reference["linear_stuck_peak_amplitude"] == pytest.approx(tuned[4][0], rel=1e-12)
    assert reference["linear_stuck_peak_frequency_Hz"] == pytest.approx(tuned[4][1], rel=1e-12)


def test_sweep_plot_draws_the_mistuning_figures(tmp_path):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    spec = _spec(Mistuning(levels=(0.02, 0.05), samples=2, seed=0))
    run_sweep(spec, tmp_path / "p.zarr", executor=SerialExecutor())
    result = CliRunner().invoke(app, ["sweep-plot", str(tmp_path / "p.zarr"), "-o", str(tmp_path / "fig")])
    assert result.exit_code == 0, result.output
    paths = sorted((tmp_path / "fig").iterdir())
    assert [p.name for p in paths] == ["mistuning_distribution.png", "mistuning_levels.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_the_example_file_plans_200_rings():
    """examples/ring_mistuning.toml (run at full size by benchmarks/bench_mistuning.py)."""
    spec = load_spec(EXAMPLE)
    plan = make_plan(spec)
    assert plan.n_cases == 200 and plan.grid_shape == (4, 50)
    assert len(plan.outputs["frf"]["frequencies_Hz"]) == 21
    assert plan.outputs["mistuning"]["responses"] == [f"blade{j}.8.x" for j in range(1, 7)]
    small = dataclasses.replace(spec.parameters[0], levels=spec.parameters[0].levels[:1], samples=2)
    assert make_plan(dataclasses.replace(spec, parameters=(small,))).hashes == plan.hashes[:2]


def _ring(n: int, deltas=(), k=4e5, kc=1.2e4, m=0.1, zeta=0.004, engine_order=1, f0=300.0, sparse=False):
    """A ring of n one-DOF blades (mass m, stiffness k (1 + delta_j), a coupling spring kc to
    each neighbour), damping C = c I with c = 2 zeta sqrt(k m), forced by an engine-order
    travelling wave F_j = sin(w t - 2 pi EO j / n)."""
    d = np.zeros(n) if len(deltas) == 0 else np.asarray(deltas, float)
    K = np.diag(k * (1 + d) + 2 * kc)
    for j in range(n):
        K[j, (j + 1) % n] -= kc
        K[(j + 1) % n, j] -= kc
    M, C = m * np.eye(n), 2 * zeta * np.sqrt(k * m) * np.eye(n)
    if sparse:
        M, C, K = (sp.csr_matrix(X) for X in (M, C, K))
    phase = -2 * np.pi * engine_order * np.arange(n) / n
    force = ss.Signal(tuple(f"x{j}" for j in range(n)), (ss.Harmonic(f0, np.ones(n), phase),))
    return ss.System(ss.Structure(M, C, K), (), ss.Excitation(force=force), name="ring")


def _brute_force(system, f_min, f_max, points):
    """(max over blades and frequencies of |X|, its frequency) on a dense grid of ``points``
    frequencies, by one batched dense solve of (K - w^2 M + i w C) X = F (single harmonic)."""
    s, h = system.structure, system.excitation.force.harmonics[0]
    K, M, C = (np.asarray(getattr(X, "toarray", lambda X=X: X)(), float) for X in (s.stiffness, s.mass, s.damping))
    F = h.amplitude * np.exp(1j * h.phase)
    f = np.linspace(f_min, f_max, points)
    w = 2 * np.pi * f[:, None, None]
    D = K[None] - w**2 * M[None] + 1j * w * C[None]
    a = np.abs(np.linalg.solve(D, np.broadcast_to(F, (f.size, F.size))[..., None])[..., 0]).max(axis=1)
    i = int(np.argmax(a))
    return float(a[i]), float(f[i]), a


def test_a_refined_linear_peak_is_the_closed_form_damped_peak():
    """Two equal masses on springs k, coupled by kc, damping c on each, both forced by the same
    sine: only the in-phase mode responds, X = F / (k - w^2 m + i w c), whose amplitude peaks at
    w_p^2 = k/m - c^2 / (2 m^2) with |X| = F / (c w_d), w_d^2 = k/m - c^2 / (4 m^2). The peak lies
    between the points of an 11-point grid; the refinement finds it to 1e-9."""
    from slipstep.steady.linear import LinearLimit
    from slipstep.sweep.mistuning import linear_peak, linear_peaks

    m, k, kc, c = 0.1, 4e5, 3e4, 2.0
    M, K, C = m * np.eye(2), np.array([[k + kc, -kc], [-kc, k + kc]]), c * np.eye(2)
    force = ss.Signal(("x0", "x1"), (ss.Harmonic(300.0, np.array([1.0, 1.0]), np.array([0.3, 0.3])),))
    system = ss.System(ss.Structure(M, C, K), (), ss.Excitation(force=force), name="two")
    f_peak = np.sqrt(k / m - c**2 / (2 * m**2)) / (2 * np.pi)
    a_peak = 1.0 / (c * np.sqrt(k / m - c**2 / (4 * m**2)))
    grid = np.linspace(250.0, 400.0, 11)
    p = linear_peaks(system, grid, ["x0", "x1"])
    assert p["linear_free_peak_amplitude"] == p["linear_stuck_peak_amplitude"]  # no contacts: one limit
    amp, f, blade = p["linear_free_peak_amplitude"]
    assert f == pytest.approx(f_peak, rel=1e-9) and amp == pytest.approx(a_peak, rel=1e-12) and blade == 1
    # the grid alone under-estimates it by far (the nearest point is 8.3 Hz away, 5 half-power
    # half-widths zeta f = 1.6 Hz: 1 / sqrt(1 + 5^2) of the peak)
    limit = LinearLimit(system, False)
    assert max(limit.amplitude(x).max() for x in grid) < 0.25 * a_peak
    # a band beside the resonance (within its width of it): the resonance's peak counts, not the
    # band's edge value (341.3 Hz, the anti-phase mode, is not forced)
    for band in ((250.0, 310.0), (320.0, 330.0)):
        amp, f, blade = linear_peak(limit, [0, 1], *band)
        assert f == pytest.approx(f_peak, rel=1e-9) and amp == pytest.approx(a_peak, rel=1e-12) and blade == 1
        assert limit.amplitude(band[1]).max() < 0.5 * a_peak
    # a band far from every mode: the nearest mode's peak
    amp, f, _ = linear_peak(limit, [0, 1], 100.0, 110.0)
    assert f == pytest.approx(f_peak, rel=1e-9)


def test_a_linear_limit_at_any_frequency_equals_the_retuned_linear_response():
    from slipstep.model.retune import retune
    from slipstep.steady.linear import LinearLimit, linear_response

    system = _ring(5, deltas=[0.01, -0.02, 0.0, 0.03, 0.01])
    limit = LinearLimit(system, False)
    for f in (250.0, 317.3, 333.0):
        np.testing.assert_allclose(limit.amplitude(f), linear_response(retune(system, f), False)[1], rtol=1e-13)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_refined_linear_peaks_of_a_mistuned_ring_equal_a_brute_force_dense_grid(seed):
    """Off-grid resonances of a mistuned 6-blade ring (split modes between the 21 grid points):
    the refined peak equals the largest value on a 150,001-point grid to 1e-6 (the dense grid's
    own resolution), at the same frequency to the dense grid's spacing."""
    from slipstep.sweep.mistuning import linear_peaks

    deltas = 0.03 * np.random.default_rng(seed).standard_normal(6)
    system = _ring(6, deltas)
    f_min, f_max = 285.0, 335.0
    amp, f, blade = linear_peaks(system, np.linspace(f_min, f_max, 21), [f"x{j}" for j in range(6)])[
        "linear_free_peak_amplitude"
    ]
    dense, f_dense, a = _brute_force(system, f_min, f_max, 150_001)
    assert amp == pytest.approx(dense, rel=1e-6) and amp >= dense * (1 - 1e-12)
    assert abs(f - f_dense) <= (f_max - f_min) / 150_000
    coarse = a[:: 150_000 // 20]  # the 21-point grid: never above the refined peak
    assert coarse.size == 21 and coarse.max() <= amp


def test_sparse_and_dense_linear_peaks_agree():
    """A spring chain with contacts (both limits differ) as scipy sparse and as dense matrices;
    the sparse path finds its modes by shift-invert, from 4 up (doubled until the band is
    covered)."""
    from test_hbm_sparse import _chain

    from slipstep.sweep.mistuning import limit_modes, linear_peaks
    from slipstep.steady.linear import LinearLimit

    grid, tip = np.linspace(20.0, 120.0, 11), ["x29"]
    sparse_sys, dense_sys = _chain(30, 3, dense=False), _chain(30, 3, dense=True)
    a = linear_peaks(sparse_sys, grid, tip, modes=4)
    b = linear_peaks(dense_sys, grid, tip, modes=4)
    assert a["linear_stuck_peak_amplitude"][1] != pytest.approx(a["linear_free_peak_amplitude"][1], rel=1e-3)
    for field in ("linear_stuck_peak_amplitude", "linear_free_peak_amplitude"):
        assert a[field][0] == pytest.approx(b[field][0], rel=1e-12)
        # the peak's frequency to the flatness of the maximum: A(f) / A_peak - 1 ~ -((f - f_p) / (zeta f_p))^2,
        # so a round-off difference in A moves it by ~ zeta sqrt(1e-16) = 1e-10 relative and more
        assert a[field][1] == pytest.approx(b[field][1], rel=1e-7)
    fs, zs = limit_modes(LinearLimit(sparse_sys, False), 20.0, 120.0, 4)
    fd, zd = limit_modes(LinearLimit(dense_sys, False), 20.0, 120.0, 4)
    np.testing.assert_allclose(fs, fd, rtol=1e-10)
    np.testing.assert_allclose(zs, zd, rtol=1e-8)
    # the 4 modes nearest the band (M = m I: the eigenvalues of K / m): its 2, then 182.8, 255.2 Hz
    s = dense_sys.structure
    f_all = np.sort(np.sqrt(np.linalg.eigvalsh(s.stiffness / s.mass[0, 0])) / (2 * np.pi))
    np.testing.assert_allclose(fd, f_all[:4], rtol=1e-10)
    assert f_all[1] < 120.0 < f_all[2]


def test_linear_amplification_factors_stay_below_the_whitehead_limit():
    """Whitehead (1966): the largest blade amplitude of a mistuned one-DOF-per-blade ring is at
    most (1 + sqrt(N)) / 2 times the tuned ring's. 40 rings of 6 blades, std 0.5 % to 4 %: every
    refined factor below it, and mistuning does amplify (some factor well above 1)."""
    from slipstep.sweep.mistuning import linear_peaks

    n, band, dofs = 6, np.linspace(270.0, 350.0, 21), [f"x{j}" for j in range(6)]
    tuned = linear_peaks(_ring(n), band, dofs)["linear_free_peak_amplitude"][0]
    limit = (1 + np.sqrt(n)) / 2
    factors = []
    for seed in range(40):
        std = (0.005, 0.01, 0.02, 0.04)[seed % 4]
        system = _ring(n, std * np.random.default_rng(seed).standard_normal(n))
        factors.append(linear_peaks(system, band, dofs)["linear_free_peak_amplitude"][0] / tuned)
    assert max(factors) <= limit
    assert max(factors) > 1.2
