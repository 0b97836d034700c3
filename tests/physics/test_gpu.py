"""The GPU back end (physics/solvers/gpu.py), tested without a GPU: its kernel run in Numba's CUDA simulator against
the CPU path (bit for bit: the simulator runs the same compiled functions), compiled to PTX for sm_90 (every shared
function must compile for the GPU), and its errors. The test that needs a GPU is marked ``gpu`` and skips without
one."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from numba import njit

from benchmarks.gpu_speed import fingers_alone
from soft_gripper_env.grasp_task import GraspBatch, GraspTask
from soft_gripper_env.physics import Simulator
from soft_gripper_env.physics.kernels.local import local_array
from soft_gripper_env.physics.solvers.gpu import GpuUnavailable, GpuUnsupported, cuda_module

ROOT = Path(__file__).resolve().parents[2]

# the fingers of the task's first two episodes without their specimens (each its own current), two intervals of
# three steps with a rate per finger, the second with the first gripper stopped; printed as JSON
_RUN = """
import json
import numpy as np
from benchmarks.gpu_speed import fingers_alone
from soft_gripper_env.physics import Simulator
from soft_gripper_env.physics.solvers.gpu import GpuRods

out = {}
loads = []
load = GpuRods.load
GpuRods.load = lambda self, state: (loads.append(state[0].shape[0]), load(self, state))[1]
for model in ("planar", "3d"):
    for device in ("cpu", "cuda"):
        del loads[:]
        sim = Simulator(fingers_alone(model, 2)[0], device=device)
        first = sim.advance(sim.initial_state(), -0.02, [[-0.3, -0.1, 0.2], [0.3, -0.3, -0.2]], 3, (-0.2, 0.2))
        second = sim.advance(first.state, first.natural_curvature, 0.25, 3, (-0.2, 0.2), running=[False, True],
                             clock=first.clock)
        state = second.state
        arrays = [state.q, state.velocity, state.acceleration, second.natural_curvature, second.clock,
                  first.newton_iterations, second.newton_iterations, second.failed]
        if model == "3d":
            arrays += [state.tangent, state.director, state.reference_twist]
        out[model + "/" + device] = [np.asarray(a, dtype=float).ravel().tolist() for a in arrays]
        out[model + "/" + device + "/time"] = state.time
        out[model + "/" + device + "/loads"] = list(loads)
print("RESULT " + json.dumps(out))
"""


# two grippers of the task's first two episodes, each grasping its own object: the task's free sphere, or the paper's
# fixed ball; closing, then opening a little. Newton's iterations are capped low so that some steps are halved (on the
# CPU, in both paths). Printed as JSON with how many grippers' steps were halved.
_GRASP_RUN = """
import json
from dataclasses import replace
import numpy as np
from soft_gripper_env.grasp_task import GraspTask, task_episode
from soft_gripper_env.physics import PAPER_BALL, Simulator

out = {}
for model in ("planar", "3d"):
    task = GraspTask(model=model)
    free = [task_episode(task, np.random.default_rng(seed), {}).scene for seed in range(2)]
    fixed = [replace(scene, grasped_object=PAPER_BALL) for scene in free]
    for name, scenes in (("free", free), ("fixed", fixed)):
        scenes = [replace(scene, newton=replace(scene.newton, max_iterations=4)) for scene in scenes]
        for device in ("cpu", "cuda"):
            sim = Simulator(scenes, device=device)
            halved = []
            sim._halve_pending = lambda *args, original=sim._halve_pending: (halved.append(len(args[-1])),
                                                                             original(*args))
            state, curvature, clock = sim.initial_state(), np.zeros((2, 3)), np.zeros(2)
            impulses = []
            for interval in range(24):
                rate = [[-0.3, -0.3, -0.3], [-0.3, -0.2, -0.3]] if interval < 20 else 0.1
                advanced = sim.advance(state, curvature, rate, task.substeps, task.curvature_range, clock=clock)
                state, curvature, clock = advanced.state, advanced.natural_curvature, advanced.clock
                impulses += [advanced.normal_impulse, advanced.impulse, advanced.newton_iterations, advanced.failed]
            arrays = [state.q, state.velocity, state.acceleration, state.held, curvature, clock] + impulses
            if model == "3d":
                arrays += [state.tangent, state.director, state.reference_twist]
            if name == "free":
                arrays += [state.hold_offset, state.body_position, state.body_velocity, state.body_orientation,
                           state.body_angular_velocity]
            key = model + "/" + name + "/" + device
            out[key] = [np.asarray(a, dtype=float).ravel().tolist() for a in arrays]
            out[key + "/time"] = state.time
            out[key + "/halved"] = sum(halved)
            out[key + "/held"] = int(state.held.sum())
