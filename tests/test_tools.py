"""The refactoring guard (scripts/golden_outputs.py), the commit comparison (benchmarks/compare_commits.py), the
reference-count benchmark's reading of gdb (benchmarks/refcounts.py) and the grasp-outcome study's scoring
(benchmarks/speed_vs_error.py)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.compare_commits import higher_is_faster, measurements
from benchmarks.refcounts import hits
from benchmarks.speed_vs_error import (
    OUTCOME_DEFAULT,
    OUTCOME_REFERENCE,
    OUTCOME_SETTINGS,
    plot_grasp_outcomes,
    summarize_outcomes,
)
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


def test_compare_commits_keeps_measurements_and_leaves_out_ratios_and_goals():
    """env_speed's JSON nests two levels deep; the comparison takes the timed numbers only."""
    results = {"ant_v5_steps_per_s": 3000.0, "vector_sizes": [1, 64],
               "ratios_to_ant_v5": {"single_vs_ant_v5": 0.2}, "two_threads_over_one": {"planar": 1.7},
               "core": {"paper_scene_planar_ms": 5.0, "batched_planar_us_per_gripper_step": 29.0},
               "batched_planar_us_per_gripper_step": {"1": 40.0, "64": 29.0},
               "goals": {"single_steps_per_s": {"goal_vs_ant_v5": 2.0, "reached_vs_ant_v5": 0.2, "met": False}}}
    assert measurements(results) == {
        "ant_v5_steps_per_s": 3000.0, "core[paper_scene_planar_ms]": 5.0,
        "core[batched_planar_us_per_gripper_step]": 29.0, "batched_planar_us_per_gripper_step[1]": 40.0,
        "batched_planar_us_per_gripper_step[64]": 29.0}


def test_compare_commits_refuses_an_unknown_base():
    out = subprocess.run([sys.executable, "-m", "benchmarks.compare_commits", "--base", "no-such-commit"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "--base 'no-such-commit' is not a commit" in out.stderr


def test_refcounts_reads_each_breakpoints_hits_from_gdb_and_refuses_output_without_both():
    listing = ("Num     Type           Disp Enb Address            What\n"
               "1       breakpoint     keep y   0x00007ffff7361050 <NRT_incref>\n"
               "\tbreakpoint already hit 78837 times\n\tignore next 99921163 hits\n"
               "2       breakpoint     keep y   0x00007ffff7361060 <NRT_decref>\n"
               "\tbreakpoint already hit 1 time\n")
    assert hits(listing) == (78837, 1)
    with pytest.raises(RuntimeError, match="two breakpoints"):
        hits(listing.split("2       breakpoint")[0])


def test_compare_commits_refuses_a_revision_that_is_not_a_commit():
    tree = subprocess.run(["git", "rev-parse", "HEAD^{tree}"], cwd=ROOT, capture_output=True, text=True).stdout
    out = subprocess.run([sys.executable, "-m", "benchmarks.compare_commits", "--base", tree.strip()], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "is not a commit" in out.stderr


def test_the_outcome_studys_default_is_the_envs():
    """The setting the study marks as the default is what GraspTask() runs with (the 3-D model's defaults)."""
    from soft_gripper_env.grasp_task import GraspTask

    task, setting = GraspTask(), OUTCOME_SETTINGS[OUTCOME_DEFAULT]
    assert (task.model, task.physics_dt, task.newton, task.friction_passes) == (
        setting["model"], setting["physics_dt"], setting["newton"], setting["friction_passes"])


def test_grasp_outcome_summary_scores_settings_against_the_reference(tmp_path):
    """On synthetic runs of 20 seeds: a setting equal to the reference meets the goals; one that flips 2 labels of
    one controller (90 % agreement) misses them, as does one that leaves every object 6 mm away; the worse
    controller decides; the gap where the reference holds counts only those seeds; the plot is written."""
    seeds = 20
    rng = np.random.default_rng(0)
    successes = rng.random(seeds) < 0.5
    positions = rng.normal(size=(seeds, 3)) * 0.05

    def run(successes, positions):
        return {"successes": [bool(x) for x in successes], "final_object_offsets": positions.tolist(),
                "success_rate": float(np.mean(successes)), "endings": {"solver_failure": 0}}

    flipped = successes.copy()
    flipped[:2] = ~flipped[:2]
    shifted = positions + np.array([0.006, 0.0, 0.0])
    labels = list(OUTCOME_SETTINGS)
    other, far = [label for label in labels if label not in (OUTCOME_REFERENCE, OUTCOME_DEFAULT)][:2]
    results = {}
    for label in labels:
        for policy in ("ramp", "reactive"):
            results[(label, policy)] = run(successes, positions)
    results[(other, "reactive")] = run(flipped, positions)
    for policy in ("ramp", "reactive"):
        results[(far, policy)] = run(successes, shifted)
    speeds = {"ant_v5": 1000.0, **{label: {"grasping": 10.0 + k, "random": 20.0 + k} for k, label in enumerate(labels)}}
    summary = summarize_outcomes(results, speeds, seeds, 7000)
    rows = summary["settings"]
    assert rows[OUTCOME_DEFAULT]["meets_goals"] and rows[OUTCOME_DEFAULT]["worst_label_agreement"] == 1.0
    assert rows[other]["worst_label_agreement"] == 0.9 and not rows[other]["meets_goals"]
    assert rows[other]["controllers"]["ramp"]["label_agreement"] == 1.0
    assert rows[far]["worst_median_position_gap_m"] == pytest.approx(0.006) and not rows[far]["meets_goals"]
    held_gap = rows[far]["controllers"]["ramp"]["median_position_gap_where_reference_holds_m"]
    assert held_gap == pytest.approx(0.006)
    assert rows[far]["vs_ant_v5"] == pytest.approx(speeds[far]["grasping"] / 1000.0)
    plot_grasp_outcomes(summary, tmp_path / "outcomes.png")
    assert (tmp_path / "outcomes.png").stat().st_size > 10_000
