"""Sweep specifications: key paths into the case file, sampling, hashing, and bad input that
names the key the user wrote. No simulation here (fast)."""

from __future__ import annotations

import numpy as np
import pytest

from slipstep.casefile.case import CASES_DIR, read_toml
from slipstep.errors import InputError
from slipstep.sweep import Parameter, SweepSpec, load_spec, make_plan, resolve, spec_from_dict
from slipstep.sweep.cases import unit_of

PAPER = read_toml(CASES_DIR / "paper.toml")


def _spec(*params, **kw):
    return SweepSpec(base="paper", parameters=tuple(params), **kw)


# ---------------------------------------------------------------- key paths


def test_key_paths_by_index_name_component_and_wildcard():
    assert resolve(PAPER, "damper.centrifugal_force_N") == [("damper", "centrifugal_force_N")]
    assert resolve(PAPER, "motion.1.amplitude") == [("motion", 0, "amplitude")]  # 1-based
    assert resolve(PAPER, "motion.right.x.amplitude") == [("motion", 0, "amplitude")]  # component with a dot
    assert resolve(PAPER, "damper.contacts.P3.friction_coefficient") == [
        ("damper", "contacts", 2, "friction_coefficient")
    ]
    assert resolve(PAPER, "damper.contacts.*.friction_coefficient") == [
        ("damper", "contacts", j, "friction_coefficient") for j in range(3)
    ]
    assert resolve(PAPER, "damper.contacts.P3.position_mm.2") == [("damper", "contacts", 2, "position_mm", 1)]
    # a key the base case leaves at its default is addressable (the case validation checks its name)
    assert resolve(PAPER, "damper.centrifugal_angle_deg") == [("damper", "centrifugal_angle_deg")]


def test_apply_values_writes_every_location_and_leaves_the_base_alone():
    plan = make_plan(
        _spec(
            Parameter("damper.contacts.*.friction_coefficient", values=(0.1, 0.2)),
            Parameter("motion.1.amplitude", values=(5.0,)),
        )
    )
    case = plan.case_dict(1)
    assert [c["friction_coefficient"] for c in case["damper"]["contacts"]] == [0.2, 0.2, 0.2]
    assert case["motion"][0]["amplitude"] == 5.0
    assert [c["friction_coefficient"] for c in PAPER["damper"]["contacts"]] == [0.4, 0.4, 0.25]
    assert plan.base["damper"]["contacts"][0]["friction_coefficient"] == 0.4


@pytest.mark.parametrize(
    "key, problem",
    [
        ("damper.centrifugal_forc_N.x", "damper has no key 'centrifugal_forc_N'"),
        ("motion.2.amplitude", "index 2 is out of range: motion has 1 entry"),
        ("motion.0.amplitude", "index 0 is out of range"),
        ("damper.contacts.P9.friction_coefficient", "damper.contacts has no entry 'P9'"),
        ("damper.contacts.P1.position_mm", "is a list, not a number"),
        ("damper.contacts", "is a list, not a number"),
        ("damper.mass_kg.x", "damper.mass_kg is a value, not a table"),
        ("damper..mass_kg", "has an empty segment"),
    ],
)
def test_bad_key_paths_name_the_key(key, problem):
    with pytest.raises(InputError) as exc:
        make_plan(_spec(Parameter(key, values=(1.0,))))
    assert exc.value.field == key
    assert problem in exc.value.problem


def test_a_misspelt_final_key_is_named_by_the_case_validation():
    from slipstep.sweep.run import labels_of

    plan = make_plan(_spec(Parameter("damper.centrifugal_forc_N", values=(100.0,))))
    with pytest.raises(InputError) as exc:
        labels_of(plan)
    assert "centrifugal_forc_N" in exc.value.field and "base case of the sweep" in exc.value.problem


def test_units_from_key_names():
    assert unit_of("damper.centrifugal_force_N", "damper") == "N"
    assert unit_of("damper.contacts.*.normal_stiffness_N_per_um", "damper") == "N/um"
    assert unit_of("motion.1.amplitude", "damper") == "um"
    assert unit_of("motion.1.amplitude", "structure") == "m"
    assert unit_of("force.1.amplitude", "structure") == "N"
    assert unit_of("damper.contacts.*.friction_coefficient", "damper") == "1"
    assert unit_of("damper.platforms.2.angle_deg", "damper") == "deg"
    assert unit_of("structure.constant_force_N.2", "structure") == "N"


