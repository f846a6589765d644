"""kernels/lean_compiler.py: the copies of aggregates folded away, the results unchanged."""

from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.core.compiler import CompilerBase, DefaultPassBuilder
from numba.core.compiler_machinery import AnalysisPass, register_pass
from numba.core.typed_passes import NoPythonSupportedFeatureValidation

from slipstep.kernels.lean_compiler import FoldAggregateCopies, LeanCompiler

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
