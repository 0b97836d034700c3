"""The paper's ramp in air, with the paper's Stokes drag, and in water (buoyancy, Morison drag, added mass).

    python -m examples.water_vs_air --out out/water [--model planar|3d] [--time-step 0.01]

Scene (SI): the paper's three Elastosil fingers (L = 0.2 m, r = 0.02 m, N = 20, E = 386.66 kPa, ρ = 1130 kg/m³),
κ̄(t) = −0.15·t, backward Euler, T = 1 s. Water: ρ_w = 1000 kg/m³, C_n = 1.2, C_t = 0.01, C_a = 1. Writes
DIR/water_vs_air.png (tip height and the time-lapses) and DIR/water_vs_air.csv (tip z of finger 1 per medium), and
prints closing time, rebound and the peak water forces on one finger.
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from examples.plotting import new_figure, plot_timelapse, plot_tip_height, save
from soft_gripper_env.physics import (
    AddedMass,
    MorisonDrag,
    Simulator,
    StepContext,
    Trajectory,
    evaluate_force,
    paper_scene,
)

MEDIA = ("air", "stokes", "water")
LABELS = {"air": "air (no fluid force)", "stokes": "paper's Stokes drag, η = 1e-3 Pa·s", "water": "water (Morison)"}


def run_with_forces(scene) -> tuple[Trajectory, np.ndarray, np.ndarray]:
    """The scripted ramp, plus the largest Morison drag and added-mass force on finger 1 at each step [N]."""
    sim = Simulator(scene)
    state = sim.initial_state()
    positions, drag_peak, inertia_peak = [sim.world_positions(state)], [], []
    water = [f for f in scene.forces if isinstance(f, (MorisonDrag, AddedMass))]
    disc = sim.disc
    iterations, converged = [], []
    for _ in range(scene.n_steps):
        old = state
        result = sim.step(state, scene.natural_curvature_rate * state.time)
        state = result.state
        positions.append(sim.world_positions(state))
        iterations.append(result.newton_iterations)
        converged.append(result.converged)
        peaks = []
        for model in water:  # re-evaluate each water force at the step's solution, finger 1 only
            D = disc.dim
            q, q_old = state.q[0, :1], old.q[0, :1]
            force = np.zeros(q.shape)
            band = np.zeros((1, disc.n_dofs, disc.band_width + 1))
            dt = scene.time_step
            ctx = StepContext(old.time, q_old[..., :D], 1 / dt, 1 / dt**2)
            acceleration = (state.velocity[0, :1] - old.velocity[0, :1])[..., :D] / dt
            evaluate_force(model, disc, scene.fluid, ctx, q[..., :D], state.velocity[0, :1][..., :D], acceleration,
                           force[..., :D], band)
            peaks.append(np.linalg.norm(force[0, :, :D].sum(axis=0)))
        drag_peak.append(peaks[0] if peaks else 0.0)
        inertia_peak.append(peaks[1] if len(peaks) > 1 else 0.0)
    trajectory = Trajectory(times=np.arange(scene.n_steps + 1) * scene.time_step, positions=np.stack(positions),
                            newton_iterations=np.stack(iterations), converged=np.stack(converged), final_state=state)
    return trajectory, np.array(drag_peak), np.array(inertia_peak)


def describe(trajectory: Trajectory) -> dict[str, float]:
    """Closing time: when the tip first passes z = −0.1 m [s]. Rebound: the largest rise of the tip above its
    lowest point so far, before t = 0.6 s, when it still falls (the first-mode swing) [m]."""
    z = trajectory.positions[:, 0, 0, -1, 2]
    t = trajectory.times
    below = np.nonzero(z < -0.1)[0]
    early = z[t < 0.6]
    return {"closing_time_s": float(t[below[0]]) if below.size else float("nan"),
            "rebound_m": float(np.max(early - np.minimum.accumulate(early)))}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--model", choices=("planar", "3d"), default="planar", help="rod model (default: planar)")
    parser.add_argument("--time-step", type=float, default=0.01, help="physics step Δt [s] (default 0.01)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    runs = {}
    for medium in MEDIA:
        try:
            scene = replace(paper_scene(args.model, medium=medium), time_step=args.time_step)
        except ValueError as error:
            parser.error(str(error))
        runs[medium] = run_with_forces(scene)
        trajectory, drag, inertia = runs[medium]
        facts = describe(trajectory)
        print(f"{medium:>6}: tip z(1 s) = {trajectory.positions[-1, 0, 0, -1, 2] * 1e3:7.1f} mm, closes past −0.1 m "
              f"at {facts['closing_time_s']:.2f} s, rebound {facts['rebound_m'] * 1e3:5.1f} mm, "
              f"Newton ≤ {trajectory.newton_iterations.max()} it/step"
              + (f", peak drag {drag.max():.3f} N, peak added-mass force {inertia.max():.3f} N on one finger"
                 if medium == "water" else ""), flush=True)
    scene = paper_scene(args.model)
    finger = scene.gripper.finger
    volume = np.pi * finger.radius**2 * finger.length
    print(f"one finger's weight {finger.material.density * volume * 9.81:.3f} N in air, "
          f"{(finger.material.density - 1000.0) * volume * 9.81:.3f} N net in water")

    fig, (ax, ax_air, ax_water) = new_figure(3, (False, True, True), width=5.2)
    for medium, style in zip(MEDIA, ("-", "--", "-"), strict=True):
        plot_tip_height(ax, runs[medium][0], LABELS[medium], ls=style)
    ax.set_title("fingertip height, κ̄ = −0.15·t")
    ax.legend(fontsize=8)
    plot_timelapse(ax_air, runs["air"][0])
    ax_air.set_title("in air (as Fig. 8)")
    plot_timelapse(ax_water, runs["water"][0])
    ax_water.set_title("in water (Morison drag, added mass, buoyancy)")
    save(fig, args.out / "water_vs_air.png")
    with open(args.out / "water_vs_air.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s"] + [f"tip_z_{medium}_m" for medium in MEDIA])
        times = runs["air"][0].times
        for k in range(1, len(times)):
            writer.writerow([f"{times[k]:.6g}"] + [f"{runs[m][0].positions[k, 0, 0, -1, 2]:.9e}" for m in MEDIA])
    print(f"wrote {args.out / 'water_vs_air.png'} and {args.out / 'water_vs_air.csv'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
