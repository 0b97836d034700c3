"""The refactoring guard (tools/golden_outputs.py), the commit comparison (tools/compare_commits.py), the
reference-count benchmark's reading of gdb (tools/refcounts.py), the profile's attribution of samples
(tools/profile_env.py), the grasp-outcome study's scoring (benchmarks/speed_vs_error.py) and env_speed's
ceiling (benchmarks/env_speed.py)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.env_speed import ceilings
from benchmarks.speed_vs_error import (
    OUTCOME_DEFAULT,
    OUTCOME_REFERENCE,
    OUTCOME_SETTINGS,
    plot_grasp_outcomes,
    summarize_outcomes,
)
from tools import refcounts
from tools.compare_commits import higher_is_faster, measurements, paired_case, plot_ratios, run_benchmark
from tools.golden_outputs import compare
from tools.profile_env import RUNTIME_BLOCK, attribute, profile
from tools.refcounts import by_function, debug_cache, demangle, hits

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
    out = subprocess.run([sys.executable, "-m", "tools.compare_commits", "--base", "no-such-commit"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "--base 'no-such-commit' is not a commit" in out.stderr


PROBE = """
import argparse, json, time
parser = argparse.ArgumentParser()
for flag in ("--repeats", "--json", "--plot"):
    parser.add_argument(flag)
args = parser.parse_args()
start_cpu, start = time.process_time(), time.perf_counter()
time.sleep(0.2)
json.dump({"slept_s": time.perf_counter() - start, "cpu_s": time.process_time() - start_cpu}, open(args.json, "w"))
"""


@pytest.mark.parametrize("clock", ["wall", "cpu"])
def test_compare_commits_times_each_tree_by_the_clock_asked_for(tmp_path, clock):
    """A benchmark that sleeps 0.2 s takes 0.2 s of wall time and almost no CPU time; the old commit's scripts read
    whichever clock through time.perf_counter."""
    (tmp_path / "tree" / "benchmarks").mkdir(parents=True)
    (tmp_path / "tree" / "benchmarks" / "probe.py").write_text(PROBE)
    result = run_benchmark(tmp_path / "tree", "probe", 1, tmp_path, clock)
    if clock == "wall":
        assert result["slept_s"] >= 0.2
    else:
        assert result["slept_s"] < 0.1
        assert result["slept_s"] == pytest.approx(result["cpu_s"], abs=0.02)


FAKE_PHYSICS = """
import time
from pathlib import Path
from types import SimpleNamespace

HERE = Path(__file__).parent
WARM_UP_S, RUN_S = {warm_up}, {run}


def paper_scene(model):
    return SimpleNamespace(n_steps=100)


def run_ramp(scene, batch_size):
    with open(HERE / "calls.txt", "a") as calls:
        calls.write(f"{{time.time()}}\\n")
    first = (HERE / "calls.txt").read_text().count("\\n") == 1
    end = time.process_time() + (WARM_UP_S if first else RUN_S * batch_size)
    while time.process_time() < end:  # busy: CPU time, as the paired runs measure it
        pass
"""


def test_paired_runs_start_timing_together_and_report_per_gripper_step(tmp_path):
    """Two fake trees whose warm-ups differ by 1 s: their timed runs still start together, and a tree whose run
    costs twice as much reads as half the speed, in µs per gripper-step."""
    trees = {}
    for side, warm_up, run in (("base", 1.0, 0.005), ("this", 0.0, 0.01)):
        package = tmp_path / side / "soft_gripper_env" / "physics"
        package.mkdir(parents=True)
        (package.parent / "__init__.py").write_text("")
        (package / "__init__.py").write_text(FAKE_PHYSICS.format(warm_up=warm_up, run=run))
        trees[side] = tmp_path / side
    cpus = sorted(os.sched_getaffinity(0))
    values = paired_case(trees, {"base": cpus[0], "this": cpus[-1]}, "batched_planar_us_per_gripper_step[16]",
                         3, "cpu")
    assert values["base"] == pytest.approx(0.005 / 100 * 1e6, rel=0.2)  # 0.005 s per gripper for 100 steps
    assert values["this"] == pytest.approx(0.01 / 100 * 1e6, rel=0.2)
    starts = {side: float((tree / "soft_gripper_env" / "physics" / "calls.txt").read_text().split()[1])
              for side, tree in trees.items()}
    assert abs(starts["base"] - starts["this"]) < 0.5


FAKE_ENV = """
import time

import gymnasium as gym
import numpy as np

ENV_ID = "PairedFake-{side}-v0"
STEP_S = {step}


class Fake(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (1,))
    action_space = gym.spaces.Box(-1.0, 1.0, (1,))

    def __init__(self, model="planar"):
        self.model = model

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {{}}

    def step(self, action):
        end = time.process_time() + STEP_S * (2 if action[0] > 1 else 1)  # an action outside the space: twice
        while time.process_time() < end:  # busy: CPU time, as the paired runs measure it
            pass
        return np.zeros(1, np.float32), 0.0, False, False, {{}}


