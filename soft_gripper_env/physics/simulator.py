"""The simulator: a batch of grippers stepped in time, their state, and what each step reports.

Every state array carries a leading batch axis B (grippers) and a finger axis F. Internally the B·F rods are
flattened to one rod axis R. The whole step runs in compiled solvers (:mod:`.solvers`): Newton's method for rods on
their own (:func:`~.solvers.newton.advance_rods`) and, with an object, the contact corrector around it
(:func:`~.solvers.corrector.solve_with_contact`), fixed or free. This module holds the batch's arrays (the
discretization, the force terms, the water's currents, the grasped bodies), bundles them for the kernels, lets the
scene's integrator compose implicit steps (:meth:`Simulator.implicit_step`), halves steps that fail and reports
contact. Each rod (or gripper, with a free body) stops iterating as soon as it has converged, so its result does not
depend on what else shares its batch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .kernels.assembly import N_DESIGN_FIELDS, RodArrays, StepInputs, assemble
from .kernels.body import BodyArrays, BodyMotion, BodyState, palm_reactions
from .kernels.contact import contact_reactions, object_in_rod_frames
from .kernels.current import CurrentBatch
from .kernels.finger_contact import FingerContact, find_near_fingers, finger_scratch
from .kernels.forces import rod_water_velocity
from .kernels.rod_3d import elastic_scratch, rod3d_elastic, rod3d_update_frames
from .kernels.rod_planar import planar_elastic
from .scene.fluid import Current
from .scene.forces import BodyLoads, ForceTerms
from .scene.objects import ContactSettings, penetration_tolerance
from .scene.scene import NATURAL_CURVATURE_LIMIT, Scene
from .solvers.corrector import ContactGeometry, contact_masks, solve_with_contact
from .solvers.gpu import GpuGrasp, GpuRods, GpuUnsupported, GraspKernelShape, RodsKernelShape, check_device
from .solvers.integrators import INTEGRATORS
from .solvers.newton import (
    Holds,
    SolverArrays,
    SolveResult,
    advance_rods,
    finish,
    for_one_gripper,
    midpoint_end,
    per_gripper,
    plain,
    predict,
)
from .solvers.records import (
    Advance,
    ContactReport,
    RodState,
    StepResult,
    _set,
    evolve,
    finite,
    put_grippers,
    record,
    take_grippers,
)
from .solvers.stepping import (
    N_ROD_STATE_FIELDS,
    Interval,
    WorkingState,
    commit_step,
    gripper_body,
    gripper_views,
    take_steps,
)


class BodyModel:
    """Mass properties and external loads of the free spheres or capsules of a batch of B grippers, one each, as
    arrays with a leading batch axis (body frame = world at t = 0). :meth:`load` sets one gripper's body."""

    def __init__(self, loads: BodyLoads, batch_size: int, contact: ContactSettings) -> None:
        self.contact = contact
        """The palm's settings (:class:`~.scene.objects.ContactSettings`)."""
        self.loads = loads
        """The scene's force models' constants for the body (:class:`~.scene.forces.BodyLoads`)."""
        B = batch_size
        self.radius = np.zeros(B)
        """Radius of each body [m], (B,)."""
        self.mass = np.zeros(B)
        """m [kg], (B,)."""
        self.inertia = np.zeros((B, 3, 3))
        """Rotational inertia about the centre, body frame [kg·m²], (B, 3, 3)."""
        self.added_mass = np.zeros((B, 3, 3))
        """Added-mass tensor, body frame [kg], (B, 3, 3)."""
        self.weight = np.zeros(B)
        """Net weight along −z, (m − ρ_w·V)·g [N], (B,)."""
        self.normal_drag = np.zeros(B)
        """½·ρ_w·C_n·D·h of a capsule's cylinder, on the velocity normal to its axis [kg/m]; 0 for a sphere."""
        self.isotropic_drag = np.zeros(B)
        """½·ρ_w·C_d·π·r² of the sphere (or a capsule's two end caps together) [kg/m]."""
        self.displaced_mass = np.zeros(B)
        """ρ_w·V of the Froude–Krylov force ρ_w·V·a_w [kg], (B,); 0 without it."""
        self.spin_damping = np.zeros(B)
        """8π·η·R³ of the creeping-flow torque on the turning body [N·m·s], (B,)."""
        self.spin_drag = np.zeros(B)
        """½·ρ_w·6.45·√ν·R⁴ of the boundary layer's torque, ·√|ω|·ω [N·m·s^(3/2)], (B,)."""
        self.tumble_drag = np.zeros(B)
        """½·ρ_w·C_n·D·h⁴/32 of a capsule's cylinder turning across its axis, ·|ω⊥|·ω⊥ [N·m·s²]; 0 for a sphere."""
        self.axis = np.tile([0.0, 0.0, 1.0], (B, 1))
        """The capsule's axis in the body frame (B, 3); any unit vector for a sphere."""
        self.segment = (np.zeros((B, 3)), np.zeros((B, 3)))
        """The object's segment ends relative to its centre, body frame [m], (B, 3) each (zero for a sphere)."""
        self.plain_arrays = plain(self.arrays())
        """:meth:`arrays` as plain fields for the kernels' entry points (the same arrays, which :meth:`load` fills)."""

    def load(self, index: int, obj) -> None:
        """Sets gripper ``index``'s body to the free :class:`~.scene.objects.Sphere` or
        :class:`~.scene.objects.Capsule` ``obj``."""
        r = obj.radius
        start, end = (np.asarray(p, dtype=float) for p in obj.segment)
        center = 0.5 * (start + end)
        length = float(np.linalg.norm(end - start))
        axis = (end - start) / length if length > 0 else np.array([0.0, 0.0, 1.0])
        along = np.outer(axis, axis)
        across = np.eye(3) - along
        cylinder, caps = math.pi * r**2 * length, 4.0 / 3.0 * math.pi * r**3
        m_cylinder, m_caps = obj.density * cylinder, obj.density * caps
        self.radius[index] = r
        self.mass[index] = m_cylinder + m_caps
        self.inertia[index] = (m_cylinder * r**2 / 2 + m_caps * 2 * r**2 / 5) * along + (
            m_cylinder * (length**2 / 12 + r**2 / 4) + m_caps * (2 * r**2 / 5 + length**2 / 4 + 3 * length * r / 8)
        ) * across
        loads = self.loads
        self.added_mass[index] = loads.cylinder_added_mass * cylinder * across \
            + loads.sphere_added_mass * caps * np.eye(3)
        self.weight[index] = (m_cylinder + m_caps) * loads.gravity - loads.buoyancy * (cylinder + caps)
        self.normal_drag[index] = loads.normal_drag * 2 * r * length
        self.isotropic_drag[index] = loads.sphere_drag * math.pi * r**2
        self.displaced_mass[index] = loads.froude_krylov * (cylinder + caps)
        self.spin_damping[index] = loads.spin_viscous * r**3
        self.spin_drag[index] = loads.spin_boundary_layer * r**4
        self.tumble_drag[index] = self.normal_drag[index] * length**3 / 32
        self.axis[index] = axis
        self.segment[0][index] = start - center
        self.segment[1][index] = end - center

    def arrays(self) -> BodyArrays:
        """The bodies' arrays as the compiled kernels take them (views: :meth:`load` updates them)."""
        return BodyArrays(self.mass, self.inertia, self.added_mass, self.weight, self.normal_drag, self.isotropic_drag,
                          self.displaced_mass, self.spin_damping, self.spin_drag, self.tumble_drag, self.axis,
                          self.segment[0], self.segment[1], self.radius, float(self.contact.palm_stiffness),
                          float(self.contact.palm_radius), float(self.contact.palm_damping_depth),
                          float(self.contact.palm_friction))

    def palm_reaction(self, c, c_old, theta, orientation, orientation_old, dt) -> np.ndarray:
        """The force of each body on the palm [N], (B, 3), over a step of ``dt`` [s] from ``c_old`` to ``c`` and
        turning by ``theta`` [rad] (B, 3)."""
        reaction = np.zeros_like(c)
        palm_reactions(self.plain_arrays, c, c_old, theta, orientation, orientation_old, dt, reaction)
        return reaction


