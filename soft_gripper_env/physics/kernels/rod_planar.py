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

E_stretch = ½·EA·l̄·(|e|/l̄ − 1)² per edge, E_bend = EI/(2·l_i)·(κ_i − κ̄)² per interior node (``docs/design.md``).
φ = θ(f) − θ(e) with θ(e) = atan2(e_z, e_s), whose derivatives are closed-form, so the Hessian is exact.
Forces (−∇E) and the lower band of ∇²E are *accumulated* into the caller's arrays.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel

# The energy terms of one edge or node are numbers in, numbers out, without a branch, and the rod's loop writes them
# into its arrays.


@kernel(inline=True)
def _stretch(q, i, l0, ea):
    """Stretch energy of edge i of one rod, of rest length ``l0`` [m] and stiffness ``ea`` [N]: returns the energy
    [J], the force on node i (s, z) [N] (node i+1 takes its opposite) and the block K (ss, sz, zz) [N/m] of the
    Hessian [[K, −K], [−K, K]] over nodes i, i+1."""
    ex = q[i + 1, 0] - q[i, 0]
    ez = q[i + 1, 1] - q[i, 1]
    length = math.sqrt(ex * ex + ez * ez)
    tx = ex / length
    tz = ez / length
    tension = ea * (length / l0 - 1.0)
    energy = 0.5 * ea * l0 * (length / l0 - 1.0) ** 2
    axial = ea / l0
    lateral = tension / length
    kxx = axial * tx * tx + lateral * (1.0 - tx * tx)
    kxz = (axial - lateral) * tx * tz
    kzz = axial * tz * tz + lateral * (1.0 - tz * tz)
    return energy, tension * tx, tension * tz, kxx, kxz, kzz


@kernel(inline=True)
def _bend(q, i, k, kappa_bar):
    """Bending energy at interior node i of one rod, of stiffness ``k`` = EI/l_i [N·m]: returns the energy [J], its
    gradient over the stencil (s, z of nodes i−1, i, i+1) [N] and the lower triangle of its Hessian there, row by
    row (21 entries) [N/m]."""
    ex = q[i, 0] - q[i - 1, 0]
    ez = q[i, 1] - q[i - 1, 1]
    fx = q[i + 1, 0] - q[i, 0]
    fz = q[i + 1, 1] - q[i, 1]
    e2 = ex * ex + ez * ez
    f2 = fx * fx + fz * fz
    kappa = 2.0 * (ex * fz - ez * fx) / (math.sqrt(e2 * f2) + ex * fx + ez * fz)  # 2·tan(φ/2)
    # ∂θ/∂e = (−e_z, e_s)/|e|²
    gex, gez = -ez / e2, ex / e2
    gfx, gfz = -fz / f2, fx / f2
    gp0, gp1, gp2, gp3, gp4, gp5 = gex, gez, -gex - gfx, -gez - gfz, gfx, gfz  # ∇φ over the stencil
    dk = kappa - kappa_bar
    dkappa = 1.0 + 0.25 * kappa * kappa  # dκ/dφ
    energy = 0.5 * k * dk * dk
    g = k * dk * dkappa
    gradient = (g * gp0, g * gp1, g * gp2, g * gp3, g * gp4, g * gp5)
    # ∂²θ/∂e² = [[2 e_s e_z, e_z² − e_s²], [e_z² − e_s², −2 e_s e_z]]/|e|⁴, stored as (ss, sz, zz);
    # φ = θ(f) − θ(e) couples nodes (0, 1) through e and (1, 2) through f.
    e4 = e2 * e2
    f4 = f2 * f2
    he0, he1, he2 = 2.0 * ex * ez / e4, (ez * ez - ex * ex) / e4, -2.0 * ex * ez / e4
    hf0, hf1, hf2 = 2.0 * fx * fz / f4, (fz * fz - fx * fx) / f4, -2.0 * fx * fz / f4
    d2kappa = 0.5 * kappa * dkappa  # d²κ/dφ²
    c = k * (dkappa * dkappa + dk * d2kappa)
    # c·∇φ∇φᵀ + g·∇²φ with c = d²E/dφ², row a, column b ≤ a
    hessian = (c * gp0 * gp0 + g * (-he0),
               c * gp1 * gp0 + g * (-he1), c * gp1 * gp1 + g * (-he2),
               c * gp2 * gp0 + g * (he0), c * gp2 * gp1 + g * (he1), c * gp2 * gp2 + g * (hf0 - he0),
               c * gp3 * gp0 + g * (he1), c * gp3 * gp1 + g * (he2), c * gp3 * gp2 + g * (hf1 - he1),
               c * gp3 * gp3 + g * (hf2 - he2),
               c * gp4 * gp0, c * gp4 * gp1, c * gp4 * gp2 + g * (-hf0), c * gp4 * gp3 + g * (-hf1),
               c * gp4 * gp4 + g * (hf0),
               c * gp5 * gp0, c * gp5 * gp1, c * gp5 * gp2 + g * (-hf1), c * gp5 * gp3 + g * (-hf2),
               c * gp5 * gp4 + g * (hf1), c * gp5 * gp5 + g * (hf2))
    return energy, gradient, hessian


