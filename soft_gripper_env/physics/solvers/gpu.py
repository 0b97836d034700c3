"""The GPU back end: the steps of a control interval on an NVIDIA GPU, one CUDA thread per gripper, compiled by
Numba from the same functions as the CPU kernels.

There is one copy of the physics. The CUDA kernel here is only the loop a CPU entry point runs around the shared
functions: it copies its gripper's state into the thread's own arrays, takes the interval's steps by calling the
very ``@njit`` functions the CPU calls (:func:`~.newton.step_gripper_rods`, and through it the rods' energies, the
water, the contact between the fingers, the banded factorisation and Newton's loop), and writes the state back.
Numba's CUDA target compiles a CPU-compiled function it meets in a kernel from that function's Python source, as a
device function, and so does every function it calls. For that, the shared functions allocate nothing (their work
arrays come in as arguments: made once per call on the CPU, the thread's ``cuda.local.array`` on the GPU) and use
only what both targets have (``math`` rather than NumPy's ufuncs on scalars).

**Layout.** A thread per gripper, its rods' state, bands and work arrays in the thread's local memory, which the GPU
interleaves across the threads of a warp, so that the same element of neighbouring threads' arrays is read in one
transaction. The arrays' sizes are the kernel's compile-time constants (fingers, nodes, coordinates per node), so a
kernel is compiled per gripper design.

**What runs here today.** Rods on their own (no grasped object): planar and 3-D, with gravity, buoyancy, the
water's drag and added mass, the current (evaluated on the host for every step of the interval and copied once) and
contact between the fingers, with the backward-Euler integrator. A step that Newton does not settle is not halved
on the GPU yet: the gripper stops there and is reported failed, keeping its last good state. Scenes with a grasped
object (the corrector, the free body) are the next part of this back end; asking for one on the GPU raises
:class:`GpuUnsupported`.

**Installation.** ``pip install -e ".[gpu]"`` brings numba-cuda and the CUDA libraries it needs; without it the
package works as before and ``device="cuda"`` raises :class:`GpuUnavailable` saying what to install. Tests run the
kernels without a GPU in Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) and compile them to PTX for sm_90.
"""

from __future__ import annotations

import importlib
import math
import os
from typing import NamedTuple

import numpy as np
from numba import njit
from numba.core import types

from ..kernels.assembly import N_DESIGN_FIELDS, StepInputs, named_rods
from ..kernels.finger_contact import finger_scratch_size
from ..kernels.forces import project_water
from ..kernels.local import local_array
from ..kernels.rod_3d import elastic_scratch_size, elastic_views, rod_frames
from ..scene.forces import ForceTerms
from .newton import NewtonWork, SolverArrays, SolveResult, step_gripper_rods

THREADS_PER_BLOCK = 64
"""CUDA threads (grippers) per block: each thread holds tens of kilobytes of local arrays, so small blocks keep
more of them resident per multiprocessor's register file and cache."""

INSTALL_HINT = ('the GPU back end needs numba-cuda and the CUDA libraries: pip install -e ".[gpu]" (or '
                '"soft-gripper-env[gpu]"), and an NVIDIA GPU with its driver')


class GpuUnavailable(RuntimeError):
    """``device="cuda"`` was asked for where the GPU back end cannot run: numba-cuda is not installed, or no CUDA
    GPU and driver are found. The message says which, and what to install."""


class GpuUnsupported(NotImplementedError):
    """A scene or setting the GPU back end does not run yet (the message says which)."""


def check_device(device: str) -> str:
    """``device`` ("cpu" or "cuda") checked: a ValueError naming the argument otherwise."""
    if device not in ("cpu", "cuda"):
        raise ValueError(f"device = {device!r} is not one of 'cpu', 'cuda'")
    return device


cuda = None
"""``numba.cuda`` once :func:`import_cuda` has imported it. The kernels name it as this module's global, which Numba's
CUDA simulator replaces with its own while a kernel runs (it cannot replace a name a closure holds)."""


def import_cuda():
    """``numba.cuda``, imported on first use, whether or not a GPU is there. NumPy 2.5 removed ``np.row_stack``,
    which numba-cuda 0.30's CUDA target still names when it compiles; the alias ``np.row_stack = np.vstack`` (the
    same function under its old name) is put back first where it is missing. Raises :class:`GpuUnavailable` if
    numba-cuda is not installed."""
    global cuda
    if not hasattr(np, "row_stack"):
        np.row_stack = np.vstack
    try:
        cuda = importlib.import_module("numba.cuda")
    except ImportError as error:
        raise GpuUnavailable(f"numba.cuda cannot be imported ({error}): {INSTALL_HINT}") from error
    if not simulated(cuda):
        _register_local_array()
    return cuda


