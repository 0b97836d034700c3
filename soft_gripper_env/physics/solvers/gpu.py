"""The GPU back end: the steps of a control interval on an NVIDIA GPU, one CUDA thread per gripper, compiled by
Numba from the same functions as the CPU kernels.

There is one copy of the physics. A CUDA kernel here is only the loop a CPU entry point runs around the shared
functions, compiled by numba-cuda: it meets a CPU-compiled (``@kernel``) function in a kernel and compiles it from its
Python source as a device function, with everything it calls. For that, the shared functions allocate nothing
(their work arrays come in as arguments: made once per call on the CPU, the thread's ``cuda.local.array`` on the
GPU; a few numbers of scratch from :func:`~..kernels.local.local_array`) and use only what both targets have
(``math`` rather than NumPy's ufuncs on scalars).

**Two kernels**, one thread per gripper, a launch per control interval:

- the rods on their own (:class:`GpuRods`): the thread copies its gripper's state into its own arrays and takes the
  interval's steps with :func:`~.newton.step_gripper_rods` (the rods' energies, the water, the contact between the
  fingers, the banded factorisation and Newton's loop) and :func:`~..kernels.rod_3d.rod_frames`;
- grasping a fixed object or a free body (:class:`GpuGrasp`): the thread runs :func:`~.stepping.step_batch`, the
  CPU's own loop of steps (predictor, contact corrector, the free body's coupled solve, the step's end, the contact
  reactions), on its gripper alone, with its scratch in its own arrays; a step the gripper does not settle is halved
  there, as the CPU halves it. The batch's state stays on the device between intervals (:class:`DeviceArrays`): it
  is uploaded whole only when the host hands over a state the device does not hold, a new episode's grippers are
  written into it row by row, and each interval copies the new state back for the host.

A thread's local memory is interleaved across the threads of a warp by the GPU, so the same element of neighbouring
threads' arrays is read in one transaction. The arrays' sizes are a kernel's compile-time constants (fingers, nodes,
coordinates per node), so a kernel is compiled per gripper design. Only the backward-Euler integrator runs here;
another raises :class:`GpuUnsupported`.

**Installation.** ``pip install -e ".[gpu]"`` brings numba-cuda and the CUDA libraries it needs; without it the
package works as before and ``device="cuda"`` raises :class:`GpuUnavailable` saying what to install. Tests run the
kernels without a GPU in Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``) and compile them to PTX for sm_90.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
import time
from contextlib import contextmanager
from typing import NamedTuple

import numpy as np
from numba.core import types

from ..kernels.assembly import FINGERS_FIELD, N_DESIGN_FIELDS, StepInputs, named_rods
from ..kernels.body import N_BODY_ARRAYS
from ..kernels.compiled import kernel
from ..kernels.current import CurrentBatch, current_velocity
from ..kernels.finger_contact import finger_scratch_size
from ..kernels.forces import project_water
from ..kernels.local import constant_shape, local_array
from ..kernels.rod_3d import elastic_scratch_size, elastic_views, rod_frames
from ..scene.forces import ForceTerms
from ..scene.scene import STEP_HALVINGS_LIMIT
from .corrector import CorrectorWork
from .newton import NewtonWork, SolverArrays, SolveResult, for_one_gripper, step_gripper_rods
from .stepping import N_ROD_STATE_FIELDS, StepWork, WorkingState, gripper_body, gripper_views, step_batch

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
    of that constant shape, as ``cuda.local.array`` makes it (the CPU's is an array on the function's stack)."""
    global _registered
    if _registered:
        return
    from numba.cuda import cudadecl, cudaimpl
    from numba.cuda.cudadrv import nvvm
    from numba.cuda.typing.templates import AbstractTemplate, signature

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


@contextmanager
def calls_kept_apart():
    """While a kernel compiles for the GPU: the shared functions that the CPU inlines at Numba's IR level
    (``inline="always"``) are compiled as device functions instead, once per signature, and NVVM inlines them at
    the LLVM level as it sees fit. Copying each one's IR into every caller made the grasp kernel's compile several
    times longer (the IR's deep copies took two thirds of it). The CPU dispatchers' option is restored on leaving,
    so a CPU compile must not run meanwhile (a GPU kernel compiles on its first launch; the CUDA simulator's launches
    do not enter this: their threads call the CPU's kernels)."""
    inlined = []
    for name, module in list(sys.modules.items()):
        if not name.startswith(_PHYSICS) or module is None:
            continue
        for value in vars(module).values():
            options = getattr(value, "targetoptions", None)
            if isinstance(options, dict) and options.get("inline") == "always" and \
                    getattr(value, "__module__", "").startswith(_PHYSICS):
                inlined.append(options)
    for options in inlined:
        options["inline"] = "never"
    try:
        yield
    finally:
        for options in inlined:
            options["inline"] = "always"


