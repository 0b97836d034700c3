"""Scene configuration: frozen, validated dataclasses in SI units, and named presets.

A scene is built from parts: a :class:`Material` and a radius profile make a :class:`FingerDesign`; fingers placed
around the palm make a :class:`GripperDesign`; a gripper, the force models acting on it, the actuation and the time
settings make a :class:`Scene`. Every invalid value raises ``ValueError`` naming the field, its unit and the allowed
range. Derived quantities (stiffnesses, masses) are computed from these, never stored twice.

The paper's scene ("seed scene", ``../shared/design/physics.md`` §1) is :func:`paper_scene`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from .contact import Capsule, ContactSettings, GraspedObject, Sphere
from .forces import ForceModel, Gravity, StokesDrag
from .hydrodynamics import MorisonDrag, fluid_forces
from .integrators import INTEGRATORS
from .validation import check_range

ClampConvention = Literal["paper", "accurate", "free"]
RodModel = Literal["planar", "3d"]
Integrator = Literal["backward_euler", "implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki"]

WATER_VISCOSITY = 1.0e-3
"""Dynamic viscosity of water at about 20 °C [Pa·s]."""


@dataclass(frozen=True)
class Material:
    """An elastomer, treated as linear elastic and incompressible (shear modulus E/3)."""

    name: str
    youngs_modulus: float
    """Young's modulus E [Pa]."""
    density: float
    """Mass density ρ [kg/m³]."""

    def __post_init__(self) -> None:
        check_range("Material", "youngs_modulus", self.youngs_modulus, "Pa", 0.0)
        check_range("Material", "density", self.density, "kg/m³", 0.0)

    @property
    def shear_modulus(self) -> float:
        """Shear modulus G = E/3 [Pa] (incompressible)."""
        return self.youngs_modulus / 3.0


ELASTOSIL_MA_4601 = Material("Elastosil MA 4601", youngs_modulus=386.66e3, density=1130.0)
SOFT_TRANSLUCENT_SILICONE = Material("Soft Translucent silicone", youngs_modulus=169.56e3, density=1100.0)


def linear_taper(base_radius: float, tip_radius: float, n_nodes: int) -> tuple[float, ...]:
    """Per-node radii [m] decreasing linearly from ``base_radius`` at node 0 to ``tip_radius`` at the tip."""
    return tuple(float(r) for r in np.linspace(base_radius, tip_radius, n_nodes))


@dataclass(frozen=True)
class FingerDesign:
    """One finger: a straight rod of circular cross-section, clamped at its base.

    ``radius`` is either one radius for the whole finger or one radius per node (variable stiffness). Bending and
    twisting stiffness and lumped mass at node i follow the node's radius; the stretching stiffness of an edge follows
    the mean radius of its two nodes.

    Clamp conventions (``../shared/design/physics.md`` §4):

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


@dataclass(frozen=True)
class NewtonSettings:
    """Stopping rule of Newton's method inside each implicit step."""

    relative_tolerance: float = 1e-6
    """Stop when every free force residual is below ``relative_tolerance``·EI/L² [N] (EI at the base), and every
    moment residual below ``relative_tolerance``·EI/L [N·m]. Dimensionless."""
    max_iterations: int = 25
    max_step_halvings: int = 4
    """When Newton fails, or the contact corrector spends its budget, the step is retried as two half steps, each of
    which may be halved again, up to this many times (at most 2**max_step_halvings substeps). 0 turns adaptive
    substepping off."""

    def __post_init__(self) -> None:
        check_range("NewtonSettings", "relative_tolerance", self.relative_tolerance, "(dimensionless)", 0.0, 1.0)
        if not isinstance(self.max_iterations, (int, np.integer)) or not 1 <= self.max_iterations <= 1000:
            raise ValueError(f"NewtonSettings.max_iterations = {self.max_iterations!r} is outside the allowed "
                             f"range [1, 1000] (integer count)")
        if not isinstance(self.max_step_halvings, (int, np.integer)) or not 0 <= self.max_step_halvings <= 20:
            raise ValueError(f"NewtonSettings.max_step_halvings = {self.max_step_halvings!r} is outside the allowed "
                             f"range [0, 20] (integer count)")