@kernel
def planar_elastic_rod(q, rest_length, stretch_stiffness, bend_stiffness, voronoi_length, natural_curvature, force,
                       band, accumulate_hessian):
    """Elastic energy of one rod [J]; adds −∇E to ``force`` (N, 2) and ∇²E to ``band`` (2N, 6).

    ``q`` (N, 2); ``natural_curvature`` κ̄ of the rod.
    """
    energy = 0.0
    n_nodes = q.shape[0]
    kd = band.shape[1] - 1
    for i in range(n_nodes - 1):
        edge_energy, pull_s, pull_z, kss, ksz, kzz = _stretch(q, i, rest_length[i], stretch_stiffness[i])
        energy += edge_energy
        force[i, 0] += pull_s
        force[i, 1] += pull_z
        force[i + 1, 0] -= pull_s
        force[i + 1, 1] -= pull_z
        if accumulate_hessian:
            o = 2 * i
            # lower triangle of [[K, −K], [−K, K]] over (s, z) of nodes i, i+1
            band[o, kd] += kss
            band[o + 1, kd - 1] += ksz
            band[o + 1, kd] += kzz
            band[o + 2, kd - 2] -= kss
            band[o + 2, kd - 1] -= ksz
            band[o + 2, kd] += kss
            band[o + 3, kd - 3] -= ksz
            band[o + 3, kd - 2] -= kzz
            band[o + 3, kd - 1] += ksz
            band[o + 3, kd] += kzz
    for i in range(1, n_nodes - 1):
        node_energy, gradient, hessian = _bend(q, i, bend_stiffness[i] / voronoi_length[i], natural_curvature)
        energy += node_energy
        offset = 2 * (i - 1)
        # these small loops read their tuples at a loop index too, through a switch, which here costs nothing that
        # shows: the same 27 writes spelled out one by one took the same time
        for a in range(6):
            force[i - 1 + a // 2, a % 2] -= gradient[a]
        if accumulate_hessian:
            entry = 0
            for a in range(6):
                for b in range(a + 1):
                    band[offset + a, kd - a + b] += hessian[entry]
                    entry += 1
    return energy


@kernel(python=True, runtime=True)  # it allocates
def planar_elastic(q, rest_length, stretch_stiffness, bend_stiffness, voronoi_length, natural_curvature,
                   force, band, accumulate_hessian):
    """Elastic energy of every rod, (R,); adds −∇E to ``force`` (R, N, 2) and ∇²E to ``band`` (R, 2N, 6).

    ``natural_curvature`` holds κ̄ per rod, (R,).
    """
    energy = np.zeros(q.shape[0])
    for r in range(q.shape[0]):
        energy[r] = planar_elastic_rod(q[r], rest_length, stretch_stiffness, bend_stiffness, voronoi_length,
                                       natural_curvature[r], force[r], band[r], accumulate_hessian)
    return energy

