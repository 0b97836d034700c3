"""Speed against error: a work-precision sweep over Δt, node count, integrator, rod model and drag model.

    python -m benchmarks.speed_vs_error --out out/speed_vs_error [--quick] [--repeats N]
    python -m benchmarks.speed_vs_error --out out/speed_vs_error --grasp-outcomes [--episodes 200] [--seed 7000]
        [--workers 2]

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

``--grasp-outcomes`` runs the grasp-outcome scene instead: the environment's own task, on ``--episodes`` seeds under
the ramp and the reactive controller, once per speed setting in :data:`OUTCOME_SETTINGS` and once with the fine
reference at the default's own step (3-D, N = 20, Δt = 1.25e-3 s, Newton tolerance 1e-9, friction settled). For
each setting it reports how often the success label agrees with the reference's, seed by seed, how far apart the
two leave the object (median and 90th percentile), and the setting's speed: one env under the reactive controller
for four episodes from ``--seed``, timed alone after the episodes, against Gymnasium's ``Ant-v5`` in the same run.
Writes DIR/grasp_outcomes.json and DIR/grasp_outcomes.png; each run's episodes are kept in DIR/grasp_outcome_runs/,
so an interrupted study resumes.
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
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
OUTCOME_REFERENCE = "reference"
OUTCOME_DEFAULT = "3d, dt 0.00125, tol 1e-4, friction 4 passes"
OUTCOME_SETTINGS = {
    label: {"model": model, "physics_dt": dt, "newton": NewtonSettings(relative_tolerance=tolerance),
            "friction_passes": passes}
    for label, model, dt, tolerance, passes in (
        (OUTCOME_REFERENCE, "3d", 0.00125, 1e-9, None),
        ("3d, dt 0.00125, tol 1e-6", "3d", 0.00125, 1e-6, None),
        ("3d, dt 0.00125, tol 1e-4", "3d", 0.00125, 1e-4, None),
        (OUTCOME_DEFAULT, "3d", 0.00125, 1e-4, 4),
        ("3d, dt 0.00125, tol 1e-4, friction 2 passes", "3d", 0.00125, 1e-4, 2),
        ("3d, dt 0.0025, tol 1e-4, friction 4 passes", "3d", 0.0025, 1e-4, 4),
        ("3d, dt 0.0025, tol 1e-4, friction 2 passes", "3d", 0.0025, 1e-4, 2),
        ("3d, dt 0.005, tol 1e-4", "3d", 0.005, 1e-4, None),
        ("3d, dt 0.005, tol 1e-4, friction 2 passes", "3d", 0.005, 1e-4, 2),
        ("3d, dt 0.01", "3d", 0.01, 1e-6, None),
        ("3d, dt 0.01, tol 1e-4", "3d", 0.01, 1e-4, None),
        ("3d, dt 0.025", "3d", 0.025, 1e-6, None),
        ("3d, dt 0.05", "3d", 0.05, 1e-6, None),
        ("planar, dt 0.00125, tol 1e-4, friction 2 passes", "planar", 0.00125, 1e-4, 2),
        ("planar, dt 0.005, tol 1e-4, friction 2 passes", "planar", 0.005, 1e-4, 2),
        ("planar, dt 0.01", "planar", 0.01, 1e-6, None),
        ("planar, dt 0.025", "planar", 0.025, 1e-6, None),
    )
}
"""The grasp-outcome scene's settings (GraspTask fields), by label; "tol" is Newton's relative tolerance, 1e-6 where
the label names none; "friction k passes" caps the corrector's re-solves for friction alone at k per physics step
(:attr:`~soft_gripper_env.physics.scene.objects.ContactSettings.friction_passes`), settled within the whole budget
where the label names none. N = 20 in all: the task's κ̄ is per node, so another node count would be another
gripper. The second row is the reference at tolerance 1e-6: how far the outcome of an episode moves under a change
far below anything the other settings make (the floor of the agreement any setting can reach)."""
OUTCOME_GOALS = {"label_agreement": 0.95, "median_position_gap_m": 0.005}


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
    parser.add_argument("--grasp-outcomes", action="store_true",
                        help="the grasp-outcome scene: each speed setting's episodes against the fine reference's")
    parser.add_argument("--episodes", type=int, default=200, help="seeds per controller (--grasp-outcomes)")
    parser.add_argument("--seed", type=int, default=7000, help="the first seed (--grasp-outcomes)")
    parser.add_argument("--workers", type=int, default=2, help="settings run at a time (--grasp-outcomes)")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.episodes < 1 or args.workers < 1:
        parser.error("--repeats, --episodes and --workers must be at least 1")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.grasp_outcomes:
        grasp_outcomes(args.episodes, args.seed, args.workers, args.out)
        return 0
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


def grasp_outcomes(episodes: int, seed: int, workers: int, out: Path) -> dict:
    """The grasp-outcome study (see the module's docstring); returns what it writes to grasp_outcomes.json.

    Each (setting, controller) run is kept in DIR/grasp_outcome_runs/ as it finishes, and a later call with the same
    episodes and seed takes it from there: an interrupted study resumes where it stopped."""
    from concurrent.futures import ProcessPoolExecutor

    from benchmarks.contact_outcomes import POLICIES, run_pair

    runs = out / "grasp_outcome_runs"
    runs.mkdir(parents=True, exist_ok=True)
    jobs = [(label, policy) for label in OUTCOME_SETTINGS for policy in POLICIES]
    results = {}
    for job in jobs:
        kept = _kept_run(runs, job, episodes, seed)
        if kept is not None:
            results[job] = kept
    missing = [job for job in jobs if job not in results]
    if missing:
        print(f"{len(missing)} runs of {episodes} episodes to do ({len(jobs) - len(missing)} kept from an earlier "
              f"call), {workers} at a time ...", flush=True)
        with ProcessPoolExecutor(workers) as pool:
            futures = {job: pool.submit(run_pair, OUTCOME_SETTINGS[job[0]]["model"], job[1], episodes, seed,
                                        **_task_fields(job[0])) for job in missing}
            for job, future in tqdm(futures.items(), desc="grasp outcomes", unit="run", file=sys.stdout):
                results[job] = future.result()
                (runs / _run_name(job)).write_text(json.dumps(results[job]))
    print("timing each setting alone (one env, the reactive controller) against Ant-v5 ...", flush=True)
    summary = summarize_outcomes(results, time_settings(seed), episodes, seed)
    (out / "grasp_outcomes.json").write_text(json.dumps(summary, indent=1))
    print(f"wrote {out / 'grasp_outcomes.json'}")
    plot_grasp_outcomes(summary, out / "grasp_outcomes.png")
    return summary


def summarize_outcomes(results: dict, speeds: dict, episodes: int, seed: int) -> dict:
    """The study's summary from the runs ``results`` {(label, controller): :func:`agents.evaluate.evaluate`'s
    result} and ``speeds`` (:func:`time_settings`): per setting and controller, the agreement with the reference
    (:func:`benchmarks.contact_outcomes.agreement`, and the median gap where the reference holds), and per setting
    the worst of its controllers, its speed and whether it meets :data:`OUTCOME_GOALS`. Prints the table."""
    from benchmarks.contact_outcomes import POLICIES, agreement

    speeds = dict(speeds)
    summary = {"episodes": episodes, "first_seed": seed, "reference": OUTCOME_REFERENCE, "default": OUTCOME_DEFAULT,
               "goals": OUTCOME_GOALS, "ant_v5_steps_per_s": speeds.pop("ant_v5"), "settings": {}}
    print(f"\n{episodes} seeds from {seed} per controller; agreement with the reference "
          f"({', '.join(f'{k} = {v}' for k, v in _describe(OUTCOME_REFERENCE).items())})\n")
    print("| setting | controller | success | labels agree | median gap [mm] | 90th pct [mm] | median gap where the "
          "reference holds [mm] | solver failures | env steps/s grasping, random (× Ant-v5) |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for label in OUTCOME_SETTINGS:
        speed = speeds[label]["grasping"]
        row = {"task": _describe(label), "env_steps_per_s": speed,
               "vs_ant_v5": speed / summary["ant_v5_steps_per_s"],
               "random_actions_env_steps_per_s": speeds[label]["random"],
               "random_actions_vs_ant_v5": speeds[label]["random"] / summary["ant_v5_steps_per_s"], "controllers": {}}
        for policy in POLICIES:
            result = results[(label, policy)]
            reference = results[(OUTCOME_REFERENCE, policy)]
            agree = agreement(result, reference)
            held = np.asarray(reference["successes"], dtype=bool)
            gap = np.linalg.norm(np.subtract(result["final_object_offsets"], reference["final_object_offsets"]),
                                 axis=1)
            agree["median_position_gap_where_reference_holds_m"] = float(np.median(gap[held])) if held.any() else None
            row["controllers"][policy] = {**agree, "success_rate": result["success_rate"],
                                          "solver_failures": result["endings"]["solver_failure"],
                                          "successes": result["successes"],
                                          "final_object_offsets": result["final_object_offsets"]}
            print(f"| {label} | {policy} | {result['success_rate']:.2f} | {agree['label_agreement']:.3f} |"
                  f" {1e3 * agree['median_position_gap_m']:.2f} | {1e3 * agree['p90_position_gap_m']:.1f} |"
                  f" {_millimetres(agree['median_position_gap_where_reference_holds_m'])} |"
                  f" {result['endings']['solver_failure']} | {speed:.0f}, {speeds[label]['random']:.0f} "
                  f"({row['vs_ant_v5']:.3f}×, {row['random_actions_vs_ant_v5']:.3f}×) |")
        controllers = row["controllers"].values()
        row["worst_label_agreement"] = min(c["label_agreement"] for c in controllers)
        row["worst_median_position_gap_m"] = max(c["median_position_gap_m"] for c in controllers)
        row["meets_goals"] = bool(label == OUTCOME_REFERENCE or (
            row["worst_label_agreement"] >= OUTCOME_GOALS["label_agreement"]
            and row["worst_median_position_gap_m"] <= OUTCOME_GOALS["median_position_gap_m"]))
        summary["settings"][label] = row
    print(f"\ngoals: labels agree on ≥ {OUTCOME_GOALS['label_agreement']:.0%} of seeds, median gap ≤ "
          f"{1e3 * OUTCOME_GOALS['median_position_gap_m']:g} mm, under both controllers")
    for label, row in summary["settings"].items():
        if label != OUTCOME_REFERENCE:
            print(f"  {label}: {'meets' if row['meets_goals'] else 'misses'} them (worst agreement "
                  f"{row['worst_label_agreement']:.3f}, worst median gap {1e3 * row['worst_median_position_gap_m']:.2f}"
                  f" mm){'  <- the default' if label == OUTCOME_DEFAULT else ''}")
    return summary


def time_settings(seed: int, steps: int = 240, repeats: int = 3) -> dict:
    """Env steps per second of every setting, one env for ``steps`` actions from seed ``seed`` (resetting as episodes
    end), the best of ``repeats``: grasping (the reactive controller) and on random actions (mostly free motion, as
    ``benchmarks.env_speed`` times it), as {label: {"grasping": …, "random": …}}; and Ant-v5's, timed in the same run
    (key ``"ant_v5"``)."""
    import gymnasium as gym

    import soft_gripper_env
    from agents.scripted import ReactivePolicy
    from benchmarks.env_speed import steps_per_second, time_ant
    from soft_gripper_env.grasp_task import GraspTask

    def once(label: str, grasping: bool) -> float:
        model = OUTCOME_SETTINGS[label]["model"]
        env = gym.make(soft_gripper_env.ENV_ID, model=model, **_task_fields(label))
        policy = ReactivePolicy(GraspTask(model=model, **_task_fields(label))) if grasping else None
        return steps_per_second(env, steps, policy, seed)

    speeds = {"ant_v5": max(time_ant() for _ in range(repeats))}
    for label in tqdm(OUTCOME_SETTINGS, desc="timing", unit="setting", file=sys.stdout):
        once(label, True)  # compile or load the kernels
        speeds[label] = {kind: max(once(label, kind == "grasping") for _ in range(repeats))
                         for kind in ("grasping", "random")}
    return speeds


def _millimetres(metres: float | None) -> str:
    return "—" if metres is None else f"{1e3 * metres:.2f}"


def _task_fields(label: str) -> dict:
    """A setting's GraspTask fields other than the model."""
    return {key: value for key, value in OUTCOME_SETTINGS[label].items() if key != "model"}


