"""Environment steps per second against Gymnasium's ``Ant-v5``, measured side by side in one run.

    python -m benchmarks.env_speed [--json out/env_speed.json] [--plot out/env_speed.png] [--repeats 3] [--quick]

What it times, each on random actions from a reset with seed 0, the best of ``--repeats`` runs (a shared machine
only ever slows a run down):

- the anchor, MuJoCo's ``Ant-v5`` from ``gym.make`` (the ``bench`` extra installs ``gymnasium[mujoco]``), for
  ``ANT_STEPS`` steps, resetting when an episode ends;
- ``SoftGripperUnderwater-v0`` from ``gym.make`` (one env) for two episodes' length of actions (``--steps`` twice,
  resetting when an episode ends), and from ``gym.make_vec`` with 1, 16, 64 and 256 envs for one episode's length
  each (``--steps`` = 60 actions; autoreset), in the planar and the 3-D model;
- ``make_vec`` with 64 envs on two threads (``num_threads=2``), in both models;
- grasping: one env and ``make_vec(64)`` driven by the reactive controller (``agents.scripted.ReactivePolicy``),
  which closes on the specimen and holds it through most of the episode, as a trained policy does. Random actions
  rarely touch it, and a held specimen costs several times more per step (more corrector passes and Newton
  iterations, each coupling fingers and body), so these figures are the ones training sees. One timed run each after
  a warm-up (they are the slowest figures of the run).

Every figure is in env steps per second on one core (Numba and BLAS are held to one thread each, and a vector's
``num_threads`` adds its own), with its ratio to ``Ant-v5``'s figure of the same run. The physics core's goals
(:mod:`benchmarks.core_speed`: the paper's scene and batched planar µs per gripper-step) are timed in the same run,
so that every goal of the throughput issue comes from one run. ``--quick`` times 16 and 64 envs only, once.

The run also times a **ceiling**: the env's fingers alone, with nothing to grasp (the task's gripper, water, current,
Δt and Newton settings, κ̄ held at zero so that they hang still in the current and Newton takes about one solve and
its test per step, the least a step can take; no specimen, so no contact, no body, no corrector and no task), 64
grippers in one batch, in µs per gripper and physics step. An env step takes the task's substeps of that and more,
for one env as for a vector of them, so ``substeps × µs`` is about the least an env step can cost with these
kernels at the task's Δt (a bound within the timing's noise: it is timed minutes apart from the env). The JSON's
``ceiling`` gives, per model, the steps per second and the ratio to Ant-v5 that no env configuration on one thread
can pass, and for each goal the most substeps per action (the shortest ``physics_dt``) at which the fingers alone
would still reach it.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

from benchmarks._timing import save_plot, time_ramp  # (sets one thread first)
from benchmarks.core_speed import GOALS as CORE_GOALS
from soft_gripper_env.env import DEFAULT_MAX_EPISODE_STEPS
from soft_gripper_env.grasp_task import GraspTask, task_episode
from soft_gripper_env.physics import Scene

ANT_STEPS = 3000
VECTOR_SIZES = (1, 16, 64, 256)
MODELS = ("planar", "3d")
GOALS = {"single_steps_per_s": 2.0, "vec64_steps_per_s": 10.0, "single_3d_steps_per_s": 0.5,
         "vec64_3d_steps_per_s": 2.0}
"""Goals as ratios to Ant-v5 of the same run."""
TWO_THREAD_GOAL = 1.7
"""Two threads against one, make_vec(64), planar."""
CEILING_BATCH = 64
"""Grippers stepped together for the ceiling (the fingers alone): a batch shares each step's fixed costs, so their
cost per gripper is the least."""
CEILING_DURATION = 0.5
"""Simulated time of one timed run of the fingers alone [s]."""


def steps_per_second(env, steps: int, policy=None, seed: int = 0) -> float:
    """Env steps per second of ``env`` (one env or a vector) over ``steps`` actions, random or ``policy``'s (a
    callable of the observation), from a reset with ``seed``; one env is reset when its episode ends (a vector
    resets its own). Closes ``env``."""
    envs = getattr(env, "num_envs", 1)
    env.action_space.seed(seed)
    observation, _ = env.reset(seed=seed)
    start = time.perf_counter()
    for _ in range(steps):
        action = env.action_space.sample() if policy is None else policy(observation)
        observation, _, terminated, truncated, _ = env.step(action)
        if envs == 1 and (terminated or truncated):
            observation, _ = env.reset()
    seconds = time.perf_counter() - start
    env.close()
    return steps * envs / seconds


def time_ant(steps: int = ANT_STEPS) -> float:
    """Ant-v5 steps per second on random actions."""
    import gymnasium as gym

    return steps_per_second(gym.make("Ant-v5"), steps)


def time_single(model: str, steps: int) -> float:
    """One env's steps per second over ``steps`` random actions, resetting when an episode ends."""
    import gymnasium as gym

    import soft_gripper_env

    return steps_per_second(gym.make(soft_gripper_env.ENV_ID, model=model), steps)


