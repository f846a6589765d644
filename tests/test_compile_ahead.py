"""Compiling a march's out-of-line kernels in a second process (methods/compile_ahead.py).

The list of callees (kernels.march.implicit_callees) must hold the argument types the march's
typing asks for, else the helper compiles kernels nobody loads: checked here by typing the march
(typing only, nothing lowered) and reading the calls of its typed IR.
"""

import os
import pickle
import pkgutil
import subprocess
import sys

import pytest
from numba import typeof, types
from numba.core import ir, typed_passes
from numba.core.compiler import CompilerBase, DefaultPassBuilder, Flags, compile_extra
from numba.core.compiler_machinery import FunctionPass, PassManager, register_pass
from numba.core.registry import cpu_target

import slipstep as ss
from slipstep.kernels import march as K
from slipstep.kernels.arguments import FIELDS, KernelArgumentsType
from slipstep.methods import compile_ahead
from slipstep.methods.marcher import Marcher
from slipstep.methods.plan import plan_run
from slipstep.methods.registry import IMPLICIT_KERNEL


@register_pass(mutates_CFG=False, analysis_only=True)
class _CallsOfTheTypedIR(FunctionPass):
    """The pipeline's result: {(dispatcher, argument types)} of every call of a numba dispatcher."""

    _name = "slipstep_calls_of_the_typed_ir"

    def __init__(self):
        FunctionPass.__init__(self)

    def run_pass(self, state):
        found = set()
        for expr, signature in state.calltypes.items():
            if not (isinstance(expr, ir.Expr) and expr.op == "call"):
                continue
            ty = state.typemap.get(expr.func.name)
            if isinstance(ty, types.Dispatcher):
                found.add((ty.dispatcher, tuple(signature.args)))
        state.cr = found
        return False


class _TypingOnly(CompilerBase):
    """numba's nopython pipeline up to type inference (nothing lowered), then the calls."""

    def define_pipelines(self):
        pm = PassManager("typing only")
        pm.passes.extend(DefaultPassBuilder.define_untyped_pipeline(self.state).passes)
        pm.add_pass(typed_passes.NopythonTypeInference, "nopython frontend")
        pm.add_pass(_CallsOfTheTypedIR, "the calls of the typed IR")
        pm.finalize()
        return [pm]


def _marcher(low_rank: bool) -> Marcher:
    system = ss.load_system("paper")
    plan = plan_run(system, "newmark", periods=0.05, linear_solver="low-rank" if low_rank else "direct")
    return Marcher(plan.with_step(plan.fixed_step(plan.max_step)))


def _march_types(marcher: Marcher) -> tuple:
    values = (marcher.plan.compiled, marcher.ws, marcher.out, marcher.q0, marcher.f0)
    return (KernelArgumentsType([(n, typeof(v)) for n, v in zip(FIELDS, values)]), typeof(marcher.settings))


def _calls_of_the_typed(py_func, argument_types: tuple) -> set:
    """{(dispatcher, argument types)} of every call of a numba dispatcher in the typed IR of
    ``py_func`` for these argument types (its inlined helpers included)."""
    flags = Flags()
    flags.error_model = "numpy"
    flags.nrt = True  # as njit: arrays allocated inside
    return compile_extra(
        cpu_target.typing_context,
        cpu_target.target_context,
        py_func,
        argument_types,
        None,
        flags,
        {},
        pipeline_class=_TypingOnly,
    )


def _calls_of_the_typed_march(backend: int, argument_types: tuple) -> set:
    """The calls of the march's typed IR and, two levels down, of the T_min kernels it calls (the
    list names the biggest of them, the Krylov routine, on its own)."""
    calls = _calls_of_the_typed(K.implicit_kernel(backend).py_func, argument_types)
    for _ in range(2):
        for dispatcher, args in list(calls):
            if dispatcher.py_func.__module__ in ("slipstep.kernels.march", "slipstep.kernels.eigen"):
                calls |= _calls_of_the_typed(dispatcher.py_func, args)
    return calls


