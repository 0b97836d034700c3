"""The discrete rod: degree-of-freedom layout, lumped masses and stiffnesses of one finger design.

Layout of the generalized coordinates ``q`` of every rod, shape (R, N, S):

========  ===================================================  ==========================
model     per node i (S entries)                               fixed DOFs
========  ===================================================  ==========================
planar    (s_i, z_i): position in the finger's vertical plane   nodes 0 and 1
          [m], s along the finger's radial direction
3d        (x_i, y_i, z_i, θ_i) [m, m, m, rad]; θ_i is the       nodes 0 and 1, θ_0, and the
          twist angle of edge i (i ≤ N − 2)                     unused θ_{N−1}
========  ===================================================  ==========================

Flattened per rod, node i owns DOFs S·i … S·i + S − 1, so every bending stencil (three nodes and, in 3-D, the two
twist angles between them) is a contiguous run of DOFs and the Newton matrix is banded with half-bandwidth
``band_width`` = 5 (planar) or 10 (3-D).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .design import GripperDesign


@dataclass(frozen=True, eq=False)
class Discretization:
    """Per-node and per-edge quantities of one finger design (identical for every finger and batch member)."""

    model: str
    n_nodes: int
    stride: int
    """Entries per node S in ``q``: 2 (planar) or 4 (3-D)."""
    dim: int
    """Spatial dimension of a node position D: 2 (planar) or 3."""
    vertical_axis: int
    """Index of the z component within a node position."""
    node_radius: np.ndarray
    """Cross-section radius at each node [m], (N,)."""
    node_mass: np.ndarray
    """Lumped mass of each node [kg], (N,)."""
    node_volume: np.ndarray
    """Lumped volume of each node [m³], (N,)."""
    rest_edge_length: np.ndarray
    """Rest length of each edge [m], (N − 1,)."""
    stretch_stiffness: np.ndarray
    """EA of each edge [N], (N − 1,)."""
    bend_stiffness: np.ndarray
    """EI at each node [N·m²], (N,); used at interior nodes."""
    twist_stiffness: np.ndarray
    """GJ at each node [N·m²], (N,); used at interior nodes (3-D only)."""
    voronoi_length: np.ndarray
    """Rest length attributed to each node [m], (N,)."""
    retardation_time: float
    """The material's Kelvin–Voigt retardation time τ [s] (:attr:`~.design.Material.retardation_time`)."""
    dof_mass: np.ndarray
    """Inertia of each DOF of one rod [kg or kg·m²], (N·S,)."""
    free: np.ndarray
    """Which DOFs of one rod are free, (N·S,) bool."""
    residual_scale: np.ndarray
    """Per-DOF tolerance unit of the Newton residual [N or N·m], (N·S,)."""
    rest_q: np.ndarray
    """Rest (straight) coordinates of one rod of each finger, (F, N, S)."""
    finger_directions: np.ndarray
    """Unit radial direction of each finger in the world frame, (F, 3)."""

    @property
    def band_width(self) -> int:
        """Half-bandwidth kd of the Newton matrix of one rod."""
        return 3 * self.stride - 1

    @property
    def n_dofs(self) -> int:
        return self.n_nodes * self.stride

    def world_positions(self, q: np.ndarray) -> np.ndarray:
        """World node positions [m], (..., B, F, N, 3), from coordinates ``q`` of shape (..., B, F, N, S): a batch,
        or any leading axes before it (a run's steps)."""
        if self.model == "3d":
            return q[..., :3].copy()
        d = self.finger_directions  # (F, 3)
        s = q[..., 0]
        z = q[..., 1]
        out = s[..., None] * d[None, :, None, :]
        out[..., 2] += z
        return out

    @classmethod
    def of(cls, gripper: GripperDesign, model: str, relative_tolerance: float) -> Discretization:
        """The discretization of ``gripper``'s fingers in the rod ``model`` ("planar" or "3d"), with Newton's
        tolerance unit ``relative_tolerance``·EI/L² per DOF (:class:`~.scene.NewtonSettings`)."""
        finger = gripper.finger
        material = finger.material
        n = finger.n_nodes
        radius = finger.node_radius
        dl = finger.edge_length
        edge_radius = 0.5 * (radius[:-1] + radius[1:])
        voronoi = np.full(n, dl)
        voronoi[[0, -1]] = 0.5 * dl
        area = math.pi * radius**2
        node_volume = area * voronoi
        node_mass = material.density * node_volume
        planar = model == "planar"
        stride, dim = (2, 2) if planar else (4, 3)

        dof_mass = np.zeros((n, stride))
        dof_mass[:, :dim] = node_mass[:, None]
        residual_scale = np.ones((n, stride))
        free = np.ones((n, stride), dtype=bool)
        if finger.clamp != "free":
            free[:2, :] = False  # nodes 0 and 1 clamp the first edge (and, in 3-D, its twist θ_0)
        if not planar:
            edge_mass = material.density * math.pi * edge_radius**2 * dl
            dof_mass[:-1, 3] = 0.5 * edge_mass * edge_radius**2
            free[-1, 3] = False  # θ_{N−1} does not exist
            residual_scale[:, 3] = finger.length  # moments [N·m] are compared with EI/L, forces with EI/L²
        bending_base = material.youngs_modulus * math.pi * radius[0] ** 4 / 4.0
        residual_scale *= relative_tolerance * bending_base / finger.length**2

        angles = np.asarray(gripper.finger_angles)
        directions = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
        s = finger.node_arclength
        rest = np.zeros((len(angles), n, stride))
        if planar:
            rest[:, :, 0] = s
        else:
            rest[:, :, :3] = s[None, :, None] * directions[:, None, :]

        return cls(model=model, n_nodes=n, stride=stride, dim=dim, vertical_axis=dim - 1,
                   node_radius=radius, node_mass=node_mass, node_volume=node_volume,
                   rest_edge_length=np.full(n - 1, dl),
                   stretch_stiffness=material.youngs_modulus * math.pi * edge_radius**2,
                   bend_stiffness=material.youngs_modulus * math.pi * radius**4 / 4.0,
                   twist_stiffness=material.shear_modulus * math.pi * radius**4 / 2.0,
                   voronoi_length=voronoi, retardation_time=material.retardation_time, dof_mass=dof_mass.ravel(),
                   free=free.ravel(),
                   residual_scale=residual_scale.ravel(), rest_q=rest, finger_directions=directions)
