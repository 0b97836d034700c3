"""Scripted policies: the paper's linear κ̄(t) ramp, and a reactive controller that closes each finger quickly until
it touches and then squeezes by a set curvature.

Both act on observations of :class:`soft_gripper_env.env.SoftGripperUnderwaterEnv` and return actions in [−1, 1].
"""

from __future__ import annotations

import numpy as np

from soft_gripper_env.env import observation_slices
from soft_gripper_env.grasp_task import GraspTask
from soft_gripper_env.physics import check_range

PAPER_RATE = -0.15
"""The paper's natural-curvature rate [1/s]: κ̄(t) = −0.15·t."""
APPROACH_RATE = -0.3
"""The reactive controller's closing rate before a finger touches [1/s], twice the paper's: a sphere 1–3 % lighter
or heavier than the water drifts off while the fingers close, so the sooner they touch the better."""


class RampPolicy:
    """The paper's actuation: every finger's κ̄ grows at a constant ``rate`` [1/s], whatever it observes."""

    def __init__(self, task: GraspTask | None = None, rate: float = PAPER_RATE) -> None:
        task = task or GraspTask()
        if abs(rate) > task.max_curvature_rate:
            raise ValueError(f"rate = {rate!r} 1/s is outside the allowed range [−{task.max_curvature_rate:g}, "
                             f"{task.max_curvature_rate:g}] 1/s of the task's actions")
        self.action = np.full(task.gripper.n_fingers, rate / task.max_curvature_rate, dtype=np.float32)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.action.copy()


class ReactivePolicy:
    """Closing with contact feedback, finger by finger. Each finger closes at ``approach_rate`` [1/s] until it
    touches the object (its normal reactions sum to at least ``touch_force`` [N]), and then waits. Once all of them
    touch, the object is caged: each finger presses on to ``squeeze`` (dimensionless) below the natural curvature at
    which it touched, at no more than ``press_rate`` [1/s], and holds there.

    The squeeze is set in curvature, not in force: stick contact makes a finger's force jump from one control
    interval to the next, and a controller chasing it loosens and tightens the grip in turn, while a fixed
    curvature past the touch holds a steady, moderate preload (a few newtons at most, against the ramp's ten or
    more). The policy remembers the touch curvatures of the episode it is acting in; an observation with κ̄ = 0 on
    every finger (every episode starts straight) begins a new one. It acts on one observation (obs_dim,) or a batch
    (B, obs_dim), as from a vector of environments; a batch's row k is always episode slot k.
    """

    def __init__(self, task: GraspTask | None = None, touch_force: float = 0.01, squeeze: float = 0.015,
                 press_rate: float = 0.05, approach_rate: float = APPROACH_RATE) -> None:
        self.task = task or GraspTask()
        check_range("ReactivePolicy", "approach_rate", approach_rate, "1/s", -self.task.max_curvature_rate, 0.0,
                    low_inclusive=True)
        check_range("ReactivePolicy", "touch_force", touch_force, "N", 0.0, 100.0)
        check_range("ReactivePolicy", "squeeze", squeeze, "(dimensionless)", 0.0, -self.task.curvature_range[0],
                    low_inclusive=True)
        check_range("ReactivePolicy", "press_rate", press_rate, "1/s", 0.0, self.task.max_curvature_rate)
        self.touch_force, self.squeeze, self.press_rate = touch_force, squeeze, press_rate
        layout = observation_slices(self.task)
        self._forces, self._curvature = layout["normal_forces"], layout["natural_curvature"]
        self._approach_action = approach_rate / self.task.max_curvature_rate
        self._n_fingers = self.task.gripper.n_fingers
        self._touched_at = np.full((0, self._n_fingers), np.nan)  # κ̄ at which each finger first touched; NaN: not yet

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        observation = np.asarray(observation)
        batch = observation.reshape(-1, observation.shape[-1])
        force = batch[:, self._forces].reshape(len(batch), self._n_fingers, -1).sum(axis=-1)
        curvature = batch[:, self._curvature].astype(float)
        if len(self._touched_at) != len(batch):
            self._touched_at = np.full((len(batch), self._n_fingers), np.nan)
        self._touched_at[(curvature == 0.0).all(axis=1)] = np.nan  # a new episode
        touching = np.isnan(self._touched_at) & (force >= self.touch_force)
        self._touched_at[touching] = curvature[touching]
        touched = ~np.isnan(self._touched_at)
        caged = touched.all(axis=1, keepdims=True)
        # the action that reaches the target within one control interval, at most the press rate
        per_action = self.task.max_curvature_rate * self.task.control_dt
        limit = self.press_rate / self.task.max_curvature_rate
        press = np.clip((self._touched_at - self.squeeze - curvature) / per_action, -limit, limit)
        action = np.where(~touched, self._approach_action, np.where(caged, press, 0.0))
        return action.astype(np.float32).reshape(observation.shape[:-1] + (self._n_fingers,))
