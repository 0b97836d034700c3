"""Reproduce the figures of the paper's gripper scene (physics.md §1), one PNG and one tip CSV per case.

    python examples/reproduce_paper.py --out out/paper [--model planar|3d] [--case fig5 fig9 ...]

Scene (SI): three fingers, L = 0.2 m, r = 0.02 m (or the taper r_i = 0.001·(20 − i) m), N = 20, Elastosil MA 4601
(E = 386.66 kPa, ρ = 1130 kg/m³), gravity 9.81 m/s², per-node Stokes drag at η = 1.0e-3 Pa·s, κ̄(t) = −0.15·t,
backward Euler, Δt = 0.01 s, T = 1 s. Each CSV holds finger 1's tip (the finger along +x) after every step.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import replace
from functools import cache
from pathlib import Path

from soft_gripper_env.physics import (
    ELASTOSIL_MA_4601,
    PAPER_DEFECTIVE_DRAG,
    SOFT_TRANSLUCENT_SILICONE,
    Trajectory,
    paper_scene,
    run_ramp,
)
from soft_gripper_env.plotting import new_figure, plot_timelapse, plot_tip_height, save

CASES = ("fig5", "fig6", "fig7", "fig8", "fig9", "fig12")
SOFT_100KPA = replace(ELASTOSIL_MA_4601, name="Elastosil, E = 100 kPa", youngs_modulus=100e3)


def write_tip_csv(path: Path, trajectory: Trajectory) -> None:
    """One row per step: the state after the step, at t = (k+1)·Δt; finger 1 of gripper 0."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s", "tip_x_m", "tip_y_m", "tip_z_m"])
        for t, tip in zip(trajectory.times[1:], trajectory.positions[1:, 0, 0, -1], strict=True):
            writer.writerow([f"{t:.6g}", f"{tip[0]:.9e}", f"{tip[1]:.9e}", f"{tip[2]:.9e}"])


@cache
def paper_run(model: str) -> Trajectory:
    """The paper's scene as it stands (Figs. 5, 7 and the references of the others), run once per model."""
    return run_ramp(paper_scene(model))


def plot_paper_defect(ax, model: str, material) -> None:
    """Overlay the same scene with the drag that produced the paper's curves (η = 1000 Pa·s on nodes 2–4)."""
    run = run_ramp(paper_scene(model, material=material, medium=(PAPER_DEFECTIVE_DRAG,)))
    plot_tip_height(ax, run, "paper's defective drag: η = 1000 Pa·s on nodes 2–4", ls=":", color="tab:red")


def run_case(case: str, model: str, out: Path) -> dict[str, Trajectory]:
    """Runs one case, writes DIR/<case>.png and DIR/<case>.csv, returns its trajectories by label."""
    base = paper_run(model)
    if case == "fig5":
        runs = {"Elastosil, Stokes drag (water)": base}
        fig, (ax,) = new_figure()
        plot_tip_height(ax, base, "Elastosil MA 4601, Stokes drag at η = 1.0e-3 Pa·s")
        plot_paper_defect(ax, model, ELASTOSIL_MA_4601)
        ax.set_title("Fig. 5: fingertip height, κ̄ = −0.15·t")
        ax.legend()
    elif case == "fig6":
        runs = {"E = 100 kPa": run_ramp(paper_scene(model, material=SOFT_100KPA))}
        fig, (ax,) = new_figure()
        plot_tip_height(ax, runs["E = 100 kPa"], "E = 100 kPa")
        plot_tip_height(ax, base, "E = 386.66 kPa (Fig. 5)", ls="--", color="gray")
        plot_paper_defect(ax, model, SOFT_100KPA)
        ax.set_title("Fig. 6: softer finger, E = 100 kPa")
        ax.legend()
    elif case == "fig7":
        runs = {"with drag": base}
        fig, (ax,) = new_figure(1, (True,), width=6.5)
        plot_timelapse(ax, base)
        ax.set_title("Fig. 7: time-lapse with Stokes drag (every 0.1 s)")
    elif case == "fig8":
        runs = {"no drag": run_ramp(paper_scene(model, medium="air"))}
        fig, (ax, ax3) = new_figure(2, (False, True))
        plot_tip_height(ax, runs["no drag"], "no drag")
        plot_tip_height(ax, base, "Stokes drag at η = 1.0e-3 Pa·s (Fig. 5)", ls="--", color="gray")
        ax.legend()
        ax.set_title("Fig. 8: without drag")
        plot_timelapse(ax3, runs["no drag"])
        ax3.set_title("time-lapse without drag (every 0.1 s)")
    elif case == "fig9":
        runs = {"variable stiffness": run_ramp(paper_scene(model, variable_stiffness=True))}
        fig, (ax,) = new_figure()
        plot_tip_height(ax, runs["variable stiffness"], "taper r = 0.020 → 0.001 m")
        plot_tip_height(ax, base, "constant r = 0.02 m (Fig. 5)", ls="--", color="gray")
        ax.set_title("Fig. 9: variable stiffness")
        ax.legend()
    elif case == "fig12":
        runs = {"Elastosil MA 4601": base,
                "Soft Translucent": run_ramp(paper_scene(model, material=SOFT_TRANSLUCENT_SILICONE))}
        fig, axes = new_figure(2)
        for ax, (label, run) in zip(axes, runs.items(), strict=True):
            plot_tip_height(ax, run, label)
            ax.set_title(f"Fig. 12: {label}")
        write_tip_csv(out / "fig12_soft_translucent.csv", runs["Soft Translucent"])
    else:
        raise ValueError(f"--case {case!r} is not one of {', '.join(CASES)}")
    save(fig, out / f"{case}.png")
    write_tip_csv(out / f"{case}.csv", next(iter(runs.values())))
    return runs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder for PNGs and CSVs")
    parser.add_argument("--model", choices=("planar", "3d"), default="3d", help="rod model (default: 3d)")
    parser.add_argument("--case", nargs="+", choices=CASES, default=list(CASES), metavar="NAME",
                        help=f"cases to run (default: all of {' '.join(CASES)})")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    print(f"Reproducing {len(args.case)} case(s) with the {args.model} model into {args.out}/ "
          "(the first run compiles the kernels, about a minute)", flush=True)
    for i, case in enumerate(args.case, 1):
        start = time.perf_counter()
        runs = run_case(case, args.model, args.out)
        summary = "; ".join(f"{label}: tip z(1 s) = {run.positions[-1, 0, 0, -1, 2] * 1e3:.1f} mm, "
                            f"min {run.positions[:, 0, 0, -1, 2].min() * 1e3:.1f} mm, "
                            f"Newton ≤ {run.newton_iterations.max()} it/step" for label, run in runs.items())
        print(f"[{i}/{len(args.case)}] {case} ({time.perf_counter() - start:.1f} s): {summary}", flush=True)
    print(f"wrote {', '.join(f'{c}.png' for c in args.case)} and the tip CSVs to {args.out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
