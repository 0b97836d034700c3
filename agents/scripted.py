"""Scripted policies: the paper's linear κ̄(t) ramp, and a reactive controller that closes each finger until it
touches and then regulates its force to a fraction of the specimen's fragility limit.

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


class ConstantPolicy:
    """The same ``action`` in [−1, 1] on every finger at every step: the open-loop check that the task needs
    feedback."""

    def __init__(self, task: GraspTask | None = None, action: float = 0.0) -> None:
        task = task or GraspTask()
        check_range("ConstantPolicy", "action", action, "(dimensionless)", -1.0, 1.0, low_inclusive=True,
                    high_inclusive=True)
        self.action = np.full(task.gripper.n_fingers, action, dtype=np.float32)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return np.broadcast_to(self.action, np.shape(observation)[:-1] + self.action.shape).copy()


class RampPolicy(ConstantPolicy):
    """The paper's actuation: every finger's κ̄ grows at a constant ``rate`` [1/s], whatever it observes."""

    def __init__(self, task: GraspTask | None = None, rate: float = PAPER_RATE) -> None:
        task = task or GraspTask()
        if abs(rate) > task.max_curvature_rate:
            raise ValueError(f"rate = {rate!r} 1/s is outside the allowed range [−{task.max_curvature_rate:g}, "
                             f"{task.max_curvature_rate:g}] 1/s of the task's actions")
        super().__init__(task, float(task.action_for_rate(rate)))


class RandomPolicy:
    """Actions drawn uniformly from [−1, 1] on every finger at every step, by a generator seeded with ``seed``."""

    def __init__(self, task: GraspTask | None = None, seed: int | None = None) -> None:
        self.n_fingers = (task or GraspTask()).gripper.n_fingers
        self.rng = np.random.default_rng(seed)

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        return self.rng.uniform(-1.0, 1.0, np.shape(observation)[:-1] + (self.n_fingers,)).astype(np.float32)


TUNED_3D_GAINS = {"grip": 0.3, "gust_grip": 0.3, "gain": 0.1}
"""The reactive controller's gains tuned in the 3-D model with four friction passes and the PPO policies' closing
reflexes, on tuning seeds 5000–5199 only: chosen at Δt 2.5 ms from 16 settings of ``grip``, ``gust_grip`` and
``gain`` (docs/notes/ppo_experiments.md), and chosen again at today's 1.25 ms from six (``python -m
agents.tune_controller``, docs/training.md): success 0.900 at a mean peak force of 1.69 N there. ``agents.evaluate
--policy reactive_tuned`` runs it: the fair baseline for a policy trained in 3-D."""

GRADED_3D_GAINS = {"grip": 0.2, "gust_grip": 0.2, "gain": 0.1, "touch_force": 0.1}
"""The reactive controller with a graded touch (``touch_force`` [N]), its settings chosen in the 3-D model with the
PPO policies' closing reflexes, on tuning seeds 5000–5199 only, as the most successful whose mean peak force is
below the on–off controller's (:data:`TUNED_3D_GAINS`): at Δt 2.5 ms from seven settings of ``touch_force``, ``grip``
and ``gust_grip`` (docs/notes/ppo_experiments.md), and again at today's 1.25 ms from four of ``grip`` and
``gust_grip`` (docs/training.md): success 0.910 at 1.68 N there, against the on–off controller's 0.900 at 1.69 N.
``agents.evaluate --policy reactive_graded`` runs it: the strongest scripted baseline in 3-D."""


def gust_window(task: GraspTask) -> tuple[float, float]:
    """The episode fractions in which a gust may blow (dimensionless): from a little (0.05) before the task's
    earliest gust start to its latest gust's end, read by a controller from the observation's episode fraction."""
    return (task.gust_start[0] / task.episode_duration - 0.05,
            (task.gust_start[1] + task.gust_duration) / task.episode_duration)


def gust_may_blow(window: tuple[float, float], fraction: np.ndarray) -> np.ndarray:
    """Where the episode ``fraction`` lies within ``window`` (:func:`gust_window`), elementwise."""
    return (fraction >= window[0]) & (fraction <= window[1])


class ReactivePolicy:
    """Closing with force feedback, finger by finger, to a grip that respects the specimen's fragility limit.

    - **Approach.** A finger that does not touch closes at ``approach_rate`` [1/s], slowing within ``slow_gap``
      [m] of the specimen in proportion to its gap, to no less than ``slowest`` times that rate: a fast touch
      presses harder than a slow one. Within 1 cm: slowing from 2 cm lost a sinking specimen more often (3-D at
      Δt 2.5 ms, tuning seeds 5000–5199: 0.77 success against 0.82, at the same mean peak force, 1.99 against
      1.98 N).
    - **Cage.** A finger that touches waits for the others, backing off only if it presses above its target.
    - **Grip.** Once every finger touches, each regulates its force F to a target of ``grip`` times the specimen's
      fragility limit F_max (observed), ``gust_grip`` times it while a gust may blow (the task's window of gust
      times, read from the episode fraction). Its curvature rate is ``gain`` × ``max_curvature_rate`` ×
      (F − target)/target [1/s], at most ``press_rate`` either way: a grip's force follows κ̄ steeply.
    - A finger that loses its touch closes again.
    - **Touch.** With ``touch_force`` None, a finger touches when the observation's touch flag is set (its
      sustained force at least the task's ``contact_force``), and the controller switches between the three
      behaviours above. With a ``touch_force`` [N], a finger's touch is a weight that rises linearly with its
      observed force (the mean over the last control interval) from 0 at no force to 1 at ``touch_force``: the
      approach is scaled by one minus the weight, the wait and the grip by the weight, and "every finger touches"
      is the smallest weight, so the action is continuous in the observation (no interval of full approach or
      none decided by a threshold).

    The policy keeps no state: it acts on one observation (obs_dim,) or a batch (B, obs_dim), as from a vector of
    envs.
    """

    def __init__(self, task: GraspTask | None = None, grip: float = 0.3, gust_grip: float = 0.4, gain: float = 0.2,
                 press_rate: float = 0.02, approach_rate: float = APPROACH_RATE, slow_gap: float = 0.01,
                 slowest: float = 0.2, touch_force: float | None = None) -> None:
        self.task = task or GraspTask()
        check_range("ReactivePolicy", "approach_rate", approach_rate, "1/s", -self.task.max_curvature_rate, 0.0,
                    low_inclusive=True)
        check_range("ReactivePolicy", "grip", grip, "(dimensionless)", 0.0, 1.0)
        check_range("ReactivePolicy", "gain", gain, "(dimensionless)", 0.0, 100.0)
        check_range("ReactivePolicy", "press_rate", press_rate, "1/s", 0.0, self.task.max_curvature_rate,
                    high_inclusive=True)
        check_range("ReactivePolicy", "slow_gap", slow_gap, "m", 0.0, 1.0, low_inclusive=True)
        check_range("ReactivePolicy", "slowest", slowest, "(dimensionless)", 0.0, 1.0, high_inclusive=True)
        check_range("ReactivePolicy", "gust_grip", gust_grip, "(dimensionless)", 0.0, 1.0)
        if touch_force is not None:
            check_range("ReactivePolicy", "touch_force", touch_force, "N", 0.0, 100.0, high_inclusive=True)
        self.touch_force = touch_force
        self.grip, self.gust_grip, self.gain, self.slow_gap, self.slowest = grip, gust_grip, gain, slow_gap, slowest
        self._gust_window = gust_window(self.task)
        self._press, self._approach = press_rate, approach_rate
        layout = observation_slices(self.task)
        self._forces, self._touching, self._limit = layout["finger_forces"], layout["touching"], layout["fragile_force"]
        self._gaps, self._fraction = layout["finger_gaps"], layout["episode_fraction"]

    def settings(self) -> dict:
        """Every setting of the constructor but the task, as keyword arguments that build this controller again:
        what a correction trained on it records (``agents.train_ppo --residual-to``, key ``base_settings``)."""
        return {"grip": self.grip, "gust_grip": self.gust_grip, "gain": self.gain, "press_rate": self._press,
                "approach_rate": self._approach, "slow_gap": self.slow_gap, "slowest": self.slowest,
                "touch_force": self.touch_force}

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        observation = np.asarray(observation)
        batch = observation.reshape(-1, observation.shape[-1]).astype(float)
        force, fraction = batch[:, self._forces], batch[:, self._fraction]
        if self.touch_force is None:
            touch = (batch[:, self._touching] > 0.5).astype(float)
        else:
            touch = np.clip(force / self.touch_force, 0.0, 1.0)
        gusty = gust_may_blow(self._gust_window, fraction)
        target = np.maximum(np.where(gusty, self.gust_grip, self.grip) * batch[:, self._limit], 1e-9)  # [N]
        regulate = np.clip(-self.gain * self.task.max_curvature_rate * (target - force) / target, -self._press,
                           self._press)  # [1/s]
        waiting = np.maximum(regulate, 0.0)  # a touching finger only backs off while the others close
        caged = touch.min(axis=1, keepdims=True)
        near = np.clip(batch[:, self._gaps] / self.slow_gap, self.slowest, 1.0) if self.slow_gap > 0 else 1.0
        # with a 0/1 touch this picks one of the three rates exactly, as a switch would
        rate = (1.0 - touch) * self._approach * near + touch * (caged * regulate + (1.0 - caged) * waiting)
        shape = observation.shape[:-1] + (self.task.gripper.n_fingers,)
        return self.task.action_for_rate(rate).astype(np.float32).reshape(shape)