def _run_name(job: tuple[str, str]) -> str:
    return "".join(c if c.isalnum() else "_" for c in f"{job[0]}__{job[1]}") + ".json"


def _kept_run(runs: Path, job: tuple[str, str], episodes: int, seed: int) -> dict | None:
    """An earlier call's run of ``job`` on the same seeds and the same task, if kept."""
    from soft_gripper_env.grasp_task import GraspTask

    path = runs / _run_name(job)
    if not path.exists():
        return None
    kept = json.loads(path.read_text())
    task = repr(GraspTask(model=OUTCOME_SETTINGS[job[0]]["model"], **_task_fields(job[0])))
    return kept if (kept.get("episodes"), kept.get("first_seed"), kept.get("task")) == (episodes, seed, task) else None


def _describe(label: str) -> dict:
    """A setting's GraspTask fields, as JSON-ready values."""
    setting = OUTCOME_SETTINGS[label]
    return {"model": setting["model"], "physics_dt_s": setting["physics_dt"],
            "newton_relative_tolerance": setting["newton"].relative_tolerance,
            "friction_passes": setting["friction_passes"], "n_nodes": 20}


def plot_grasp_outcomes(summary: dict, path: Path) -> None:
    """Env speed against outcome error, one point per setting (the worse of the two controllers), the default
    ringed and the goals shaded."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, (*axes, key_axis) = plt.subplots(1, 3, figsize=(15.5, 5.5), gridspec_kw={"width_ratios": (1, 1, 0.5)})
    axes[1].sharex(axes[0])
    goals = summary["goals"]
    # Twenty labels side by side overlap where settings cost about the same, so each point carries a number and
    # the key beside the panels names it.
    numbers = {label: str(k + 1) for k, label in enumerate(
        label for label in summary["settings"] if label != summary["reference"])}
    panels = ((axes[0], lambda row: 1.0 - row["worst_label_agreement"], 1.0 - goals["label_agreement"],
               "share of seeds whose success label differs from the reference's"),
              (axes[1], lambda row: 1e3 * row["worst_median_position_gap_m"], 1e3 * goals["median_position_gap_m"],
               "median distance between final object positions [mm]"))
    for ax, value, goal, ylabel in panels:
        rows = [(label, row) for label, row in summary["settings"].items() if label != summary["reference"]]
        xs = [row["vs_ant_v5"] for _, row in rows]
        ax.axhspan(0.0, goal, color="tab:green", alpha=0.08, lw=0, label="goal: at most this")
        ax.axhline(goal, color="tab:green", ls="--", lw=1)
        for label, row in rows:
            x, y = row["vs_ant_v5"], value(row)
            color = "tab:blue" if row["task"]["model"] == "3d" else "tab:orange"
            ax.scatter(x, y, s=45, color=color, zorder=3)
            if label == summary["default"]:
                ax.scatter(x, y, s=260, facecolor="none", edgecolor="k", lw=1.5, zorder=4, label="the env's default")
            ax.annotate(numbers[label], (x, y), xytext=(9, 6) if label == summary["default"] else (4, 3),
                        textcoords="offset points", fontsize=8)
        ax.scatter([], [], color="tab:blue", label="3-D")
        ax.scatter([], [], color="tab:orange", label="planar")
        ax.set_xscale("log")
        ax.set_xlim(min(xs) / 1.3, max(xs) * 1.8)
        ax.xaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}×"))
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_ylim(bottom=0.0)
        ax.set_ylabel(ylabel)
        ax.set_xlabel(f"env steps per second of one env grasping (the reactive controller), as multiples of\nAnt-v5 "
                      f"({summary['ant_v5_steps_per_s']:,.0f} steps/s in the same run)", fontsize=8)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8, loc="center left")
    key = "\n".join(f"{numbers[label]:>2}  {label}{'  (the default)' if label == summary['default'] else ''}"
                    for label in numbers)
    key_axis.axis("off")
    key_axis.text(0.0, 0.5, key, fontsize=8, family="monospace", va="center", ha="left",
                  transform=key_axis.transAxes)
    reference_dt_ms = 1e3 * OUTCOME_SETTINGS[OUTCOME_REFERENCE]["physics_dt"]
    fig.suptitle(f"grasp outcomes of each speed setting against the fine reference (3-D, N = 20, "
                 f"Δt = {reference_dt_ms:g} ms, tolerance 1e-9)\n{summary['episodes']} seeds; each point the worse "
                 f"of the ramp and the reactive controller")
    save_plot(fig, path)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
