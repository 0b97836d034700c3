#!/usr/bin/env bash
# Sets up .venv, reproduces the paper's figures into out/paper, and records a video of the paper's ramp as a
# policy in the SoftGripperUnderwater-v0 environment into out/video (or under the folder given as the first
# argument).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
out="${1:-out}"
.venv/bin/python -m examples.reproduce_paper --out "$out/paper"
.venv/bin/python -m examples.record_ramp_video --out "$out/video"
