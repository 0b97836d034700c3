"""What a gripper is made of and how it is shaped: materials, finger designs and the gripper, in SI units.

A :class:`Material` and a radius profile make a :class:`FingerDesign`; fingers placed around the palm make a
:class:`GripperDesign`. Every invalid value raises ``ValueError`` naming the field, its unit and the allowed range.
Derived quantities (stiffnesses, masses) are computed from these (:mod:`.discretization`), never stored twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from .validation import check_range

ClampConvention = Literal["paper", "accurate", "free"]


@dataclass(frozen=True)
class Material:
    """An elastomer, treated as incompressible (shear modulus E/3) and linear viscoelastic of the Kelvin–Voigt kind:
    stress E·(ε + τ·ε̇) in stretch, bend and twist alike."""

    name: str
    youngs_modulus: float
    """Young's modulus E [Pa]."""
    density: float
    """Mass density ρ [kg/m³]."""
    retardation_time: float = 0.0
    """Kelvin–Voigt retardation time τ [s]: the loss factor at angular frequency ω is τ·ω, so a mode of frequency ω
    has the damping ratio τ·ω/2. 0 is purely elastic."""

    def __post_init__(self) -> None:
        check_range("Material", "youngs_modulus", self.youngs_modulus, "Pa", 0.0)
        check_range("Material", "density", self.density, "kg/m³", 0.0)
        check_range("Material", "retardation_time", self.retardation_time, "s", 0.0, 1.0, low_inclusive=True)
        object.__setattr__(self, "retardation_time", float(self.retardation_time))  # one compiled type for it

    @property
    def shear_modulus(self) -> float:
        """Shear modulus G = E/3 [Pa] (incompressible)."""
        return self.youngs_modulus / 3.0


SILICONE_RETARDATION_TIME = 8e-3
"""The Kelvin–Voigt retardation time given to the silicones here [s]: a loss factor τ·ω of 0.1 at 2 Hz, the paper
finger's first bending mode in water. Silicone rubbers show loss factors of order 0.05–0.2 at a few hertz; this value
is representative, not measured on these materials (``docs/model.md`` §5)."""


ELASTOSIL_MA_4601 = Material("Elastosil MA 4601", youngs_modulus=386.66e3, density=1130.0,
                             retardation_time=SILICONE_RETARDATION_TIME)


SOFT_TRANSLUCENT_SILICONE = Material("Soft Translucent silicone", youngs_modulus=169.56e3, density=1100.0,
                                     retardation_time=SILICONE_RETARDATION_TIME)


def linear_taper(base_radius: float, tip_radius: float, n_nodes: int) -> tuple[float, ...]:
    """Per-node radii [m] decreasing linearly from ``base_radius`` at node 0 to ``tip_radius`` at the tip."""
    return tuple(float(r) for r in np.linspace(base_radius, tip_radius, n_nodes))


