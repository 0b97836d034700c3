"""Compiles the physics kernels into Numba's cache before their first use, side by side on the machine's cores.

    python -m soft_gripper_env.precompile [--objects free,fixed,none] [--processes N]

Numba compiles a kernel on its first call on a machine and keeps it in its cache (``__pycache__`` beside the
sources); later processes load it in seconds. The kernels are compiled once for each kind of grasped object, since
a kernel is specialised on what the fingers grasp (one set serves both rod models and any batch size):

- ``free``: a free body, the env's sphere (``gym.make("SoftGripperUnderwater-v0")``, either model): about 100 s
  of CPU from an empty cache;
- ``fixed``: a fixed object, such as the paper's ball: about 85 s alone, 45 s more after ``none``;
- ``none``: the fingers alone: about 45 s alone, 20 s more after ``fixed``.

Compilation is single-threaded, so the kinds asked for are compiled in several processes at once (by default
one per core, at most one per kind): on two cores all three take about as long as the env's kind alone. Each
process steps a two-gripper :class:`~soft_gripper_env.physics.Simulator` of the default task's scene with that
object and reports how many of this package's functions it compiled: none where the cache already holds them.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace

import numpy as np

from .grasp_task import GraspTask, task_episode
from .physics import PAPER_BALL, Simulator
from .physics.kernels import compile_notice

OBJECTS = ("free", "fixed", "none")
"""What the fingers grasp, each its own set of compiled kernels: a free body, a fixed object, nothing."""


def compile_kernels(grasped: str) -> tuple[float, int]:
    """Steps the default task's scene with the object ``grasped`` (one of :data:`OBJECTS`) in this process,
    compiling what Numba's cache lacks. Returns (CPU time [s], how many of this package's functions it compiled
    rather than found compiled)."""
    if grasped not in OBJECTS:
        raise ValueError(f"grasped must be one of {OBJECTS}, got {grasped!r}")
    compiled_before, start = compile_notice.LISTENER.compiled, time.process_time()
    scene = task_episode(GraspTask(), np.random.default_rng(0), {}).scene
    if grasped != "free":
        scene = replace(scene, grasped_object=PAPER_BALL if grasped == "fixed" else None)
    sim = Simulator([scene, scene])
    # two grippers closing at different rates for a few steps: the paths a control interval takes, contact included
    rates = np.outer([-0.3, -0.2], np.ones(scene.gripper.n_fingers))
    sim.advance(sim.initial_state(), np.zeros_like(rates), rates, 4, (-1.0, 1.0))
    return time.process_time() - start, compile_notice.LISTENER.compiled - compiled_before


def _usable_cores() -> int:
    """The cores this process may run on (a container's share, not the host's count, where the OS says)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _quiet_child() -> None:
    compile_notice.LISTENER.said = True  # the parent has said what is going on


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m soft_gripper_env.precompile",
                                     description=__doc__.split("\n")[0])
    parser.add_argument("--objects", default=",".join(OBJECTS),
                        help=f"comma-separated kinds of grasped object, of {', '.join(OBJECTS)} (default: all)")
    parser.add_argument("--processes", type=int, default=None,
                        help="processes side by side, at least 1 (default: one per core, at most one per kind)")
    arguments = parser.parse_args(argv)
    objects = [name.strip() for name in arguments.objects.split(",") if name.strip()]
    if not objects or any(name not in OBJECTS for name in objects):
        parser.error(f"--objects must name one or more of {', '.join(OBJECTS)}, got {arguments.objects!r}")
    arguments.objects = list(dict.fromkeys(objects))
    if arguments.processes is not None and arguments.processes < 1:
        parser.error(f"--processes must be at least 1, got {arguments.processes}")
    return arguments


def main(argv: list[str] | None = None) -> dict[str, tuple[float, int]]:
    """Compiles the kinds named by ``--objects``, side by side; prints a line as each finishes and returns
    {kind: (CPU seconds, functions compiled)}."""
    arguments = _parse(argv)
    objects = arguments.objects
    processes = arguments.processes or max(1, min(len(objects), _usable_cores()))
    print(f"precompile: the kernels for {', '.join(objects)} objects in {processes} "
          f"process{'es' if processes > 1 else ''} (from an empty cache about one and a half minutes on 2 cores; "
          "from a full one, seconds)", flush=True)
    results = {}
    # each process starts empty (spawn, not fork): a fork would inherit what this one has compiled
    with ProcessPoolExecutor(processes, mp_context=multiprocessing.get_context("spawn"),
                             initializer=_quiet_child) as pool:
        futures = {name: pool.submit(compile_kernels, name) for name in objects}
        for name, future in futures.items():
            seconds, compiled = future.result()
            results[name] = (seconds, compiled)
            what = f"{compiled} functions compiled" if compiled else "nothing left to compile"
            print(f"precompile: {name}: {what} ({seconds:.1f} s of CPU)", flush=True)
    return results


if __name__ == "__main__":
    main(sys.argv[1:])
