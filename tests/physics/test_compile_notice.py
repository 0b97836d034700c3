"""The one line a first compile prints (soft_gripper_env/physics/kernels/compile_notice.py)."""

import os
import subprocess
import sys
from pathlib import Path

from soft_gripper_env.physics.kernels.compile_notice import NOTICE

ROOT = Path(__file__).resolve().parents[2]
_SOLVE = """
import numpy as np
from soft_gripper_env.physics.kernels.linalg import solve_dense, symmetric_band_entry
a, x = np.array([[2.0, 1.0], [1.0, 3.0]]), np.array([3.0, 5.0])
assert solve_dense(a, x) and np.allclose(x, [0.8, 1.4])
band = np.array([[0.0, 4.0], [1.0, 5.0]])  # two functions compiled, one notice
assert symmetric_band_entry(band, 0, 1) == symmetric_band_entry(band, 1, 0)
from soft_gripper_env.physics.kernels.compile_notice import LISTENER
print("compiled", LISTENER.compiled)
"""


def _run(cache: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    run = subprocess.run([sys.executable, "-c", _SOLVE], capture_output=True, text=True, env=env, cwd=ROOT,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    return run


def test_a_first_compile_says_so_once_and_a_load_from_the_cache_says_nothing(tmp_path):
    """The notice once, though two functions compiled, and the count of them; from the cache, neither."""
    first = _run(tmp_path)
    assert first.stderr.count(NOTICE) == 1
    assert first.stdout.split() == ["compiled", "2"]
    second = _run(tmp_path)  # every kernel it needs is in the cache now
    assert second.stderr.count(NOTICE) == 0
    assert second.stdout.split() == ["compiled", "0"]
