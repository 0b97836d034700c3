"""The compiled assembly of one rod's implicit system: its elastic forces and the scene's force terms, with
−∂f/∂q, for a backward-Euler step of Δt from q_old with the predictor q_pred = q_old + Δt·v_old.

The arguments shared by these kernels:

=====================  ===========================================================================  ===========
name                   meaning                                                                      shape
=====================  ===========================================================================  ===========
``q``                  coordinates (positions [m], twist angles [rad])                              (R, N, S)
``natural_curvature``  κ̄ per rod (dimensionless)                                                    (R,)
``water``              the water's velocity at every rod, in its coordinates [m/s]                  (R, D)
``rods``               :class:`RodArrays`: the rod's constants and the start-of-step frames         bundle
``terms``              :class:`~..scene.forces.ForceTerms`, as :class:`TermArrays`                  bundle
=====================  ===========================================================================  ===========
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..scene.discretization import Discretization
from ..scene.fluid import Fluid
from ..scene.forces import ForceModel, ForceTerms
from .compiled import kernel
from .current import current_at
from .finger_contact import FingerContact, any_near, finger_contact_rod, finger_scratch
from .forces import added_mass, linear_damping, morison_drag, rod_water_velocity
from .rod_3d import elastic_scratch, rod3d_elastic_rod
from .rod_planar import planar_elastic_rod


class RodArrays(NamedTuple):
    """What every kernel needs to know of the rods besides their coordinates: the finger design's constants
    (:class:`~..scene.discretization.Discretization`, per node or edge of one rod) and, in 3-D, every rod's reference
    frames at the start of the step (empty arrays in the planar model)."""

    rest_length: np.ndarray
    """Rest length of each edge [m], (N − 1,)."""
    stretch_stiffness: np.ndarray
    """EA of each edge [N], (N − 1,)."""
    bend_stiffness: np.ndarray
    """EI at each node [N·m²], (N,)."""
    twist_stiffness: np.ndarray
    """GJ at each node [N·m²], (N,)."""
    voronoi_length: np.ndarray
    """Rest length attributed to each node [m], (N,)."""
    retardation_time: float
    """The material's Kelvin–Voigt retardation time τ [s]."""
    numerical_retardation: float
    """The damping the integrator's step adds of its own, as a Kelvin–Voigt retardation time in units of the step
    (dimensionless): 1 for backward Euler, 0 for the midpoint rule
    (:attr:`~..solvers.integrators.BackwardEuler.numerical_retardation`)."""
    fingers: FingerContact
    """The constants of contact between a gripper's fingers (:class:`~.finger_contact.FingerContact`)."""
    tangent: np.ndarray
    """Start-of-step unit tangent of every edge, (R, N − 1, 3); (0, 0, 3) in the planar model."""
    director: np.ndarray
    """Start-of-step first director of every edge, (R, N − 1, 3); (0, 0, 3) in the planar model."""
    reference_twist: np.ndarray
    """Start-of-step reference twist at every node [rad], (R, N); (0, 0) in the planar model."""

    @classmethod
    def of(cls, disc: Discretization, fingers: FingerContact, numerical_retardation: float) -> RodArrays:
        """The arrays of ``disc`` with the contact between its fingers and the integrator's own damping, without
        frames (a state's are put in with ``_replace``)."""
        return cls(disc.rest_edge_length, disc.stretch_stiffness, disc.bend_stiffness, disc.twist_stiffness,
                   disc.voronoi_length, disc.retardation_time, float(numerical_retardation), fingers,
                   np.empty((0, 0, 3)), np.empty((0, 0, 3)), np.empty((0, 0)))


N_DESIGN_FIELDS = RodArrays._fields.index("tangent")
"""How many fields of :class:`RodArrays` a design fixes: those before a state's frames."""
FINGERS_FIELD = RodArrays._fields.index("fingers")
"""Where the finger contact's constants are among the fields of :class:`RodArrays` (for its plain tuple)."""


@kernel(python=True, inline=True, runtime=True)  # inlined, its bundle is its caller's; from Python, a new one
def named_rods(rods):
    """:class:`RodArrays` from its fields as plain tuples (:func:`~..solvers.newton.plain`), named again, the
    finger contact's too."""
    return RodArrays(rods[0], rods[1], rods[2], rods[3], rods[4], rods[5], rods[6], FingerContact(*rods[7]), rods[8],
                     rods[9], rods[10])


