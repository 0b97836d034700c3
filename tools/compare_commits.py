"""Speed of this tree against an older commit, side by side in one run: the anchor is timed with the same machine
load, so the ratio holds even when the machine's own speed drifts.

    python -m tools.compare_commits --base COMMIT [--benchmarks core_speed env_speed] [--rounds 3]
        [--repeats 3] [--clock wall|cpu] [--paired] [--json out/compare_commits.json]
        [--plot out/compare_commits.png]

The base commit is checked out into a temporary git worktree. Each round runs every benchmark once in each tree, in
alternating order, as a separate process that imports only that tree's package; every benchmark reports the best of
``--repeats`` timings of its own, and across rounds the best counts again. The table gives, per measurement, the
base and this tree's value and the speed ratio (this tree's speed over the base's: above 1 is faster), and the
median and range of the ratios of single rounds.

``--clock cpu`` times both trees by the CPU time of their process instead of the wall clock: every benchmark's
``time.perf_counter`` reads ``time.process_time`` in the child, so old commits' scripts need no change. On a shared
virtual machine the time the host takes away from this one inflates wall time in bursts, and CPU time far less.
It suits single-threaded measurements (``core_speed``, and ``env_speed``'s one-thread cases); a two-thread
measurement then counts both cores' time.

``--paired`` times each of ``core_speed``'s cases, and of ``env_speed``'s one-thread cases of one env and of
``make_vec(64)`` on random actions, in the two trees at the same time, each in a process pinned to a CPU of its own,
the CPUs swapped every round: both warm up, then start timing together. Then both see the same spell of the
machine, fast or slow. Where the whole machine drifts, that takes the drift out of each round's ratio: in a quiet
half hour of 2026-12-03, eight paired rounds of the batched planar core agreed within 2 %, where sequential runs an
hour before had put the same two trees 40 % apart. Where the host slows one CPU and not the other, single rounds
still scatter (by up to 30 % in a busier hour the same evening), and the median of the rounds is the figure to
read. Run whole, side by side, the benchmarks' phases would drift apart and lose the pairing, hence the cases one by
one. The two processes share the cache and the memory bus (and, where the two CPUs are one core's hyperthreads,
that core), so the ratio is of the trees under that shared load. It needs two CPUs.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ("core_speed", "env_speed")

ISOLATE = """
import sys
tree = sys.argv[1]
sys.meta_path[:] = [f for f in sys.meta_path if '__editable__' not in (getattr(f, '__module__', '') or '')
                    and '__editable__' not in type(f).__module__ and '__editable__' not in getattr(f, '__name__', '')]
"""
"""The start of a child process that imports the package from the tree named by its first argument alone: the
editable install's finder would otherwise serve this checkout's package to every tree."""

_RUNNER = ISOLATE + """
import runpy
import time
name, clock = sys.argv[2], sys.argv[3]
if clock == 'cpu':
    time.perf_counter = time.process_time
script = tree + '/benchmarks/' + name + '.py'
sys.path[:0] = [tree, tree + '/benchmarks']
sys.argv = [script] + sys.argv[4:]
if __import__('os').path.exists(tree + '/benchmarks/__init__.py'):
    runpy.run_module('benchmarks.' + name, run_name='__main__', alter_sys=True)
else:
    runpy.run_path(script, run_name='__main__')
"""


def resolve(revision: str) -> str | None:
    """The full hash of ``revision`` in this repository, or None if it names no commit."""
    done = subprocess.run(["git", "rev-parse", "--verify", "--quiet", f"{revision}^{{commit}}"], cwd=ROOT,
                          capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 else None


@contextlib.contextmanager
def worktree(commit: str) -> Iterator[Path]:
    """``commit`` checked out into a temporary git worktree, removed afterwards."""
    with tempfile.TemporaryDirectory() as tmp:
        tree = Path(tmp) / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(tree), commit], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            yield tree
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT, capture_output=True)


CLOCKS = ("wall", "cpu")


def run_benchmark(tree: Path, name: str, repeats: int, workdir: Path, clock: str = "wall") -> dict[str, float]:
    """One run of benchmark ``name`` from ``tree``, timed by ``clock`` (:data:`CLOCKS`); its JSON results, flattened
    to {measurement: value}."""
    out = workdir / f"{tree.name}-{name}.json"
    command = [sys.executable, "-c", _RUNNER, str(tree), name, clock, "--repeats", str(repeats), "--json", str(out),
               "--plot", str(workdir / f"{name}.png")]
    done = subprocess.run(command, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{name} failed in {tree}:\n{done.stderr[-3000:]}")
    return measurements(json.loads(out.read_text()))


_PAIRED_RUNNER = ISOLATE + """
import json
import time
clock = time.process_time if sys.argv[2] == 'cpu' else time.perf_counter
model, batch_size, repeats = sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
sys.path[:0] = [tree]
from soft_gripper_env.physics import paper_scene, run_ramp
scene = paper_scene(model)
run_ramp(scene, batch_size)  # compilation and first-call costs, outside the timing
print('ready', flush=True)
sys.stdin.readline()  # the other tree is ready too: time together
times = []
for _ in range(repeats):
    start = clock()
    run_ramp(scene, batch_size)
    times.append(clock() - start)
