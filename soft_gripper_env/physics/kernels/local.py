"""Small work arrays of a constant shape that both compile targets can make.

A kernel function that needs a few numbers of scratch (a point, a normal, a 3×3 rotation) calls
:func:`local_array` with a constant shape. The array lives on the calling function's stack, one per call site (as a
GPU thread's local array does), and is valid until that function returns: never return one. On the CPU it is an
``alloca`` in the function's entry block, so no heap and no reference count (kernels without Numba's runtime can
make one). On the GPU the same call is the thread's own array (``cuda.local.array``): the GPU back end registers it
with numba-cuda when it first imports it (:func:`~..solvers.gpu.import_cuda`), so the kernels here never import the
CUDA target. The shape must be an integer or a tuple of integers written in the call (a compile-time constant); a
size known only at run time takes the largest it can be, sliced (``local_array(3)[:dim]``).
"""

from __future__ import annotations

import numpy as np
from numba.core import cgutils, types
from numba.core.imputils import lower_builtin
from numba.extending import type_callable
from numba.np.arrayobj import make_array, populate_array

_ITEM_BYTES = 8
"""Bytes of one float64."""


def local_array(shape):
    """Uninitialised float64 work array of the constant ``shape`` (an int, or a tuple of ints)."""
    return np.empty(shape)


def constant_shape(shape) -> tuple[int, ...] | None:
    """The dimensions of a ``local_array`` call's shape argument (a Numba type), or None where they are not
    constants written in the call."""
    if isinstance(shape, types.IntegerLiteral):
        return (shape.literal_value,)
    if isinstance(shape, types.BaseTuple) and all(isinstance(member, types.IntegerLiteral) for member in shape.types):
        return tuple(member.literal_value for member in shape.types)
    return None


@type_callable(local_array)
def _type_local_array(context):
    def typer(shape):
        dimensions = constant_shape(shape)
        return None if dimensions is None else types.Array(types.float64, len(dimensions), "C")

    return typer


@lower_builtin(local_array, types.IntegerLiteral)
@lower_builtin(local_array, types.BaseTuple)
def _lower_local_array_on_the_stack(context, builder, signature, args):
    dimensions = constant_shape(signature.args[0])
    size = int(np.prod(dimensions, dtype=np.int64))
    data = cgutils.alloca_once(builder, context.get_value_type(types.float64), size=max(size, 1))
    strides, stride = [], _ITEM_BYTES
    for dimension in reversed(dimensions):
        strides.insert(0, stride)
        stride *= dimension
    array = make_array(signature.return_type)(context, builder)
    populate_array(array, data=data, shape=[context.get_constant(types.intp, d) for d in dimensions],
                   strides=[context.get_constant(types.intp, s) for s in strides],
                   itemsize=context.get_constant(types.intp, _ITEM_BYTES), meminfo=None)
    return array._getvalue()


__all__ = ["constant_shape", "local_array"]