_PHYSICS = __name__.rsplit(".", 2)[0]
"""The physics core's package, whose modules hold the shared functions."""


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


_KERNELS: dict[tuple, object] = {}
"""Each kernel built, by its shape (:class:`RodsKernelShape` or :class:`GraspKernelShape`, whose types tell them
apart; a plain tuple naming a kernel that takes no shape): numba-cuda compiles it on its first launch and keeps
it."""


def _compiled(shape: tuple, build):
    """The kernel ``build`` makes for ``shape``, built once."""
    kernel = _KERNELS.get(shape)
    if kernel is None:
        cuda_module()
        kernel = _KERNELS[shape] = build(shape)
    return kernel


def rods_kernel(shape: RodsKernelShape):
    """The CUDA kernel that steps rods on their own through a control interval, for grippers of ``shape``
    (compiled on its first launch, then kept). Its arguments are tuples of device arrays (a tuple reaches the
    simulator's threads as the host's arrays, where the shared ``@kernel`` functions can take them):

    ``state`` = (q, velocity, acceleration (R, N, S), tangent, director (R, N − 1, 3), reference twist (R, N));
    ``rods`` = the design's fields of :class:`~..kernels.assembly.RodArrays` and the finger contact's, as plain
    tuples; ``terms`` the :class:`~..scene.forces.ForceTerms`' fields; ``solver`` the
    :class:`~.newton.SolverArrays`' fields (their per-rod arrays for one gripper's F rods);
    ``interval`` = (the steps' times (K + 1,) [s], the currents' :class:`~..kernels.current.CurrentArrays` fields,
    finger directions (F, 3), κ̄ (R,), rate (R,) [1/s], (low, high), running (B,) bool, failed (B,) bool, clock
    (B,) [s], Newton iterations (B,) int, (dt [s], steps K))."""
    return _compiled(shape, _build_rods_kernel)


