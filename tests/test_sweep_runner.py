"""The sweep's per-worker runner (slipstep.sweep.runner): a compiled system patched per case
gives the numbers of the case-format path (every case built from its TOML dictionary,
execute.run_case) to 1e-12, for loads, friction coefficients, contact stiffnesses and normal
preloads, on a damper and on a general structure, quasi-static and dynamic; a parameter it
cannot patch, a value the case format refuses and a wrong patch all take the case-format path."""

from __future__ import annotations

import math

import pytest

from slipstep.sweep import Parameter, SweepSpec
from slipstep.sweep.cases import make_plan
from slipstep.sweep.execute import payload_of, run_case
from slipstep.sweep.runner import CaseRunner

QUASI = {"method": "quasi-static", "periods": 2, "steps_per_period": 60}

# two DOFs, a contact driven by a motion and a Jenkins contact preloaded by its normal offset
STRUCTURE = {
    "name": "two",
    "motion_names": ["slide"],
    "structure": {
        "dof_names": ["x", "y"],
        "mass_kg": [[1e-3, 0.0], [0.0, 1e-3]],
        "stiffness_N_per_m": [[2e5, -1e5], [-1e5, 2e5]],
        "constant_force_N": [0.0, 4.0],
    },
    "contacts": [
        {
            "name": "A",
            "dof_gather": [[1.0, 0.0], [0.0, 1.0]],
            "motion_gather": [[-1.0], [0.0]],
            "normal_stiffness_N_per_m": 1e8,
            "tangential_stiffness_N_per_m": 1e6,
            "friction_coefficient": 0.5,
        },
        {
            "name": "B",
            "dof_gather": [[1.0, 0.0], [0.0, 0.0]],
            "normal_stiffness_N_per_m": 1e7,
            "tangential_stiffness_N_per_m": 5e5,
            "friction_coefficient": 0.3,
            "normal_offset_m": 1e-7,
        },
    ],
    "motion": [{"component": "slide", "amplitude": 10e-6, "frequency_Hz": 100.0}],
    "force": [{"component": "x", "amplitude": 0.5, "frequency_Hz": 100.0, "phase_deg": 30.0}],
    "run": {"method": "quasi-static", "periods": 2, "steps_per_period": 100},
}


def _same(runner_result: dict, plain: dict) -> None:
    assert runner_result["status"] == plain["status"]
    assert runner_result["message"] == plain["message"]
    assert runner_result["warning"] == plain["warning"]
    assert runner_result["summary"].keys() == plain["summary"].keys()
    for key, value in plain["summary"].items():
        got = runner_result["summary"][key]
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(got), key
        else:
            assert got == pytest.approx(value, rel=1e-12, abs=1e-300), key


def _compare(spec: SweepSpec) -> CaseRunner:
    """Every case through one runner and through run_case; returns the runner."""
    plan = make_plan(spec)
    payload = payload_of(plan)
    runner = CaseRunner(payload)
    for i in range(plan.n_cases):
        _same(runner.run(plan.values[i]), run_case(payload, plan.values[i]))
    return runner


@pytest.mark.parametrize(
    "parameters",
    [
        (  # a normal preload, a load amplitude, every friction coefficient
            Parameter("damper.centrifugal_force_N", values=(80.0, 350.0)),
            Parameter("motion.1.amplitude", values=(3.0, 45.0)),
            Parameter("damper.contacts.*.friction_coefficient", values=(0.15, 0.55)),
        ),
        (  # contact stiffnesses (planned again: T_min), one contact's friction
            Parameter("damper.contacts.P3.normal_stiffness_N_per_um", values=(5.0, 40.0)),
            Parameter("damper.contacts.*.tangential_stiffness_N_per_um", values=(8.0, 30.0)),
            Parameter("damper.contacts.P1.friction_coefficient", values=(0.2, 0.5)),
        ),
    ],
)
def test_patched_damper_cases_equal_the_case_format(parameters):
    runner = _compare(SweepSpec(base="paper", run=QUASI, parameters=parameters))
    assert runner.patching is True, runner.reason
    assert runner.checked == set(range(len(parameters)))  # each patch confirmed once by the case format
    assert runner.replans == any("stiffness" in p.keys[0] for p in parameters)  # T_min planned again


def test_a_dynamic_run_with_the_step_pilot_takes_the_case_format_path():
    """The default step rule of a dynamic method refines the step by twin marches of the case's
    own System (accuracy.pilot_plan): not patched."""
    runner = _compare(
        SweepSpec(
            base="paper",
            run={"method": "newmark", "periods": 1.0},
            parameters=(Parameter("damper.contacts.*.friction_coefficient", values=(0.2, 0.45)),),
        )
    )
    assert runner.patching is False
    assert "pilot" in runner.reason


def test_patched_structure_cases_equal_the_case_format():
    """A general structure: a constant force, a harmonic force and motion amplitude, a Jenkins
    contact's normal offset (its preload), stiffnesses and friction."""
    runner = _compare(
        SweepSpec(
            base=STRUCTURE,
            parameters=(
                Parameter("structure.constant_force_N.2", values=(2.0, 6.0)),
                Parameter("contacts.B.normal_offset_m", values=(5e-8, 3e-7)),
                Parameter("force.1.amplitude", values=(0.2, 0.9)),
                Parameter("motion.1.amplitude", values=(4e-6, 12e-6)),
                Parameter("contacts.A.tangential_stiffness_N_per_m", values=(5e5, 2e6)),
                Parameter("contacts.*.friction_coefficient", values=(0.2, 0.6)),
            ),
        )
    )
    assert runner.patching is True, runner.reason