def time_vector(model: str, num_envs: int, steps: int, num_threads: int = 1) -> float:
    """``make_vec``'s env steps per second over ``steps`` random actions of every env (autoreset)."""
    import gymnasium as gym

    import soft_gripper_env

    return steps_per_second(gym.make_vec(soft_gripper_env.ENV_ID, num_envs=num_envs, model=model,
                                         num_threads=num_threads), steps)


def time_grasping(model: str, num_envs: int, steps: int) -> float:
    """Env steps per second while the reactive controller grasps: one env (``num_envs`` = 0) over ``steps``
    actions, resetting when an episode ends, or ``make_vec(num_envs)`` (autoreset)."""
    import gymnasium as gym

    import soft_gripper_env
    from agents.scripted import ReactivePolicy
    from soft_gripper_env.grasp_task import GraspTask

    policy = ReactivePolicy(GraspTask(model=model))
    env = gym.make(soft_gripper_env.ENV_ID, model=model) if num_envs == 0 else \
        gym.make_vec(soft_gripper_env.ENV_ID, num_envs=num_envs, model=model)
    return steps_per_second(env, steps, policy)


def fingers_alone(model: str) -> tuple[Scene, int]:
    """The env's fingers with nothing to grasp, and the task's physics substeps per action: the scene of the task's
    first episode (seed 0: its water, current, Δt and Newton settings) without its specimen, κ̄ held at zero for
    :data:`CEILING_DURATION`."""
    import numpy as np

    task = GraspTask(model=model)
    scene = task_episode(task, np.random.default_rng(0), {}).scene
    return replace(scene, grasped_object=None, duration=CEILING_DURATION, natural_curvature_rate=0.0), task.substeps


def time_fingers_alone(model: str, repeats: int) -> tuple[float, float, int]:
    """µs per gripper and physics step of :func:`fingers_alone`, :data:`CEILING_BATCH` grippers in one batch,
    Newton's mean iterations per step there (about one: a solve and the test after it, the least a step can do), and
    the task's substeps per action."""
    scene, substeps = fingers_alone(model)
    seconds, trajectory = time_ramp(scene, CEILING_BATCH, repeats)
    return 1e6 * seconds / (scene.n_steps * CEILING_BATCH), float(trajectory.newton_iterations.mean()), substeps


def ceilings(ant_steps_per_s: float, fingers_alone_us: dict[str, float], substeps: dict[str, int]) -> dict:
    """Per model: the least an env step can cost with these kernels, ``substeps`` × ``fingers_alone_us`` (µs per
    gripper and physics step), as steps per second and as a ratio to Ant-v5; and for each goal of that model
    (:data:`GOALS`) the most substeps per action at which the fingers alone would reach it (0: none)."""
    out = {}
    for model, us in fingers_alone_us.items():
        if not (us > 0 and substeps[model] >= 1 and ant_steps_per_s > 0):
            raise ValueError(f"ceilings: {model}: µs per gripper-step {us!r} and Ant-v5's steps/s "
                             f"{ant_steps_per_s!r} must be positive, substeps {substeps[model]!r} at least 1")
        steps_per_s = 1e6 / (substeps[model] * us)
        # named without the goals' unit suffix: compare_commits reads a name ending in _per_s as a timed rate
        goals = {key.removesuffix("_steps_per_s"): math.floor(1e6 / (goal * ant_steps_per_s * us) + 1e-9)
                 for key, goal in GOALS.items() if ("_3d" in key) == (model == "3d")}
        out[model] = {"fingers_alone_us_per_gripper_step": us, "substeps_per_action": substeps[model],
                      "env_steps_per_s_at_most": steps_per_s, "vs_ant_v5": steps_per_s / ant_steps_per_s,
                      "most_substeps_for_goal": goals}
    return out


def best(function, repeats: int, *args) -> float:
    """The largest of ``repeats`` results of ``function(*args)``, after one untimed call (compilation, caches)."""
    function(*args)
    return max(function(*args) for _ in range(repeats))


