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
    """The paper's ramp with contact-force feedback. All fingers close together at the paper's rate until every
    finger presses at least ``touch_force`` [N] (the object is caged), or one presses ``force_band[0]``; they
    hold κ̄ from there, and open at ``release`` (an action) while a finger presses more than ``force_band[1]``.
    So a delicate object is held near the task's fragility threshold, where the ramp keeps squeezing."""

    def __init__(self, task: GraspTask | None = None, touch_force: float = 0.05,
                 force_band: tuple[float, float] = (0.45, 0.6), release: float = 0.3) -> None:
        self.task = task or GraspTask()
        low, high = force_band
        if not 0.0 < low < high <= 100.0:
            raise ValueError(f"force_band = {force_band!r} N must satisfy 0 < low < high ≤ 100 N")
        if not 0.0 < touch_force <= low:
            raise ValueError(f"touch_force = {touch_force!r} N is outside the allowed range (0, {low:g}] N")
        self.touch_force, self.force_band, self.release = touch_force, (float(low), float(high)), release
        self._forces = observation_slices(self.task)["normal_forces"]
        self._paper_action = PAPER_RATE / self.task.max_curvature_rate

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        observation = np.asarray(observation)
        force = observation[..., self._forces].reshape(observation.shape[:-1] + (3, -1)).sum(axis=-1)
        closing = (force.min(axis=-1) < self.touch_force) & (force.max(axis=-1) < self.force_band[0])
        rate = np.where(closing, self._paper_action, np.where(force.max(axis=-1) > self.force_band[1],
                                                              self.release, 0.0))
        return np.repeat(np.asarray(rate, dtype=np.float32)[..., None], 3, axis=-1)
