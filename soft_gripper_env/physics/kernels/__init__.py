"""Compiled kernels: the rods' elastic energies, the force terms, contact geometry, the rigid body's loads and the
banded linear algebra, each written once over one rod (or one body) and looped over a batch. They read the scene
layer's descriptions and nothing above it."""

from . import compile_notice  # noqa: F401  (says so, once, while Numba compiles the kernels)
