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

**Most kernels also run without Numba's reference counts** (its runtime, NRT). With the runtime every array a
function binds, each member of a bundle of twenty included, is counted up and down again, and those counts were a
quarter of a 3-D env step and a third of a planar one. A kernel that allocates (``np.empty``) needs the runtime, and
so does one that returns arrays to Python: ``@kernel(runtime=True)``. Every other kernel leaves it out (there an
allocation fails to compile: Numba finds "no implementation" of ``np.empty``), and an inlined kernel's copies take
their caller's mode. The two kinds may pass arrays to each other as arguments (borrowed, neither side counts them),
but an array *returned* from one kind to the other would be released twice or never, so a kernel whose compiled
code receives one across that boundary is refused when it compiles, naming both functions
(:func:`_refuse_arrays_returned_across_the_runtime_boundary`).
"""

from __future__ import annotations

from numba import config
from numba.core import errors, ir, types
from numba.core.caching import FunctionCache
from numba.core.registry import CPUDispatcher
from numba.core.typing.templates import _OverloadFunctionTemplate, _OverloadMethodTemplate

_OPTIONS = {"nopython": True, "boundscheck": None, "nogil": True, "error_model": "numpy"}
"""The target options every kernel compiles with (``boundscheck`` None: Numba's own default, settable by its
environment variable)."""


_NUMBA_WITHOUT_RUNTIME = "Only accept returning of array passed into the function as argument"
"""What Numba says where a function compiled without its runtime makes an array (its allocating overloads return one
they did not take)."""


_ALLOCATES = "is compiled without Numba's runtime, which making an array"


def _holds_array(numba_type) -> bool:
    """Whether a value of this Numba type holds an array (itself, or in a tuple or an optional)."""
    if isinstance(numba_type, types.Array):
        return True
    if isinstance(numba_type, types.BaseTuple):
        return any(_holds_array(member) for member in numba_type.types)
    if isinstance(numba_type, types.Optional):
        return _holds_array(numba_type.type)
    return False


def _brief(numba_type) -> str:
    """A type's name cut to a line (a bundle's spells out its twenty members' types)."""
    text = str(numba_type)
    return text if len(text) <= 80 else text[:77] + "..."


def _has_runtime(dispatcher) -> bool:
    return dispatcher.targetoptions.get("_nrt", True)


def _mode(runtime: bool) -> str:
    return "with Numba's runtime" if runtime else "without Numba's runtime"


def _overload_modes(callee) -> set:
    """The runtime modes of the ``@overload`` implementations that ``callee`` (a call's function type) may compile as
    functions of their own: True or False where the overload sets ``_nrt`` in its ``jit_options``, None where it
    takes the mode of whichever caller compiled it first (inlined overloads are lowered in their caller: no mode)."""
    templates = [callee.template] if isinstance(callee, types.BoundFunction) else getattr(callee, "templates", ())
    return {template._jit_options.get("_nrt") for template in templates
            if isinstance(template, type) and issubclass(template, (_OverloadFunctionTemplate, _OverloadMethodTemplate))
            and not template._inline.is_always_inline}


def _refuse_arrays_returned_across_the_runtime_boundary(dispatcher, cres) -> None:
    """Raises :class:`TypeError` where the kernel just compiled receives arrays from a call whose reference
    counting differs from its own: a kernel in the other mode, a plain Numba function or a separately compiled
    overload (their mode is not known) in a kernel without the runtime."""
    calltypes = cres.fndesc.calltypes
    if calltypes is None:  # loaded from the cache: it was checked when it compiled
        return
    runtime = _has_runtime(dispatcher)
    caller = f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"
    if not runtime and not isinstance(dispatcher, KernelOnlyDispatcher) and _holds_array(cres.signature.return_type):
        raise TypeError(
            f"{caller} is called from Python and returns arrays ({_brief(cres.signature.return_type)}) but is compiled "
            "without Numba's runtime, which Python's reference to a returned array needs: give it "
            "@kernel(python=True, runtime=True), or return nothing but scalars")
    for expression, signature in calltypes.items():
        if not (isinstance(expression, ir.Expr) and expression.op == "call" and _holds_array(signature.return_type)):
            continue
        callee = cres.fndesc.typemap[expression.func.name]
        if isinstance(callee, types.Dispatcher):
            callee_dispatcher = callee.dispatcher
            name = f"{callee_dispatcher.py_func.__module__}.{callee_dispatcher.py_func.__qualname__}"
            if isinstance(callee_dispatcher, KernelDispatcher):
                if _has_runtime(callee_dispatcher) == runtime:
                    continue
                detail = f"{name} is compiled {_mode(not runtime)}"
            elif runtime:
                continue
            else:
                detail = f"{name} is not a @kernel, so its mode is not known"
        else:
            modes = _overload_modes(callee)
            if modes <= {runtime} or (runtime and modes <= {True, None}):
                continue
            detail = (f"the overload {callee} compiles {_mode(not runtime)}" if None not in modes else
                      f"the overload {callee} compiles in the mode of whichever kernel compiled it first")
        raise TypeError(
            f"{caller} (compiled {_mode(runtime)}) receives arrays ({_brief(signature.return_type)}) from a call at "
            f"{expression.loc.short()} where {detail}: the arrays would be released twice or never. Compile both with "
            "the same @kernel(runtime=...), or return nothing but scalars across the boundary")