print(json.dumps({'best_s': min(times), 'gripper_steps': scene.n_steps * batch_size}), flush=True)
"""

PAIRED_CASES = {"seed_scene_planar_s": ("planar", 1), "seed_scene_3d_s": ("3d", 1)} | {
    f"batched_planar_us_per_gripper_step[{b}]": ("planar", b) for b in (1, 16, 64, 256)}
"""``core_speed``'s measurements as the paired runs take them: {measurement: (rod model, grippers)}, each the
paper scene's scripted run through the public ``paper_scene`` and ``run_ramp``, which every commit since the
layering has."""

ENV_AND_POLICY = """
import gymnasium as gym
import soft_gripper_env
env = (gym.make(soft_gripper_env.ENV_ID, model=model) if num_envs == 1 else
       gym.make_vec(soft_gripper_env.ENV_ID, num_envs=num_envs, model=model))
if policy == 'reactive':
    from agents.scripted import ReactivePolicy
    from soft_gripper_env.grasp_task import GraspTask
    act = ReactivePolicy(GraspTask(model=model))
else:
    act = lambda observation: env.action_space.sample()
env.action_space.seed(0)
observation, _ = env.reset(seed=0)
"""
"""Child-script lines that make the env (``model``, ``num_envs``) and its driver ``act`` (``policy``: random actions
or the reactive controller) through public names every commit since the env has, and reset it: shared by the
paired timings here and ``tools.profile_env``."""

_PAIRED_ENV_RUNNER = ISOLATE + """
import json
import os
import time
clock = time.process_time if sys.argv[2] == 'cpu' else time.perf_counter
model, num_envs, repeats, steps, policy = sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), int(sys.argv[6]), sys.argv[7]
os.environ.setdefault('NUMBA_NUM_THREADS', '1')
sys.path[:0] = [tree]
""" + ENV_AND_POLICY + """
def run():
    global observation
    for _ in range(steps):
        observation, _, terminated, truncated, _ = env.step(act(observation))
        if num_envs == 1 and (terminated or truncated):
            observation, _ = env.reset()
run()  # compilation and first-call costs, outside the timing
print('ready', flush=True)
sys.stdin.readline()
times = []
for _ in range(repeats):
    start = clock()
    run()
    times.append(clock() - start)
