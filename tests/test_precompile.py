"""`python -m soft_gripper_env.precompile`: the kernels compiled ahead of their first use, into Numba's cache."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from soft_gripper_env.precompile import OBJECTS, compile_kernels, main

ROOT = Path(__file__).resolve().parents[1]


def _precompile(*arguments: str, cache: Path | None = None) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    run = subprocess.run([sys.executable, "-m", "soft_gripper_env.precompile", *arguments], capture_output=True,
                         text=True, env=env, cwd=ROOT, timeout=900)
    assert run.returncode == 0, run.stdout[-2000:] + run.stderr[-3000:]
    return run.stdout


@pytest.mark.slow
def test_from_an_empty_cache_it_compiles_and_a_new_process_then_compiles_nothing(tmp_path):
    """The fingers alone (the cheapest kind, about 45 s of CPU) into an empty cache of their own: the first run
    compiles the package's functions, the second, a new process stepping the same scene, finds them all cached."""
    first = _precompile("--objects", "none", cache=tmp_path).splitlines()
    assert re.fullmatch(r"precompile: none: ([0-9]+) functions compiled \([0-9.]+ s of CPU\)", first[1]), first
    assert int(first[1].split()[2]) > 10
    second = _precompile("--objects", "none", cache=tmp_path).splitlines()
    assert re.fullmatch(r"precompile: none: nothing left to compile \([0-9.]+ s of CPU\)", second[1]), second


@pytest.mark.slow
def test_after_a_precompile_a_new_process_finds_every_kernel_compiled():
    """Two runs one after the other, each kind of object in processes of their own: whatever the first had to
    compile (nothing where the cache was full), the second, new processes stepping the same scenes, compiles
    nothing. A line for every kind, and one line saying what is going on before them."""
    _precompile("--processes", "2")
    out = _precompile("--processes", "2")
    lines = out.splitlines()
    assert len(lines) == 1 + len(OBJECTS) and "in 2 processes" in lines[0]
    for name, line in zip(OBJECTS, lines[1:], strict=True):
        assert re.fullmatch(rf"precompile: {name}: nothing left to compile \([0-9.]+ s of CPU\)", line), line


@pytest.mark.parametrize("arguments, message", [
    (["--objects", "ball"], "--objects must name one or more of free, fixed, none, got 'ball'"),
    (["--objects", ","], "--objects must name one or more of free, fixed, none, got ','"),
    (["--processes", "0"], "--processes must be at least 1, got 0"),
])
def test_bad_arguments_are_refused_by_name(arguments, message, capsys):
    with pytest.raises(SystemExit) as stop:
        main(arguments)
    assert stop.value.code == 2
    assert message in capsys.readouterr().err


def test_an_unknown_object_is_refused_before_anything_compiles():
    with pytest.raises(ValueError, match=r"grasped must be one of \('free', 'fixed', 'none'\), got 'ball'"):
        compile_kernels("ball")