class StepInputs(NamedTuple):
    """What a backward-Euler step of every rod starts from (arrays over all rods R)."""

    q_old: np.ndarray
    """Coordinates at the start of the step, (R, N, S) [m, rad]."""
    q_pred: np.ndarray
    """The predictor q_old + Δt·v_old, (R, N, S) [m, rad]."""
    natural_curvature: np.ndarray
    """κ̄ of every rod, (R,) (dimensionless)."""
    water: np.ndarray
    """The water's velocity at every rod, in its coordinates, (R, D) [m/s]."""
    dt: float
    """Δt [s]."""
    near: np.ndarray
    """The nearest edge of each other finger to each node at the start of the step, −1 where it is far, (R, N, F)
    int (:func:`~.finger_contact.find_near_fingers`); empty without finger contact."""


@kernel
def external_forces_rod(positions, start_positions, velocities, accelerations, water, terms, velocity_derivative,
                        acceleration_derivative, stride, force, band):
    """Adds the force terms' force [N] to one rod's ``force`` (N, ≥D) and their negated Jacobian to its ``band``.
    ``positions``, ``start_positions``, ``velocities``, ``accelerations``: (N, D); ``water`` (D,)."""
    node_force, damping, drag_normal, drag_tangential, edge_added_mass = terms
    n_nodes, dim = positions.shape
    if node_force.size:
        for i in range(n_nodes):
            for k in range(dim):
                force[i, k] += node_force[i, k]
    if damping.size:
        linear_damping(damping, velocities, velocity_derivative, stride, force, band)
    if drag_normal.size:
        morison_drag(positions, velocities, water, drag_normal, drag_tangential, velocity_derivative, stride, force,
                     band)
    if edge_added_mass.size:
        added_mass(start_positions, accelerations, edge_added_mass, acceleration_derivative, stride, force, band)


@kernel(python=True)
def external_forces(positions, start_positions, velocities, accelerations, water, terms, velocity_derivative,
                    acceleration_derivative, stride, force, band):
    """:func:`external_forces_rod` for every rod: arrays (R, N, D), ``water`` (R, D), ``band`` (R, n, kd+1)."""
    for r in range(positions.shape[0]):
        external_forces_rod(positions[r], start_positions[r], velocities[r], accelerations[r], water[r], terms,
                            velocity_derivative, acceleration_derivative, stride, force[r], band[r])


@kernel(inline=True)
def assemble_rod(r, q, step, rods, terms, hessian, force, band, strained, velocity, acceleration, elastic, fingers):
    """Overwrites ``force`` (N, S) with rod r's total force [N] at coordinates ``q`` (R, N, S) of the backward-Euler
    step ``step`` (:class:`StepInputs`), and ``band`` (n, kd+1) with −∂f/∂q (when ``hessian``). Work arrays, passed
    in so that it allocates nothing (a GPU thread has no heap to allocate from): ``strained`` (N, S) (the
    coordinates the elastic force is evaluated at, with material damping), ``velocity`` and ``acceleration``
    (N, D), the 3-D energy's buffer ``elastic`` (:func:`~.rod_3d.elastic_scratch`; empty in the planar model) and the
    finger contact's ``fingers`` (:func:`~.finger_contact.finger_scratch`; empty without it). ``rods`` is
    :class:`RodArrays`, ``terms`` the scene's :class:`~..scene.forces.ForceTerms`. Returns its elastic energy [J]
    (at ``strained`` with material damping).

    Material damping (Kelvin–Voigt, stress E·(ε + τ·ε̇)) adds −τ·K·v to the elastic force f(q), K = −∂f/∂q. With the
    step's v = (q − q_old)/Δt that is, to first order in τ·v, the elastic force at q* = q + (τ/Δt)·(q − q_old): one
    evaluation of the same elastic kernel, whose Jacobian is (1 + τ/Δt)·∂f/∂q(q*). A mode of angular frequency ω
    gets the damping ratio τ·ω/2, and the actuation's κ̄ is left out of it (it damps the material's strain rate).

    A backward-Euler step damps a mode with ω·Δt ≪ 1 as a Kelvin–Voigt material of τ = Δt would (its modified
    equation adds Δt·ω²/2 to the decay rate), so with the material's τ at full strength the damping grows with the
    step: a first-order error that kept a grasp's peak force from converging in the step. The step therefore
    applies τ − ``numerical_retardation``·Δt (never below 0), and the sum of the two is the material's τ to first
    order; a step longer than τ damps more than the material, by its own part alone."""
    force[:] = 0.0
    band[:] = 0.0
    stride = q.shape[2]
    viscous = max(rods.retardation_time - rods.numerical_retardation * step.dt, 0.0) / step.dt
    at = q[r]
    if viscous != 0.0:
        at = strained
        for i in range(q.shape[1]):
            for k in range(stride):
                strained[i, k] = q[r, i, k] + viscous * (q[r, i, k] - step.q_old[r, i, k])
    if stride == 2:
        energy = planar_elastic_rod(at, rods.rest_length, rods.stretch_stiffness, rods.bend_stiffness,
                                    rods.voronoi_length, step.natural_curvature[r], force, band, hessian)
    else:
        energy = rod3d_elastic_rod(at, rods.tangent[r], rods.director[r], rods.reference_twist[r],
                                   rods.rest_length, rods.stretch_stiffness, rods.bend_stiffness,
                                   rods.twist_stiffness, rods.voronoi_length, step.natural_curvature[r], force,
                                   band, hessian, elastic)
    if viscous != 0.0 and hessian:
        for j in range(band.shape[0]):
            for k in range(band.shape[1]):
                band[j, k] *= 1.0 + viscous
    n_nodes, dim = velocity.shape
    dt = step.dt
    for i in range(n_nodes):
        for k in range(dim):
            velocity[i, k] = (q[r, i, k] - step.q_old[r, i, k]) / dt
            acceleration[i, k] = (q[r, i, k] - step.q_pred[r, i, k]) / (dt * dt)
    external_forces_rod(q[r, :, :dim], step.q_old[r, :, :dim], velocity, acceleration, step.water[r], terms,
                        1.0 / dt, 1.0 / (dt * dt), stride, force, band)
    near = step.near
    # finger contact is on, and the rod is near another finger: the tests cost less than binding the call's arrays
    if near.size > 0 and any_near(near, r):
        finger_contact_rod(r, q, step.q_old, step.q_pred, dt, rods.fingers, near, hessian, force, band, fingers)
    return energy


