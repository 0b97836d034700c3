"""What each part of a scene costs per step, and how far the planar and 3-D models agree where both apply.

    python -m benchmarks.medium_cost [--json PATH] [--plot PATH] [--repeats 5]

The paper's whole ramp (3 fingers, 100 steps of 0.01 s, N = 20) in air, with Stokes drag, in water, and with
Stokes drag and the paper's fixed ball (contact), single-threaded, best of ``--repeats`` after a warm-up, the
variants timed in turn: µs per gripper-step and the ratio to air in the same run. A scene pays only for what it
lists, so air is the floor. For each variant it also reports the largest distance between the planar and the 3-D
model's nodes over the run [m].
"""

from __future__ import annotations

import json
import sys

import numpy as np

from benchmarks._timing import parse_arguments, save_plot, time_ramp
from soft_gripper_env.physics import PAPER_BALL, paper_scene

MEDIA = ("air", "stokes", "water", "stokes+ball")
CONFIGURATIONS = (("planar", 1), ("3d", 1), ("planar", 64))


def variant_scene(model: str, variant: str):
    medium, _, obj = variant.partition("+")
    return paper_scene(model, medium=medium, grasped_object=PAPER_BALL if obj == "ball" else None)


def time_variants(model: str, batch_size: int, repeats: int) -> dict:
    """Best µs per gripper-step of every variant's whole paper ramp, the variants timed in turn (A, B, C, D, A, …)
    so that drift on a shared machine affects their ratios least; plus Newton iterations and trajectories."""
    scenes = {variant: variant_scene(model, variant) for variant in MEDIA}
    runs = {variant: time_ramp(scene, batch_size, 0)[1] for variant, scene in scenes.items()}  # warm-ups
    best = dict.fromkeys(MEDIA, float("inf"))
    for _ in range(repeats):
        for variant, scene in scenes.items():
            best[variant] = min(best[variant], time_ramp(scene, batch_size, 1)[0])
    return {variant: (best[variant] / (scenes[variant].n_steps * batch_size) * 1e6,
                      float(runs[variant].newton_iterations.mean()), runs[variant]) for variant in MEDIA}


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(__doc__, "medium_cost.png", argv)

    results, positions = {}, {}
    for model, batch in CONFIGURATIONS:
        key = f"{model}_B{batch}"
        results[key] = {}
        print(f"timing {model}, B = {batch}: {', '.join(MEDIA)} ...", flush=True)
        for medium, (us, iterations, run) in time_variants(model, batch, args.repeats).items():
            results[key][medium] = {"us_per_gripper_step": us, "newton_iterations_per_step": iterations}
            if batch == 1:
                positions[model, medium] = run.positions
    results["planar_vs_3d_max_distance_m"] = {
        medium: float(np.linalg.norm(positions["planar", medium] - positions["3d", medium], axis=-1).max())
        for medium in MEDIA}

    print()
    print(f"{'configuration':<14}" + "".join(f"{m + ' [µs]':>18}{'× air':>7}{'Newton':>7}" for m in MEDIA))
    for key, row in results.items():
        if key == "planar_vs_3d_max_distance_m":
            continue
        air = row["air"]["us_per_gripper_step"]
        cells = "".join(f"{row[m]['us_per_gripper_step']:18.1f}{row[m]['us_per_gripper_step'] / air:7.2f}"
                        f"{row[m]['newton_iterations_per_step']:7.2f}" for m in MEDIA)
        print(f"{key:<14}{cells}")
    print(f"{'planar vs 3-D':<14}" + "".join(f"{d:17.1e}m{'':>14}"
                                             for d in results["planar_vs_3d_max_distance_m"].values()))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 4.2))
    width = 0.2
    timed = {key: row for key, row in results.items() if key != "planar_vs_3d_max_distance_m"}
    x = np.arange(len(timed))
    for i, medium in enumerate(MEDIA):
        values = [row[medium]["us_per_gripper_step"] for row in timed.values()]
        bars = ax.bar(x + (i - 1.5) * width, values, width, label=medium)
        ax.bar_label(bars, fmt="%.0f", fontsize=7)
    ax.set_xticks(x, [key.replace("_B", ", B = ") for key in timed])
    ax.set_ylabel("µs per gripper-step (one core)")
    ax.set_title("cost of each part of a scene on the paper's ramp")
    ax.legend()
    save_plot(fig, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
