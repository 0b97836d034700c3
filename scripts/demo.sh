#!/usr/bin/env bash
# Sets up .venv, then reproduces the paper's figures into out/paper (or the folder given as the first argument).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
exec .venv/bin/python examples/reproduce_paper.py --out "${1:-out/paper}"
