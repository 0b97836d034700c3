"""Numba's atomic reference counts per call of the rods' step kernel, this tree against an older commit.

    python -m benchmarks.refcounts [--base COMMIT] [--calls 100] [--json out/refcounts.json]

Every array a compiled function binds (an argument, a bundle's member, a view) costs Numba an atomic increment and
decrement of its reference count unless its optimiser proves the pair unneeded. Uncontended, each is a locked
instruction of a few nanoseconds, and in the rods' own step they add up to a fifth of the kernel's time. Unlike a
timing, the count does not depend on the machine's load, so it shows small differences between two trees exactly.

It runs the paper's scene (3 fingers, N = 20, no object) through the simulator in a child process under gdb, keeps
the arguments of ``--calls`` of its calls of the step kernel (``simulator.advance_rods``, spread over the run), calls
the kernel with them once to warm up, and then counts, with a breakpoint on each, how often ``NRT_incref`` and
``NRT_decref`` run while it calls the kernel with them again. Needs gdb.
"""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.compare_commits import ISOLATE, ROOT, resolve, worktree

MODELS = ("planar", "3d")

_CHILD = ISOLATE + """
import os, signal
sys.path[:0] = [tree]
model, calls, address_file = sys.argv[2], int(sys.argv[3]), sys.argv[4]
os.environ.setdefault('NUMBA_NUM_THREADS', '1')
import numpy as np
from numba.core.runtime import rtsys
from soft_gripper_env.physics import paper_scene, run_ramp
import soft_gripper_env.physics.simulator as simulator
kernel, captured = simulator.advance_rods, []
def capture(*args):
    captured.append(tuple(np.copy(a) if isinstance(a, np.ndarray) else a for a in args))
    return kernel(*args)
simulator.advance_rods = capture
run_ramp(paper_scene(model), 1)
simulator.advance_rods = kernel
chosen = [captured[i * len(captured) // calls] for i in range(calls)]
for args in chosen:
    kernel(*args)
open(address_file, 'w').write(str(rtsys.library.get_pointer_to_function('NRT_incref')) + ' '
                              + str(rtsys.library.get_pointer_to_function('NRT_decref')))
os.kill(os.getpid(), signal.SIGUSR1)
for args in chosen:
    kernel(*args)
os.kill(os.getpid(), signal.SIGUSR1)
"""

_GDB = """set pagination off
handle SIGUSR1 stop nopass
run
python
increment, decrement = open({address_file!r}).read().split()
gdb.execute("break *" + increment)
gdb.execute("break *" + decrement)
gdb.execute("ignore 1 1000000000")
gdb.execute("ignore 2 1000000000")
end
continue
info breakpoints
kill
quit
"""


def hits(gdb_output: str) -> tuple[int, int]:
    """How often the first and the second breakpoint were hit, from gdb's ``info breakpoints``."""
    counts = [int(n) for n in re.findall(r"breakpoint already hit (\d+) times?", gdb_output)]
    if len(counts) != 2:
        raise RuntimeError(f"expected the hit counts of two breakpoints in gdb's output, found {counts}:\n"
                           f"{gdb_output[-2000:]}")
    return counts[0], counts[1]


def count(tree: Path, model: str, calls: int) -> dict[str, float]:
    """Reference-count increments and decrements per kernel call in ``tree``'s package, the paper scene in
    ``model``."""
    with tempfile.TemporaryDirectory() as tmp:
        address_file, script = Path(tmp) / "address", Path(tmp) / "count.gdb"
        script.write_text(_GDB.format(address_file=str(address_file)))
        done = subprocess.run(["gdb", "-q", "-batch", "-x", str(script), "--args", sys.executable, "-c", _CHILD,
                               str(tree), model, str(calls), str(address_file)],
                              cwd=tree, capture_output=True, text=True, timeout=1800)
        increments, decrements = hits(done.stdout + done.stderr)
    return {"incref_per_call": increments / calls, "decref_per_call": decrements / calls}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="an older commit to count as well (any git revision)")
    parser.add_argument("--calls", type=int, default=100, help="kernel calls counted (default 100)")
    parser.add_argument("--models", nargs="+", default=list(MODELS), choices=MODELS)
    parser.add_argument("--json", type=Path, help="write the counts to this JSON file")
    args = parser.parse_args(argv)
    if not 1 <= args.calls <= 10_000:
        parser.error(f"--calls = {args.calls} must be within [1, 10000]")
    if shutil.which("gdb") is None:
        parser.error("gdb is needed (it counts the calls with breakpoints) and is not on the PATH")
    base_commit = None
    if args.base is not None:
        base_commit = resolve(args.base)
        if base_commit is None:
            parser.error(f"--base {args.base!r} is not a commit of this repository")

    results: dict = {"base": base_commit, "head": resolve("HEAD"), "calls": args.calls, "models": {}}
    for model in args.models:
        print(f"counting the paper scene's step kernel, {model}, {args.calls} calls ...", flush=True)
        entry = {"this": count(ROOT, model, args.calls)}
        if base_commit is not None:
            with worktree(base_commit) as base_tree:
                entry["base"] = count(base_tree, model, args.calls)
            total = {side: sum(entry[side].values()) for side in ("base", "this")}
            entry["ratio_this_to_base"] = total["this"] / total["base"]
        results["models"][model] = entry

    print(f"\n{'model':<8}{'tree':<8}{'increments':>12}{'decrements':>12}   per kernel call")
    for model, entry in results["models"].items():
        for side in ("base", "this"):
            if side in entry:
                print(f"{model:<8}{side:<8}{entry[side]['incref_per_call']:>12.1f}"
                      f"{entry[side]['decref_per_call']:>12.1f}")
        if "ratio_this_to_base" in entry:
            print(f"{model:<8}this tree / base: {entry['ratio_this_to_base']:.3f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")
    return results


if __name__ == "__main__":
    main()
