"""The FRF entry point (slipstep.frequency.frf) of issue 24: every solver behind one function,
the auto rule, an error estimate on every point checked against the exact continuous orbit
of the Jenkins oscillator (tests/frf_accuracy.py), the linear limits as the answer where the
contacts are absent, stuck or open, strict JSON and the same short options on the CLI."""

import json
import math
import warnings

import numpy as np
import pytest
from frf_accuracy import FREQUENCIES, JENKINS, frf_at_defaults, reference, rows

import slipstep as ss
from slipstep.errors import InputError
from slipstep.frequency import SOLVERS, choose_solver, frf, retune
from slipstep.frequency.error_estimate import FrfAccuracyWarning
from slipstep.frequency.response import point_values
from slipstep.steady import shoot
from slipstep.steady.marching import STEADY_STEPS_PER_PERIOD as DEFAULT_STEPS  # the steady step T / N

COARSE = 50  # steps per period of the checks that need errors above 1e-3


def _cli(*args):
    from typer.testing import CliRunner

    from slipstep.cli.main import app

    return CliRunner().invoke(app, list(args))


def _strict_json(text: str):
    """json.loads refusing NaN and Infinity (what JSON parsers outside Python do)."""

    def refuse(constant):
        raise ValueError(f"{constant} is not JSON")

    return json.loads(text, parse_constant=refuse)


# ---- the accuracy on the Jenkins oscillator --------------------------------------------------


@pytest.mark.parametrize("solver", ["march", "shoot", "hbm", "auto"])
def test_jenkins_at_defaults_within_rtol_or_warns_and_the_estimate_tracks_the_error(solver):
    """At 11 frequencies across 250-500 Hz (the resonance and both flanks), each solver at its
    defaults: every point within 1 % of the exact energies per cycle, or it warns; the error
    estimate within a factor 3 of the true error wherever that is above 2e-4 (a fiftieth of the
    default rtol; at 250 Hz the true error is 1.3e-4 and the estimate of the pair of 128 and 256
    steps 0.23 of it: there the transitions' timing, not h^2, dominates the small error)."""
    ds, warned = frf_at_defaults(solver)
    points = rows(ds)
    assert [p["frequency_Hz"] for p in points] == pytest.approx(list(FREQUENCIES))
    assert all(p["status"] == "OK" for p in points), points
    for p in points:
        assert p["true_error"] <= 1e-2 or p["status_message"], p
        if p["true_error"] > 2e-4:
            assert p["true_error"] / 3 <= p["error_estimate"] <= 3 * p["true_error"], p
    assert len(warned) == any(p["status_message"] for p in points)
    assert np.isfinite(ds["steps_per_period"].values).all()
    if solver != "hbm":  # solved at T / (N/2), the point returned is the doubled-steps solution
        assert (ds["steps_per_period"].values >= DEFAULT_STEPS).all()
        assert ds["time_step"].values == pytest.approx(1 / ds["frequency"].values / ds["steps_per_period"].values)


@pytest.mark.parametrize("solver", ["march", "shoot"])
def test_the_warning_follows_the_true_error(solver):
    """At 50 steps per period (100 in the returned points), rtol 2e-3 and no refinement: the
    points whose true error is above 2 rtol warn, those below rtol / 3 do not (both kinds occur
    on the grid), with one summary warning."""
    rtol = 2e-3
    ds, warned = frf_at_defaults(solver, rtol=rtol, max_refinements=0, steps_per_period=COARSE)
    points = rows(ds)
    big = [p for p in points if p["true_error"] > 2 * rtol]
    small = [p for p in points if p["true_error"] < rtol / 3]
    assert big and small
    assert all(p["status_message"] and "above rtol" in p["status_message"] for p in big), big
    assert not any(p["status_message"] for p in small), small
    assert all(p["status"] == "OK" for p in points)  # a warning keeps the status
    assert len(warned) == 1 and issubclass(warned[0].category, FrfAccuracyWarning)
    assert (ds["step_refinements"].values == 0).all() and (ds["steps_per_period"].values == 2 * COARSE).all()


