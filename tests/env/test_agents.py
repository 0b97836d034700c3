"""The SB3 adapter, the evaluation script and the PPO training script."""

import json

import numpy as np
import pytest

from agents.sb3_vec_env import SoftGripperSB3VecEnv
from agents.scripted import RampPolicy


def test_sb3_vec_env_autoresets_in_the_same_step_and_reports_truncation():
    env = SoftGripperSB3VecEnv(num_envs=2, seed=3, max_episode_steps=3)
    obs = env.reset()
    assert obs.shape == (2, 309) and obs.dtype == np.float32
    for _ in range(3):
        env.step_async(np.full((2, 3), -0.3, dtype=np.float32))
        obs, reward, done, infos = env.step_wait()
    assert done.all() and reward.dtype == np.float32
    for info in infos:
        assert info["TimeLimit.truncated"] and "terminal_observation" in info
        assert not np.array_equal(info["terminal_observation"], obs[0])  # the new episode's first observation
    np.testing.assert_array_equal(obs[:, -9:-6], 0.0)  # κ̄ back to zero after the same-step reset
    assert env.get_attr("render_mode") == [None, None] and env.env_is_wrapped(object) == [False, False]


def test_sb3_vec_env_seeds_like_single_envs():
    import gymnasium as gym

    import soft_gripper_env

    env = SoftGripperSB3VecEnv(num_envs=2, seed=7)
    obs = env.reset()
    single, _ = gym.make(soft_gripper_env.ENV_ID).reset(seed=8)
    np.testing.assert_allclose(obs[1], single, atol=1e-7)


@pytest.mark.slow
def test_ppo_trains_and_is_evaluated_against_the_baselines(tmp_path):
    from agents import train_ppo

    results = train_ppo.main(["--out", str(tmp_path), "--timesteps", "256", "--num-envs", "4",
                              "--eval-episodes", "1"])
    saved = json.loads((tmp_path / "evaluation.json").read_text())
    for name in ("ppo", "ramp", "reactive"):
        assert 0.0 <= saved[name]["success_rate"] <= 1.0 and np.isfinite(saved[name]["mean_return"])
    assert results["ppo"]["episodes"] == 1
    assert (tmp_path / "vecnormalize.pkl").exists() and (tmp_path / "learning_curve.png").stat().st_size > 5000


def test_evaluate_reports_the_ramp(tmp_path):
    from agents.evaluate import evaluate

    result = evaluate(RampPolicy(), episodes=1, seed=1000, progress=False, max_episode_steps=5)
    assert result["episodes"] == 1 and result["mean_length"] == 5
    assert result["mean_return"] == pytest.approx(result["returns"][0])
