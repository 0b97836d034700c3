"""What each medium costs per step: the paper's scene in air, with Stokes drag, and in water, side by side.

    python benchmarks/medium_cost.py [--json PATH] [--plot PATH] [--repeats 5]

Each row is the paper's whole ramp (3 fingers, 100 steps of 0.01 s, N = 20), single-threaded, best of
``--repeats`` after a warm-up, as µs per gripper-step, with its ratio to air in the same run. A scene pays only for
the fluid forces it lists, so air is the floor.
"""

from __future__ import annotations

import json
import sys

from _timing import parse_arguments, save_plot, time_ramp

from soft_gripper_env.physics import paper_scene

MEDIA = ("air", "stokes", "water")
CONFIGURATIONS = (("planar", 1), ("3d", 1), ("planar", 64))


def time_run(model: str, medium: str, batch_size: int, repeats: int) -> tuple[float, float]:
    """(µs per gripper-step, mean Newton iterations per step) of the whole paper ramp."""
    scene = paper_scene(model, medium=medium)
    best, run = time_ramp(scene, batch_size, repeats)
    return best / (scene.n_steps * batch_size) * 1e6, float(run.newton_iterations.mean())


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(__doc__, "medium_cost.png", argv)

    results = {}
    for model, batch in CONFIGURATIONS:
        key = f"{model}_B{batch}"
        results[key] = {}
        for medium in MEDIA:
            print(f"timing {model}, B = {batch}, {medium} ...", flush=True)
            us, iterations = time_run(model, medium, batch, args.repeats)
            results[key][medium] = {"us_per_gripper_step": us, "newton_iterations_per_step": iterations}

    print()
    print(f"{'configuration':<16}" + "".join(f"{m + ' [µs]':>14}{'× air':>8}{'Newton':>8}" for m in MEDIA))
    for key, row in results.items():
        air = row["air"]["us_per_gripper_step"]
        cells = "".join(f"{row[m]['us_per_gripper_step']:14.1f}{row[m]['us_per_gripper_step'] / air:8.2f}"
                        f"{row[m]['newton_iterations_per_step']:8.2f}" for m in MEDIA)
        print(f"{key:<16}{cells}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    width = 0.25
    x = np.arange(len(results))
    for i, medium in enumerate(MEDIA):
        values = [row[medium]["us_per_gripper_step"] for row in results.values()]
        bars = ax.bar(x + (i - 1) * width, values, width, label=medium)
        ax.bar_label(bars, fmt="%.0f", fontsize=7)
    ax.set_xticks(x, [key.replace("_B", ", B = ") for key in results])
    ax.set_ylabel("µs per gripper-step (one core)")
    ax.set_title("cost of each medium on the paper's ramp")
    ax.legend()
    save_plot(fig, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
