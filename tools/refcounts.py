"""Numba's atomic reference counts per call of the rods' step kernel, this tree against an older commit.

    python -m tools.refcounts [--base COMMIT] [--calls 100] [--json out/refcounts.json]

Every array a compiled function binds (an argument, a bundle's member, a view) costs Numba an atomic increment and
decrement of its reference count unless its optimiser proves the pair unneeded. Uncontended, each is a locked
instruction of a few nanoseconds, and in the rods' own step they add up to a fifth of the kernel's time. Unlike a
timing, the count does not depend on the machine's load, so it shows small differences between two trees exactly.

It runs the paper's scene (3 fingers, N = 20, no object) through the simulator in a child process under gdb, keeps
the arguments of ``--calls`` of its calls of the step kernel (``simulator.advance_rods``, spread over the run), calls
the kernel with them once to warm up, and then counts, with a breakpoint on each, how often ``NRT_incref`` and
``NRT_decref`` run while it calls the kernel with them again. Needs gdb.

    python -m tools.refcounts --env MODEL [--steps 1] [--json out/refcounts_env.json]

counts them instead over whole steps of the environment (``SoftGripperUnderwater-v0`` in ``MODEL``, random actions
after a dozen), each a control interval of physics steps in one compiled call with the free sphere and the
corrector, and says which compiled function makes them: a breakpoint reads each operation's return address, which
falls in a function of the control interval's machine code (a function that Numba or LLVM has inlined counts as its
caller). That shows where a step's reference counts are worth removing. Needs gdb and readelf.

    python -m tools.refcounts --env MODEL --lines [--json F]

also gives each operation to the line of Python source whose code makes it (a line of a function Numba inlined
counts as its own). For that the child compiles the package with Numba's debug information
(``NUMBA_DEBUGINFO=1``, less the rest of Numba's debug mode, which keeps variables alive longer, checks bounds and
stops inlining, and so changes the counts), into a cache of its own under ``out/refcounts_debug_cache``, a folder
per version of the package's source, so that the package's cache is not touched and no edit is counted stale (the
first run of a version compiles everything, ten minutes or more, then counts in a second run that loads it all), and
``addr2line`` reads the lines from the object's line table. The totals should match a run without ``--lines``; the
JSON holds both views.

    python -m tools.refcounts --env MODEL --allocations [--lines] [--json F]

counts the arrays that compiled code allocates instead (calls of Numba's runtime allocators, :data:`ALLOCATORS`),
by function, or line, the same way: each is a heap allocation and, later, its free.
"""

from __future__ import annotations

import argparse
import bisect
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from tools.compare_commits import ISOLATE, ROOT, resolve, worktree

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

ALLOCATORS = ("NRT_MemInfo_alloc", "NRT_MemInfo_alloc_safe", "NRT_MemInfo_alloc_aligned",
              "NRT_MemInfo_alloc_safe_aligned", "NRT_MemInfo_alloc_dtor_safe")
"""The functions of Numba's runtime that compiled code calls to allocate an array (``np.empty`` and the like); each
allocates and later frees on the heap, tens of nanoseconds or more."""

