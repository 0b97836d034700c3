"""The grasp's physics against Δt, without the task or a controller: where the sphere ends, and how often contacts
are made and let go, as the step falls.

    python -m benchmarks.physics_convergence [--model 3d] [--seeds 8] [--seed 0] [--still]
        [--dts 0.0025,0.00125,0.000625,0.0003125,0.00015625] [--workers 2]
        [--json out/physics_convergence.json] [--plot out/physics_convergence.png]

Each seed's scene is the task's episode (its sphere, its current and gust; ``--still`` stills the water). The
fingers close at κ̄ rate −0.3/s, control interval by control interval as the env steps them, until κ̄ reaches −0.2
(0.67 s), and hold there; after 2.5 s the run goes on one step at a time for 0.5 s, counting the nodes caught
(held anew) and let go. At 3 s the sphere's place is compared with the finest Δt's. Per Δt: the median gap over the
seeds, its fitted order in Δt (:func:`benchmarks.outcome_convergence.gap_order`; backward Euler alone would give
first order), and the holds made per second. A physics-level probe of the outcome study's slow convergence
(``docs/notes/outcome_convergence.md``): minutes where the task's episodes take hours.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ._timing import save_plot
from .outcome_convergence import gap_order

DEFAULT_DTS = (0.0025, 0.00125, 0.000625, 0.0003125, 0.00015625)
CLOSING_RATE = -0.3
"""κ̄ rate while closing [1/s]."""
CURVATURE_RANGE = (-0.2, 0.0)
DURATION_S = 3.0
COUNT_FROM_S = 2.5
"""From when the holds made and let go are counted, step by step [s]."""
STILL = {"current_velocity": (0.0, 0.0, 0.0), "current_oscillation": (0.0, 0.0, 0.0),
         "gust_velocity": (0.0, 0.0, 0.0)}


def run_seed(model: str, seed: int, dt: float, still: bool) -> dict:
    """One seed's scripted grasp at step ``dt`` [s]: the sphere's place at the end [m], and the holds made and let
    go while counting."""
    from soft_gripper_env.grasp_task import GraspTask, task_episode
    from soft_gripper_env.physics import Simulator

    task = GraspTask(model=model, physics_dt=dt)
    sim = Simulator(task_episode(task, np.random.default_rng(seed), STILL if still else {}).scene)
    state, curvature = sim.initial_state(), np.zeros(task.gripper.n_fingers)
    per_interval = round(task.control_dt / dt)
    for _ in range(round(COUNT_FROM_S / task.control_dt)):
        advanced = sim.advance(state, curvature, CLOSING_RATE, per_interval, CURVATURE_RANGE)
        state, curvature = advanced.state, advanced.natural_curvature
    held = np.array(state.held)
    made = let_go = 0
    for _ in range(round((DURATION_S - COUNT_FROM_S) / dt)):
        advanced = sim.advance(state, curvature, CLOSING_RATE, 1, CURVATURE_RANGE)
        state, curvature = advanced.state, advanced.natural_curvature
        now = np.asarray(state.held)
        made += int(np.sum(now & ~held))
        let_go += int(np.sum(held & ~now))
        held = now.copy()
    return {"final_position_m": np.asarray(state.body_position).ravel().tolist(), "holds_made": made,
            "holds_let_go": let_go, "failed": bool(np.any(advanced.failed))}


def summarize(runs: dict, seeds: list[int], dts: list[float]) -> dict:
    """Per Δt: the median and 90th percentile of the final gap to the finest Δt over the seeds, and the holds made
    per second (median and largest); the gap's fitted order."""
    finest = min(dts)
    window = DURATION_S - COUNT_FROM_S
    rows = {}
    for dt in sorted(dts, reverse=True):
        made = np.array([runs[(seed, dt)]["holds_made"] for seed in seeds]) / window
        row = {"median_holds_made_per_s": float(np.median(made)), "most_holds_made_per_s": float(made.max()),
               "failed": sum(runs[(seed, dt)]["failed"] for seed in seeds), "against_reference": None}
        if dt != finest:
            gaps = [np.linalg.norm(np.subtract(runs[(seed, dt)]["final_position_m"],
                                               runs[(seed, finest)]["final_position_m"])) for seed in seeds]
            row["against_reference"] = {"median_position_gap_m": float(np.median(gaps)),
                                        "p90_position_gap_m": float(np.percentile(gaps, 90))}
        rows[f"{dt:g}"] = row
    return {"reference_dt_s": finest, "dts": rows, "median_gap_order": gap_order(rows)}


