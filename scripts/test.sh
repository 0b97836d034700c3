#!/usr/bin/env bash
# Sets up .venv, compiles the kernels once, then runs the test suite on every core (pytest-xdist, one test file per
# worker at a time). Extra arguments go to pytest, e.g. `bash scripts/test.sh -m "not slow"`, or `-n 0` to run in one
# process.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
# every kind of kernel the tests use, compiled side by side before the workers start, each once: otherwise the
# workers and the tests' own processes compile the same ones at once (seconds when Numba's cache holds them)
.venv/bin/python -m soft_gripper_env.precompile
exec .venv/bin/python -m pytest -n auto --dist loadfile "$@"