_registered = False


def _register_local_array() -> None:
    """Teaches numba-cuda :func:`~..kernels.local.local_array` once: on the GPU its call is the thread's own array
    of that constant shape, as ``cuda.local.array`` makes it (the CPU's ``np.empty`` needs a heap)."""
    global _registered
    if _registered:
        return
    from numba.cuda import cudadecl, cudaimpl
    from numba.cuda.cudadrv import nvvm
    from numba.cuda.typing.templates import AbstractTemplate, signature

    def constant_shape(shape):
        if isinstance(shape, types.IntegerLiteral):
            return (shape.literal_value,)
        if isinstance(shape, types.BaseTuple) and all(isinstance(s, types.IntegerLiteral) for s in shape):
            return tuple(s.literal_value for s in shape)
        return None

    @cudadecl.register
    class LocalArray(AbstractTemplate):
        key = local_array

        def generic(self, args, kws):
            if len(args) == 1 and not kws and (shape := constant_shape(args[0])) is not None:
                return signature(types.Array(types.float64, len(shape), "C"), args[0])
            return None

    cudadecl.register_global(local_array, types.Function(LocalArray))

    @cudaimpl.lower(local_array, types.IntegerLiteral)
    @cudaimpl.lower(local_array, types.BaseTuple)
    def lower_local_array(context, builder, sig, args):
        return cudaimpl._generic_array(context, builder, shape=constant_shape(sig.args[0]), dtype=types.float64,
                                       symbol_name="_cudapy_lmem", addrspace=nvvm.ADDRSPACE_LOCAL,
                                       can_dynsized=False)

    _registered = True


def cuda_module():
    """:func:`import_cuda`, where kernels can run: raises :class:`GpuUnavailable` where there is neither a GPU with
    its driver nor the simulator (``NUMBA_ENABLE_CUDASIM=1``)."""
    import_cuda()
    if not simulated(cuda):
        try:
            available = cuda.is_available()
        except Exception as error:  # the driver's own errors vary from one numba-cuda version to the next
            raise GpuUnavailable(f"no CUDA driver ({error}): {INSTALL_HINT}") from error
        if not available:
            raise GpuUnavailable(f"no CUDA GPU is available: {INSTALL_HINT}")
    return cuda


def simulated(cuda) -> bool:
    """Whether ``cuda`` is Numba's CUDA simulator, which runs kernels as Python on the CPU (for tests)."""
    return bool(getattr(cuda, "simulator_mode", False) or os.environ.get("NUMBA_ENABLE_CUDASIM") == "1")


class RodsKernelShape(NamedTuple):
    """What a kernel's arrays are sized by: its compile-time constants."""

    n_fingers: int
    n_nodes: int
    stride: int
    """Coordinates per node S: 2 planar, 4 in 3-D (position and twist)."""
    dim: int
    """Position coordinates per node D: 2 planar, 3 in 3-D."""
    finger_contact: bool
    """Whether the fingers touch each other (the search and the penalty are compiled in)."""


_KERNELS: dict[RodsKernelShape, object] = {}


def rods_kernel(shape: RodsKernelShape):
    """The CUDA kernel that steps rods on their own through a control interval, for grippers of ``shape``
    (compiled on its first launch, then kept). Its arguments are tuples of device arrays (a tuple reaches the
    simulator's threads as the host's arrays, where the shared ``@njit`` functions can take them):

    ``state`` = (q, velocity, acceleration (R, N, S), tangent, director (R, N − 1, 3), reference twist (R, N));
    ``rods`` = the design's fields of :class:`~..kernels.assembly.RodArrays` and the finger contact's, as plain
    tuples; ``terms`` the :class:`~..scene.forces.ForceTerms`' fields; ``solver`` the
    :class:`~.newton.SolverArrays`' fields (their per-rod arrays for one gripper's F rods);
    ``interval`` = (gripper water (K + 1, B, 3) [m/s], finger directions (F, 3), κ̄ (R,), rate (R,) [1/s], (low,
    high), running (B,) bool, failed (B,) bool, clock (B,) [s], Newton iterations (B,) int, (dt [s], steps K))."""
    kernel = _KERNELS.get(shape)
    if kernel is None:
        cuda_module()
        kernel = _KERNELS[shape] = _build_rods_kernel(shape)
    return kernel


