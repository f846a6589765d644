"""Harmonic balance and the linear limits on a sparse structure (issue 24, item 7): the
structure's matrices stay sparse (one sparse LU per harmonic, System.compile('contacts')) and
the answer equals the dense path's to round-off."""

import numpy as np
import pytest
import scipy.sparse as sp

import slipstep as ss
import slipstep.hbm as hbm
from slipstep.steady.linear import linear_limits


def _chain(n: int, n_contacts: int, dense: bool) -> ss.System:
    """A fixed-free spring chain with Jenkins-like contacts on interior DOFs, forced at the tip."""
    k, m = 4e5, 0.02
    main = 2.0 * np.ones(n)
    main[-1] = 1.0
    K = sp.diags([-np.ones(n - 1), main, -np.ones(n - 1)], [-1, 0, 1], format="csr") * k
    M = sp.identity(n, format="csr") * m
    C = 2e-5 * K + 2.0 * M
    contacts = []
    for i, dof in enumerate(np.linspace(2, n - 3, n_contacts).round().astype(int)):
        A = sp.csr_matrix(([1.0, 0.5], ([0, 1], [dof, dof + 1])), shape=(2, n))
        A = A.toarray() if dense else A
        contacts.append(ss.ContactElement(f"J{i}", A, 5e5, 5e5, 0.3, normal_offset=2e-5 * (1 + i % 3)))
    amplitude = np.zeros(n)
    amplitude[-1] = 2.0
    force = ss.Signal(tuple(f"x{i}" for i in range(n)), (ss.Harmonic(40.0, amplitude),))
    if dense:
        M, C, K = M.toarray(), C.toarray(), K.toarray()
    return ss.System(ss.Structure(M, C, K), tuple(contacts), ss.Excitation(force=force), name="chain")


@pytest.mark.parametrize("condense", ["dofs", "contacts"])
def test_sparse_harmonic_balance_equals_dense(condense):
    sparse_sys, dense_sys = _chain(40, 4, dense=False), _chain(40, 4, dense=True)
    hb_s = hbm.HarmonicBalance(sparse_sys, harmonics=5, condense=condense)
    hb_d = hbm.HarmonicBalance(dense_sys, harmonics=5, condense=condense)
    assert hb_s.linear.sparse and not hb_d.linear.sparse
    omega = 2 * np.pi * 40.0
    p_s, p_d = hb_s.solve(omega), hb_d.solve(omega)
    assert p_s.converged and p_d.converged
    scale = np.abs(p_d.X).max()
    assert np.abs(p_s.X - p_d.X).max() <= 1e-9 * scale
    # the Jacobian's frequency and level columns too (continuation uses them)
    R_s, J_s, dw_s, dl_s = hb_s.evaluate(p_d.Y, omega)
    R_d, J_d, dw_d, dl_d = hb_d.evaluate(p_d.Y, omega)
    for a, b in ((J_s, J_d), (dw_s, dw_d), (dl_s, dl_d)):
        assert np.abs(a - b).max() <= 1e-9 * max(np.abs(b).max(), 1e-300)


def test_sparse_linear_limits_equal_dense():
    freqs = [20.0, 40.0, 65.0]
    a = linear_limits(_chain(30, 3, dense=False), freqs)
    b = linear_limits(_chain(30, 3, dense=True), freqs)
    for v in ("linear_free_amplitude", "linear_stuck_amplitude"):
        ref = b[v].values
        assert np.abs(a[v].values - ref).max() <= 1e-10 * np.abs(ref).max()
    # the stuck limit is stiffer than the free one at the tip below the first resonance
    assert float(b["linear_stuck_amplitude"].sel(frequency=20.0)[-1]) < float(
        b["linear_free_amplitude"].sel(frequency=20.0)[-1]
    )


