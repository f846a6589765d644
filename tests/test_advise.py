"""The method advisor: paper Eq. 9, T_min per state, flutter detection."""

import math

import numpy as np
import pytest

import slipstep
from slipstep.study.advise import advise, analyse_state, enumerate_states, inertia_limit_frequency, inertia_ratio
from slipstep.casefile.case import CASES_DIR, build_system, parse_case, read_toml
from slipstep.errors import InputError

SLIP_POS, SLIP_NEG = 2, 3


def test_eq9_inertia_limit_is_30_kHz():
    f = inertia_limit_frequency(1e-7, 3600.0, 0.5, rho_limit=0.05)
    assert f == pytest.approx(30e3, rel=1e-9)
    assert inertia_ratio(f, 1e-7, 3600.0, 0.5) == pytest.approx(0.05, rel=1e-12)
    # rho grows with omega^2: at 200 Hz it is (200/30000)^2 * 5 %
    assert inertia_ratio(200.0, 1e-7, 3600.0, 0.5) == pytest.approx(0.05 * (200 / 30e3) ** 2, rel=1e-12)


def test_eq9_bad_input():
    with pytest.raises(InputError, match="radius_m"):
        inertia_limit_frequency(1e-7, 3600.0, 0.0)


@pytest.fixture(scope="module")
def paper_advice():
    return advise(slipstep.load_system("paper"), rotor_speed_rpm=3600, radius_m=0.5, displacement_amplitude_m=1e-7)


@pytest.fixture(scope="module")
def mu05_advice():
    data = read_toml(CASES_DIR / "paper.toml")
    for c in data["damper"]["contacts"]:
        c["friction_coefficient"] = 0.5
    return advise(build_system(parse_case(data)))


def test_paper_case_steps_and_frequencies(paper_advice):
    a = paper_advice
    assert a.inertia_limit_Hz == pytest.approx(30e3, rel=1e-9)
    assert a.stick_t_min_s == pytest.approx(84.3e-6, rel=2e-3)
    assert a.fixed_dt_s == pytest.approx(26.84e-6, rel=2e-3)
    assert a.fixed_steps_per_period == 187
    stick = next(s for s in a.states if s.state == (1, 1, 1))
    assert np.allclose(stick.frequencies_Hz, [8.41e3, 10.48e3, 11.86e3], rtol=2e-3)
    # slip states have longer T_min: the adaptive step needs fewer steps per period
    assert 120 < a.adaptive_steps_per_period_estimate < 187
    assert a.states_enumerated and len(a.states) == 4**3


def test_paper_case_free_of_flutter_in_visited_states(paper_advice):
    a = paper_advice
    assert a.flutter_free and a.flutter_visited == []
    visited = {s.state for s in a.states if s.visited}
    assert {(1, 1, 1), (2, 2, 3), (3, 3, 2)} <= visited  # stick and the two gross-slip states
    assert not any(s.complex_eigenvalues for s in a.states if s.visited)
    # among ALL combinations, "all three slip+" has complex eigenvalues, but the wedge's
    # kinematics never reach it (the faces slip in opposite directions): listed, not visited
    assert (SLIP_POS,) * 3 in a.flutter_not_visited
    assert a.singular_visited == []
    assert "free of flutter" in a.text()
    assert a.recommendation.startswith("quasi-static")


def test_mu05_variant_reports_flutter(mu05_advice):
    a = mu05_advice
    assert not a.flutter_free
    for state in a.flutter_visited:
        info = next(s for s in a.states if s.state == state)
        assert info.visited and info.complex_eigenvalues and info.max_imag_ratio > 1e-3
    # the all-slip-same-direction states of physics.md 8
    assert (SLIP_POS,) * 3 in a.flutter_visited + a.flutter_not_visited
    assert (SLIP_NEG,) * 3 in a.flutter_visited + a.flutter_not_visited
    assert "FLUTTER" in a.text()


def test_flutter_flag_matches_an_independent_eigen_check():
    system = slipstep.load_system("paper")
    cs = system.compile()
    for state in [(1, 1, 1), (2, 2, 3), (2, 2, 2)]:
        info = analyse_state(cs, state)
        K = cs.K.copy()
        from slipstep.kernels.contact import add_contact_stiffness

        add_contact_stiffness(cs, np.array(state, np.int8), 1.0, K)
        ev = np.linalg.eigvals(np.linalg.solve(cs.M, K))
        assert info.complex_eigenvalues == bool(np.abs(ev.imag).max() > 1e-6 * np.abs(ev).max())
        assert info.t_min_s == pytest.approx(2 * math.pi / math.sqrt(np.abs(ev).max()), rel=1e-12)


def test_enumeration_counts_and_limit():
    cs = slipstep.load_system("paper").compile()
    states = enumerate_states(cs)
    assert len(states) == 64 and len(set(states)) == 64
    assert enumerate_states(cs, max_states=10) is None


def test_partial_eq9_arguments_are_an_input_error():
    with pytest.raises(InputError, match="rotor_speed_rpm"):
        advise(slipstep.load_system("paper"), rotor_speed_rpm=3600, run_cases=False)


def test_advice_to_dict_is_plain(paper_advice):
    d = paper_advice.to_dict()
    assert d["flutter_free"] is True and d["fixed_steps_per_period"] == 187