@dataclass(frozen=True)
class FingerDesign:
    """One finger: a straight rod of circular cross-section, clamped at its base.

    ``radius`` is either one radius for the whole finger or one radius per node (variable stiffness). Bending and
    twisting stiffness and lumped mass at node i follow the node's radius; the stretching stiffness of an edge follows
    the mean radius of its two nodes.

    Clamp conventions (``docs/model.md`` §4):

    - ``"paper"``: nodes 0 and 1 fixed at s = 0 and s = Δl, first edge rigid, Δl = L/(N − 1). The bending region of
      node 1 starts half an edge beyond the wall, so a cantilever under-deflects by about 10 % at N = 20.
    - ``"accurate"``: the rigid first edge is centred on the wall (nodes 0 and 1 at s = −Δl/2 and +Δl/2,
      Δl = L/(N − 1.5)), so the bending region of node 1 starts exactly at the wall and the tip sits at s = L.
    - ``"free"``: nothing is held; a free rod of length L (validation of fluid forces, free objects).
    """

    length: float
    """Free length L from the palm to the tip [m]."""
    n_nodes: int
    """Number of nodes N (N − 1 edges)."""
    radius: float | tuple[float, ...]
    """Cross-section radius [m]: a single value, or one value per node from base to tip."""
    material: Material
    clamp: ClampConvention = "paper"

    def __post_init__(self) -> None:
        check_range("FingerDesign", "length", self.length, "m", 0.0)
        if not isinstance(self.n_nodes, (int, np.integer)) or not 4 <= self.n_nodes <= 10_000:
            raise ValueError(f"FingerDesign.n_nodes = {self.n_nodes!r} (count) is outside the allowed range "
                             f"[4, 10000] and must be an integer")
        if self.clamp not in ("paper", "accurate", "free"):
            raise ValueError(f"FingerDesign.clamp = {self.clamp!r} is not one of 'paper', 'accurate', 'free'")
        if isinstance(self.radius, (tuple, list, np.ndarray)):
            if len(self.radius) != self.n_nodes:
                raise ValueError(f"FingerDesign.radius has {len(self.radius)} values; a per-node radius profile "
                                 f"needs exactly n_nodes = {self.n_nodes} values [m]")
            object.__setattr__(self, "radius", tuple(float(r) for r in self.radius))
            for r in self.radius:
                check_range("FingerDesign", "radius", r, "m", 0.0, self.length)
        else:
            check_range("FingerDesign", "radius", self.radius, "m", 0.0, self.length)

    @property
    def node_radius(self) -> np.ndarray:
        """Radius at each node [m], shape (N,)."""
        return np.broadcast_to(np.asarray(self.radius, dtype=float), (self.n_nodes,)).copy()

    @property
    def edge_length(self) -> float:
        """Rest length Δl of every edge [m]."""
        offset = 1.5 if self.clamp == "accurate" else 1.0
        return self.length / (self.n_nodes - offset)

    @property
    def node_arclength(self) -> np.ndarray:
        """Rest position of each node along the finger, measured from the palm [m], shape (N,)."""
        start = -0.5 if self.clamp == "accurate" else 0.0
        return (start + np.arange(self.n_nodes)) * self.edge_length


@dataclass(frozen=True)
class GripperDesign:
    """Identical fingers whose bases sit at the palm centre (the origin), pointing radially in the plane z = 0."""

    finger: FingerDesign
    finger_angles: tuple[float, ...] = (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    """Direction of each finger about +z [rad]; finger k points along (cos a_k, sin a_k, 0)."""

    def __post_init__(self) -> None:
        if len(self.finger_angles) < 1:
            raise ValueError("GripperDesign.finger_angles must list at least one angle [rad]")
        for a in self.finger_angles:
            check_range("GripperDesign", "finger_angles", a, "rad", -2 * math.pi, 2 * math.pi, low_inclusive=True)

    @property
    def n_fingers(self) -> int:
        return len(self.finger_angles)


def without_material_damping(gripper: GripperDesign) -> GripperDesign:
    """``gripper`` with its fingers' material purely elastic (retardation time 0), as the paper has it."""
    finger = gripper.finger
    material = replace(finger.material, retardation_time=0.0)
    return replace(gripper, finger=replace(finger, material=material))


PAPER_RADIUS = 0.02
"""Finger cross-section radius of the paper's scene [m]."""


def paper_finger(material: Material = ELASTOSIL_MA_4601, variable_stiffness: bool = False,
                 clamp: ClampConvention = "paper", n_nodes: int = 20) -> FingerDesign:
    """The paper's finger: L = 0.2 m, N = 20, r = 0.02 m, or its taper r_i = 0.001·(N − i) [m]."""
    radius = linear_taper(PAPER_RADIUS, PAPER_RADIUS / n_nodes, n_nodes) if variable_stiffness else PAPER_RADIUS
    return FingerDesign(length=0.2, n_nodes=n_nodes, radius=radius, material=material, clamp=clamp)


__all__ = ["ClampConvention", "Material", "SILICONE_RETARDATION_TIME", "ELASTOSIL_MA_4601", "SOFT_TRANSLUCENT_SILICONE",
           "linear_taper", "FingerDesign", "GripperDesign", "without_material_damping", "PAPER_RADIUS", "paper_finger"]
