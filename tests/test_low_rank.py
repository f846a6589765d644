"""The low-rank (Woodbury) state solve gives the direct solve's results, on every method, for
structures with many more DOFs than contact coordinates (kernels/state_solve.py)."""

from pathlib import Path

import numpy as np
import pytest

import slipstep

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def chain(n=40, n_contacts=5):
    """A fixed-free spring chain with Jenkins-type contacts (constant normal load by interference)
    on every 8th mass, a quasi-3D one between two masses, and a harmonic force."""
    K = 4e5 * (np.diag(np.full(n, 2.0)) - np.diag(np.ones(n - 1), 1) - np.diag(np.ones(n - 1), -1))
    M = np.diag(np.full(n, 0.02))
    contacts = []
    for i in range(n_contacts - 1):
        A = np.zeros((2, n))
        A[0, 4 + 8 * i] = 1.0
        contacts.append(slipstep.ContactElement(f"J{i}", A, 5e5, 5e5, 0.3, normal_offset=2e-5 * (1 + i)))
    A3 = np.zeros((3, n))
    A3[0, 10], A3[0, 11], A3[1, 20], A3[2, 30], A3[2, 31] = 1.0, -1.0, 1.0, 1.0, -1.0
    contacts.append(slipstep.ContactElement("Q", A3, (5e5, 3e5), 5e5, 0.25, normal_offset=1e-5))
    amplitude = np.zeros(n)
    amplitude[[5, 21, 37]] = 20.0, -10.0, 15.0
    force = slipstep.Signal(tuple(f"x{i}" for i in range(n)), (slipstep.Harmonic(40.0, amplitude),))
    exc = slipstep.Excitation(force=force)
    return slipstep.System(slipstep.Structure(M, 2e-5 * K + 2.0 * M, K), tuple(contacts), exc, name="chain")


CASES = {"chain": chain, "shroud": lambda: slipstep.load_system(EXAMPLES / "shroud_pair.toml")}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize(
    "method", ["newmark", "piecewise-linear", "piecewise-linear-adaptive", "full-newton", "quasi-static"]
)
def test_low_rank_equals_direct(case, method):
    system = CASES[case]()
    direct = slipstep.run(system, method, periods=3, linear_solver="direct")
    low = slipstep.run(system, method, periods=3, linear_solver="low-rank")
    assert direct.attrs["status"] == low.attrs["status"] == "OK"
    assert (direct.attrs["linear_solver"], low.attrs["linear_solver"]) == ("direct", "low-rank")
    scale = np.abs(direct.displacement.values).max()
    assert np.abs(direct.displacement.values - low.displacement.values).max() <= 1e-9 * scale
    assert np.array_equal(direct.contact_state.values, low.contact_state.values)
    assert direct.attrs["steps"] == low.attrs["steps"]
    assert direct.attrs["state_changes"] > 0  # the contacts do change state: C(S) != I is exercised


def test_auto_choice():
    assert slipstep.run(chain(), "piecewise-linear", periods=0.5).attrs["linear_solver"] == "low-rank"
    assert (
        slipstep.run(slipstep.load_system("paper"), "piecewise-linear", periods=0.5).attrs["linear_solver"] == "direct"
    )
