"""The event-driven quasi-static method (kernels/events.py): within a contact state the
quasi-static solution is linear in the harmonic loads and motions, so the transitions are
roots of known functions of time. Checked against Method 4 on fine grids (whose transitions
are late by at most one step) and by the convergence of the energies."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import slipstep as ss
from slipstep.errors import InputError
from slipstep.post.energy import friction_energy_per_period
from slipstep.post.timeline import change_times

ROOT = Path(__file__).resolve().parents[1]
PAPER_PHASES = [91.2, 134.4, 172.8, 271.2, 322.8, 352.8]


def last_period_phases(ds):
    T = ds.attrs["period_s"]
    t = change_times(ds)
    return (t[t > ds.attrs["t_end_s"] - T] - (ds.attrs["t_end_s"] - T)) / T * 360.0


@pytest.fixture(scope="module")
def paper():
    return ss.load_system("paper")


def test_paper_grid_reproduces_method4(paper):
    ev = ss.run(paper, "quasi-static-events", periods=3)
    m4 = ss.run(paper, "quasi-static", periods=3)
    assert ev.attrs["status"] == "OK" and ev.attrs["steps"] == m4.attrs["steps"] == 900
    assert np.allclose(last_period_phases(ev), PAPER_PHASES, atol=1e-6)
    # both are the exact quasi-static solution at the grid points between transitions
    assert np.array_equal(ev.contact_state.values, m4.contact_state.values)
    scale = np.abs(m4.displacement.values).max()
    assert np.abs(ev.displacement.values - m4.displacement.values).max() <= 1e-6 * scale
    # one factorisation per state visited, a solve per phase: far fewer than Method 4's
    assert ev.attrs["solves"] < 0.05 * m4.attrs["solves"]


def test_exact_transitions_against_a_fine_method4_grid(paper):
    """36000 steps per period (0.01 deg): Method 4 sees each transition within one step after
    it; the event method samples the exact solution, so the phases agree to 0.01 deg, and the
    slip -> stick transitions fall at the motion reversals (90 and 270 deg) exactly."""
    ev = ss.run(paper, "quasi-static-events", periods=3, steps_per_period=36000)
    m4 = ss.run(paper, "quasi-static", periods=3, steps_per_period=36000)
    p_ev, p_m4 = last_period_phases(ev), last_period_phases(m4)
    assert len(p_ev) == len(p_m4) == 6
    assert np.all(np.abs(p_ev - p_m4) <= 0.01 + 1e-9)
    assert np.allclose(p_ev[[0, 3]], [90.01, 270.01], atol=1e-6)  # first sample after 90 / 270 deg
    e_ev, e_m4 = friction_energy_per_period(ev).values, friction_energy_per_period(m4).values
    assert np.allclose(e_ev, e_m4, rtol=1e-6)


def test_energies_converge_with_the_output_grid(paper):
    """The outputs are exact samples: the energy per period (trapezoid on the samples)
    converges at second order, to 1e-6 between 3600 and 36000 samples per period."""
    e = [
        friction_energy_per_period(ss.run(paper, "quasi-static-events", periods=3, steps_per_period=spp)).values
        for spp in (3600, 36000)
    ]
    assert np.allclose(e[0], e[1], rtol=1e-6)


def test_two_harmonics_general_root_finding(tmp_path):
    """Two frequencies (scan + Illinois): the event method against Method 4 on a fine grid."""
    text = (
        (ROOT / "docs" / "guide" / "case_files.md")
        .read_text()
        .split("## Kind 2")[1]
        .split("```toml\n")[1]
        .split("```")[0]
    )
    path = tmp_path / "two_dof.toml"
    path.write_text(text)
    system, _ = ss.load_case(path)
    force = ss.Signal(("x", "y"), (ss.Harmonic(50.0, [6.0, 0.0]), ss.Harmonic(150.0, [2.0, 3.0], [0.5, 0.5])))
    system = dataclasses.replace(system, excitation=dataclasses.replace(system.excitation, force=force))
    ev = ss.run(system, "quasi-static-events", periods=2, steps_per_period=20000)
    m4 = ss.run(system, "quasi-static", periods=2, steps_per_period=20000)
    assert ev.attrs["status"] == m4.attrs["status"] == "OK"
    assert ev.attrs["state_changes"] >= 4
    differ = np.any(ev.contact_state.values != m4.contact_state.values, axis=1)
    assert differ.sum() <= ev.attrs["state_changes"]  # at most the one sample after each transition
    scale = np.abs(m4.displacement.values).max()
    assert np.abs(ev.displacement.values - m4.displacement.values).max() <= 2e-3 * scale


def test_unsupported_cases_are_input_errors(paper):
    system, _ = ss.load_case(ROOT / "examples" / "shroud_pair.toml")
    contact = dataclasses.replace(system.contacts[0], law="3d-circle", tangential_stiffness=1.5e7)
    with pytest.raises(InputError) as err:
        ss.Simulation(dataclasses.replace(system, contacts=(contact,)), "quasi-static-events")
    assert err.value.field == "method"
    ramped = dataclasses.replace(
        paper,
        excitation=dataclasses.replace(
            paper.excitation, motion=dataclasses.replace(paper.excitation.motion, ramp_time=1e-3)
        ),
    )
    with pytest.raises(InputError) as err:
        ss.Simulation(ramped, "quasi-static-events")
    assert err.value.field == "ramp_time"
