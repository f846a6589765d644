"""Mistuning sweeps (issue 27): the blade deltas of each sample (reproducible, the asked
distribution), written into chain and chain-less assemblies, and the amplification statistics
of the FRF against a direct serial computation through slipstep.frequency.response.frf."""

from __future__ import annotations

import copy
import math
import dataclasses
from pathlib import Path

import numpy as np
import pytest

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


def _direct_peaks(data: dict, responses: list[str]) -> tuple[float, float, int, float, float]:
    """(peak amplitude, its frequency, blade 1-based, linear-free peak, linear-stuck peak) of a
    case dictionary, by slipstep.frequency.response.frf directly (not through the sweep)."""
    from slipstep.frequency.response import frf

    system, _ = build_case(data, str(CASES_DIR))
    freqs = np.linspace(FAST_FRF["start_Hz"], FAST_FRF["stop_Hz"], FAST_FRF["num"])
    ds = frf(system, freqs, solver="hbm", harmonics=(1, 3), responses=responses, check="none", adequacy=False)
    ds = ds.isel(frequency=np.flatnonzero(ds["point_kind"].values.astype(str) == "asked")).sortby("frequency")
    a = ds["amplitude"].transpose("frequency", "response").values
    i, j = np.unravel_index(np.argmax(a), a.shape)

    def resonant_peak(name):  # the largest value of a linear limit, NaN on the grid's edge
        values = ds[name].transpose("frequency", "response").values.max(axis=1)
        k = int(np.argmax(values))
        return float(values[k]) if 0 < k < values.size - 1 else math.nan

    return (
        float(a[i, j]),
        float(ds["frequency"].values[i]),
        int(j) + 1,
        resonant_peak("linear_free_amplitude"),
        resonant_peak("linear_stuck_amplitude"),
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
        peak, freq, blade, free, stuck = _direct_peaks(data, responses)
        assert ds["peak_blade_amplitude"].values[i] == pytest.approx(peak, rel=1e-12)
        assert ds["peak_frequency_Hz"].values[i] == freq and ds["peak_blade"].values[i] == blade
        assert ds["amplification_factor"].values[i] == pytest.approx(peak / tuned[0], rel=1e-12)
        assert ds["linear_free_amplification_factor"].values[i] == pytest.approx(
            free / tuned[3], rel=1e-12, nan_ok=True
        )
        assert ds["linear_stuck_amplification_factor"].values[i] == pytest.approx(
            stuck / tuned[4], rel=1e-12, nan_ok=True
        )
        assert ds["mistuning_rms"].values[i] == pytest.approx(np.sqrt(np.mean(np.square(data["chain"]["mistuning"]))))
    # mistuning localises the response: some sample amplifies (AF > 1) the tuned peak
    assert ds["amplification_factor"].max() > 1.0
    assert ds["amplification_factor"].attrs["units"] == "1" and ds["peak_frequency_Hz"].attrs["units"] == "Hz"


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


def test_a_linear_limit_peaking_on_the_grid_edge_has_no_amplification_factor():
    """A linear limit whose largest value is on the first or last frequency resonates outside
    the grid: no peak (NaN, blade -1), so no amplification factor; an interior maximum is kept
    and the friction response's peak is kept wherever it lies."""
    from slipstep.sweep.mistuning import peaks

    f = np.array([100.0, 110.0, 120.0, 130.0])
    rising = np.array([[1.0, 2.0], [2.0, 3.0], [3.0, 4.0], [4.0, 5.0]])  # peak on the last point
    interior = np.array([[1.0, 2.0], [5.0, 3.0], [3.0, 4.0], [1.0, 2.0]])
    p = peaks(
        {"amplitude": rising, "linear_stuck_amplitude": rising, "linear_free_amplitude": interior},
        f,
        ["a", "b"],
        ["a", "b"],
    )
    assert math.isnan(p["linear_stuck_peak_amplitude"][0]) and p["linear_stuck_peak_amplitude"][2] == -1
    assert p["linear_free_peak_amplitude"] == (5.0, 110.0, 1)
    assert p["peak_blade_amplitude"] == (5.0, 130.0, 2)
