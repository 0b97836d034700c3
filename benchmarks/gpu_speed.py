"""The GPU back end against the CPU path, measured side by side in one run: speed and agreement.

    python -m benchmarks.gpu_speed --json out/gpu_speed.json [--plot out/gpu_speed.png] [--sizes 1024,4096,...]
    python -m benchmarks.gpu_speed --plot-only out/gpu_speed.json --plot docs/img/gpu_speed.png

Two workloads (``--workloads``), each in both rod models:

**grasp**: the env itself, ``SoftGripperUnderwaterVectorEnv(num_envs, device=...)`` (what ``gym.make_vec`` builds),
driven by random actions and by the reactive controller (``agents.scripted.ReactivePolicy``), episodes resetting
as they end:

- **GPU speed** for each of ``--sizes`` envs: env steps per second over ``--steps`` actions after a first one (whose
  time, less a later one's, is mostly the kernels' compile), and the share of that time spent in the physics
  (``Simulator.advance``) against the task's own work on the host, with the physics' shares split into the copies to
  the device, the kernel (halved steps included) and the copies back (``gpu_phase_shares``);
- **the CPU anchor, in the same run**: ``make_vec(64)`` on one thread with the same controller, and the ratio of
  each GPU figure to it.

**fingers**: the env's **fingers alone**, with nothing to grasp, the ceiling of the physics. Each gripper has the
scene of one of the task's episodes (its gripper, water, current, Δt and Newton settings) without its specimen, and
every control interval (``control_dt``, the task's substeps) takes a random natural-curvature rate per finger
within the task's range, κ̄ kept within [−0.2, 0.2]: the physics of random actions, without the task.

- **agreement**: 8 grippers for ``--agreement-seconds`` (1 s) of such intervals on the CPU and on the GPU, from the
  same start with the same rates: the largest distance between any node's world positions at any interval's end
  [m], and the Newton iterations of each;
- **GPU speed**: ``Simulator(..., device="cuda").advance`` over one control interval, for each of ``--sizes``
  grippers: env steps per second (grippers × intervals / seconds) and µs per gripper-step, end to end (the state
  kept on the device and copied back at every call), and the kernel alone (CUDA's own clock); the first call's time
  less a later one's is the kernel's compile time;
- **the CPU anchor, in the same run**: the same intervals on the CPU path for 64 grippers in one batch on one
  thread (the ``make_vec(64)`` layout), and the ratio of each GPU figure to it.

Without a GPU (or numba-cuda) it says so and times nothing on the GPU. The grasp workload needs Gymnasium (the
``rl`` extra); without it, that workload records why it did not run.
"""

from __future__ import annotations

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from soft_gripper_env.grasp_task import GraspTask, task_episode  # noqa: E402
from soft_gripper_env.physics import Simulator  # noqa: E402

SIZES = (1024, 4096, 16384, 65536)
"""Grippers per batch on the GPU."""
CPU_BATCH = 64
"""Grippers in the CPU anchor's batch (the make_vec(64) layout, one thread)."""
CURVATURE_RANGE = (-0.2, 0.2)
"""κ̄ kept within this range (dimensionless): the env's actuation."""
AGREEMENT_GRIPPERS = 8


def fingers_alone(model: str, n_grippers: int) -> tuple[list, GraspTask]:
    """The scenes of the task's first ``n_grippers`` episodes (seeds 0, 1, …) without their specimens, and the
    task."""
    task = GraspTask(model=model)
    scenes = [replace(task_episode(task, np.random.default_rng(seed), {}).scene, grasped_object=None)
              for seed in range(n_grippers)]
    return scenes, task


def random_rates(task: GraspTask, n_grippers: int, n_intervals: int, seed: int = 0) -> np.ndarray:
    """A random κ̄ rate per interval, gripper and finger [1/s], (K, B, F), uniform within the task's range."""
    rng = np.random.default_rng(seed)
    return task.max_curvature_rate * rng.uniform(-1.0, 1.0, (n_intervals, n_grippers, task.gripper.n_fingers))


