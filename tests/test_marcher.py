"""The march separated from the run (methods/plan.py, marcher.py, start.py, state.py): the
facade and the new path give the same numbers bit for bit, a march split into segments
continues the whole one, a plan runs no kernel, a marcher is reused without new buffers."""

import dataclasses

import numpy as np
import pytest

import slipstep as ss
from slipstep.errors import Status
from slipstep.kernels import march as K
from slipstep.methods import accuracy
from slipstep.methods.marcher import Marcher
from slipstep.methods.plan import plan_run
from slipstep.methods.start import consistent_start, static_equilibrium
from slipstep.methods.state import State
from slipstep.model.excitation import evaluate_compiled, motion_signal

FIELDS = ("t", "dt", "x", "v", "a", "q", "f", "w", "state", "solves", "step")


@pytest.fixture(scope="module")
def paper():
    return ss.load_system("paper")


@pytest.mark.parametrize("method", ["newmark", "piecewise-linear-adaptive", "quasi-static", "quasi-static-events"])
def test_facade_and_new_path_are_bit_for_bit_equal(paper, method):
    sim = ss.Simulation(paper, method, periods=1, error_estimate=False)
    assert sim.march() == Status.OK
    plan = plan_run(paper, method, periods=1, error_estimate=False)
    marcher = Marcher(plan)
    start = static_equilibrium(plan)  # its own workspace, not the marcher's
    segment = marcher.advance(start)
    assert segment.status == Status.OK
    n = segment.trace.n_steps
    assert n == int(sim.out.counters[0]) and n > 10
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(segment.trace, name), getattr(sim.out, name)[: n + 1], err_msg=name)
    np.testing.assert_array_equal(segment.counters, sim.out.counters)
    end = segment.end_state
    assert end.t == pytest.approx(plan.t_end, rel=1e-15)
    np.testing.assert_array_equal(end.x, sim.ws.x)
    np.testing.assert_array_equal(end.contact_state, sim.ws.state)
    with pytest.raises(ValueError):  # the trace is a read-only view
        segment.trace.x[0, 0] = 1.0


def test_every_method_names_its_kernel():
    """The registry names each method's kernel entry (Method.kernel): a function of the structure
    backend giving the numba kernel(args, st); the exact event-driven method has none."""
    from numba.core.registry import CPUDispatcher

    from slipstep.kernels.events import event_march_packed
    from slipstep.methods.marcher import march_kernel
    from slipstep.methods.registry import METHODS

    for method in METHODS.values():
        if method.kernel is None:
            with pytest.raises(ValueError, match="no march kernel"):
                march_kernel(method)
            continue
        assert isinstance(march_kernel(method)(0), CPUDispatcher), method.name
    assert METHODS["events"].kernel is None
    assert march_kernel(METHODS["quasi-static-events"])(0) is event_march_packed
    assert march_kernel(METHODS["newmark"])(2) is K.implicit_kernel(2)


