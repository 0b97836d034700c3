"""The scene: a gripper, the forces on it, its fluid, the grasped object and the solver's settings, and presets.

A scene is built from parts (:mod:`.design`, :mod:`.forces`, :mod:`.fluid`, :mod:`.objects`): fingers placed around
the palm make a gripper; a gripper, the force models acting on it, the fluid, the actuation and the time settings make
a :class:`Scene`. Every invalid value raises ``ValueError`` naming the field, its unit and the allowed range.

The paper's scene (``docs/paper_reproduction.md``) is :func:`paper_scene`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from .design import (
    ELASTOSIL_MA_4601,
    ClampConvention,
    FingerDesign,
    GripperDesign,
    Material,
    paper_finger,
    without_material_damping,
)
from .discretization import Discretization
from .fluid import WATER, Fluid
from .forces import ForceModel, Gravity, fluid_forces
from .objects import Capsule, ContactSettings, GraspedObject, Sphere
from .validation import check_range

RodModel = Literal["planar", "3d"]
Integrator = Literal["backward_euler", "implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki"]
INTEGRATOR_NAMES = ("backward_euler", "implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki")
"""The time integrators a scene may name (``docs/speed_vs_error.md``; they are implemented by the solvers)."""

NATURAL_CURVATURE_LIMIT = 2.0
"""Largest |κ̄| a step accepts (dimensionless): a natural turning angle of 90° per node, 2·atan(κ̄/2). The integrated
curvature κ = 2·tan(φ/2) is singular at φ = 180°, and a finger already curls 18 × 90° = 1620° at this limit. The
same clip as dismech-rl's."""


STEP_HALVINGS_LIMIT = 20
"""The largest :attr:`NewtonSettings.max_step_halvings` allowed (a step in 2²⁰ substeps)."""


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
        halvings = self.max_step_halvings
        if not isinstance(halvings, (int, np.integer)) or not 0 <= halvings <= STEP_HALVINGS_LIMIT:
            raise ValueError(f"NewtonSettings.max_step_halvings = {self.max_step_halvings!r} is outside the "
                             f"allowed range [0, {STEP_HALVINGS_LIMIT}] (integer count)")


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
    fluid: Fluid = WATER
    """The fluid around the gripper (density, viscosity, current); the force models read it."""
    grasped_object: GraspedObject | None = None
    """The object the fingers may touch (a :class:`Sphere`, or a :class:`Capsule` in 3-D); None for no contact at
    all (no search, no cost)."""
    integrator: Integrator = "backward_euler"
    """Time integrator, a name from :data:`INTEGRATOR_NAMES`."""
    contact: ContactSettings = field(default_factory=ContactSettings)

    def __post_init__(self) -> None:
        if self.grasped_object is not None and not isinstance(self.grasped_object, (Sphere, Capsule)):
            raise ValueError(f"Scene.grasped_object must be a Sphere, a Capsule or None, got "
                             f"{type(self.grasped_object).__name__}")
        if isinstance(self.grasped_object, Capsule) and self.model != "3d":
            raise ValueError("Scene.grasped_object: contact with a Capsule needs Scene.model = '3d' (a vertical finger "
                             "plane cuts a capsule in a general curve)")
        if self.integrator not in INTEGRATOR_NAMES:
            raise ValueError(f"Scene.integrator = {self.integrator!r} is not one of "
                             f"{', '.join(map(repr, INTEGRATOR_NAMES))}")
        if not isinstance(self.fluid, Fluid):
            raise ValueError(f"Scene.fluid must be a Fluid, got {type(self.fluid).__name__}")
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
            force.check_finger(self.gripper.finger)

    def discretization(self) -> Discretization:
        """The discrete rod of this scene's fingers (:class:`~.discretization.Discretization`)."""
        return Discretization.of(self.gripper, self.model, self.newton.relative_tolerance)

    @property
    def n_steps(self) -> int:
        """Number of steps of a scripted run, round(T/Δt)."""
        return max(1, int(round(self.duration / self.time_step)))


Medium = Literal["air", "stokes", "water"]


def paper_scene(model: RodModel = "planar", *, material: Material = ELASTOSIL_MA_4601,
                variable_stiffness: bool = False, medium: Medium | tuple[ForceModel, ...] = "stokes",
                grasped_object: GraspedObject | None = None) -> Scene:
    """The paper's three-finger scene, exactly as the paper gives it (``docs/paper_reproduction.md``).

    The ramp κ̄ = −0.15·t, backward Euler at Δt = 0.01 s for T = 1 s, the paper's clamp, and full weight. ``medium``
    chooses the fluid forces (:func:`~.forces.fluid_forces`): ``"stokes"`` is the paper's per-node Stokes drag
    at water's viscosity and no buoyancy; ``"air"`` has no fluid force; ``"water"`` has buoyancy, Morison drag and
    added mass. A tuple of force models replaces them, e.g. ``(PAPER_DEFECTIVE_DRAG,)``. ``grasped_object`` adds
    contact, e.g. with the paper's fixed ball :data:`~.objects.PAPER_BALL`; the contact is on the fingers' centre
    lines and the fingers pass through each other (``ContactSettings(finger_thickness=False,
    finger_contact_stiffness=0)``), and the material is purely elastic (its retardation time set to 0), as the paper
    has it.
    """

    forces: tuple[ForceModel, ...] = (Gravity(),)
    forces += tuple(medium) if isinstance(medium, tuple) else fluid_forces(medium)
    gripper = without_material_damping(GripperDesign(paper_finger(material, variable_stiffness)))
    return Scene(gripper=gripper, forces=forces, model=model, grasped_object=grasped_object,
                 contact=ContactSettings(finger_thickness=False, finger_contact_stiffness=0.0))


def cantilever_scene(n_nodes: int = 20, clamp: ClampConvention = "accurate", model: RodModel = "planar") -> Scene:
    """The cantilever benchmark (``docs/speed_vs_error.md``): L = 0.1 m, r = 0.01 m, E = 386.66 kPa,
    ρ = 1200 kg/m³, gravity along −z, clamped horizontally at the wall x = 0, no actuation."""
    material = Material("cantilever silicone", youngs_modulus=386.66e3, density=1200.0)
    finger = FingerDesign(length=0.1, n_nodes=n_nodes, radius=0.01, material=material, clamp=clamp)
    return Scene(gripper=GripperDesign(finger, finger_angles=(0.0,)), forces=(Gravity(),), model=model,
                 natural_curvature_rate=0.0)


__all__ = ["RodModel", "Integrator", "INTEGRATOR_NAMES", "NATURAL_CURVATURE_LIMIT", "STEP_HALVINGS_LIMIT",
           "NewtonSettings", "Scene", "Medium", "paper_scene", "cantilever_scene", "replace"]
