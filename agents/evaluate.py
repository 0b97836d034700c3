"""Evaluate a policy on SoftGripperUnderwater-v0 over fixed seeds: success rate, mean return, largest finger force.

    python agents/evaluate.py --policy ramp|reactive|ppo [--model-dir out/ppo] [--episodes 20] [--seed 1000]
        [--json FILE]

Every policy sees the same episodes (seeds seed, seed + 1, ...), so their numbers compare directly.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import soft_gripper_env  # noqa: E402
from agents.scripted import RampPolicy, ReactivePolicy  # noqa: E402
from soft_gripper_env.grasp_task import GraspTask  # noqa: E402


def evaluate(policy: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int = 1000,
             progress: bool = True, **settings) -> dict:
    """Runs ``episodes`` episodes with seeds seed, seed + 1, ...; returns the success rate, mean and standard
    deviation of the return, the mean episode length, the mean of each episode's largest finger force [N], and
    the per-episode outcomes."""
    env = gym.make(soft_gripper_env.ENV_ID, **settings)
    successes, returns, lengths, forces = [], [], [], []
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
        returns.append(total)
        lengths.append(steps)
        forces.append(largest)
    env.close()
    return {"episodes": episodes, "first_seed": seed, "success_rate": float(np.mean(successes)),
            "mean_return": float(np.mean(returns)), "std_return": float(np.std(returns)),
            "mean_length": float(np.mean(lengths)), "mean_largest_finger_force_N": float(np.mean(forces)),
            "successes": successes, "returns": returns}


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
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
