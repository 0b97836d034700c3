"""The compiled assembly of the implicit system, and Newton's method for rods that move on their own.

One rod's Newton matrix and residual come from :func:`assemble_rod`: the elastic forces of the planar or 3-D rod
and the scene's :class:`~.forces.ForceTerms`, at coordinates q of a backward-Euler step of Δt from q_old with the
predictor q_pred = q_old + Δt·v_old. :func:`newton_solve` runs the whole Newton loop of every rod in one call, so a
step costs one kernel call instead of a few dozen array operations per iteration; :func:`assemble` gives the
batch's forces and bands to the body-coupled solve (:mod:`.rigid_body`), which iterates in Python.

The arguments shared by these kernels:

=====================  ===========================================================================  ===========
name                   meaning                                                                      shape
=====================  ===========================================================================  ===========
``q``                  coordinates (positions [m], twist angles [rad])                              (R, N, S)
``natural_curvature``  κ̄ per rod (dimensionless)                                                    (R,)
``water``              the water's velocity at every rod, in its coordinates [m/s]                  (R, D)
``elastic``            rest edge length [m], EA [N], EI [N·m²], GJ [N·m²], Voronoi length [m]       5 arrays
``frames``             start-of-step tangent, director (R, N − 1, 3) and reference twist (R, N);   3 arrays
                       empty arrays in the planar model
``terms``              :meth:`~.forces.ForceTerms.arrays`                                           5 arrays
=====================  ===========================================================================  ===========
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .forces import linear_damping
from .hydrodynamics import added_mass, morison_drag
from .linalg import solve_banded_symmetric_rod
from .rod_3d import rod3d_elastic_rod
from .rod_planar import planar_elastic_rod


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def external_forces(positions, start_positions, velocities, accelerations, water, terms, velocity_derivative,
                    acceleration_derivative, stride, force, band):
    """:func:`external_forces_rod` for every rod: arrays (R, N, D), ``water`` (R, D), ``band`` (R, n, kd+1)."""
    for r in range(positions.shape[0]):
        external_forces_rod(positions[r], start_positions[r], velocities[r], accelerations[r], water[r], terms,
                            velocity_derivative, acceleration_derivative, stride, force[r], band[r])


@njit(cache=True, error_model="numpy")
def assemble_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, hessian, force, band,
                 velocity, acceleration):
    """Overwrites ``force`` (N, S) with rod r's total force [N] and ``band`` (n, kd+1) with −∂f/∂q; ``velocity`` and
    ``acceleration`` (N, D) are scratch. Returns its elastic energy [J]."""
    force[:] = 0.0
    band[:] = 0.0
    stride = q.shape[2]
    rest_length, stretch_stiffness, bend_stiffness, twist_stiffness, voronoi_length = elastic
    if stride == 2:
        energy = planar_elastic_rod(q[r], rest_length, stretch_stiffness, bend_stiffness, voronoi_length,
                                    natural_curvature[r], force, band, hessian)
    else:
        energy = rod3d_elastic_rod(q[r], frames[0][r], frames[1][r], frames[2][r], rest_length, stretch_stiffness,
                                   bend_stiffness, twist_stiffness, voronoi_length, natural_curvature[r], force,
                                   band, hessian)
    n_nodes, dim = velocity.shape
    for i in range(n_nodes):
        for k in range(dim):
            velocity[i, k] = (q[r, i, k] - q_old[r, i, k]) / dt
            acceleration[i, k] = (q[r, i, k] - q_pred[r, i, k]) / (dt * dt)
    external_forces_rod(q[r, :, :dim], q_old[r, :, :dim], velocity, acceleration, water[r], terms, 1.0 / dt,
                        1.0 / (dt * dt), stride, force, band)
    return energy


@njit(cache=True, error_model="numpy")
def assemble(q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, hessian, force, band):
    """Every rod's force (R, N, S) [N] and −∂f/∂q (R, n, kd+1), written into ``force`` and ``band``."""
    dim = water.shape[1]
    velocity = np.empty((q.shape[1], dim))
    acceleration = np.empty((q.shape[1], dim))
    for r in range(q.shape[0]):
        assemble_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, hessian, force[r],
                     band[r], velocity, acceleration)