# ---------------------------------------------------------------- sampling


def test_grid_order_first_parameter_slowest():
    plan = make_plan(
        _spec(
            Parameter("damper.centrifugal_force_N", values=(100.0, 200.0)),
            Parameter("motion.1.amplitude", start=1.0, stop=100.0, num=3, scale="log"),
        )
    )
    assert plan.grid_shape == (2, 3)
    np.testing.assert_allclose(plan.values, [[100, 1], [100, 10], [100, 100], [200, 1], [200, 10], [200, 100]])
    assert [p.name for p in plan.parameters] == ["centrifugal_force_N", "amplitude"]
    names = make_plan(
        _spec(
            Parameter("damper.contacts.P3.position_mm.2", values=(1.0,)),
            Parameter("damper.contacts.P1.friction_coefficient", values=(0.3,)),
            Parameter("damper.contacts.P3.friction_coefficient", values=(0.3,)),
        )
    ).parameters
    assert [p.name for p in names] == ["position_mm_2", "P1_friction_coefficient", "P3_friction_coefficient"]
    assert [p.unit for p in plan.parameters] == ["N", "um"]


def test_zip_pairs_the_lists():
    plan = make_plan(
        _spec(
            Parameter("damper.centrifugal_force_N", values=(100.0, 200.0, 300.0)),
            Parameter("motion.1.amplitude", start=10.0, stop=30.0, num=3),
            sampling="zip",
        )
    )
    assert plan.grid_shape is None
    np.testing.assert_allclose(plan.values, [[100, 10], [200, 20], [300, 30]])


@pytest.mark.parametrize("sampling", ["latin-hypercube", "sobol"])
def test_sampled_sweeps_fill_the_box_reproducibly(sampling):
    params = (
        Parameter("damper.centrifugal_force_N", low=50.0, high=400.0),
        Parameter("damper.contacts.*.friction_coefficient", low=0.05, high=0.8, scale="log"),
    )
    a = make_plan(_spec(*params, sampling=sampling, samples=64, seed=3))
    b = make_plan(_spec(*params, sampling=sampling, samples=64, seed=3))
    c = make_plan(_spec(*params, sampling=sampling, samples=64, seed=4))
    np.testing.assert_array_equal(a.values, b.values)
    assert not np.array_equal(a.values, c.values)
    assert a.values[:, 0].min() >= 50 and a.values[:, 0].max() <= 400
    assert a.values[:, 1].min() >= 0.05 and a.values[:, 1].max() <= 0.8
    # stratified: each of 8 equal bins of each (log) axis holds 8 of the 64 points
    for col, (lo, hi, log) in enumerate([(50.0, 400.0, False), (0.05, 0.8, True)]):
        v = np.log(a.values[:, col]) if log else a.values[:, col]
        edges = np.linspace(np.log(lo) if log else lo, np.log(hi) if log else hi, 9)
        counts = np.histogram(v, edges)[0]
        assert counts.tolist() == [8] * 8, counts


def test_integer_parameters_stay_integers():
    plan = make_plan(_spec(Parameter("run.steps_per_period", values=(100, 200))))
    case = plan.case_dict(0)
    assert case["run"]["steps_per_period"] == 100 and isinstance(case["run"]["steps_per_period"], int)
    with pytest.raises(InputError, match="whole numbers") as exc:
        make_plan(_spec(Parameter("run.steps_per_period", values=(100, 150.5))))
    assert exc.value.field == "[[parameter]] 1: values"


# ---------------------------------------------------------------- hashes


def test_case_hashes_identify_the_resolved_case():
    p = Parameter("damper.centrifugal_force_N", values=(100.0, 200.0))
    a = make_plan(_spec(p, run={"method": "quasi-static"}))
    b = make_plan(_spec(p, run={"method": "quasi-static"}, name="renamed"))
    c = make_plan(_spec(p, run={"method": "quasi-static", "steps_per_period": 200}))
    assert a.hashes == b.hashes and len(set(a.hashes)) == 2  # the sweep's name is not an input of a case
    assert not set(a.hashes) & set(c.hashes)  # a run option is
    # the same case reached by another key path has the same hash
    d = make_plan(_spec(Parameter("damper.centrifugal_force_N", values=(200.0, 100.0)), run={"method": "quasi-static"}))
    assert d.hashes == a.hashes[::-1]


