#!/usr/bin/env bash
# Creates .venv (if needed) and installs the project with its test and RL dependencies, torch pinned to the CPU
# build. Re-runs are quick: nothing is reinstalled unless pyproject.toml or the constraints changed.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
python="${PYTHON:-python3}"
if [[ ! -x .venv/bin/python ]]; then
    echo "setup: creating .venv with $($python --version)"
    "$python" -m venv .venv
fi
stamp=".venv/.installed-$(cat pyproject.toml requirements/cpu.txt | sha1sum | cut -c1-16)"
if [[ ! -f "$stamp" ]]; then
    echo "setup: installing soft-gripper-env and its dependencies into .venv (torch: CPU build)"
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet -c requirements/cpu.txt torch
    .venv/bin/python -m pip install --quiet -c requirements/cpu.txt -e ".[dev,rl,bench]"
    rm -f .venv/.installed-*
    touch "$stamp"
fi