def test_auto_chooses_harmonic_balance_above_the_dense_cap():
    from slipstep.frequency.choice import choose
    from slipstep.model.structure import DENSE_MAX_N

    big = choose(_chain(DENSE_MAX_N + 500, 5, dense=False))
    assert big.solver == "hbm" and "sparse" in big.reason
    assert choose(_chain(40, 4, dense=False)).solver == "shoot"


def test_frf_above_the_dense_cap_skips_the_march_and_keeps_the_truncation_estimate():
    """check='auto' (the default) marches no steady state on a sparse structure above the cap
    (minutes there) and says so; the point still carries its harmonic-truncation estimate."""
    from slipstep.frequency.response import frf
    from slipstep.hbm.frf import resolved_check
    from slipstep.model.structure import DENSE_MAX_N

    big = _chain(DENSE_MAX_N + 100, 3, dense=False)
    assert resolved_check(big, "auto")[0] == "none" and "sparse" in resolved_check(big, "auto")[1]
    assert resolved_check(big, "peak") == ("peak", "")
    assert resolved_check(_chain(40, 4, dense=False), "auto") == ("peak", "")
    ds = frf(big, [40.0], solver="auto", harmonics=3, rtol=0.5)
    assert ds.attrs["solver"] == "hbm" and "check_skipped" in ds.attrs
    assert "check_summary" not in ds.attrs  # no march was run
    assert str(ds["status"].values[0]) == "OK"
    est = float(ds["error_estimate"].values[0])
    assert np.isfinite(est) and est >= 0


def test_level_continuation_keeps_one_factorisation_per_frequency():
    """LinearPart.at refactorises only when omega changes (a level continuation at fixed omega
    reuses the factors), and the answer is the same as from a fresh factorisation."""
    hb = hbm.HarmonicBalance(_chain(40, 4, dense=False), harmonics=3)
    omega = 2 * np.pi * 40.0
    hb.linear.at(omega, 0.5)
    lu = hb.linear.lu
    hb.linear.at(omega, 1.0)
    assert hb.linear.lu is lu and hb.linear.level == 1.0
    hb.linear.at(omega * 1.01, 1.0)
    assert hb.linear.lu is not lu
    p = hb.solve(omega, 1.0)
    fresh = hbm.HarmonicBalance(_chain(40, 4, dense=False), harmonics=3).solve(omega, 1.0)
    assert p.converged and np.abs(p.X - fresh.X).max() <= 1e-12 * np.abs(fresh.X).max()


def test_auto_takes_harmonic_balance_where_shooting_costs_minutes():
    """A dense structure whose one-period Jacobian is above SHOOTING_MAX_FLOP gets harmonic
    balance (and no time-marching cross-check) from the auto rule; a small one keeps shooting."""
    from slipstep.frequency.choice import SHOOTING_MAX_FLOP, choose, time_domain_cost
    from slipstep.hbm.frf import resolved_check

    big = _chain(300, 100, dense=True)
    flop, why = time_domain_cost(big)
    # N n (3 n + r) (2 n + n_d): 256 steps, 300 DOFs, r = 200 contact DOFs (A couples dof, dof + 1)
    assert flop == 256 * 300 * (3 * 300 + 200) * (2 * 300 + 100) and flop > SHOOTING_MAX_FLOP
    assert "multiply-adds" in why and choose(big).solver == "hbm"
    assert resolved_check(big, "auto")[0] == "none"
    small = _chain(40, 4, dense=True)
    assert time_domain_cost(small)[1] == "" and choose(small).solver == "shoot"


def test_frf_passes_asked_only_to_harmonic_balance():
    """frf(..., solver='hbm', asked_only=True) returns the asked frequencies only."""
    from slipstep.frequency.response import frf

    system = _chain(30, 2, dense=False)
    ds = frf(system, [35.0, 40.0, 45.0], solver="hbm", harmonics=3, check="none", asked_only=True)
    assert list(ds["point_kind"].values) == ["asked"] * 3
    assert np.allclose(ds["frequency"].values, [35.0, 40.0, 45.0])
