"""Kernel arguments unboxed once (kernels/arguments.py): every march kernel, as the runners call
it (their kernel entry: the arguments packed once, the compiled overload kept), writes the same
numbers into the runner's own arrays as its ``march(sys, st, ws, out, q0, f0)`` wrapper called
on the argument tuples, and a runner packs its arrays again only when it replaces one."""

import numpy as np
import pytest

import slipstep
from slipstep.integrators.explicit_simulation import ExplicitSimulation
from slipstep.integrators import get_integrator
from slipstep.kernels import march as K
from slipstep.kernels.events import event_march
from slipstep.kernels.explicit import explicit_march
from slipstep.kernels.arguments import KernelArguments, pack_arguments, unpacked
from slipstep.kernels.quasi_static import quasi_static_march
from slipstep.methods.simulation import Simulation, _reset_cache, reset_outputs, saved_rows
from numba import njit

from slipstep.kernels.codes import C_STEPS

OUTPUTS = ("t", "dt", "x", "v", "a", "q", "f", "w", "state", "solves", "step")


def _runners():
    paper = slipstep.load_system("paper")
    wrappers = {
        "newmark": K.march,
        "piecewise-linear-adaptive": K.march,
        "quasi-static": quasi_static_march,
        "quasi-static-events": event_march,
    }
    for method, wrapper in wrappers.items():
        yield method, Simulation(paper, method, periods=1), wrapper
    yield "rk4", ExplicitSimulation(paper, get_integrator("rk4"), periods=0.5), explicit_march


def _outputs(sim) -> dict:
    return {name: getattr(sim.out, name).copy() for name in (*OUTPUTS, "counters")}


@pytest.mark.parametrize("label, sim, kernel", list(_runners()), ids=lambda v: v if isinstance(v, str) else "")
def test_the_runners_kernel_call_writes_what_the_wrapper_writes(label, sim, kernel):
    sim.run()
    packed = _outputs(sim)
    assert sim._packed is not None, "the runner packed the arguments"
    held = sim._packed[-1]
    assert isinstance(held, KernelArguments)
    # the kernel's wrapper, on the argument tuples, from the same start
    for name in OUTPUTS:
        # (the runner's numbers are kept in `packed`; v, a as allocated: quasi-static kernels leave them 0)
        getattr(sim.out, name)[...] = 0 if name in ("v", "a") else -9
    ws = sim.ws
    for name, start in zip(("x", "v", "a", "fe", "gf", "w", "state"), sim.preload_state):
        if hasattr(ws, name):  # (the explicit workspace has no fe, gf)
            getattr(ws, name)[...] = start
    if hasattr(ws, "lr"):
        _reset_cache(ws)
    sim.out.counters[:] = 0
    reset_outputs(sim.out)
    status = kernel(*sim.kernel_arguments())
    assert status == 0
    direct = _outputs(sim)
    rows = saved_rows(sim.out, int(direct["counters"][C_STEPS]))
    assert rows > 10
    np.testing.assert_array_equal(packed["counters"], direct["counters"])
    for name in OUTPUTS:
        np.testing.assert_array_equal(packed[name][:rows], direct[name][:rows], err_msg=f"{label}: {name}")
    # a second march reuses the packed arguments; replacing an array packs again, into the new array
    sim.march()
    assert sim._packed[-1] is held
    sim.out = sim.out._replace(x=np.zeros_like(sim.out.x))
    sim.march()
    assert sim._packed[-1] is not held
    np.testing.assert_array_equal(sim.out.x, packed["x"])


@njit(cache=True)
def _first_entries(args):
    sys, ws, out, q0, f0 = unpacked(args)
    out.counters[0] = 7  # lands in the caller's array
    return q0[0], f0[0]


def test_unpacked_gives_the_callers_arrays():
    sim = Simulation(slipstep.load_system("paper"), "newmark", periods=1)
    sys, _, ws, out, q0, f0 = sim.kernel_arguments()
    q0[0], f0[0] = 1.5, -2.5
    args = pack_arguments(sys, ws, out, q0, f0)
    assert _first_entries(args) == (1.5, -2.5)
    assert out.counters[0] == 7
