"""A bundle that is None or not, decided when a kernel compiles, so that each kernel compiles one kind of object.

Numba types every call in a function, in a branch that cannot run as well, and compiles the callee for it. It prunes
a branch on ``x is None`` before typing only where the argument ``x`` *is* None. So a kernel compiled for a free
body, whose fixed-object branch passed a literal None on, compiled the corrector and Newton's method a second time
for a fixed object that never came: a third of the default env's first compile. A function made with
:func:`none_or` returns None where its first argument is None and ``build``'s result otherwise, and the choice is
made from the argument's type (a Numba overload for every target, the CPU's and the GPU's), so one call site passes
one type: the callee's arguments for a free body, or None.

On the CPU the overload compiles in ``build``'s reference-counting mode (:mod:`~.compiled`), which its callers
must share; left to itself, it would take the mode of whichever kernel compiled it first. (Inlining it into its
callers instead, Numba's ``inline="always"`` for overloads, gave wrong steps.)
"""

from __future__ import annotations

from numba import types
from numba.extending import overload


def none_or(build):
    """A function of ``(value, *rest)``: None where ``value`` is None, else ``build(value, *rest)`` (``build`` a
    compiled function), with the branch chosen by ``value``'s type when the calling kernel compiles."""

    def chosen(value, *rest):
        return None if value is None else build(value, *rest)

    options = getattr(build, "targetoptions", {})
    jit_options = {"_nrt": options["_nrt"]} if "_nrt" in options else {}

    @overload(chosen, target="generic", jit_options=jit_options)
    def _typed(value, *rest):
        if isinstance(value, types.NoneType):
            return lambda value, *rest: None
        return lambda value, *rest: build(value, *rest)

    chosen.__name__ = chosen.__qualname__ = f"none_or_{build.__name__.lstrip('_')}"
    chosen.__doc__ = f"None where the first argument is None, else ``{build.__name__}``'s result (:func:`none_or`)."
    return chosen


__all__ = ["none_or"]
