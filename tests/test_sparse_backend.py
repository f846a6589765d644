"""The condensed sparse backend (issue 26, kernels/sparse.py, methods/sparse.py): the same
march as the dense backend (an independent solve: n x n LU per contact state) to 1e-9 of the
range, on a sparse chain with variable normal loads and lift-off, and on the coarse FE mesh of
the bolted beam (scikit-fem; skipped without it)."""

import numpy as np
import pytest
import scipy.sparse as sp

import slipstep as ss
from slipstep.errors import InputError
from slipstep.methods.plan import plan_run
from slipstep.methods.schemes import hht

FIELDS = ("displacement", "velocity", "normal_force", "tangential_force", "slider")


def _chain(n: int = 60, n_contacts: int = 8, amplitude: float = 30.0) -> ss.System:
    """A fixed-free spring chain with 2D contacts (tangential on one DOF, the normal on its
    neighbour: variable normal load, lift-off possible) and a harmonic tip force."""
    k, m = 4e5, 0.02
    main = 2 * np.ones(n)
    main[-1] = 1
    K = sp.diags([-np.ones(n - 1), main, -np.ones(n - 1)], [-1, 0, 1], format="csr") * k
    M = sp.identity(n, format="csr") * m
    C = 2e-5 * K + 2.0 * M
    contacts = []
    for i, dof in enumerate(np.linspace(2, n - 3, n_contacts).round().astype(int)):
        A = sp.csr_matrix(([1.0, 0.5], ([0, 1], [dof, dof + 1])), shape=(2, n))
        contacts.append(ss.ContactElement(f"J{i}", A, 5e5, 5e5, 0.3, normal_offset=1e-5 * (1 + i % 3)))
    force_amplitude = np.zeros(n)
    force_amplitude[-1] = amplitude
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(40.0, force_amplitude),))
    return ss.System(ss.Structure(M, C, K), tuple(contacts), ss.Excitation(force=force))


def _agree(a, b, rtol=1e-9) -> None:
    for name in FIELDS:
        x, y = a[name].values, b[name].values
        assert x.shape == y.shape, name
        scale = max(np.ptp(x), 1e-300)
        assert np.abs(x - y).max() <= rtol * scale, (name, np.abs(x - y).max() / scale)


def _slipped(ds) -> bool:
    states = ds["contact_state"].values
    return bool(np.isin(states, (2, 3)).any())


@pytest.mark.parametrize("scheme", [None, hht(0.1)], ids=["newmark", "hht"])
def test_chain_equals_dense(scheme):
    """Method 3 on a sparse chain: sparse = direct to 1e-9 of the range, with slip and a last
    step shorter than the others (the second factorisation), Newmark and HHT (kfac != 1)."""
    system = _chain()
    options = {"duration": 2.013 / 40.0, "dt": 1 / 40.0 / 80, "error_estimate": False}
    if scheme is not None:
        options["scheme"] = scheme
    dense = ss.run(system, "piecewise-linear", linear_solver="direct", raise_on_failure=True, **options)
    sparse = ss.run(system, "piecewise-linear", linear_solver="sparse", raise_on_failure=True, **options)
    assert sparse.attrs["linear_solver"] == "sparse" and dense.attrs["linear_solver"] == "direct"
    assert _slipped(dense)
    assert not np.isclose(sparse["step_size"].values[-1], options["dt"])  # a shorter last step was marched
    _agree(dense, sparse)


def test_refusals():
    """Methods and options the sparse backend does not march are refused naming the key."""
    system = _chain(n=20, n_contacts=2)
    with pytest.raises(InputError) as err:
        plan_run(system, "newmark", linear_solver="sparse")
    assert err.value.field == "linear_solver"
    with pytest.raises(InputError) as err:
        plan_run(system, "piecewise-linear", linear_solver="sparse", rtol=1e-3)
    assert err.value.field == "rtol"