_ENV_CHILD = ISOLATE + f"ALLOCATORS = {ALLOCATORS!r}\n" + """
import json, os, signal
sys.path[:0] = [tree]
model, steps, address_file, object_file, counted = sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6]
os.environ.setdefault('NUMBA_NUM_THREADS', '1')
import numba.core.codegen as codegen
objects = []  # each library's machine code as Numba loads it (from its cache, or compiled)
set_compiled_object = codegen.CPUCodeLibrary._set_compiled_object
def keep(library, value):
    objects.append((library, bytes(value)))
    return set_compiled_object(library, value)
codegen.CPUCodeLibrary._set_compiled_object = keep
if os.environ.get('NUMBA_DEBUGINFO') == '1':  # debug information without the rest of Numba's debug mode
    from numba.core import cpu, lowering
    finalize, pre_lower = cpu.CPUTargetOptions.finalize, lowering.Lower.pre_lower
    def optimised(self, flags, options):  # variables die when unused and bounds go unchecked, as without
        finalize(self, flags, options)
        flags.dbg_extend_lifetimes, flags.boundscheck = False, False
    def inlined(self):  # and LLVM may inline
        pre_lower(self)
        self.builder.function.attributes.discard('noinline')
    cpu.CPUTargetOptions.finalize, lowering.Lower.pre_lower = optimised, inlined
from pathlib import Path
import gymnasium as gym
from numba.core.runtime import rtsys
import soft_gripper_env
from soft_gripper_env.physics.solvers import stepping
from tools.refcounts import function_symbols
env = gym.make(soft_gripper_env.ENV_ID, model=model)
env.action_space.seed(0)
env.reset(seed=0)
for _ in range(12):
    env.step(env.action_space.sample())
(result,) = stepping.take_steps.overloads.values()
code = [value for owner, value in objects if owner is result.library]
if not code:  # compiled in this process rather than loaded from the cache: the library holds it
    code = [bytes(result.library._get_compiled_object())]
    Path(object_file + '.compiled').write_text('')  # and the other libraries' objects went uncaptured
Path(object_file).write_bytes(code[-1])
symbols = function_symbols(Path(object_file))
# the object's code lies at its entry point's address less that function's offset in it; the object links in its
# own copies of NRT_incref and NRT_decref, which its code calls rather than the runtime's
name = result.fndesc.llvm_func_name
base = result.library.get_pointer_to_function(name) - symbols[name][0]
if counted == 'allocations':  # the runtime's C functions, which compiled code calls to allocate an array
    import llvmlite.binding as llvm
    targets = [llvm.address_of_symbol(n) for n in ALLOCATORS]
else:
    targets = [rtsys.library.get_pointer_to_function(n) for n in ('NRT_incref', 'NRT_decref')]
    targets += [base + symbols[n][0] for n in ('NRT_incref', 'NRT_decref') if n in symbols]
Path(address_file).write_text(' '.join(str(a) for a in [base] + targets))
others = []  # every other library's object and where it lies, for the lines of code outside the interval's object
for k, (owner, value) in enumerate(objects):
    if owner is result.library:
        continue
    path = Path(object_file + f'.{k}')
    path.write_bytes(value)
    for symbol, (offset, _) in function_symbols(path).items():
        try:
            others.append((str(path), owner.get_pointer_to_function(symbol) - offset))
            break
        except Exception:
            continue
Path(object_file + '.others').write_text(json.dumps(others))
os.kill(os.getpid(), signal.SIGUSR1)
for _ in range(steps):
    env.step(env.action_space.sample())
os.kill(os.getpid(), signal.SIGUSR1)
"""

_ENV_GDB = """set pagination off
handle SIGUSR1 stop nopass
run
python
import collections, json
base, *targets = [int(a) for a in open({address_file!r}).read().split()]
returns = collections.Counter()
class Count(gdb.Breakpoint):
    def stop(self):
        stack = int(gdb.parse_and_eval('$rsp'))
        returns[int.from_bytes(bytes(gdb.selected_inferior().read_memory(stack, 8)), 'little') - base] += 1
        return False
breakpoints = [Count('*%d' % t) for t in targets]
end
continue
python
json.dump(sorted(returns.items()), open({counts_file!r}, 'w'))
end
kill
quit
"""


def demangle(name: str) -> str:
    """The dotted name of a Numba-compiled function from its mangled symbol (``_ZN`` and length-prefixed parts up
    to Numba's ``B`` or ``E``), less the package's prefix: ``kernels.contact.contact_reactions``."""
    if not name.startswith("_ZN"):
        return name
    parts, i = [], 3
    while i < len(name) and name[i].isdigit():
        j = i
        while name[j].isdigit():
            j += 1
        length = int(name[i:j])
        parts.append(name[j:j + length])
        i = j + length
    while parts and parts[0] in ("soft_gripper_env", "physics"):
        parts.pop(0)
    return ".".join(parts) or name


def function_symbols(object_code: Path) -> dict[str, tuple[int, int]]:
    """The functions an ELF object defines, name → (offset, size) [bytes], as ``readelf`` lists them (a size of
    100,000 bytes or more in hexadecimal)."""
    listing = subprocess.run(["readelf", "-sW", str(object_code)], capture_output=True, text=True, check=True).stdout
    symbols = {}
    for line in listing.splitlines():
        fields = line.split()
        if len(fields) >= 8 and fields[3] == "FUNC" and fields[6] != "UND":
            symbols[fields[7]] = (int(fields[1], 16), int(fields[2], 0))
    return symbols