@njit(cache=True, error_model="numpy")
def newton_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, mass_term,
               tolerance_inverse, free, max_iterations, converged, iterations, ratio, residual, force, band, velocity,
               acceleration, step):
    """Newton's method for rod r (see :func:`newton_solve`); ``force``, ``band``, ``velocity``, ``acceleration`` and
    ``step`` are scratch."""
    n = step.size
    band_width = band.shape[1] - 1
    converged[r] = False
    iterations[r] = 0
    q_r = q[r].reshape(n)
    q_pred_r = q_pred[r].reshape(n)
    force_r = force.reshape(n)
    for it in range(max_iterations + 1):
        assemble_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, True, force, band,
                     velocity, acceleration)
        largest = 0.0
        for j in range(n):
            residual[r, j] = mass_term[j] * (q_r[j] - q_pred_r[j]) - force_r[j]
            step[j] = -residual[r, j]
            scaled = abs(residual[r, j]) * tolerance_inverse[r, j] if free[r, j] else 0.0
            if not scaled <= largest:  # also catches NaN
                largest = scaled
        ratio[r] = largest
        if largest <= 1.0:
            converged[r] = True
            return
        if it == max_iterations:
            return
        for j in range(n):
            band[j, band_width] += mass_term[j]
        if not solve_banded_symmetric_rod(band, step, free[r]):
            ratio[r] = np.inf
            return
        for j in range(n):
            q_r[j] += step[j]
        iterations[r] += 1


@njit(cache=True, error_model="numpy")
def newton_solve(q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, band_width, mass_term,
                 tolerance_inverse, free, rods, max_iterations, converged, iterations, ratio, residual):
    """Newton's method for every rod where ``rods`` is True, each on its own until it converges.

    ``q`` (R, N, S) holds the start and receives the solution; only DOFs where ``free`` (R, n) is True move. With
    the residual r = M·(q − q_pred)/Δt² − f (``mass_term`` = M/Δt² per DOF, (n,)), a rod has converged when its
    largest |r|·``tolerance_inverse`` (R, n) over free DOFs is ≤ 1. Writes per rod ``converged``, ``iterations``
    (linear solves) and that ``ratio`` (R,), and the final ``residual`` (R, n): on held DOFs, the contact reaction.
    A rod whose factorisation fails stops with ratio inf and NaN coordinates.
    """
    scratch = _newton_scratch(q, water, band_width)
    for r in range(q.shape[0]):
        if rods[r]:
            newton_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, mass_term,
                       tolerance_inverse, free, max_iterations, converged, iterations, ratio, residual, *scratch)


@njit(cache=True, error_model="numpy")
def _newton_scratch(q, water, band_width):
    """One rod's work arrays for :func:`newton_rod`: force, band, velocity, acceleration and step."""
    n_nodes, stride, dim = q.shape[1], q.shape[2], water.shape[1]
    return (np.empty((n_nodes, stride)), np.empty((n_nodes * stride, band_width + 1)), np.empty((n_nodes, dim)),
            np.empty((n_nodes, dim)), np.empty(n_nodes * stride))


@njit(cache=True, error_model="numpy")
def predict(q_old, velocity_old, acceleration_old, dt, q_pred, q_start):
    """The predictor q_pred = q_old + Δt·v_old of every rod, and Newton's start q_pred + Δt²·a_old, the last step's
    motion extrapolated (``acceleration_old`` empty: the predictor itself). Arrays (R, N, S)."""
    for r in range(q_old.shape[0]):
        _predict_rod(r, q_old, velocity_old, acceleration_old, dt, q_pred, q_start)


@njit(cache=True, error_model="numpy", inline="always")
def _predict_rod(r, q_old, velocity_old, acceleration_old, dt, q_pred, q_start):
    extrapolate = acceleration_old.size > 0
    for i in range(q_old.shape[1]):
        for k in range(q_old.shape[2]):
            q_pred[r, i, k] = q_old[r, i, k] + dt * velocity_old[r, i, k]
            q_start[r, i, k] = q_pred[r, i, k] + (dt * dt * acceleration_old[r, i, k] if extrapolate else 0.0)


