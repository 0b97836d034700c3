"""Shared by the benchmark scripts: one thread everywhere, and best-of-N timing of the paper's ramp."""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from soft_gripper_env.physics import Scene, Trajectory, run_ramp  # noqa: E402


def time_ramp(scene: Scene, batch_size: int, repeats: int) -> tuple[float, Trajectory]:
    """Best wall time [s] of ``repeats`` whole scripted runs after a warm-up run (compilation excluded), and the
    warm-up's trajectory. With ``repeats`` = 0 it only warms up (the time is then infinite)."""
    trajectory = run_ramp(scene, batch_size)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run_ramp(scene, batch_size)
        best = min(best, time.perf_counter() - start)
    return best, trajectory


def parse_arguments(doc: str, plot_name: str, argv: list[str] | None) -> argparse.Namespace:
    """The command line shared by the timing benchmarks: --json, --plot and --repeats."""
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="write the results to this JSON file")
    parser.add_argument("--plot", type=Path, default=Path("out") / plot_name, help="plot path (PNG)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repetitions; the best counts (default 5)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats = {args.repeats} must be at least 1")
    return args


def save_plot(fig, path: Path) -> None:
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")
