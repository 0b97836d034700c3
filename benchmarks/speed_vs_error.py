"""Speed against error: a work-precision sweep over Δt, node count, integrator, rod model and drag model.

    python -m benchmarks.speed_vs_error --out out/speed_vs_error [--quick] [--repeats N]

Scenes (SI):

- ``cantilever_damped``: the cantilever of ``docs/model.md`` §4 (L = 0.1 m, r = 0.01 m, E = 386.66 kPa, ρ = 1200 kg/m³,
  accurate clamp) released straight under gravity, with mass-proportional damping γ = 10 s⁻¹, for 2 s;
- ``cantilever_undamped``: the same without damping;
- ``paper_ramp``: the paper's three-finger ramp κ̄ = −0.15·t for 1 s (at N = 20; other N keep the curvature per
  metre), with the paper's Stokes drag and in water;
- ``grasp_water``: the fingers close (κ̄ = −0.6·t, held at −0.25 from 0.42 s) on a free sphere in water
  (R = 0.05 m, ρ = 1100 kg/m³, centre 0.1 m below the palm) and hold it, for 1.5 s; backward Euler only (contact
  is resolved for it alone), N = 20 only (whether the grasp holds depends on N, so the reference keeps N = 20 and
  the error measures time stepping alone), Δt ≤ 1e-2 s (the coupled grasp diverges at Δt ≥ 2e-2 s). Its error is
  measured on the sphere's centre.

Each run is timed single-threaded (wall seconds per simulated second, after a warm-up; the best of ``--repeats``
passes over the whole grid, 3 by default, since a shared machine only ever slows a run down) and compared with a
converged reference of the same scene, model and drag (implicit midpoint, or backward Euler with contact;
Δt = 2.5e-4 s, N = 80): the error is the largest distance between the two fingertips [m], sampled every 0.02 s.
Writes DIR/speed_vs_error.csv, one work-precision plot per scene (DIR/<scene>.png), and prints the settings that
meet the issue's goals. ``--quick`` runs the cantilever scenes on a smaller grid in under 3 minutes.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from benchmarks._timing import save_plot
from soft_gripper_env.physics import (
    MassProportionalDamping,
    NewtonSettings,
    Scene,
    Simulator,
    Sphere,
    cantilever_scene,
    paper_scene,
)

HEADER = ["scene", "model", "integrator", "n_nodes", "dt_s", "wall_s_per_sim_s", "max_tip_error_m",
          "steady_tip_z_m"]
SAMPLE_S = 0.02
LINE_STYLES = {"implicit_midpoint": "-", "midpoint_triple_jump": "-.", "midpoint_suzuki": ":"}
NODE_MARKERS = {10: "o", 20: "s", 40: "^"}
GOALS = ((0.01, 0.02), (0.003, 0.08))
"""The issue's goals on the damped cantilever: (wall s per simulated s, tip error relative to the deflection)."""
DAMPED_DEFLECTION = 14.95e-3
"""The damped cantilever's static tip deflection [m], the scale of its relative errors."""
GRASP_CURVATURE = 0.25
"""|κ̄| at which the grasp scene's fingers stop closing (dimensionless), holding the sphere below the palm."""
REFERENCE = {"dt": 2.5e-4, "n_nodes": 80, "integrator": "implicit_midpoint"}


@dataclass(frozen=True)
class Case:
    scene: str
    model: str
    drag: str
    integrator: str
    n_nodes: int
    dt: float


def build_scene(case: Case) -> Scene:
    if case.scene.startswith("cantilever"):
        scene = cantilever_scene(case.n_nodes, "accurate", case.model)
        scene = replace(scene, duration=2.0)
        if case.scene == "cantilever_damped":
            scene = replace(scene, forces=scene.forces + (MassProportionalDamping(rate=10.0),))
    else:
        grasp = case.scene == "grasp_water"
        sphere = Sphere(0.05, (0.0, 0.0, -0.1), density=1100.0) if grasp else None
        base = paper_scene(case.model, medium=case.drag, grasped_object=sphere)
        if grasp:
            base = replace(base, natural_curvature_rate=-0.6, duration=1.5)
        finger = replace(base.gripper.finger, n_nodes=case.n_nodes)
        # κ̄ is curvature integrated over a node's length Δl: keep the curvature per metre, not per node, so that
        # runs at different N actuate the same finger
        rate = base.natural_curvature_rate * finger.edge_length / base.gripper.finger.edge_length
        scene = replace(base, gripper=replace(base.gripper, finger=finger), natural_curvature_rate=rate)
    # an error of 1e-6·EI/L² in force is far below anything this sweep resolves
    return replace(scene, time_step=case.dt, integrator=case.integrator, newton=NewtonSettings())