def test_the_point_is_the_finer_solution_and_the_estimate_is_richardsons():
    """At 350 Hz from 50 steps per period: the returned point equals the orbit shot at 100 steps
    per period, and its estimate is |E_50 - E_100| / |E_100| / 3 of the two energies (the larger)."""
    system = ss.load_system(JENKINS)
    ds = frf(system, [350.0], solver="shoot", linear=False, steps_per_period=COARSE)
    s = retune(system, 350.0)
    e = {}
    for n in (COARSE, 2 * COARSE):
        v = point_values(shoot(s, steps_per_period=n), s, ["x"], 1)
        e[n] = (float(v["energy_per_cycle"].sum()), float(v["excitation_work"]))
    assert float(ds["energy_per_cycle"].values.sum()) == pytest.approx(e[100][0], rel=1e-7)
    assert float(ds["excitation_work"].values[0]) == pytest.approx(e[100][1], rel=1e-7)
    expected = max(abs(e[50][k] - e[100][k]) / abs(e[100][k]) / 3 for k in (0, 1))
    assert float(ds["error_estimate"].values[0]) == pytest.approx(expected, rel=1e-5)
    assert int(ds["steps_per_period"].values[0]) == 100 and ds.attrs["rtol"] == 1e-2
    assert float(ds["error_estimate"].values[0]) > 1e-3  # an error the check can see
    assert "step doubling" in ds.attrs["error_estimate_method"]


# ---- the linear limits: no contacts, every contact stuck, contacts that never close ----------


def _jenkins_variant(kind: str):
    base = ss.load_system(JENKINS)
    c = base.contacts[0]
    if kind == "none":
        return ss.System(base.structure, (), base.excitation, name="none"), 0.0
    if kind == "stuck":
        contact = ss.ContactElement(
            c.name, c.dof_gather, c.tangential_stiffness, c.normal_stiffness, 1e6, normal_offset=c.normal_offset
        )
        return ss.System(base.structure, (contact,), base.excitation, name="stuck"), 1e7
    # the gap is x + 1 m: the contact never closes at micrometre amplitudes
    contact = ss.ContactElement(
        c.name, np.array([[1.0], [1.0]]), c.tangential_stiffness, c.normal_stiffness, 1.0, normal_offset=-1.0
    )
    return ss.System(base.structure, (contact,), base.excitation, name="open"), 0.0


@pytest.mark.parametrize("kind", ["none", "stuck", "open"])
@pytest.mark.parametrize("solver", ["march", "shoot", "hbm", "auto"])
def test_linear_limits_are_the_answer(kind, solver):
    """The response is linear: harmonic 1 equals F / (k + k_t - w^2 m + i w c) to round-off, at
    the excitation frequency for harmonic balance and at the trapezoidal rule's warped frequency
    (2/h) tan(w h / 2) for the time-domain solvers (h: the step the Dataset records); no higher
    harmonics, no friction work; the time-domain error of the excitation work (exact: pi c w |X|^2
    per cycle) below rtol, and its estimate within 3x of it away from the resonance."""
    system, kt = _jenkins_variant(kind)
    options = {"tolerance": 1e-12, "max_periods": 5000} if solver == "march" else {}
    ds = frf(system, [300.0, 400.0, 450.0], solver=solver, **options)
    assert (ds["status"].values == "OK").all()
    m, c, k, force = 2.5, 100.0, 1e7, 100.0
    w = 2 * np.pi * ds["frequency"].values
    if solver != "hbm":
        h = 1 / ds["frequency"].values / ds["steps_per_period"].values
        w_eff = 2 / h * np.tan(w * h / 2)
    else:
        w_eff = w
    X = force / (k + kt - w_eff**2 * m + 1j * w_eff * c)
    A = ds["harmonic_amplitude"].sel(response="x").values
    phase = ds["harmonic_phase"].sel(response="x", harmonic=1).values
    got = A[:, 1] * np.exp(1j * (phase + np.pi / 2))  # x = |X| sin(w t + arg X) = |X| cos(w t + arg X - pi/2)
    assert np.abs(got - X).max() <= 1e-8 * np.abs(X).max()
    assert np.abs(A[:, 2:]).max() <= 1e-8 * np.abs(X).max()
    W = ds["excitation_work"].values
    assert np.abs(ds["energy_per_cycle"].values).max(initial=0.0) <= 1e-10 * W.max()
    if solver != "hbm":
        exact = np.pi * c * w * np.abs(force / (k + kt - w**2 * m + 1j * w * c)) ** 2
        true = np.abs(W - exact) / exact
        est = ds["error_estimate"].values
        assert (true <= 1e-2).all() and (est <= 1e-2).all()
        # within 1 % of the resonance (450.16 Hz stuck: the 450 Hz point) the step's frequency shift
        # (w h)^2 / 12 crosses the peak between h and h/2: the error is not yet ~ h^2 there
        away = np.abs(w / np.sqrt((k + kt) / m) - 1) > 0.01
        assert away.sum() >= 2
        assert ((true / 3 <= est) & (est <= 3 * true))[away].all(), (true, est)


