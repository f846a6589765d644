"""kernels/lean_compiler.py: the copies of aggregates folded away and the inline helpers inlined
with one copy of their scope, the results unchanged."""

import contextlib
import copy
import io
import os
import re
import subprocess
import sys
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.core import bytecode, ir, ir_utils
from numba.core.compiler import CompilerBase, DefaultPassBuilder, Flags
from numba.core.compiler_machinery import AnalysisPass, register_pass
from numba.core.registry import cpu_target
from numba.core.typed_passes import NoPythonSupportedFeatureValidation
from numba.core.untyped_passes import ExtractByteCode, InlineInlinables

from slipstep.kernels.lean_compiler import FoldAggregateCopies, InlineWithOneScopeCopy, LeanCompiler, one_copy_per_scope

AGGREGATE_VARIABLES: list[int] = []  # per compile: the tuple-typed variables that reach lowering


@register_pass(mutates_CFG=False, analysis_only=True)
class CountAggregates(AnalysisPass):
    _name = "test_count_aggregates"

    def __init__(self):
        AnalysisPass.__init__(self)

    def run_pass(self, state):
        AGGREGATE_VARIABLES.append(sum(isinstance(t, types.BaseTuple) for t in state.typemap.values()))
        return False


class CountingLean(LeanCompiler):
    def define_pipelines(self):
        (pm,) = LeanCompiler.define_pipelines(self)
        at = [kind for kind, _ in pm.passes].index(NoPythonSupportedFeatureValidation)
        pm.passes.insert(at, (CountAggregates, "count"))
        pm.finalize()
        return [pm]


class CountingDefault(CompilerBase):
    def define_pipelines(self):
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)
        at = [kind for kind, _ in pm.passes].index(NoPythonSupportedFeatureValidation)
        pm.passes.insert(at, (CountAggregates, "count"))
        pm.finalize()
        return [pm]


class Arrays(NamedTuple):
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray


@njit(inline="always")
def _axpy(arrays, a):
    for i in range(arrays.x.shape[0]):
        arrays.y[i] += a * arrays.x[i]


@njit(inline="always")
def _scale(arrays, a):
    _axpy(arrays, a)
    for i in range(arrays.z.shape[0]):
        arrays.z[i] = a * arrays.y[i]


def _body(arrays, other, n):
    """Inline helpers taking a named tuple (copies), and a tuple variable assigned in a loop
    (several assignments: must not be folded)."""
    current = arrays
    for k in range(n):
        _scale(current, 0.5 + k)
        _axpy(arrays, 1.0)
        current = other if k % 2 == 0 else arrays
    total = 0.0
    for i in range(arrays.y.shape[0]):
        total += arrays.y[i] + other.z[i] + current.x[i]
    return total


def _inputs(seed):
    rng = np.random.default_rng(seed)
    return (Arrays(*(rng.standard_normal(7) for _ in range(3))), Arrays(*(rng.standard_normal(7) for _ in range(3))))


def test_folded_kernel_computes_exactly_what_the_default_one_computes():
    lean, plain = njit(pipeline_class=CountingLean)(_body), njit(pipeline_class=CountingDefault)(_body)
    for seed in range(3):
        a1, o1 = _inputs(seed)
        a2, o2 = _inputs(seed)
        assert lean(a1, o1, 5) == plain(a2, o2, 5)
        for got, want in zip(a1 + o1, a2 + o2):
            np.testing.assert_array_equal(got, want)
    folded, default = AGGREGATE_VARIABLES[-2:]
    assert folded < default  # the inline helpers' copies of the named tuple are gone


def test_the_pass_runs_in_the_lean_pipeline():
    @njit(pipeline_class=LeanCompiler)
    def f(arrays):
        _scale(arrays, 2.0)
        return arrays.z.sum()

    a, _ = _inputs(0)
    expect = 2.0 * (a.y + 2.0 * a.x)
    assert np.isclose(f(a), expect.sum())
    np.testing.assert_array_equal(a.z, expect)
    passes = f.overloads[f.signatures[0]].metadata["pipeline_times"]["nopython"]
    assert any(name.endswith(FoldAggregateCopies._name) for name in passes)