gym.register(ENV_ID, entry_point=Fake)
"""


def test_paired_env_cases_report_env_steps_per_second_of_each_tree(tmp_path):
    """env_speed's one-env case, paired: a fake env whose step costs twice the CPU time reads as half the env steps
    per second."""
    trees = {}
    for side, step in (("base", 0.001), ("this", 0.002)):
        package = tmp_path / side / "soft_gripper_env"
        package.mkdir(parents=True)
        (package / "__init__.py").write_text(FAKE_ENV.format(side=side, step=step))
        trees[side] = tmp_path / side
    cpus = sorted(os.sched_getaffinity(0))
    values = paired_case(trees, {"base": cpus[0], "this": cpus[-1]}, "single_steps_per_s", 2, "cpu")
    assert values["base"] == pytest.approx(1000.0, rel=0.2)
    assert values["this"] == pytest.approx(500.0, rel=0.2)


FAKE_POLICY = """
import numpy as np


class ReactivePolicy:
    def __init__(self, task):
        self.task = task

    def __call__(self, observation):
        return np.full(1, 2.0, np.float32)  # outside the action space: the fake env's step takes twice as long
"""

FAKE_TASK = """
class GraspTask:
    def __init__(self, model="planar"):
        self.model = model
"""


def test_paired_grasping_cases_drive_the_env_with_the_reactive_controller_of_each_tree(tmp_path):
    """The grasping cases take each tree's reactive controller: the fake env's step costs twice as long on its
    actions as on random ones, so both trees read half of what random actions give."""
    trees = {}
    for side in ("base", "this"):
        package = tmp_path / side / "soft_gripper_env"
        package.mkdir(parents=True)
        (package / "__init__.py").write_text(FAKE_ENV.format(side=side, step=0.001))
        (package / "grasp_task.py").write_text(FAKE_TASK)
        (tmp_path / side / "agents").mkdir()
        (tmp_path / side / "agents" / "__init__.py").write_text("")
        (tmp_path / side / "agents" / "scripted.py").write_text(FAKE_POLICY)
        trees[side] = tmp_path / side
    cpus = sorted(os.sched_getaffinity(0))
    values = paired_case(trees, {"base": cpus[0], "this": cpus[-1]}, "single_grasping_steps_per_s", 2, "cpu")
    assert values["base"] == pytest.approx(500.0, rel=0.2)
    assert values["this"] == pytest.approx(500.0, rel=0.2)


def test_compare_commits_plots_the_rounds_it_ran(tmp_path):
    results = {"base": "a" * 40, "head": "b" * 40, "rounds": 2, "clock": "cpu", "paired": True,
               "rows": [{"measurement": "seed_scene_planar_s", "speed_ratio": 1.02, "round_ratios": [0.97, 1.05],
                         "median_round_ratio": 1.01},
                        {"measurement": "batched_planar_us_per_gripper_step[64]", "speed_ratio": 0.9,
                         "round_ratios": [0.88, 0.93], "median_round_ratio": 0.905}]}
    plot_ratios(results, tmp_path / "ratios.png")
    assert (tmp_path / "ratios.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_refcounts_reads_each_breakpoints_hits_from_gdb_and_refuses_output_without_both():
    listing = ("Num     Type           Disp Enb Address            What\n"
               "1       breakpoint     keep y   0x00007ffff7361050 <NRT_incref>\n"
               "\tbreakpoint already hit 78837 times\n\tignore next 99921163 hits\n"
               "2       breakpoint     keep y   0x00007ffff7361060 <NRT_decref>\n"
               "\tbreakpoint already hit 1 time\n")
    assert hits(listing) == (78837, 1)
    with pytest.raises(RuntimeError, match="two breakpoints"):
        hits(listing.split("2       breakpoint")[0])


def test_allocation_census_breaks_on_functions_the_runtime_has_and_needs_an_env(capsys):
    """Every allocator the census sets a breakpoint on is a symbol of Numba's runtime once it has started (a name
    that is not would break nowhere and count nothing), and --allocations without --env is refused by name."""
    import llvmlite.binding as llvm
    import numba
    from numba.core.runtime import rtsys

    numba.njit(lambda: 0)()  # starts the runtime, which registers its symbols
    assert rtsys._init
    assert all(llvm.address_of_symbol(name) for name in refcounts.ALLOCATORS)
    with pytest.raises(SystemExit):
        refcounts.main(["--allocations"])
    assert "--allocations counts within env steps: give --env MODEL" in capsys.readouterr().err


def test_refcounts_names_numbas_functions_and_gives_each_return_address_to_the_function_holding_it():
    mangled = ("_ZN16soft_gripper_env7physics7kernels7contact17contact_reactionsB4v317B56c8tJTIeFIjxB2IKSgI4CrvQCk0Z4y"
               "RYcWsBAK4JJIqUWsIgmAA_3d_3dE5ArrayIdLi3E1C7mutable7alignedE")
    assert demangle(mangled) == "kernels.contact.contact_reactions"
    assert demangle("_ZN5numba2np6linalg10solve_implB4v252E") == "numba.np.linalg.solve_impl"
    assert demangle("NRT_incref") == "NRT_incref"
    symbols = {mangled: (0x100, 0x40), "_ZN16soft_gripper_env7physics7solvers8stepping10take_stepsB2v5E": (0, 0x100)}
    counts = by_function([(0x10, 3), (0x100, 5), (0x13F, 1), (0x140, 2), (0xFF, 4)], symbols)
    assert counts == {"solvers.stepping.take_steps": 7, "kernels.contact.contact_reactions": 6, "elsewhere": 2}
    assert list(counts) == ["solvers.stepping.take_steps", "kernels.contact.contact_reactions", "elsewhere"]


def test_compare_commits_refuses_a_revision_that_is_not_a_commit():
    tree = subprocess.run(["git", "rev-parse", "HEAD^{tree}"], cwd=ROOT, capture_output=True, text=True).stdout
    out = subprocess.run([sys.executable, "-m", "tools.compare_commits", "--base", tree.strip()], cwd=ROOT,
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


def test_profile_gives_each_sample_to_a_compiled_function_the_reference_counts_or_perfs_symbol():
    drag = "_ZN16soft_gripper_env7physics7kernels6forces12morison_dragB4v123E"
    steps = "_ZN16soft_gripper_env7physics7solvers8stepping10take_stepsB4v456E"
    symbols = {drag: (0, 100), steps: (100, 50)}
    base, runtime = 10_000, 50_000
    samples = [(base + 10, "[unknown]"), (base + 99, "[unknown]"), (base + 120, ""),  # compiled
               (runtime + 9, "[unknown]"), (runtime + RUNTIME_BLOCK - 1, "[unknown]"),  # reference counts
               (runtime + RUNTIME_BLOCK, "[unknown]"), (base + 150, "[unknown]"),  # just outside both: unknown
               (90_000, "_PyEval_EvalFrameDefault")]
    assert attribute(samples, base, symbols, runtime) == {
        "kernels.forces.morison_drag": 2, "runtime (reference counts)": 2, "unknown": 2,
        "solvers.stepping.take_steps": 1, "_PyEval_EvalFrameDefault": 1}


def test_profile_refuses_a_policy_it_does_not_know():
    with pytest.raises(ValueError, match="policy = 'ppo' must be one of"):
        profile("planar", 1, 1, 1000, policy="ppo")


def test_refcounts_debug_cache_is_a_folder_per_version_of_the_source(tmp_path, monkeypatch):
    monkeypatch.setattr(refcounts, "DEBUG_CACHE", tmp_path / "cache")
    tree = tmp_path / "tree"
    (tree / "soft_gripper_env" / "physics").mkdir(parents=True)
    kernel = tree / "soft_gripper_env" / "physics" / "kernel.py"
    kernel.write_text("x = 1\n")
    first = debug_cache(tree)
    first.mkdir(parents=True)
    assert debug_cache(tree) == first and first.exists()  # the same source: the same cache, kept
    kernel.write_text("x = 2\n")  # an edit in any file of the package, whose functions others may inline
    second = debug_cache(tree)
    assert second != first and not first.exists()  # a new cache, and the stale one gone
    (tree / "soft_gripper_env" / "README.txt").write_text("not source")
    assert debug_cache(tree) == second


def test_function_symbols_reads_readelf_sizes_in_decimal_and_hexadecimal(monkeypatch):
    """readelf -sW prints a symbol's size in decimal below 100,000 bytes and in hexadecimal from there (a large
    compiled step's); both are read, and only defined functions are kept."""
    listing = """
Symbol table '.symtab' contains 4 entries:
   Num:    Value          Size Type    Bind   Vis      Ndx Name
     1: 0000000000001000  2048 FUNC    GLOBAL DEFAULT    1 small_function
     2: 0000000000002000 0x18fb4 FUNC    GLOBAL DEFAULT    1 large_function
     3: 0000000000000000     0 FUNC    GLOBAL DEFAULT  UND NRT_MemInfo_alloc
     4: 0000000000003000    16 OBJECT  GLOBAL DEFAULT    2 a_constant
"""
    monkeypatch.setattr(refcounts.subprocess, "run",
                        lambda *args, **kwargs: subprocess.CompletedProcess(args, 0, stdout=listing, stderr=""))
    assert refcounts.function_symbols(Path("any.o")) == {"small_function": (0x1000, 2048),
                                                         "large_function": (0x2000, 0x18FB4)}


