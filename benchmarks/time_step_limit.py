"""The largest physics time step the grasp works at: the environment's episodes under the two scripted controllers,
planar and 3-D, at each Δt, on the same seeds: solver failures, success, time per environment step, and agreement
with the finest Δt (success labels, final object positions).

    python -m benchmarks.time_step_limit [--dts 0.01 0.025 0.05] [--episodes 100] [--seed 7000] [--workers 2]
        [--json out/time_step_limit.json] [--plot out/time_step_limit.png]

Every Δt must divide the control interval (0.05 s). Each (model, controller, Δt) runs in its own process.
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from ._timing import save_plot
from .contact_outcomes import MODELS, POLICIES, agreement, parse_run_arguments, run_pair


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dts", type=float, nargs="+", default=[0.01, 0.025, 0.05],
                        help="physics time steps [s]; the first is the reference")
    args = parse_run_arguments(parser, argv, 100, 7000, "time_step_limit")
    runs = [(model, policy, dt) for dt in args.dts for model in MODELS for policy in POLICIES]
    print(f"{args.episodes} episodes for each of {len(runs)} (model, controller, Δt) runs, {args.workers} at a "
          "time ...", flush=True)
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {run: pool.submit(run_pair, run[0], run[1], args.episodes, args.seed, physics_dt=run[2])
                   for run in runs}
        results = {}
        for run, future in futures.items():
            results[run] = future.result()
            print(f"  done: {run[0]}, {run[1]}, Δt = {run[2]} s", flush=True)
    reference = args.dts[0]
    rows = []
    print(f"\n| model | controller | Δt [s] | solver failures | success | labels agree with Δt = {reference} |"
          " median position gap [mm] | ms per env step |\n|---|---|---|---|---|---|---|---|")
    for (model, policy, dt), result in results.items():
        agree = agreement(results[(model, policy, reference)], result)
        steps = result["mean_length"] * result["episodes"]
        row = {"model": model, "controller": policy, "physics_dt": dt,
               "solver_failures": result["endings"]["solver_failure"], "success_rate": result["success_rate"],
               "label_agreement": agree["label_agreement"], "median_position_gap_m": agree["median_position_gap_m"],
               "ms_per_step": 1e3 * result["seconds"] / steps}
        rows.append(row)
        print(f"| {model} | {policy} | {dt} | {row['solver_failures']} of {result['episodes']} |"
              f" {row['success_rate']:.2f} | {row['label_agreement']:.2f} |"
              f" {1e3 * row['median_position_gap_m']:.1f} | {row['ms_per_step']:.2f} |")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"episodes": args.episodes, "first_seed": args.seed, "rows": rows}, indent=1))
    print(f"wrote {args.json}")
    _plot(rows, args.plot)
    return {"rows": rows}


def _plot(rows: list[dict], path: Path) -> None:
    """Solver failures and label agreement with the finest Δt against Δt, one line per model and controller."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (failures, agree) = plt.subplots(1, 2, figsize=(10, 4))
    for model in MODELS:
        for policy in POLICIES:
            mine = sorted((row for row in rows if row["model"] == model and row["controller"] == policy),
                          key=lambda row: row["physics_dt"])
            dts = [row["physics_dt"] for row in mine]
            failures.plot(dts, [row["solver_failures"] for row in mine], marker="o", label=f"{model}, {policy}")
            agree.plot(dts, [row["label_agreement"] for row in mine], marker="o", label=f"{model}, {policy}")
    failures.set_xlabel("physics Δt [s]")
    failures.set_ylabel("episodes ended by a solver failure")
    agree.set_xlabel("physics Δt [s]")
    agree.set_ylabel("success labels as at the finest Δt")
    agree.set_ylim(0.0, 1.02)
    for ax in (failures, agree):
        ax.legend(fontsize=7)
        ax.grid(alpha=0.3)
    save_plot(fig, path)


if __name__ == "__main__":
    main()