def test_auto_takes_sparse_for_a_wide_band():
    """'auto' takes the sparse backend for a large sparse structure with a wide band marched
    by Method 3, and keeps the banded one for a chain (bandwidth 1) with 100 contacts
    (methods.sparse.step_costs: the estimated costs per step decide)."""
    side = 50  # a square grid of springs: bandwidth about 50 after reverse Cuthill-McKee
    n = side * side
    idx = np.arange(n).reshape(side, side)
    pairs = [(idx[i, j], idx[i, j + 1]) for i in range(side) for j in range(side - 1)]
    pairs += [(idx[i, j], idx[i + 1, j]) for i in range(side - 1) for j in range(side)]
    a, b = np.array(pairs).T
    grounded = idx[:, 0]
    rows = np.concatenate([a, b, a, b, grounded])
    cols = np.concatenate([a, b, b, a, grounded])
    vals = np.concatenate([np.ones(2 * a.size), -np.ones(2 * a.size), np.ones(grounded.size)])
    K = sp.csr_matrix((4e5 * vals, (rows, cols)), shape=(n, n))
    A = sp.csr_matrix(([1.0], ([0], [int(idx[side // 2, -1])])), shape=(2, n))
    contact = ss.ContactElement("J", A, 5e5, 5e5, 0.3, normal_offset=1e-5)
    amplitude = np.zeros(n)
    amplitude[idx[0, -1]] = 10.0
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(40.0, amplitude),))
    grid = ss.System(ss.Structure(sp.identity(n, format="csr") * 0.02, None, K), (contact,), ss.Excitation(force=force))
    plan = plan_run(grid, "piecewise-linear", step_rule="accuracy", error_estimate=False)
    assert plan.backend == "sparse"
    # a chain with many contacts: the banded step (band 1) is cheaper than the nq^2 contact-space work
    assert plan_run(_chain(n=1000, n_contacts=100), "piecewise-linear", error_estimate=False).backend == "banded"


def test_fe_mesh_sparse_equals_dense():
    """The coarse bolted beam (scikit-fem hexahedra, contact points on the joint face's nodes):
    the sparse backend equals the dense one to 1e-9 of the range, with partial slip."""
    pytest.importorskip("skfem")
    from slipstep.model.fe_mesh import bolted_beam, coarse_spec

    model = bolted_beam(coarse_spec(force=800.0, pressure=1e6))
    system = model.system
    assert len(system.contacts) == 15 and np.isclose(model.contact_area.sum(), 0.024 * 0.5 * 4 / 12)
    assert np.allclose(model.contact_normal, [0.0, 0.0, -1.0])
    options = {"periods": 1, "dt": 1 / 300.0 / 200, "error_estimate": False}
    dense = ss.run(system, "piecewise-linear", linear_solver="direct", raise_on_failure=True, **options)
    sparse = ss.run(system, "piecewise-linear", linear_solver="sparse", raise_on_failure=True, **options)
    assert _slipped(dense) and sparse.attrs["linear_solver"] == "sparse"
    _agree(dense, sparse)


def test_pilot_adaptive_and_steady_marching_equal_dense():
    """The whole default pipeline (the step-doubling pilot twins pick the same step), Method
    2+3 under the 'accuracy' rule (its step the cap), and the steady-state search that reuses
    one marcher period after period: sparse = direct."""
    from slipstep.steady.marching import march_to_steady

    system = _chain()
    runs = {b: ss.run(system, "piecewise-linear", linear_solver=b, periods=1) for b in ("direct", "sparse")}
    assert runs["direct"].attrs["dt_s"] == runs["sparse"].attrs["dt_s"]
    _agree(runs["direct"], runs["sparse"])
    runs = {
        b: ss.run(system, "piecewise-linear-adaptive", linear_solver=b, periods=1, step_rule="accuracy")
        for b in ("direct", "sparse")
    }
    _agree(runs["direct"], runs["sparse"])
    options = {"dt": 1 / 40 / 100, "error_estimate": False, "max_periods": 4}
    steady = {b: march_to_steady(system, "piecewise-linear", linear_solver=b, **options) for b in ("direct", "sparse")}
    x, y = steady["direct"].final_state.x, steady["sparse"].final_state.x
    assert np.abs(x - y).max() <= 1e-9 * np.ptp(x)