print(json.dumps({'best_s': min(times), 'env_steps': steps * num_envs}), flush=True)
"""

PAIRED_ENV_CASES = {"single_steps_per_s": ("planar", 1, 300, "random"),
                    "single_3d_steps_per_s": ("3d", 1, 100, "random"),
                    "vec64_steps_per_s": ("planar", 64, 12, "random"),
                    "vec64_3d_steps_per_s": ("3d", 64, 4, "random"),
                    "single_grasping_steps_per_s": ("planar", 1, 150, "reactive"),
                    "single_3d_grasping_steps_per_s": ("3d", 1, 40, "reactive")}
"""``env_speed``'s one-thread measurements as the paired runs take them: {measurement: (rod model, envs, actions
per timing, policy)}, random actions or the reactive controller grasping (``agents.scripted.ReactivePolicy``, from
a reset: its first actions close the fingers on the sphere), from ``gym.make`` or ``gym.make_vec``, each timing
about half a second to a second."""


def paired_case(trees: dict[str, Path], cpus: dict[str, int], measurement: str, repeats: int,
                clock: str) -> dict[str, float]:
    """One of :data:`PAIRED_CASES` or :data:`PAIRED_ENV_CASES` run in both trees at once, each process pinned to its
    CPU (``cpus``: side → CPU). Each warms up, then both time ``repeats`` runs from the same moment; {side: the best
    run's value}."""
    if measurement in PAIRED_ENV_CASES:
        runner, arguments = _PAIRED_ENV_RUNNER, [str(value) for value in PAIRED_ENV_CASES[measurement]]
        arguments.insert(2, str(repeats))
    else:
        model, batch_size = PAIRED_CASES[measurement]
        runner, arguments = _PAIRED_RUNNER, [model, str(batch_size), str(repeats)]
    processes = {side: subprocess.Popen(
        [sys.executable, "-c", runner, str(tree), clock, *arguments], cwd=tree,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        preexec_fn=lambda cpu=cpus[side]: os.sched_setaffinity(0, {cpu})) for side, tree in trees.items()}
    try:
        for side, process in processes.items():
            if process.stdout.readline().strip() != "ready":
                raise RuntimeError(f"{measurement} failed in {trees[side]}:\n{process.communicate()[1][-3000:]}")
        for process in processes.values():
            process.stdin.write("go\n")
            process.stdin.flush()
        values = {}
        for side, process in processes.items():
            out, err = process.communicate()
            if process.returncode != 0:
                raise RuntimeError(f"{measurement} failed in {trees[side]}:\n{err[-3000:]}")
            result = json.loads(out)
            if measurement in PAIRED_ENV_CASES:
                values[side] = result["env_steps"] / result["best_s"]
            elif measurement.startswith("seed_scene"):
                values[side] = result["best_s"]
            else:
                values[side] = result["best_s"] / result["gripper_steps"] * 1e6
        return values
    finally:
        for process in processes.values():
            process.kill()


UNITS = ("_per_s", "_s", "_ms")
"""How a measurement's name ends (a rate or a time); a name holding ``_us`` is a time in µs too."""


def measurements(results: dict, prefix: str = "", unit: bool = False) -> dict[str, float]:
    """A benchmark's results flattened to {measurement: value}, nested entries as ``outer[inner]``: every number
    whose own name carries a unit (:data:`UNITS`), or that is one size of a measurement with a unit
    (``batched_planar_us_per_gripper_step[64]``). Ratios, goals and flags are left out: they follow from the
    measurements."""
    flat = {}
    for key, value in results.items():
        name = f"{prefix}[{key}]" if prefix else key
        measured = key.endswith(UNITS) or "_us" in key or (unit and key.isdigit())
        if isinstance(value, dict):
            flat.update(measurements(value, name, measured))
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and measured:
            flat[name] = float(value)
    return flat


def higher_is_faster(measurement: str) -> bool:
    """Rates (per second) grow with speed; times (s, µs) shrink."""
    return measurement.split("[")[0].endswith("_per_s")


def speed_ratio(measurement: str, base: float, this: float) -> float:
    """This tree's speed over the base's for one measurement (above 1 is faster)."""
    return this / base if higher_is_faster(measurement) else base / this


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the commit to compare against (any git revision)")
    parser.add_argument("--benchmarks", nargs="+", default=list(BENCHMARKS), choices=BENCHMARKS)
    parser.add_argument("--rounds", type=int, default=3, help="runs of each benchmark per tree (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="timings within each run (default 3)")
    parser.add_argument("--clock", choices=CLOCKS, default="wall",
                        help="wall time, or the CPU time of each benchmark's process (default wall)")
    parser.add_argument("--paired", action="store_true",
                        help="time the benchmarks' one-thread cases in both trees at the same time, one per CPU")
    parser.add_argument("--json", type=Path, default=Path("out") / "compare_commits.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / "compare_commits.png")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.repeats < 1:
        parser.error("--rounds and --repeats must be at least 1")
    base_commit = resolve(args.base)
    if base_commit is None:
        parser.error(f"--base {args.base!r} is not a commit of this repository")
    head_commit = resolve("HEAD")
    cpus = sorted(os.sched_getaffinity(0))[:2]
    if args.paired and len(cpus) < 2:
        parser.error(f"--paired runs the two trees on two CPUs at once; this process may use {len(cpus)}")

    with worktree(base_commit) as base_tree, tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        trees = {"base": base_tree, "this": ROOT}
        best: dict[str, dict[str, float]] = {"base": {}, "this": {}}
        rounds: dict[str, list[float]] = {}
        if args.paired:  # each case in both trees at once, on CPUs swapped every round
            cases = {"core_speed": list(PAIRED_CASES), "env_speed": list(PAIRED_ENV_CASES)}
            runs = [(r, case) for r in range(args.rounds) for name in args.benchmarks for case in cases[name]]
        else:
            runs = [(r, name) for r in range(args.rounds) for name in args.benchmarks]
        for r, what in tqdm(runs, desc="benchmark rounds", unit="round"):
            sides = ("base", "this") if r % 2 == 0 else ("this", "base")
            if args.paired:
                values = paired_case(trees, dict(zip(sides, cpus, strict=True)), what, args.repeats, args.clock)
                measured = {side: {what: value} for side, value in values.items()}
            else:
                measured = {side: run_benchmark(trees[side], what, args.repeats, workdir, args.clock)
                            for side in sides}
            for side in sides:
                for key, value in measured[side].items():
                    pick = max if higher_is_faster(key) else min
                    best[side][key] = pick(best[side].get(key, value), value)
            for key in measured["base"].keys() & measured["this"].keys():
                rounds.setdefault(key, []).append(speed_ratio(key, measured["base"][key], measured["this"][key]))

    rows = []
    print(f"\n{'measurement':<48}{'base':>12}{'this tree':>12}{'speed ratio':>13}{'rounds: median':>16}{'range':>16}")
    for key in best["base"]:
        if key not in best["this"]:
            continue
        old, new = best["base"][key], best["this"][key]
        ratio, per_round = speed_ratio(key, old, new), rounds[key]
        rows.append({"measurement": key, "base": old, "this": new, "speed_ratio": ratio,
                     "round_ratios": per_round, "median_round_ratio": statistics.median(per_round)})
        print(f"{key:<48}{old:>12.4g}{new:>12.4g}{ratio:>12.3f}×{statistics.median(per_round):>15.3f}×"
              f"{min(per_round):>9.3f}–{max(per_round):.3f}")
    slowest = min(row["speed_ratio"] for row in rows)
    slowest_median = min(row["median_round_ratio"] for row in rows)
    print(f"\nslowest case: {slowest:.3f}× the base's speed, best of all rounds; {slowest_median:.3f}× by the median "
          f"of single rounds (base {base_commit[:10]}, this tree {head_commit[:10]} plus uncommitted changes if any)")
    results = {"base": base_commit, "head": head_commit, "rounds": args.rounds, "repeats": args.repeats,
               "clock": args.clock, "paired": args.paired, "rows": rows, "slowest_speed_ratio": slowest,
               "slowest_median_round_ratio": slowest_median}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.json}")

    plot_ratios(results, args.plot)
    return results


def plot_ratios(results: dict, path: Path) -> None:
    """One bar per measurement: the median of the single rounds' speed ratios, written at the right, their range as
    whiskers and the best-of ratio as a diamond; from :func:`main`'s results (its JSON)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    rows = results["rows"]
    fig, ax = plt.subplots(figsize=(9, 0.45 * len(rows) + 1.8))
    labels = [row["measurement"] for row in rows]
    medians = np.array([row["median_round_ratio"] for row in rows])
    low = medians - np.array([min(row["round_ratios"]) for row in rows])
    high = np.array([max(row["round_ratios"]) for row in rows]) - medians
    ax.barh(labels, medians, xerr=(low, high), capsize=3, error_kw={"lw": 1},
            color=["tab:green" if r >= 0.95 else "tab:red" for r in medians], label="median of single rounds")
    ax.plot([row["speed_ratio"] for row in rows], labels, "kD", ms=4, label="best of all rounds")
    ax.axvline(1.0, color="k", lw=1)
    ax.axvline(0.95, color="0.5", ls="--", lw=1, label="5 % slower")
    right = max(1.15, (medians + high).max() + 0.25)
    ax.set_xlim(min(0.8, (medians - low).min() - 0.05), right)
    for y, median in enumerate(medians):  # past every whisker, so no label sits on one
        ax.text(right - 0.01, y, f"{median:.3f}×", va="center", ha="right", fontsize=8)
    how = "paired runs, " if results.get("paired") else ""
    ax.set_xlabel(f"speed of this tree ({results['head'][:10]}) / speed of {results['base'][:10]}\n"
                  f"({how}{results.get('clock', 'wall')} time; whiskers: the range of {results['rounds']} rounds)")
    ax.invert_yaxis()
    ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=3, fontsize=8, frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
