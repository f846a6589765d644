"""numba's compiler with one pass more for the march kernels: the copies of aggregates folded away.

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
it computed before, with fewer stack slots. Use it with
``njit(..., pipeline_class=LeanCompiler)``.
"""

from collections import Counter

from numba.core import ir, types
from numba.core.compiler import CompilerBase, DefaultPassBuilder
from numba.core.compiler_machinery import FunctionPass, register_pass
from numba.core.ir_utils import build_definitions, replace_vars
from numba.core.typed_passes import NoPythonSupportedFeatureValidation


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


class LeanCompiler(CompilerBase):
    """numba's default nopython pipeline with :class:`FoldAggregateCopies` before lowering."""

    def define_pipelines(self):
        pm = DefaultPassBuilder.define_nopython_pipeline(self.state)
        # after typing and numba's typed rewrites, before the lowering pipeline (whose IR
        # legalisation inserts the variables' deletions)
        at = [kind for kind, _ in pm.passes].index(NoPythonSupportedFeatureValidation)
        pm.passes.insert(at, (FoldAggregateCopies, "fold the copies of aggregates"))
        pm.finalize()
        return [pm]
