"""numba's compiler for the march kernels: the copies of aggregates folded away, and the
``inline="always"`` helpers inlined without copying the callee's scope once per block.

A march kernel handles its arrays as a few named tuples (CompiledSystem: 44 arrays, Workspace:
52, the state cache, the step vectors, the contact table). Every ``inline="always"`` helper that
takes one of them gets its own variable for it (``helper_v12_sys = sys``), and numba lowers every
variable to a stack slot holding the whole aggregate (an array is 7 machine words): the implicit
march had 33 copies of the CompiledSystem, 24 of the contact table, 16 of the state cache. LLVM's
scalar replacement of aggregates (SROA) and value propagation over those copies took about 30 of
the 40 s of LLVM function passes of that kernel (``NUMBA_LLVM_PASS_TIMINGS=1``); numba's own
issue 5953 measures the same growth with tuples of arrays.

:class:`FoldAggregateCopies` runs after type inference, before lowering: a variable of a tuple
or array type that is assigned exactly once, from another variable of the same type that is
itself assigned exactly once, is replaced by that variable everywhere and its assignment removed. Both
being single-assignment, the source holds the same value at every use of the copy (its one
definition precedes the copy's, which precedes every use), so the kernel computes exactly what
it computed before, with fewer stack slots.

:class:`InlineWithOneScopeCopy` is numba's inlining of ``inline="always"`` functions (untyped, before
type inference) with one change in how the callee's IR is copied. numba copies the callee block by
block (``copy.deepcopy`` of each block, twice per call site), and every block's copy drags along
its own copy of the callee's whole variable scope (every ``Var`` holds the scope). That is
(blocks x variables) work per call site: on the paper case's implicit march 15 of its 60 s of
compile time, 87 % of the inlining pass in deep copies. Here, within one call site's inlining, every
copy of one scope is the same copy (:func:`one_copy_per_scope`), so the IR that is inlined is the
same, block for block and name for name; only the discarded unmutated copy numba also makes shares
that scope. Use both with ``njit(..., pipeline_class=LeanCompiler)``.
"""

import contextlib
import copy
from collections import Counter

from numba.core import inline_closurecall, ir, types
from numba.core.compiler import CompilerBase, DefaultPassBuilder
from numba.core.compiler_machinery import FunctionPass, register_pass
from numba.core.ir_utils import build_definitions, replace_vars
from numba.core.typed_passes import NoPythonSupportedFeatureValidation
from numba.core.untyped_passes import InlineInlinables


@register_pass(mutates_CFG=False, analysis_only=False)
class FoldAggregateCopies(FunctionPass):
    """Replace the single-assignment copies of tuple- and array-typed variables by their source
    (module docstring)."""

    _name = "slipstep_fold_aggregate_copies"

    def __init__(self):
        FunctionPass.__init__(self)

    def run_pass(self, state):
        blocks, typemap = state.func_ir.blocks, state.typemap
        assignments = Counter(
            stmt.target.name for block in blocks.values() for stmt in block.body if isinstance(stmt, ir.Assign)
        )
        source = {}
        for block in blocks.values():
            for stmt in block.body:
                if not (isinstance(stmt, ir.Assign) and isinstance(stmt.value, ir.Var)):
                    continue
                target, value = stmt.target.name, stmt.value.name
                kind = typemap.get(target)
                if (
                    isinstance(kind, (types.BaseTuple, types.Array))
                    and typemap.get(value) == kind
                    and assignments[target] == 1
                    and assignments[value] == 1
                ):
                    source[target] = stmt.value
        if not source:
            return False

        def root(var):
            while var.name in source:
                var = source[var.name]
            return var

        replacement = {name: root(var) for name, var in source.items()}
        for block in blocks.values():
            block.body = [
                stmt
                for stmt in block.body
                if not (isinstance(stmt, ir.Assign) and stmt.target.name in replacement)
            ]
        replace_vars(blocks, replacement)
        for name in replacement:
            typemap.pop(name, None)
        state.func_ir._definitions = build_definitions(blocks)
        return True


@contextlib.contextmanager
def one_copy_per_scope():
    """Within this block every ``copy.deepcopy`` of a numba IR ``Scope`` returns one copy per
    original scope (numba's deep copy otherwise makes a new one per copied block). Entered only
    while numba compiles, under its global compiler lock; re-entering it changes nothing."""
    if "__deepcopy__" in vars(ir.Scope):
        yield
        return
    copies = {}  # id(original) -> (original, its copy): the original kept alive, its id not reused

    def deepcopy_scope(scope, memo):
        kept = copies.get(id(scope))
        if kept is None:
            duplicate = ir.Scope.__new__(ir.Scope)
            memo[id(scope)] = duplicate
            kept = copies[id(scope)] = (scope, duplicate)
            duplicate.__dict__.update(copy.deepcopy(scope.__dict__, memo))
        memo[id(scope)] = kept[1]
        return kept[1]

    ir.Scope.__deepcopy__ = deepcopy_scope
    try:
        yield
    finally:
        del ir.Scope.__deepcopy__


class _OneScopeCopyInliner(inline_closurecall.InlineWorker):
    """numba's inline worker; each call site's inlining within :func:`one_copy_per_scope`."""

    def inline_ir(self, *args, **kwargs):
        with one_copy_per_scope():
            return super().inline_ir(*args, **kwargs)


@register_pass(mutates_CFG=True, analysis_only=False)
class InlineWithOneScopeCopy(InlineInlinables):
    """numba's ``InlineInlinables`` with :class:`_OneScopeCopyInliner` as its worker, for the
    callees' own (nested) inlining too (module docstring)."""

    _name = "slipstep_inline_with_one_scope_copy"

    def run_pass(self, state):
        # numba's pass imports the worker class when it runs (and so do the nested passes it
        # starts): swap it for the duration of this pass
        worker = inline_closurecall.InlineWorker
        inline_closurecall.InlineWorker = _OneScopeCopyInliner
        try:
            return super().run_pass(state)
        finally:
            inline_closurecall.InlineWorker = worker


class LeanCompiler(CompilerBase):
    """numba's default nopython pipeline with :class:`InlineWithOneScopeCopy` in place of its
    inlining pass and :class:`FoldAggregateCopies` before lowering."""

    def define_pipelines(self):
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)
        kinds = [kind for kind, _ in pm.passes]
        at = kinds.index(InlineInlinables)
        pm.passes[at] = (InlineWithOneScopeCopy, pm.passes[at][1])
        # after typing and numba's typed rewrites, before the lowering pipeline (whose IR
        # legalisation inserts the variables' deletions)
        at = kinds.index(NoPythonSupportedFeatureValidation)
        pm.passes.insert(at, (FoldAggregateCopies, "fold the copies of aggregates"))
        pm.finalize()
        return [pm]