def _check_the_callee_list(low_rank: bool) -> None:
    marcher = _marcher(low_rank)
    backend = marcher.settings.structure
    assert backend == (K.LOW_RANK if low_rank else K.DENSE)
    first, rest = K.implicit_callees(backend, marcher.plan.compiled, marcher.ws)
    listed = first + rest
    assert len(listed) == 11
    calls = _calls_of_the_typed_march(backend, _march_types(marcher))
    for path, argument_types in listed:
        dispatcher = pkgutil.resolve_name(path)
        asked = {args for d, args in calls if d is dispatcher}
        assert asked == {tuple(argument_types)}, (path, asked, argument_types)


@pytest.mark.parametrize("low_rank", [False, True], ids=["dense", "low-rank"])
def test_the_callee_list_holds_the_types_the_march_asks_for(low_rank):
    """In a process of its own: numba's typing-only pipeline leaves state that can crash a process
    at exit once the same kernel has also been compiled in it."""
    script = (
        f"import os, sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); import test_compile_ahead as t\n"
        f"t._check_the_callee_list({low_rank})\nsys.stdout.flush(); os._exit(0)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]


def test_the_banded_march_has_no_callee_list():
    marcher = _marcher(False)
    assert K.implicit_callees(K.BANDED, marcher.plan.compiled, marcher.ws) == ([], [])


def test_nothing_starts_outside_the_command_line(monkeypatch):
    started = []
    monkeypatch.setattr(subprocess, "Popen", lambda *a, **k: started.append(a))
    marcher = _marcher(False)
    args = (marcher.plan.compiled, marcher.settings, marcher.ws, marcher.out, marcher.q0, marcher.f0)
    compile_ahead.start(IMPLICIT_KERNEL, K.implicit_kernel(0), args)
    assert started == []


def test_a_march_in_the_disk_cache_is_known_and_starts_no_helper(monkeypatch):
    ss.run(ss.load_system("paper"), "newmark", periods=0.05)  # compiled or loaded: on disk now
    marcher = _marcher(False)
    dispatcher = K.implicit_kernel(marcher.settings.structure)
    assert compile_ahead.in_disk_cache(dispatcher, _march_types(marcher))
    assert not compile_ahead.in_disk_cache(dispatcher, (types.int64, types.float64))
    started = []
    monkeypatch.setattr(compile_ahead.subprocess, "Popen", lambda *a, **k: started.append(a))
    monkeypatch.setattr(compile_ahead, "_started", set())
    args = (marcher.plan.compiled, marcher.settings, marcher.ws, marcher.out, marcher.q0, marcher.f0)
    with compile_ahead.enabled():
        compile_ahead.start(IMPLICIT_KERNEL, dispatcher, args)
    assert started == []


def test_the_helper_compiles_its_list_into_an_empty_cache(tmp_path):
    """The helper process, on a small kernel: its cache files appear in the given directory."""
    listed = [("slipstep.kernels.eigen:lower_solve", (types.float64[:, ::1], types.float64[::1], types.float64[::1]))]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    done = subprocess.run(
        [sys.executable, "-m", "slipstep.methods.compile_ahead"], input=pickle.dumps(listed), env=env, timeout=300
    )
    assert done.returncode == 0
    written = [p.name for p in tmp_path.rglob("*") if p.suffix in (".nbi", ".nbc")]
    assert any(name.startswith("eigen.lower_solve") and name.endswith(".nbi") for name in written), written
    assert any(name.endswith(".nbc") for name in written)


def test_the_helper_is_stopped_when_the_block_ends(monkeypatch):
    """Within enabled() the first march of a kernel not on disk starts the helper; the march's
    end and the block's end stop it."""
    marcher = _marcher(False)
    monkeypatch.setattr(compile_ahead, "_started", set())
    monkeypatch.setattr(compile_ahead, "in_disk_cache", lambda dispatcher, argument_types: False)
    args = (marcher.plan.compiled, marcher.settings, marcher.ws, marcher.out, marcher.q0, marcher.f0)
    with compile_ahead.enabled():
        compile_ahead.start(IMPLICIT_KERNEL, K.implicit_kernel(0), args)
        helper = compile_ahead._helper
        assert helper is not None and helper.args[-1] == "slipstep.methods.compile_ahead"
        # a second march of the same kernel and backend starts nothing
        compile_ahead.start(IMPLICIT_KERNEL, K.implicit_kernel(0), args)
        assert compile_ahead._helper is helper
    assert compile_ahead._helper is None
    assert helper.poll() is not None  # terminated (or done), and waited for