@njit(cache=True, nogil=True, error_model="numpy")
def copy_rod(source, source_rod, target, target_rod, frames):
    """Copies rod ``source_rod`` of the state ``source`` into rod ``target_rod`` of ``target``, element by element
    (the GPU build copies no array into another by slice). A state is a tuple (q, velocity, acceleration (R, N, S),
    tangent, director (R, N − 1, 3), reference twist (R, N)); its frames are copied with ``frames``."""
    q, velocity, acceleration, tangent, director, twist = source
    q_to, velocity_to, acceleration_to, tangent_to, director_to, twist_to = target
    for i in range(q.shape[1]):
        for s in range(q.shape[2]):
            q_to[target_rod, i, s] = q[source_rod, i, s]
            velocity_to[target_rod, i, s] = velocity[source_rod, i, s]
            acceleration_to[target_rod, i, s] = acceleration[source_rod, i, s]
    if frames:
        for e in range(tangent.shape[1]):
            for k in range(3):
                tangent_to[target_rod, e, k] = tangent[source_rod, e, k]
                director_to[target_rod, e, k] = director[source_rod, e, k]
        for i in range(twist.shape[1]):
            twist_to[target_rod, i] = twist[source_rod, i]


def _build_rods_kernel(shape: RodsKernelShape):
    F, N, S, D = shape.n_fingers, shape.n_nodes, shape.stride, shape.dim
    n = N * S
    band = 3 * S  # kd + 1: the planar band's half width is 5, the 3-D one's 10 (scene.discretization)
    three_d = S == 4
    edges = N - 1
    contact_fingers = F if shape.finger_contact else 0
    framed = F if three_d else 1
    elastic_size = elastic_scratch_size(N if three_d else 0)
    finger_size = finger_scratch_size(contact_fingers, N)
    float64, int64, boolean = types.float64, types.int64, types.boolean

    @cuda.jit
    def advance_rods_interval(state, rods_design, terms_fields, solver_fields, interval):
        b = cuda.grid(1)
        gripper_water, directions, curvature, rate, curvature_range, running, failed, clock, iterations_sum, \
            timing = interval
        if b >= running.shape[0] or not running[b]:
            return
        dt, n_steps = timing
        first = b * F
        # the gripper's state in the thread's own arrays: old and new of each, swapped by copying at a step's end
        q_old = cuda.local.array((F, N, S), float64)
        velocity_old = cuda.local.array((F, N, S), float64)
        acceleration_old = cuda.local.array((F, N, S), float64)
        q = cuda.local.array((F, N, S), float64)
        q_pred = cuda.local.array((F, N, S), float64)
        velocity = cuda.local.array((F, N, S), float64)
        acceleration = cuda.local.array((F, N, S), float64)
        # the planar model has no frames, and a gripper without finger contact no near-finger table: empty
        # arrays, as on the CPU (a local array has at least one element; its slice has none)
        frames_old = (cuda.local.array((framed, edges, 3), float64)[:framed if three_d else 0],
                      cuda.local.array((framed, edges, 3), float64)[:framed if three_d else 0],
                      cuda.local.array((framed, N), float64)[:framed if three_d else 0])
        frames = (cuda.local.array((framed, edges, 3), float64), cuda.local.array((framed, edges, 3), float64),
                  cuda.local.array((framed, N), float64))
        kappa = cuda.local.array(F, float64)
        water = cuda.local.array((F, D), float64)
        near = cuda.local.array((F, N, F), int64)[:contact_fingers]
        start = (q_old, velocity_old, acceleration_old) + frames_old  # a step's start; its end:
        end = (q, velocity, acceleration) + frames
        for f in range(F):
            kappa[f] = curvature[first + f]
            copy_rod(state, first + f, start, f, three_d)
        # Newton's results and work arrays (newton.new_work's, sized for one gripper)
        flags = cuda.local.array((5, F), boolean)  # converged, changed, every rod, active, rubbing
        counts = cuda.local.array((2, F), int64)
        ratios = cuda.local.array((3, F), float64)
        for f in range(F):  # as newton.new_work's zeros: a rod rubs another only where the search says so
            for row in range(5):
                flags[row, f] = False
            counts[0, f] = 0
            counts[1, f] = 0
        result = SolveResult(flags[0], counts[0], ratios[0], cuda.local.array((F, n), float64), counts[1],
                             flags[1])
        every_rod = flags[2]
        for f in range(F):
            every_rod[f] = True
        motion = cuda.local.array((2, N, D), float64)
        # a buffer a model or a gripper does not use is an empty slice (a local array has at least one element)
        elastic = cuda.local.array(elastic_size or 1, float64)[:elastic_size]
        vector = cuda.local.array(1, float64)[:0]
        matrix = cuda.local.array((1, 1), float64)[:0]
        tensor = cuda.local.array((1, 1, 6), float64)[:0]
        work = NewtonWork(cuda.local.array((N, S), float64), motion[0], motion[1], elastic,
                          cuda.local.array(finger_size or 1, float64)[:finger_size],
                          cuda.local.array((F, n, band), float64), tensor, cuda.local.array((F, n), float64),
                          tensor, tensor, matrix,
                          cuda.local.array((F, n), float64)[:contact_fingers], ratios[1], flags[3],
                          cuda.local.array(F, boolean), cuda.local.array(F, boolean), vector, matrix, vector, vector,
                          matrix, matrix, cuda.local.array(band, float64),
                          cuda.local.array((1, 1, D), float64)[:0], cuda.local.array((D, D), float64)[:0], flags[4],
                          ratios[2])
        rods = named_rods(rods_design + frames_old)
        terms = ForceTerms(*terms_fields)
        solver = SolverArrays(*solver_fields)
        low, high = curvature_range
        for k in range(n_steps):
            project_water(directions, gripper_water[k, b:b + 1], water)
            step = StepInputs(q_old, q_pred, kappa, water, dt, near)
            step_gripper_rods(0, velocity_old, acceleration_old, step, rods, terms, solver, False, q, velocity,
                              acceleration, every_rod, result, work)
            ok = True
            most = 0
            for f in range(F):
                ok = ok and result.converged[f]
                most = max(most, result.iterations[f])
                if three_d:
                    _, _, m1, m2, _, lengths, _, _, _ = elastic_views(elastic, N)
                    rod_frames(q[f], frames_old[0][f], frames_old[1][f], frames_old[2][f], frames[0][f],
                               frames[1][f], frames[2][f], m1, m2, lengths)
                for i in range(N):
                    for s in range(S):
                        ok = ok and math.isfinite(q[f, i, s]) and math.isfinite(velocity[f, i, s])
            if not ok:  # the step is not halved here yet: the gripper stops at its last good state
                running[b] = False
                failed[b] = True
                break
            for f in range(F):  # the step taken: its end is the next one's start (stepping.commit_step's order)
                copy_rod(end, f, start, f, three_d)
                kappa[f] = min(max(kappa[f] + rate[first + f] * dt, low), high)
            iterations_sum[b] += most
            clock[b] += dt
        for f in range(F):
            curvature[first + f] = kappa[f]
            copy_rod(start, f, state, first + f, three_d)

    return advance_rods_interval


