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
from pathlib import Path

import numpy as np
import pytest

from benchmarks.gpu_speed import fingers_alone
from soft_gripper_env.grasp_task import GraspTask, task_episode
from soft_gripper_env.physics import Simulator
from soft_gripper_env.physics.solvers.gpu import GpuUnavailable, GpuUnsupported, cuda_module

ROOT = Path(__file__).resolve().parents[2]

# the fingers of the task's first two episodes without their specimens (each its own current), two intervals of
# three steps with a rate per finger, the second with the first gripper stopped; printed as JSON
_RUN = """
import json
import numpy as np
from benchmarks.gpu_speed import fingers_alone
from soft_gripper_env.physics import Simulator

out = {}
for model in ("planar", "3d"):
    for device in ("cpu", "cuda"):
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
print("RESULT " + json.dumps(out))
"""


def _python(script: str, simulator: bool) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    if simulator:
        env["NUMBA_ENABLE_CUDASIM"] = "1"
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.run([sys.executable, "-c", textwrap.dedent(script)], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=900)


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
    range, clocks, Newton iterations, the 3-D frames, and a gripper left out of an interval left alone."""
    result = _result(_python(_RUN, simulator=True))
    for model in ("planar", "3d"):
        cpu, gpu = result[model + "/cpu"], result[model + "/cuda"]
        assert len(cpu) == len(gpu)
        for index, (a, b) in enumerate(zip(cpu, gpu, strict=True)):
            assert np.array_equal(np.array(a), np.array(b)), (model, index)
        assert result[model + "/cpu/time"] == result[model + "/cuda/time"]
        clock = np.array(cpu[4])
        assert clock[0] < clock[1]  # the stopped gripper's clock did not run in the second interval
        assert max(abs(x) for x in cpu[0]) > 0.0


@pytest.mark.slow
@needs_numba_cuda
def test_kernels_compile_to_ptx_for_sm_90():
    """Both models' kernels, with every physics function they call, compile for an H100/H200 (sm_90) without a GPU
    from the shared ``@njit`` source: the check that nothing on the GPU's path allocates or needs what the GPU
    lacks."""
    script = """
    import json, time
    from benchmarks.gpu_speed import fingers_alone
    from soft_gripper_env.physics import Simulator
    from soft_gripper_env.physics.solvers.gpu import rods_ptx

    out = {}
    for model in ("planar", "3d"):
        sim = Simulator(fingers_alone(model, 1)[0])
        work = sim._working_state(sim.initial_state(), copy=True)
        start = time.perf_counter()
        ptx = rods_ptx(sim.gpu_constants(), (work.q, work.velocity, work.acceleration, work.tangent,
                                             work.director, work.reference_twist), 1)
        out[model] = {"target": ".target sm_90" in ptx, "entry": ptx.count(".entry"),
                      "seconds": time.perf_counter() - start}
    print("RESULT " + json.dumps(out))
    """
    result = _result(_python(script, simulator=False))
    for model in ("planar", "3d"):
        assert result[model]["target"], model
        assert result[model]["entry"] == 1, model


def test_device_is_checked():
    scene = fingers_alone("planar", 1)[0][0]
    with pytest.raises(ValueError, match="device = 'tpu'"):
        Simulator(scene, device="tpu")


def test_a_scene_with_an_object_is_refused_on_the_gpu_for_now():
    task = GraspTask(model="planar")
    scene = task_episode(task, np.random.default_rng(0), {}).scene
    with pytest.raises(GpuUnsupported, match="grasped object"):
        Simulator(scene, device="cuda")


def test_without_a_gpu_the_error_says_what_to_install():
    try:
        cuda_module()
    except GpuUnavailable:
        pass
    else:
        pytest.skip("a GPU (or the simulator) is available here")
    with pytest.raises(GpuUnavailable, match=r'pip install -e "\.\[gpu\]"'):
        Simulator(fingers_alone("planar", 1)[0][0], device="cuda")


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
