#!/usr/bin/env bash
# Sets up .venv, then runs the test suite on every core (pytest-xdist, one test file per worker at a time). Extra
# arguments go to pytest, e.g. `bash scripts/test.sh -m "not slow"`, or `-n 0` to run in one process.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/python -m pytest -n auto --dist loadfile "$@"