@kernel(python=True)
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
        times, currents, directions, curvature, rate, curvature_range, running, failed, clock, iterations_sum, \
            timing = interval
        if b >= running.shape[0] or not running[b]:
            return
        dt, n_steps = timing
        current = cuda.local.array((1, 3), float64)  # the water at the gripper at a step's start
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
        work = NewtonWork(cuda.local.array((N, S), float64), cuda.local.array((N, S), float64), motion[0], motion[1],
                          elastic, cuda.local.array(finger_size or 1, float64)[:finger_size],
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
            current_velocity(currents, b, times[k], current[0])
            project_water(directions, current, water)
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


class _Stepper:
    """What the GPU's steppers share: the batch's state kept on the device between advances (:class:`DeviceArrays`
    of :class:`~.stepping.WorkingState`'s fields), and a count of each phase's wall time."""

    def __init__(self, host: bool) -> None:
        self.cuda = None if host else cuda_module()
        self.seconds = _phases()
        """Wall seconds spent in each phase of the advances so far (:func:`_phases`)."""
        self.state: DeviceArrays | None = None
        """The batch's state on the device, once :meth:`load` has put one there; each advance updates it in
        place."""

    def load(self, state: tuple) -> None:
        """Uploads ``state`` (:class:`~.stepping.WorkingState`'s fields, host arrays) whole, as the state the next
        advance starts from."""
        begin = time.perf_counter()
        if self.state is None:
            self.state = DeviceArrays(self.cuda, state)
        else:
            self.state.load(state)
        self.seconds["upload"] += time.perf_counter() - begin

    def put(self, rows: tuple, values: tuple) -> None:
        """Writes ``values`` (:class:`~.stepping.WorkingState`'s fields for some grippers) into the rows ``rows``
        (one index array per field) of the state on the device, leaving the other grippers' rows as they are."""
        begin = time.perf_counter()
        self._loaded().put(rows, values)
        self.seconds["upload"] += time.perf_counter() - begin

    def _loaded(self) -> DeviceArrays:
        if self.state is None:
            raise RuntimeError(f"{type(self).__name__}: no state on the device; load one first")
        return self.state

    def _fetch(self) -> tuple:
        """A host copy of the state on the device (new arrays), its time counted as a download."""
        begin = time.perf_counter()
        host = self._loaded().fetch()
        self.seconds["download"] += time.perf_counter() - begin
        return host


class GpuRods(_Stepper):
    """Rods on their own, stepped on the GPU: the batch's constants on the device, the state kept there, and
    :meth:`advance`.

    ``rods``, ``terms`` and ``solver`` are the plain fields the CPU's entry points take
    (:func:`~.newton.advance_rods`), ``finger_directions`` (F, 3). With ``host`` the arrays stay the host's and no
    GPU is needed (for :func:`rods_ptx`, which only compiles)."""

    def __init__(self, rods: tuple, terms: tuple, solver: tuple, finger_directions: np.ndarray,
                 shape: RodsKernelShape, host: bool = False) -> None:
        super().__init__(host)
        self.shape = shape
        design = rods[:N_DESIGN_FIELDS]
        fingers = design[FINGERS_FIELD]
        self.rods = _on_device(self.cuda, design[:FINGERS_FIELD], False) + (
            (float(fingers[0]), float(fingers[1])) + _on_device(self.cuda, fingers[2:], False),)
        self.terms = _on_device(self.cuda, tuple(terms), False)
        self.solver = _on_device(self.cuda, for_one_gripper(solver, shape.n_fingers), False)
        self.directions = _on_device(self.cuda, np.ascontiguousarray(finger_directions, dtype=float), False)

    def arguments(self, state: tuple, times: np.ndarray, currents: tuple, natural_curvature: np.ndarray,
                  rate: np.ndarray, curvature_range: tuple[float, float], running: np.ndarray, failed: np.ndarray,
                  clock: np.ndarray, iterations: np.ndarray, dt: float, n_steps: int) -> tuple[tuple, list, list]:
        """The kernel's arguments for :meth:`advance`'s (``state`` the six arrays it steps, the device's or the
        host's), and the host arrays it writes besides the state with their device copies."""
        written = [natural_curvature, running, failed, clock, iterations]
        device = [_on_device(self.cuda, x) for x in written]
        interval = (_on_device(self.cuda, np.ascontiguousarray(times, dtype=float), False),
                    _on_device(self.cuda, tuple(currents)), self.directions,
                    device[0], _on_device(self.cuda, np.ascontiguousarray(rate, dtype=float), False),
                    (float(curvature_range[0]), float(curvature_range[1])), *device[1:],
                    (float(dt), int(n_steps)))
        arguments = (_on_device(self.cuda, tuple(state)), self.rods, self.terms, self.solver, interval)
        return arguments, written, device

    def advance(self, times: np.ndarray, currents: tuple, natural_curvature: np.ndarray, rate: np.ndarray,
                curvature_range: tuple[float, float], running: np.ndarray, failed: np.ndarray, clock: np.ndarray,
                iterations: np.ndarray, dt: float, n_steps: int) -> tuple:
        """Steps the grippers ``running`` through ``n_steps`` steps of ``dt`` [s] from the state on the device
        (:meth:`load`, :meth:`put`, the last advance), which it updates there, with the water of ``currents``
        (:class:`~..kernels.current.CurrentArrays`) at each step's start, the batch times ``times`` (n_steps + 1,)
        [s]; κ̄ is held through a step, then ramped
        by ``rate`` (R,) [1/s] within ``curvature_range``. The other arrays are the host's and are updated in
        place: κ̄ (R,), ``running``, ``failed`` (B,) bool, ``clock`` (B,) [s], ``iterations`` (B,) int. Returns a
        host copy of the new state (:class:`~.stepping.WorkingState`'s fields, new arrays)."""
        state = self._loaded()
        begin = time.perf_counter()
        q, velocity, acceleration, _, _, tangent, director, twist = state.device[:N_ROD_STATE_FIELDS]
        arguments, written, device = self.arguments((q, velocity, acceleration, tangent, director, twist), times,
                                                    currents, natural_curvature, rate, curvature_range, running,
                                                    failed, clock, iterations, dt, n_steps)
        self.seconds["upload"] += time.perf_counter() - begin
        _launch(self.cuda, rods_kernel(self.shape), running.shape[0], arguments, written, device, self.seconds)
        return self._fetch()


class GraspKernelShape(NamedTuple):
    """What a grasp kernel's arrays are sized by, and what it compiles in: its compile-time constants."""

    n_fingers: int
    n_nodes: int
    stride: int
    """Coordinates per node S: 2 planar, 4 in 3-D (position and twist)."""
    dim: int
    """Position coordinates per node D: 2 planar, 3 in 3-D."""
    finger_contact: bool
    """Whether the fingers touch each other."""
    free_body: bool
    """Whether the object is a free body (else it is fixed)."""


def grasp_kernel(shape: GraspKernelShape):
    """The CUDA kernel that takes the steps of a control interval of grippers grasping an object, for grippers of
    ``shape``, one thread per gripper (compiled on its first launch, then kept): each thread runs
    :func:`~.stepping.step_batch`, the CPU's own loop, on its gripper alone, with its scratch in the thread's own
    arrays. Its arguments are tuples (a tuple reaches the simulator's threads as the host's arrays):
    ``state`` the :class:`~.stepping.WorkingState`'s fields; ``rods`` the design's fields of
    :class:`~..kernels.assembly.RodArrays`; ``terms`` the :class:`~..scene.forces.ForceTerms`' fields; ``solver``
    the :class:`~.newton.SolverArrays`' fields for one gripper's F rods, at each level of halving (steps of dt,
    dt/2, …); ``geometry`` = (the :class:`~.corrector.ContactGeometry`'s fields, the projection (F, D, 3)); ``body``
    the :class:`~..kernels.body.BodyArrays`' fields (a placeholder for a fixed object); ``interval`` the
    :class:`~.stepping.Interval`'s fields; ``timing`` = (the steps' times (K + 1,) [s], the currents'
    :class:`~..kernels.current.CurrentArrays` fields, where each gripper stopped (B,) int, written, dt [s], K)."""
    return _compiled(shape, _build_grasp_kernel)


def _build_grasp_kernel(shape: GraspKernelShape):
    F, N, S, D = shape.n_fingers, shape.n_nodes, shape.stride, shape.dim
    n = N * S
    band = 3 * S  # kd + 1
    three_d = S == 4
    free = shape.free_body
    planar_free = free and not three_d
    # a local array has at least one element: what a model or object does not have is an empty slice of one
    edges = N - 1
    framed = F if three_d else 0
    held_by_body = F if free else 0
    bodies = 1 if free else 0
    moving = 1 if free and three_d else 0  # a 3-D free body's admissible motions
    contact_fingers = F if shape.finger_contact else 0
    elastic_size = elastic_scratch_size(N if three_d else 0)
    finger_size = finger_scratch_size(contact_fingers, N)
    levels = STEP_HALVINGS_LIMIT + 1  # of halving: each level's half step's start time
    float64, int64, boolean = types.float64, types.int64, types.boolean

    @cuda.jit
    def grasp_interval(state, rods_design, terms, solvers, geometry_projection, body, interval, timing):
        b = cuda.grid(1)
        running = interval[4]
        if b >= running.shape[0]:
            return
        times, currents, stops, dt, n_steps = timing
        geometry, projection = geometry_projection
        own, own_geometry, own_interval, own_currents = gripper_views(b, F, held_by_body, framed, bodies, moving,
                                                                      state, geometry, interval, currents)
        rods = rods_design + (own.tangent, own.director, own.reference_twist)  # empty views in the planar model
        own_body = None
        if free:
            own_body = gripper_body(body, b)
        # the scratch (stepping.step_work's, for one gripper), in the thread's own arrays
        flags = cuda.local.array((8, F), boolean)
        node_flags = cuda.local.array((7, F, N), boolean)
        counts = cuda.local.array((3, F), int64)
        ratios = cuda.local.array((3, F), float64)
        for f in range(F):  # new_work's zeros: nothing rubs or touches before a solve says so
            flags[3, f] = False
        new = WorkingState(cuda.local.array((F, N, S), float64), cuda.local.array((F, N, S), float64),
                           cuda.local.array((F, N, S), float64), node_flags[0],
                           cuda.local.array((F, N, 3), float64)[:held_by_body],
                           cuda.local.array((F, edges, 3), float64)[:framed],
                           cuda.local.array((F, edges, 3), float64)[:framed],
                           cuda.local.array((F, N), float64)[:framed],
                           cuda.local.array((1, 3), float64)[:bodies], cuda.local.array((1, 3), float64)[:bodies],
                           cuda.local.array((1, 3, 3), float64)[:bodies], cuda.local.array((1, 3), float64)[:bodies])
        saved = WorkingState(cuda.local.array((F, N, S), float64), cuda.local.array((F, N, S), float64),
                             cuda.local.array((F, N, S), float64), cuda.local.array((F, N), boolean),
                             cuda.local.array((F, N, 3), float64)[:held_by_body],
                             cuda.local.array((F, edges, 3), float64)[:framed],
                             cuda.local.array((F, edges, 3), float64)[:framed],
                             cuda.local.array((F, N), float64)[:framed],
                             cuda.local.array((1, 3), float64)[:bodies], cuda.local.array((1, 3), float64)[:bodies],
                             cuda.local.array((1, 3, 3), float64)[:bodies],
                             cuda.local.array((1, 3), float64)[:bodies])
        rod_steps = cuda.local.array((2, F, n), float64)  # x0 and the rods' last steps
        for f in range(F):
            for j in range(n):
                rod_steps[1, f, j] = 0.0
        newton = NewtonWork(
            cuda.local.array((N, S), float64), cuda.local.array((N, S), float64), cuda.local.array((N, D), float64),
            cuda.local.array((N, D), float64),
            cuda.local.array(elastic_size or 1, float64)[:elastic_size],
            cuda.local.array(finger_size or 1, float64)[:finger_size],
            cuda.local.array((F, n, band), float64),
            cuda.local.array((F, n, 6), float64)[:held_by_body], rod_steps[0],
            cuda.local.array((F, n, 6), float64)[:held_by_body], cuda.local.array((F, 6, 6), float64)[:held_by_body],
            cuda.local.array((F, 6), float64)[:held_by_body], rod_steps[1], ratios[0], flags[0], flags[1], flags[2],
            cuda.local.array(6, float64)[:6 * bodies], cuda.local.array((6, 6), float64)[:6 * bodies],
            cuda.local.array(6, float64)[:6 * bodies], cuda.local.array(6, float64)[:6 * bodies],
            cuda.local.array((3, 3), float64)[:3 * bodies], cuda.local.array((n, 6), float64)[:n * bodies],
            cuda.local.array(band, float64), cuda.local.array((F, N, D), float64), cuda.local.array((D, D), float64),
            flags[3], ratios[1])
        points = cuda.local.array((4, F, N, D), float64)
        corrector = CorrectorWork(flags[4], cuda.local.array((F, n), boolean), cuda.local.array((F, D), float64),
                                  node_flags[1], node_flags[2], node_flags[3], points[0], node_flags[4], node_flags[6],
                                  points[1],
                                  flags[5], counts[0],
                                  cuda.local.array((1, 6, 6), float64)[:1 if planar_free else 0], newton)
        gripper = cuda.local.array(1, int64)
        gripper[0] = 0
        work = StepWork(cuda.local.array((F, N, S), float64), new, saved,
                        cuda.local.array(levels, float64), cuda.local.array((1, 3), float64),
                        cuda.local.array((F, D), float64),
                        cuda.local.array((1, 3), float64), cuda.local.array((F, N, F), int64)[:contact_fingers],
                        node_flags[5], points[2], cuda.local.array((F, n), boolean), points[3], flags[6], flags[7],
                        counts[1], counts[2], ratios[2], cuda.local.array((F, n), float64),
                        cuda.local.array((F, N, 3), float64), cuda.local.array((F, N), float64),
                        cuda.local.array(1, boolean), cuda.local.array(1, int64), gripper, corrector)
        stops[b] = step_batch(0, n_steps, dt, times, own_currents, own, rods, terms, solvers, own_geometry,
                              projection, own_body, own_interval, work)

    return grasp_interval


class GpuGrasp(_Stepper):
    """Grippers grasping an object, stepped on the GPU: the batch's constants on the device, the state kept there,
    and :meth:`advance`.

    ``rods``, ``terms``, ``solvers`` (one per level of halving), ``geometry`` and ``projection`` are the plain fields
    the CPU's :func:`~.stepping.take_steps` takes, ``body`` the free bodies' (None for a fixed object). The object's
    place and friction (``geometry``), the bodies' constants and the currents are copied at every :meth:`advance`,
    since a new episode changes them. With ``host`` the arrays stay the host's and no GPU is needed (for
    :func:`grasp_ptx`)."""

    def __init__(self, rods: tuple, terms: tuple, solvers: tuple, projection: np.ndarray, shape: GraspKernelShape,
                 host: bool = False) -> None:
        super().__init__(host)
        self.shape = shape
        F = shape.n_fingers
        self.rods = _on_device(self.cuda, rods[:N_DESIGN_FIELDS])
        self.terms = _on_device(self.cuda, terms)
        self.solvers = _on_device(self.cuda, tuple(for_one_gripper(solver, F) for solver in solvers))
        self.projection = _on_device(self.cuda, projection[:F])

    def arguments(self, state: tuple, geometry: tuple, body: tuple | None, interval: tuple, times: np.ndarray,
                  currents: tuple, stops: np.ndarray, dt: float, n_steps: int) -> tuple[tuple, list, list]:
        """The kernel's arguments (``state`` the device's arrays, or the host's), and the host arrays it writes
        besides the state with their device copies."""
        n_grippers = stops.shape[0]
        written = [*(interval[i] for i in _INTERVAL_WRITTEN), stops]
        device = [_on_device(self.cuda, x) for x in written]
        written_at = {index: device[i] for i, index in enumerate(_INTERVAL_WRITTEN)}
        device_interval = [written_at[i] if i in written_at else _on_device(self.cuda, x)
                           for i, x in enumerate(interval)]
        if body is None:  # a fixed object: a placeholder the kernel does not read
            body = tuple(np.zeros(n_grippers) for _ in range(N_BODY_ARRAYS)) + (0.0, 0.0, 0.0, 0.0)
        arguments = (_on_device(self.cuda, tuple(state)), self.rods, self.terms, self.solvers,
                     (_on_device(self.cuda, tuple(geometry)), self.projection),
                     _on_device(self.cuda, tuple(body)),
                     tuple(device_interval),
                     (_on_device(self.cuda, np.ascontiguousarray(times, dtype=float)),
                      _on_device(self.cuda, tuple(currents)), device[-1], float(dt), int(n_steps)))
        return arguments, written, device

    def advance(self, geometry: tuple, body: tuple | None, interval: tuple, times: np.ndarray, currents: tuple,
                dt: float, n_steps: int) -> tuple[np.ndarray, tuple]:
        """Takes ``n_steps`` steps of ``dt`` [s] of every running gripper from the batch times ``times``
        (n_steps + 1,) [s], as :func:`~.stepping.take_steps` takes them on the CPU, with the water of ``currents``
        (:class:`~..kernels.current.CurrentArrays`), from the state on the device (:meth:`load`, :meth:`put`, the
        last advance), which it updates there; a step a gripper does not settle is halved in its thread.
        ``interval`` (:class:`~.stepping.Interval`'s fields) is the host's and is updated in place. Returns the step
        where each gripper stopped (B,) (``n_steps``, or the step after a failed one) and a host copy of the new
        state (:class:`~.stepping.WorkingState`'s fields, new arrays)."""
        state = self._loaded()
        begin = time.perf_counter()
        stops = np.zeros(interval[4].shape[0], dtype=np.int64)
        arguments, written, device = self.arguments(state.device, geometry, body, interval, times, currents, stops,
                                                    dt, n_steps)
        self.seconds["upload"] += time.perf_counter() - begin
        _launch(self.cuda, grasp_kernel(self.shape), stops.shape[0], arguments, written, device, self.seconds)
        return stops, self._fetch()


_INTERVAL_WRITTEN = (0, 4, 5, 6, 7, 8, 9, 10)
"""The fields of :class:`~.stepping.Interval` the kernel writes: κ̄, running, failed, clock, Newton iterations, the
two impulses, pending."""


def grasp_ptx(constants: tuple, state: tuple, geometry: tuple, body: tuple | None, interval: tuple,
              compute_capability: tuple[int, int] = (9, 0), optimised: bool = True) -> str:
    """The PTX of the grasp kernel, compiled for ``compute_capability`` without a GPU: ``constants`` are
    :class:`GpuGrasp`'s first arguments, the others :meth:`GpuGrasp.advance`'s (host arrays). A check that every
    shared function compiles for the GPU. ``optimised``: as :func:`_ptx`."""
    import_cuda()
    gpu = GpuGrasp(*constants, host=True)
    n_grippers = interval[4].shape[0]
    arguments, _, _ = gpu.arguments(state, geometry, body, interval, np.zeros(2), CurrentBatch(n_grippers).arrays,
                                    np.zeros(n_grippers, dtype=np.int64), 1e-3, 1)
    return _ptx(_build_grasp_kernel(constants[-1]), arguments, compute_capability, optimised)


class DeviceArrays:
    """Host arrays' copies kept on the device between launches (a batch's state, which each control interval
    updates in place there): uploaded whole (:meth:`load`), written gripper by gripper (:meth:`put`) and copied back
    whole (:meth:`fetch`). An array the host has empty is one placeholder element there, never copied. In the CUDA
    simulator the device's arrays are copies of the host's, as on a GPU, so that a copy left out shows in its
    tests.

    ``bytes`` counts what went each way so far (``upload``, ``download``)."""

    def __init__(self, cuda, host: tuple) -> None:
        self.cuda = cuda
        self.kinds = tuple((array.shape, array.dtype) for array in host)
        """Each host array's shape and dtype."""
        self.bytes = {"upload": 0, "download": 0}
        self.device = tuple(self._allocate(np.ascontiguousarray(array)) for array in host)
        self.bytes["upload"] += sum(array.nbytes for array in host)

    def _allocate(self, array: np.ndarray):
        if simulated(self.cuda):
            return array.copy()
        return self.cuda.to_device(array if array.size else np.zeros((1,) * array.ndim, dtype=array.dtype))

    def load(self, host: tuple) -> None:
        """Copies ``host`` (arrays of the same shapes and dtypes as the first) into the device's arrays."""
        for array, on_device, (shape, dtype) in zip(host, self.device, self.kinds, strict=True):
            if array.shape != shape or array.dtype != dtype:
                raise ValueError(f"DeviceArrays.load: an array of shape {array.shape} and dtype {array.dtype} where "
                                 f"the device holds {shape}, {dtype}")
            if not array.size:
                continue
            array = np.ascontiguousarray(array)
            if simulated(self.cuda):
                np.copyto(on_device, array)
            else:
                on_device.copy_to_device(array)
            self.bytes["upload"] += array.nbytes

    def put(self, rows: tuple, values: tuple) -> None:
        """Writes ``values[i]`` (k_i rows of array i's trailing shape) into the rows ``rows[i]`` (k_i,) of array
        ``i`` on the device: only those rows cross, then a kernel scatters them."""
        scatter = _compiled(("scatter_rows",), _build_scatter_kernel)
        for index, (array_rows, array, on_device, (shape, dtype)) in enumerate(
                zip(rows, values, self.device, self.kinds, strict=True)):
            if not len(array_rows) or not np.prod(shape):
                continue
            array_rows = np.ascontiguousarray(array_rows, dtype=np.int64)
            array = np.ascontiguousarray(array, dtype=dtype)
            if array.shape != (len(array_rows),) + shape[1:] or array_rows.min() < 0 or array_rows.max() >= shape[0]:
                raise ValueError(f"DeviceArrays.put: array {index}: {array.shape[0]} rows of shape {array.shape[1:]} "
                                 f"into rows {array_rows.min()}..{array_rows.max()} of {shape}")
            width = int(np.prod(shape[1:]))
            target = on_device.reshape(shape[0], width)
            source = array.reshape(len(array_rows), width)
            if not simulated(self.cuda):
                array_rows, source = self.cuda.to_device(array_rows), self.cuda.to_device(source)
            threads = len(array_rows) * width
            scatter[(threads + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK, THREADS_PER_BLOCK](target, array_rows,
                                                                                             source)
            self.bytes["upload"] += array.nbytes + 8 * len(array_rows)
        if not simulated(self.cuda):
            self.cuda.synchronize()

    def fetch(self) -> tuple:
        """New host copies of the device's arrays (empty where the host's were)."""
        host = []
        for on_device, (shape, dtype) in zip(self.device, self.kinds, strict=True):
            if not np.prod(shape):
                host.append(np.empty(shape, dtype=dtype))
            elif simulated(self.cuda):
                host.append(on_device.copy())
            else:
                host.append(on_device.copy_to_host())
            self.bytes["download"] += host[-1].nbytes
        return tuple(host)


def _build_scatter_kernel(_):
    @cuda.jit
    def scatter_rows(target, rows, values):
        """``target[rows[i], j] = values[i, j]``, one thread per element of ``values``."""
        element = cuda.grid(1)
        width = values.shape[1]
        if element < rows.shape[0] * width:
            i = element // width
            j = element - i * width
            target[rows[i], j] = values[i, j]

    return scatter_rows


def _on_device(cuda, value, placeholder: bool = True):
    """``value`` with its arrays on the device, all the way down a tuple; other values as they are. The simulator's
    threads, and a host-only stepper (``cuda`` None), take the host's own arrays. With ``placeholder``, an empty
    array goes as one element of its dimensions (a size the kernel slices back to none, or state it does not read,
    such as the planar model's frames)."""
    if isinstance(value, tuple):
        return tuple(_on_device(cuda, x, placeholder) for x in value)
    if not isinstance(value, np.ndarray):
        return value
    array = np.ascontiguousarray(value)
    if cuda is None or simulated(cuda):
        return array
    if placeholder and not array.size:
        array = np.zeros((1,) * array.ndim, dtype=array.dtype)
    return cuda.to_device(array)


def _phases() -> dict[str, float]:
    """A count of an advance's phases in wall seconds: ``upload`` (the arguments made and copied to the device),
    ``kernel`` (launch to completion; a kernel's first launch includes its compile) and ``download`` (the arrays it
    wrote copied back)."""
    return {"upload": 0.0, "kernel": 0.0, "download": 0.0}


def _launch(cuda, kernel, n_grippers: int, arguments: tuple, host: list, device: list, seconds: dict) -> None:
    """Launches ``kernel`` with a thread per gripper, waits for it, and copies each array it writes back into its
    ``host`` array (from its ``device`` copy; in the simulator they are the same arrays), adding each phase's wall
    time to ``seconds`` (:func:`_phases`)."""
    begin = time.perf_counter()
    blocks = (n_grippers + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK
    if getattr(kernel, "overloads", None) or simulated(cuda):
        # compiled (at its first launch): no scan of the modules per action; the simulator's threads call the CPU's
        # kernels, which compile (and are cached) as the CPU's own, inlined calls and reference counting unchanged
        kernel[blocks, THREADS_PER_BLOCK](*arguments)
    else:
        with calls_kept_apart():
            kernel[blocks, THREADS_PER_BLOCK](*arguments)
    cuda.synchronize()
    copied = time.perf_counter()
    seconds["kernel"] += copied - begin
    for array, on_device in zip(host, device, strict=True):
        if not array.size or on_device is array:
            continue
        if isinstance(on_device, np.ndarray):  # the simulator's contiguous copy of a host array
            array[...] = on_device
        else:
            on_device.copy_to_host(array)
    seconds["download"] += time.perf_counter() - copied


def rods_ptx(constants: tuple, state: tuple, n_grippers: int, compute_capability: tuple[int, int] = (9, 0),
             optimised: bool = True) -> str:
    """The PTX of the rods' kernel, compiled for ``compute_capability`` without a GPU (only numba-cuda and NVVM are
    needed): ``constants`` are :class:`GpuRods`' first arguments (:meth:`~..simulator.Simulator.gpu_constants`),
    ``state`` the host's state arrays as :meth:`GpuRods.advance` takes them. A check that every shared function
    compiles for the GPU. ``optimised``: as :func:`_ptx`."""
    shape = constants[-1]
    import_cuda()
    gpu = GpuRods(*constants, host=True)
    R = n_grippers * shape.n_fingers
    arguments, _, _ = gpu.arguments(state, np.zeros(2), CurrentBatch(n_grippers).arrays, np.zeros(R), np.zeros(R),
                                    (-1.0, 1.0),
                                    np.ones(n_grippers, dtype=bool), np.zeros(n_grippers, dtype=bool),
                                    np.zeros(n_grippers), np.zeros(n_grippers, dtype=np.int64), 1e-3, 1)
    return _ptx(_build_rods_kernel(shape), arguments, compute_capability, optimised)


def _ptx(kernel, arguments: tuple, compute_capability: tuple[int, int], optimised: bool = True) -> str:
    """The PTX of ``kernel`` for ``arguments``' types, compiled for ``compute_capability`` without a GPU.
    ``optimised``: whether NVVM optimises the code (``-opt=3``, as a launch does) or only translates it
    (``-opt=0``): whether every function types, lowers and passes NVVM does not depend on it, and the 3-D grasp
    kernel then compiles in about a third of the time (33 s against 108 s on a 2-core machine)."""
    if not isinstance(optimised, bool):
        raise TypeError(f"optimised must be a bool, got {optimised!r}")
    from numba import typeof
    from numba.cuda import dispatcher

    signature = tuple(typeof(argument) for argument in arguments)
    # a device function is compiled for the current device's compute capability: without a device, the one asked for
    current = dispatcher.get_current_device
    dispatcher.get_current_device = lambda: _Device(compute_capability)
    try:
        with calls_kept_apart():
            ptx, _ = cuda.compile_ptx(kernel.py_func, signature, cc=compute_capability, opt=optimised)
    finally:
        dispatcher.get_current_device = current
    return ptx


class _Device(NamedTuple):
    compute_capability: tuple[int, int]


__all__ = ["THREADS_PER_BLOCK", "INSTALL_HINT", "GpuUnavailable", "GpuUnsupported", "check_device", "import_cuda",
           "cuda_module", "simulated", "RodsKernelShape", "rods_kernel", "GpuRods", "rods_ptx", "GraspKernelShape",
           "grasp_kernel", "GpuGrasp", "DeviceArrays", "grasp_ptx"]
