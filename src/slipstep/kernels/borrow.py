"""Borrowed views: the arrays of a kernel's arguments without numba's reference counting.

numba counts references to every array (an atomic increment and decrement, NRT_incref /
NRT_decref) each time a variable takes it: every argument of an inlined helper, every field
taken from a tuple, every non-inlined call's parameters. In the march loop those updates were
the largest per-step cost (perf on the paper case, Method 4: 46 % of the kernel time at the
session start, 80 % once the march was split into helpers taking tuples). A view whose
``meminfo`` is NULL is not counted (NRT_incref / NRT_decref return at once on NULL).

:func:`borrowed` returns such a view of an array, or of every array inside a (named, nested)
tuple. Safe only for arrays that outlive the kernel call: the kernel's own arguments (the
caller holds them), never an array allocated inside the kernel (numba may free that once
its own variable is dead), and a borrowed view must never be returned or stored.
"""

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


def borrow_value(context, builder, ty, value):
    """``value`` (of numba type ``ty``) with the MemInfo of every array in it set to NULL."""
    if isinstance(ty, types.Array):
        ary = cgutils.create_struct_proxy(ty)(context, builder, value=value)
        ary.meminfo = ir.Constant(ary.meminfo.type, None)
        return ary._getvalue()
    if isinstance(ty, types.BaseTuple):
        for i, member in enumerate(ty.types):
            item = builder.extract_value(value, i)
            value = builder.insert_value(value, borrow_value(context, builder, member, item), i)
        return value
    return value


@intrinsic
def borrowed(typingctx, value):
    """A view of ``value`` (an array or a tuple holding arrays) whose arrays are not
    reference counted (module docstring)."""

    def codegen(context, builder, signature, args):
        return borrow_value(context, builder, signature.args[0], args[0])

    return value(value), codegen


@intrinsic
def keep_alive(typingctx, value):
    """Does nothing with ``value``: a use that keeps the variables it names alive up to this
    point. A kernel may borrow an array it allocated (numba frees an array once its variable
    is dead) if it calls keep_alive on the owning variable after the last use of the view:

        own = np.zeros(n); buf = borrowed(own)
        ... loops using buf ...
        keep_alive(own)
    """

    def codegen(context, builder, signature, args):
        return context.get_dummy_value()

    return types.none(value), codegen