@kernel(python=True, runtime=True)  # it allocates
def assemble(q, step, rods, terms, hessian, force, band):
    """Every rod's force (R, N, S) [N] and −∂f/∂q (R, n, kd+1), written into ``force`` and ``band``."""
    n_nodes = q.shape[1]
    motion = np.empty((2, n_nodes, step.water.shape[1]))  # velocity and acceleration
    strained = np.empty((n_nodes, q.shape[2]))
    elastic = elastic_scratch(n_nodes if q.shape[2] == 4 else 0)
    fingers = finger_scratch(rods.fingers.eligible.shape[0] if step.near.size > 0 else 0, n_nodes)
    for r in range(q.shape[0]):
        assemble_rod(r, q, step, rods, terms, hessian, force[r], band[r], strained, motion[0], motion[1], elastic,
                     fingers)


@dataclass(frozen=True, eq=False)
class StepContext:
    """What the integrator tells a force model evaluated on its own (:func:`evaluate_force`) about the step."""

    time: float
    """Time at the start of the step [s]."""
    start_positions: np.ndarray
    """Node positions at the start of the step [m], (R, N, D)."""
    velocity_derivative: float
    """∂v/∂q of the integrator [1/s]."""
    acceleration_derivative: float
    """∂a/∂q of the integrator [1/s²]."""


def evaluate_force(model: ForceModel, disc: Discretization, fluid: Fluid, ctx: StepContext, positions: np.ndarray,
                   velocities: np.ndarray, accelerations: np.ndarray, force: np.ndarray,
                   system_band: np.ndarray) -> None:
    """Adds one force ``model``'s force [N] to ``force`` and its negated Jacobian
    −(∂f/∂q + ∂f/∂v·∂v/∂q + ∂f/∂a·∂a/∂q) to ``system_band``, through the kernel the simulator runs, in ``fluid``
    whose current is evaluated at ``ctx.time``. Arrays (R, N, D) [m, m/s, m/s², N] as in
    :class:`~..scene.discretization.Discretization`, ``system_band`` (R, n, kd+1)."""
    n_grippers = positions.shape[0] // len(disc.finger_directions)
    water = rod_water_velocity(disc, np.tile(current_at(fluid.current, ctx.time), (n_grippers, 1)))
    external_forces(positions, ctx.start_positions, velocities, accelerations, water,
                    ForceTerms.of(disc, (model,), fluid), ctx.velocity_derivative, ctx.acceleration_derivative,
                    disc.stride, force, system_band)


__all__ = ["RodArrays", "N_DESIGN_FIELDS", "FINGERS_FIELD", "named_rods", "StepInputs", "external_forces_rod",
           "external_forces", "assemble_rod", "assemble", "StepContext", "evaluate_force"]
