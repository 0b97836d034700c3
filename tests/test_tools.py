"""The refactoring guard (scripts/golden_outputs.py) and the commit comparison (benchmarks/compare_commits.py)."""

import subprocess
import sys
from pathlib import Path

import numpy as np

from benchmarks.compare_commits import higher_is_faster
from scripts.golden_outputs import compare

ROOT = Path(__file__).resolve().parents[1]


def test_golden_compare_tells_bitwise_close_and_different(tmp_path, capsys):
    before = {"a": np.array([1.0, 2.0]), "b": np.array([[0.1, 0.2]]), "c": np.array([True, False])}
    np.savez(tmp_path / "before.npz", **before)
    np.savez(tmp_path / "same.npz", **before)
    assert compare(tmp_path / "before.npz", tmp_path / "same.npz", 1e-12)
    assert "3 of 3 arrays bitwise equal" in capsys.readouterr().out

    np.savez(tmp_path / "close.npz", **{**before, "a": before["a"] + 1e-14})
    assert compare(tmp_path / "before.npz", tmp_path / "close.npz", 1e-12)
    assert "CLOSE  a" in capsys.readouterr().out

    np.savez(tmp_path / "far.npz", **{**before, "b": before["b"] + 1e-9})
    assert not compare(tmp_path / "before.npz", tmp_path / "far.npz", 1e-12)
    assert "DIFFERS  b" in capsys.readouterr().out

    np.savez(tmp_path / "missing.npz", a=before["a"], b=before["b"])
    assert not compare(tmp_path / "before.npz", tmp_path / "missing.npz", 1e-12)
    assert "MISSING  c" in capsys.readouterr().out


def test_compare_commits_reads_rates_and_times_the_right_way_round():
    assert higher_is_faster("single_steps_per_s")
    assert higher_is_faster("vector_64_env_steps_per_s")
    assert not higher_is_faster("seed_scene_planar_s")
    assert not higher_is_faster("batched_planar_us_per_gripper_step[64]")


def test_compare_commits_refuses_an_unknown_base():
    out = subprocess.run([sys.executable, "-m", "benchmarks.compare_commits", "--base", "no-such-commit"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "--base 'no-such-commit' is not a commit" in out.stderr