def test_segments_continue_the_whole_march(paper):
    """[0, T] then [T, 2T] from the first segment's end state equals a march over [0, 2T] up to
    the round-off of the elastic-form contact force at the joint."""
    T = paper.period
    whole = Marcher(plan_run(paper, "piecewise-linear", periods=2, error_estimate=False))
    end_whole = whole.advance(static_equilibrium(whole.plan)).end_state
    plan = plan_run(paper, "piecewise-linear", periods=1, error_estimate=False)
    marcher = Marcher(plan)
    first = marcher.advance(static_equilibrium(plan))
    assert first.end_state.terms is None and first.end_state.t == pytest.approx(T)
    second = marcher.advance(first.end_state, 2 * T)
    assert second.status == Status.OK and second.trace.t[0] == pytest.approx(T)
    scale = np.abs(end_whole.x).max()
    np.testing.assert_allclose(second.end_state.x, end_whole.x, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(second.end_state.w, end_whole.w, rtol=0, atol=1e-9 * scale)
    np.testing.assert_array_equal(second.end_state.contact_state, end_whole.contact_state)


def test_a_marcher_is_reused_without_new_buffers(paper):
    plan = plan_run(paper, "newmark", periods=0.5, error_estimate=False)
    marcher = Marcher(plan)
    start = static_equilibrium(plan, marcher.ws)
    first = marcher.advance(start)
    x1 = first.trace.x.copy()
    held, out, ws = marcher.entry.packed[-1], marcher.out, marcher.ws
    again = marcher.advance(start)
    assert marcher.entry.packed[-1] is held and marcher.out is out and marcher.ws is ws
    np.testing.assert_array_equal(again.trace.x, x1)  # the start is not consumed by a march


@pytest.mark.parametrize("method", ["piecewise-linear", "piecewise-linear-adaptive", "newmark-adaptive"])
def test_kept_factorisations_give_the_same_march(paper, method):
    """A marcher that keeps its J(S) between marches of one plan (shooting's) refactorises
    nothing the second time and marches the same numbers as a marcher that forgets them;
    another plan, or a failed static equilibrium on its workspace, empties the cache."""
    plan = plan_run(paper, method, periods=1, error_estimate=False)
    start = static_equilibrium(plan)
    forget = Marcher(plan)
    keep = Marcher(plan)
    keep.keep_factorisations = True
    first = keep.advance(start)
    assert first.status == Status.OK and first.counters[K.C_FACTORISATIONS] > 0
    again = keep.advance(start)
    reference = forget.advance(start)
    assert again.counters[K.C_FACTORISATIONS] < reference.counters[K.C_FACTORISATIONS]
    if method == "piecewise-linear":  # fixed step: every J(S) was cached (an adaptive last step is not)
        assert again.counters[K.C_FACTORISATIONS] == 0
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(again.trace, name), getattr(reference.trace, name), err_msg=name)
    keep.retarget(dataclasses.replace(plan))  # another plan (the same numbers): its own factorisations
    assert keep.advance(start).counters[K.C_FACTORISATIONS] == reference.counters[K.C_FACTORISATIONS]
    static_equilibrium(keep.plan, keep.ws)  # a quasi-static march on the workspace: its J(S) are dropped
    assert not keep.ws.cache_used.any()


def test_consistent_start_has_the_equation_of_motion(paper):
    """a = M^-1 (f_e - C v - K x - A^T f) at the given state, f = k (q - w) elastic."""
    plan = plan_run(paper, "newmark", periods=1, error_estimate=False)
    cs = plan.compiled
    pre = static_equilibrium(plan)
    v = np.array([0.01, -0.02, 0.3])
    s = consistent_start(plan, pre.x * 1.1, v, pre.w, t=0.3 * paper.period)
    residual = cs.M @ s.a + cs.C @ s.v + cs.K @ s.x + cs.A.T @ s.terms.f - s.terms.fe
    scale = max(np.abs(cs.A.T @ s.terms.f).max(), np.abs(s.terms.fe).max(), np.abs(cs.M @ s.a).max())
    assert scale > 0 and np.abs(residual).max() <= 1e-12 * scale
    p = evaluate_compiled(motion_signal(cs), np.array([s.t]))[0]  # the prescribed motion at t
    q = cs.A @ s.x - cs.B @ p + cs.g
    np.testing.assert_allclose(s.terms.q, q, rtol=1e-14, atol=1e-20)
    tr = np.asarray(cs.tangential_row)
    closed = q[np.asarray(cs.normal_row)] > 0
    expected = np.where(closed[cs.direction_contact], cs.kt * (q[tr] - s.w), 0.0)
    np.testing.assert_allclose(s.terms.f[tr], expected, rtol=1e-14, atol=1e-14)


