"""Where an env step's time goes, by compiled function: a sampling profile of the environment under ``perf``.

    python -m tools.profile_env [--model planar|3d] [--envs 64] [--steps 100] [--policy random|reactive]
                                     [--json out/profile_env.json]

It runs ``SoftGripperUnderwater-v0`` (one env, or ``gym.make_vec`` with ``--envs``) on random actions, or grasping
under the reactive controller (``agents.scripted.ReactivePolicy``, as ``env_speed``'s grasping figures), in a child
process under ``perf record``, one Numba and one BLAS thread, and gives each sample to the function whose code
holds it: the compiled control interval's functions (``solvers.stepping.take_steps`` and everything Numba or LLVM
linked into it, read from its object code as Numba loads it, as :mod:`tools.refcounts` does), or the symbol
``perf`` names (the interpreter, NumPy, the C library). Samples in Numba's runtime, whose ``NRT_incref`` and
``NRT_decref`` are the atomic reference counts, have no symbol ``perf`` can read; they count as
``runtime (reference counts)`` when they fall in the runtime's small block of code around those two functions.

Only the timed steps count: sampling starts after the env is made and warmed up (a dozen steps), and stops before the
child exits (its shutdown is a full garbage collection and the freeing of every module). Shares are of the samples
taken, so they do not depend on the machine's speed, though a busy machine adds its noise. Needs perf and readelf.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tools.compare_commits import ENV_AND_POLICY, ROOT
from tools.refcounts import _require, _write_json, by_function, function_symbols

RUNTIME_BLOCK = 64
"""Bytes from ``NRT_incref``'s start within which a sample counts as the reference counts (the two functions and
the atomic helpers they call lie together in the runtime's module)."""

POLICIES = ("random", "reactive")
"""What drives the profiled env: random actions, or the reactive controller grasping."""

PERF_ATTACH_S = 0.5
"""Seconds given ``perf record`` to attach to the child before its timed steps begin."""

_CHILD = """
import json, os, sys, time
os.environ.setdefault('NUMBA_NUM_THREADS', '1')
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
model, envs, steps, out, policy = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
import numba.core.codegen as codegen
objects = []
set_compiled_object = codegen.CPUCodeLibrary._set_compiled_object
def keep(library, value):
    objects.append((library, bytes(value)))
    return set_compiled_object(library, value)
codegen.CPUCodeLibrary._set_compiled_object = keep
from pathlib import Path
from numba.core.runtime import rtsys
from soft_gripper_env.physics.solvers import stepping
from tools.refcounts import function_symbols
num_envs = envs
""" + ENV_AND_POLICY + """def run(n):
    global observation
    for _ in range(n):
        observation, _, terminated, truncated, _ = env.step(act(observation))
        if envs == 1 and (terminated or truncated):
            observation, _ = env.reset()
run(12)
(result,) = stepping.take_steps.overloads.values()
code = [value for owner, value in objects if owner is result.library] or [bytes(result.library._get_compiled_object())]
Path(out + '.o').write_bytes(code[-1])
name = result.fndesc.llvm_func_name
base = result.library.get_pointer_to_function(name) - function_symbols(Path(out + '.o'))[name][0]
Path(out + '.json').write_text(json.dumps({'base': base,
                                           'incref': rtsys.library.get_pointer_to_function('NRT_incref')}))
print('ready', flush=True)
sys.stdin.readline()  # the parent is sampling
start = time.perf_counter()
run(steps)
Path(out + '.time').write_text(str(time.perf_counter() - start))
print('done', flush=True)
sys.stdin.readline()  # the parent has stopped sampling: the interpreter's shutdown is not the env's time
"""


def attribute(samples: list[tuple[int, str]], base: int, symbols: dict[str, tuple[int, int]],
              runtime: int) -> dict[str, int]:
    """Samples per function, most first, from (instruction address, ``perf``'s symbol) pairs: an address in the
    control interval's object (which starts at ``base``) goes to its compiled function (:func:`~tools.
    refcounts.by_function`), one within :data:`RUNTIME_BLOCK` bytes of ``runtime`` (``NRT_incref``) to the
    reference counts, any other to ``perf``'s symbol."""
    totals: dict[str, int] = {}
    compiled = []
    ends = {name: offset + size for name, (offset, size) in symbols.items()}
    low, high = min(o for o, _ in symbols.values()), max(ends.values())
    for address, symbol in samples:
        if low <= address - base < high:
            compiled.append((address - base, 1))
        elif runtime <= address < runtime + RUNTIME_BLOCK:
            totals["runtime (reference counts)"] = totals.get("runtime (reference counts)", 0) + 1
        else:
            name = symbol if symbol and not symbol.startswith("[unknown]") else "unknown"
            totals[name] = totals.get(name, 0) + 1
    for name, n in by_function(compiled, symbols).items():
        totals[name] = totals.get(name, 0) + n
    return dict(sorted(totals.items(), key=lambda item: -item[1]))


