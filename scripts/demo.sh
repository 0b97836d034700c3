#!/usr/bin/env bash
# Sets up .venv, reproduces the paper's figures into out/paper, and records two grasp episodes of the
# SoftGripperUnderwater-v0 environment into out/video (or under the folder given as the first argument): the paper's
# ramp as a policy, which crushes the specimen, and the shipped PPO policy holding it through the gust.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."
bash scripts/setup.sh
out="${1:-out}"
# the kernels the demo's three kinds of scene use (fixed ball, no object, free sphere), compiled side by side first
.venv/bin/python -m soft_gripper_env.precompile
.venv/bin/python -m examples.reproduce_paper --out "$out/paper"
.venv/bin/python -m examples.record_video --out "$out/video" --policy ramp
.venv/bin/python -m examples.record_video --out "$out/video" --policy pretrained --gif --frame-at 2.5
