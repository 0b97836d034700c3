"""A bundle that is None or not, chosen when a kernel compiles (soft_gripper_env/physics/kernels/typed_none.py)."""

import numpy as np
from numba import njit

from soft_gripper_env.physics.kernels.typed_none import none_or


def _fresh_functions():
    """A callee that branches on None, a bundle builder made with :func:`none_or`, and two callers: one passes a
    literal None on in the branch for no bundle (what the corrector did), one passes the chosen value."""

    @njit
    def callee(bundle, out):
        if bundle is None:
            out[0] = -1.0
        else:
            out[0] = bundle[0] + bundle[1][0]

    @njit
    def _pair(value, extra):
        return (value[0], extra)

    pair = none_or(_pair)

    @njit
    def with_literal_none(value, extra, out):
        if value is None:
            callee(None, out)
        else:
            callee((value[0], extra), out)

    @njit
    def with_chosen(value, extra, out):
        callee(pair(value, extra), out)

    return callee, pair, with_literal_none, with_chosen


def test_none_or_gives_none_or_the_built_value_on_the_cpu_and_in_python():
    callee, pair, _, with_chosen = _fresh_functions()
    out = np.zeros(1)
    with_chosen(None, np.array([2.0]), out)
    assert out[0] == -1.0
    with_chosen((3.0,), np.array([2.0]), out)
    assert out[0] == 5.0
    # the plain Python function (the CUDA simulator runs kernels as Python) chooses the same
    assert pair(None, np.array([2.0])) is None
    assert pair((3.0,), 4.0) == (3.0, 4.0)


def test_a_kernel_compiled_for_a_bundle_compiles_its_callee_for_the_bundle_alone():
    callee, _, with_literal_none, with_chosen = _fresh_functions()
    out = np.zeros(1)
    with_literal_none((3.0,), np.array([2.0]), out)
    assert out[0] == 5.0
    assert len(callee.signatures) == 2  # the branch that cannot run compiled the callee for None as well
    callee, _, _, with_chosen = _fresh_functions()
    with_chosen((3.0,), np.array([2.0]), out)
    assert out[0] == 5.0
    assert len(callee.signatures) == 1
    assert "none" not in str(callee.signatures[0]).lower()