def plot(summary: dict, path: Path) -> None:
    """The median final gap against Δt beside a first-order line, and the holds made per second against Δt."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summary["dts"]
    fig, (gap, holds) = plt.subplots(1, 2, figsize=(11, 4))
    tested = [k for k in rows if rows[k]["against_reference"] is not None]
    dt = np.array([float(k) for k in tested]) * 1e3
    median = np.array([rows[k]["against_reference"]["median_position_gap_m"] for k in tested]) * 1e3
    gap.plot(dt, median, "o-", label="median over the seeds")
    gap.plot(dt, [rows[k]["against_reference"]["p90_position_gap_m"] * 1e3 for k in tested], "s--",
             label="90th percentile")
    gap.plot(dt, median[0] * dt / dt[0], ":", color="gray", label="first order, from the largest Δt")
    gap.set(xscale="log", yscale="log", xlabel="physics step Δt [ms]", ylabel="gap to the finest Δt [mm]",
            title=f"the sphere's place at {DURATION_S:g} s against {1e3 * summary['reference_dt_s']:g} ms")
    every = np.array([float(k) for k in rows]) * 1e3
    holds.plot(every, [rows[k]["median_holds_made_per_s"] for k in rows], "o-", label="median over the seeds")
    holds.plot(every, [rows[k]["most_holds_made_per_s"] for k in rows], "s--", label="the most")
    holds.set(xscale="log", xlabel="physics step Δt [ms]", ylabel="holds made per second",
              title=f"contacts caught, {COUNT_FROM_S:g}–{DURATION_S:g} s (κ̄ held)")
    holds.set_yscale("symlog", linthresh=1.0)  # none made is a point too
    holds.set_ylim(bottom=0.0)
    for axis in (gap, holds):
        axis.set_xticks(every, [f"{x:g}" for x in every])
        axis.minorticks_off()
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=8)
    fig.suptitle(f"scripted grasp, {summary['model']}, {len(summary['seeds'])} seeds"
                 f"{', still water' if summary['still'] else ''}")
    save_plot(fig, path)
    plt.close(fig)


def parse_steps(parser: argparse.ArgumentParser, text: str, at_least: int) -> list[float]:
    """The ``--dts`` option's steps [s], coarsest first: at least ``at_least`` of them, each in (0, 0.01] s and
    dividing the task's control interval of 0.05 s; otherwise the parser's error, naming the option."""
    words = ("two", "three", "four")
    try:
        dts = sorted({float(v) for v in text.split(",")}, reverse=True)
    except ValueError:
        parser.error(f"--dts = {text!r} is not a comma-separated list of steps [s]")
    if len(dts) < at_least or any(not 0.0 < dt <= 0.01 for dt in dts):
        parser.error(f"--dts = {text!r}: at least {words[at_least - 2]} steps, each in (0, 0.01] s")
    if any(abs(0.05 / dt - round(0.05 / dt)) > 1e-9 for dt in dts):
        parser.error(f"--dts = {text!r}: each step must divide the control interval, 0.05 s")
    return dts


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", choices=("3d", "planar"), default="3d")
    parser.add_argument("--seeds", type=int, default=8, help="how many seeds (default 8)")
    parser.add_argument("--seed", type=int, default=0, help="the first seed (default 0)")
    parser.add_argument("--dts", default=",".join(f"{dt:g}" for dt in DEFAULT_DTS), help="physics steps [s]")
    parser.add_argument("--still", action="store_true", help="no current and no gust")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", type=Path, default=Path("out") / "physics_convergence.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / "physics_convergence.png")
    args = parser.parse_args(argv)
    dts = parse_steps(parser, args.dts, 3)
    if args.seeds < 1 or args.workers < 1:
        parser.error("--seeds and --workers must be at least 1")
    seeds = list(range(args.seed, args.seed + args.seeds))
    jobs = [(seed, dt) for dt in dts for seed in seeds]
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {job: pool.submit(run_seed, args.model, job[0], job[1], args.still) for job in jobs}
        runs = {job: future.result() for job, future in tqdm(futures.items(), desc="runs", file=sys.stdout)}
    summary = {"model": args.model, "seeds": seeds, "still": args.still, **summarize(runs, seeds, dts),
               "runs": {f"{seed}/{dt:g}": runs[(seed, dt)] for seed, dt in jobs}}
    print("| Δt [ms] | median gap to the finest [mm] | 90th pct [mm] | holds made per s (median, most) |\n"
          "|---|---|---|---|")
    for key, row in summary["dts"].items():
        test = row["against_reference"]
        print(f"| {1e3 * float(key):g} | " + ("reference | — |" if test is None else
              f"{1e3 * test['median_position_gap_m']:.2f} | {1e3 * test['p90_position_gap_m']:.2f} |")
              + f" {row['median_holds_made_per_s']:.0f}, {row['most_holds_made_per_s']:.0f} |")
    if summary["median_gap_order"] is not None:
        print(f"the median gap falls as Δt^{summary['median_gap_order']:.2f}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.json}")
    plot(summary, args.plot)
    return summary


if __name__ == "__main__":
    main()
