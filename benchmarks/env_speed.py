"""Environment steps per second on one core: one env from gym.make, and make_vec at several num_envs.

Each configuration resets with seed 0 and then takes random actions for a fixed simulated time (the default
scene in the planar model, which this benchmark has always timed: fingers in water, a free sphere, a current; 5
physics steps per action; the environment's default is now the 3-D model); episodes that end are
reset, by the TimeLimit wrapper's truncation for the single env and by autoreset for the vector. The best of
``--repeats`` runs counts. Goals (issue 5): ≥ 2,000 steps/s single, ≥ 20,000 env-steps/s batched.

    python -m benchmarks.env_speed [--json FILE] [--plot PNG] [--repeats N] [--steps K]
"""

from __future__ import annotations

import json
import time

import gymnasium as gym

import soft_gripper_env  # noqa: F401
from benchmarks._timing import parse_arguments, save_plot  # (sets one thread first)

VECTOR_SIZES = (1, 16, 64, 256)
MODEL = "planar"


def time_single(steps: int) -> float:
    env = gym.make(soft_gripper_env.ENV_ID, model=MODEL)
    env.action_space.seed(0)
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def time_vector(num_envs: int, steps: int) -> float:
    env = gym.make_vec(soft_gripper_env.ENV_ID, num_envs=num_envs, model=MODEL)
    env.action_space.seed(0)
    env.reset(seed=0)
    start = time.perf_counter()
    for _ in range(steps):
        env.step(env.action_space.sample())
    return steps * num_envs / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> dict:
    import argparse

    extra = argparse.ArgumentParser(add_help=False)
    extra.add_argument("--steps", type=int, default=40, help="control steps per timed run (default 40)")
    known, rest = extra.parse_known_args(argv)
    args = parse_arguments(__doc__, "env_speed.png", rest)
    time_single(2)  # compile and warm up
    results = {"single_steps_per_s": max(time_single(known.steps) for _ in range(args.repeats))}
    for n in VECTOR_SIZES:
        time_vector(n, 2)
        results[f"vector_{n}_env_steps_per_s"] = max(time_vector(n, known.steps) for _ in range(args.repeats))
    print(f"{'configuration':<26}{'env steps/s':>14}")
    for key, value in results.items():
        print(f"{key:<26}{value:>14.0f}")
    print("goals: single >= 2000, batched >= 20000 env steps/s")
    if args.json:
        args.json.write_text(json.dumps(results, indent=2))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    ax.loglog(VECTOR_SIZES, [results[f"vector_{n}_env_steps_per_s"] for n in VECTOR_SIZES], "o-",
              label="make_vec (one batched simulator)")
    ax.axhline(results["single_steps_per_s"], color="C1", ls="--", label="gym.make, one env")
    ax.axhline(20000, color="0.5", ls=":", label="goal, batched")
    ax.set_xlabel("num_envs")
    ax.set_ylabel("env steps per second (one core)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    save_plot(fig, args.plot)
    return results


if __name__ == "__main__":
    main()
