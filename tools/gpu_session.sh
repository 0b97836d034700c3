#!/usr/bin/env bash
# The GPU back end's checks and figures on a machine with an NVIDIA GPU, for a developer with a few minutes of a lent
# GPU (issue 47): run from the repository root, results written under $OUT (default out/gpu).
#
#   bash tools/gpu_session.sh speed      # benchmarks/gpu_speed.py, 3-D first (JSON + plot; its "agreement" stage
#                                        #   is the 1 s GPU-against-CPU trajectory check)
#   bash tools/gpu_session.sh outcomes   # benchmarks/gpu_outcomes.py, both parts, 1,000 seeds per model
#   bash tools/gpu_session.sh tests      # the tests marked gpu
#
# Each part is one Python process after the warm-up, because the CUDA kernels are compiled in the process that
# launches them (a minute or more each, not kept on disk) while the CPU kernels are cached on disk: the warm-up
# compiles those from an empty cache with one process per model side by side on the machine's cores. The machine
# needs python3 with numpy, numba and numba-cuda (and scipy, matplotlib, tqdm); packages it lacks (gymnasium, from
# this project's dependencies) can come as wheels in .whl/, installed into /tmp/site. Each part stops itself before
# the device tool's 10-minute limit (GPU_SESSION_BUDGET_S, default 540 s) and keeps what it has written.
set -uo pipefail

part="${1:-}"
if [[ "$part" != speed && "$part" != outcomes && "$part" != tests ]]; then
    echo "usage: bash tools/gpu_session.sh speed|outcomes|tests (results under \$OUT, default out/gpu)" >&2
    exit 2
fi
OUT="${OUT:-out/gpu}"
mkdir -p "$OUT"
budget="${GPU_SESSION_BUDGET_S:-540}"
start=$(date +%s)
left() { echo $((budget - ($(date +%s) - start))); }
log() { echo "[gpu_session $(($(date +%s) - start)) s] $*" | tee -a "$OUT/session.log"; }

if compgen -G ".whl/*.whl" > /dev/null; then
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl \
        || { log "installing the carried wheels failed"; exit 1; }
    export PYTHONPATH="/tmp/site:${PYTHONPATH:-}"
fi
export PYTHONPATH=".:${PYTHONPATH:-}"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv > "$OUT/gpu.csv" 2>&1
log "device: $(tail -n 1 "$OUT/gpu.csv")"
python3 - > "$OUT/versions.txt" 2>&1 <<'EOF'
import importlib
for name in ("numpy", "numba", "numba_cuda", "scipy", "matplotlib", "gymnasium", "tqdm"):
    try:
        print(name, importlib.import_module(name).__version__)
    except Exception as error:  # noqa: BLE001 - report whatever stops it
        print(name, "missing:", error)
EOF

warm() {  # the CPU kernels, cached on disk: the env in each model, side by side
    log "warming the CPU kernels' cache"
    local pids=()
    for model in 3d planar; do
        python3 -c "
import gymnasium as gym, numpy as np, soft_gripper_env
env = gym.make('SoftGripperUnderwater-v0', model='$model'); env.reset(seed=0); env.step(np.zeros(3))" \
            > "$OUT/warm_env_$model.log" 2>&1 &
        pids+=($!)
    done
    for pid in "${pids[@]}"; do wait "$pid" || log "a warming process failed (see $OUT/warm_*.log)"; done
    log "cache warm"
}

case "$part" in
speed)
    warm
    log "benchmarks/gpu_speed.py"
    # 3-D first (the default model, the issue's first goal); the JSON is written after every stage
    timeout "$(left)" python3 -m benchmarks.gpu_speed --json "$OUT/gpu_speed.json" --plot "$OUT/gpu_speed.png" \
        --models 3d,planar --sizes "${GPU_SESSION_SIZES:-1024,8192,32768}" --steps "${GPU_SESSION_STEPS:-10}" \
        --intervals 3 \
        > "$OUT/gpu_speed.log" 2>&1
    log "gpu_speed: exit $? (the JSON keeps every stage it finished)"
    ;;
tests)
    warm
    log "the tests marked gpu"
    timeout "$(left)" python3 -m pytest -q -p no:cacheprovider -m gpu tests/physics/test_gpu.py \
        > "$OUT/gpu_tests.log" 2>&1
    log "tests: $(tail -n 1 "$OUT/gpu_tests.log")"
    ;;
outcomes)
    warm
    episodes="${GPU_SESSION_EPISODES:-1000}"
    log "benchmarks/gpu_outcomes.py --part cpu, $episodes seeds per model, on every core"
    timeout "$(left)" python3 -m benchmarks.gpu_outcomes --part cpu --episodes "$episodes" --workers "$(nproc)" \
        --runs "$OUT/gpu_outcomes_runs" > "$OUT/gpu_outcomes_cpu.log" 2>&1
    log "cpu part: exit $?"
    timeout "$(left)" python3 -m benchmarks.gpu_outcomes --part cuda --episodes "$episodes" \
        --runs "$OUT/gpu_outcomes_runs" --json "$OUT/gpu_outcomes.json" --plot "$OUT/gpu_outcomes.png" \
        > "$OUT/gpu_outcomes_cuda.log" 2>&1
    log "cuda part: exit $?"
    ;;
esac
log "done"
