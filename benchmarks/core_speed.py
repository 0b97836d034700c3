"""Speed of the physics core, single-threaded: the paper's whole run, and batched planar throughput.

    python -m benchmarks.core_speed [--json PATH] [--plot PATH] [--repeats 5]

The paper-scene run is 3 fingers × 100 steps of 0.01 s with N = 20 (backward Euler, Newton to 1e-6·EI/L²),
timed whole, best of ``--repeats`` after a warm-up (compilation excluded). Batched throughput runs the same
planar scene for B grippers stepped together and reports µs per gripper-step. Goals (:data:`GOALS`, absolute on the
reference 2-core machine): planar run ≤ 2 ms, 3-D run ≤ 10 ms, batched planar ≤ 10 µs per gripper-step at B ≥ 64.
"""

from __future__ import annotations

import json
import sys

from benchmarks._timing import parse_arguments, save_plot, time_ramp
from soft_gripper_env.physics import paper_scene

BATCH_SIZES = (1, 16, 64, 256)
GOALS = {"paper_scene_planar_ms": 2.0, "paper_scene_3d_ms": 10.0, "batched_planar_us_per_gripper_step": 10.0}
"""The physics core's goals, absolute on the reference 2-core machine (``benchmarks/env_speed.py`` reports them
too, in the same run as its anchor)."""


def time_batched(batch_size: int, repeats: int) -> float:
    """µs per gripper-step of the planar paper scene's whole run, B grippers stepped as one batch."""
    scene = paper_scene("planar")
    return time_ramp(scene, batch_size, repeats)[0] / (scene.n_steps * batch_size) * 1e6


def main(argv: list[str] | None = None) -> int:
    args = parse_arguments(__doc__, "core_speed.png", argv)

    print("timing the paper scene (3 fingers, 100 steps, N = 20), single-threaded ...", flush=True)
    planar_s = time_ramp(paper_scene("planar"), 1, args.repeats)[0]
    spatial_s = time_ramp(paper_scene("3d"), 1, args.repeats)[0]
    batched = {}
    for b in BATCH_SIZES:
        print(f"timing batched planar, B = {b} ...", flush=True)
        batched[str(b)] = time_batched(b, args.repeats)

    print()
    print(f"{'measurement':<40}{'value':>12}{'goal':>12}{'goal / value':>14}")
    rows = [("paper scene, planar [ms]", planar_s * 1e3, GOALS["paper_scene_planar_ms"]),
            ("paper scene, 3-D [ms]", spatial_s * 1e3, GOALS["paper_scene_3d_ms"])]
    rows += [(f"batched planar, B = {b} [µs/gripper-step]", us,
              GOALS["batched_planar_us_per_gripper_step"] if int(b) >= 64 else None)
             for b, us in batched.items()]
    for label, value, goal in rows:
        goal_text = f"{goal:12.1f}{goal / value:13.2f}×" if goal else f"{'—':>12}{'—':>14}"
        print(f"{label:<40}{value:12.2f}{goal_text}")
    paper_code_s = 31.0
    print(f"\nspeed-up over the paper's own code (about {paper_code_s:.0f} s for this run on these machines): "
          f"planar {paper_code_s / planar_s:,.0f}×, 3-D {paper_code_s / spatial_s:,.0f}×")

    results = {"seed_scene_planar_s": planar_s, "seed_scene_3d_s": spatial_s,
               "batched_planar_us_per_gripper_step": batched}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.2))
    names = ["planar", "3-D"]
    values = [planar_s * 1e3, spatial_s * 1e3]
    goals = [GOALS["paper_scene_planar_ms"], GOALS["paper_scene_3d_ms"]]
    bars = ax0.bar(names, values, color=["tab:blue", "tab:orange"])
    ax0.scatter(names, goals, marker="_", s=900, color="k", zorder=3, label="goal")
    ax0.bar_label(bars, fmt="%.1f ms")
    ax0.set_ylabel("wall time of the whole run [ms]")
    ax0.set_title("paper scene: 3 fingers, 100 steps, N = 20")
    ax0.legend(loc="upper left")
    sizes = [int(b) for b in batched]
    ax1.loglog(sizes, list(batched.values()), "o-", label="planar, batched")
    ax1.axhline(GOALS["batched_planar_us_per_gripper_step"], color="k", ls="--", label="goal at B ≥ 64")
    ax1.set_xlabel("batch size B [grippers]")
    ax1.set_ylabel("µs per gripper-step")
    ax1.set_title("batched planar throughput (one core)")
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend()
    save_plot(fig, args.plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