def time_core(repeats: int) -> dict:
    """The physics core's goals: the paper's scene in both models [ms], batched planar at B = 64 [µs per
    gripper-step]."""
    from soft_gripper_env.physics import paper_scene

    planar, spatial = paper_scene("planar"), paper_scene("3d")
    return {"paper_scene_planar_ms": 1e3 * time_ramp(planar, 1, repeats)[0],
            "paper_scene_3d_ms": 1e3 * time_ramp(spatial, 1, repeats)[0],
            "batched_planar_us_per_gripper_step": 1e6 * time_ramp(planar, 64, repeats)[0] / (planar.n_steps * 64)}


def measure(repeats: int, sizes: tuple[int, ...], steps: int) -> dict:
    """Every figure of the run, anchor first and last (its best counts), with the ratios and goals."""
    results = {"ant_v5_steps_per_s": best(time_ant, repeats)}
    alone = {}
    for model in MODELS:
        suffix = "" if model == "planar" else "_3d"
        print(f"timing {model}: one env ...", flush=True)
        results[f"single{suffix}_steps_per_s"] = best(time_single, repeats, model, 2 * steps)
        for n in sizes:
            print(f"timing {model}: make_vec({n}) ...", flush=True)
            results[f"vec{n}{suffix}_steps_per_s"] = best(time_vector, repeats, model, n, steps)
        print(f"timing {model}: the fingers alone (the ceiling) ...", flush=True)
        alone[model] = time_fingers_alone(model, repeats)  # next to the vectors, which it bounds
        print(f"timing {model}: make_vec(64) on two threads ...", flush=True)
        results[f"vec64{suffix}_two_threads_steps_per_s"] = best(time_vector, repeats, model, 64, steps, 2)
        print(f"timing {model}: grasping, one env and make_vec(64) ...", flush=True)
        results[f"single{suffix}_grasping_steps_per_s"] = best(time_grasping, 1, model, 0, 2 * steps)
        results[f"vec64{suffix}_grasping_steps_per_s"] = best(time_grasping, 1, model, 64, steps)
    print("timing the physics core ...", flush=True)
    core = time_core(repeats)
    # the anchor again, at the end: a machine that slowed down during the run shows as two different figures
    results["ant_v5_steps_per_s"] = max(results["ant_v5_steps_per_s"], best(time_ant, repeats))
    ant = results["ant_v5_steps_per_s"]
    ratios = {key.removesuffix("_steps_per_s") + "_vs_ant_v5": value / ant for key, value in results.items()
              if key != "ant_v5_steps_per_s"}
    threads = {model: results[f"vec64{s}_two_threads_steps_per_s"] / results[f"vec64{s}_steps_per_s"]
               for model, s in (("planar", ""), ("3d", "_3d")) if f"vec64{s}_steps_per_s" in results}
    goals = {key: {"goal_vs_ant_v5": goal, "reached_vs_ant_v5": results[key] / ant, "met": results[key] / ant >= goal}
             for key, goal in GOALS.items() if key in results}
    if "planar" in threads:
        goals["vec64_two_threads_over_one"] = {"goal": TWO_THREAD_GOAL, "reached": threads["planar"],
                                               "met": threads["planar"] >= TWO_THREAD_GOAL}
    for key, goal in CORE_GOALS.items():
        goals[key] = {"goal": goal, "reached": core[key], "met": core[key] <= goal}
    ceiling = ceilings(ant, {model: us for model, (us, _, _) in alone.items()},
                       {model: substeps for model, (_, _, substeps) in alone.items()})
    for model, (_, iterations, _) in alone.items():
        ceiling[model]["newton_iterations_per_step"] = iterations
    return {**results, "ratios_to_ant_v5": ratios, "two_threads_over_one": threads, "core": core, "goals": goals,
            "ceiling": ceiling}


