"""Batched implicit time stepping of the gripper's fingers.

Every state array carries a leading batch axis B (grippers) and a finger axis F. Internally the B·F rods are
flattened to one rod axis R. The whole Newton loop runs in compiled kernels (:mod:`.assembly` for rods on their own
or against a fixed object, :func:`.rigid_body.coupled_newton` for rods and a free body); this module sets up the
step, runs the contact corrector around the solves and halves steps that fail. Each rod (or gripper, with a free
body) stops iterating as soon as it has converged, so its result does not depend on what else shares its batch.

Backward Euler, on the free DOFs q (physics.md §1):

    M·(q − q_old − Δt·v_old)/Δt² − f(q, (q − q_old)/Δt) = 0,

solved by Newton's method started from the predictor q_old + Δt·v_old plus the last step's motion, Δt²·a_old.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from .assembly import advance_rods, assemble, finish, midpoint_end, newton_solve, per_gripper, predict
from .config import Scene
from .contact import (
    ContactReport,
    contact_changes,
    corrector_continues,
    normal_reactions,
    object_in_rod_frames,
    reachable,
    release_held,
    update_holds,
)
from .discretization import Discretization
from .forces import ForceTerms
from .hydrodynamics import Current, CurrentBatch, MorisonDrag, rod_water_velocity
from .integrators import INTEGRATORS, evolve, record
from .rigid_body import BodyModel, solve_with_body
from .rod_3d import rod3d_elastic, rod3d_update_frames
from .rod_planar import planar_elastic

NATURAL_CURVATURE_LIMIT = 2.0
"""Largest |κ̄| a step accepts (dimensionless): a natural turning angle of 90° per node, 2·atan(κ̄/2). The integrated
curvature κ = 2·tan(φ/2) is singular at φ = 180°, and a finger already curls 18 × 90° = 1620° at this limit. The
same clip as dismech-rl's."""


@dataclass(frozen=True, eq=False)
class RodState:
    """The state of B grippers at one instant.

    ``q`` and ``velocity`` are (B, F, N, S) in the layout of :class:`~.discretization.Discretization`
    ([m] and [m/s]; twist angles [rad] and [rad/s]). The 3-D model also carries the reference frame of every edge,
    which is part of the state because it is transported in time: ``tangent`` and ``director`` (B, F, N − 1, 3),
    ``reference_twist`` (B, F, N) [rad]. They are None in the planar model.
    """

    q: np.ndarray
    velocity: np.ndarray
    time: float
    """Simulated time [s]."""
    acceleration: np.ndarray | None = None
    """Mean acceleration over the last step, (v − v_old)/Δt, (B, F, N, S) [m/s²]; None before the first step.
    It only improves Newton's starting guess."""
    tangent: np.ndarray | None = None
    director: np.ndarray | None = None
    reference_twist: np.ndarray | None = None
    held: np.ndarray | None = None
    """Nodes held on the grasped object's surface, (B, F, N) bool; None in a scene without an object."""
    hold_offset: np.ndarray | None = None
    """For a free object: each held node's offset from the object's centre in the object's frame [m], (B, F, N, 3)."""
    body_position: np.ndarray | None = None
    """Centre of a free object [m], (B, 3); None unless the scene's object is free."""
    body_velocity: np.ndarray | None = None
    """Its velocity [m/s], (B, 3)."""
    body_orientation: np.ndarray | None = None
    """Its orientation, body to world, (B, 3, 3)."""
    body_angular_velocity: np.ndarray | None = None
    """Its angular velocity [rad/s], (B, 3)."""


@dataclass(frozen=True, eq=False)
class StepResult:
    """What one implicit step returns. Per-gripper arrays have shape (B,)."""

    state: RodState
    converged: np.ndarray
    """Whether Newton's method met its tolerance on every finger of the gripper."""
    newton_iterations: np.ndarray
    """Linear solves (Newton iterations) the slowest finger needed."""
    residual: np.ndarray
    """Final residual: the largest free-DOF residual divided by its tolerance (≤ 1 when converged; dimensionless)."""
    substeps: np.ndarray
    """Substeps the step took, (B,): 1 unless Newton failed or the contact corrector spent its budget, and the step
    was halved (adaptive substepping)."""
    contact: ContactReport | None = None
    """Contact reactions of the step; None in a scene without an object."""


