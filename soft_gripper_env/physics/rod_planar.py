"""Elastic energy of a planar discrete elastic rod: stretching and bending, with analytic gradient and Hessian.

Notation (one rod; arrays carry a leading rod axis R):

=======  ===============================================================  ==========
symbol   meaning                                                          unit
=======  ===============================================================  ==========
x_i      node position (s, z) in the finger's plane                       m
e, f     the edges x_i − x_{i−1} and x_{i+1} − x_i around node i          m
l̄        rest edge length                                                 m
EA       stretching stiffness of an edge                                  N
EI       bending stiffness at a node                                      N·m²
l_i      Voronoi (rest) length of node i                                  m
φ_i      signed turning angle from e to f (positive counter-clockwise)    rad
κ_i      integrated curvature 2·tan(φ_i/2)                                1
κ̄        natural curvature, the same at every interior node of a rod      1
=======  ===============================================================  ==========

E_stretch = ½·EA·l̄·(|e|/l̄ − 1)² per edge, E_bend = EI/(2·l_i)·(κ_i − κ̄)² per interior node (physics.md §1).
φ = θ(f) − θ(e) with θ(e) = atan2(e_z, e_s), whose derivatives are closed-form, so the Hessian is exact.
Forces (−∇E) and the lower band of ∇²E are *accumulated* into the caller's arrays.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .linalg import scatter_contiguous


@njit(cache=True, inline="always")
def _stretch(q, r, i, rest_length, stretch_stiffness, force, band, hessian, accumulate_hessian):
    """Stretch energy of edge i of rod r; adds force and Hessian (DOFs of nodes i, i+1)."""
    ex = q[r, i + 1, 0] - q[r, i, 0]
    ez = q[r, i + 1, 1] - q[r, i, 1]
    length = math.sqrt(ex * ex + ez * ez)
    tx = ex / length
    tz = ez / length
    l0 = rest_length[i]
    ea = stretch_stiffness[i]
    tension = ea * (length / l0 - 1.0)
    energy = 0.5 * ea * l0 * (length / l0 - 1.0) ** 2
    force[r, i, 0] += tension * tx
    force[r, i, 1] += tension * tz
    force[r, i + 1, 0] -= tension * tx
    force[r, i + 1, 1] -= tension * tz
    if accumulate_hessian:
        axial = ea / l0
        lateral = tension / length
        kxx = axial * tx * tx + lateral * (1.0 - tx * tx)
        kxz = (axial - lateral) * tx * tz
        kzz = axial * tz * tz + lateral * (1.0 - tz * tz)
        for a in range(2):
            for b in range(2):
                sign = 1.0 if a == b else -1.0
                hessian[2 * a, 2 * b] = sign * kxx
                hessian[2 * a, 2 * b + 1] = sign * kxz
                hessian[2 * a + 1, 2 * b] = sign * kxz
                hessian[2 * a + 1, 2 * b + 1] = sign * kzz
        scatter_contiguous(band[r], 2 * i, hessian, 4)
    return energy


@njit(cache=True, inline="always")
def _bend(q, r, i, bend_stiffness, voronoi_length, kappa_bar, force, band, grad_phi, hess_phi, hessian,
          accumulate_hessian):
    """Bending energy at interior node i of rod r; adds force and Hessian (DOFs of nodes i−1, i, i+1)."""
    ex = q[r, i, 0] - q[r, i - 1, 0]
    ez = q[r, i, 1] - q[r, i - 1, 1]
    fx = q[r, i + 1, 0] - q[r, i, 0]
    fz = q[r, i + 1, 1] - q[r, i, 1]
    e2 = ex * ex + ez * ez
    f2 = fx * fx + fz * fz
    kappa = 2.0 * (ex * fz - ez * fx) / (math.sqrt(e2 * f2) + ex * fx + ez * fz)  # 2·tan(φ/2)
    # ∂θ/∂e = (−e_z, e_s)/|e|²
    gex, gez = -ez / e2, ex / e2
    gfx, gfz = -fz / f2, fx / f2
    grad_phi[0], grad_phi[1] = gex, gez
    grad_phi[2], grad_phi[3] = -gex - gfx, -gez - gfz
    grad_phi[4], grad_phi[5] = gfx, gfz
    k = bend_stiffness[i] / voronoi_length[i]
    dk = kappa - kappa_bar
    dkappa = 1.0 + 0.25 * kappa * kappa  # dκ/dφ
    energy = 0.5 * k * dk * dk
    g = k * dk * dkappa
    for a in range(3):
        force[r, i - 1 + a, 0] -= g * grad_phi[2 * a]
        force[r, i - 1 + a, 1] -= g * grad_phi[2 * a + 1]
    if accumulate_hessian:
        # ∂²θ/∂e² = [[2 e_s e_z, e_z² − e_s²], [e_z² − e_s², −2 e_s e_z]]/|e|⁴; φ = θ(f) − θ(e)
        hess_phi[:, :] = 0.0
        e4 = e2 * e2
        f4 = f2 * f2
        he = (2.0 * ex * ez / e4, (ez * ez - ex * ex) / e4, -2.0 * ex * ez / e4)  # (ss, sz, zz)
        hf = (2.0 * fx * fz / f4, (fz * fz - fx * fx) / f4, -2.0 * fx * fz / f4)
        for a in range(2):
            for b in range(2):
                hea = he[a + b]
                hfa = hf[a + b]
                hess_phi[a, b] -= hea
                hess_phi[a, 2 + b] += hea
                hess_phi[2 + a, b] += hea
                hess_phi[2 + a, 2 + b] += hfa - hea
                hess_phi[2 + a, 4 + b] -= hfa
                hess_phi[4 + a, 2 + b] -= hfa
                hess_phi[4 + a, 4 + b] += hfa
        d2kappa = 0.5 * kappa * dkappa  # d²κ/dφ²
        outer_coeff = k * (dkappa * dkappa + dk * d2kappa)
        for a in range(6):
            for b in range(6):
                hessian[a, b] = outer_coeff * grad_phi[a] * grad_phi[b] + g * hess_phi[a, b]
        scatter_contiguous(band[r], 2 * (i - 1), hessian, 6)
    return energy


@njit(cache=True)
def planar_elastic(q, rest_length, stretch_stiffness, bend_stiffness, voronoi_length, natural_curvature,
                   force, band, accumulate_hessian):
    """Elastic energy of every rod, (R,); adds −∇E to ``force`` (R, N, 2) and ∇²E to ``band`` (R, 2N, 6).

    ``natural_curvature`` holds κ̄ per rod, (R,).
    """
    n_rods, n_nodes = q.shape[0], q.shape[1]
    energy = np.zeros(n_rods)
    grad_phi = np.empty(6)
    hess_phi = np.empty((6, 6))
    hessian = np.empty((6, 6))
    for r in range(n_rods):
        for i in range(n_nodes - 1):
            energy[r] += _stretch(q, r, i, rest_length, stretch_stiffness, force, band, hessian, accumulate_hessian)
        for i in range(1, n_nodes - 1):
            energy[r] += _bend(q, r, i, bend_stiffness, voronoi_length, natural_curvature[r], force, band,
                               grad_phi, hess_phi, hessian, accumulate_hessian)
    return energy


def turning_angles(q: np.ndarray) -> np.ndarray:
    """Signed turning angle φ_i [rad] at the interior nodes, (..., N − 2), from planar coordinates (..., N, 2)."""
    e = np.diff(q, axis=-2)
    cross = e[..., :-1, 0] * e[..., 1:, 1] - e[..., :-1, 1] * e[..., 1:, 0]
    dot = np.einsum("...k,...k->...", e[..., :-1, :], e[..., 1:, :])
    return np.arctan2(cross, dot)