# ---- one entry point, the auto rule, the asked grid ------------------------------------------


def test_hbm_through_the_entry_point():
    system = ss.load_system(JENKINS)
    ds = frf(system, np.linspace(320, 380, 4), solver="hbm", check="none")
    assert ds.attrs["solver"] == "hbm" and "truncation" in ds.attrs["error_estimate_method"]
    assert np.array_equal(ds["error_estimate"].values, ds["harmonic_truncation_estimate"].values, equal_nan=True)
    assert (ds["steps_per_period"].values == ds.attrs["samples"]).all()
    assert (ds["status"].values == "OK").all() and np.isnan(ds["time_step"].values).all()


def test_hbm_returns_the_asked_grid():
    system = ss.load_system(JENKINS)
    for asked in ([340.0, 350.0, 360.0], list(np.linspace(300, 400, 9))):
        ds = frf(system, asked, solver="hbm", check="none")
        kind = ds["point_kind"].values
        on_grid = ds["frequency"].values[kind == "asked"]
        assert on_grid == pytest.approx(asked)


def test_march_and_shoot_return_the_asked_grid_per_sweep():
    system = ss.load_system(JENKINS)
    asked = [360.0, 300.0, 330.0]
    down = frf(system, asked, direction="down", linear=False)
    assert list(down["frequency"].values) == sorted(asked, reverse=True)
    both = frf(system, asked, solver="march", direction="both", linear=False)
    assert list(both["frequency"].values) == sorted(asked) and list(both["sweep"].values) == ["up", "down"]
    assert np.isfinite(both["error_estimate"].values).all()


def test_auto_chooses_shooting_and_the_advisors_method():
    for case in ("blades", "ring"):
        name, reason = choose_solver(ss.load_system(case))
        assert name == "shoot" and "quasi-static-dofs" in reason and "advisor" in reason
    for case in ("paper", JENKINS):
        name, reason = choose_solver(ss.load_system(case))
        assert name == "shoot" and "piecewise-linear" in reason
    assert tuple(SOLVERS) == ("auto", "march", "shoot", "hbm")
    import inspect
    import pkgutil

    import slipstep.cli.main  # noqa: F401  (first: cli_frf imported alone registers nothing: a circular import)
    from slipstep.cli.frf import frf as frf_command
    from slipstep.frequency import choice, response
    from slipstep.hbm.frf import frf as hbm_frf
    from slipstep.output.frf_schema import FRF_SOLVERS, solver_help
    from slipstep.steady import march_to_steady, shoot

    assert tuple(FRF_SOLVERS) == tuple(SOLVERS)  # one table: the CLI's --solver values are frf's
    option = inspect.signature(frf_command).parameters["solver"].default
    assert option.help == solver_help() and all(f"{name} (" in option.help for name in SOLVERS)
    runs = {name: pkgutil.resolve_name(s.runs) for name, s in FRF_SOLVERS.items()}
    assert runs == {"auto": choice.choose, "march": march_to_steady, "shoot": shoot, "hbm": hbm_frf}
    assert response.STEADY_SOLVERS == {"march": march_to_steady, "shoot": shoot}