class GpuRods:
    """Rods on their own, stepped on the GPU: the batch's constants on the device, and :meth:`advance`.

    ``rods``, ``terms`` and ``solver`` are the plain fields the CPU's entry points take
    (:func:`~.newton.advance_rods`), ``finger_directions`` (F, 3). With ``host`` the arrays stay the host's and no
    GPU is needed (for :func:`rods_ptx`, which only compiles)."""

    def __init__(self, rods: tuple, terms: tuple, solver: tuple, finger_directions: np.ndarray,
                 shape: RodsKernelShape, host: bool = False) -> None:
        self.cuda = None if host else cuda_module()
        self.shape = shape
        to_device = self._to_device
        design = rods[:N_DESIGN_FIELDS]
        fingers = design[5]
        self.rods = tuple(to_device(x) for x in design[:5]) + (
            (float(fingers[0]), float(fingers[1])) + tuple(to_device(x) for x in fingers[2:]),)
        self.terms = tuple(to_device(x) for x in terms)
        solver_arrays = SolverArrays(*solver)
        one_gripper = solver_arrays._replace(tolerance_inverse=solver_arrays.tolerance_inverse[:shape.n_fingers],
                                             clamp_free=solver_arrays.clamp_free[:shape.n_fingers])
        self.solver = tuple(to_device(x) if isinstance(x, np.ndarray) else x for x in one_gripper)
        self.directions = to_device(np.ascontiguousarray(finger_directions, dtype=float))

    def _to_device(self, array: np.ndarray, placeholder: bool = False):
        """``array`` on the device (the simulator's threads, and a host-only instance, take the host's own). With
        ``placeholder``, an empty array goes as one element of its dimensions: for state the kernel does not read
        (the planar model's frames), where a size test decides nothing."""
        array = np.ascontiguousarray(array)
        if self.cuda is None or simulated(self.cuda):
            return array
        if placeholder and not array.size:
            array = np.zeros((1,) * array.ndim, dtype=array.dtype)
        return self.cuda.to_device(array)

    def arguments(self, state: tuple, gripper_water: np.ndarray, natural_curvature: np.ndarray, rate: np.ndarray,
                  curvature_range: tuple[float, float], running: np.ndarray, failed: np.ndarray, clock: np.ndarray,
                  iterations: np.ndarray, dt: float, n_steps: int) -> tuple[tuple, tuple, list]:
        """The kernel's arguments for :meth:`advance`'s, and the host arrays it updates with their device copies."""
        host = [*state, natural_curvature, running, failed, clock, iterations]
        device = [self._to_device(x, placeholder=True) for x in host]
        n_state = len(state)
        interval = (self._to_device(np.ascontiguousarray(gripper_water, dtype=float)), self.directions,
                    device[n_state], self._to_device(np.ascontiguousarray(rate, dtype=float)),
                    (float(curvature_range[0]), float(curvature_range[1])), *device[n_state + 1:],
                    (float(dt), int(n_steps)))
        arguments = (tuple(device[:n_state]), self.rods, self.terms, self.solver, interval)
        return arguments, tuple(host), device

    def advance(self, state: tuple, gripper_water: np.ndarray, natural_curvature: np.ndarray, rate: np.ndarray,
                curvature_range: tuple[float, float], running: np.ndarray, failed: np.ndarray, clock: np.ndarray,
                iterations: np.ndarray, dt: float, n_steps: int) -> None:
        """Steps the grippers ``running`` through ``n_steps`` steps of ``dt`` [s] with the current at every gripper
        at each step's start, ``gripper_water`` (n_steps + 1, B, 3) [m/s]; κ̄ is held through a step, then ramped
        by ``rate`` (R,) [1/s] within ``curvature_range``. Every other array is the host's and is updated in place:
        ``state`` (q, velocity, acceleration (R, N, S), tangent, director (R, N − 1, 3), reference twist (R, N)),
        κ̄ (R,), ``running``, ``failed`` (B,) bool, ``clock`` (B,) [s], ``iterations`` (B,) int."""
        arguments, host, device = self.arguments(state, gripper_water, natural_curvature, rate, curvature_range,
                                                 running, failed, clock, iterations, dt, n_steps)
        n_grippers = running.shape[0]
        blocks = (n_grippers + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
        rods_kernel(self.shape)[blocks, THREADS_PER_BLOCK](*arguments)
        if not simulated(self.cuda):
            for array, on_device in zip(host, device, strict=True):
                if array.size:
                    on_device.copy_to_host(array)


def rods_ptx(constants: tuple, state: tuple, n_grippers: int, compute_capability: tuple[int, int] = (9, 0)) -> str:
    """The PTX of the rods' kernel, compiled for ``compute_capability`` without a GPU (only numba-cuda and NVVM are
    needed): ``constants`` are :class:`GpuRods`' first arguments (:meth:`~..simulator.Simulator.gpu_constants`),
    ``state`` the host's state arrays as :meth:`GpuRods.advance` takes them. A check that every shared function
    compiles for the GPU."""
    shape = constants[-1]
    import_cuda()
    from numba import typeof
    from numba.cuda import dispatcher

    gpu = GpuRods(*constants, host=True)
    R = n_grippers * shape.n_fingers
    arguments, _, _ = gpu.arguments(state, np.zeros((2, n_grippers, 3)), np.zeros(R), np.zeros(R), (-1.0, 1.0),
                                    np.ones(n_grippers, dtype=bool), np.zeros(n_grippers, dtype=bool),
                                    np.zeros(n_grippers), np.zeros(n_grippers, dtype=np.int64), 1e-3, 1)
    signature = tuple(typeof(argument) for argument in arguments)
    kernel = _build_rods_kernel(shape)
    # a device function is compiled for the current device's compute capability: without a device, the one asked for
    current = dispatcher.get_current_device
    dispatcher.get_current_device = lambda: _Device(compute_capability)
    try:
        ptx, _ = cuda.compile_ptx(kernel.py_func, signature, cc=compute_capability)
    finally:
        dispatcher.get_current_device = current
    return ptx


class _Device(NamedTuple):
    compute_capability: tuple[int, int]


__all__ = ["THREADS_PER_BLOCK", "INSTALL_HINT", "GpuUnavailable", "GpuUnsupported", "check_device", "import_cuda",
           "cuda_module", "simulated", "RodsKernelShape", "rods_kernel", "GpuRods", "rods_ptx"]
