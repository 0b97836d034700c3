"""Residual policies: a learnt correction added to a scripted controller's natural-curvature rate.

PPO trained from scratch must first discover how to close on the specimen at all, and the reactive controller
already does that well; a residual policy starts where the controller is and learns only what to change. The
policy's action r in [−1, 1] per finger adds ``rate`` × r [1/s] to the rate the controller asks for, and the sum
goes to the env through the task's action map (:meth:`GraspTask.action_for_rate`, clipped to the fastest rate),
so the env, its reward and its closing reflexes see one ordinary action, and a residual policy is compared with its
controller on the same task.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from agents.scripted import gust_may_blow, gust_window
from soft_gripper_env.env import observation_slices
from soft_gripper_env.grasp_task import GraspTask
from soft_gripper_env.physics import check_range

RESIDUAL_BASES = ("reactive", "reactive_tuned", "reactive_graded")
"""The controllers a residual policy may correct (``agents.evaluate``'s names)."""


class ResidualAction:
    """The env action of ``base``'s rate plus ``rate`` × the residual [1/s], per finger, through ``task``'s action
    map. ``base`` acts on raw observations (one or a batch), as the scripted controllers do.

    Three optional guards limit what the correction may do, the same in training and in use (the policy is the
    correction and its guards): with ``gust_hold``, it may not open a finger (a positive rate) while a gust may blow
    (:func:`~agents.scripted.gust_window`), so that it cannot hold more loosely than its controller through the
    gust; with ``press_limit`` (a fraction of the specimen's fragility limit, in (0, 1]), it may not close a finger
    (a negative rate) that presses above that fraction of the limit; with ``press_taper`` (a fraction in (0, 1] too),
    its closing rate on a finger is scaled by the margin left to that fraction of the limit, 1 − force / (fraction ×
    limit), clipped to [0, 1], so that it brakes as the force rises instead of at a threshold it may overshoot within
    a control interval; with ``close_untouched``, it may not open a finger that does not touch the specimen (the
    observation's ``touching`` part), so that it cannot hold back a finger the controller closes onto the specimen.
    The observation must hold the sensors' parts (finger forces, touching, fragility limit, episode fraction) for
    any of them."""

    def __init__(self, task: GraspTask, base: Callable[[np.ndarray], np.ndarray], rate: float,
                 gust_hold: bool = False, press_limit: float | None = None, close_untouched: bool = False,
                 press_taper: float | None = None) -> None:
        check_range("ResidualAction", "rate", rate, "1/s", 0.0, task.max_curvature_rate, high_inclusive=True)
        for name, fraction in (("press_limit", press_limit), ("press_taper", press_taper)):
            if fraction is not None:
                check_range("ResidualAction", name, fraction, "(dimensionless)", 0.0, 1.0, high_inclusive=True)
        self.task, self.base, self.rate = task, base, rate
        self.gust_hold, self.press_limit, self.close_untouched = bool(gust_hold), press_limit, bool(close_untouched)
        self.press_taper = press_taper
        self._guards = self.gust_hold or press_limit is not None or self.close_untouched or press_taper is not None
        if self._guards:
            layout = observation_slices(task)
            self._forces, self._limit = layout["finger_forces"], layout["fragile_force"]
            self._fraction, self._window = layout["episode_fraction"], gust_window(task)
            self._touching = layout["touching"]

    def __call__(self, observation: np.ndarray, residual: np.ndarray) -> np.ndarray:
        """The env action [−1, 1] for ``observation`` (raw) and the residual in [−1, 1] (clipped), same shapes."""
        base_rate = self.task.curvature_rate(np.asarray(self.base(observation), dtype=float))
        correction = self.rate * np.clip(np.asarray(residual, dtype=float), -1.0, 1.0)
        if self._guards:
            correction = self._guarded(np.asarray(observation, dtype=float), correction)
        return self.task.action_for_rate(base_rate + correction).astype(np.float32)

    def _guarded(self, observation: np.ndarray, correction: np.ndarray) -> np.ndarray:
        """``correction`` [1/s] with the guards applied, for raw observations of the same leading shape."""
        if self.gust_hold:
            gusty = gust_may_blow(self._window, observation[..., self._fraction])
            correction = np.where(gusty, np.minimum(correction, 0.0), correction)
        if self.press_limit is not None:
            pressing = observation[..., self._forces] > self.press_limit * observation[..., self._limit]
            correction = np.where(pressing, np.maximum(correction, 0.0), correction)
        if self.press_taper is not None:
            margin = 1.0 - observation[..., self._forces] / (self.press_taper * observation[..., self._limit])
            correction = np.where(correction < 0.0, correction * np.clip(margin, 0.0, 1.0), correction)
        if self.close_untouched:
            untouched = observation[..., self._touching] < 0.5
            correction = np.where(untouched, np.minimum(correction, 0.0), correction)
        return correction

    def settings(self) -> dict:
        """What a run's config.json records of the correction besides its controller (``residual``)."""
        return {"rate": self.rate, "gust_hold": self.gust_hold, "press_limit": self.press_limit,
                "close_untouched": self.close_untouched, "press_taper": self.press_taper}


class ResidualVecEnv(VecEnvWrapper):
    """An SB3 VecEnv whose actions are residuals (:class:`ResidualAction`) on the controller's: it keeps the raw
    observation of each env (after an autoreset, the next episode's first) for the controller's next action. Wrap
    it below VecNormalize, whose normalised observations the controller must not see."""

    def __init__(self, venv: VecEnv, combine: ResidualAction) -> None:
        super().__init__(venv)
        self.combine = combine
        self._observation: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        self._observation = self.venv.reset()
        return self._observation

    def step_async(self, actions: np.ndarray) -> None:
        if self._observation is None:
            raise RuntimeError("ResidualVecEnv.step_async before reset: the controller has no observation to act on")
        self.venv.step_async(self.combine(self._observation, actions))

    def step_wait(self):
        observation, reward, done, infos = self.venv.step_wait()
        self._observation = observation
        return observation, reward, done, infos


def residual_policy(residual: Callable[[np.ndarray], np.ndarray],
                    combine: ResidualAction) -> Callable[[np.ndarray], np.ndarray]:
    """The env's policy of a residual one (acting on raw observations, as :func:`agents.evaluate.ppo_policy`
    gives) and its controller: ``combine``'s action for each observation. Keeps ``residual``'s attributes (its
    observation size, its training task)."""

    def act(observation: np.ndarray) -> np.ndarray:
        return combine(observation, residual(observation))

    act.__dict__.update(residual.__dict__)
    act.residual = combine
    return act
