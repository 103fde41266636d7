"""Borrowed array views for compiled hot loops: no reference counting on the view or its slices.

numba counts references on every array view it makes or passes (an atomic increment and
decrement through a call each time); in the scene tracker's scan loop that was about half the
time. :func:`borrowed` returns a view of an array that owns no reference: its slices and the
views made of it in called kernels count nothing. The caller keeps the array itself alive while
the view is in use (an argument of the caller, or a local used again after the views with
:func:`keep_alive`), and never returns or stores the view.
"""

from __future__ import annotations

from typing import Any

from numba import types
from numba.core import cgutils
from numba.extending import intrinsic


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
def keep_alive(typingctx: Any, obj: Any) -> Any:
    """Use ``obj`` here and do nothing (compiled code only).

    numba frees a local array right after its last use; a function that borrows views of its
    own arrays calls this with them after its last use of the views.
    """

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        return context.get_dummy_value()

    return types.none(obj), codegen
