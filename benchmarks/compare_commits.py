"""Speed of this tree against an older commit, side by side in one run: the anchor is timed with the same machine
load, so the ratio holds even when the machine's own speed drifts.

    python -m benchmarks.compare_commits --base COMMIT [--benchmarks core_speed env_speed] [--rounds 3]
        [--repeats 3] [--json out/compare_commits.json] [--plot out/compare_commits.png]

The base commit is checked out into a temporary git worktree. Each round runs every benchmark once in each tree, in
alternating order, as a separate process that imports only that tree's package; every benchmark reports the best of
``--repeats`` timings of its own, and across rounds the best counts again. The table gives, per measurement, the
base and this tree's value and the speed ratio (this tree's speed over the base's: above 1 is faster).
"""

from __future__ import annotations

import argparse
import contextlib
import json
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
name = sys.argv[2]
script = tree + '/benchmarks/' + name + '.py'
sys.path[:0] = [tree, tree + '/benchmarks']
sys.argv = [script] + sys.argv[3:]
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


def run_benchmark(tree: Path, name: str, repeats: int, workdir: Path) -> dict[str, float]:
    """One run of benchmark ``name`` from ``tree``; its JSON results, flattened to {measurement: value}."""
    out = workdir / f"{tree.name}-{name}.json"
    command = [sys.executable, "-c", _RUNNER, str(tree), name, "--repeats", str(repeats), "--json", str(out),
               "--plot", str(workdir / f"{name}.png")]
    done = subprocess.run(command, cwd=tree, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{name} failed in {tree}:\n{done.stderr[-3000:]}")
    return measurements(json.loads(out.read_text()))


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


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the commit to compare against (any git revision)")
    parser.add_argument("--benchmarks", nargs="+", default=list(BENCHMARKS), choices=BENCHMARKS)
    parser.add_argument("--rounds", type=int, default=3, help="runs of each benchmark per tree (default 3)")
    parser.add_argument("--repeats", type=int, default=3, help="timings within each run (default 3)")
    parser.add_argument("--json", type=Path, default=Path("out") / "compare_commits.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / "compare_commits.png")
    args = parser.parse_args(argv)
    if args.rounds < 1 or args.repeats < 1:
        parser.error("--rounds and --repeats must be at least 1")
    base_commit = resolve(args.base)
    if base_commit is None:
        parser.error(f"--base {args.base!r} is not a commit of this repository")
    head_commit = resolve("HEAD")

    with worktree(base_commit) as base_tree, tempfile.TemporaryDirectory() as tmp:
        workdir = Path(tmp)
        trees = {"base": base_tree, "this": ROOT}
        best: dict[str, dict[str, float]] = {"base": {}, "this": {}}
        runs = [(r, name, side) for r in range(args.rounds) for name in args.benchmarks
                for side in (("base", "this") if r % 2 == 0 else ("this", "base"))]
        for _, name, side in tqdm(runs, desc="benchmark runs", unit="run"):
            for key, value in run_benchmark(trees[side], name, args.repeats, workdir).items():
                pick = max if higher_is_faster(key) else min
                best[side][key] = pick(best[side].get(key, value), value)

    rows = []
    print(f"\n{'measurement':<48}{'base':>12}{'this tree':>12}{'speed ratio':>13}")
    for key in best["base"]:
        if key not in best["this"]:
            continue
        old, new = best["base"][key], best["this"][key]
        ratio = new / old if higher_is_faster(key) else old / new
        rows.append({"measurement": key, "base": old, "this": new, "speed_ratio": ratio})
        print(f"{key:<48}{old:>12.4g}{new:>12.4g}{ratio:>12.3f}×")
    slowest = min(row["speed_ratio"] for row in rows)
    print(f"\nslowest case: {slowest:.3f}× the base's speed (base {base_commit[:10]}, this tree {head_commit[:10]}"
          f" plus uncommitted changes if any)")
    results = {"base": base_commit, "head": head_commit, "rounds": args.rounds, "repeats": args.repeats,
               "rows": rows, "slowest_speed_ratio": slowest}
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.json}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 0.45 * len(rows) + 1.5))
    labels = [row["measurement"] for row in rows]
    ratios = [row["speed_ratio"] for row in rows]
    bars = ax.barh(labels, ratios, color=["tab:green" if r >= 0.95 else "tab:red" for r in ratios])
    ax.bar_label(bars, fmt="%.3f×", padding=3, fontsize=8)
    ax.axvline(1.0, color="k", lw=1)
    ax.axvline(0.95, color="0.5", ls="--", lw=1, label="5 % slower")
    ax.set_xlim(min(0.8, min(ratios) - 0.05), max(1.15, max(ratios) + 0.1))
    ax.set_xlabel(f"speed of this tree / speed of {base_commit[:10]} (same run)")
    ax.invert_yaxis()
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    args.plot.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.plot, dpi=110)
    print(f"wrote {args.plot}")
    return results


if __name__ == "__main__":
    main()