def run_intervals(sim: Simulator, rates: np.ndarray, substeps: int, record: bool = False):
    """``len(rates)`` control intervals of ``substeps`` steps from the initial state; returns the final advance,
    the wall time [s] of each interval, and (with ``record``) the world positions after each, (K, B, F, N, 3)."""
    state = sim.initial_state()
    curvature = np.zeros(rates.shape[1:])
    seconds, positions, advanced = [], [], None
    for rate in rates:
        start = time.perf_counter()
        advanced = sim.advance(state, curvature, rate, substeps, CURVATURE_RANGE)
        seconds.append(time.perf_counter() - start)
        state, curvature = advanced.state, advanced.natural_curvature
        if record:
            positions.append(sim.world_positions(state))
    return advanced, np.array(seconds), (np.stack(positions) if record else None)


def agreement(model: str, seconds: float) -> dict:
    """CPU and GPU from the same start with the same rates for ``seconds`` of intervals."""
    scenes, task = fingers_alone(model, AGREEMENT_GRIPPERS)
    n_intervals = int(round(seconds / task.control_dt))
    rates = random_rates(task, AGREEMENT_GRIPPERS, n_intervals, seed=1)
    runs = {}
    for device in ("cpu", "cuda"):
        advanced, _, positions = run_intervals(Simulator(scenes, device=device), rates, task.substeps, record=True)
        runs[device] = (advanced, positions)
    (cpu, cpu_positions), (gpu, gpu_positions) = runs["cpu"], runs["cuda"]
    return {"grippers": AGREEMENT_GRIPPERS, "simulated_s": n_intervals * task.control_dt,
            "max_position_difference_m": float(np.abs(cpu_positions - gpu_positions).max()),
            "newton_iterations_cpu": cpu.newton_iterations.tolist(),
            "newton_iterations_gpu": gpu.newton_iterations.tolist(),
            "failed_cpu": int(cpu.failed.sum()), "failed_gpu": int(gpu.failed.sum())}


def cpu_anchor(model: str, n_intervals: int) -> dict:
    """The CPU path's figures for :data:`CPU_BATCH` grippers, one thread (after a warm-up interval)."""
    scenes, task = fingers_alone(model, CPU_BATCH)
    sim = Simulator(scenes)
    run_intervals(sim, random_rates(task, CPU_BATCH, 1), task.substeps)
    _, seconds, _ = run_intervals(sim, random_rates(task, CPU_BATCH, n_intervals), task.substeps)
    total = float(seconds.sum())
    return {"grippers": CPU_BATCH, "intervals": n_intervals, "substeps": task.substeps,
            "env_steps_per_s": CPU_BATCH * n_intervals / total,
            "us_per_gripper_step": 1e6 * total / (CPU_BATCH * n_intervals * task.substeps)}