def report(results: dict) -> None:
    ant = results["ant_v5_steps_per_s"]
    print(f"\n{'configuration':<36}{'steps/s':>10}{'vs Ant-v5':>11}")
    print(f"{'Ant-v5 (MuJoCo, the anchor)':<36}{ant:>10.0f}{1.0:>10.2f}×")
    for key, value in results.items():
        if key.endswith("_steps_per_s") and key != "ant_v5_steps_per_s":
            print(f"{key.removesuffix('_steps_per_s'):<36}{value:>10.0f}{value / ant:>10.2f}×")
    print("\ngoals:")
    for key, goal in results["goals"].items():
        if "goal_vs_ant_v5" in goal:
            text = f"≥ {goal['goal_vs_ant_v5']:g}× Ant-v5, reached {goal['reached_vs_ant_v5']:.2f}×"
        elif key.startswith("vec64_two"):
            text = f"≥ {goal['goal']:g}× one thread, reached {goal['reached']:.2f}×"
        else:
            text = f"≤ {goal['goal']:g}, reached {goal['reached']:.2f}"
        print(f"  {key:<36}{text:<44}{'met' if goal['met'] else 'not met'}")
    print("\nceiling: the fingers alone (no specimen, contact, body or task), batched, times the task's substeps:")
    for model, each in results["ceiling"].items():
        most = ", ".join(f"{key} {n}" for key, n in each["most_substeps_for_goal"].items())
        print(f"  {model:<7}{each['fingers_alone_us_per_gripper_step']:7.1f} µs per gripper-step × "
              f"{each['substeps_per_action']} substeps: at most {each['env_steps_per_s_at_most']:,.0f} steps/s = "
              f"{each['vs_ant_v5']:.2f}× Ant-v5; most substeps per action that could reach each goal: {most}")


def plot(results: dict, sizes: tuple[int, ...], path: Path) -> None:
    """Env steps per second against num_envs, per model, as multiples of Ant-v5, with the goals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ant = results["ant_v5_steps_per_s"]
    fig, ax = plt.subplots(figsize=(9.5, 4.8))
    for model, suffix, color in (("planar", "", "C0"), ("3-D", "_3d", "C1")):
        ax.loglog(sizes, [results[f"vec{n}{suffix}_steps_per_s"] / ant for n in sizes], "o-", color=color,
                  label=f"make_vec, {model}, one thread")
        ax.scatter([64], [results[f"vec64{suffix}_two_threads_steps_per_s"] / ant], marker="^", s=70, color=color,
                   label=f"make_vec(64), {model}, two threads", zorder=3)
        ax.axhline(results[f"single{suffix}_steps_per_s"] / ant, color=color, ls=":", label=f"gym.make, {model}")
        if "ceiling" in results:
            ceiling = results["ceiling"]["3d" if suffix else "planar"]
            ax.axhline(ceiling["vs_ant_v5"], color=color, ls="--", lw=2.0,
                       label=f"ceiling, {model}, one thread: the fingers alone × "
                             f"{ceiling['substeps_per_action']} substeps")
        if f"vec64{suffix}_grasping_steps_per_s" in results:
            ax.scatter([1, 64], [results[f"single{suffix}_grasping_steps_per_s"] / ant,
                                 results[f"vec64{suffix}_grasping_steps_per_s"] / ant], marker="x", s=70,
                       color=color, label=f"grasping (reactive controller): gym.make at 1, make_vec(64), {model}",
                       zorder=3)
    ax.axhline(1.0, color="k", lw=1.5, label=f"Ant-v5 ({ant:,.0f} steps/s in this run)")
    for (key, goal), marker in zip(GOALS.items(), ("s", "D", "s", "D"), strict=True):
        color = "C1" if "3d" in key else "C0"
        x = 64 if key.startswith("vec64") else 1  # the one-env goals belong to gym.make, drawn at 1
        ax.scatter([x], [goal], marker=marker, facecolor="none", edgecolor=color, s=90, zorder=3)
    ax.scatter([], [], marker="s", facecolor="none", edgecolor="0.3", label="goal, one env (at num_envs = 1)")
    ax.scatter([], [], marker="D", facecolor="none", edgecolor="0.3", label="goal, make_vec(64)")
    ax.set_xlabel("num_envs")
    ax.set_ylabel("env steps per second, as multiples of Ant-v5")
    ax.set_title("SoftGripperUnderwater-v0 against Gymnasium's Ant-v5, one run")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    save_plot(fig, path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, default=Path("out") / "env_speed.json", help="results (JSON)")
    parser.add_argument("--plot", type=Path, default=Path("out") / "env_speed.png", help="plot (PNG)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per figure; the best counts (default 3)")
    parser.add_argument("--quick", action="store_true", help="16 and 64 envs only, one timed run each")
    parser.add_argument("--steps", type=int, default=DEFAULT_MAX_EPISODE_STEPS,
                        help=f"actions per timed vector run, twice as many for one env (default "
                             f"{DEFAULT_MAX_EPISODE_STEPS}, an episode)")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.steps < 1:
        parser.error("--repeats and --steps must be at least 1")
    sizes = (16, 64) if args.quick else VECTOR_SIZES
    results = measure(1 if args.quick else args.repeats, sizes, args.steps)
    results["vector_sizes"] = list(sizes)
    report(results)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.json}")
    plot(results, sizes, args.plot)
    return results


if __name__ == "__main__":
    main()
