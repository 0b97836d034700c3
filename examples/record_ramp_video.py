"""Record a video of the paper's scripted ramp (or the reactive controller) grasping the sphere under water.

    python -m examples.record_ramp_video --out out/video [--policy ramp|reactive] [--seed 0] [--model planar|3d]

Uses Gymnasium's RecordVideo wrapper (moviepy) and writes DIR/<policy>-episode-0.mp4.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
from tqdm import tqdm

import soft_gripper_env
from agents.scripted import RampPolicy, ReactivePolicy
from soft_gripper_env.grasp_task import GraspTask


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out") / "video", help="output folder")
    parser.add_argument("--policy", choices=("ramp", "reactive"), default="ramp")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", choices=("planar", "3d"), default="3d")
    args = parser.parse_args(argv)
    env = gym.make(soft_gripper_env.ENV_ID, render_mode="rgb_array", model=args.model)
    env = gym.wrappers.RecordVideo(env, str(args.out), name_prefix=args.policy, episode_trigger=lambda _: True,
                                   disable_logger=True)
    task = GraspTask(model=args.model)
    policy = RampPolicy(task) if args.policy == "ramp" else ReactivePolicy(task)
    obs, _ = env.reset(seed=args.seed)
    total, done = 0.0, False
    with tqdm(total=env.spec.max_episode_steps, desc=f"{args.policy} episode", unit="step") as bar:
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            total += reward
            done = terminated or truncated
            bar.update()
    env.close()
    video = args.out / f"{args.policy}-episode-0.mp4"
    print(f"return {total:.2f}, success {info['is_success']}, wrote {video}")
    return video


if __name__ == "__main__":
    main()