def test_state_is_frozen_and_round_trips_its_unknowns():
    s = State(0.5, np.arange(3.0), np.ones(3), np.zeros(3), np.array([0.1, 0.2]), np.array([1, 2], np.int8))
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.x = np.zeros(3)
    assert s.states is s.contact_state
    z = s.unknowns(False)
    np.testing.assert_array_equal(z, [0, 1, 2, 1, 1, 1, 0.1, 0.2])
    back = State.from_unknowns(z, 3, False, s.contact_state, t=0.5)
    np.testing.assert_array_equal(back.unknowns(False), z)
    assert back.a is None  # the consistent start fills it
    quasi = State.from_unknowns(s.unknowns(True), 3, True, s.contact_state)
    np.testing.assert_array_equal(quasi.v, 0.0)
    np.testing.assert_array_equal(quasi.w, s.w)


def test_a_pilot_plan_completes_the_plan_and_reuses_its_coarse_twin(paper):
    plan = plan_run(paper, "newmark", periods=3)
    assert plan.pilot_allowed and plan.settings is None and plan.capacity == 0  # no kernel run yet
    refined = accuracy.pilot_plan(plan)
    assert refined.dt <= plan.dt and refined.capacity > 0 and refined.settings.dt == refined.dt
    sim = ss.Simulation(paper, "newmark", periods=3)
    assert sim.dt == refined.dt and sim.max_step == refined.max_step


def test_a_retuned_plan_keeps_the_matrices_and_equals_a_new_plan(paper):
    from slipstep.frequency import retune

    plan = plan_run(paper, "piecewise-linear", periods=1, error_estimate=False)
    other = retune(paper, 173.0)
    retuned = plan.retuned(173.0, system=other)
    fresh = plan_run(other, "piecewise-linear", periods=1, error_estimate=False)
    assert retuned.compiled.M is plan.compiled.M and retuned.t_min_stick == plan.t_min_stick  # no compile
    for name, value in fresh.compiled._asdict().items():
        np.testing.assert_array_equal(getattr(retuned.compiled, name), value, err_msg=name)
    assert (retuned.dt, retuned.capacity, retuned.t_end, retuned.settings) == (
        fresh.dt,
        fresh.capacity,
        fresh.t_end,
        fresh.settings,
    )
    assert plan.retuned(173.0).period == pytest.approx(1 / 173.0, rel=1e-15)  # retune done by the plan
    marcher = Marcher(plan)
    out, ws = marcher.out, marcher.ws
    marcher.retarget(retuned)  # a longer period: more steps than the rows hold, new rows
    assert marcher.out is not out and marcher.ws is ws and marcher.plan is retuned
    out = marcher.out
    marcher.retarget(plan.retuned(230.0))  # a shorter one: the rows fit
    assert marcher.out is out and int(out.plan[0]) == marcher.plan.capacity


@pytest.mark.parametrize("solver", ["march", "shoot"])
def test_an_frf_point_on_the_reused_marcher_equals_one_on_a_new_marcher(paper, solver):
    from slipstep.frequency import retune
    from slipstep.steady import march_to_steady, shoot

    solve = shoot if solver == "shoot" else (lambda s, **kw: march_to_steady(s, max_periods=40, **kw))
    first = solve(retune(paper, 190.0))
    assert first._marcher is not None
    reused = solve(retune(paper, 200.0), initial=first)
    fresh = solve(retune(paper, 200.0), initial=dataclasses.replace(first, _marcher=None))
    assert reused._marcher is first._marcher and fresh._marcher is not first._marcher
    assert reused.status == fresh.status and reused.periods == fresh.periods
    for name in ("displacement", "velocity", "slider", "contact_state", "time"):
        np.testing.assert_array_equal(reused.period[name].values, fresh.period[name].values, err_msg=name)
    np.testing.assert_array_equal(reused.final_state.x, fresh.final_state.x)
    import pickle

    copy = pickle.loads(pickle.dumps(reused))  # the marcher (buffers, a compiled entry) is not pickled
    assert copy._marcher is None and copy.status == reused.status
    np.testing.assert_array_equal(copy.final_state.x, reused.final_state.x)