# ---------------------------------------------------------------- the TOML file and its errors


def test_the_example_spec_reads(tmp_path):
    spec = load_spec(CASES_DIR.parents[3] / "examples" / "amplitude_sweep.toml")
    plan = make_plan(spec)
    assert plan.grid_shape == (8, 12) and spec.run["method"] == "quasi-static"
    # a relative base path is relative to the spec file
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "mine.toml").write_text((CASES_DIR / "paper.toml").read_text())
    (tmp_path / "s.toml").write_text(
        '[sweep]\nbase = "cases/mine.toml"\n[[parameter]]\nkey = "damper.mass_kg"\nvalues = [0.01, 0.02]\n'
    )
    assert make_plan(load_spec(tmp_path / "s.toml")).base["damper"]["mass_kg"] == 0.012


BAD_SPECS = [
    ({"sweep": {"base": "paper", "samplng": "grid"}}, "[sweep] samplng", "not a known key"),
    ({"sweep": {}}, "[sweep] base", "required"),
    ({"parameter": []}, "[[parameter]]", "no [[parameter]]"),
    ({"sweep": {"base": "paper", "sampling": "random"}}, "[sweep] sampling", "'random'"),
    ({"sweep": {"base": "nope"}}, "[sweep] base", "not a built-in case"),
    ({"sweep": {"base": "paper", "sampling": "sobol", "samples": 100}}, "[sweep] samples", "powers of 2"),
    ({"sweep": {"base": "paper", "sampling": "latin-hypercube"}}, "[sweep] samples", "is None"),
    ({"sweep": {"base": "paper", "samples": 8}}, "[sweep] samples", "is set but sampling is 'grid'"),
    ({"parameter": [{"values": [1.0]}]}, "[[parameter]] 1: key", "required"),
    ({"parameter": [{"key": "damper.mass_kg", "value": [1.0]}]}, "[[parameter]] 1: value", "not a known key"),
    ({"parameter": [{"key": "damper.mass_kg", "values": [1.0, True]}]}, "[[parameter]] 1: values[1]", "True"),
    ({"parameter": [{"key": "damper.mass_kg", "values": [1.0, 1.0]}]}, "[[parameter]] 1: values", "repeats"),
    ({"parameter": [{"key": "damper.mass_kg", "values": []}]}, "[[parameter]] 1: values", "empty"),
    ({"parameter": [{"key": "damper.mass_kg", "start": 1.0, "stop": 2.0}]}, "[[parameter]] 1", "['start', 'stop']"),
    (
        {"parameter": [{"key": "damper.mass_kg", "start": 0.0, "stop": 2.0, "num": 3, "scale": "log"}]},
        "[[parameter]] 1: start",
        "log range",
    ),
    (
        {"parameter": [{"key": "damper.mass_kg", "start": 1.0, "stop": 2.0, "num": 3, "scale": "exp"}]},
        "[[parameter]] 1: scale",
        "'exp'",
    ),
    ({"parameter": [{"key": "damper.mass_kg", "low": 1.0, "high": 2.0}]}, "[[parameter]] 1: low", "latin-hypercube"),
    (
        {
            "sweep": {"base": "paper", "sampling": "latin-hypercube", "samples": 8},
            "parameter": [{"key": "damper.mass_kg", "low": 2.0, "high": 1.0}],
        },
        "[[parameter]] 1: high",
        "not above low",
    ),
    (
        {
            "sweep": {"base": "paper", "sampling": "zip"},
            "parameter": [
                {"key": "damper.mass_kg", "values": [1.0, 2.0]},
                {"key": "damper.inertia_kg_m2", "values": [1.0]},
            ],
        },
        "[[parameter]]",
        "lengths [1, 2]",
    ),
    (
        {"parameter": [{"key": "damper.mass_kg", "values": [1.0]}, {"key": "damper.mass_kg", "values": [2.0]}]},
        "[[parameter]] name",
        "both named 'mass_kg'",
    ),
    (
        {
            "parameter": [
                {"key": "damper.mass_kg", "values": [1.0], "name": "m"},
                {"key": "damper.mass_kg", "values": [2.0], "name": "n"},
            ]
        },
        "[[parameter]] 2: key",
        "parameter 1",
    ),
    (
        {"parameter": [{"key": "damper.mass_kg", "values": [1.0], "name": "status"}]},
        "[[parameter]] 1: name",
        "a variable of the sweep store",
    ),
    (
        {"parameter": [{"key": "damper.mass_kg", "values": [1.0], "name": "energy_per_cycle_J"}]},
        "[[parameter]] 1: name",
        "a variable of the sweep store",
    ),
    ({"parameter": [{"key": "damper.mass_kg", "values": [1.0], "name": "m/s"}]}, "[[parameter]] 1: name", "'m/s'"),
    ({"run": {"tolerence": 1e-6}}, "[run] tolerence", "not a known run option"),
    ({"outputs": {"histories": ["tangential_forces"]}}, "[outputs] histories[0]", "not a time history"),
    ({"outputs": {"frf": True}}, "[outputs.frf]", "is True"),
    ({"outputs": {"frf": {"solver": "march"}}}, "[outputs.frf]", "no frequencies"),
    ({"outputs": {"frf": {"frequencies_Hz": [10.0, -1.0]}}}, "[outputs.frf] frequencies_Hz", "distinct and positive"),
    ({"outputs": {"frf": {"frequencies_Hz": [10.0], "solver": "auto"}}}, "[outputs.frf] solver", "'auto'"),
    ({"outputs": {"frf": {"frequencies_Hz": [10.0], "check": "none"}}}, "[outputs.frf] check", "solver hbm"),
    (
        {"outputs": {"frf": {"frequencies_Hz": [10.0], "solver": "hbm", "harmonics": [1, 1]}}},
        "[outputs.frf] harmonics",
        "repeats",
    ),
    ({"outputs": {"frf": {"frequencies_Hz": [10.0], "direction": "both"}}}, "[outputs.frf] direction", "'both'"),
    ({"outputs": {"frf": {"frequencies_Hz": [10.0], "harmonic": 3}}}, "[outputs.frf] harmonic", "not a known key"),
    ({"outputs": {"summary": False}}, "[outputs] summary", "cannot be switched off"),
]


