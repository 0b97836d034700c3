"""The SB3 adapter, the evaluation script and the PPO training script."""

import json
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import soft_gripper_env
from agents.sb3_vec_env import SoftGripperSB3VecEnv
from agents.scripted import RampPolicy
from soft_gripper_env.env import observation_bounds
from soft_gripper_env.grasp_task import GraspTask

ROOT = Path(__file__).resolve().parents[2]


def test_sb3_vec_env_autoresets_in_the_same_step_and_reports_truncation():
    env = SoftGripperSB3VecEnv(num_envs=2, seed=3, max_episode_steps=3)
    obs = env.reset()
    assert obs.shape == (2, observation_bounds(GraspTask())[0].size) and obs.dtype == np.float32
    for _ in range(3):
        env.step_async(np.full((2, 3), -0.3, dtype=np.float32))
        obs, reward, done, infos = env.step_wait()
    assert done.all() and reward.dtype == np.float32
    for info in infos:
        assert info["TimeLimit.truncated"] and "terminal_observation" in info
        assert not np.array_equal(info["terminal_observation"], obs[0])  # the new episode's first observation
    np.testing.assert_array_equal(obs[:, -9:-6], 0.0)  # κ̄ back to zero after the same-step reset
    assert env.get_attr("render_mode") == [None, None] and env.env_is_wrapped(object) == [False, False]


@pytest.mark.parametrize("num_threads", [1, 2])
def test_sb3_vec_env_seeds_like_single_envs(num_threads):
    env = SoftGripperSB3VecEnv(num_envs=2, seed=7, num_threads=num_threads)
    obs = env.reset()
    single, _ = gym.make(soft_gripper_env.ENV_ID).reset(seed=8)
    np.testing.assert_allclose(obs[1], single, atol=1e-7)


@pytest.mark.slow
def test_sb3_subproc_vec_env_runs_the_single_env():
    """SB3's SubprocVecEnv (one process per env) steps the registered env like its DummyVecEnv."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    make = [lambda: gym.make(soft_gripper_env.ENV_ID, model="planar", max_episode_steps=3) for _ in range(2)]
    actions = np.random.default_rng(3).uniform(-1, 1, (4, 2, 3)).astype(np.float32)
    results = []
    for vector in (SubprocVecEnv(make), DummyVecEnv(make)):
        vector.seed(9)
        outputs = [vector.reset()]
        for action in actions:
            obs, reward, done, infos = vector.step(action)
            outputs += [obs, reward, done, np.array([info.get("is_success", False) for info in infos])]
        vector.close()
        results.append(outputs)
    for a, b in zip(*results, strict=True):  # DummyVecEnv keeps rewards in float32, SubprocVecEnv in float64
        np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=1e-6, atol=0)
    assert results[0][11].all()  # done at the third step (episodes of 3), so the autoresets were compared too


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
    from agents.evaluate import ENDINGS, evaluate

    result = evaluate(RampPolicy(), episodes=1, seed=1000, progress=False, max_episode_steps=5)
    assert result["episodes"] == 1 and result["mean_length"] == 5
    assert result["mean_return"] == pytest.approx(result["returns"][0])
    # after 0.25 s the ramp's fingers have not reached the sphere
    assert result["episode_endings"] == ["not_all_touching"]
    assert set(result["endings"]) == set(ENDINGS) and sum(result["endings"].values()) == 1


def test_episode_ending_names_the_first_failed_condition():
    from agents.evaluate import episode_ending
    from soft_gripper_env.env import observation_slices
    from soft_gripper_env.grasp_task import GraspTask

    task = GraspTask()
    layout = observation_slices(task)
    observation = np.zeros(layout["object_velocity"].stop, dtype=np.float32)
    observation[layout["object_position"]] = task.grasp_point
    held = {"is_success": False, "solver_failure": False, "finger_forces_N": np.full(3, 2 * task.contact_force)}

    def ending(terminated=False, offset=0.0, speed=0.0, **info):
        obs = observation.copy()
        obs[layout["object_position"].start] += offset
        obs[layout["object_velocity"].start] = speed
        return episode_ending(task, obs, terminated, {**held, **info})

    assert ending() == "held_too_briefly"
    assert ending(is_success=True, terminated=True) == "success"
    assert ending(terminated=True, solver_failure=True) == "lost"
    assert ending(solver_failure=True) == "solver_failure"
    assert ending(finger_forces_N=np.array([1.0, 0.5 * task.contact_force, 1.0])) == "not_all_touching"
    assert ending(offset=1.5 * task.hold_distance, speed=2 * task.rest_speed) == "off_grasp_point"
    assert ending(offset=0.5 * task.hold_distance, speed=2 * task.rest_speed) == "moving"


def run_script(*args, timeout=600):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.slow
def test_record_video_example_writes_an_mp4(tmp_path):
    out = run_script("-m", "examples.record_ramp_video", "--out", str(tmp_path), "--seed", "3")
    assert out.returncode == 0, out.stderr
    video = tmp_path / "ramp-episode-0.mp4"
    assert video.exists() and video.stat().st_size > 10_000
    assert "success" in out.stdout


@pytest.mark.slow
def test_env_speed_benchmark_writes_json_and_plot(tmp_path):
    """The issue's JSON keys are there, every ratio is its figure over the anchor's, and the plot is written."""
    out = run_script("-m", "benchmarks.env_speed", "--json", str(tmp_path / "speed.json"), "--plot",
                     str(tmp_path / "speed.png"), "--quick", "--steps", "2")
    assert out.returncode == 0, out.stderr
    results = json.loads((tmp_path / "speed.json").read_text())
    required = {"ant_v5_steps_per_s", "single_steps_per_s", "vec64_steps_per_s", "single_3d_steps_per_s",
                "vec64_3d_steps_per_s", "vec64_two_threads_steps_per_s"}
    assert required <= set(results) and all(results[key] > 0 for key in required)
    ant = results["ant_v5_steps_per_s"]
    for key in required - {"ant_v5_steps_per_s"}:
        ratio = results["ratios_to_ant_v5"][key.removesuffix("_steps_per_s") + "_vs_ant_v5"]
        assert ratio == pytest.approx(results[key] / ant)
    assert {"paper_scene_planar_ms", "paper_scene_3d_ms", "batched_planar_us_per_gripper_step"} <= set(
        results["goals"])
    assert (tmp_path / "speed.png").stat().st_size > 5000


def test_scripts_reject_bad_arguments(tmp_path):
    out = run_script("-m", "agents.evaluate", "--policy", "ramp", "--episodes", "0")
    assert out.returncode == 2 and "--episodes = 0 must be at least 1" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path), "--timesteps", "0")
    assert out.returncode == 2 and "--timesteps = 0 must be at least 1" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path), "--num-envs", "2", "--num-threads", "3")
    assert out.returncode == 2 and "--num-threads = 3 must be at most --num-envs = 2" in out.stderr
