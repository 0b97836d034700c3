"""What Coulomb friction costs against stick contact, side by side in one run: the environment's episodes under the
reactive controller on the same seeds, with the object's friction μ = 0.3 (the default) and μ = ∞ (every contact
sticks), planar and 3-D, one thread.

    python -m benchmarks.friction_cost [--episodes 20] [--rounds 3] [--json out/friction_cost.json]

The two settings are timed in alternating rounds and the best round counts, so that the machine's drift affects
their ratio least. Reported per setting: environment steps per second, Newton iterations per step, and the ratio
of friction's speed to stick's.
"""

from __future__ import annotations

import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402

import soft_gripper_env  # noqa: E402
from agents.scripted import ReactivePolicy  # noqa: E402
from soft_gripper_env.grasp_task import GraspTask  # noqa: E402

SETTINGS = {"friction 0.3": 0.3, "stick": math.inf}


def run_episodes(model: str, friction: float, episodes: int, seed: int) -> tuple[float, int, int]:
    """Wall time [s], environment steps and Newton iterations of ``episodes`` reactive episodes."""
    env = gym.make(soft_gripper_env.ENV_ID, model=model, object_friction=friction)
    task = GraspTask(model=model, object_friction=friction)
    steps = iterations = 0
    start = time.perf_counter()
    for k in range(episodes):
        policy = ReactivePolicy(task)
        obs, info = env.reset(seed=seed + k)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs))
            steps += 1
            iterations += int(info["newton_iterations"])
            done = terminated or truncated
    return time.perf_counter() - start, steps, iterations


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=7000)
    parser.add_argument("--json", type=Path, default=Path("out") / "friction_cost.json")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.rounds < 1:
        parser.error("--episodes and --rounds must be at least 1")
    results = {}
    for model in ("planar", "3d"):
        for friction in SETTINGS.values():
            run_episodes(model, friction, 1, args.seed)  # compile and warm up
        best = {name: (math.inf, 0, 0) for name in SETTINGS}
        for round_ in range(args.rounds):
            for name, friction in SETTINGS.items():
                print(f"{model}, {name}, round {round_ + 1}/{args.rounds} ...", flush=True)
                seconds, steps, iterations = run_episodes(model, friction, args.episodes, args.seed)
                if seconds < best[name][0]:
                    best[name] = (seconds, steps, iterations)
        for name, (seconds, steps, iterations) in best.items():
            results[f"{model}/{name}"] = {"steps_per_s": steps / seconds, "newton_iterations_per_step":
                                          iterations / steps, "steps": steps}
        results[f"{model}/friction_over_stick_speed"] = results[f"{model}/friction 0.3"]["steps_per_s"] / \
            results[f"{model}/stick"]["steps_per_s"]
    print("\n| model | setting | env steps/s | Newton iterations per env step |\n|---|---|---|---|")
    for model in ("planar", "3d"):
        for name in SETTINGS:
            row = results[f"{model}/{name}"]
            print(f"| {model} | {name} | {row['steps_per_s']:.0f} | {row['newton_iterations_per_step']:.1f} |")
        print(f"| {model} | friction / stick speed | {results[f'{model}/friction_over_stick_speed']:.2f}× | |")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2))
    print(f"wrote {args.json}")
    return results


if __name__ == "__main__":
    main()