def gpu_speed(model: str, size: int, n_intervals: int) -> dict:
    """The GPU's figures for ``size`` grippers: end to end through ``Simulator.advance``, and the kernel alone."""
    from soft_gripper_env.physics.solvers.gpu import THREADS_PER_BLOCK, cuda_module, rods_kernel

    cuda = cuda_module()
    scenes, task = fingers_alone(model, min(size, 256))
    scenes = (scenes * (size // len(scenes) + 1))[:size]
    start = time.perf_counter()
    sim = Simulator(scenes, device="cuda")
    setup = time.perf_counter() - start
    _, first, _ = run_intervals(sim, random_rates(task, size, 1), task.substeps)
    advanced, seconds, _ = run_intervals(sim, random_rates(task, size, n_intervals), task.substeps)
    total = float(seconds.sum())
    result = {"grippers": size, "intervals": n_intervals, "substeps": task.substeps, "setup_s": setup,
              "first_call_s": float(first[0]), "compile_s": float(first[0] - seconds.min()),
              "env_steps_per_s": size * n_intervals / total,
              "us_per_gripper_step": 1e6 * total / (size * n_intervals * task.substeps),
              "newton_iterations_per_step": float(advanced.newton_iterations.mean() / task.substeps),
              "failed": int(advanced.failed.sum())}
    # the kernel alone: the same interval on arrays that stay on the device (CUDA events time it)
    work = sim._working_state(advanced.state, copy=True)
    B, R = sim.batch_size, sim.n_rods
    times = advanced.state.time + task.physics_dt * np.arange(task.substeps + 1)
    arguments, _, _ = sim._gpu.arguments(
        (work.q, work.velocity, work.acceleration, work.tangent, work.director, work.reference_twist), times,
        sim._kernel_currents,
        advanced.natural_curvature.reshape(R).copy(), np.zeros(R), CURVATURE_RANGE, np.ones(B, dtype=bool),
        np.zeros(B, dtype=bool), np.zeros(B), np.zeros(B, dtype=np.int64), task.physics_dt, task.substeps)
    kernel = rods_kernel(sim._gpu.shape)
    blocks = (B + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    start_event, end_event = cuda.event(), cuda.event()
    best = float("inf")
    for _ in range(3):
        start_event.record()
        kernel[blocks, THREADS_PER_BLOCK](*arguments)
        end_event.record()
        end_event.synchronize()
        best = min(best, start_event.elapsed_time(end_event) / 1e3)  # [ms] to [s]
    result["kernel_s_per_interval"] = best
    result["kernel_env_steps_per_s"] = size / best
    result["kernel_us_per_gripper_step"] = 1e6 * best / (size * task.substeps)
    return result


CONTROLLERS = ("random", "reactive")
"""What drives the grasp workload: uniform random actions, or the reactive controller."""


def grasp_speed(model: str, num_envs: int, steps: int, controller: str, device: str) -> dict:
    """Env steps per second of the env's vector of ``num_envs`` on ``device`` over ``steps`` actions of
    ``controller`` after a first action, and where the time goes: the physics (``Simulator.advance``) or the task."""
    from agents.scripted import ReactivePolicy
    from soft_gripper_env.env import SoftGripperUnderwaterVectorEnv

    start = time.perf_counter()
    env = SoftGripperUnderwaterVectorEnv(num_envs, model=model, device=device)
    policy = ReactivePolicy(env.task) if controller == "reactive" else None
    env.action_space.seed(0)
    observation, _ = env.reset(seed=0)
    setup = time.perf_counter() - start
    batch = env._shards[0].batch
    physics = [0.0]
    advance = batch.sim.advance

    def timed_advance(*args, **kwargs):
        begin = time.perf_counter()
        try:
            return advance(*args, **kwargs)
        finally:
            physics[0] += time.perf_counter() - begin

    batch.sim.advance = timed_advance  # the simulator is built at the first reset and kept while the kind holds

    def act(observation):
        return env.action_space.sample() if policy is None else policy(observation)

    seconds, in_physics = [], []
    ended = 0
    phases = None
    for step in range(steps + 1):
        if step == 1 and batch.sim._gpu is not None:  # the GPU's phases, counted from after the first (compiling) step
            phases, moved = dict(batch.sim._gpu.seconds), dict(batch.sim._gpu.state.bytes)
        begin, physics_before = time.perf_counter(), physics[0]
        observation, _, terminated, truncated, _ = env.step(act(observation))
        seconds.append(time.perf_counter() - begin)
        in_physics.append(physics[0] - physics_before)
        ended += int(np.sum(terminated | truncated))
    first, timed = seconds[0], np.array(seconds[1:])
    total = float(timed.sum())
    result = {"envs": num_envs, "controller": controller, "steps": steps, "setup_s": setup, "first_step_s": first,
              "compile_s": float(first - timed.min()), "env_steps_per_s": num_envs * steps / total,
              "physics_share": float(np.sum(in_physics[1:]) / total), "episodes_ended": ended}
    if phases is not None:  # where an action's time goes: copies to the device, the kernel, copies back
        result["gpu_phase_shares"] = {name: (batch.sim._gpu.seconds[name] - phases[name]) / total for name in phases}
        # the state's bytes each way per env step: the state stays on the device, so uploads are new episodes' rows
        result["state_bytes_per_env_step"] = {
            name: (batch.sim._gpu.state.bytes[name] - moved[name]) / (num_envs * steps) for name in moved}
    env.close()
    return result


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (grasp_ax, ax) = plt.subplots(1, 2, figsize=(13, 4.8))
    for model, color in (("planar", "tab:blue"), ("3d", "tab:red")):
        grasp = results.get("models", {}).get(model, {}).get("grasp", {})
        for controller, style in (("reactive", "o-"), ("random", "s--")):
            runs = [g for g in grasp.get("gpu", []) if g["controller"] == controller]
            if runs:
                grasp_ax.plot([g["envs"] for g in runs], [g["env_steps_per_s"] for g in runs], style, color=color,
                              label=f"{model}, {controller}: GPU")
            anchor = grasp.get("cpu", {}).get(controller)
            if anchor:
                grasp_ax.axhline(anchor["env_steps_per_s"], color=color, ls=":" if controller == "reactive" else "-.",
                                 lw=1, label=f"{model}, {controller}: CPU, make_vec({anchor['envs']}), one thread")
    grasp_ax.set_xscale("log", base=2)
    grasp_ax.set_yscale("log")
    grasp_ax.set_xlabel("envs (grippers) stepped together")
    grasp_ax.set_ylabel("env steps per second")
    grasp_ax.set_title(results.get("device", "GPU") + ": grasping, the env's vector, GPU against the CPU in one run",
                       fontsize=9)
    grasp_ax.grid(True, which="both", alpha=0.3)
    grasp_ax.legend(fontsize=7)
    for model, color in (("planar", "tab:blue"), ("3d", "tab:red")):
        each = results.get("models", {}).get(model)
        if not each or not each.get("gpu"):
            continue
        sizes = [g["grippers"] for g in each["gpu"]]
        ax.plot(sizes, [g["env_steps_per_s"] for g in each["gpu"]], "o-", color=color,
                label=f"{model}: GPU, Simulator.advance (with copies)")
        ax.plot(sizes, [g["kernel_env_steps_per_s"] for g in each["gpu"]], "s--", color=color,
                label=f"{model}: GPU kernel alone")
        if "cpu" in each:
            ax.axhline(each["cpu"]["env_steps_per_s"], color=color, ls=":",
                       label=f"{model}: CPU, {each['cpu']['grippers']} grippers, one thread")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("grippers stepped together")
    ax.set_ylabel("env steps per second (fingers alone, one control interval each)")
    ax.set_title(results.get("device", "GPU") + ": the fingers alone, GPU against the CPU in one run", fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, help="write the results to this JSON file (after every stage)")
    parser.add_argument("--plot", type=Path, default=Path("out") / "gpu_speed.png", help="plot path (PNG)")
    parser.add_argument("--plot-only", type=Path, help="draw the plot from this JSON file and stop")
    parser.add_argument("--sizes", default=",".join(str(s) for s in SIZES), help="grippers per GPU batch")
    parser.add_argument("--models", default="planar,3d", help="rod models, comma-separated")
    parser.add_argument("--workloads", default="grasp,fingers", help="grasp, fingers or both, comma-separated")
    parser.add_argument("--controllers", default=",".join(CONTROLLERS), help="the grasp workload's controllers")
    parser.add_argument("--steps", type=int, default=20, help="timed env steps per size in the grasp workload")
    parser.add_argument("--intervals", type=int, default=5, help="timed control intervals per size (default 5)")
    parser.add_argument("--agreement-seconds", type=float, default=1.0, help="simulated time of the agreement run")
    args = parser.parse_args(argv)
    if args.plot_only:
        plot(json.loads(args.plot_only.read_text()), args.plot)
        return 0
    if args.intervals < 1:
        parser.error(f"--intervals = {args.intervals} must be at least 1")
    sizes = [int(s) for s in args.sizes.split(",")]
    models = args.models.split(",")
    for model in models:
        if model not in ("planar", "3d"):
            parser.error(f"--models: {model!r} is not one of planar, 3d")
    workloads = args.workloads.split(",")
    if not workloads or any(w not in ("grasp", "fingers") for w in workloads):
        parser.error(f"--workloads = {args.workloads!r}: each must be one of grasp, fingers")
    controllers = args.controllers.split(",")
    if not controllers or any(c not in CONTROLLERS for c in controllers):
        parser.error(f"--controllers = {args.controllers!r}: each must be one of {', '.join(CONTROLLERS)}")
    if args.steps < 1:
        parser.error(f"--steps = {args.steps} must be at least 1")
    from soft_gripper_env.physics.solvers.gpu import GpuUnavailable, cuda_module

    results: dict = {"models": {}}
    try:
        name = getattr(cuda_module().get_current_device(), "name", "Numba's CUDA simulator")
        results["device"] = name.decode() if isinstance(name, bytes) else str(name)
    except GpuUnavailable as error:
        print(f"no GPU: {error}")
        results["device"] = None
        results["error"] = str(error)

    def save() -> None:
        if args.json:
            args.json.parent.mkdir(parents=True, exist_ok=True)
            args.json.write_text(json.dumps(results, indent=1))

    for model in models:
        each = results["models"][model] = {}
        if "grasp" in workloads:
            grasp = each["grasp"] = {"cpu": {}, "gpu": []}
            try:
                import gymnasium  # noqa: F401
            except ImportError as error:
                grasp["error"] = f"the grasp workload needs Gymnasium (the rl extra): {error}"
                print(grasp["error"], flush=True)
            else:
                for controller in controllers:
                    print(f"{model}: grasping, {controller}, the CPU anchor, make_vec({CPU_BATCH}) ...", flush=True)
                    grasp["cpu"][controller] = grasp_speed(model, CPU_BATCH, args.steps, controller, "cpu")
                    print(f"  {grasp['cpu'][controller]}", flush=True)
                    save()
                for size in sizes if results["device"] is not None else ():
                    for controller in controllers:
                        print(f"{model}: grasping, {controller}, GPU, {size} envs ...", flush=True)
                        figures = grasp_speed(model, size, args.steps, controller, "cuda")
                        figures["vs_cpu"] = figures["env_steps_per_s"] / grasp["cpu"][controller]["env_steps_per_s"]
                        grasp["gpu"].append(figures)
                        print(f"  {figures}", flush=True)
                        save()
        if "fingers" not in workloads:
            continue
        print(f"{model}: the CPU anchor ...", flush=True)
        each["cpu"] = cpu_anchor(model, args.intervals)
        print(f"  {each['cpu']}", flush=True)
        save()
        if results["device"] is None:
            continue
        print(f"{model}: agreement over {args.agreement_seconds} s ...", flush=True)
        each["agreement"] = agreement(model, args.agreement_seconds)
        print(f"  {each['agreement']}", flush=True)
        save()
        each["gpu"] = []
        for size in sizes:
            print(f"{model}: GPU, {size} grippers ...", flush=True)
            figures = gpu_speed(model, size, args.intervals)
            figures["vs_cpu"] = figures["env_steps_per_s"] / each["cpu"]["env_steps_per_s"]
            figures["kernel_vs_cpu"] = figures["kernel_env_steps_per_s"] / each["cpu"]["env_steps_per_s"]
            each["gpu"].append(figures)
            print(f"  {figures}", flush=True)
            save()
    if results["device"] is not None:
        plot(results, args.plot)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
