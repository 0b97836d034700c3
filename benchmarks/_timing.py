"""Shared by the benchmark scripts: one thread everywhere, and best-of-N timing of the paper's ramp."""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import time  # noqa: E402
from pathlib import Path  # noqa: E402

from soft_gripper_env.physics import Scene, Trajectory, run_ramp  # noqa: E402


def time_ramp(scene: Scene, batch_size: int, repeats: int) -> tuple[float, Trajectory]:
    """Best wall time [s] of ``repeats`` whole scripted runs after a warm-up run (compilation excluded)."""
    trajectory = run_ramp(scene, batch_size)
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run_ramp(scene, batch_size)
        best = min(best, time.perf_counter() - start)
    return best, trajectory


def save_plot(fig, path: Path) -> None:
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")