print("RESULT " + json.dumps(out))
"""


def _python(script: str, simulator: bool, arguments: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(script), *arguments], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=900)


def _result(run: subprocess.CompletedProcess) -> dict:
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-5000:]
    line = next(line for line in run.stdout.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT "):])


def _numba_cuda_installed() -> bool:
    try:
        import numba_cuda  # noqa: F401
    except ImportError:
        return False
    return True


needs_numba_cuda = pytest.mark.skipif(not _numba_cuda_installed(),
                                      reason="numba-cuda is not installed (the gpu extra)")


@pytest.mark.slow
@needs_numba_cuda
def test_simulated_kernel_steps_exactly_as_the_cpu():
    """The kernel in the CUDA simulator (the CUDA kernel's own code, as Python, calling the shared functions) gives
    the CPU path's state bit for bit, planar and 3-D: positions, velocities, accelerations, κ̄ ramped within its
    range, clocks, Newton iterations, the 3-D frames, and a gripper left out of an interval left alone; the
    second interval starts from the state left on the device, uploading nothing."""
    result = _result(_python(_RUN, simulator=True))
    for model in ("planar", "3d"):
        cpu, gpu = result[model + "/cpu"], result[model + "/cuda"]
        assert len(cpu) == len(gpu)
        for index, (a, b) in enumerate(zip(cpu, gpu, strict=True)):
            assert np.array_equal(np.array(a), np.array(b)), (model, index)
        assert result[model + "/cpu/time"] == result[model + "/cuda/time"]
        clock = np.array(cpu[4])
        assert clock[0] < clock[1]  # the stopped gripper's clock did not run in the second interval
        assert result[model + "/cuda/loads"] == [6]  # the second interval started from the state on the device
        assert max(abs(x) for x in cpu[0]) > 0.0


@pytest.mark.slow
@needs_numba_cuda
def test_simulated_grasp_kernel_steps_exactly_as_the_cpu():
    """The grasp kernel in the CUDA simulator gives the CPU path's grasp bit for bit, planar and 3-D, on a free
    sphere and on a fixed ball: the fingers' state and holds, the body's state and holds' offsets, κ̄, clocks, the
    impulses of the contact reactions, Newton iterations and failures, interval by interval, with steps that each
    thread halves on its own while the CPU's batch of two halves them on the host."""
    result = _result(_python(_GRASP_RUN, simulator=True))
    for model in ("planar", "3d"):
        for name in ("free", "fixed"):
            key = model + "/" + name
            cpu, gpu = result[key + "/cpu"], result[key + "/cuda"]
            assert len(cpu) == len(gpu)
            for index, (a, b) in enumerate(zip(cpu, gpu, strict=True)):
                assert np.array_equal(np.array(a), np.array(b)), (key, index)
            assert result[key + "/cpu/time"] == result[key + "/cuda/time"]
            assert result[key + "/cpu/held"] > 0, key  # the fingers grasp
            assert result[key + "/cuda/halved"] == 0  # the GPU's threads left no step to the host
    assert sum(result[key] for key in result if key.endswith("/cpu/halved")) > 0  # some steps were halved


# three episodes of the task on each device, closing for twelve intervals, a new episode in slot 1 after nine while
# the others hold their spheres, then opening; then the state before the last interval (no longer the device's)
# stepped again. Printed as JSON with the grippers of every whole upload.
_RESIDENT_RUN = """
import json
import numpy as np
from soft_gripper_env.grasp_task import GraspBatch, GraspTask, task_episode
from soft_gripper_env.physics.solvers.gpu import GpuGrasp

out = {}
loads = []
load = GpuGrasp.load
GpuGrasp.load = lambda self, state: (loads.append(state[0].shape[0]), load(self, state))[1]
for model in ("planar", "3d"):
    task = GraspTask(model=model)
    for device in ("cpu", "cuda"):
        del loads[:]
        batch = GraspBatch(task, 3, device=device)
        batch.reset(np.arange(3), [task_episode(task, np.random.default_rng(seed), {}) for seed in range(3)], "task")
        arrays = []
        for interval in range(14):
            if interval == 9:
                batch.reset([1], [task_episode(task, np.random.default_rng(10), {})], "task")
            if interval == 13:
                saved = (batch.state, batch.natural_curvature.copy(), batch.time.copy())
            outcome = batch.step(np.full((3, 3), -1.0 if interval < 12 else 0.3), np.ones(3, dtype=bool))
            state = batch.state
            arrays += [state.q, state.velocity, state.acceleration, state.held, state.hold_offset,
                       state.body_position, state.body_velocity, state.body_orientation, batch.normal_force,
                       outcome.reward]
        key = model + "/" + device
        out[key + "/loads"] = list(loads)
        again = batch.sim.advance(saved[0], saved[1], -0.1, task.substeps, task.curvature_range, clock=saved[2])
        arrays += [again.state.q, again.state.velocity, again.normal_impulse]
        out[key + "/again_loads"] = list(loads)
        out[key] = [np.asarray(a, dtype=float).ravel().tolist() for a in arrays]
        try:
            batch.state.q[0, 0, 0, 0] = 1.0
            out[key + "/writable"] = True
        except ValueError:
            out[key + "/writable"] = False
print("RESULT " + json.dumps(out))
"""


@pytest.mark.slow
@needs_numba_cuda
def test_the_state_stays_on_the_simulated_device_between_intervals():
    """The task's batch on the device in the CUDA simulator (whose device arrays are copies of the host's, as on a
    GPU) steps as on the CPU, bit for bit, through fourteen intervals of grasping and a new episode in one slot,
    with one whole upload of the state: the new episode's grippers go into the device's state row by row. A state
    the device no longer holds is uploaded again and steps as on the CPU; the state handed back is read-only, so
    that it cannot drift from the device's copy on the host alone."""
    result = _result(_python(_RESIDENT_RUN, simulator=True))
    for model in ("planar", "3d"):
        cpu, gpu = result[model + "/cpu"], result[model + "/cuda"]
        assert len(cpu) == len(gpu) == 143
        for index, (a, b) in enumerate(zip(cpu, gpu, strict=True)):
            assert np.array_equal(np.array(a), np.array(b)), (model, index)
        assert np.sum(cpu[10 * 12 + 3]) > 0 and np.abs(cpu[10 * 12 + 4]).max() > 0  # nodes held, with offsets
        assert result[model + "/cuda/loads"] == [9]  # one upload of the 3 grippers' 9 rods
        assert result[model + "/cuda/again_loads"] == [9, 9]
        assert result[model + "/cuda/writable"] is False and result[model + "/cpu/writable"] is True


# kernels compiled to PTX for sm_90 without a GPU, named model/kind on the command line (kind: rods alone, or grasping
# a free or a fixed object); printed as JSON with each one's seconds
_PTX = """
import json, sys, time
from dataclasses import replace
import numpy as np
from benchmarks.gpu_speed import fingers_alone
from soft_gripper_env.grasp_task import GraspTask, task_episode
from soft_gripper_env.physics import PAPER_BALL, Simulator
from soft_gripper_env.physics.solvers.gpu import grasp_ptx, rods_ptx
from soft_gripper_env.physics.solvers.stepping import Interval

out = {}
for name in sys.argv[1:]:
    model, kind = name.split("/")
    start = time.perf_counter()
    if kind == "rods":
        sim = Simulator(fingers_alone(model, 1)[0])
        work = sim._working_state(sim.initial_state(), copy=True)
        ptx = rods_ptx(sim.gpu_constants(), (work.q, work.velocity, work.acceleration, work.tangent, work.director,
                                             work.reference_twist), 1, optimised=False)
    else:
        scene = task_episode(GraspTask(model=model), np.random.default_rng(0), {}).scene
        sim = Simulator(scene if kind == "free" else replace(scene, grasped_object=PAPER_BALL))
        work = sim._working_state(sim.initial_state(), copy=True)
        R, N = sim.n_rods, sim.disc.n_nodes
        interval = Interval(np.zeros(R), np.zeros(R), -0.2, 0.0, np.ones(1, bool), np.zeros(1, bool), np.zeros(1),
                            np.zeros(1, np.int64), np.zeros((R, N)), np.zeros((R, N, 3)), np.zeros(1, bool), True)
        body = None if sim._body is None else sim._body.plain_arrays
        ptx = grasp_ptx(sim.gpu_constants(), tuple(work), sim._plain_geometry, body, tuple(interval),
                        optimised=False)
    out[name] = {"target": ".target sm_90" in ptx, "entry": ptx.count(".entry"),
                 "seconds": time.perf_counter() - start}
print("RESULT " + json.dumps(out))
"""


@pytest.mark.slow
@needs_numba_cuda
def test_kernels_compile_to_ptx_for_sm_90():
    """The kernels, with every physics function they call, compile for an H100/H200 (sm_90) without a GPU from the
    shared ``@njit`` source: the check that nothing on the GPU's path allocates or needs what the GPU lacks. Three
    kernels between them reach every shared function: grasping a free body in 3-D (the env's default: the 3-D
    energies and frames, the coupled solve, the palm), and in the planar model grasping a fixed object (its holds,
    the rubbing fingers' line search) and the rods alone (``step_gripper_rods``). NVVM translates without
    optimising (whether a function compiles does not depend on it; a launch on a GPU optimises, and the ``gpu``
    tests launch): about a minute in one process."""
    names = ("3d/free", "planar/fixed", "planar/rods")
    result = _result(_python(_PTX, simulator=False, arguments=names))
    for name in names:
        assert result[name]["target"], name
        assert result[name]["entry"] == 1, name


@pytest.mark.slow
@needs_numba_cuda
def test_gpu_speed_benchmark_runs_in_the_simulator(tmp_path):
    """The benchmark a lent GPU runs, end to end on two envs in Numba's CUDA simulator (no speed is meant): both
    workloads and controllers write their figures (the grasp's split of the physics into copies and kernel too), the
    grasp runs end as the CPU's and the plot is drawn."""
    out = tmp_path / "gpu_speed.json"
    run = _python(f"""
    from benchmarks.gpu_speed import main
    main(["--models", "planar", "--sizes", "2", "--steps", "1", "--intervals", "1", "--agreement-seconds", "0.05",
          "--json", "{out}", "--plot", "{tmp_path / 'gpu_speed.png'}"])
    print("RESULT {{}}")
    """, simulator=True)
    _result(run)
    planar = json.loads(out.read_text())["models"]["planar"]
    grasp = planar["grasp"]
    assert set(grasp["cpu"]) == {"random", "reactive"}
    assert [(g["envs"], g["controller"]) for g in grasp["gpu"]] == [(2, "random"), (2, "reactive")]
    assert all(g["env_steps_per_s"] > 0 and 0 < g["physics_share"] <= 1 for g in grasp["gpu"])
    for g in grasp["gpu"]:  # the physics' time split into copies and the kernel, within the physics' share
        phases = g["gpu_phase_shares"]
        assert set(phases) == {"upload", "kernel", "download"} and phases["kernel"] > 0
        assert sum(phases.values()) <= g["physics_share"] + 1e-9
        moved = g["state_bytes_per_env_step"]  # the state back every step; none up unless an episode began
        assert moved["download"] > 0 and moved["upload"] >= 0
    assert planar["agreement"]["max_position_difference_m"] == 0.0  # the simulator runs the CPU's code
    assert (tmp_path / "gpu_speed.png").stat().st_size > 0


@pytest.mark.slow
@needs_numba_cuda
def test_gpu_outcome_study_runs_in_the_simulator(tmp_path):
    """The outcome study a lent GPU runs, on three planar seeds: the CPU part's pieces (kept for the GPU machine),
    then the GPU part in Numba's CUDA simulator, which runs the CPU's code, so the GPU's episodes end exactly as
    the CPU's: every label agrees and the sphere ends in the same place. The GPU part refuses to start without the
    CPU's pieces."""
    options = ["--models", "planar", "--episodes", "3", "--runs", str(tmp_path / "runs"), "--json",
               str(tmp_path / "gpu_outcomes.json"), "--plot", str(tmp_path / "gpu_outcomes.png")]
    missing = _python(f"from benchmarks.gpu_outcomes import main\nmain({['--part', 'cuda'] + options!r})",
                      simulator=True)
    assert missing.returncode != 0 and "run --part cpu first" in missing.stderr
    run = _python(f"""
    from benchmarks.gpu_outcomes import main
    main({['--part', 'cpu', '--workers', '1'] + options!r})
    main({['--part', 'cuda'] + options!r})
    print("RESULT {{}}")
    """, simulator=True)
    _result(run)
    planar = json.loads((tmp_path / "gpu_outcomes.json").read_text())["models"]["planar"]
    assert planar["gpu"]["episodes"] == planar["cpu"]["episodes"] == 3
    against = planar["gpu_against_cpu"]
    assert against["label_agreement"] == 1.0 and against["p90_position_gap_m"] == 0.0 and against["passes"]
    assert 0.0 <= planar["floor"]["label_agreement"] <= 1.0
    assert (tmp_path / "gpu_outcomes.png").stat().st_size > 10_000


def test_the_ptx_check_refuses_an_optimised_flag_that_is_not_a_bool():
    from soft_gripper_env.physics.solvers.gpu import _ptx

    with pytest.raises(TypeError, match="optimised must be a bool, got 0"):
        _ptx(None, (), (9, 0), optimised=0)


def test_device_is_checked():
    scene = fingers_alone("planar", 1)[0][0]
    with pytest.raises(ValueError, match="device = 'tpu'"):
        Simulator(scene, device="tpu")


def test_an_integrator_other_than_backward_euler_is_refused_on_the_gpu():
    scene = replace(fingers_alone("planar", 1)[0][0], integrator="implicit_midpoint")
    with pytest.raises(GpuUnsupported, match="'implicit_midpoint'"):
        Simulator(scene, device="cuda")


def test_local_array_on_the_cpu_is_an_array_on_the_stack_of_each_call_site():
    """The kernels' small work arrays: on the CPU a float64 array of the constant shape asked for, one per call
    site, which a function compiled without Numba's runtime can make and which allocates nothing from the heap."""
    from numba.core.runtime import _nrt_python, rtsys

    def fill(first, second):
        vector, matrix = local_array(3), local_array((2, 6))
        vector[:] = first
        matrix[:, :] = second
        part = local_array(3)[:2]
        part[:] = 5.0
        return vector.sum(), matrix.sum(), matrix.shape[0] * 100 + matrix.shape[1], part.sum(), vector.sum()

    expected = (3.0, 24.0, 206, 10.0, 3.0)  # the other sites' writes did not reach the first array
    assert njit(_nrt=False)(fill)(1.0, 2.0) == expected
    with_runtime = njit(fill)
    assert with_runtime(1.0, 2.0) == expected
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats().alloc
        assert with_runtime(-1.0, 0.5) == (-3.0, 6.0, 206, 10.0, -3.0)
        assert rtsys.get_allocation_stats().alloc == before
    finally:
        _nrt_python.memsys_disable_stats()


def test_the_vector_env_checks_its_device():
    from soft_gripper_env.env import SoftGripperUnderwaterVectorEnv

    with pytest.raises(ValueError, match="device = 'gpu'"):
        SoftGripperUnderwaterVectorEnv(2, device="gpu")
    with pytest.raises(ValueError, match="num_threads = 2 with device = 'cuda'"):
        SoftGripperUnderwaterVectorEnv(2, num_threads=2, device="cuda")


def test_without_a_gpu_the_error_says_what_to_install():
    try:
        cuda_module()
    except GpuUnavailable:
        pass
    else:
        pytest.skip("a GPU (or the simulator) is available here")
    with pytest.raises(GpuUnavailable, match=r'pip install -e "\.\[gpu\]"'):
        Simulator(fingers_alone("planar", 1)[0][0], device="cuda")
    with pytest.raises(GpuUnavailable, match=r'pip install -e "\.\[gpu\]"'):  # at construction, not at reset
        GraspBatch(GraspTask(model="planar"), 2, device="cuda")


def _gpu_available() -> bool:
    try:
        cuda_module()
    except GpuUnavailable:
        return False
    return os.environ.get("NUMBA_ENABLE_CUDASIM") != "1"


@pytest.mark.gpu
@pytest.mark.skipif(not _gpu_available(), reason="needs a CUDA GPU")
@pytest.mark.parametrize("model", ["planar", "3d"])
def test_gpu_trajectory_equals_the_cpu_one_over_one_second(model):
    """On a real GPU (which fuses multiplies and adds where the CPU rounds twice), rods alone stay within 1e-9 m of
    the CPU path over 1 s of random rates."""
    scenes, task = fingers_alone(model, 8)
    rng = np.random.default_rng(0)
    rates = task.max_curvature_rate * rng.uniform(-1.0, 1.0, (int(round(1.0 / task.control_dt)), 8, 3))
    positions = {}
    for device in ("cpu", "cuda"):
        sim = Simulator(scenes, device=device)
        state, curvature, path = sim.initial_state(), np.zeros((8, 3)), []
        for rate in rates:
            advanced = sim.advance(state, curvature, rate, task.substeps, (-0.2, 0.2))
            state, curvature = advanced.state, advanced.natural_curvature
            assert not advanced.failed.any()
            path.append(sim.world_positions(state))
        positions[device] = np.stack(path)
    assert np.abs(positions["cpu"] - positions["cuda"]).max() <= 1e-9


# arrays of a batch's state's kinds (per rod, per gripper, bool, an empty one) loaded on the device, rows written, a
# second load, fetched after each; printed as JSON with whether each fetch equals NumPy's own row assignment
_DEVICE_ARRAYS_RUN = """
import json
import numpy as np
from soft_gripper_env.physics.solvers.gpu import DeviceArrays, cuda_module

rng = np.random.default_rng(0)
host = (rng.normal(size=(12, 5, 4)), rng.normal(size=(4, 3, 3)), rng.random((12, 5)) < 0.5, np.zeros((0, 0, 3)))
device = DeviceArrays(cuda_module(), host)
checks = {"loaded": all(np.array_equal(a, b) for a, b in zip(device.fetch(), host, strict=True))}
rows = (np.array([3, 4, 5, 9, 10, 11]), np.array([1, 3]), np.array([3, 4, 5, 9, 10, 11]), np.array([], dtype=int))
values = (rng.normal(size=(6, 5, 4)), rng.normal(size=(2, 3, 3)), rng.random((6, 5)) < 0.5, np.zeros((0, 0, 3)))
device.put(rows, values)
expected = tuple(a.copy() for a in host)
for array, index, value in zip(expected, rows, values, strict=True):
    array[index] = value
fetched = device.fetch()
checks["put"] = all(np.array_equal(a, b) and a.dtype == b.dtype for a, b in zip(fetched, expected, strict=True))
checks["host_untouched"] = not np.array_equal(host[0], expected[0])
again = tuple(a + 1 if a.dtype != bool else ~a for a in host)
device.load(again)
checks["reloaded"] = all(np.array_equal(a, b) for a, b in zip(device.fetch(), again, strict=True))
checks["bytes"] = device.bytes
print("RESULT " + json.dumps(checks))
"""


def _check_device_arrays(simulator: bool) -> None:
    checks = _result(_python(_DEVICE_ARRAYS_RUN, simulator=simulator))
    assert checks["loaded"] and checks["put"] and checks["host_untouched"] and checks["reloaded"], checks
    state_bytes = 12 * 5 * 4 * 8 + 4 * 3 * 3 * 8 + 12 * 5
    assert checks["bytes"]["upload"] == 2 * state_bytes + 6 * 5 * 4 * 8 + 2 * 3 * 3 * 8 + 6 * 5 + 8 * (6 + 2 + 6)
    assert checks["bytes"]["download"] == 3 * state_bytes


@needs_numba_cuda
def test_device_arrays_load_write_rows_and_fetch_in_the_simulator():
    """The state's store on the device (its arrays copies of the host's in the simulator, as on a GPU): loaded,
    some rows written by the scatter kernel (float and bool arrays, per-rod and per-gripper rows, an empty array
    skipped), loaded again, each fetch equal to NumPy's own assignment; the bytes each way counted."""
    _check_device_arrays(simulator=True)


@pytest.mark.gpu
@pytest.mark.skipif(not _gpu_available(), reason="needs a CUDA GPU")
def test_device_arrays_load_write_rows_and_fetch_on_a_gpu():
    """The same on a real GPU, where the copies and the scatter kernel are the device's own."""
    _check_device_arrays(simulator=False)