class Simulator:
    """Steps a batch of identical grippers of one :class:`~.config.Scene` in time.

    >>> sim = Simulator(paper_scene())
    >>> state = sim.initial_state()
    >>> result = sim.step(state, natural_curvature=-0.15 * state.time)
    """

    def __init__(self, scene: Scene | Sequence[Scene], batch_size: int | None = None) -> None:
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
        self.disc = Discretization.from_scene(scene)
        self._integrator = INTEGRATORS[scene.integrator]
        self._subsimulators: dict[int, Simulator] = {}
        self._tolerance_inverse = np.where(self.disc.free, 1.0 / self.disc.residual_scale, 0.0)
        self._per_step_cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._clamp_free = np.tile(self.disc.free, (self.n_rods, 1))
        self._all_rods = np.ones(self.n_rods, dtype=bool)
        self._no_shift = np.zeros((self.n_rods, self.disc.dim))
        self._first_free_node = 0 if scene.gripper.finger.clamp == "free" else 2
        self._force_tolerance = self.disc.residual_scale[0]
        """Newton's tolerance on a force DOF, relative_tolerance·EI/L² [N]."""
        self._structure = _structure(scene)
        disc = self.disc
        self._force_terms = ForceTerms.of(disc, scene.forces).arrays()
        self._elastic = (disc.rest_edge_length, disc.stretch_stiffness, disc.bend_stiffness, disc.twist_stiffness,
                         disc.voronoi_length)
        self._no_frames = (np.empty((0, 0, 3)), np.empty((0, 0, 3)), np.empty((0, 0)))  # planar: none
        self._no_acceleration = np.empty((0, 0, 0))
        drag = [f for f in scene.forces if isinstance(f, MorisonDrag)]
        self._currents = CurrentBatch(B) if drag else None
        self._water_cache: tuple[float, tuple[np.ndarray, np.ndarray] | None] = (math.nan, None)
        if not drag:
            still = np.zeros((B, 3))
            self._water_cache = (math.inf, (still, rod_water_velocity(self.disc, still)))  # for all time
        self._object = None
        self._body = None
        obj = scene.grasped_object
        if obj is not None and obj.free:
            self._body = BodyModel(scene.forces, B, scene.contact.palm_stiffness, scene.contact.palm_radius)
            directions = self.disc.finger_directions
            self._plane_normals = np.stack([-directions[:, 1], directions[:, 0], np.zeros(len(directions))], axis=1)
            """Normal of each finger's vertical plane (F, 3)."""
            if scene.model == "3d":
                projection = np.broadcast_to(np.eye(3), (len(directions), 3, 3))
            else:
                projection = np.stack([directions, np.tile([0.0, 0.0, 1.0], (len(directions), 1))], axis=1)
            self._projection = np.tile(projection, (B, 1, 1))  # rod coordinates from world, (R, D, 3)
            force_tolerance = self._force_tolerance
            length = scene.gripper.finger.length
            self._body_tolerance = np.repeat([force_tolerance, force_tolerance * length], 3)  # [N], [N·m]
            self._any_motion = np.tile(np.eye(6), (B, 1, 1)) if scene.model == "3d" else np.empty((0, 6, 6))
        elif obj is not None:
            R, D = self.n_rods, self.disc.dim
            self._object = (np.zeros((R, D)), np.zeros((R, D)), np.zeros(R), np.zeros(R, dtype=bool))
        for index, each in enumerate(self.scenes):
            if each is not scene and _structure(each) != self._structure:
                raise ValueError(f"Simulator.scene[{index}] differs from scene[0] in more than the grasped object's "
                                 f"size, place, density and velocity and the water's current")
            self._load(index, each)

    def set_scene(self, index: int, scene: Scene, start_time: float = 0.0) -> None:
        """Gives gripper ``index`` another scene, which may differ from the batch's only in the grasped object's
        size, place, density and velocity, and in the current (e.g. a new episode of one environment of a vector).
        The new scene applies to states made by :meth:`initial_state` from now on. Its current runs on its own
        clock, which reads 0 at the batch's time ``start_time`` [s]."""
        if not 0 <= index < self.batch_size:
            raise ValueError(f"index = {index} is outside the allowed range [0, {self.batch_size - 1}]")
        if _structure(scene) != self._structure:
            raise ValueError("Simulator.set_scene: the scene differs from the batch's in more than the grasped "
                             "object's size, place, density and velocity and the water's current")
        self.scenes[index] = scene
        self._load(index, scene)
        if self._currents is not None:
            self._currents.start_time[index] = start_time
            self._water_cache = (math.nan, None)

    def _load(self, index: int, scene: Scene) -> None:
        """Writes gripper ``index``'s object and current into the per-gripper arrays (the scene already checked)."""
        if self._currents is not None:
            self._currents.load(index, next(f for f in scene.forces if isinstance(f, MorisonDrag)).current)
        obj = scene.grasped_object
        if self._body is not None:
            self._body.load(index, obj)
        elif self._object is not None:
            F = self.n_fingers
            planar = scene.model == "planar"
            rods = slice(index * F, (index + 1) * F)
            starts, ends, radii = object_in_rod_frames(obj, self.disc.finger_directions, planar)
            self._object[0][rods], self._object[1][rods], self._object[2][rods] = starts, ends, radii
            self._object[3][rods] = reachable(obj, self.disc.finger_directions, scene.gripper.finger.length, planar)

    @property
    def n_rods(self) -> int:
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
        kbar = self._natural_curvature(natural_curvature)
        force = np.zeros((R, N, S))
        band = np.zeros((R, N * S, disc.band_width + 1))
        if disc.model == "3d":
            energy = rod3d_elastic(q, *self._frames(state), disc.rest_edge_length, disc.stretch_stiffness,
                                   disc.bend_stiffness, disc.twist_stiffness, disc.voronoi_length, kbar, force, band,
                                   False)
        else:
            energy = planar_elastic(q, disc.rest_edge_length, disc.stretch_stiffness, disc.bend_stiffness,
                                    disc.voronoi_length, kbar, force, band, False)
        velocity = state.velocity.reshape(R, -1)
        energy = energy + 0.5 * (velocity**2) @ disc.dof_mass
        for model in self.scene.forces:
            potential = model.potential_energy(disc, q[..., :D])
            if potential is not None:
                energy = energy + potential
        return energy.reshape(self.batch_size, self.n_fingers).sum(axis=1)

    def _natural_curvature(self, natural_curvature) -> np.ndarray:
        """κ̄ per rod (R,), from a scalar, (F,) or (B, F), checked."""
        if isinstance(natural_curvature, (float, int)) and abs(natural_curvature) <= NATURAL_CURVATURE_LIMIT:
            return np.full(self.n_rods, float(natural_curvature))  # the common scalar case, fast
        kbar = np.asarray(natural_curvature, dtype=float)
        if kbar.shape != (self.batch_size, self.n_fingers):
            try:
                kbar = np.broadcast_to(kbar, (self.batch_size, self.n_fingers))
            except ValueError:
                raise ValueError(f"natural_curvature has shape {kbar.shape}; expected a scalar, (F,) = "
                                 f"({self.n_fingers},) or (B, F) = ({self.batch_size}, {self.n_fingers})") from None
        if np.abs(kbar).max() <= NATURAL_CURVATURE_LIMIT:  # False for NaN too
            return np.ascontiguousarray(kbar).reshape(-1)
        if not np.all(np.isfinite(kbar)):
            raise ValueError("natural_curvature (dimensionless) must be finite")
        raise ValueError(f"natural_curvature = {kbar.flat[np.abs(kbar).argmax()]:g} (dimensionless) is outside "
                         f"the allowed range [−{NATURAL_CURVATURE_LIMIT:g}, {NATURAL_CURVATURE_LIMIT:g}]: "
                         f"κ = 2·tan(φ/2) is singular at a turning angle φ = 180°")

    def step(self, state: RodState, natural_curvature) -> StepResult:
        """Advance ``state`` by one time step Δt with natural curvature κ̄ (dimensionless) per gripper and finger.

        ``natural_curvature`` is a scalar, (F,) or (B, F). It is held constant over the step.
        """
        kbar = self._natural_curvature(natural_curvature)
        return self._step_adaptive(state, kbar, self.scene.time_step, self.scene.newton.max_step_halvings)

    def _step_adaptive(self, state: RodState, kbar: np.ndarray, dt: float, halvings: int) -> StepResult:
        """One step of the scene's integrator; grippers whose Newton solve fails take two half steps instead, each
        of which may be halved again while ``halvings`` allows. Only the failed grippers are re-run."""
        result = self._integrator.advance(self, state, kbar, dt)
        settled = result.converged if result.contact is None else result.converged & result.contact.resolved
        if halvings == 0 or settled.all():
            return result
        failed = np.nonzero(~settled)[0]  # a corrector that spent its budget is retried in halves too
        sub = self._subsimulator(failed)
        sub_kbar = kbar.reshape(self.batch_size, -1)[failed].ravel()
        first = sub._step_adaptive(take_grippers(state, failed), sub_kbar, 0.5 * dt, halvings - 1)
        second = sub._step_adaptive(first.state, sub_kbar, 0.5 * dt, halvings - 1)
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
            sub._currents.start_time[:] = self._currents.start_time[grippers]
            sub._water_cache = (math.nan, None)
        return sub

    def equilibrium(self, state: RodState, natural_curvature, max_steps: int = 200) -> StepResult:
        """The static equilibrium reached from ``state`` with κ̄ held fixed, by pseudo-transient continuation.

        Implicit steps from rest, each with a step twice as long as the last, until the inertial term itself is
        below the Newton tolerance, which makes the result an equilibrium of the static forces alone. The returned
        state is at rest at the same time as ``state``.
        """
        kbar = self._natural_curvature(natural_curvature)
        pseudo_step = self.scene.time_step
        zero = np.zeros_like(state.velocity)
        result = None
        for _ in range(max_steps):
            result = self._advance(state, kbar, pseudo_step, zero)
            if not np.all(result.converged):
                pseudo_step *= 0.25
                continue
            state = evolve(result.state, velocity=zero, time=state.time, acceleration=None)
            static = self.static_residual(state, kbar)
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
        rod3d_update_frames(q, *frames, *transported)
        return transported

    def _frames(self, state: RodState):
        if self.disc.model != "3d":
            return None
        R, N = self.n_rods, self.disc.n_nodes
        return (state.tangent.reshape(R, N - 1, 3), state.director.reshape(R, N - 1, 3),
                state.reference_twist.reshape(R, N))

    def _assemble(self, q, q_old, q_pred, frames_old, kbar, time, dt, hessian=True):
        """Total force [N] on every DOF (R, N, S) and the band of −∂f/∂q (R, n, kd+1) at coordinates q, for a
        backward-Euler step of length ``dt`` from ``q_old`` with predictor ``q_pred`` = q_old + Δt·v_old."""
        disc = self.disc
        R = q.shape[0]
        force = np.empty(q.shape)
        band = np.empty((R, disc.n_dofs, disc.band_width + 1))
        assemble(q, q_old, q_pred, kbar, self._water(time)[1], dt, self._elastic, frames_old or self._no_frames,
                 self._force_terms, hessian, force, band)
        return force, band

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
        free = self._clamp_free.copy()
        release_held(free, held, disc.dim)
        return free

    def _per_step(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """For steps of ``dt``: the mass term M/Δt² of every DOF (n,), and 1/tolerance of every DOF of every rod
        (R, n). The tolerance is the scene's, raised where needed above the roundoff of the inertial term
        M·(q − q_pred)/Δt², which at tiny steps would otherwise make it unreachable."""
        if dt not in self._per_step_cache:
            disc = self.disc
            mass_term = disc.dof_mass / dt**2
            roundoff = 64.0 * np.finfo(float).eps * mass_term * self.scene.gripper.finger.length
            tolerance = np.maximum(disc.residual_scale, roundoff)
            self._per_step_cache[dt] = mass_term, np.tile(np.where(disc.free, 1.0 / tolerance, 0.0),
                                                          (self.n_rods, 1))
        return self._per_step_cache[dt]

    def _newton(self, q, q_old, q_pred, frames_old, kbar, time, dt, free, rods):
        """Newton's method for the rods where ``rods`` is True; ``q`` (R, N, S) holds the start and receives the
        solution. Returns per-rod converged, iterations and residual ratio (R,), and the residual
        M·(q − q_pred)/Δt² − f at the solution (R, n): on held DOFs, the contact reaction."""
        disc = self.disc
        R = q.shape[0]
        converged = np.zeros(R, dtype=bool)
        iterations = np.zeros(R, dtype=np.int64)
        ratio = np.full(R, np.inf)
        residual = np.zeros((R, disc.n_dofs))
        mass_term, tolerance_inverse = self._per_step(dt)
        newton_solve(q, q_old, q_pred, kbar, self._water(time)[1], dt, self._elastic, frames_old or self._no_frames,
                     self._force_terms, disc.band_width, mass_term, tolerance_inverse, free, rods,
                     self.scene.newton.max_iterations, converged, iterations, ratio, residual)
        return converged, iterations, ratio, residual

    def _solve_with_contact(self, state, q, q_old, q_pred, frames_old, kbar, dt):
        """The predictor–corrector (see :mod:`.contact`): solve, release adhesive holds, hold new penetrations, and
        solve the rods that changed again (each from its last solution), until none does or the corrector's budget is
        spent. ``q`` (R, N, S) holds Newton's start and receives the solution."""
        disc = self.disc
        R, N, D = self.n_rods, disc.n_nodes, disc.dim
        held = state.held.reshape(R, N).copy() if state.held is not None else np.zeros((R, N), dtype=bool)
        hold_at = q_old[..., :D].copy()  # nodes already held stay where they are
        converged = np.zeros(R, dtype=bool)
        iterations = np.zeros(R, dtype=np.int64)
        ratio = np.full(R, np.inf)
        residual = np.zeros((R, disc.n_dofs))
        corrector = np.zeros(R, dtype=np.int64)
        rods = self._all_rods.copy()
        starts, ends, radii, searched = self._object
        adhesive, new_hold = np.empty((R, N), dtype=bool), np.empty((R, N), dtype=bool)
        changed = np.empty(R, dtype=bool)
        for k in range(self.scene.contact.max_corrector_iterations + N + 1):  # holds-only solves end by N
            q[..., :D][held & rods[:, None]] = hold_at[held & rods[:, None]]  # from the last solution, warm
            solved = self._newton(q, q_old, q_pred, frames_old, kbar, state.time, dt, self._free_mask(held), rods)
            for total, part in zip((converged, iterations, ratio, residual), solved, strict=True):
                total[rods] = part[rods]
            contact_changes(q[..., :D], q_old[..., :D], residual, held, starts, ends, radii, searched, self._no_shift,
                            self._first_free_node, self._force_tolerance, adhesive, new_hold, hold_at, changed)
            within_budget = k < self.scene.contact.max_corrector_iterations
            if not corrector_continues(within_budget, new_hold, changed, rods):
                break
            update_holds(within_budget, held, adhesive, new_hold)
            corrector[rods] += 1
        return q, held, changed, corrector, converged, iterations, ratio, residual, (starts, ends)

    def _solve_with_body(self, state, q, q_old, q_pred, frames_old, kbar, dt):
        """Predictor–corrector contact with a free sphere (:func:`~.rigid_body.solve_with_body`, one compiled
        loop): each solve moves rods and body together; new penetrations are held where they entered the body's
        surface, with their offset in the body's frame, and adhesive holds are released, until nothing changes. Each
        re-solve starts from the last solution, so Newton starts a few penetration depths from the new one;
        restarting from the predictor would start a hold far from a body that the impact has slowed, a jump the 3-D
        coupled solve did not always survive. Only the grippers whose contacts changed are solved again. ``q``
        (R, N, S) holds Newton's start and receives the solution."""
        disc = self.disc
        R, N = self.n_rods, disc.n_nodes
        held = state.held.reshape(R, N).copy()
        offsets = state.hold_offset.reshape(R, N, 3).copy()
        body_old = tuple(np.ascontiguousarray(x) for x in (state.body_position, state.body_velocity,
                                                           state.body_orientation, state.body_angular_velocity))
        c, theta = body_old[0] + dt * body_old[1], dt * body_old[3]  # the body's predictor
        converged = np.empty(R, dtype=bool)
        iterations = np.empty(R, dtype=np.int64)
        ratio = np.empty(R)
        residual = np.zeros((R, disc.n_dofs))
        corrector = np.empty(R, dtype=np.int64)
        changed = np.empty(R, dtype=bool)
        mass_term, tolerance_inverse = self._per_step(dt)
        water, rod_water = self._water(state.time)
        held, orientation, starts, ends = solve_with_body(
            q, q_old, q_pred, kbar, rod_water, dt, self._elastic, frames_old or self._no_frames, self._force_terms,
            disc.band_width, mass_term, tolerance_inverse, self._clamp_free, held, offsets, self._projection,
            *self._body.arrays(), c, theta, body_old, water, self._any_motion, disc.finger_directions,
            self._plane_normals, self._body_tolerance, self.scene.newton.max_iterations,
            self.scene.gripper.finger.length, self._first_free_node, self._force_tolerance,
            self.scene.contact.max_corrector_iterations, converged, iterations, ratio, residual, corrector, changed)
        return (q, held, changed, corrector, converged, iterations, ratio, residual, (starts, ends),
                (offsets, c, (c - body_old[0]) / dt, orientation, theta / dt))

    def _advance(self, state: RodState, kbar: np.ndarray, dt: float, velocity_old: np.ndarray,
                 midpoint: bool = False) -> StepResult:
        """A backward-Euler step of ``dt`` from ``state`` with the old velocity ``velocity_old`` (zero for a
        pseudo-step); with ``midpoint``, the implicit midpoint rule's half step, extrapolated to the end of its step
        of 2·``dt`` (:func:`~.assembly.midpoint_end`)."""
        disc = self.disc
        R, N, S, D = self.n_rods, disc.n_nodes, disc.stride, disc.dim
        q_old, v_old = state.q.reshape(R, N, S), velocity_old.reshape(R, N, S)
        extrapolate = state.acceleration is not None and velocity_old is state.velocity  # not for a pseudo-step
        acceleration_old = state.acceleration.reshape(R, N, S) if extrapolate else self._no_acceleration
        q = np.empty((R, N, S))
        velocity, acceleration = np.empty(state.q.shape), np.empty(state.q.shape)
        frames_old = self._frames(state)
        body = held = changed = corrector = None
        end_in_kernel = False
        if self._body is None and self._object is None:  # rods on their own: the whole step in one kernel
            mass_term, tolerance_inverse = self._per_step(dt)
            end_in_kernel = midpoint and frames_old is None  # 3-D frames are carried to the midpoint first
            summary = advance_rods(q_old, v_old, acceleration_old, kbar, self._water(state.time)[1], dt,
                                   self._elastic, frames_old or self._no_frames, self._force_terms, disc.band_width,
                                   mass_term, tolerance_inverse, self._clamp_free, self.scene.newton.max_iterations,
                                   end_in_kernel, self.n_fingers, q, velocity.reshape(R, N, S),
                                   acceleration.reshape(R, N, S))
        else:
            q_pred = np.empty((R, N, S))
            predict(q_old, v_old, acceleration_old, dt, q_pred, q)
            if self._body is not None:
                q, held, changed, corrector, converged, iterations, ratio, residual, surface, body = \
                    self._solve_with_body(state, q, q_old, q_pred, frames_old, kbar, dt)
            else:
                q, held, changed, corrector, converged, iterations, ratio, residual, surface = \
                    self._solve_with_contact(state, q, q_old, q_pred, frames_old, kbar, dt)
            finish(q, q_old, v_old, dt, velocity.reshape(R, N, S), acceleration.reshape(R, N, S))
            summary = per_gripper(converged, iterations, ratio, self.n_fingers)
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
            reaction = np.zeros((R, N, S))
            reaction[..., :D] = residual.reshape(R, N, S)[..., :D] * held[..., None]
            starts, ends = surface  # the object's segment as each rod sees it at the solution
            contact = ContactReport(
                held=held.reshape(B, F, N),
                reaction=disc.world_positions(reaction.reshape(B, F, N, S)),
                normal_reaction=normal_reactions(q[..., :D], reaction[..., :D], starts, ends).reshape(B, F, N),
                corrector_iterations=corrector.reshape(B, F).max(axis=1),
                resolved=~changed.reshape(B, F).any(axis=1),
                palm_reaction=None if body is None else self._body.palm_reaction(
                    body[1], state.body_position, body[3], state.body_orientation, dt))
        converged, iterations, ratio = summary
        return record(StepResult, state=new_state, converged=converged, newton_iterations=iterations, residual=ratio,
                      contact=contact, substeps=np.full(B, 1))


def _structure(scene: Scene) -> tuple:
    """What every gripper of a batch must share: the scene less its object's size, place, density and velocity,
    and less the current."""
    obj = scene.grasped_object
    if obj is not None:
        obj = (type(obj), obj.free)
    forces = tuple(replace(f, current=Current()) if isinstance(f, MorisonDrag) else f for f in scene.forces)
    return replace(scene, grasped_object=None, forces=forces), obj


def take_grippers(record, index: np.ndarray):
    """The grippers ``index`` of a state or contact report (every array field has the batch axis first)."""
    return evolve(record, **{name: value[index] for name, value in vars(record).items()
                             if isinstance(value, np.ndarray)})


def put_grippers(record, index: np.ndarray, part):
    """A copy of ``record`` whose grippers ``index`` are taken from ``part``."""
    return evolve(record, **{name: _set(value, index, getattr(part, name)) for name, value in vars(record).items()
                             if isinstance(value, np.ndarray)})


def _set(array: np.ndarray, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = array.copy()
    out[index] = values
    return out


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
    positions = [sim.world_positions(state)]
    iterations, converged, contacts = [], [], []
    for k in range(n_steps):
        kbar = min(max(scene.natural_curvature_rate * state.time, -NATURAL_CURVATURE_LIMIT), NATURAL_CURVATURE_LIMIT)
        result = sim.step(state, kbar)
        state = result.state
        positions.append(sim.world_positions(state))
        iterations.append(result.newton_iterations)
        converged.append(result.converged)
        if result.contact is not None:
            contacts.append(result.contact)
        if progress is not None:
            progress(k + 1, n_steps)
    return Trajectory(times=np.arange(n_steps + 1) * scene.time_step, positions=np.stack(positions),
                      newton_iterations=np.stack(iterations), converged=np.stack(converged), final_state=state,
                      contacts=tuple(contacts))
