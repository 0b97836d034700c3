"""Evaluate a policy on SoftGripperUnderwater-v0 over fixed seeds: success rate, mean return, largest finger force,
and how the episodes ended.

    python -m agents.evaluate --policy ramp|reactive|ppo [--model-dir out/ppo] [--episodes 20] [--seed 1000]
        [--json FILE]

Every policy sees the same episodes (seeds seed, seed + 1, ...), so their numbers compare directly.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import soft_gripper_env
from agents.scripted import RampPolicy, ReactivePolicy
from soft_gripper_env.env import observation_slices
from soft_gripper_env.grasp_task import GraspTask

ENDINGS = ("success", "lost", "solver_failure", "not_all_touching", "off_grasp_point", "moving", "held_too_briefly")
"""How an episode can end, in the order :func:`episode_ending` tests them."""


def episode_ending(task: GraspTask, observation: np.ndarray, terminated: bool, info: dict) -> str:
    """Why an episode ended as it did, from its last observation and info: ``"success"``; ``"lost"`` (terminated:
    the object beyond ``lost_distance``); ``"solver_failure"``; or, at the time limit, the first condition of a
    hold that failed there: ``"not_all_touching"`` (a finger pressing less than ``contact_force``),
    ``"off_grasp_point"`` (farther than ``hold_distance``), ``"moving"`` (faster than ``rest_speed``), else
    ``"held_too_briefly"`` (held, but for less than ``success_duration``)."""
    if info["is_success"]:
        return "success"
    if terminated:
        return "lost"
    if info["solver_failure"]:
        return "solver_failure"
    if np.any(np.asarray(info["finger_forces_N"]) < task.contact_force):
        return "not_all_touching"
    layout = observation_slices(task)
    offset = np.asarray(observation[layout["object_position"]], dtype=float) - np.asarray(task.grasp_point)
    if np.linalg.norm(offset) > task.hold_distance:
        return "off_grasp_point"
    if np.linalg.norm(np.asarray(observation[layout["object_velocity"]], dtype=float)) > task.rest_speed:
        return "moving"
    return "held_too_briefly"


def evaluate(policy: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int = 1000,
             progress: bool = True, **settings) -> dict:
    """Runs ``episodes`` episodes with seeds seed, seed + 1, ...; returns the success rate, mean and standard
    deviation of the return, the mean episode length, the mean of each episode's largest finger force [N], how
    many episodes ended each way (:func:`episode_ending`), the wall time [s], and the per-episode outcomes, with the
    object's final position [m] (world frame, as observed)."""
    env = gym.make(soft_gripper_env.ENV_ID, **settings)
    task = env.unwrapped.task
    layout = observation_slices(task)
    successes, returns, lengths, forces, endings, positions = [], [], [], [], [], []
    start = time.perf_counter()
    for k in tqdm(range(episodes), desc="episodes", disable=not progress):
        obs, info = env.reset(seed=seed + k)
        total, largest, steps, done = 0.0, 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += reward
            largest = max(largest, float(np.max(info["finger_forces_N"])))
            steps += 1
            done = terminated or truncated
        successes.append(bool(info["is_success"]))
        endings.append(episode_ending(task, obs, terminated, info))
        returns.append(total)
        lengths.append(steps)
        forces.append(largest)
        positions.append([float(x) for x in obs[layout["object_position"]]])
    seconds = time.perf_counter() - start
    env.close()
    return {"episodes": episodes, "first_seed": seed, "success_rate": float(np.mean(successes)),
            "mean_return": float(np.mean(returns)), "std_return": float(np.std(returns)),
            "mean_length": float(np.mean(lengths)), "mean_largest_finger_force_N": float(np.mean(forces)),
            "endings": {name: endings.count(name) for name in ENDINGS},
            "seconds": seconds, "successes": successes, "returns": returns, "largest_finger_forces_N": forces,
            "episode_endings": endings, "final_object_positions": positions}


def load_ppo(model_dir: Path) -> Callable[[np.ndarray], np.ndarray]:
    """A trained PPO policy with its observation normalisation (both saved by agents/train_ppo.py)."""
    import pickle

    from stable_baselines3 import PPO

    model = PPO.load(model_dir / "ppo_model.zip", device="cpu")
    with open(model_dir / "vecnormalize.pkl", "rb") as f:
        normalize = pickle.load(f)
    normalize.training = False

    def act(observation: np.ndarray) -> np.ndarray:
        action, _ = model.predict(normalize.normalize_obs(observation[None]), deterministic=True)
        return action[0]

    return act


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", choices=("ramp", "reactive", "ppo"), required=True)
    parser.add_argument("--model-dir", type=Path, default=Path("out") / "ppo", help="where train_ppo.py saved")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes = {args.episodes} must be at least 1")
    task = GraspTask()
    policy = {"ramp": lambda: RampPolicy(task), "reactive": lambda: ReactivePolicy(task),
              "ppo": lambda: load_ppo(args.model_dir)}[args.policy]()
    result = evaluate(policy, args.episodes, args.seed)
    print(f"{args.policy}: success {result['success_rate']:.2f}, return {result['mean_return']:.2f} "
          f"± {result['std_return']:.2f}, largest finger force {result['mean_largest_finger_force_N']:.2f} N")
    print("endings: " + ", ".join(f"{name} {count}" for name, count in result["endings"].items() if count))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