def profile(model: str, envs: int, steps: int, frequency: int, policy: str = "random") -> dict:
    """Runs the child under ``perf record`` and returns the share of samples per function; ``policy`` is
    ``"random"`` or ``"reactive"``."""
    if policy not in POLICIES:
        raise ValueError(f"policy = {policy!r} must be one of {POLICIES}")
    with tempfile.TemporaryDirectory() as tmp:
        out, data = str(Path(tmp) / "interval"), Path(tmp) / "perf.data"
        child = subprocess.Popen([sys.executable, "-c", _CHILD, model, str(envs), str(steps), out, policy], cwd=ROOT,
                                 env={**os.environ, "PYTHONPATH": str(ROOT)}, stdin=subprocess.PIPE,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            if child.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the env did not start:\n{child.communicate()[1][-3000:]}")
            recorder = subprocess.Popen(["perf", "record", "-F", str(frequency), "-p", str(child.pid), "-o",
                                         str(data)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            time.sleep(PERF_ATTACH_S)
            child.stdin.write("go\n")
            child.stdin.flush()
            child.stdout.readline()  # "done", or nothing if the child failed
            recorder.send_signal(signal.SIGINT)  # before the child exits: its shutdown (a full garbage
            recorder.wait()  # collection, freeing every module) took a sixth of a short run's samples
            _, errors = child.communicate("exit\n")
            if child.returncode != 0:
                raise RuntimeError(f"the env failed:\n{errors[-3000:]}")
        finally:
            child.kill()
        listing = subprocess.run(["perf", "script", "-i", str(data), "-F", "ip,sym"], capture_output=True,
                                 text=True).stdout
        samples = []
        for line in listing.splitlines():
            parts = line.split(None, 1)
            if parts:
                try:
                    samples.append((int(parts[0], 16), parts[1].strip() if len(parts) > 1 else ""))
                except ValueError:
                    continue
        where = json.loads(Path(out + ".json").read_text())
        totals = attribute(samples, where["base"], function_symbols(Path(out + ".o")), where["incref"])
        seconds = float(Path(out + ".time").read_text())
    count = sum(totals.values())
    return {"model": model, "envs": envs, "steps": steps, "policy": policy, "env_steps_per_s": steps * envs / seconds,
            "samples": count, "share_by_function": {name: n / count for name, n in totals.items()}}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", choices=("planar", "3d"), default="planar")
    parser.add_argument("--envs", type=int, default=64, help="1 for one env, else make_vec's size (default 64)")
    parser.add_argument("--steps", type=int, default=100, help="timed actions (default 100)")
    parser.add_argument("--policy", choices=POLICIES, default="random",
                        help="random actions, or the reactive controller grasping (default random)")
    parser.add_argument("--frequency", type=int, default=4000, help="samples per second (default 4000)")
    parser.add_argument("--json", type=Path, help="write the profile to this JSON file")
    args = parser.parse_args(argv)
    if not 1 <= args.envs <= 1024:
        parser.error(f"--envs = {args.envs} must be within [1, 1024]")
    if not 1 <= args.steps <= 100_000:
        parser.error(f"--steps = {args.steps} must be within [1, 100000]")
    if not 100 <= args.frequency <= 20_000:
        parser.error(f"--frequency = {args.frequency} Hz must be within [100, 20000]")
    _require(parser, "perf", "readelf")
    what = "one env" if args.envs == 1 else f"make_vec({args.envs})"
    print(f"profiling {args.steps} {args.policy} actions of {what}, {args.model} ...", flush=True)
    result = profile(args.model, args.envs, args.steps, args.frequency, args.policy)
    print(f"\n{result['samples']:,} samples, {result['env_steps_per_s']:,.0f} env steps/s while sampled; by function:")
    for name, share in list(result["share_by_function"].items())[:30]:
        print(f"{100 * share:6.2f} %  {name}")
    _write_json(args.json, result)
    return result


if __name__ == "__main__":
    main()
