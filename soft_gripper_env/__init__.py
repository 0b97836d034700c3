"""soft-gripper-env: soft robotic grippers under water, simulated with discrete elastic rods.

The physics core lives in :mod:`soft_gripper_env.physics` and needs only NumPy, SciPy and Numba. Importing this
package registers the Gymnasium environment ``SoftGripperUnderwater-v0`` when Gymnasium is installed (the ``rl``
extra); ``gym.make("soft_gripper_env:SoftGripperUnderwater-v0")`` imports it for you.
"""

__version__ = "0.1.0"

ENV_ID = "SoftGripperUnderwater-v0"


def _register() -> None:
    try:
        import gymnasium
    except ImportError:  # the core runs without the RL stack
        return
    from .env import DEFAULT_MAX_EPISODE_STEPS

    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="soft_gripper_env.env:SoftGripperUnderwaterEnv",
                           vector_entry_point="soft_gripper_env.env:SoftGripperUnderwaterVectorEnv",
                           max_episode_steps=DEFAULT_MAX_EPISODE_STEPS)


_register()
