"""Compiled force kernels of one rod: linear damping, Morison drag and added mass, each adding its force and its
negated Jacobian to the rod's Newton system (``docs/water.md``).

Both water models enter the implicit solve with their Jacobians with respect to the velocity and the acceleration,
which are exact and symmetric. Two approximations keep the Newton matrix symmetric. First, the added-mass matrix uses
each edge's tangent at the start of the step. Second, the drag's dependence on the tangent turning within a step is
left out of the Newton matrix, though not out of the force. Newton still converges in a few iterations
(tests/physics/test_water.py).

In the planar model each finger sees the current's component in its own vertical plane (:func:`rod_water_velocity`);
the component across the plane would push a finger that cannot move that way, so it is dropped.
"""

from __future__ import annotations

import math

import numpy as np

from ..scene.discretization import Discretization
from .compiled import kernel


def rod_water_velocity(disc: Discretization, water_velocity: np.ndarray) -> np.ndarray:
    """The water's velocity per gripper (B, 3) as each rod sees it, (R, D) [m/s]: world (3-D) or in the finger's
    vertical plane (planar; the component across the plane would push a finger that cannot move that way)."""
    rods = np.empty((len(water_velocity) * len(disc.finger_directions), disc.dim))
    project_water(disc.finger_directions, np.ascontiguousarray(water_velocity, dtype=float), rods)
    return rods


@kernel(python=True)
def project_water(finger_directions, water_velocity, rods):
    """:func:`rod_water_velocity` into ``rods`` (R, D), from the fingers' radial directions (F, 3): the compiled
    steps' one way to see the current from each rod."""
    n_fingers = finger_directions.shape[0]
    planar = rods.shape[1] == 2
    for b in range(water_velocity.shape[0]):
        for f in range(n_fingers):
            r = b * n_fingers + f
            if planar:
                rods[r, 0] = water_velocity[b, 0] * finger_directions[f, 0] \
                    + water_velocity[b, 1] * finger_directions[f, 1] + water_velocity[b, 2] * finger_directions[f, 2]
                rods[r, 1] = water_velocity[b, 2]
            else:
                for d in range(3):
                    rods[r, d] = water_velocity[b, d]


@kernel
def linear_damping(coefficient, velocities, velocity_derivative, stride, force, band):
    """Adds −c_i·v_i to one rod's ``force`` (N, D) and c_i·∂v/∂q to the position diagonal of its ``band``
    (n, kd+1)."""
    n_nodes, dim = velocities.shape
    kd = band.shape[1] - 1
    for i in range(n_nodes):
        c = coefficient[i]
        for k in range(dim):
            force[i, k] -= c * velocities[i, k]
            band[stride * i + k, kd] += c * velocity_derivative


# An edge's vectors are 3-tuples, zero-padded in the planar model: values that Numba keeps in registers. The padding
# adds exact zeros, so the arithmetic on the plane's two components is what a loop over them did, to the bit.


@kernel(inline=True)
def _padded(array, i, dim):
    """Row i of an (N, D) array as a 3-tuple; its third component 0 in the planar model (D = 2)."""
    return (array[i, 0], array[i, 1], array[i, 2] if dim == 3 else 0.0)


@kernel(inline=True)
def _unit_tangent(start, end):
    """The unit vector from ``start`` to ``end`` (3-tuples)."""
    d = (end[0] - start[0], end[1] - start[1], end[2] - start[2])
    inverse_length = 1.0 / math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    return (d[0] * inverse_length, d[1] * inverse_length, d[2] * inverse_length)