@dataclass(frozen=True)
class Scene:
    """Everything needed to run a simulation: gripper, forces, actuation and time settings."""

    gripper: GripperDesign
    forces: tuple[ForceModel, ...] = (Gravity(),)
    """The force models acting on the fingers; only these are evaluated."""
    model: RodModel = "planar"
    """``"planar"``: each finger moves in its own vertical plane (2 DOF per node, no twist).
    ``"3d"``: full discrete elastic rod with twist (3 DOF per node plus one twist angle per edge)."""
    time_step: float = 0.01
    """Physics time step Δt [s]."""
    duration: float = 1.0
    """Simulated time T for scripted runs [s]."""
    natural_curvature_rate: float = -0.15
    """Rate of the scripted natural-curvature ramp κ̄(t) = rate·t [1/s] (κ̄ is dimensionless integrated curvature;
    negative curls the fingers toward −z)."""
    newton: NewtonSettings = field(default_factory=NewtonSettings)
    grasped_object: GraspedObject | None = None
    """The object the fingers may touch (a :class:`Sphere`, or a :class:`Capsule` in 3-D); None for no contact at
    all (no search, no cost)."""
    integrator: Integrator = "backward_euler"
    """Time integrator, a name from :data:`~.integrators.INTEGRATORS`."""
    contact: ContactSettings = field(default_factory=ContactSettings)

    def __post_init__(self) -> None:
        if self.grasped_object is not None and not isinstance(self.grasped_object, (Sphere, Capsule)):
            raise ValueError(f"Scene.grasped_object must be a Sphere, a Capsule or None, got "
                             f"{type(self.grasped_object).__name__}")
        if isinstance(self.grasped_object, Capsule) and self.model != "3d":
            raise ValueError("Scene.grasped_object: contact with a Capsule needs Scene.model = '3d' (a vertical finger "
                             "plane cuts a capsule in a general curve)")
        if self.integrator not in INTEGRATORS:
            raise ValueError(f"Scene.integrator = {self.integrator!r} is not one of "
                             f"{', '.join(map(repr, INTEGRATORS))}")
        if self.grasped_object is not None and self.integrator != "backward_euler":
            raise ValueError(f"Scene.integrator = {self.integrator!r}: contact with a grasped object is resolved "
                             f"for 'backward_euler' only, so far")
        if self.model not in ("planar", "3d"):
            raise ValueError(f"Scene.model = {self.model!r} is not one of 'planar', '3d'")
        check_range("Scene", "time_step", self.time_step, "s", 0.0, 10.0)
        check_range("Scene", "duration", self.duration, "s", 0.0)
        check_range("Scene", "natural_curvature_rate", self.natural_curvature_rate, "1/s", -100.0, 100.0,
                    low_inclusive=True)
        object.__setattr__(self, "forces", tuple(self.forces))
        for force in self.forces:
            if not isinstance(force, ForceModel):
                raise ValueError(f"Scene.forces must hold ForceModel instances, got {type(force).__name__}")
            if isinstance(force, StokesDrag):
                force.check_nodes(self.gripper.finger.n_nodes)
        drags = [f for f in self.forces if isinstance(f, MorisonDrag)]
        if len(drags) > 1:
            raise ValueError(f"Scene.forces holds {len(drags)} MorisonDrag models; at most one is allowed (the water "
                             f"has one current)")

    @property
    def n_steps(self) -> int:
        """Number of steps of a scripted run, round(T/Δt)."""
        return max(1, int(round(self.duration / self.time_step)))


PAPER_RADIUS = 0.02
"""Finger cross-section radius of the paper's scene [m]."""


def paper_finger(material: Material = ELASTOSIL_MA_4601, variable_stiffness: bool = False,
                 clamp: ClampConvention = "paper", n_nodes: int = 20) -> FingerDesign:
    """The paper's finger: L = 0.2 m, N = 20, r = 0.02 m, or its taper r_i = 0.001·(N − i) [m]."""
    radius = linear_taper(PAPER_RADIUS, PAPER_RADIUS / n_nodes, n_nodes) if variable_stiffness else PAPER_RADIUS
    return FingerDesign(length=0.2, n_nodes=n_nodes, radius=radius, material=material, clamp=clamp)


PAPER_DEFECTIVE_DRAG = StokesDrag(viscosity=1000.0, nodes=(2, 3, 4))
"""The drag that produced the paper's published curves (physics.md §2): η = 10⁶ × water's, on nodes 2–4 only."""


Medium = Literal["air", "stokes", "water"]


def paper_scene(model: RodModel = "planar", *, material: Material = ELASTOSIL_MA_4601,
                variable_stiffness: bool = False, medium: Medium | tuple[ForceModel, ...] = "stokes",
                grasped_object: GraspedObject | None = None) -> Scene:
    """The paper's three-finger scene, exactly as ``physics.md`` §1 gives it.

    The ramp κ̄ = −0.15·t, backward Euler at Δt = 0.01 s for T = 1 s, the paper's clamp, and full weight. ``medium``
    chooses the fluid forces (:func:`~.hydrodynamics.fluid_forces`): ``"stokes"`` is the paper's per-node Stokes drag
    at water's viscosity and no buoyancy; ``"air"`` has no fluid force; ``"water"`` has buoyancy, Morison drag and
    added mass. A tuple of force models replaces them, e.g. ``(PAPER_DEFECTIVE_DRAG,)``. ``grasped_object`` adds
    contact, e.g. with the paper's fixed ball :data:`~.contact.PAPER_BALL`.
    """

    forces: tuple[ForceModel, ...] = (Gravity(),)
    forces += tuple(medium) if isinstance(medium, tuple) else fluid_forces(medium)
    finger = paper_finger(material, variable_stiffness)
    return Scene(gripper=GripperDesign(finger), forces=forces, model=model, grasped_object=grasped_object)


def cantilever_scene(n_nodes: int = 20, clamp: ClampConvention = "accurate", model: RodModel = "planar") -> Scene:
    """The shared cantilever benchmark of ``physics.md`` §4: L = 0.1 m, r = 0.01 m, E = 386.66 kPa,
    ρ = 1200 kg/m³, gravity along −z, clamped horizontally at the wall x = 0, no actuation."""
    material = Material("cantilever silicone", youngs_modulus=386.66e3, density=1200.0)
    finger = FingerDesign(length=0.1, n_nodes=n_nodes, radius=0.01, material=material, clamp=clamp)
    return Scene(gripper=GripperDesign(finger, finger_angles=(0.0,)), forces=(Gravity(),), model=model,
                 natural_curvature_rate=0.0)


__all__ = ["Material", "FingerDesign", "GripperDesign", "NewtonSettings", "Scene", "ELASTOSIL_MA_4601",
           "SOFT_TRANSLUCENT_SILICONE", "WATER_VISCOSITY", "PAPER_DEFECTIVE_DRAG", "linear_taper", "paper_finger",
           "paper_scene", "cantilever_scene", "check_range", "replace", "Medium"]
