"""One line on the terminal while the physics compiles: Numba compiles the kernels on their first call on a machine,
and keeps them in its cache (``__pycache__`` beside the sources) for later runs. Without a word, a first env step
that takes minutes looks like a hang.

A listener on Numba's compile events says so once per process, when Numba begins to compile one of this package's
functions: never when every kernel loads from the cache."""

from __future__ import annotations

import sys

from numba.core import event

PACKAGE = __name__.split(".")[0]
NOTICE = (f"{PACKAGE}: compiling the physics kernels for this machine, once (the default env's first step takes "
          "about a minute on 2 cores); later runs load them from Numba's cache in seconds")


class _FirstCompile(event.Listener):
    """Prints :data:`NOTICE` to stderr at the first compile of a function of this package, and counts them."""

    def __init__(self) -> None:
        self.said = False
        self.compiled = 0
        """How many of this package's functions this process has compiled (a load from the cache is not one)."""

    def on_start(self, compile_event) -> None:
        data = compile_event.data if isinstance(compile_event.data, dict) else {}
        module = getattr(getattr(data.get("dispatcher"), "py_func", None), "__module__", None) or ""
        if module.split(".")[0] != PACKAGE:
            return
        self.compiled += 1
        if not self.said:
            self.said = True
            print(NOTICE, file=sys.stderr, flush=True)

    def on_end(self, compile_event) -> None:
        pass


LISTENER = _FirstCompile()
event.register("numba:compile", LISTENER)