def test_env_speed_ceiling_is_substeps_times_the_fingers_alone_and_gives_each_goal_its_most_substeps():
    """Ant-v5 at 1,000 steps/s; the fingers alone at 50 µs per gripper-step planar (10 substeps) and 100 µs in 3-D
    (20): an env step costs at least 500 and 2,000 µs, at most 2,000 and 500 steps/s (2× and 0.5× Ant-v5). A goal of
    g× Ant-v5 leaves 1e6 / (g · 1000) µs per action: 10 planar substeps for one env (2×), 2 for make_vec(64) (10×),
    20 and 5 in 3-D (0.5×, 2×)."""
    result = ceilings(1000.0, {"planar": 50.0, "3d": 100.0}, {"planar": 10, "3d": 20})
    planar, spatial = result["planar"], result["3d"]
    assert planar["env_steps_per_s_at_most"] == pytest.approx(2000.0) and planar["vs_ant_v5"] == pytest.approx(2.0)
    assert spatial["env_steps_per_s_at_most"] == pytest.approx(500.0) and spatial["vs_ant_v5"] == pytest.approx(0.5)
    assert planar["most_substeps_for_goal"] == {"single": 10, "vec64": 2}
    assert spatial["most_substeps_for_goal"] == {"single_3d": 20, "vec64_3d": 5}
    # the derived figures are not read as timings by compare_commits; the one measurement is
    assert set(measurements({"ceiling": result})) == {"ceiling[planar][fingers_alone_us_per_gripper_step]",
                                                      "ceiling[3d][fingers_alone_us_per_gripper_step]"}
    with pytest.raises(ValueError, match="planar: µs per gripper-step 0.0"):
        ceilings(1000.0, {"planar": 0.0}, {"planar": 10})