@kernel(python=True)
def morison_drag(positions, velocities, current, normal, tangential, velocity_derivative, stride, force, band):
    """Morison drag of every edge of one rod: adds the force to ``force`` (N, D) and its velocity Jacobian to
    ``band`` (n, kd+1).

    ``normal``, ``tangential``: ½·ρ_w·C·D·l̄ per edge [kg/m] (the tangential one with π·D); ``current`` (D,).
    """
    n_nodes, dim = positions.shape
    kd = band.shape[1] - 1
    quarter = 0.25 * velocity_derivative
    u = (current[0], current[1], current[2] if dim == 3 else 0.0)
    start, v_start = _padded(positions, 0, dim), _padded(velocities, 0, dim)
    for e in range(n_nodes - 1):
        end, v_end = _padded(positions, e + 1, dim), _padded(velocities, e + 1, dim)
        t = _unit_tangent(start, end)
        w = (0.5 * (v_start[0] + v_end[0]) - u[0], 0.5 * (v_start[1] + v_end[1]) - u[1],
             0.5 * (v_start[2] + v_end[2]) - u[2])
        s = w[0] * t[0] + w[1] * t[1] + w[2] * t[2]
        wn = (w[0] - s * t[0], w[1] - s * t[1], w[2] - s * t[2])
        speed_n = math.sqrt(wn[0] * wn[0] + wn[1] * wn[1] + wn[2] * wn[2])
        cn = normal[e]
        ct = tangential[e]
        for k in range(dim):
            f = -cn * speed_n * wn[k] - ct * abs(s) * s * t[k]
            force[e, k] += 0.5 * f
            force[e + 1, k] += 0.5 * f
        # ∂(edge force)/∂w = −[C_n·(|w_n|·P + w_n w_nᵀ/|w_n|) + 2·C_t·|s|·t tᵀ], P = I − t tᵀ; w = (v_e + v_{e+1})/2
        # and each node takes half the force: ¼ of each entry on every node pair, into the band's lower part. Each
        # entry is added where it is computed: through a small array allocated per call and a helper called per
        # edge, the kernel took 1.6-1.7 times as long (the same arithmetic)
        for a in range(dim):
            for b in range(dim):
                projector = (1.0 if a == b else 0.0) - t[a] * t[b]
                value = cn * speed_n * projector + 2.0 * ct * abs(s) * t[a] * t[b]
                if speed_n > 0.0:
                    value += cn * wn[a] * wn[b] / speed_n
                value = quarter * value
                row, column = stride * e + a, stride * e + b
                if row >= column:
                    band[row, kd - row + column] += value
                    band[row + stride, kd - row + column] += value
                band[row + stride, kd - row - stride + column] += value
        start, v_start = end, v_end


@kernel(python=True)
def added_mass(start_positions, accelerations, edge_mass, acceleration_derivative, stride, force, band):
    """Added-mass force −Σ ½·m_a·(I − t tᵀ)·a_node of every edge of one rod, with tangents at the start of the
    step; adds the force to ``force`` (N, D) and ½·m_a·(I − t tᵀ)·∂a/∂q on the node blocks of ``band``."""
    n_nodes, dim = start_positions.shape
    kd = band.shape[1] - 1
    start = _padded(start_positions, 0, dim)
    for e in range(n_nodes - 1):
        end = _padded(start_positions, e + 1, dim)
        t = _unit_tangent(start, end)
        half = 0.5 * edge_mass[e]
        # each entry ½·m_a·(δ_ab − t_a·t_b) computed where it is used, not kept in a small array allocated per call:
        # the kernel then takes about 0.6 of the time, planar and 3-D (the same arithmetic)
        for node in (e, e + 1):
            for a in range(dim):
                f = 0.0
                for b in range(dim):
                    f -= half * ((1.0 if a == b else 0.0) - t[a] * t[b]) * accelerations[node, b]
                force[node, a] += f
                row = stride * node + a
                for b in range(a + 1):
                    band[row, kd - a + b] += acceleration_derivative * (half * ((1.0 if a == b else 0.0)
                                                                                 - t[a] * t[b]))
        start = end


__all__ = ["rod_water_velocity", "project_water", "linear_damping", "morison_drag", "added_mass"]
