"""The array arguments of a march kernel held by one numba object (a structref), unboxed once.

numba unboxes every array of a kernel's arguments on each call: a MemInfo allocated and freed,
the array object, its shape, strides and data read (about 40 ns per array with warm caches).
The implicit and quasi-static marches take over 100 arrays (CompiledSystem, Workspace,
Outputs, q0, f0), the event-driven march 50. Measured on the paper case with a kernel that
returns at once, called between the other methods' runs as ``slipstep compare`` calls it
(caches cold): 6-10 us per call for the event kernel's 50 arrays (2 us back to back), against
2-4 us (0.3 us) for one :class:`KernelArguments`, about a fifth of the event-driven march.

A :class:`KernelArguments` is built once per (system, workspace, outputs, q0, f0) by the
runner's kernel entry (methods/marcher.py, :func:`pack_arguments`); it holds the caller's arrays
(what a kernel writes lands in them) and keeps them alive. Every march kernel is written in that
form, ``kernel(args, st)`` starting from ``(sys, ws, out, q0, f0) = unpacked(args)`` (the settings
``st``, which change from march to march, passed beside), and its module gives it as a function
of the structure backend (``implicit_kernel``, ``quasi_static_kernel``: one kernel per backend;
``event_kernel``, ``explicit_kernel``: one for all), which the method registry names; the
``march(sys, st, ws, out, q0, f0)`` of each (``quasi_static_march``, ``event_march``,
``explicit_march``) is a Python wrapper that packs the arguments.
"""

from numba import njit, types
from numba.core import cgutils
from numba.experimental import structref
from numba.extending import intrinsic

from slipstep.kernels.borrow import borrow_value

FIELDS = ("sys", "ws", "out", "q0", "f0")


@structref.register
class KernelArgumentsType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class KernelArguments(structref.StructRefProxy):
    """sys, ws, out, q0, f0 of a march kernel, unboxed once (module docstring)."""


structref.define_proxy(KernelArguments, KernelArgumentsType, list(FIELDS))


@njit(cache=True)
def pack_arguments(sys, ws, out, q0, f0):
    """A :class:`KernelArguments` of these tuples and arrays (compiled once per layout and
    cached on disk, unlike the proxy's own constructor)."""
    return KernelArguments(sys, ws, out, q0, f0)


@intrinsic
def unpacked(typingctx, args):
    """(sys, ws, out, q0, f0) of a :class:`KernelArguments`, as borrowed views
    (kernels/borrow.py: no reference counting; the structref keeps the arrays alive for the
    call). numba's own field access would count a reference to every array it returns,
    touching each array's MemInfo, which is what unboxing once avoids."""
    if not isinstance(args, KernelArgumentsType):
        return None
    fields = [args.field_dict[name] for name in FIELDS]
    result = types.Tuple(fields)

    def codegen(context, builder, signature, values):
        ref = cgutils.create_struct_proxy(args)(context, builder, value=values[0])
        payload = args.get_data_type()
        pointer = context.nrt.meminfo_data(builder, ref.meminfo)
        pointer = builder.bitcast(pointer, context.data_model_manager[payload].get_value_type().as_pointer())
        data = cgutils.create_struct_proxy(payload)(context, builder, ref=pointer)
        items = [borrow_value(context, builder, ty, getattr(data, name)) for name, ty in zip(FIELDS, fields)]
        return context.make_tuple(builder, result, items)

    return result(args), codegen
