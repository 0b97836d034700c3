"""Small work arrays of a constant shape that both compile targets can make.

A kernel function that needs a few numbers of scratch (a point, a normal, a 3×3 rotation) calls
:func:`local_array` with a constant shape. On the CPU it is ``np.empty``. On the GPU, where a device function cannot
allocate from the heap, the same call is the thread's own array (``cuda.local.array``): the GPU back end registers it
with numba-cuda when it first imports it (:func:`~..solvers.gpu.import_cuda`), so the kernels here never import the
CUDA target. The shape must be an integer or a tuple of integers written in the call (a compile-time constant on the
GPU); a size known only at run time takes the largest it can be, sliced (``local_array(3)[:dim]``).
"""

from __future__ import annotations

import numpy as np
from numba.extending import overload


def local_array(shape):
    """Uninitialised float64 work array of the constant ``shape`` (an int, or a tuple of ints)."""
    return np.empty(shape)


@overload(local_array, target="cpu")
def _local_array_cpu(shape):
    def make(shape):
        return np.empty(shape)

    return make


__all__ = ["local_array"]