def run(case: Case) -> tuple[float, np.ndarray, bool]:
    """Wall seconds per simulated second, the tip of finger 1 (or the grasped sphere's centre) every SAMPLE_S [m]
    (K, 3), and whether every step converged."""
    scene = build_scene(case)
    sim = Simulator(scene)
    sim.step(sim.initial_state(), 0.0)  # warm-up: compile, allocate
    state = sim.initial_state()
    every = max(1, int(round(SAMPLE_S / case.dt)))
    samples, ok = [], True
    start = time.perf_counter()
    for k in range(int(round(scene.duration / case.dt))):
        kbar = scene.natural_curvature_rate * state.time
        result = sim.step(state, max(kbar, -GRASP_CURVATURE) if case.scene == "grasp_water" else kbar)
        ok &= bool(result.converged.all())
        state = result.state
        if (k + 1) % every == 0:
            samples.append(state)  # the states are immutable; the tips are read after the clock stops
    wall = time.perf_counter() - start
    tips = [s.body_position[0] if s.body_position is not None else sim.world_positions(s)[0, 0, -1] for s in samples]
    return wall / scene.duration, np.array(tips), ok


def sample_on(tips: np.ndarray, dt: float, reference: np.ndarray) -> np.ndarray:
    """The tips of a run whose samples fall every ``round(SAMPLE_S/dt)·dt``, at the reference's sample times."""
    period = max(1, int(round(SAMPLE_S / dt))) * dt
    times = period * np.arange(1, len(tips) + 1)
    reference_times = SAMPLE_S * np.arange(1, len(reference) + 1)
    return np.stack([np.interp(reference_times, times, tips[:, k]) for k in range(3)], axis=1)


