"""Record a video of one grasp episode under water: the paper's scripted ramp, the reactive controller, or the
shipped PPO policy.

    python -m examples.record_video --out out/video [--policy ramp|reactive|pretrained|pretrained_planar] [--seed 0]
        [--model 3d|planar] [--gif] [--frame-at 2.5]

Writes DIR/<policy>-episode-0.mp4 (moviepy, as Gymnasium's RecordVideo does); with ``--gif`` also a smaller GIF
(half size, every second frame) for a web page, and with ``--frame-at SECONDS`` a PNG of that moment of the episode.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import numpy as np
from PIL import Image
from tqdm import tqdm

import soft_gripper_env
from agents.evaluate import REFLEXES, SHIPPED, make_policy
from soft_gripper_env.grasp_task import GraspTask

POLICIES = ("ramp", "reactive", *SHIPPED)


def write_gif(frames: list[np.ndarray], path: Path, fps: float, every: int = 2, scale: float = 0.5) -> None:
    """Every ``every``-th frame at ``scale`` of its size, looping, at the episode's own pace."""
    images = [Image.fromarray(frame).resize((round(frame.shape[1] * scale), round(frame.shape[0] * scale)),
                                            Image.Resampling.LANCZOS) for frame in frames[::every]]
    images[0].save(path, save_all=True, append_images=images[1:], duration=round(1000 * every / fps), loop=0,
                   optimize=True)


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("out") / "video", help="output folder")
    parser.add_argument("--policy", choices=POLICIES, default="ramp")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--model", choices=("planar", "3d"), default="3d")
    parser.add_argument("--gif", action="store_true", help="also write a GIF, half size, every second frame")
    parser.add_argument("--frame-at", type=float, default=None, metavar="SECONDS",
                        help="also write a PNG of the frame at this time of the episode [s]")
    args = parser.parse_args(argv)
    task = GraspTask(model=args.model)
    if args.frame_at is not None and not 0.0 <= args.frame_at <= task.episode_duration:
        parser.error(f"--frame-at {args.frame_at} is outside the episode, [0, {task.episode_duration}] s")
    policy = make_policy(args.policy, task, args.seed)
    trained = getattr(policy, "trained_task", {})  # a trained policy acts with its own observation and reflexes
    settings = {"observation": getattr(policy, "observation", task.observation),
                **{name: trained.get(name) for name in REFLEXES}}
    env = gym.make(soft_gripper_env.ENV_ID, render_mode="rgb_array", model=args.model, **settings)
    obs, info = env.reset(seed=args.seed)
    frames, total, done = [env.render()], 0.0, False
    with tqdm(total=env.spec.max_episode_steps, desc=f"{args.policy} episode", unit="step") as bar:
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            frames.append(env.render())
            total += reward
            done = terminated or truncated
            bar.update()
    fps = env.metadata["render_fps"]
    env.close()
    from moviepy.video.io.ImageSequenceClip import ImageSequenceClip

    args.out.mkdir(parents=True, exist_ok=True)
    video = args.out / f"{args.policy}-episode-0.mp4"
    ImageSequenceClip(frames, fps=fps).write_videofile(str(video), logger=None)
    written = [video]
    if args.gif:
        written.append(args.out / f"{args.policy}-episode-0.gif")
        write_gif(frames, written[-1], fps)
    if args.frame_at is not None:
        written.append(args.out / f"{args.policy}-episode-0-{args.frame_at:g}s.png")
        Image.fromarray(frames[min(len(frames) - 1, round(args.frame_at / task.control_dt))]).save(written[-1])
    print(f"return {total:.2f}, success {info['is_success']}, wrote {', '.join(map(str, written))}")
    return video


if __name__ == "__main__":
    main()