@pytest.mark.parametrize("patch, field, problem", BAD_SPECS)
def test_bad_specs_name_the_key(patch, field, problem):
    data = {"sweep": {"base": "paper"}, "parameter": [{"key": "damper.mass_kg", "values": [0.012]}]}
    data.update(patch)
    with pytest.raises(InputError) as exc:
        make_plan(spec_from_dict(data))
    assert exc.value.field == field, exc.value
    assert problem in exc.value.problem, exc.value
    assert exc.value.fix


def test_bad_spec_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_spec(tmp_path / "missing.toml")
    (tmp_path / "bad.toml").write_text("[sweep\n")
    with pytest.raises(InputError, match="not valid TOML"):
        load_spec(tmp_path / "bad.toml")


def test_one_parameter_sets_several_keys():
    keys = ["damper.contacts.P1.normal_stiffness_N_per_um", "damper.contacts.P1.tangential_stiffness_N_per_um"]
    spec = spec_from_dict(
        {
            "sweep": {"base": "paper"},
            "parameter": [{"key": keys, "values": [10.0, 20.0], "name": "k_P1", "unit": "N/um"}],
        }
    )
    plan = make_plan(spec)
    contact = plan.case_dict(1)["damper"]["contacts"][0]
    assert contact["normal_stiffness_N_per_um"] == contact["tangential_stiffness_N_per_um"] == 20.0
    assert plan.parameters[0].name == "k_P1" and plan.parameters[0].keys == tuple(keys)


def test_the_guide_sweep_example_is_a_valid_spec():
    import tomllib

    guide = (CASES_DIR.parents[3] / "docs" / "guide" / "forced_response.md").read_text()
    block = guide.split("### Every key of a sweep file")[1].split("```toml\n")[1].split("```")[0]
    plan = make_plan(spec_from_dict(tomllib.loads(block)))
    assert plan.grid_shape == (3, 12, 3) and plan.outputs["frf"]["frequencies_Hz"] == [180.0, 200.0, 220.0]
    assert [p.name for p in plan.parameters] == ["centrifugal_force_N", "amplitude", "friction_coefficient"]
