"""Stable-Baselines3's VecEnv over the batched Gymnasium vector env: SB3 does not use Gymnasium vector envs, and
subprocess vectorisation gains nothing here, since one process steps all episodes in one simulator."""

from __future__ import annotations

from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from soft_gripper_env.env import DEFAULT_MAX_EPISODE_STEPS, SoftGripperUnderwaterVectorEnv


class SoftGripperSB3VecEnv(VecEnv):
    """``num_envs`` episodes of SoftGripperUnderwater-v0 for SB3 (PPO, A2C, ...). Same-step autoreset: a finished
    episode's last observation is in ``info["terminal_observation"]``, ``info["TimeLimit.truncated"]`` marks a
    truncation, and ``info["is_success"]`` is there for ``VecMonitor(info_keywords=("is_success",))``."""

    def __init__(self, num_envs: int = 16, seed: int | None = None,
                 max_episode_steps: int = DEFAULT_MAX_EPISODE_STEPS, **settings) -> None:
        self.venv = SoftGripperUnderwaterVectorEnv(num_envs, max_episode_steps=max_episode_steps, **settings)
        self.render_mode = None
        super().__init__(num_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._first_seed = seed
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        seeds = self._seeds if any(s is not None for s in self._seeds) else self._first_seed
        self._first_seed = None
        obs, _ = self.venv.reset(seed=seeds)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, reward, terminated, truncated, infos = self.venv.step(self._actions)
        done = terminated | truncated
        per_env = [{"is_success": bool(infos["is_success"][i]), "solver_failure": bool(infos["solver_failure"][i]),
                    "TimeLimit.truncated": bool(truncated[i] and not terminated[i])} for i in range(self.num_envs)]
        if done.any():
            for i in np.nonzero(done)[0]:
                per_env[i]["terminal_observation"] = obs[i]
            obs = self.venv.reset_done()
        return obs, reward.astype(np.float32), done, per_env

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        return [getattr(self, attr_name) if attr_name == "render_mode" else getattr(self.venv, attr_name)
                for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        return [getattr(self.venv, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
