"""Shooting FRF points started from harmonic balance when stepping in frequency fails (issue 24).

The gap oscillator of tests/hbm_cases.py folds over between 19 and 20 Hz: stepping up from the
upper branch, shooting at 20 Hz does not converge (Newton from the previous orbit fails, the
marching fallback does not settle in 200 periods); the harmonic balance continued from 19 Hz
lands on the lower branch, from which shooting converges to the stable orbit that marching from
the preload also reaches.
"""

import dataclasses

import numpy as np
import pytest
from hbm_cases import gap_oscillator

import slipstep as ss

from slipstep.frequency.hbm_seed import HbmSeeder
from slipstep.frequency.response import _WithHbmStart, frf, sweep
from slipstep.model.retune import retune
from slipstep.steady import march_to_steady, shoot

FREQUENCIES = np.linspace(14.0, 24.0, 11)
FOLD_POINT = 6  # 20 Hz, the first point past the upper branch's turning point


@pytest.fixture(scope="module")
def sweeps():
    system = gap_oscillator()
    return (
        frf(system, FREQUENCIES, solver="shoot", linear=False, rtol=None),
        frf(system, FREQUENCIES, solver="shoot", linear=False, rtol=None, hbm_start=False),
    )


def test_every_point_converges_with_the_harmonic_balance_start(sweeps):
    seeded, plain = sweeps
    assert list(seeded["status"].values.ravel()) == ["OK"] * len(FREQUENCIES)
    assert plain["status"].values.ravel()[FOLD_POINT] != "OK"  # the failure the start is for
    starts = list(seeded["solve_start"].values.ravel())
    assert starts[FOLD_POINT] == "harmonic balance"
    assert starts[:FOLD_POINT] + starts[FOLD_POINT + 1 :] == ["previous orbit"] * (len(FREQUENCIES) - 1)
    assert set(plain["solve_start"].values.ravel()) == {"previous orbit"}
    a, b = seeded["amplitude"].values.ravel(), plain["amplitude"].values.ravel()
    np.testing.assert_array_equal(a[:FOLD_POINT], b[:FOLD_POINT])  # untouched before the fold
    # after it, stepping starts from the seeded orbit or from the marched state: the same orbits
    np.testing.assert_allclose(a[FOLD_POINT + 1 :], b[FOLD_POINT + 1 :], rtol=1e-8)


def test_the_started_orbit_is_the_one_marching_reaches(sweeps):
    seeded, _ = sweeps
    system_f = retune(gap_oscillator(), float(FREQUENCIES[FOLD_POINT]))
    marched = march_to_steady(system_f, tolerance=1e-9, max_periods=2000)
    assert marched.status == "OK"
    x = marched.period.displacement.values[:, 0]
    amplitude = 0.5 * (x.max() - x.min())
    got = float(seeded["amplitude"].values.ravel()[FOLD_POINT])
    assert got == pytest.approx(amplitude, rel=1e-3)  # the lower branch, not the upper (12x larger)
    assert float(seeded["floquet_multiplier_max"].values.ravel()[FOLD_POINT]) < 1.0  # a stable orbit


def test_the_start_is_within_newtons_reach():
    """Started from harmonic balance, shooting at the fold point needs a few Newton periods."""
    system = gap_oscillator()
    start, text = HbmSeeder(system).start(float(FREQUENCIES[FOLD_POINT - 1]), float(FREQUENCIES[FOLD_POINT]))
    assert start is not None and "harmonic balance" in text
    steady = shoot(retune(system, float(FREQUENCIES[FOLD_POINT])), initial=start)
    assert steady.status == "OK" and steady.periods <= 30


def test_a_law_without_harmonic_balance_gives_the_reason():
    system = gap_oscillator()
    A = np.array([[1.0], [0.0], [0.0]])  # u1 = x, u2 = 0, v = 0: a friction circle with a constant preload
    contact = ss.ContactElement("c", A, 1e4, 2e4, 0.3, normal_offset=1e-3, law="3d-circle")
    circle = dataclasses.replace(system, contacts=(contact,))
    start, text = HbmSeeder(circle).start(19.0, 20.0)
    assert start is None and "piecewise-linear" in text


@pytest.fixture(scope="module")
def upper_branch_orbit():
    """The orbit at 19 Hz (the point before the fold) of a sweep stepping up the upper branch."""
    _, last = sweep(gap_oscillator(), FREQUENCIES[:FOLD_POINT], solver="shoot", rtol=None)
    assert last.status == "OK"
    return last


FEW_ITERATIONS = dict(max_iterations=16, max_periods=200, march_fallback=True)


def test_a_resolve_with_a_balance_start_to_come_is_not_marched(upper_branch_orbit):
    """The error estimate's re-solves go through _WithHbmStart: when the balance can start the
    point, the failed Newton is not marched up to max_periods first (which cost the blade pair's
    FRF 11 s at one point)."""
    system, f = gap_oscillator(), float(FREQUENCIES[FOLD_POINT])
    failed = shoot(retune(system, f), initial=upper_branch_orbit, **FEW_ITERATIONS)
    assert failed.status != "OK" and failed.periods >= 200  # the march this saves
    solve = _WithHbmStart(shoot, HbmSeeder(system), float(FREQUENCIES[FOLD_POINT - 1]), f)
    steady = solve(retune(system, f), initial=upper_branch_orbit, **FEW_ITERATIONS)
    assert steady.status == "OK" and solve.used
    assert steady.periods < 60  # Newton's periods from both starts, no marching fallback


def test_without_a_balance_start_the_resolve_keeps_its_marching_fallback(upper_branch_orbit):
    system, f = gap_oscillator(), float(FREQUENCIES[FOLD_POINT])
    seeder = HbmSeeder(system)
    seeder.unavailable = "no balance for this test"
    solve = _WithHbmStart(shoot, seeder, float(FREQUENCIES[FOLD_POINT - 1]), f)
    steady = solve(retune(system, f), initial=upper_branch_orbit, **FEW_ITERATIONS)
    alone = shoot(retune(system, f), initial=upper_branch_orbit, **FEW_ITERATIONS)
    assert not solve.used
    assert (steady.status, steady.periods) == (alone.status, alone.periods)  # the same solve, marched
    assert "no balance for this test" in steady.message