@njit(cache=True, error_model="numpy")
def finish(q, q_old, velocity_old, dt, velocity, acceleration):
    """The end of a backward-Euler step of every rod: v = (q − q_old)/Δt and the mean acceleration (v − v_old)/Δt."""
    for r in range(q.shape[0]):
        _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration)


@njit(cache=True, error_model="numpy", inline="always")
def _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration):
    for i in range(q.shape[1]):
        for k in range(q.shape[2]):
            velocity[r, i, k] = (q[r, i, k] - q_old[r, i, k]) / dt
            acceleration[r, i, k] = (velocity[r, i, k] - velocity_old[r, i, k]) / dt


@njit(cache=True, error_model="numpy")
def midpoint_end(q_old, velocity_old, q, velocity):
    """The implicit midpoint rule's end from its backward-Euler half step (see :mod:`.integrators`), in place:
    q₁ = 2·q_½ − q₀, v₁ = 2·v_½ − v₀. Arrays (R, N, S)."""
    for r in range(q.shape[0]):
        _midpoint_end_rod(r, q_old, velocity_old, q, velocity)


@njit(cache=True, error_model="numpy", inline="always")
def _midpoint_end_rod(r, q_old, velocity_old, q, velocity):
    for i in range(q.shape[1]):
        for k in range(q.shape[2]):
            q[r, i, k] = 2.0 * q[r, i, k] - q_old[r, i, k]
            velocity[r, i, k] = 2.0 * velocity[r, i, k] - velocity_old[r, i, k]


@njit(cache=True, error_model="numpy")
def advance_rods(q_old, velocity_old, acceleration_old, natural_curvature, water, dt, elastic, frames, terms,
                 band_width, mass_term, tolerance_inverse, free, max_iterations, midpoint, n_fingers, q, velocity,
                 acceleration):
    """A whole backward-Euler step of rods that move on their own: :func:`predict`, :func:`newton_solve` from the
    extrapolated start, and :func:`finish`, rod by rod, in one call (the scene without an object's hot path); with
    ``midpoint``, it is the midpoint rule's half step and :func:`midpoint_end` follows. Writes the new coordinates,
    velocities and accelerations (R, N, S); returns :func:`per_gripper`'s summary of the Newton solves."""
    n_rods = q.shape[0]
    scratch = _newton_scratch(q, water, band_width)
    q_pred = np.empty(q.shape)
    residual = np.empty((n_rods, q.shape[1] * q.shape[2]))
    converged = np.empty(n_rods, dtype=np.bool_)
    iterations = np.empty(n_rods, dtype=np.int64)
    ratio = np.empty(n_rods)
    for r in range(q.shape[0]):
        _predict_rod(r, q_old, velocity_old, acceleration_old, dt, q_pred, q)
        newton_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, mass_term,
                   tolerance_inverse, free, max_iterations, converged, iterations, ratio, residual, *scratch)
        _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration)
        if midpoint:
            _midpoint_end_rod(r, q_old, velocity_old, q, velocity)
    return per_gripper(converged, iterations, ratio, n_fingers)


@njit(cache=True, error_model="numpy")
def per_gripper(converged, iterations, ratio, n_fingers):
    """A step's per-rod Newton results (R,) per gripper (B,): whether every finger converged, the most iterations,
    and the largest residual ratio (NaN read as inf)."""
    n_grippers = converged.size // n_fingers
    all_converged = np.ones(n_grippers, dtype=np.bool_)
    most = np.zeros(n_grippers, dtype=np.int64)
    largest = np.zeros(n_grippers)
    for b in range(n_grippers):
        for r in range(b * n_fingers, (b + 1) * n_fingers):
            all_converged[b] &= converged[r]
            most[b] = max(most[b], iterations[r])
            largest[b] = max(largest[b], np.inf if np.isnan(ratio[r]) else ratio[r])
    return all_converged, most, largest
