"""How the physics compiles a function: the :func:`kernel` decorator, the one place that holds Numba's options.

Every kernel is cached on disk (Numba's cache, so a later process loads it in seconds), releases the GIL when Python
calls it, and divides as NumPy does (a division by zero gives inf or nan, it raises nothing).

**Most kernels are called only by other kernels**, and those are compiled without the two entry points Numba builds
for every function by default: the CPython wrapper that unboxes Python's arguments, and a C-callable wrapper. Each is
code of its own that LLVM optimises and emits whenever its function compiles, and for the solvers' large argument
bundles (tuples of twenty arrays) it is large: leaving them out of the kernels that Python never calls made the
default env's first compile from an empty cache 1.16× faster (docs/notes/compile_time.md). A kernel that Python
calls (an entry point of the simulator, one a test checks on its own, one the CUDA simulator's threads call) says so
with ``python=True``. Calling one that does not from Python raises :class:`TypeError` (without the guard Numba would
jump to a wrapper that was never built).
"""

from __future__ import annotations

from numba import config
from numba.core.registry import CPUDispatcher

_OPTIONS = {"nopython": True, "boundscheck": None, "nogil": True, "error_model": "numpy"}
"""The target options every kernel compiles with (``boundscheck`` None: Numba's own default, settable by its
environment variable)."""


class KernelOnlyDispatcher(CPUDispatcher):
    """A compiled function without a Python entry point: other compiled functions call it, Python may not."""

    def __call__(self, *args, **kwargs):
        function = self.py_func
        raise TypeError(
            f"{function.__module__}.{function.__qualname__} is compiled to be called from other compiled kernels "
            "only (it has no Python entry point); call it from a compiled function, or give it "
            "@kernel(python=True)")


def kernel(function=None, *, python: bool = False, inline: bool = False):
    """Compiles ``function`` for the CPU (and, through the GPU back end, from the same source for the GPU).

    ``python``: whether Python calls it (then it gets Numba's entry wrappers; otherwise only compiled functions
    may). ``inline``: whether each compiled caller takes a copy of its code (Numba's ``inline="always"``, at the IR
    level) instead of calling it. Used bare (``@kernel``) or with arguments (``@kernel(python=True)``)."""
    if not isinstance(python, bool):
        raise TypeError(f"kernel(python=...) must be a bool, got {python!r}")
    if not isinstance(inline, bool):
        raise TypeError(f"kernel(inline=...) must be a bool, got {inline!r}")

    def compile_later(function):
        if config.DISABLE_JIT:
            return function
        options = dict(_OPTIONS, inline="always" if inline else "never")
        if not python:
            options.update(no_cpython_wrapper=True, no_cfunc_wrapper=True)
        dispatcher_class = CPUDispatcher if python else KernelOnlyDispatcher
        dispatcher = dispatcher_class(py_func=function, locals={}, targetoptions=options)
        dispatcher.enable_caching()
        return dispatcher

    return compile_later if function is None else compile_later(function)


__all__ = ["KernelOnlyDispatcher", "kernel"]
