"""Reproduce the figures of the paper's gripper scene (``docs/model.md`` §1), one PNG and one tip CSV per case.

    python -m examples.reproduce_paper --out out/paper [--model planar|3d] [--case fig5 fig9 ...]

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

import numpy as np

from examples.plotting import (
    new_figure,
    plot_contact_forces,
    plot_sphere,
    plot_timelapse,
    plot_tip_height,
    save,
)
from soft_gripper_env.physics import (
    ELASTOSIL_MA_4601,
    PAPER_BALL,
    PAPER_DEFECTIVE_DRAG,
    SOFT_TRANSLUCENT_SILICONE,
    Trajectory,
    paper_scene,
    run_ramp,
)

CASES = ("fig5", "fig6", "fig7", "fig8", "fig9", "fig10", "fig11", "fig12", "fig12_contact")
CONTACT_HEADER = ["time_s", "finger", "node", "x_m", "y_m", "z_m", "fx_N", "fy_N", "fz_N", "fn_N"]
SOFT_100KPA = replace(ELASTOSIL_MA_4601, name="Elastosil, E = 100 kPa", youngs_modulus=100e3)


def write_tip_csv(path: Path, trajectory: Trajectory) -> None:
    """One row per step: the state after the step, at t = (k+1)·Δt; finger 1 of gripper 0."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s", "tip_x_m", "tip_y_m", "tip_z_m"])
        for t, tip in zip(trajectory.times[1:], trajectory.positions[1:, 0, 0, -1], strict=True):
            writer.writerow([f"{t:.6g}", f"{tip[0]:.9e}", f"{tip[1]:.9e}", f"{tip[2]:.9e}"])


def write_contacts_csv(path: Path, trajectory: Trajectory) -> None:
    """One row per held node per step, world frame; fingers numbered from 1 (finger 1 along +x), nodes from 0
    (node 0 at the palm). fn_N is the normal (compressive, ≥ 0) part of the reaction (fx, fy, fz)."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(CONTACT_HEADER)
        for t, x, report in zip(trajectory.times[1:], trajectory.positions[1:, 0], trajectory.contacts, strict=True):
            for finger, node in zip(*np.nonzero(report.held[0]), strict=True):
                f = report.reaction[0, finger, node]
                writer.writerow([f"{t:.6g}", finger + 1, node, *(f"{v:.9e}" for v in x[finger, node]),
                                 *(f"{v:.9e}" for v in f), f"{report.normal_reaction[0, finger, node]:.9e}"])


def normal_force_per_finger(trajectory: Trajectory) -> np.ndarray:
    """Sum of the normal reactions on each finger of gripper 0 after every step [N], (K, F)."""
    return np.array([report.normal_reaction[0].sum(axis=-1) for report in trajectory.contacts])


@cache
def ball_run(model: str, material=ELASTOSIL_MA_4601) -> Trajectory:
    """The paper's scene grasping its fixed ball (R = 0.065 m at (0, 0, −0.09) m)."""
    return run_ramp(paper_scene(model, material=material, grasped_object=PAPER_BALL))


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
    elif case == "fig10":
        run = ball_run(model)
        runs = {"ball": run}
        fig, (ax, ax_force) = new_figure(2)
        s = run.positions[..., 0] * 1.0  # finger 1 lies along +x: its plane coordinate s is x
        for k in range(0, len(run.times), 10):
            ax.plot(s[k, 0, 0], run.positions[k, 0, 0, :, 2], color=plt_gray(k / len(run.times)), lw=1)
        angle = np.linspace(0, 2 * np.pi, 200)
        ax.plot(PAPER_BALL.radius * np.cos(angle) + PAPER_BALL.center[0],
                PAPER_BALL.radius * np.sin(angle) + PAPER_BALL.center[2], color="tab:blue", label="ball")
        last = run.contacts[-1]
        x = run.positions[-1, 0, 0]
        held = last.held[0, 0]
        outward = unit(x[held] - np.asarray(PAPER_BALL.center))
        ax.quiver(x[held, 0], x[held, 2], outward[:, 0], outward[:, 2], color="crimson", angles="xy",
                  scale_units="xy", scale=25.0, width=0.006)
        ax.scatter(x[held, 0], x[held, 2], color="crimson", zorder=3, label="held nodes, outward normal")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m] (finger 1's plane)")
        ax.set_ylabel("z [m]")
        ax.set_title("Fig. 10: finger 1 on the ball (every 0.1 s)")
        ax.legend(fontsize=8)
        normal = normal_force_per_finger(run)
        ax_force.plot(run.times[1:], normal[:, 0], label="normal reaction on finger 1")
        tangential = [np.linalg.norm(r.finger_reaction[0, 0] - (r.normal_reaction[0, 0][:, None]
                      * unit(run.positions[k + 1, 0, 0] - np.asarray(PAPER_BALL.center))).sum(axis=0))
                      for k, r in enumerate(run.contacts)]
        ax_force.plot(run.times[1:], tangential, ls="--", label="tangential (stick) reaction")
        ax_force.set_xlabel("time t [s]")
        ax_force.set_ylabel("force [N]")
        ax_force.set_xlim(0.8, 1.0)
        ax_force.grid(True, alpha=0.3)
        ax_force.legend(fontsize=8)
        ax_force.set_title("contact force on finger 1")
    elif case == "fig11":
        run = ball_run(model)
        runs = {"ball": run}
        fig, (ax,) = new_figure(1, (True,), width=6.5)
        plot_timelapse(ax, run)
        plot_sphere(ax, PAPER_BALL)
        plot_contact_forces(ax, run.positions[-1, 0], run.contacts[-1], scale=0.05)
        ax.legend(fontsize=8, loc="upper left")
        ax.set_title("Fig. 11: the gripper closing on the fixed ball (every 0.1 s)")
    elif case == "fig12_contact":
        runs = {"Elastosil MA 4601": ball_run(model),
                "Soft Translucent": ball_run(model, SOFT_TRANSLUCENT_SILICONE)}
        fig, axes = new_figure(2)
        for ax, (label, run) in zip(axes, runs.items(), strict=True):
            normal = normal_force_per_finger(run)
            total = np.linalg.norm([r.finger_reaction[0, 0] for r in run.contacts], axis=-1)
            ax.plot(run.times[1:], normal[:, 0], label="normal reaction, finger 1")
            ax.plot(run.times[1:], total, ls="--", label="|reaction vector|, finger 1")
            ax.set_xlabel("time t [s]")
            ax.set_ylabel("force [N]")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=8)
            paper = 33.86 if label.startswith("Elastosil") else 21.23
            ax.set_title(f"Fig. 12: {label} (paper: {paper} N)")
        write_tip_csv(out / "fig12_contact_soft_translucent.csv", runs["Soft Translucent"])
        write_contacts_csv(out / "fig12_contact_soft_translucent_contacts.csv", runs["Soft Translucent"])
    else:
        raise ValueError(f"--case {case!r} is not one of {', '.join(CASES)}")
    save(fig, out / f"{case}.png")
    first = next(iter(runs.values()))
    write_tip_csv(out / f"{case}.csv", first)
    if first.contacts:
        write_contacts_csv(out / f"{case}_contacts.csv", first)
    return runs


def unit(vectors: np.ndarray) -> np.ndarray:
    return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def plt_gray(fraction: float):
    return str(0.8 - 0.7 * fraction)


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
    print(f"wrote {', '.join(f'{c}.png' for c in args.case)} and the tip (and contact) CSVs to {args.out}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
