"""Scripted policies: the paper's linear κ̄(t) ramp, and a reactive controller of each finger's contact force.

Both act on observations of :class:`soft_gripper_env.env.SoftGripperUnderwaterEnv` and return actions in [−1, 1].
"""

from __future__ import annotations

import numpy as np

from soft_gripper_env.env import observation_slices
from soft_gripper_env.grasp_task import GraspTask

PAPER_RATE = -0.15
"""The paper's natural-curvature rate [1/s]: κ̄(t) = −0.15·t."""


class RampPolicy:
    """The paper's actuation: every finger's κ̄ grows at a constant ``rate`` [1/s], whatever it observes."""

    def __init__(self, task: GraspTask | None = None, rate: float = PAPER_RATE) -> None:
        task = task or GraspTask()
        if abs(rate) > task.max_curvature_rate:
            raise ValueError(f"rate = {rate!r} 1/s is outside the allowed range [−{task.max_curvature_rate:g}, "
                             f"{task.max_curvature_rate:g}] 1/s of the task's actions")
        self.action = np.full(3, rate / task.max_curvature_rate, dtype=np.float32)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.action.copy()


class ReactivePolicy:
    """Closes all fingers together at full rate until the first one touches, then at a third of it until all three
    press, and from then holds their mean normal force near ``target_force`` [N] with a proportional law. The
    fingers move as one, so the object is caged rather than pushed from one side."""

    def __init__(self, task: GraspTask | None = None, target_force: float = 0.2, gain: float = 0.5) -> None:
        self.task = task or GraspTask()
        if not 0.0 < target_force <= 100.0:
            raise ValueError(f"target_force = {target_force!r} N is outside the allowed range (0, 100] N")
        self.target_force = target_force
        self.gain = gain
        self._forces = observation_slices(self.task)["normal_forces"]

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        observation = np.asarray(observation)
        force = observation[..., self._forces].reshape(observation.shape[:-1] + (3, -1)).sum(axis=-1)
        touching = force >= self.task.contact_force
        error = (self.target_force - force.mean(axis=-1)) / self.target_force
        rate = np.where(touching.all(axis=-1), np.clip(-self.gain * error, -1.0, 1.0),
                        np.where(touching.any(axis=-1), -1.0 / 3.0, -1.0))
        return np.repeat(np.asarray(rate, dtype=np.float32)[..., None], 3, axis=-1)