def grid(quick: bool) -> list[Case]:
    steps = (1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2)
    cases = []
    for scene in ("cantilever_damped", "cantilever_undamped"):
        models = ("planar",) if quick else ("planar", "3d")
        nodes = (10, 20) if quick else (10, 20, 40)
        integrators = ("backward_euler", "implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki")
        for model, integrator, n, dt in itertools.product(models, integrators, nodes, steps):
            cases.append(Case(scene, model, "none", integrator, n, dt))
    if not quick:
        for model, drag, integrator, n, dt in itertools.product(("planar", "3d"), ("stokes", "water"),
                                                                ("backward_euler", "implicit_midpoint"), (10, 20),
                                                                (2e-3, 5e-3, 1e-2, 2e-2, 5e-2)):
            cases.append(Case("paper_ramp", model, drag, integrator, n, dt))
        for model, dt in itertools.product(("planar", "3d"), (2.5e-3, 5e-3, 1e-2)):
            cases.append(Case("grasp_water", model, "water", "backward_euler", 20, dt))
    return cases


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--quick", action="store_true", help="cantilever scenes on a small grid (< 3 minutes)")
    parser.add_argument("--repeats", type=int, default=3,
                        help="timed passes over the grid; each case's best counts (default 3)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats = {args.repeats} must be at least 1")
    args.out.mkdir(parents=True, exist_ok=True)
    cases = grid(args.quick)
    references = {}
    rows = []
    for case in tqdm(cases, desc="speed vs error", unit="run", file=sys.stdout):
        key = (case.scene, case.model, case.drag)
        if key not in references:
            grasp = case.scene == "grasp_water"
            reference_case = Case(case.scene, case.model, case.drag,
                                  "backward_euler" if grasp else REFERENCE["integrator"],
                                  case.n_nodes if grasp else REFERENCE["n_nodes"], REFERENCE["dt"])
            references[key] = run(reference_case)[1]
        wall, tips, ok = run(case)
        reference = references[key]
        error = np.linalg.norm(sample_on(tips, case.dt, reference) - reference, axis=1).max() if ok else np.nan
        label = case.scene if case.drag == "none" or case.scene == "grasp_water" else f"{case.scene}_{case.drag}"
        rows.append([label, case.model, case.integrator, case.n_nodes, case.dt, wall, error, tips[-1, 2]])
    # further timed passes over the whole grid, not back to back per case: this machine's slow spells last seconds
    for _ in tqdm(range(args.repeats - 1), desc="timing passes", unit="pass", file=sys.stdout):
        for row, case in zip(rows, cases, strict=True):
            row[5] = min(row[5], run(case)[0])

    with open(args.out / "speed_vs_error.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(HEADER)
        for row in rows:
            writer.writerow([row[0], row[1], row[2], row[3], f"{row[4]:g}", f"{row[5]:.6g}", f"{row[6]:.6g}",
                             f"{row[7]:.9g}"])
    print(f"wrote {args.out / 'speed_vs_error.csv'} ({len(rows)} runs)")
    plot(rows, args.out)
    report_goals(rows)
    return 0


def plot(rows, out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    integrators = list(dict.fromkeys(r[2] for r in rows))
    colors = {name: f"C{k}" for k, name in enumerate(integrators)}
    for scene in sorted({row[0] for row in rows}):
        selected = [row for row in rows if row[0] == scene]
        models = sorted({r[1] for r in selected}, key=("planar", "3d").index)
        fig, axes = plt.subplots(1, len(models), figsize=(6.5 * len(models), 5), sharex=True, sharey=True,
                                 squeeze=False)
        for ax, model in zip(axes[0], models, strict=True):
            for integrator, n in sorted({(r[2], r[3]) for r in selected if r[1] == model}):
                series = sorted((r for r in selected if r[1:4] == [model, integrator, n]), key=lambda r: r[4])
                errors = np.array([r[6] for r in series])
                walls = np.array([r[5] for r in series])
                ax.loglog(errors, walls, LINE_STYLES.get(integrator, "--"), color=colors[integrator],
                          marker=NODE_MARKERS.get(n, "o"), ms=4, label=f"{integrator}, N = {n}")
                for r, e, w in zip(series, errors, walls, strict=True):
                    if np.isfinite(e) and r[4] in (1e-3, 1e-2, 5e-2):
                        ax.annotate(f"{r[4]:g}", (e, w), fontsize=6, color=colors[integrator])
            ax.set_xlabel("max tip error against the converged reference [m]")
            ax.set_title(f"{model} (labels: Δt [s])")
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=6, ncol=2)
        if scene == "cantilever_damped":  # the goals as shaded corners, on the limits the data set
            (left, right), (bottom, top) = axes[0, 0].get_xlim(), axes[0, 0].get_ylim()
            for ax, (budget, tolerance) in itertools.product(axes[0], GOALS):
                ax.fill_between([left, tolerance * DAMPED_DEFLECTION], bottom, budget, color="0.5", alpha=0.12, lw=0)
                ax.annotate(f"goal: ≤ {tolerance:.0%} at ≤ {budget:g} s/s", (tolerance * DAMPED_DEFLECTION, budget),
                            fontsize=7, ha="right", va="bottom", color="0.3")
            axes[0, 0].set_xlim(left, right)
            axes[0, 0].set_ylim(bottom, top)
        axes[0, 0].set_ylabel("wall seconds per simulated second (one core)")
        fig.suptitle(f"work–precision: {scene}")
        save_plot(fig, out / f"{scene}.png")
        plt.close(fig)


def report_goals(rows) -> None:
    """The issue's goals on the damped cantilever: ≤ 0.01 wall s per simulated s at ≤ 2 % tip error, ≤ 0.003 at
    ≤ 8 %, stable at Δt = 5e-2 s. Tip error relative to the static deflection (14.95 mm)."""
    deflection = DAMPED_DEFLECTION
    damped = [r for r in rows if r[0] == "cantilever_damped"]
    for budget, tolerance in GOALS:
        meeting = [r for r in damped if r[5] <= budget and r[6] <= tolerance * deflection]
        best = min(meeting, key=lambda r: r[6], default=None)
        fastest = min((r for r in damped if r[6] <= tolerance * deflection), key=lambda r: r[5], default=None)
        if best:
            print(f"goal ≤ {budget} wall s/sim s at ≤ {tolerance:.0%} error: met, e.g. {best[1]} {best[2]} "
                  f"N = {best[3]} Δt = {best[4]:g}: {best[5]:.4f} s/s, error {best[6] / deflection:.2%}")
        else:
            print(f"goal ≤ {budget} wall s/sim s at ≤ {tolerance:.0%} error: not met; fastest within the error: "
                  + (f"{fastest[1]} {fastest[2]} N = {fastest[3]} Δt = {fastest[4]:g}: {fastest[5]:.4f} s/s"
                     if fastest else "none"))
    stable = [r for r in damped if r[4] == 5e-2]
    print(f"Δt = 5e-2 on the damped cantilever: {sum(np.isfinite(r[6]) for r in stable)} of {len(stable)} runs "
          "converged on every step")


if __name__ == "__main__":
    sys.exit(main())
