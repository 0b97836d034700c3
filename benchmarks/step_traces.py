"""Where a grasp starts to depend on Δt: the same episodes stepped at successive Δt, the sphere's place recorded at
every control interval, and the median gap between successive steps over time.

    python -m benchmarks.step_traces [--model planar] [--controller reactive] [--seeds 40] [--seed 3000000]
        [--dts 0.00125,0.000625,0.0003125,0.00015625] [--until 0.6] [--friction MU] [--workers 2]
        [--json out/step_traces.json] [--plot out/step_traces.png]

``--controller closing`` closes every finger at the task's fastest rate (action −1) whatever it observes: the open
loop, to tell the physics from the controller. ``--friction`` sets the specimen's Coulomb μ (``inf`` sticks, ``0``
slides freely). Backward Euler is first order, so where the physics converges each halving of Δt halves the gap
between successive steps; a gap that stays put from one halving to the next is an error of order zero, and the time
at which that begins shows which part of the episode makes it (``docs/notes/outcome_convergence.md``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from itertools import pairwise
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ._timing import save_plot
from .physics_convergence import parse_steps

DEFAULT_DTS = (0.00125, 0.000625, 0.0003125, 0.00015625)
CONTROLLERS = ("reactive", "closing")


def run_traces(model: str, controller: str, dt: float, first_seed: int, seeds: int, until: float,
               friction: float | None) -> list:
    """The sphere's offset from the grasp point [m] at the end of every control interval up to ``until`` [s], per
    seed, (intervals, seeds, 3) as nested lists; NaN after an episode ended."""
    from agents.scripted import ConstantPolicy, ReactivePolicy
    from soft_gripper_env.env import SoftGripperUnderwaterVectorEnv, observation_slices

    settings = {"model": model, "physics_dt": dt}
    if friction is not None:
        settings["object_friction"] = friction
    venv = SoftGripperUnderwaterVectorEnv(seeds, **settings)
    task = venv.task
    policy = ReactivePolicy(task) if controller == "reactive" else ConstantPolicy(task, -1.0)
    offset = observation_slices(task)["object_offset"]
    observations, _ = venv.reset(seed=[first_seed + k for k in range(seeds)])
    intervals = round(until / task.control_dt)
    trace = np.full((intervals, seeds, 3), np.nan)
    running = np.ones(seeds, dtype=bool)
    for k in range(intervals):
        observations, _, terminated, truncated, _ = venv.step(policy(observations))
        trace[k, running] = observations[running][:, offset]
        running &= ~(terminated | truncated)
        if not running.any():
            break
    venv.close()
    return trace.tolist()


def successive_gaps(traces: dict[float, np.ndarray]) -> dict[str, list[float]]:
    """The median over the seeds of the distance [m] between the sphere's places at successive Δt, per control
    interval, keyed by the pair, e.g. ``"0.00125-0.000625"``."""
    dts = sorted(traces, reverse=True)
    gaps = {}
    for coarse, fine in pairwise(dts):
        distance = np.linalg.norm(np.asarray(traces[coarse]) - np.asarray(traces[fine]), axis=-1)
        gaps[f"{coarse:g}-{fine:g}"] = [float(np.nanmedian(row)) if np.isfinite(row).any() else math.nan
                                        for row in distance]
    return gaps


def plot(summary: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(7, 4.5))
    times = np.asarray(summary["times_s"])
    for pair, gaps in summary["median_gaps_m"].items():
        coarse, fine = (1e3 * float(v) for v in pair.split("-"))
        axis.semilogy(times, np.asarray(gaps) * 1e3, "o-", markersize=3, label=f"{coarse:g} against {fine:g} ms")
    axis.set_xlabel("time in the episode [s]")
    axis.set_ylabel("median gap of the sphere's place [mm]")
    friction = summary["friction"]
    axis.set_title(f"{summary['model']}, {summary['controller']}"
                   + ("" if friction is None else f", μ = {friction:g}") + f", {len(summary['seeds'])} seeds:"
                   " successive steps (first order: each halving halves the gap)", fontsize=9)
    axis.grid(True, which="both", alpha=0.3)
    axis.legend(fontsize=8)
    save_plot(fig, path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", choices=("3d", "planar"), default="planar")
    parser.add_argument("--controller", choices=CONTROLLERS, default="reactive")
    parser.add_argument("--seeds", type=int, default=40, help="how many seeds (default 40)")
    parser.add_argument("--seed", type=int, default=3_000_000, help="the first seed (default 3000000)")
    parser.add_argument("--dts", default=",".join(f"{dt:g}" for dt in DEFAULT_DTS), help="physics steps [s]")
    parser.add_argument("--until", type=float, default=0.6, help="how far into the episodes [s] (default 0.6)")
    parser.add_argument("--friction", type=float, default=None, help="the specimen's Coulomb μ (default the task's)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--json", type=Path, default=Path("out") / "step_traces.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / "step_traces.png")
    args = parser.parse_args(argv)
    dts = parse_steps(parser, args.dts, 2)
    if not 0.05 <= args.until <= 10.0:
        parser.error(f"--until = {args.until!r} s is outside the allowed range [0.05, 10] s")
    if args.friction is not None and not args.friction >= 0.0:
        parser.error(f"--friction = {args.friction!r} is outside the allowed range [0, inf]")
    if args.seeds < 1 or args.workers < 1:
        parser.error("--seeds and --workers must be at least 1")
    with ProcessPoolExecutor(args.workers) as pool:
        futures = {dt: pool.submit(run_traces, args.model, args.controller, dt, args.seed, args.seeds, args.until,
                                   args.friction) for dt in dts}
        traces = {dt: np.asarray(future.result()) for dt, future in tqdm(futures.items(), desc="steps",
                                                                         file=sys.stdout)}
    gaps = successive_gaps(traces)
    times = [0.05 * (k + 1) for k in range(len(next(iter(gaps.values()))))]
    summary = {"model": args.model, "controller": args.controller, "friction": args.friction,
               "seeds": list(range(args.seed, args.seed + args.seeds)), "dts_s": dts, "times_s": times,
               "median_gaps_m": gaps, "traces_m": {f"{dt:g}": traces[dt].tolist() for dt in dts}}
    shown = [k for k, t in enumerate(times) if k % max(1, len(times) // 8) == 0 or k == len(times) - 1]
    print("| successive Δt [ms] | " + " | ".join(f"{times[k]:.2f} s" for k in shown) + " |")
    print("|---|" + "---|" * len(shown))
    for pair, row in gaps.items():
        coarse, fine = (1e3 * float(v) for v in pair.split("-"))
        print(f"| {coarse:g} – {fine:g} | " + " | ".join(f"{1e3 * row[k]:.3f}" for k in shown) + " |")
    print("(median gap of the sphere's place between successive steps, mm)")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.json}")
    plot(summary, args.plot)
    return summary


if __name__ == "__main__":
    main()