@pytest.mark.parametrize("case", ["ring", "paper"])
def test_auto_converges_on_the_built_in_cases(case):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FrfAccuracyWarning)  # converged is the claim here, not within rtol
        ds = frf(ss.load_system(case), [200.0, 300.0, 400.0], linear=False)
    assert (ds["status"].values == "OK").all(), ds["status_message"].values
    assert ds.attrs["solver"] == "shoot" and ds.attrs["solver_reason"]
    assert np.isfinite(ds["error_estimate"].values).all() and np.isfinite(ds["floquet_multiplier_max"].values).all()


def test_bad_input_names_the_key():
    system = ss.load_system(JENKINS)
    for kwargs, key in (
        ({"rtol": 0.0}, "rtol"),
        ({"rtol": 2.0}, "rtol"),
        ({"max_refinements": -1}, "max_refinements"),
        ({"solver": "newton"}, "solver"),
        ({"solver": "march", "samples": 64}, "samples"),
        ({"solver": "hbm", "settle_periods": 2}, "settle_periods"),
    ):
        with pytest.raises(InputError) as err:
            frf(system, [300.0], **kwargs)
        assert err.value.field == key


# ---- the command line ------------------------------------------------------------------------


def test_cli_default_converges_on_blades_and_prints_the_choice(tmp_path):
    r = _cli("frf", "blades", "--frequencies", "200:400:5", "-o", str(tmp_path), "--json")
    assert r.exit_code == 0, r.output
    s = _strict_json(r.stdout)
    assert s["solver"] == "shoot" and "quasi-static-dofs" in s["solver_reason"]
    assert s["points"] == 5 and s["points_not_ok"] == 0
    assert s["rtol"] == 1e-2 and s["points_above_rtol"] == 0 and 0 < s["max_error_estimate"] <= 1e-2
    text = _cli("frf", "blades", "--frequencies", "300", "-o", str(tmp_path))
    assert text.exit_code == 0 and "solver: shoot (shooting" in text.output and "error estimate" in text.output


def test_cli_warns_above_rtol_and_exits_0_when_converged(tmp_path):
    r = _cli("frf", str(JENKINS), "-f", "320,350", "--rtol", "1e-5", "--max-refinements", "0", "-o", str(tmp_path))
    assert r.exit_code == 0, r.output
    assert "WARNING: 2 point(s) above rtol" in r.output and "warning: 2 FRF point(s)" in r.output
    import xarray as xr

    ds = xr.load_dataset(tmp_path / "jenkins_frf.nc", engine="h5netcdf")
    assert all("above rtol" in m for m in ds["status_message"].values) and (ds["status"].values == "OK").all()


def test_cli_json_is_strict_where_values_are_missing(tmp_path):
    """Harmonic balance's cross-check of a system without friction has no energy difference
    (NaN in the Dataset): null in the JSON, never a bare NaN."""
    case = tmp_path / "free.toml"
    text = JENKINS.read_text()
    case.write_text(text[: text.index("[[contacts]]")] + text[text.index("[[force]]") :])
    r = _cli("frf", str(case), "-f", "300", "--solver", "hbm", "-o", str(tmp_path), "--json")
    assert r.exit_code == 0, r.output
    s = _strict_json(r.stdout)
    assert s["checks"] and s["checks"][0]["energy_rel_diff"] is None
    assert "NaN" not in r.stdout and "Infinity" not in r.stdout


