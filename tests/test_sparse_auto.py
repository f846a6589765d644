"""linear_solver 'auto' by estimated cost per step (methods.sparse.step_costs, auto_choice,
issue 26): the sparse backend where its cost is the lowest, the dense backend for small models
and the paper case, the banded one for narrow bands; the result says which backend ran and why."""

import numpy as np
import pytest
import scipy.sparse as sp

import slipstep as ss
from slipstep.methods import sparse as SB
from slipstep.methods.plan import plan_run


def _grid(side: int, n_contacts: int, dense_input: bool = False) -> ss.System:
    """A square grid of springs (band about ``side`` after RCM), clamped on one edge, Jenkins
    contacts spread over the interior, a harmonic force on the free edge."""
    n = side * side
    idx = np.arange(n).reshape(side, side)
    pairs = [(idx[i, j], idx[i, j + 1]) for i in range(side) for j in range(side - 1)]
    pairs += [(idx[i, j], idx[i + 1, j]) for i in range(side - 1) for j in range(side)]
    return _springs(n, pairs, idx[:, 0], idx[:, 1:-1].ravel(), int(idx[0, -1]), n_contacts, dense_input)


def _hub_chain(n: int, n_contacts: int, dense_input: bool = False) -> ss.System:
    """A chain whose last DOF (a hub, as the damper between the two blades of the blade pair)
    is coupled to every 10th DOF: a wide RCM band (79 at n = 400), little minimum-degree fill."""
    pairs = [(i, i + 1) for i in range(n - 2)] + [(i, n - 1) for i in range(5, n - 1, 10)]
    return _springs(n, pairs, [0], np.arange(1, n - 2), n - 2, n_contacts, dense_input)


def _chain(n: int, n_contacts: int) -> ss.System:
    """A fixed-free chain (band 1)."""
    return _springs(n, [(i, i + 1) for i in range(n - 1)], [0], np.arange(1, n - 1), n - 1, n_contacts, False)


def _springs(n, pairs, grounded, candidates, tip, n_contacts, dense_input) -> ss.System:
    a, b = np.array(pairs).T
    grounded = np.asarray(grounded)
    rows = np.concatenate([a, b, a, b, grounded])
    cols = np.concatenate([a, b, b, a, grounded])
    vals = np.concatenate([np.ones(2 * a.size), -np.ones(2 * a.size), np.ones(grounded.size)])
    K = sp.csr_matrix((4e5 * vals, (rows, cols)), shape=(n, n))
    M = sp.identity(n, format="csr") * 0.02
    C = 2e-5 * K + 2.0 * M
    where = candidates[np.linspace(0, candidates.size - 1, n_contacts).round().astype(int)]
    contacts = []
    for i, dof in enumerate(where):
        A = sp.csr_matrix(([1.0], ([0], [int(dof)])), shape=(2, n))
        contacts.append(
            ss.ContactElement(
                f"J{i}", A.toarray() if dense_input else A, 5e5, 5e5, 0.3, normal_offset=1e-5 * (1 + i % 3)
            )
        )
    amplitude = np.zeros(n)
    amplitude[tip] = 20.0
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(40.0, amplitude),))
    if dense_input:
        M, C, K = M.toarray(), C.toarray(), K.toarray()
    return ss.System(ss.Structure(M, C, K), tuple(contacts), ss.Excitation(force=force))


def _backend(system, method="piecewise-linear", **options):
    plan = plan_run(system, method, error_estimate=False, **options)
    return plan.backend, plan.backend_reason


def test_rcm_profile_of_a_tridiagonal_pattern():
    """Band 1 and envelope 2n - 1 (the diagonal and one entry left of it per row but the first)."""
    n = 50
    P = sp.diags([np.ones(n - 1), np.ones(n), np.ones(n - 1)], [-1, 0, 1], format="csr")
    assert SB.rcm_profile(P) == (1, 2 * n - 1)


@pytest.mark.parametrize("build", [lambda: _grid(18, 30), lambda: _hub_chain(400, 20)], ids=["grid", "hub"])
def test_fill_estimate_of_the_sparse_factor(build):
    """The minimum-degree fill of the pattern (methods.sparse.minimum_degree_fill) is within a
    factor 2 of nnz(L + U) of the sparse backend's factor (its order puts the contact DOFs
    last), and the cost model's estimate (the envelope, or that fill) is not below it / 2."""
    system = build()
    plan = plan_run(system, "piecewise-linear", linear_solver="sparse", error_estimate=False)
    actual = SB.factor_nnz(SB.factor_of(plan.compiled, plan.settings, plan.dt, True))
    A = sp.vstack([sp.csr_matrix(c.dof_gather) for c in system.contacts])
    P = (SB._pattern(system.structure) + abs(A.T) @ abs(A)).tocsr()
    assert 0.5 <= actual / SB.minimum_degree_fill(P) <= 2.0
    assert actual <= 2.0 * SB.step_costs(system).lu_entries