def by_function(returns: list[tuple[int, int]], symbols: dict[str, tuple[int, int]]) -> dict[str, int]:
    """Operations per function, most first, from (return address as an offset in the object, count) pairs: each goes
    to the function whose code holds it (its :func:`demangle`\\ d name), or to ``"elsewhere"``."""
    ranges = sorted((offset, offset + size, demangle(name)) for name, (offset, size) in symbols.items())
    totals: dict[str, int] = {}
    for address, count in returns:
        owner = next((name for low, high, name in ranges if low <= address < high), "elsewhere")
        totals[owner] = totals.get(owner, 0) + count
    return dict(sorted(totals.items(), key=lambda item: -item[1]))


DEBUG_CACHE = ROOT / "out" / "refcounts_debug_cache"
"""Where ``--lines`` keeps the package compiled with debug information, in a folder per version of its source
(:func:`debug_cache`)."""


def debug_cache(tree: Path) -> Path:
    """The debug build's cache for ``tree``'s package as its source is now, the others removed. Numba checks a
    cached function against its own file only, not against the files of what it inlined, so a cache kept across
    edits of another file would count the old code."""
    digest = hashlib.sha256()
    for path in sorted((tree / "soft_gripper_env").rglob("*.py")):
        digest.update(str(path.relative_to(tree)).encode() + b"\0" + path.read_bytes())
    folder = DEBUG_CACHE / digest.hexdigest()[:16]
    if DEBUG_CACHE.exists():
        for other in DEBUG_CACHE.iterdir():
            if other != folder:
                shutil.rmtree(other) if other.is_dir() else other.unlink()
    return folder


def source_lines(objects: list[tuple[Path, int]], returns: list[tuple[int, int]]) -> dict[str, int]:
    """Operations per source line (``file:line``, the file's path from the package's folder on), most first, from
    (return address, count) pairs and the ``objects`` the code lies in, each with the address its offsets start
    from, through ``addr2line``: a call's line is that of the byte before its return address; a line inlined into
    another is its own."""
    ranges = sorted((base + offset, base + offset + size, path, base) for path, base in objects
                    for offset, size in function_symbols(path).values())
    starts = [low for low, _, _, _ in ranges]
    by_object: dict[Path, list[tuple[int, int]]] = {}
    totals: dict[str, int] = {}
    for address, n in returns:
        k = bisect.bisect_right(starts, address - 1) - 1
        if k >= 0 and ranges[k][0] <= address - 1 < ranges[k][1]:
            by_object.setdefault(ranges[k][2], []).append((address - 1 - ranges[k][3], n))
        else:
            totals["elsewhere"] = totals.get("elsewhere", 0) + n
    for path, calls in by_object.items():
        listing = subprocess.run(["addr2line", "-e", str(path)] + [hex(offset) for offset, _ in calls],
                                 capture_output=True, text=True, check=True).stdout.splitlines()
        for (_, n), where in zip(calls, listing, strict=True):
            where = where.split(" (discriminator")[0]
            marker = where.find("soft_gripper_env/")
            where = where[marker + len("soft_gripper_env/"):] if marker >= 0 else where
            totals[where] = totals.get(where, 0) + n
    return dict(sorted(totals.items(), key=lambda item: -item[1]))