class _KernelCache(FunctionCache):
    """Numba's on-disk cache, keyed also by the kernel's target options, so that a kernel whose options change (its
    runtime mode among them) is compiled again rather than loaded as it was."""

    def __init__(self, dispatcher):
        super().__init__(dispatcher.py_func)
        self._options = dispatcher.targetoptions  # read when a key is made: the GPU back end switches inlining

    def _index_key(self, sig, codegen):
        return (*super()._index_key(sig, codegen), repr(sorted(self._options.items())))


class KernelDispatcher(CPUDispatcher):
    """A kernel's compiled function: checked, whenever it compiles, for arrays returned across the runtime
    boundary, and cached by its options as well as its source."""

    def add_overload(self, cres):
        _refuse_arrays_returned_across_the_runtime_boundary(self, cres)
        super().add_overload(cres)

    def compile(self, sig):
        try:
            return super().compile(sig)
        except errors.NumbaError as error:
            # Numba's own words for an allocation without the runtime do not say what to change; said once, by the
            # kernel that allocates (its callers see the same words in their error)
            message = str(error)
            if not _has_runtime(self) and _NUMBA_WITHOUT_RUNTIME in message and _ALLOCATES not in message:
                error.patch_message(f"{error.args[0]}\n{self.py_func.__module__}.{self.py_func.__qualname__} "
                                    f"{_ALLOCATES} (np.empty, np.zeros, a copy) needs: give it @kernel(runtime=True), "
                                    "or take the array as an argument (a work array, or kernels.local.local_array)")
            raise

    def enable_caching(self):
        self._cache = _KernelCache(self)


class KernelOnlyDispatcher(KernelDispatcher):
    """A compiled function without a Python entry point: other compiled functions call it, Python may not."""

    def __call__(self, *args, **kwargs):
        function = self.py_func
        raise TypeError(
            f"{function.__module__}.{function.__qualname__} is compiled to be called from other compiled kernels "
            "only (it has no Python entry point); call it from a compiled function, or give it "
            "@kernel(python=True)")


def kernel(function=None, *, python: bool = False, inline: bool = False, runtime: bool = False):
    """Compiles ``function`` for the CPU (and, through the GPU back end, from the same source for the GPU).

    ``python``: whether Python calls it (then it gets Numba's entry wrappers; otherwise only compiled functions
    may). ``inline``: whether each compiled caller takes a copy of its code (Numba's ``inline="always"``, at the IR
    level) instead of calling it. ``runtime``: whether it compiles with Numba's reference-counting runtime, which
    allocating needs, and so does returning arrays to Python. Used bare (``@kernel``) or with arguments
    (``@kernel(python=True)``)."""
    for name, value in (("python", python), ("inline", inline), ("runtime", runtime)):
        if not isinstance(value, bool):
            raise TypeError(f"kernel({name}=...) must be a bool, got {value!r}")

    def compile_later(function):
        if config.DISABLE_JIT:
            return function
        options = dict(_OPTIONS, inline="always" if inline else "never", _nrt=runtime)
        if not python:
            options.update(no_cpython_wrapper=True, no_cfunc_wrapper=True)
        dispatcher_class = KernelDispatcher if python else KernelOnlyDispatcher
        dispatcher = dispatcher_class(py_func=function, locals={}, targetoptions=options)
        dispatcher.enable_caching()
        return dispatcher

    return compile_later if function is None else compile_later(function)


__all__ = ["KernelDispatcher", "KernelOnlyDispatcher", "kernel"]