def test_paper_case_and_small_models_keep_the_dense_backend():
    """The paper case (dense, a few DOFs) and a small sparse chain stay on the dense backend,
    below SPARSE_MIN_N, with the reason saying so."""
    paper = ss.load_system("paper")
    backend, reason = _backend(paper)
    assert backend in ("dense", "low-rank") and str(SB.SPARSE_MIN_N) in reason
    backend, reason = _backend(_chain(SB.SPARSE_MIN_N - 1, 20))
    assert backend in ("dense", "low-rank") and "small" in reason


def test_wide_band_takes_sparse_dense_input_too():
    """A 400-DOF chain with a hub (band 79, little fill) and a 2,500-DOF grid with 100
    contacts take the sparse backend (its estimate at least SPARSE_GAIN below the others'); the
    hub chain given as dense matrices too (the blade pair's assembly is dense input with a sparse
    pattern)."""
    for system in (_hub_chain(400, 20), _hub_chain(400, 20, dense_input=True), _grid(50, 100)):
        est = SB.step_costs(system)
        others = min(t for b, t in est.seconds.items() if b != "sparse")
        assert SB.SPARSE_GAIN * est.seconds["sparse"] <= others
        backend, reason = _backend(system)
        assert backend == "sparse" and reason.startswith("auto: estimated us per step sparse")


def test_close_call_keeps_the_banded_backend():
    """A 400-DOF grid with 40 contacts (band 20): the sparse and banded estimates are close (and
    so are the measured times, benchmarks/bench_backends.py): the banded backend stays."""
    system = _grid(20, 40)
    est = SB.step_costs(system)
    assert est.seconds["sparse"] * SB.SPARSE_GAIN > est.seconds["banded"]
    backend, reason = _backend(system)
    assert backend == "banded" and "banded (narrow band)" in reason


def test_narrow_band_with_many_contacts_stays_banded():
    """A 1,000-DOF chain with 100 contacts (nq = 200): the banded step (band 1) is cheaper than
    the sparse one's nq^2 contact-space work: banded."""
    system = _chain(1000, 100)
    est = SB.step_costs(system)
    assert est.band == 1 and est.seconds["banded"] < est.seconds["sparse"]
    assert _backend(system)[0] == "banded"


def test_methods_it_does_not_march_and_too_many_contacts(monkeypatch):
    """Newmark (Method 1) is not marched by the sparse backend; above SPARSE_MAX_NQ contact
    coordinates 'auto' does not take it either; the reason says which."""
    system = _hub_chain(400, 20)
    backend, reason = _backend(system, "newmark")
    assert backend != "sparse" and "newmark" in reason
    monkeypatch.setattr(SB, "SPARSE_MAX_NQ", 39)
    backend, reason = _backend(system)
    assert backend != "sparse" and "contact coordinates" in reason


def test_result_attribute_says_which_backend_and_why():
    """The dataset's linear_solver and linear_solver_reason: 'auto' with its estimate, or the
    option given; the schema documents the attribute."""
    from slipstep.output.results import ATTRS

    system = _hub_chain(400, 20)
    options = {"duration": 2.0 / 40.0 / 10, "dt": 1 / 40.0 / 100, "error_estimate": False}
    auto = ss.run(system, "piecewise-linear", raise_on_failure=True, **options)
    assert auto.attrs["linear_solver"] == "sparse"
    assert auto.attrs["linear_solver_reason"].startswith("auto: estimated us per step sparse")
    given = ss.run(system, "piecewise-linear", linear_solver="banded", raise_on_failure=True, **options)
    assert (
        given.attrs["linear_solver"] == "banded"
        and given.attrs["linear_solver_reason"] == "given: linear_solver 'banded'"
    )
    assert "linear_solver_reason" in ATTRS


def test_auto_equals_the_sparse_backend_given():
    """'auto' marching on the sparse backend gives the run of linear_solver='sparse' exactly."""
    system = _hub_chain(400, 20)
    options = {"duration": 2.0 / 40.0 / 10, "dt": 1 / 40.0 / 100, "error_estimate": False}
    a = ss.run(system, "piecewise-linear", raise_on_failure=True, **options)
    b = ss.run(system, "piecewise-linear", linear_solver="sparse", raise_on_failure=True, **options)
    assert np.array_equal(a["displacement"].values, b["displacement"].values)


def test_shooting_keeps_the_dense_backend():
    """Shooting's period Jacobian needs the dense matrices: dense input that 'auto' would march
    on the sparse backend is given linear_solver 'direct'; a small model keeps 'auto'."""
    from slipstep.steady.shooting import dense_backend_options

    wide = _hub_chain(400, 20, dense_input=True)
    assert _backend(wide)[0] == "sparse"
    assert dense_backend_options(wide, {}, "piecewise-linear") == {"linear_solver": "direct"}
    assert dense_backend_options(ss.load_system("paper"), {}, "piecewise-linear") == {}