class Simulator:
    """Steps a batch of grippers in time: one :class:`~.scene.scene.Scene` for all, or one per gripper that differ
    only in the grasped object's size, place, density and velocity and in the water's current.

    >>> sim = Simulator(paper_scene())
    >>> state = sim.initial_state()
    >>> result = sim.step(state, natural_curvature=-0.15 * state.time)
    """

    def __init__(self, scene: Scene | Sequence[Scene], batch_size: int | None = None, device: str = "cpu") -> None:
        self.device = check_device(device)
        """Where :meth:`advance` steps the batch: "cpu", or "cuda" (:mod:`.solvers.gpu`: rods on their own, or
        grasping a fixed or free object, with the backward-Euler integrator; every other call runs on the CPU).
        On the GPU the state stays on the device between calls: :meth:`advance` returns a state whose arrays are
        read-only copies, and given that state back (or what :meth:`put_grippers` made of it) uploads nothing."""
        scenes = [scene] if isinstance(scene, Scene) else list(scene)
        if not scenes or not all(isinstance(s, Scene) for s in scenes):
            raise ValueError("Simulator.scene must be a Scene or a non-empty sequence of Scenes")
        if batch_size is None:
            batch_size = len(scenes) if len(scenes) > 1 else 1
        if not isinstance(batch_size, (int, np.integer)) or not 1 <= batch_size <= 10_000_000:
            raise ValueError(f"Simulator.batch_size = {batch_size!r} (count) is outside the allowed range "
                             f"[1, 10000000]")
        if len(scenes) not in (1, batch_size):
            raise ValueError(f"Simulator got {len(scenes)} scenes for batch_size = {batch_size}: give one scene, "
                             f"or one per gripper")
        self.scene = scene = scenes[0]
        """The batch's first scene; every structural setting (gripper, forces, model, time step) is the same in
        all."""
        self.batch_size = B = int(batch_size)
        self.n_fingers = scene.gripper.n_fingers
        self.scenes = scenes * B if len(scenes) == 1 else scenes
        """Each gripper's scene: they differ at most in the grasped object's size, place, density and velocity,
        and in the water's current (:meth:`set_scene`)."""
        self.disc = disc = scene.discretization()
        R, D, F, N = self.n_rods, disc.dim, self.n_fingers, disc.n_nodes
        self._integrator = INTEGRATORS[scene.integrator]
        self._subsimulators: dict[int, Simulator] = {}
        self._tolerance_inverse = np.where(disc.free, 1.0 / disc.residual_scale, 0.0)
        self._per_step_cache: dict[float, tuple] = {}
        self._clamp_free = np.tile(disc.free, (R, 1))
        self._force_tolerance = disc.residual_scale[0]
        """Newton's tolerance on a force DOF, relative_tolerance·EI/L² [N]."""
        self._structure = _structure(scene)
        self._force_terms = ForceTerms.of(disc, scene.forces, scene.fluid)
        contact = scene.contact
        self._finger_contact = FingerContact.of(disc, contact.finger_contact_stiffness, contact.finger_friction,
                                                first_free_node=0 if scene.gripper.finger.clamp == "free" else 2)
        # 3-D: the frames are the state's (_rod_arrays)
        self._rods = RodArrays.of(disc, self._finger_contact, self._integrator.numerical_retardation)
        self._plain_rods, self._plain_terms = plain(self._rods), plain(self._force_terms)
        self._no_acceleration = np.empty((0, 0, 0))
        directions = disc.finger_directions
        plane_normals = np.stack([-directions[:, 1], directions[:, 0], np.zeros(F)], axis=1)
        if scene.model == "3d":
            projection = np.broadcast_to(np.eye(3), (F, 3, 3))
        else:
            projection = np.stack([directions, np.tile([0.0, 0.0, 1.0], (F, 1))], axis=1)
        self._projection = np.ascontiguousarray(np.tile(projection, (B, 1, 1)))  # rod coordinates from world, (R, D, 3)
        obj = scene.grasped_object
        self._has_object = obj is not None
        self._body = None
        if obj is not None and obj.free:
            self._body = BodyModel(BodyLoads.total(scene.forces, scene.fluid), B, scene.contact)
            any_motion = np.tile(np.eye(6), (B, 1, 1)) if scene.model == "3d" else np.empty((0, 6, 6))
        else:  # rods on their own or against a fixed object: no body moves, and none is held to
            any_motion = np.empty((0, 6, 6))
        self.finger_contact_radius = disc.node_radius.copy() if scene.contact.finger_thickness else np.zeros(N)
        """The finger's radius at each node that contact adds to the object's [m], (N,): the radius profile, or
        zeros for contact on the centre lines (``ContactSettings.finger_thickness``)."""
        self._geometry = ContactGeometry(np.zeros((R, D)), np.zeros((R, D)), np.zeros((R, N)),
                                         self.finger_contact_radius, np.full(R, np.inf),
                                         directions, plane_normals, any_motion)
        # the current moves what feels it: the rods' drag, and a free body's drag and the water's inertia on it
        body_loads = None if self._body is None else self._body.loads
        moving_water = self._force_terms.drag_normal.size > 0 or (body_loads is not None and (
            body_loads.sphere_drag > 0 or body_loads.froude_krylov > 0 or body_loads.sphere_added_mass > 0))
        self._currents = CurrentBatch(B) if moving_water else None
        self._kernel_currents = tuple((self._currents or CurrentBatch(B)).arrays)
        """The currents as the compiled steps take them: still water's zeros where the water moves nothing."""
        self._water_cache: tuple[float, tuple[np.ndarray, np.ndarray] | None] = (math.nan, None)
        if not moving_water:
            still = np.zeros((B, 3))
            self._water_cache = (math.inf, (still, rod_water_velocity(disc, still)))  # for all time
        self._plain_geometry = plain(self._geometry)  # the same arrays: _load and the kernels write into them
        for index, each in enumerate(self.scenes):
            if each is not scene and _structure(each) != self._structure:
                raise ValueError(f"Simulator.scene[{index}] differs from scene[0] in more than the grasped object's "
                                 f"size, place, density and velocity and the water's current")
            self._load(index, each)
        self._gpu: GpuRods | GpuGrasp | None = None
        if device == "cuda":
            if scene.integrator != "backward_euler":
                raise GpuUnsupported(f"Simulator(device='cuda'): the integrator {scene.integrator!r} does not run "
                                     f"on the GPU yet; backward_euler does")
            self._gpu = (GpuGrasp if self._has_object else GpuRods)(*self.gpu_constants())
        self._on_device: RodState | None = None
        """The state whose values the GPU holds: the last one :meth:`advance` or
        :meth:`put_grippers` returned, whose arrays are read-only so that it cannot change on the host alone."""

    def set_scene(self, index: int, scene: Scene, start_time: float = 0.0) -> None:
        """Gives gripper ``index`` another scene, which may differ from the batch's only in the grasped object's
        size, place, density, velocity and friction, and in the current (e.g. a new episode of one environment of a
        vector). The new scene applies to states made by :meth:`initial_state` from now on; a free object's size,
        density and friction, a fixed object's place, size and friction, and the current also apply from the next
        step of a running state. Its current runs on its own clock, which reads 0 at the batch's time
        ``start_time`` [s]."""
        if not 0 <= index < self.batch_size:
            raise ValueError(f"index = {index} is outside the allowed range [0, {self.batch_size - 1}]")
        if _structure(scene) != self._structure:
            raise ValueError("Simulator.set_scene: the scene differs from the batch's in more than the grasped "
                             "object's size, place, density and velocity and the water's current")
        self.scenes[index] = scene
        self._load(index, scene)
        if self._currents is not None:
            self._currents.set_clock(index, start_time)
            self._water_cache = (math.nan, None)

    def _load(self, index: int, scene: Scene) -> None:
        """Writes gripper ``index``'s object and current into the per-gripper arrays (the scene already checked)."""
        if self._currents is not None:
            self._currents.load(index, scene.fluid.current)
        obj = scene.grasped_object
        if self._body is not None:
            self._body.load(index, obj)
        elif obj is not None:
            rods = slice(index * self.n_fingers, (index + 1) * self.n_fingers)
            geometry = self._geometry
            geometry.starts[rods], geometry.ends[rods], geometry.radii[rods] = object_in_rod_frames(
                obj, self.disc.finger_directions, self.finger_contact_radius, scene.model == "planar")
        if obj is not None:
            self._geometry.friction[index * self.n_fingers:(index + 1) * self.n_fingers] = obj.friction

    @property
    def n_rods(self) -> int:
        """Rods in the batch, B·F."""
        return self.batch_size * self.n_fingers

    def initial_state(self) -> RodState:
        """All fingers straight and at rest at t = 0."""
        disc = self.disc
        q = np.broadcast_to(disc.rest_q, (self.batch_size,) + disc.rest_q.shape).copy()
        state = RodState(q=q, velocity=np.zeros_like(q), time=0.0)
        if disc.model == "3d":
            n_edges = disc.n_nodes - 1
            tangent = np.broadcast_to(disc.finger_directions[None, :, None, :],
                                      (self.batch_size, self.n_fingers, n_edges, 3)).copy()
            director = np.zeros_like(tangent)
            director[..., 2] = 1.0  # m1 = +z, so κ1 < 0 bends toward −z
            state = evolve(state, tangent=tangent, director=director, reference_twist=np.zeros(q.shape[:3]))
        if self._body is not None:
            B, objects = self.batch_size, [s.grasped_object for s in self.scenes]
            centers = np.array([0.5 * (obj.segment[0] + obj.segment[1]) for obj in objects])
            state = evolve(state, held=np.zeros(q.shape[:3], dtype=bool), hold_offset=np.zeros(q.shape[:3] + (3,)),
                           body_position=centers, body_velocity=np.array([obj.velocity for obj in objects]),
                           body_orientation=np.tile(np.eye(3), (B, 1, 1)), body_angular_velocity=np.zeros((B, 3)))
        return state

    def world_positions(self, state: RodState) -> np.ndarray:
        """Node positions in the world frame [m], (B, F, N, 3)."""
        return self.disc.world_positions(state.q)

    def mechanical_energy(self, state: RodState, natural_curvature) -> np.ndarray:
        """Kinetic + elastic + gravitational and buoyant potential energy of each gripper [J], (B,).

        The kinetic energy is that of the rods' own lumped masses (and twist inertia); water carried as added mass
        is not counted.
        """
        disc = self.disc
        R, N, S, D = self.n_rods, disc.n_nodes, disc.stride, disc.dim
        q = np.ascontiguousarray(state.q.reshape(R, N, S))
        per_rod = self._natural_curvature(natural_curvature)
        force = np.zeros((R, N, S))
        band = np.zeros((R, N * S, disc.band_width + 1))
        if disc.model == "3d":
            energy = rod3d_elastic(q, *self._frames(state), disc.rest_edge_length, disc.stretch_stiffness,
                                   disc.bend_stiffness, disc.twist_stiffness, disc.voronoi_length, per_rod, force,
                                   band, False)
        else:
            energy = planar_elastic(q, disc.rest_edge_length, disc.stretch_stiffness, disc.bend_stiffness,
                                    disc.voronoi_length, per_rod, force, band, False)
        velocity = state.velocity.reshape(R, -1)
        energy = energy + 0.5 * (velocity**2) @ disc.dof_mass
        for model in self.scene.forces:
            potential = model.potential_energy(disc, q[..., :D], self.scene.fluid)
            if potential is not None:
                energy = energy + potential
        return energy.reshape(self.batch_size, self.n_fingers).sum(axis=1)

    def _natural_curvature(self, natural_curvature) -> np.ndarray:
        """κ̄ per rod (R,), from a scalar, (F,) or (B, F), checked."""
        if isinstance(natural_curvature, (float, int)) and abs(natural_curvature) <= NATURAL_CURVATURE_LIMIT:
            per_rod = np.empty(self.n_rods)  # the common scalar case, fast (np.full costs five times as much)
            per_rod.fill(natural_curvature)
            return per_rod
        value = np.asarray(natural_curvature, dtype=float)
        if value.shape != (self.batch_size, self.n_fingers):
            try:
                value = np.broadcast_to(value, (self.batch_size, self.n_fingers))
            except ValueError:
                raise ValueError(f"natural_curvature has shape {value.shape}; expected a scalar, (F,) = "
                                 f"({self.n_fingers},) or (B, F) = ({self.batch_size}, {self.n_fingers})") from None
        if np.abs(value).max() <= NATURAL_CURVATURE_LIMIT:  # False for NaN too
            return np.ascontiguousarray(value).reshape(-1)
        if not np.all(np.isfinite(value)):
            raise ValueError("natural_curvature (dimensionless) must be finite")
        raise ValueError(f"natural_curvature = {value.flat[np.abs(value).argmax()]:g} (dimensionless) is outside "
                         f"the allowed range [−{NATURAL_CURVATURE_LIMIT:g}, {NATURAL_CURVATURE_LIMIT:g}]: "
                         f"κ = 2·tan(φ/2) is singular at a turning angle φ = 180°")

    def step(self, state: RodState, natural_curvature) -> StepResult:
        """Advance ``state`` by one time step Δt with natural curvature κ̄ (dimensionless) per gripper and finger.

        ``natural_curvature`` is a scalar, (F,) or (B, F). It is held constant over the step.
        """
        return self._step_adaptive(state, self._natural_curvature(natural_curvature), self.scene.time_step,
                                   self.scene.newton.max_step_halvings)

    def advance(self, state: RodState, natural_curvature, curvature_rate, n_steps: int,
                curvature_range: tuple[float, float] = (-NATURAL_CURVATURE_LIMIT, NATURAL_CURVATURE_LIMIT),
                running: np.ndarray | None = None, clock: np.ndarray | None = None) -> Advance:
        """``n_steps`` steps of Δt from ``state``, as many calls of :meth:`step` would take them, with κ̄ (a scalar,
        (F,) or (B, F), dimensionless) held through each step and then ramped by ``curvature_rate`` [1/s] (the same
        shapes) within ``curvature_range``. Only the grippers ``running`` (B,) bool (default all) step; one whose
        step fails (after halving) stops there, keeps its last good state and is reported ``failed``. Each running
        gripper's ``clock`` (B,) [s] (default zeros) advances by Δt per step it takes. The steps stop early once
        no gripper runs; the batch's time is that of the last step taken.

        With an object, the steps run in one compiled call (:func:`~.solvers.stepping.take_steps`), leaving it only
        for a step that a gripper of a batch of several needs halved (a batch of one halves it in the call), so a
        control interval costs one call instead of one per step."""
        B, F, R = self.batch_size, self.n_fingers, self.n_rods
        if not isinstance(n_steps, (int, np.integer)) or not 1 <= n_steps <= 1_000_000:
            raise ValueError(f"Simulator.advance: n_steps = {n_steps!r} (count) is outside the allowed range "
                             f"[1, 1000000]")
        low, high = (float(x) for x in curvature_range)
        if not -NATURAL_CURVATURE_LIMIT <= low <= high <= NATURAL_CURVATURE_LIMIT:
            raise ValueError(f"Simulator.advance: curvature_range = ({low:g}, {high:g}) (dimensionless) must be "
                             f"ordered and within [−{NATURAL_CURVATURE_LIMIT:g}, {NATURAL_CURVATURE_LIMIT:g}]")
        rate = _copy_as(curvature_rate, (B, F), float).reshape(R)
        if not np.isfinite(rate).all():
            raise ValueError("Simulator.advance: curvature_rate [1/s] must be finite")
        running = np.ones(B, dtype=bool) if running is None else _copy_as(running, (B,), bool)
        clock = np.zeros(B) if clock is None else _copy_as(clock, (B,), float)
        interval = Interval(self._natural_curvature(natural_curvature).copy(), rate, low, high, running,
                            np.zeros(B, dtype=bool), clock, np.zeros(B, dtype=np.int64),
                            np.zeros((R, self.disc.n_nodes)), np.zeros((R, self.disc.n_nodes, 3)),
                            np.zeros(B, dtype=bool), self.scene.newton.max_step_halvings > 0)
        dt = self.scene.time_step
        times = [state.time]
        for _ in range(n_steps):
            times.append(times[-1] + dt)  # the clock of successive steps, to the bit
        if self._gpu is not None:
            return self._advance_record(self._advance_on_gpu(state, interval, times, n_steps), interval)
        work = self._working_state(state, copy=True)
        k = 0
        if self._has_object:
            step_times = np.array(times)
            rods = self._plain_rods if work.tangent.size == 0 else \
                self._plain_rods[:N_DESIGN_FIELDS] + (work.tangent, work.director, work.reference_twist)
            body = None if self._body is None else self._body.plain_arrays
        while k < n_steps and interval.running.any():
            if not self._has_object:
                self._adaptive_step(work, times[k], dt, interval)
                k += 1
                continue
            k = take_steps(k, n_steps, dt, step_times, self._kernel_currents, work, rods, self._plain_terms,
                           self._halving_levels(dt), self._plain_geometry, self._projection, body, interval)
            if interval.pending.any():  # the others took step k; it is halved for the grippers left pending
                self._halve_pending(work, interval, k, dt, step_times, body, np.nonzero(interval.pending)[0])
                k += 1
            elif k < n_steps and interval.running.any():
                raise RuntimeError(f"take_steps stopped at step {k} of {n_steps} with grippers running and none "
                                   f"pending")
        return self._advance_record(self._state_of(work, times[k]), interval)

    def _advance_record(self, state: RodState, interval: Interval) -> Advance:
        """What :meth:`advance` returns: ``state`` and ``interval``'s results, shaped per gripper."""
        B, F, N = self.batch_size, self.n_fingers, self.disc.n_nodes
        return record(Advance, state=state, natural_curvature=interval.natural_curvature.reshape(B, F),
                      clock=interval.clock, failed=interval.failed, newton_iterations=interval.newton_iterations,
                      normal_impulse=interval.normal_impulse.reshape(B, F, N),
                      impulse=interval.impulse.reshape(B, F, N, 3))

    def gpu_constants(self) -> tuple:
        """The first arguments of this batch's GPU stepper (:class:`~.solvers.gpu.GpuRods` for rods on their own,
        :class:`~.solvers.gpu.GpuGrasp` with an object): its constants and kernel shape."""
        disc = self.disc
        finger_contact = self._finger_contact.stiffness > 0.0
        solver = self._per_step(self.scene.time_step)
        if self._has_object:
            shape = GraspKernelShape(self.n_fingers, disc.n_nodes, disc.stride, disc.dim, finger_contact,
                                     self._body is not None)
            return (self._plain_rods, self._plain_terms, self._halving_levels(self.scene.time_step), self._projection,
                    shape)
        shape = RodsKernelShape(self.n_fingers, disc.n_nodes, disc.stride, disc.dim, finger_contact)
        return self._plain_rods, self._plain_terms, solver, disc.finger_directions, shape

    def _advance_on_gpu(self, state: RodState, interval: Interval, times: list[float], n_steps: int) -> RodState:
        """:meth:`advance`'s steps on the GPU from ``state``, updating ``interval``; the state after them. The state
        stays on the device: it is uploaded only if it is not the one the device holds, and the state returned is
        the device's new one, copied back (read-only). With an object (:class:`~.solvers.gpu.GpuGrasp`), a step that
        a gripper does not settle is halved in its thread, as :meth:`advance` halves it; rods on their own
        (:class:`~.solvers.gpu.GpuRods`) do not halve a failed step (the gripper stops there)."""
        dt = self.scene.time_step
        if state is not self._on_device:
            self._gpu.load(tuple(self._working_state(state, copy=False)))
        if isinstance(self._gpu, GpuGrasp):
            body = None if self._body is None else self._body.plain_arrays
            stops, arrays = self._gpu.advance(self._plain_geometry, body, tuple(interval), np.array(times),
                                              self._kernel_currents, dt, n_steps)
            taken = int(stops.max())  # the step where each gripper stopped: the batch's time is the last's
        else:
            clock_before = interval.clock.copy()
            arrays = self._gpu.advance(np.array(times), self._kernel_currents, interval.natural_curvature,
                                       interval.curvature_rate, (interval.curvature_low, interval.curvature_high),
                                       interval.running, interval.failed, interval.clock,
                                       interval.newton_iterations, dt, n_steps)
            taken = int(np.rint((interval.clock - clock_before) / dt).max())
        self._on_device = self._state_of(WorkingState(*(_read_only(array) for array in arrays)), times[taken])
        return self._on_device

    def put_grippers(self, state: RodState, indices, part: RodState) -> RodState:
        """A copy of ``state`` whose grippers ``indices`` (k,) are ``part``'s (a state of k grippers, e.g. new
        episodes' ``take_grippers(sim.initial_state(), indices)``); an acceleration that ``part`` lacks and
        ``state`` has is zero (Newton then starts from the predictor, as a fresh state's does). Where the GPU holds
        ``state``, only those grippers' rows are uploaded into it, and the GPU holds the copy."""
        indices = np.asarray(indices, dtype=np.int64).reshape(-1)
        if indices.size and (indices.min() < 0 or indices.max() >= self.batch_size):
            raise ValueError(f"Simulator.put_grippers: indices {indices.min()}..{indices.max()} are outside the "
                             f"allowed range [0, {self.batch_size - 1}]")
        if part.q.shape != (indices.size,) + state.q.shape[1:]:
            raise ValueError(f"Simulator.put_grippers: part has q of shape {part.q.shape}; expected "
                             f"{(indices.size,) + state.q.shape[1:]} for {indices.size} grippers")
        if state.acceleration is not None and part.acceleration is None:
            part = evolve(part, acceleration=np.zeros_like(part.q))
        for name, value in vars(state).items():
            if isinstance(value, np.ndarray) and getattr(part, name) is None:
                raise ValueError(f"Simulator.put_grippers: part has no {name}, which the state has")
        merged = put_grippers(state, indices, part)
        if state is self._on_device:
            rods = (indices[:, None] * self.n_fingers + np.arange(self.n_fingers)).reshape(-1)
            rows = tuple(rods if field < N_ROD_STATE_FIELDS else indices for field in range(len(WorkingState._fields)))
            self._gpu.put(rows, tuple(self._working_state(part, copy=False)))
            for value in vars(merged).values():
                if isinstance(value, np.ndarray):
                    _read_only(value)  # put_grippers made new arrays
            self._on_device = merged
        return merged

    def _adaptive_step(self, work: WorkingState, time: float, dt: float, interval: Interval) -> None:
        """One step of :meth:`advance` on the adaptive path (:meth:`step`'s), committed into ``work`` and
        ``interval`` as the compiled steps commit theirs."""
        result = self._step_adaptive(self._state_of(work, time), interval.natural_curvature, dt,
                                     self.scene.newton.max_step_halvings)
        self._commit(np.arange(self.batch_size), result.converged & finite(result.state), result.newton_iterations,
                     result, dt, work, interval)

    def _halve_pending(self, work: WorkingState, interval: Interval, k: int, dt: float, step_times: np.ndarray,
                       body: tuple | None, grippers: np.ndarray) -> None:
        """Step ``k`` of :meth:`advance` (of ``dt`` [s], from the batch time ``step_times[k]``) for ``grippers``,
        which the compiled steps left pending: each takes it in halves as a batch of one, through the same compiled
        steps on views of its rows of ``work`` and ``interval``, which it updates."""
        F = self.n_fingers
        solvers = tuple(for_one_gripper(solver, F) for solver in self._halving_levels(dt))
        projection = self._projection[:F]
        counts = (F if work.hold_offset.shape[0] else 0, F if work.tangent.shape[0] else 0,
                  1 if work.body_position.shape[0] else 0, 1 if self._geometry.any_motion.shape[0] else 0)
        for b in grippers:
            state, geometry, own, currents = gripper_views(b, F, *counts, work, self._plain_geometry, interval,
                                                           self._kernel_currents)
            rod_arrays = self._plain_rods if state.tangent.size == 0 else \
                self._plain_rods[:N_DESIGN_FIELDS] + (state.tangent, state.director, state.reference_twist)
            take_steps(k, k + 1, dt, step_times, currents, state, rod_arrays, self._plain_terms, solvers, geometry,
                       projection, None if body is None else gripper_body(body, b), own)

    def _commit(self, grippers: np.ndarray, ok: np.ndarray, iterations: np.ndarray, result: StepResult, dt: float,
                work: WorkingState, interval: Interval) -> None:
        """Commits ``result``, a step of this simulator's grippers, into the grippers ``grippers`` of an advancing
        batch's ``work`` and ``interval`` through :func:`~.solvers.stepping.commit_step`; its contact reactions are
        the step's last (a halved step's second half's)."""
        R, N = self.n_rods, self.disc.n_nodes
        contact = result.contact
        normal = np.zeros((R, N)) if contact is None else contact.normal_reaction.reshape(R, N)
        reaction = np.zeros((R, N, 3)) if contact is None else contact.reaction.reshape(R, N, 3)
        commit_step(dt, grippers, ok, self._working_state(result.state, copy=False), iterations, normal, reaction,
                    work, interval)

    def _working_state(self, state: RodState, copy: bool) -> WorkingState:
        """``state``'s arrays flattened per rod for the compiled steps (:class:`~.solvers.stepping.WorkingState`):
        copies that they may update, or views of the same arrays; fields the state lacks are zeros (an
        acceleration, which starts Newton at the predictor, and the holds) or empty."""
        N, S = self.disc.n_nodes, self.disc.stride
        R = state.q.shape[0] * state.q.shape[1]  # the batch's rods, or a part's (put_grippers)

        def flat(array, shape, empty_shape, dtype=float):
            if array is None:
                return np.zeros(shape if empty_shape is None else empty_shape, dtype=dtype)
            array = array.reshape(shape)
            return np.array(array) if copy else np.ascontiguousarray(array)

        return WorkingState(
            flat(state.q, (R, N, S), None), flat(state.velocity, (R, N, S), None),
            flat(state.acceleration, (R, N, S), None), flat(state.held, (R, N), None, bool),
            flat(state.hold_offset, (R, N, 3), (0, 0, 3)), flat(state.tangent, (R, N - 1, 3), (0, 0, 3)),
            flat(state.director, (R, N - 1, 3), (0, 0, 3)), flat(state.reference_twist, (R, N), (0, 0)),
            flat(state.body_position, (-1, 3), (0, 3)), flat(state.body_velocity, (-1, 3), (0, 3)),
            flat(state.body_orientation, (-1, 3, 3), (0, 3, 3)), flat(state.body_angular_velocity, (-1, 3), (0, 3)))

    def _state_of(self, work: WorkingState, time: float) -> RodState:
        """A :class:`~.solvers.records.RodState` at ``time`` [s] over the arrays of ``work`` (views)."""
        B, F, N, S = self.batch_size, self.n_fingers, self.disc.n_nodes, self.disc.stride
        shape = (B, F, N, S)
        state = RodState(q=work.q.reshape(shape), velocity=work.velocity.reshape(shape), time=time,
                         acceleration=work.acceleration.reshape(shape))
        if work.tangent.size:
            state = evolve(state, tangent=work.tangent.reshape(B, F, N - 1, 3),
                           director=work.director.reshape(B, F, N - 1, 3),
                           reference_twist=work.reference_twist.reshape(B, F, N))
        if self._has_object:
            state = evolve(state, held=work.held.reshape(B, F, N))
        if self._body is not None:
            state = evolve(state, hold_offset=work.hold_offset.reshape(B, F, N, 3), body_position=work.body_position,
                           body_velocity=work.body_velocity, body_orientation=work.body_orientation,
                           body_angular_velocity=work.body_angular_velocity)
        return state

    def _step_adaptive(self, state: RodState, natural_curvature: np.ndarray, dt: float, halvings: int) -> StepResult:
        """One step of the scene's integrator; grippers whose Newton solve fails take two half steps instead, each
        of which may be halved again while ``halvings`` allows. Only the failed grippers are re-run."""
        result = self._integrator.advance(self, state, natural_curvature, dt)
        settled = result.converged if result.contact is None else result.converged & result.contact.resolved
        if halvings == 0 or settled.all():
            return result
        failed = np.nonzero(~settled)[0]  # a corrector that spent its budget is retried in halves too
        sub_natural_curvature = natural_curvature.reshape(self.batch_size, -1)[failed].ravel()
        first, second = self._halves(take_grippers(state, failed), failed, sub_natural_curvature, dt, halvings)
        merged = evolve(put_grippers(result.state, failed, second.state), time=result.state.time)
        contact = result.contact
        if contact is not None:
            contact = put_grippers(contact, failed, evolve(
                second.contact, corrector_iterations=first.contact.corrector_iterations
                + second.contact.corrector_iterations))
        return StepResult(state=merged, converged=_set(result.converged, failed, first.converged & second.converged),
                          newton_iterations=_set(result.newton_iterations, failed,
                                                 first.newton_iterations + second.newton_iterations),
                          residual=_set(result.residual, failed, np.maximum(first.residual, second.residual)),
                          contact=contact, substeps=_set(result.substeps, failed, first.substeps + second.substeps))

    def _halves(self, state: RodState, grippers: np.ndarray, natural_curvature: np.ndarray, dt: float,
                halvings: int) -> tuple[StepResult, StepResult]:
        """A step of ``dt`` [s] for this batch's ``grippers`` from ``state`` (theirs alone) with κ̄ per rod, taken
        as two half steps, each of which may be halved again while ``halvings`` − 1 allows: the two halves'
        results."""
        sub = self._subsimulator(grippers)
        first = sub._step_adaptive(state, natural_curvature, 0.5 * dt, halvings - 1)
        second = sub._step_adaptive(first.state, natural_curvature, 0.5 * dt, halvings - 1)
        return first, second

    def _subsimulator(self, grippers: np.ndarray) -> Simulator:
        """A simulator of the scenes of ``grippers`` (indices), kept for reuse by their count."""
        scenes = [self.scenes[i] for i in grippers]
        sub = self._subsimulators.get(len(scenes))
        if sub is None:
            sub = self._subsimulators[len(scenes)] = Simulator(scenes)
        for index, scene in enumerate(scenes):
            if sub.scenes[index] is not scene:
                sub.set_scene(index, scene)
        if self._currents is not None:
            sub._currents.set_clock(slice(None), self._currents.start_time[grippers])
            sub._water_cache = (math.nan, None)
        return sub

    def equilibrium(self, state: RodState, natural_curvature, max_steps: int = 200) -> StepResult:
        """The static equilibrium reached from ``state`` with κ̄ held fixed, by pseudo-transient continuation.

        Implicit steps from rest, each with a step twice as long as the last, until the inertial term itself is
        below the Newton tolerance, which makes the result an equilibrium of the static forces alone. The returned
        state is at rest at the same time as ``state``.
        """
        per_rod = self._natural_curvature(natural_curvature)
        pseudo_step = self.scene.time_step
        zero = np.zeros_like(state.velocity)
        result = None
        for _ in range(max_steps):
            result = self.implicit_step(state, per_rod, pseudo_step, zero)
            if not np.all(result.converged):
                pseudo_step *= 0.25
                continue
            state = evolve(result.state, velocity=zero, time=state.time, acceleration=None)
            static = self.static_residual(state, per_rod)
            if np.all(static <= 1.0):
                return evolve(result, state=state, residual=static)
            pseudo_step = min(2.0 * pseudo_step, 1.0e6)
        assert result is not None
        return evolve(result, converged=np.zeros_like(result.converged))

    def static_residual(self, state: RodState, natural_curvature) -> np.ndarray:
        """Largest force imbalance at rest on a free DOF (not clamped, not held by contact) divided by its Newton
        tolerance, per gripper (B,)."""
        R, N, S = self.n_rods, self.disc.n_nodes, self.disc.stride
        q = state.q.reshape(R, N, S)
        force, _ = self._assemble(q, q, q, self._frames(state), self._natural_curvature(natural_curvature),
                                  state.time, 1.0, hessian=False)
        held = state.held.reshape(R, N) if state.held is not None else np.zeros((R, N), dtype=bool)
        ratio = np.max(np.abs(force.reshape(R, -1)) * self._tolerance_inverse * self._free_mask(held), axis=1)
        return ratio.reshape(self.batch_size, self.n_fingers).max(axis=1)

    def _transported_frames(self, q: np.ndarray, frames: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The 3-D reference frames (tangent, director (R, N − 1, 3), reference twist (R, N)) carried from
        ``frames`` to the coordinates ``q`` (R, N, 4)."""
        R, N = self.n_rods, self.disc.n_nodes
        transported = np.empty((R, N - 1, 3)), np.empty((R, N - 1, 3)), np.empty((R, N))
        rod3d_update_frames(q, *frames, *transported, elastic_scratch(N))
        return transported

    def _frames(self, state: RodState):
        if self.disc.model != "3d":
            return None
        R, N = self.n_rods, self.disc.n_nodes
        return (state.tangent.reshape(R, N - 1, 3), state.director.reshape(R, N - 1, 3),
                state.reference_twist.reshape(R, N))

    def _assemble(self, q, q_old, q_pred, frames_old, natural_curvature, time, dt, hessian=True):
        """Total force [N] on every DOF (R, N, S) and the band of −∂f/∂q (R, n, kd+1) at coordinates q, for a
        backward-Euler step of length ``dt`` from ``q_old`` with predictor ``q_pred`` = q_old + Δt·v_old."""
        disc = self.disc
        R = q.shape[0]
        force = np.empty(q.shape)
        band = np.empty((R, disc.n_dofs, disc.band_width + 1))
        step = StepInputs(q_old, q_pred, natural_curvature, self._water(time)[1], dt, self._near_buffer())
        find_near_fingers(q_old, q_pred, self._finger_contact, step.near,
                          finger_scratch(self.n_fingers if step.near.size else 0, disc.n_nodes))
        assemble(q, step, self._rod_arrays(frames_old), self._force_terms, hessian, force, band)
        return force, band

    def _near_buffer(self) -> np.ndarray:
        """A new array for the fingers near each other in a step (:attr:`StepInputs.near`), empty without finger
        contact."""
        shape = (self.n_rods, self.disc.n_nodes, self.n_fingers) if self._finger_contact.stiffness > 0 else (0, 0, 0)
        return np.empty(shape, dtype=np.int64)

    def _rod_arrays(self, frames) -> RodArrays:
        """The rods' constants with the 3-D frames of a state (:meth:`_frames`), as the kernels take them."""
        return self._rods if frames is None else self._rods._replace(tangent=frames[0], director=frames[1],
                                                                     reference_twist=frames[2])

    def _water(self, time: float) -> tuple[np.ndarray, np.ndarray]:
        """The current at ``time`` at every gripper (B, 3) and as every rod sees it (R, D) [m/s], kept for the solves
        of a step; still water in a scene without drag."""
        if self._currents is not None and self._water_cache[0] != time:
            grippers = self._currents.at(time)
            self._water_cache = (time, (grippers, rod_water_velocity(self.disc, grippers)))
        return self._water_cache[1]

    def _free_mask(self, held: np.ndarray) -> np.ndarray:
        """Free DOFs of every rod, (R, n): the clamp's, less the positions of nodes held by contact."""
        disc = self.disc
        if not held.any():
            return self._clamp_free  # never written to
        free, measured = np.empty_like(self._clamp_free), np.empty_like(self._clamp_free)
        contact_masks(self._clamp_free, held, np.zeros_like(held), disc.dim, free, measured)
        return measured

    def _per_step(self, dt: float) -> tuple:
        """The solvers' settings for steps of ``dt`` (:class:`~.solvers.newton.SolverArrays`, as plain fields for the
        kernels, :func:`~.solvers.newton.plain`): among them the mass
        term M/Δt² of every DOF (n,), and 1/tolerance of every DOF of every rod (R, n). The tolerance is the scene's,
        raised where needed above the roundoff of the inertial term M·(q − q_pred)/Δt², which at tiny steps would
        otherwise make it unreachable."""
        if dt not in self._per_step_cache:
            disc, scene = self.disc, self.scene
            mass_term = disc.dof_mass / dt**2
            roundoff = 64.0 * np.finfo(float).eps * mass_term * scene.gripper.finger.length
            tolerance = np.maximum(disc.residual_scale, roundoff)
            force_tolerance, length = self._force_tolerance, scene.gripper.finger.length
            self._per_step_cache[dt] = plain(SolverArrays(
                mass_term=mass_term, tolerance_inverse=np.tile(np.where(disc.free, 1.0 / tolerance, 0.0),
                                                               (self.n_rods, 1)),
                clamp_free=self._clamp_free,
                body_tolerance=np.repeat([force_tolerance, force_tolerance * length], 3),  # [N], [N·m]
                max_iterations=scene.newton.max_iterations, n_fingers=self.n_fingers,
                max_corrector_iterations=scene.contact.max_corrector_iterations,
                friction_passes=min(scene.contact.max_corrector_iterations,
                                    scene.contact.max_corrector_iterations if scene.contact.friction_passes is None
                                    else scene.contact.friction_passes),
                first_free_node=0 if scene.gripper.finger.clamp == "free" else 2,
                force_tolerance=float(force_tolerance), finger_length=float(length),
                penetration_tolerance=penetration_tolerance(dt)))
        return self._per_step_cache[dt]

    def _halving_levels(self, dt: float) -> tuple:
        """:meth:`_per_step`'s settings for steps of ``dt``, ``dt``/2, … [s], one for each level of halving that the
        scene allows (``NewtonSettings.max_step_halvings``) and one more, as the compiled steps take them."""
        levels, h = [], dt
        for _ in range(self.scene.newton.max_step_halvings + 1):
            levels.append(self._per_step(h))
            h *= 0.5  # as the adaptive path halves: 0.5·dt, 0.5·(0.5·dt), …
        return tuple(levels)

    def implicit_step(self, state: RodState, natural_curvature: np.ndarray, dt: float, velocity_old: np.ndarray,
                      midpoint: bool = False) -> StepResult:
        """A backward-Euler step of ``dt`` [s] from ``state`` with κ̄ per rod (R,) and the old velocity
        ``velocity_old`` (zero for a pseudo-step); with ``midpoint``, the implicit midpoint rule's half step,
        extrapolated to the end of its step of 2·``dt`` (:func:`~.solvers.newton.midpoint_end`). The scene's
        integrator composes its step from these (:mod:`.solvers.integrators`)."""
        disc = self.disc
        R, N, S = self.n_rods, disc.n_nodes, disc.stride
        q_old, v_old = state.q.reshape(R, N, S), velocity_old.reshape(R, N, S)
        extrapolate = state.acceleration is not None and velocity_old is state.velocity  # not for a pseudo-step
        acceleration_old = state.acceleration.reshape(R, N, S) if extrapolate else self._no_acceleration
        q = np.empty((R, N, S))
        velocity, acceleration = np.empty(state.q.shape), np.empty(state.q.shape)
        frames_old = self._frames(state)
        rods = self._plain_rods if frames_old is None else self._plain_rods[:N_DESIGN_FIELDS] + frames_old
        solver = self._per_step(dt)
        water = self._water(state.time)[1]
        held = body = result = None
        end_in_kernel = False
        if not self._has_object:  # rods on their own: the whole step in one kernel
            end_in_kernel = midpoint and frames_old is None  # 3-D frames are carried to the midpoint first
            summary = advance_rods(q_old, v_old, acceleration_old, natural_curvature, water, dt, rods,
                                   self._plain_terms, solver, end_in_kernel, q, velocity.reshape(R, N, S),
                                   acceleration.reshape(R, N, S))
        else:
            step = StepInputs(q_old, np.empty((R, N, S)), natural_curvature, water, dt, self._near_buffer())
            result = SolveResult(np.empty(R, dtype=bool), np.empty(R, dtype=np.int64), np.empty(R),
                                 np.empty((R, disc.n_dofs)), np.zeros(R, dtype=np.int64), np.zeros(R, dtype=bool))
            predict(q_old, v_old, acceleration_old, dt, step.q_pred, q)
            holds, body = self._run_corrector(state, q, step, rods, solver, result)
            held = holds.held
            finish(q, q_old, v_old, dt, velocity.reshape(R, N, S), acceleration.reshape(R, N, S))
            summary = per_gripper(result.converged, result.iterations, result.ratio, self.n_fingers)
        if midpoint and not end_in_kernel:
            if frames_old is not None:
                frames_old = self._transported_frames(q, frames_old)  # to the midpoint, whence to the end
            midpoint_end(q_old, v_old, q, velocity.reshape(R, N, S))
        B, F = self.batch_size, self.n_fingers
        # the mean acceleration over a midpoint step, (v₁ − v₀)/(2·dt), is the half step's own, (v_½ − v₀)/dt
        new_state = evolve(state, q=q.reshape(state.q.shape), velocity=velocity,
                           time=state.time + (2.0 * dt if midpoint else dt), acceleration=acceleration,
                           held=None if held is None else held.reshape(B, F, N))
        if body is not None:
            offsets, position, body_velocity, orientation, angular_velocity = body
            new_state = evolve(new_state, hold_offset=offsets.reshape(B, F, N, 3), body_position=position,
                               body_velocity=body_velocity, body_orientation=orientation,
                               body_angular_velocity=angular_velocity)
        if disc.model == "3d":
            tangent, director, reference_twist = self._transported_frames(q, frames_old)
            shape = state.q.shape[:3]
            new_state = evolve(new_state, tangent=tangent.reshape(shape[:2] + (N - 1, 3)),
                               director=director.reshape(shape[:2] + (N - 1, 3)),
                               reference_twist=reference_twist.reshape(shape))
        contact = None
        if held is not None:
            geometry = self._geometry  # the object as each rod sees it at the solution
            reaction, normal = np.empty((B, F, N, 3)), np.empty((B, F, N))
            contact_reactions(q, result.residual, held, holds.friction, geometry.starts, geometry.ends,
                              disc.finger_directions, reaction.reshape(R, N, 3), normal.reshape(R, N))
            contact = ContactReport(
                held=held.reshape(B, F, N),
                sliding=holds.sliding.reshape(B, F, N),
                reaction=reaction,
                normal_reaction=normal,
                corrector_iterations=result.corrector.reshape(B, F).max(axis=1),
                resolved=~result.changed.reshape(B, F).any(axis=1),
                palm_reaction=None if body is None else self._body.palm_reaction(
                    body[1], state.body_position, body[4] * dt, body[3], state.body_orientation, dt))
        converged, iterations, ratio = summary
        substeps = np.empty(B, dtype=np.int64)
        substeps.fill(1)
        return record(StepResult, state=new_state, converged=converged, newton_iterations=iterations, residual=ratio,
                      contact=contact, substeps=substeps)

    def _run_corrector(self, state, q, step, rods, solver, result):
        """Bundles the holds and the bodies' start for the compiled predictor–corrector
        (:func:`~.solvers.corrector.solve_with_contact`) and runs it from Newton's start ``q`` (R, N, S), which
        receives the solution. With a free body, each solve moves rods and body together
        and a new hold keeps its offset in the body's frame; each re-solve starts from the last solution, so Newton
        starts a few penetration depths from the new one (restarting from the predictor would start a hold far from
        a body that the impact has slowed, a jump the 3-D coupled solve did not always survive). Returns the holds
        (:class:`~.solvers.newton.Holds`: which nodes are held and slide, and their friction) and, with a free body,
        its hold offsets and new state (else None). A node that slid holds where it ended, stuck, at the next
        step's start."""
        R, N, D = self.n_rods, self.disc.n_nodes, self.disc.dim
        held = state.held.reshape(R, N).copy() if state.held is not None else np.zeros((R, N), dtype=bool)
        hold_at = step.q_old[..., :D].copy()  # nodes already held stay where they are, stuck at first
        dt = step.dt
        geometry = self._geometry
        contact = (np.zeros((R, N), dtype=bool), np.zeros((R, N, D)), np.empty_like(self._clamp_free),
                   geometry.starts, geometry.ends, geometry.radii, geometry.finger_radius)  # sliding, friction,
        # measured, and the object
        if self._body is None:
            free_body = None
            holds = Holds(held, np.empty((0, 0, 3)), self._projection, *contact)
        else:
            old = BodyState(*(np.ascontiguousarray(x) for x in (state.body_position, state.body_velocity,
                                                                state.body_orientation,
                                                                state.body_angular_velocity)))
            body = self._body.plain_arrays
            water_acceleration = np.zeros((self.batch_size, 3)) if self._currents is None else \
                self._currents.mean_acceleration(state.time, dt)
            motion = BodyMotion(old.position + dt * old.velocity, dt * old.angular_velocity,
                                np.empty((self.batch_size, 3, 3)), old, self._water(state.time)[0],
                                water_acceleration)  # the predictor
            free_body = (body, (motion.position, motion.rotation, motion.orientation, tuple(old), motion.water,
                                motion.water_acceleration))  # plain(motion), without its generic recursion
            holds = Holds(held, state.hold_offset.reshape(R, N, 3).copy(), self._projection, *contact)
        solve_with_contact(q, tuple(step), rods, self._plain_terms, solver, tuple(holds), hold_at,
                           self._plain_geometry, free_body, tuple(result))
        if self._body is None:
            return holds, None
        c, theta = motion.position, motion.rotation
        return holds, (holds.offsets, c, (c - motion.old.position) / dt, motion.orientation, theta / dt)


def _read_only(array: np.ndarray) -> np.ndarray:
    """``array``, no longer writeable (a state the GPU holds a copy of: an edit on the host alone raises)."""
    array.flags.writeable = False
    return array


def _copy_as(value, shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """A new array of ``shape`` and ``dtype`` from ``value`` broadcast to it (a ValueError if it cannot be); an array
    of that shape already skips ``np.broadcast_to``, whose call costs more than the copy."""
    if isinstance(value, np.ndarray) and value.shape == shape:
        return np.array(value, dtype=dtype)
    return np.array(np.broadcast_to(value, shape), dtype=dtype)


def _structure(scene: Scene) -> tuple:
    """What every gripper of a batch must share: the scene less its object's size, place, density and velocity,
    and less the current."""
    obj = scene.grasped_object
    if obj is not None:
        obj = (type(obj), obj.free)
    return replace(scene, grasped_object=None, fluid=replace(scene.fluid, current=Current())), obj


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A scripted run: world node positions after every step, and the solver's counters."""

    times: np.ndarray
    """t = 0, Δt, 2Δt, … [s], (K + 1,)."""
    positions: np.ndarray
    """World node positions [m], (K + 1, B, F, N, 3); index 0 is the initial state."""
    newton_iterations: np.ndarray
    """(K, B)."""
    converged: np.ndarray
    """(K, B)."""
    final_state: RodState
    contacts: tuple[ContactReport, ...] = ()
    """The contact report of every step, (K,); empty in a scene without an object."""


def run_ramp(scene: Scene, batch_size: int = 1, progress: Callable[[int, int], None] | None = None) -> Trajectory:
    """Run the scene's scripted ramp κ̄(t) = rate·t (t at the start of each step) for its duration. The ramp
    saturates at ±:data:`NATURAL_CURVATURE_LIMIT`, as a pneumatic finger saturates at its maximum pressure."""
    sim = Simulator(scene, batch_size)
    state = sim.initial_state()
    n_steps = scene.n_steps
    coordinates = [state.q]  # the states' own arrays, which no step writes into; positions from all at the end
    iterations, converged, contacts = [], [], []
    for k in range(n_steps):
        natural_curvature = min(max(scene.natural_curvature_rate * state.time, -NATURAL_CURVATURE_LIMIT),
                                NATURAL_CURVATURE_LIMIT)
        result = sim.step(state, natural_curvature)
        state = result.state
        coordinates.append(state.q)
        iterations.append(result.newton_iterations)
        converged.append(result.converged)
        if result.contact is not None:
            contacts.append(result.contact)
        if progress is not None:
            progress(k + 1, n_steps)
    return Trajectory(times=np.arange(n_steps + 1) * scene.time_step,
                      positions=sim.disc.world_positions(np.stack(coordinates)),
                      newton_iterations=np.stack(iterations), converged=np.stack(converged), final_state=state,
                      contacts=tuple(contacts))