def test_first_step_refuses_an_unknown_model_rounds_or_base(capsys):
    from tools import first_step

    for argv, named in ((["--models", "4d"], "--models"), (["--rounds", "0"], "--rounds"),
                        (["--base", "no-such-commit"], "--base")):
        with pytest.raises(SystemExit):
            first_step.main(argv)
        assert named in capsys.readouterr().err


def test_first_step_adds_a_processes_phases_and_plots_its_bars(tmp_path):
    from tools.first_step import plot, total

    phases = {"import": {"wall_s": 1.0, "cpu_s": 0.5}, "make_and_reset": {"wall_s": 2.0, "cpu_s": 1.5},
              "first_step": {"wall_s": 40.0, "cpu_s": 30.0}}
    assert total(phases, "cpu_s") == 32.0 and total(phases, "wall_s") == 43.0
    results = {"trees": {"this": {"3d": {"empty_cache": phases, "warm_cache": phases}}}}
    plot(results, ["3d"], tmp_path / "first_step.png")
    assert (tmp_path / "first_step.png").stat().st_size > 0


def test_first_step_times_the_demos_own_commands(tmp_path):
    """The demo it times is scripts/demo.sh's, command for command, so the two cannot drift apart."""
    from tools.first_step import demo_commands

    root = Path(__file__).resolve().parents[1]
    commands = demo_commands(root, tmp_path)
    script = (root / "scripts" / "demo.sh").read_text()
    assert len(commands) == script.count("\n.venv/bin/python ") >= 4
    assert all(command[:2] == [sys.executable, "-c"] and command[3] == str(root) for command in commands)
    assert [command[4] for command in commands] == ["soft_gripper_env.precompile", "examples.reproduce_paper",
                                                    "examples.record_video", "examples.record_video"]
    assert all(str(tmp_path) in " ".join(command[4:]) and "$out" not in " ".join(command) for command in commands[1:])
    demo = tmp_path / "tree" / "scripts" / "demo.sh"
    demo.parent.mkdir(parents=True)
    demo.write_text(".venv/bin/python examples/record_video.py --out $out\n")
    with pytest.raises(ValueError, match="python -m MODULE"):
        demo_commands(tmp_path / "tree", tmp_path)


def test_the_gpu_session_script_parses_and_refuses_an_unknown_part(tmp_path):
    """tools/gpu_session.sh, run on a lent GPU: valid bash, and a part it does not know stops it before anything
    runs (no results folder made)."""
    script = Path(__file__).resolve().parent.parent / "tools" / "gpu_session.sh"
    assert subprocess.run(["bash", "-n", str(script)], capture_output=True).returncode == 0
    out = tmp_path / "gpu"
    run = subprocess.run(["bash", str(script), "sideways"], capture_output=True, text=True,
                         env={**os.environ, "OUT": str(out)})
    assert run.returncode == 2 and "usage: bash tools/gpu_session.sh speed|outcomes|tests" in run.stderr
    assert not out.exists()