def test_every_output_option_has_the_same_short_name():
    import typer.main

    from slipstep.cli.main import app

    group = typer.main.get_command(app)
    checked = 0
    for name, command in group.commands.items():
        for param in command.params:
            longs = [o for o in param.opts if o.startswith("--output")]
            if longs:
                assert "-o" in param.opts + param.secondary_opts, (name, param.opts)
                checked += 1
    assert checked >= 6  # run, compare, frf, plot, report, sweep, sweep-plot ...


def test_error_variables_are_in_the_schema_with_units():
    from slipstep.frequency import FRF_SCHEMA

    assert FRF_SCHEMA["error_estimate"][1] == "1" and FRF_SCHEMA["time_step"][1] == "s"
    ds = frf_at_defaults("shoot", FREQUENCIES[:2])[0]
    assert ds["status_message"].dtype.kind == "U" and ds["error_estimate"].attrs["units"] == "1"
    assert not math.isnan(reference(FREQUENCIES[0])["excitation_work"])


def test_a_point_not_steady_keeps_its_status_and_step_without_an_estimate(tmp_path):
    ds = frf(ss.load_system(JENKINS), [350.0], solver="march", max_periods=2, linear=False)
    assert ds["status"].values[0] == "NOT_STEADY" and "not steady after 2" in ds["status_message"].values[0]
    # solved at T / (N/2), and again at T / N when that did not converge: the step it ended at is recorded
    assert np.isnan(ds["error_estimate"].values[0]) and ds["steps_per_period"].values[0] == DEFAULT_STEPS
    assert ds["periods_to_steady"].values[0] == 4  # both solves counted
    r = _cli(
        "frf", str(JENKINS), "-f", "340,350", "--solver", "march", "--max-periods", "2", "-o", str(tmp_path), "--json"
    )
    assert r.exit_code == 1, r.output
    s = _strict_json(r.stdout)
    assert s["points_not_ok"] == 2 and s["max_error_estimate"] is None and s["points_without_estimate"] == 2


def test_rtol_none_gives_the_points_as_solved():
    system = ss.load_system(JENKINS)
    ds = frf(system, [350.0], solver="shoot", rtol=None, linear=False)
    s = retune(system, 350.0)
    v = point_values(shoot(s), s, ["x"], 1)
    assert float(ds["energy_per_cycle"].values.sum()) == pytest.approx(float(v["energy_per_cycle"].sum()), rel=1e-9)
    assert ds["steps_per_period"].values[0] == DEFAULT_STEPS and np.isnan(ds["error_estimate"].values[0])
    assert "rtol" not in ds.attrs and ds.attrs["error_estimate_method"] == "none"
    with pytest.raises(InputError, match="rtol"):
        frf(system, [350.0], solver="hbm", rtol=None)


@pytest.mark.parametrize("solver", ["march", "shoot"])
def test_stepped_points_are_the_asked_ones(solver):
    """A stepped FRF (march, shoot) solves exactly the asked frequencies: point_kind "asked"."""
    ds = frf(ss.load_system(JENKINS), [340.0, 360.0], solver=solver, linear=False, rtol=None)
    assert list(ds["point_kind"].values) == ["asked", "asked"]


def test_a_point_that_fails_after_an_unstable_orbit_names_the_turning_point():
    """Issue 24: a point that does not converge after a point whose orbit was unstable (|mu| > 1)
    says that a turning point may lie between and names the solver that passes it; after a stable
    orbit, or without multipliers (marching), nothing is added."""
    from types import SimpleNamespace

    from slipstep.frequency.response import turning_point_hint

    unstable = SimpleNamespace(floquet_multipliers=np.array([1.24 + 0.1j, 0.5]))
    hint = turning_point_hint(unstable)
    assert "turning point" in hint and "solver='hbm'" in hint and "1.24" in hint
    assert turning_point_hint(SimpleNamespace(floquet_multipliers=np.array([0.99, 0.5]))) == ""
    assert turning_point_hint(SimpleNamespace(floquet_multipliers=None)) == ""
    assert turning_point_hint(None) == ""
