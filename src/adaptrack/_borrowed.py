"""Borrowed array views for compiled hot loops: no reference counting on the view or its slices.

numba counts references on every array view it makes or passes (an atomic increment and
decrement through a call each time); in the scene tracker's scan loop that was about half the
time. :func:`borrowed` returns a view of an array that owns no reference: its slices and the
views made of it in called kernels count nothing. The caller keeps the array itself alive while
the view is in use (an argument of the caller, or a local of it used again after the
views), and never returns or stores the view. :func:`on_stack` gives a kernel
small scratch arrays in its own stack frame: no allocation and no reference counting at all.
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import populate_array


@intrinsic
def borrowed(typingctx: Any, arr: Any) -> Any:
    """View of array ``arr`` (same type) holding no reference to its memory; compiled code only."""
    if not isinstance(arr, types.Array):
        return None

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        src = context.make_array(arr)(context, builder, value=args[0])
        view = context.make_array(arr)(context, builder)
        for name in ("nitems", "itemsize", "data", "shape", "strides"):
            setattr(view, name, getattr(src, name))
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()

    return arr(arr), codegen


@intrinsic
def on_stack(typingctx: Any, shape: Any) -> Any:
    """Zeroed float64 C-contiguous array of a literal ``shape`` in the caller's stack frame.

    For small scratch buffers of a kernel (compiled code only): the memory is reserved once in
    the frame of the compiled function the call ends up in (inlined helpers: their caller's)
    and zeroed at each call; it is gone when that function returns, so the array is never
    returned or stored. ``shape``: an int or a tuple of ints known when compiling.
    """
    members = (shape,) if isinstance(shape, types.IntegerLiteral) else getattr(shape, "types", ())
    if not members or not all(isinstance(t, types.IntegerLiteral) for t in members):
        return None
    dims = tuple(t.literal_value for t in members)
    result = types.Array(types.float64, len(dims), "C")

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        count = 1
        for d in dims:
            count *= d
        item = context.get_abi_sizeof(context.get_data_type(types.float64))
        data = cgutils.alloca_once(builder, context.get_data_type(types.float64), size=count)
        cgutils.memset(builder, data, context.get_constant(types.intp, item * count), 0)
        strides: list[int] = []
        step = item
        for d in reversed(dims):
            strides.insert(0, step)
            step *= d
        view = context.make_array(result)(context, builder)
        populate_array(
            view,
            data=data,
            shape=cgutils.pack_array(builder, [context.get_constant(types.intp, d) for d in dims]),
            strides=cgutils.pack_array(
                builder, [context.get_constant(types.intp, st) for st in strides]
            ),
            itemsize=context.get_constant(types.intp, item),
            meminfo=None,
        )
        return view._getvalue()

    return result(shape), codegen
