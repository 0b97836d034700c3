"""Grasp outcomes of the baseline controllers in the planar and 3-D models, on the same seeds: how often each
succeeds, its return, peak finger force and how its episodes end, whether the two models agree on each episode's
success label, how far apart they leave the object, solver failures, and each model's speed.

    python -m benchmarks.contact_outcomes [--episodes 300] [--seed 5000] [--workers 2]
        [--json out/contact_outcomes.json] [--plot docs/img/contact_outcomes.png]

Each (model, controller) pair runs in its own process, ``--workers`` at a time.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from ._timing import save_plot

MODELS = ("planar", "3d")
POLICIES = ("ramp", "reactive")


def run_pair(model: str, policy: str, episodes: int, seed: int, **settings) -> dict:
    """:func:`agents.evaluate.evaluate` of one controller in one model (a worker process); ``settings`` go to the
    task (:class:`~soft_gripper_env.grasp_task.GraspTask`), e.g. ``physics_dt``."""
    from agents.evaluate import evaluate
    from agents.scripted import RampPolicy, ReactivePolicy
    from soft_gripper_env.grasp_task import GraspTask

    task = GraspTask(model=model, **settings)
    controller = RampPolicy(task) if policy == "ramp" else ReactivePolicy(task)
    evaluate(controller, 1, seed, progress=False, model=model, **settings)  # compiles (or loads) the kernels, untimed
    result = evaluate(controller, episodes, seed, progress=False, model=model, **settings)
    return {**result, "task": repr(task)}  # what the episodes ran, so that a kept run of another task is not reused


def agreement(first: dict, second: dict) -> dict:
    """How two runs' episodes on the same seeds compare, seed by seed: the share with the same success label, and
    the median and 90th percentile of the distance between the objects' final positions [m]."""
    same = np.mean(np.equal(first["successes"], second["successes"]))
    gap = np.linalg.norm(np.subtract(first["final_object_offsets"], second["final_object_offsets"]), axis=1)
    return {"label_agreement": float(same), "median_position_gap_m": float(np.median(gap)),
            "p90_position_gap_m": float(np.percentile(gap, 90))}


def parse_run_arguments(parser: argparse.ArgumentParser, argv: list[str] | None, episodes: int, seed: int,
                        name: str) -> argparse.Namespace:
    """Adds the options of an episode benchmark (--episodes, --seed, --workers, --json out/NAME.json, --plot
    out/NAME.png) to ``parser`` and parses ``argv``, refusing fewer than one episode or worker."""
    parser.add_argument("--episodes", type=int, default=episodes)
    parser.add_argument("--seed", type=int, default=seed, help=f"the first seed (default {seed})")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", type=Path, default=Path("out") / f"{name}.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / f"{name}.png")
    args = parser.parse_args(argv)
    if args.episodes < 1 or args.workers < 1:
        parser.error("--episodes and --workers must be at least 1")
    return args


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    args = parse_run_arguments(parser, argv, 300, 5000, "contact_outcomes")
    pairs = [(model, policy) for model in MODELS for policy in POLICIES]
    print(f"{args.episodes} episodes for each of {len(pairs)} (model, controller) pairs, {args.workers} at a time ...",
          flush=True)
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {pair: pool.submit(run_pair, *pair, args.episodes, args.seed) for pair in pairs}
        results = {}
        for pair, future in futures.items():
            results[pair] = future.result()
            print(f"  done: {pair[0]}, {pair[1]}", flush=True)
    summary = {"episodes": args.episodes, "first_seed": args.seed, "runs": {}, "agreement": {}}
    print("\n| model | controller | success | return | peak finger force [N] | solver failures | ms per env step |"
          " endings |\n|---|---|---|---|---|---|---|---|")
    for (model, policy), result in results.items():
        steps = result["mean_length"] * result["episodes"]
        row = {key: result[key] for key in ("success_rate", "mean_return", "std_return",
                                             "mean_peak_contact_force_N", "endings", "seconds")}
        row["ms_per_step"] = 1e3 * result["seconds"] / steps
        summary["runs"][f"{model}/{policy}"] = row
        endings = ", ".join(f"{name} {count}" for name, count in result["endings"].items() if count)
        print(f"| {model} | {policy} | {row['success_rate']:.2f} | {row['mean_return']:.1f} ± {row['std_return']:.1f}"
              f" | {row['mean_peak_contact_force_N']:.2f} | {result['endings']['solver_failure']} |"
              f" {row['ms_per_step']:.2f} | {endings} |")
    print("\n| controller | success labels agree | median final position gap [mm] | 90th percentile [mm] |\n"
          "|---|---|---|---|")
    for policy in POLICIES:
        agree = agreement(results[("planar", policy)], results[("3d", policy)])
        summary["agreement"][policy] = agree
        print(f"| {policy} | {agree['label_agreement']:.2f} | {1e3 * agree['median_position_gap_m']:.1f} |"
              f" {1e3 * agree['p90_position_gap_m']:.1f} |")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"summary": summary, "episodes": {
        f"{m}/{p}": {k: r[k] for k in ("successes", "returns", "peak_contact_forces_N", "episode_endings",
                                        "final_object_offsets")} for (m, p), r in results.items()}}, indent=1))
    print(f"wrote {args.json}")
    _plot(results, args.plot)
    return summary


def _plot(results: dict, path: Path) -> None:
    """Final object positions (x, z) of every episode, planar against 3-D, one panel per controller."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(POLICIES), figsize=(5 * len(POLICIES), 4.2), squeeze=False)
    for ax, policy in zip(axes[0], POLICIES, strict=True):
        for model, marker in zip(MODELS, ("o", "x"), strict=True):
            result = results[(model, policy)]
            xyz = np.array(result["final_object_offsets"])
            success = np.array(result["successes"])
            ax.scatter(xyz[success, 0] * 1e3, xyz[success, 2] * 1e3, marker=marker, s=14, label=f"{model}, held")
            ax.scatter(xyz[~success, 0] * 1e3, xyz[~success, 2] * 1e3, marker=marker, s=14, alpha=0.4,
                       label=f"{model}, not held")
        ax.set_title(f"{policy}: where the object ends")
        ax.set_xlabel("x [mm]")
        ax.set_ylabel("z [mm]")
        ax.legend(fontsize=7)
    save_plot(fig, path)


if __name__ == "__main__":
    main()