def _untyped_ir_text(one_scope_copy: bool) -> str:
    """numba's untyped pipeline on :func:`_body` (nested inline helpers, loops, branches), with
    numba's inlining pass or :class:`InlineWithOneScopeCopy`: the IR as text, labels renumbered,
    object addresses removed."""
    flags = Flags()
    flags.nrt = True
    state = CompilerBase(cpu_target.typing_context, cpu_target.target_context, None, None, None, flags, {}).state
    state.func_id = bytecode.FunctionIdentity.from_function(_body)
    ExtractByteCode().run_pass(state)
    state.args = (types.pyobject,) * _body.__code__.co_argcount
    pm = DefaultPassBuilder.define_untyped_pipeline(state)
    if one_scope_copy:
        at = [kind for kind, _ in pm.passes].index(InlineInlinables)
        pm.passes[at] = (InlineWithOneScopeCopy, "inline")
    pm.finalize()
    pm.run(state)
    state.func_ir.blocks = ir_utils.rename_labels(state.func_ir.blocks)
    text = io.StringIO()
    with contextlib.redirect_stdout(text):
        state.func_ir.dump()
    return re.sub(r"0x[0-9a-f]+", "0x", text.getvalue())


def test_the_inlined_ir_is_numbas_block_for_block_and_name_for_name():
    """Each pipeline in a process of its own, with one hash seed: the inlined variables' names
    hold process-wide counters, and the order of some phi copies follows set iteration."""
    script = (
        f"import sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); import test_lean_compiler as t\n"
        "sys.stdout.write(t._untyped_ir_text(sys.argv[1] == 'lean'))\n"
    )
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    numba_ir, lean_ir = (
        subprocess.run(
            [sys.executable, "-c", script, kind], capture_output=True, text=True, env=env, timeout=300
        ).stdout
        for kind in ("numba", "lean")
    )
    assert "_scale" in numba_ir and "_axpy" in numba_ir and "call" in numba_ir  # inlined, nested
    assert lean_ir == numba_ir


def test_one_copy_per_scope_while_inlining_only():
    scope = ir.Scope(None, ir.Loc("f", 1))
    blocks = [ir.Block(scope, ir.Loc("f", k)) for k in range(3)]
    for k, block in enumerate(blocks):
        block.append(ir.Assign(ir.Const(k, block.loc), scope.define(f"x{k}", block.loc), block.loc))
    separate = [copy.deepcopy(block) for block in blocks]
    assert len({id(block.scope) for block in separate}) == 3  # numba's deep copy: a scope per block
    with one_copy_per_scope():
        with one_copy_per_scope():  # re-entered: nothing changes
            pass
        shared = [copy.deepcopy(block) for block in blocks]
        assert "__deepcopy__" in vars(ir.Scope)
    assert "__deepcopy__" not in vars(ir.Scope)  # numba's own copy again
    (one,) = {id(block.scope) for block in shared}
    assert one != id(scope)
    assert shared[0].scope.localvars.get("x2").name == "x2"  # a whole copy of the scope's variables
    for copied, original in zip(shared, blocks):
        assert (
            copied.body[0].target.scope is copied.scope and copied.body[0].target.name == original.body[0].target.name
        )
    with contextlib.suppress(RuntimeError), one_copy_per_scope():
        raise RuntimeError
    assert "__deepcopy__" not in vars(ir.Scope)  # removed on an error too


def test_the_lean_pipeline_inlines_with_one_scope_copy():
    f = njit(pipeline_class=LeanCompiler)(_body)
    a1, o1 = _inputs(1)
    a2, o2 = _inputs(1)
    assert f(a1, o1, 3) == njit(_body)(a2, o2, 3)
    passes = f.overloads[f.signatures[0]].metadata["pipeline_times"]["nopython"]
    assert any(name.endswith(InlineWithOneScopeCopy._name) for name in passes)
    assert not any(name.endswith("_" + InlineInlinables._name) for name in passes)
