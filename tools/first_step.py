"""How long a new user waits for the first env step: the kernels compiled from an empty Numba cache, then loaded
from the cache by a later run, for this tree and (the anchor, timed in the same run) an older commit.

    python -m tools.first_step [--base COMMIT] [--models 3d,planar] [--rounds 1] [--demo]
        [--json out/first_step.json] [--plot out/first_step.png]

Each measurement is a process of its own whose Numba cache is a fresh, empty folder (``NUMBA_CACHE_DIR``): it
imports the package, makes the env (``gym.make("SoftGripperUnderwater-v0", model=...)``), resets it and takes one
step, and reports the wall and CPU time of each phase; a second process then does the same from the cache the first
one filled. The trees alternate within a round, and across rounds the least time counts. ``--demo`` also times the
README's demo (each tree's scripts/demo.sh commands: the paper's figures and two episodes' videos) from an empty
cache, once per tree (JSON keys ``demo_empty_cache``, ``demo_empty_cache_base`` and ``demo_speedup_wall``, the base's
wall time over this tree's). Compilation is single-threaded, so the CPU time of a first step is the figure least
disturbed by other load on the machine; the demo compiles in several processes at once, so its wall time is the one
a user waits.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tools.compare_commits import ISOLATE, resolve, worktree

ROOT = Path(__file__).resolve().parents[1]
MODELS = ("3d", "planar")
GOAL_S = 30.0
"""What a first step from an empty cache should take at most on a 2-core machine [s] (the plot's dotted line)."""

_CHILD = ISOLATE + """
import json
import time
wall, cpu = time.perf_counter(), time.process_time()
def phase():
    global wall, cpu
    now_wall, now_cpu = time.perf_counter(), time.process_time()
    spent = {'wall_s': now_wall - wall, 'cpu_s': now_cpu - cpu}
    wall, cpu = now_wall, now_cpu
    return spent
sys.path[:0] = [tree]
import numpy as np
import gymnasium as gym
import soft_gripper_env  # noqa: F401
phases = {'import': phase()}
env = gym.make('SoftGripperUnderwater-v0', model=sys.argv[2])
env.reset(seed=0)
phases['make_and_reset'] = phase()
env.step(np.zeros(env.action_space.shape, dtype=np.float32))
phases['first_step'] = phase()
print(json.dumps(phases))
"""


def time_first_step(tree: Path, model: str, cache: Path) -> dict[str, dict[str, float]]:
    """The phases of a first env step of ``model`` in a fresh process of ``tree`` with the Numba cache ``cache``:
    {phase: {"wall_s", "cpu_s"}}."""
    environment = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    done = subprocess.run([sys.executable, "-c", _CHILD, str(tree), model], cwd=tree, env=environment,
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the first step of model {model!r} failed in {tree}:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def total(phases: dict[str, dict[str, float]], clock: str) -> float:
    """The time from the process's start to the end of its first step [s] by ``clock`` ("wall_s" or "cpu_s")."""
    return sum(spent[clock] for spent in phases.values())


_DEMO_COMMAND = ISOLATE + """
import runpy
sys.path[:0] = [tree]
sys.argv = sys.argv[2:]
runpy.run_module(sys.argv[0], run_name="__main__", alter_sys=True)
"""


def demo_commands(tree: Path, out: Path) -> list[list[str]]:
    """The README's demo of ``tree``: the ``python -m`` commands of its scripts/demo.sh (without its set-up), each
    importing the package from ``tree`` alone, writing under ``out``."""
    lines = (tree / "scripts" / "demo.sh").read_text().splitlines()
    commands = [shlex.split(line.replace("$out", str(out)))[1:] for line in lines
                if line.startswith(".venv/bin/python ")]
    if any(command[0] != "-m" for command in commands):
        raise ValueError(f"{tree / 'scripts' / 'demo.sh'}: every Python command must be `python -m MODULE ...`")
    return [[sys.executable, "-c", _DEMO_COMMAND, str(tree), *command[1:]] for command in commands]


def time_demo(tree: Path = ROOT) -> dict[str, float]:
    """The README's demo of ``tree`` from an empty cache [s]."""
    with tempfile.TemporaryDirectory() as tmp:
        environment = dict(os.environ, NUMBA_CACHE_DIR=str(Path(tmp) / "cache"))
        start_wall, start_cpu = time.perf_counter(), _children_cpu()
        for command in demo_commands(tree, Path(tmp) / "out"):
            subprocess.run(command, cwd=tree, env=environment, check=True, capture_output=True)
        return {"wall_s": time.perf_counter() - start_wall, "cpu_s": _children_cpu() - start_cpu}


def _children_cpu() -> float:
    usage = os.times()
    return usage.children_user + usage.children_system


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", help="an older commit, timed the same way in the same run (the anchor)")
    parser.add_argument("--models", default=",".join(MODELS), help="comma-separated, of 3d, planar (default both)")
    parser.add_argument("--rounds", type=int, default=1, help="rounds of every measurement; the least time counts")
    parser.add_argument("--demo", action="store_true", help="also time the README's demo from an empty cache")
    parser.add_argument("--json", type=Path, default=Path("out") / "first_step.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / "first_step.png")
    args = parser.parse_args(argv)
    models = [model.strip() for model in args.models.split(",") if model.strip()]
    for model in models:
        if model not in MODELS:
            parser.error(f"--models: {model!r} is not one of {', '.join(MODELS)}")
    if args.rounds < 1:
        parser.error(f"--rounds = {args.rounds} must be at least 1")
    base = None
    if args.base is not None:
        base = resolve(args.base)
        if base is None:
            parser.error(f"--base {args.base!r} names no commit of this repository")

    results: dict = {"base": base, "rounds": args.rounds, "trees": {}}
    with tempfile.TemporaryDirectory() as tmp, (worktree(base) if base else contextlib.nullcontext()) as base_tree:
        trees = {"this": ROOT} | ({"base": base_tree} if base else {})
        for name in trees:
            results["trees"][name] = {model: {"empty_cache": None, "warm_cache": None} for model in models}
        steps = [(round_, model, name) for round_ in range(args.rounds) for model in models for name in trees]
        for count, (round_, model, name) in enumerate(steps, start=1):
            print(f"[{count}/{len(steps)}] round {round_ + 1}, {model}, {name} tree: compiling from an empty cache …",
                  file=sys.stderr, flush=True)
            cache = Path(tmp) / f"cache-{name}-{model}-{round_}"
            measured = {"empty_cache": time_first_step(trees[name], model, cache),
                        "warm_cache": time_first_step(trees[name], model, cache)}
            kept = results["trees"][name][model]
            for kind, phases in measured.items():
                if kept[kind] is None or total(phases, "cpu_s") < total(kept[kind], "cpu_s"):
                    kept[kind] = phases
        if args.demo:
            for name, tree in trees.items():
                print(f"the demo of {'this' if name == 'this' else 'the base'} tree from an empty cache …",
                      file=sys.stderr, flush=True)
                results["demo_empty_cache" + ("" if name == "this" else "_base")] = time_demo(tree)

    print("\n| model | tree | first step, empty cache: wall [s] | CPU [s] | first step, warm cache: wall [s] |")
    print("|---|---|---|---|---|")
    for model in models:
        for name, tree_results in results["trees"].items():
            empty, warm = tree_results[model]["empty_cache"], tree_results[model]["warm_cache"]
            print(f"| {model} | {name} | {total(empty, 'wall_s'):.1f} | {total(empty, 'cpu_s'):.1f} | "
                  f"{total(warm, 'wall_s'):.1f} |")
        if base:
            ratio = total(results["trees"]["base"][model]["empty_cache"], "cpu_s") / \
                total(results["trees"]["this"][model]["empty_cache"], "cpu_s")
            results.setdefault("speedup_empty_cache_cpu", {})[model] = ratio
            print(f"| {model} | base over this (CPU) | {ratio:.2f}× | | |")
    if args.demo:
        for key, name in (("demo_empty_cache", "this tree"), ("demo_empty_cache_base", "the base tree")):
            if key in results:
                print(f"\nthe demo of {name} from an empty cache: {results[key]['wall_s']:.0f} s wall, "
                      f"{results[key]['cpu_s']:.0f} s CPU")
        if base:
            results["demo_speedup_wall"] = results["demo_empty_cache_base"]["wall_s"] / \
                results["demo_empty_cache"]["wall_s"]
            print(f"the demo, base over this (wall): {results['demo_speedup_wall']:.2f}×")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1))
    plot(results, models, args.plot)
    print(f"\n{args.json}, {args.plot}")
    return results


def plot(results: dict, models: list[str], path: Path) -> None:
    """Bars of the first step's CPU time from an empty cache, by phase, per model and tree."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trees = list(results["trees"])
    fig, ax = plt.subplots(figsize=(7.5, 3.2))
    labels, bottoms = [], None
    for phase, color in (("import", "#999999"), ("make_and_reset", "#4c72b0"), ("first_step", "#dd8452")):
        values = [results["trees"][tree][model]["empty_cache"][phase]["cpu_s"] for model in models for tree in trees]
        bottoms = [0.0] * len(values) if bottoms is None else bottoms
        ax.barh(range(len(values)), values, left=bottoms, color=color, label=phase.replace("_", " "))
        bottoms = [b + v for b, v in zip(bottoms, values, strict=True)]
    labels = [f"{model}, {tree}" for model in models for tree in trees]
    ax.set_yticks(range(len(labels)), labels)
    ax.invert_yaxis()
    ax.axvline(GOAL_S, color="k", linestyle=":", linewidth=1)
    ax.text(GOAL_S, -0.6, f" goal {GOAL_S:g} s", fontsize=8, va="bottom")
    ax.set_xlabel("CPU time from an empty Numba cache to the first env step [s]")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=150)
    plt.close(fig)


if __name__ == "__main__":
    main()