def test_a_parameter_it_cannot_patch_takes_the_case_format_path():
    runner = _compare(
        SweepSpec(
            base="paper",
            run=QUASI,
            parameters=(
                Parameter("damper.mass_kg", values=(0.01, 0.02)),
                Parameter("damper.contacts.*.friction_coefficient", values=(0.2, 0.5)),
            ),
        )
    )
    assert runner.patching is False
    assert "damper.mass_kg" in runner.reason


def test_a_refused_value_is_the_case_formats_input_error():
    plan = make_plan(
        SweepSpec(
            base="paper",
            run=QUASI,
            parameters=(Parameter("damper.contacts.P2.friction_coefficient", values=(0.3, -0.1, 0.5)),),
        )
    )
    payload = payload_of(plan)
    runner = CaseRunner(payload)
    results = [runner.run(v) for v in plan.values]
    for result, values in zip(results, plan.values):
        _same(result, run_case(payload, values))
    assert results[1]["status"] == "INPUT_ERROR" and "friction_coefficient" in results[1]["message"]
    assert runner.patching is True  # the other cases are still patched


def test_a_wrong_patch_is_caught_by_the_self_check(monkeypatch):
    """A patch that writes a wrong number: the first case that moves its parameter differs from
    the case format's, the runner stops patching, and every result is still the case format's."""
    import slipstep.sweep.runner as R

    right = R.Patch.write
    monkeypatch.setattr(R.Patch, "write", lambda self, v, array, amplitude: right(self, v * 1.001, array, amplitude))
    runner = _compare(
        SweepSpec(base="paper", run=QUASI, parameters=(Parameter("motion.1.amplitude", values=(5.0, 20.0, 40.0)),))
    )
    assert runner.patching is False
    assert "differs from the case format" in runner.reason


def test_one_runner_per_thread_and_payload_content():
    """A worker receives the same payload as separate objects (the warm-up, each task): one
    runner for them; another payload or another thread gets its own (a marcher is not shared)."""
    import pickle
    import threading

    from slipstep.sweep.execute import run_batch
    from slipstep.sweep.runner import case_runner

    spec = SweepSpec(base="paper", run=QUASI, parameters=(Parameter("motion.1.amplitude", values=(5.0, 20.0)),))
    plan = make_plan(spec)
    payload = payload_of(plan)
    run_batch(payload, [(i, plan.hashes[i], plan.values[i].tolist()) for i in range(plan.n_cases)])
    runner = case_runner(payload)
    assert runner.patching is True
    assert case_runner(pickle.loads(pickle.dumps(payload))) is runner
    again = payload_of(
        make_plan(SweepSpec(base="paper", run=QUASI, parameters=(Parameter("motion.1.amplitude", values=(7.0,)),)))
    )
    assert case_runner(again) is runner  # the values are not in the payload: the same runner serves
    other = payload_of(
        make_plan(SweepSpec(base="paper", run=QUASI, parameters=(Parameter("damper.mass_kg", values=(0.02,)),)))
    )
    assert case_runner(other) is not runner
    seen = []
    thread = threading.Thread(target=lambda: seen.append(case_runner(payload)))
    thread.start()
    thread.join()
    assert seen[0] is not runner


def test_the_patched_system_is_the_compiled_case_array_for_array():
    """CaseRunner.compiled_for against System.compile of the case built from its dictionary:
    every array and scalar of the CompiledSystem equal to the last bit."""
    import numpy as np

    from slipstep.methods.plan import compile_backend
    from slipstep.sweep.cases import build_case

    spec = SweepSpec(
        base=STRUCTURE,
        parameters=(
            Parameter("structure.constant_force_N.2", values=(2.0, 6.0)),
            Parameter("contacts.B.normal_offset_m", values=(5e-8, 3e-7)),
            Parameter("force.1.amplitude", values=(0.2, 0.9)),
            Parameter("contacts.A.normal_stiffness_N_per_m", values=(3e7, 2e8)),
            Parameter("contacts.*.friction_coefficient", values=(0.2, 0.6)),
        ),
    )
    plan = make_plan(spec)
    runner = CaseRunner(payload_of(plan))
    runner.run(plan.values[0])
    for i in range(plan.n_cases):
        patched = runner.compiled_for([float(v) for v in plan.values[i]])
        system, _ = build_case(plan.case_dict(i), plan.base_dir)
        built = system.compile(compile_backend(runner.base.options.linear_solver))
        for name, value in built._asdict().items():
            got = getattr(patched, name)
            if isinstance(value, np.ndarray):
                assert got.dtype == value.dtype and np.array_equal(got, value), name
            else:
                assert got == value, name


def test_an_assembly_case_is_left_to_the_case_format_at_once():
    plan = make_plan(
        SweepSpec(
            base="blades",
            run={"method": "piecewise-linear", "periods": 2},
            parameters=(Parameter("dampers.damper.centrifugal_force_N", values=(100.0, 300.0)),),
        )
    )
    runner = CaseRunner(payload_of(plan))
    runner._build([float(v) for v in plan.values[0]])
    assert runner.patching is False and "assembly" in runner.reason
