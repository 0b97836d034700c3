"""The example and benchmark scripts run as users call them, and write what they promise."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from soft_gripper_env.physics import paper_scene, run_ramp

ROOT = Path(__file__).resolve().parents[2]


def run_script(*args, timeout=600):
    out = subprocess.run([sys.executable, *map(str, args)], cwd=ROOT, capture_output=True, text=True,
                         timeout=timeout)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_reproduce_paper_writes_png_and_tip_csv(tmp_path):
    stdout = run_script("-m", "examples.reproduce_paper", "--out", tmp_path, "--model", "planar", "--case", "fig5",
                        "fig12")
    assert "[2/2] fig12" in stdout
    for name in ("fig5.png", "fig12.png", "fig12_soft_translucent.csv"):
        assert (tmp_path / name).stat().st_size > 0
    with open(tmp_path / "fig5.csv") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["time_s", "tip_x_m", "tip_y_m", "tip_z_m"]
    data = np.array(rows[1:], dtype=float)
    assert data.shape == (100, 4)
    np.testing.assert_allclose(data[:, 0], 0.01 * np.arange(1, 101))  # the state after each step
    expected = run_ramp(paper_scene("planar")).positions[1:, 0, 0, -1]
    np.testing.assert_allclose(data[:, 1:], expected, rtol=1e-8, atol=1e-12)
    assert (tmp_path / "fig5.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_reproduce_paper_writes_contact_csv(tmp_path):
    run_script("-m", "examples.reproduce_paper", "--out", tmp_path, "--model", "planar", "--case", "fig10")
    with open(tmp_path / "fig10_contacts.csv") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["time_s", "finger", "node", "x_m", "y_m", "z_m", "fx_N", "fy_N", "fz_N", "fn_N"]
    data = np.array(rows[1:], dtype=float)
    assert len(data) >= 3 and set(data[:, 1]) == {1.0, 2.0, 3.0}
    assert np.all(data[:, 9] >= 0)  # compression only
    radius = np.linalg.norm(data[:, 3:6] - np.array([0.0, 0.0, -0.09]), axis=1)
    np.testing.assert_allclose(radius, 0.065, atol=1e-9)  # held nodes sit on the ball
    assert (tmp_path / "fig10.csv").exists() and (tmp_path / "fig10.png").stat().st_size > 0


def test_reproduce_paper_rejects_unknown_case(tmp_path):
    out = subprocess.run([sys.executable, "-m", "examples.reproduce_paper", "--out", str(tmp_path), "--case", "fig99"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2 and "invalid choice: 'fig99'" in out.stderr


def test_cantilever_json(tmp_path):
    path = tmp_path / "c.json"
    stdout = run_script("-m", "examples.cantilever", "--nodes", "20", "--clamp", "accurate", "--json", path)
    result = json.loads(path.read_text())
    assert result["exact_tip_z_m"] == pytest.approx(-14.95e-3, abs=0.01e-3)
    assert abs(result["tip_z_m"] / result["exact_tip_z_m"] - 1) < 0.01
    assert "exact elastica" in stdout


def test_cantilever_rejects_bad_node_count():
    out = subprocess.run([sys.executable, "-m", "examples.cantilever", "--nodes", "3"], cwd=ROOT, capture_output=True,
                         text=True)
    assert out.returncode == 2 and "FingerDesign.n_nodes = 3" in out.stderr


@pytest.mark.slow
def test_core_speed_benchmark_writes_json_and_plot(tmp_path):
    stdout = run_script("-m", "benchmarks.core_speed", "--repeats", "1", "--json", tmp_path / "s.json", "--plot",
                        tmp_path / "s.png")
    result = json.loads((tmp_path / "s.json").read_text())
    assert set(result) == {"seed_scene_planar_s", "seed_scene_3d_s", "batched_planar_us_per_gripper_step"}
    assert set(result["batched_planar_us_per_gripper_step"]) == {"1", "16", "64", "256"}
    assert all(v > 0 for v in result["batched_planar_us_per_gripper_step"].values())
    assert (tmp_path / "s.png").stat().st_size > 0
    assert "goal / value" in stdout


def test_water_vs_air_example(tmp_path):
    stdout = run_script("-m", "examples.water_vs_air", "--out", tmp_path)
    with open(tmp_path / "water_vs_air.csv") as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["time_s", "tip_z_air_m", "tip_z_stokes_m", "tip_z_water_m"]
    data = np.array(rows[1:], dtype=float)
    assert data.shape == (100, 4)
    # water closes the finger more slowly than air: at 0.15 s the tip is still much higher
    assert data[14, 3] > data[14, 1] + 0.03
    assert (tmp_path / "water_vs_air.png").stat().st_size > 0
    assert "peak drag" in stdout


def test_water_vs_air_rejects_bad_time_step(tmp_path):
    out = subprocess.run([sys.executable, "-m", "examples.water_vs_air", "--out", str(tmp_path), "--time-step", "-1"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2 and "Scene.time_step = -1.0 s" in out.stderr


@pytest.mark.slow
def test_medium_cost_benchmark(tmp_path):
    stdout = run_script("-m", "benchmarks.medium_cost", "--repeats", "1", "--json", tmp_path / "m.json", "--plot",
                        tmp_path / "m.png")
    result = json.loads((tmp_path / "m.json").read_text())
    assert set(result) == {"planar_B1", "3d_B1", "planar_B64", "planar_vs_3d_max_distance_m"}
    assert set(result["planar_B1"]) == {"air", "stokes", "water", "stokes+ball"}
    assert max(result["planar_vs_3d_max_distance_m"].values()) < 1e-6  # the models agree where both apply
    assert "× air" in stdout and (tmp_path / "m.png").stat().st_size > 0


@pytest.mark.slow
def test_speed_vs_error_quick(tmp_path):
    stdout = run_script("-m", "benchmarks.speed_vs_error", "--out", tmp_path, "--quick", "--repeats", "1")
    with open(tmp_path / "speed_vs_error.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0]) == ["scene", "model", "integrator", "n_nodes", "dt_s", "wall_s_per_sim_s", "max_tip_error_m",
                             "steady_tip_z_m"]
    assert {row["scene"] for row in rows} == {"cantilever_damped", "cantilever_undamped"}
    assert {row["integrator"] for row in rows} == {"backward_euler", "implicit_midpoint", "midpoint_triple_jump",
                                                     "midpoint_suzuki"}
    errors = {(r["scene"], r["integrator"], r["n_nodes"], r["dt_s"]): float(r["max_tip_error_m"]) for r in rows}
    # on the damped cantilever, errors fall as Δt falls, and midpoint beats backward Euler at Δt = 1e-2
    assert errors[("cantilever_damped", "implicit_midpoint", "20", "0.001")] < \
        errors[("cantilever_damped", "implicit_midpoint", "20", "0.01")]
    assert errors[("cantilever_damped", "implicit_midpoint", "20", "0.01")] < \
        errors[("cantilever_damped", "backward_euler", "20", "0.01")]
    # undamped at Δt = 1e-2: the triple jump keeps the phase that the midpoint rule loses
    assert errors[("cantilever_undamped", "midpoint_triple_jump", "20", "0.01")] < \
        0.3 * errors[("cantilever_undamped", "implicit_midpoint", "20", "0.01")]
    assert errors[("cantilever_undamped", "midpoint_suzuki", "20", "0.02")] < \
        0.3 * errors[("cantilever_undamped", "midpoint_triple_jump", "20", "0.02")]
    steady = [float(r["steady_tip_z_m"]) for r in rows if r["scene"] == "cantilever_damped" and r["dt_s"] == "0.001"]
    assert all(-0.0152 < z < -0.0145 for z in steady)  # settles near the elastica's 14.95 mm
    assert (tmp_path / "cantilever_damped.png").stat().st_size > 0
    assert "goal ≤ 0.01 wall s/sim s" in stdout
