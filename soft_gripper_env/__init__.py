"""soft-gripper-env: soft robotic grippers under water, simulated with discrete elastic rods.

The physics core lives in :mod:`soft_gripper_env.physics` and needs only NumPy, SciPy and Numba.
"""

__version__ = "0.1.0"