def count_env(tree: Path, model: str, steps: int, lines: bool = False, allocations: bool = False) -> dict:
    """Reference-count operations (or, with ``allocations``, calls of Numba's array allocators, :data:`ALLOCATORS`)
    over ``steps`` env steps in ``model``: per env step, in all, by function and, with ``lines``, by source line
    (compiled with debug information, :data:`DEBUG_CACHE`)."""
    with tempfile.TemporaryDirectory() as tmp:
        address_file, object_file, counts_file, script = (Path(tmp) / name for name in
                                                          ("address", "object.o", "counts.json", "count.gdb"))
        script.write_text(_ENV_GDB.format(address_file=str(address_file), counts_file=str(counts_file)))
        environment = dict(os.environ)
        if lines:
            environment.update(NUMBA_DEBUGINFO="1", NUMBA_CACHE_DIR=str(debug_cache(tree)))
        # a run that compiles the package sees only the control interval's object, not the other libraries' that
        # the lines need: with --lines it fills the cache, and a second run, which loads everything from it, counts
        for _ in range(2 if lines else 1):
            done = subprocess.run(["gdb", "-q", "-batch", "-x", str(script), "--args", sys.executable, "-c",
                                   _ENV_CHILD, str(tree), model, str(steps), str(address_file), str(object_file),
                                   "allocations" if allocations else "refcounts"],
                                  cwd=tree, capture_output=True, text=True, timeout=3600, env=environment)
            if not Path(f"{object_file}.compiled").exists():
                break
            Path(f"{object_file}.compiled").unlink()
        if not counts_file.exists():
            raise RuntimeError(f"gdb wrote no counts:\n{(done.stdout + done.stderr)[-3000:]}")
        returns = [(int(address), int(n)) for address, n in json.loads(counts_file.read_text())]
        functions = by_function(returns, function_symbols(object_file))
        by_line = {}
        if lines:  # the offsets are from the interval's object's start; other libraries' code lies elsewhere
            base = int(address_file.read_text().split()[0])
            others = [(Path(path), other) for path, other in json.loads(Path(f"{object_file}.others").read_text())]
            by_line = source_lines([(object_file, base)] + others, [(base + a, n) for a, n in returns])
    total = sum(functions.values())
    result = {"model": model, "counted": "allocations" if allocations else "reference counts", "env_steps": steps,
              "per_env_step": total / steps,
              "by_function_per_env_step": {name: n / steps for name, n in functions.items()}}
    if lines:
        result["by_line_per_env_step"] = {where: n / steps for where, n in by_line.items()}
    return result


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
    parser.add_argument("--env", choices=MODELS, help="count whole env steps in this model instead, by function")
    parser.add_argument("--steps", type=int, default=1, help="env steps counted with --env (default 1)")
    parser.add_argument("--lines", action="store_true",
                        help="with --env, also by source line (compiles with debug information, cached apart)")
    parser.add_argument("--allocations", action="store_true",
                        help="with --env, count Numba's array allocations instead of reference counts")
    args = parser.parse_args(argv)
    if args.env is not None:
        return _main_env(parser, args)
    for flag in ("lines", "allocations"):
        if getattr(args, flag):
            parser.error(f"--{flag} counts within env steps: give --env MODEL with it")
    if not 1 <= args.calls <= 10_000:
        parser.error(f"--calls = {args.calls} must be within [1, 10000]")
    _require(parser, "gdb")
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
    _write_json(args.json, results)
    return results


def _require(parser: argparse.ArgumentParser, *tools: str) -> None:
    """Stops with a usage error naming each of ``tools`` that is not on the PATH (gdb counts the operations with
    breakpoints; readelf names the functions that make them)."""
    missing = [tool for tool in tools if shutil.which(tool) is None]
    if missing:
        parser.error(f"{' and '.join(missing)} needed and not on the PATH")


def _write_json(path: Path | None, results: dict) -> None:
    """Writes ``results`` to ``path`` (its folder made), unless ``path`` is None."""
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {path}")


def _main_env(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict:
    """``--env``: counts and prints an env step's operations by function."""
    if not 1 <= args.steps <= 100:
        parser.error(f"--steps = {args.steps} must be within [1, 100]")
    _require(parser, "gdb", "readelf", *(("addr2line",) if args.lines else ()))
    print(f"counting {args.steps} env step(s), {args.env}" + (" by line (debug build, may compile first)"
                                                              if args.lines else "") + " ...", flush=True)
    result = count_env(ROOT, args.env, args.steps, args.lines, args.allocations)
    total = result["per_env_step"]
    counted = "array allocations" if args.allocations else "reference-count operations"
    for key, what in (("by_function_per_env_step", "function"), ("by_line_per_env_step", "source line")):
        if key in result:
            print(f"\n{total:,.0f} {counted} per env step ({args.env}), by {what}:")
            for name, n in list(result[key].items())[:25]:
                print(f"{n:>10,.0f}  {100 * n / total:5.1f} %  {name}")
    _write_json(args.json, result)
    return result


if __name__ == "__main__":
    main()
