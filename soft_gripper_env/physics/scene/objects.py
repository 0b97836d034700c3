"""The objects a gripper may grasp, and the settings of contact with them (SI units).

A :class:`Sphere`, or a :class:`Capsule` (the points within a radius of a segment; a sphere is a capsule of zero
length, and one set of kernels serves both), fixed in space or free when it has a density. How contact with them
is found and resolved is described in ``docs/contact.md``; the kernels are :mod:`..kernels.contact` and the
corrector :mod:`..solvers.corrector`.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass

import numpy as np

from .validation import check_range

PENETRATION_TOLERANCE = 1e-6
"""No free node ends a step deeper inside the object than this [m]; steps shorter than 2.5 ms hold it tighter
(:func:`penetration_tolerance`)."""

PENETRATION_ACCELERATION = 0.16
"""The acceleration [m/s²] that catching a node allowed inside the object may give it: the corrector puts a node
found ε inside back onto the surface, a move of ε within one step of Δt, that is an acceleration of the order of
ε/Δt². A fixed ε would make that artefact grow as 1/Δt² (at 1 µm and 0.156 ms, 40 m/s²: fingers chatter on the
object), so ε = min(:data:`PENETRATION_TOLERANCE`, this·Δt²), which keeps 1 µm at 2.5 ms and longer steps."""


def penetration_tolerance(time_step: float) -> float:
    """How deep [m] a free node may end a step of ``time_step`` [s] inside the object before the corrector holds
    it on the surface (:data:`PENETRATION_ACCELERATION`)."""
    return min(PENETRATION_TOLERANCE, PENETRATION_ACCELERATION * time_step**2)

DEFAULT_FRICTION = 0.3
"""The default Coulomb friction coefficient μ of silicone on a wet object (dimensionless); the sources and the
range it is drawn from are in ``docs/contact.md``."""


@dataclass(frozen=True)
class _Body:
    """What a grasped object has whether it is a sphere or a capsule: fixed, or free with a density."""

    _: KW_ONLY
    density: float | None = None
    """Mass density [kg/m³] of a free object; None for an object fixed in space."""
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Initial velocity of a free object [m/s]."""
    friction: float = DEFAULT_FRICTION
    """Coulomb friction coefficient μ between the fingers and the object (dimensionless): a contact sticks while
    its tangential reaction is at most μ times its normal one, and slides otherwise; 0 is frictionless, ``math.inf``
    always sticks (as the paper's holds do)."""

    @property
    def free(self) -> bool:
        return self.density is not None


@dataclass(frozen=True)
class Sphere(_Body):
    """A rigid sphere: fixed in space (the paper's ball is :data:`PAPER_BALL`), or free when it has a density, moved
    by gravity, buoyancy, drag, added mass and the contact reactions (:mod:`.rigid_body`)."""

    radius: float
    """Radius [m]."""
    center: tuple[float, float, float]
    """Centre in the world frame [m] (at t = 0, for a free sphere)."""

    def __post_init__(self) -> None:
        check_range("Sphere", "radius", self.radius, "m", 0.0)
        center = tuple(float(c) for c in self.center)
        if len(center) != 3:
            raise ValueError(f"Sphere.center = {self.center!r} must have 3 components [m]")
        for c in center:
            check_range("Sphere", "center", c, "m", -1e3, 1e3)
        object.__setattr__(self, "center", center)
        _check_motion(self)

    @property
    def segment(self) -> tuple[np.ndarray, np.ndarray]:
        """The object as a swept sphere: the segment its surface is at ``radius`` from (a point, for a sphere)."""
        return np.asarray(self.center), np.asarray(self.center)


def _check_motion(obj) -> None:
    """Validates the ``density``, initial ``velocity`` and ``friction`` of a sphere or capsule."""
    kind = type(obj).__name__
    try:
        friction = float(obj.friction)
    except (TypeError, ValueError):
        raise ValueError(f"{kind}.friction = {obj.friction!r} is not a number (dimensionless)") from None
    if not friction >= 0.0:
        raise ValueError(f"{kind}.friction = {obj.friction!r} is outside the allowed range [0, inf] (dimensionless)")
    object.__setattr__(obj, "friction", friction)
    if obj.density is not None:
        check_range(kind, "density", obj.density, "kg/m³", 0.0, 1e5)
    velocity = tuple(float(v) for v in obj.velocity)
    if len(velocity) != 3:
        raise ValueError(f"{kind}.velocity = {obj.velocity!r} must have 3 components [m/s]")
    for v in velocity:
        check_range(kind, "velocity", v, "m/s", -100.0, 100.0, low_inclusive=True)
    if any(velocity) and obj.density is None:
        raise ValueError(f"{kind}.velocity needs {kind}.density: an object fixed in space cannot move")
    object.__setattr__(obj, "velocity", velocity)


@dataclass(frozen=True)
class Capsule(_Body):
    """A rigid capsule (a cylinder with hemispherical ends): every point within ``radius`` of the segment from
    ``start`` to ``end``. Fixed in space, or free when it has a density. Contact with it needs the 3-D rod model."""

    radius: float
    """Radius [m]."""
    start: tuple[float, float, float]
    """One end of the axis, world frame [m] (at t = 0, for a free capsule)."""
    end: tuple[float, float, float]
    """The other end of the axis, world frame [m]."""

    def __post_init__(self) -> None:
        check_range("Capsule", "radius", self.radius, "m", 0.0)
        for name in ("start", "end"):
            point = tuple(float(c) for c in getattr(self, name))
            if len(point) != 3:
                raise ValueError(f"Capsule.{name} = {getattr(self, name)!r} must have 3 components [m]")
            for c in point:
                check_range("Capsule", name, c, "m", -1e3, 1e3)
            object.__setattr__(self, name, point)
        _check_motion(self)

    @property
    def segment(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.start), np.asarray(self.end)


GraspedObject = Sphere | Capsule


PAPER_BALL = Sphere(radius=0.065, center=(0.0, 0.0, -0.09), friction=math.inf)
"""The paper's ball: R = 0.065 m, centre (0, 0, −0.09) m, fixed; its holds stick, as the paper's do."""


@dataclass(frozen=True)
class ContactSettings:
    max_corrector_iterations: int = 10
    """Re-solves of one step allowed for new contacts and releases."""
    friction_passes: int | None = None
    """Re-solves of one step in which a sliding node's friction that moved (in size or direction, beyond the
    corrector's friction tolerance) is reason enough to solve again; after them a step keeps the friction of its
    last solve, which the next step updates. New holds, releases, slides that start and nodes that stick again
    re-solve within ``max_corrector_iterations`` either way. None settles friction within the whole budget. Capping
    it is a speed setting: a 3-D grasp spends about a quarter of its steps cycling on friction
    (``docs/speed_vs_error.md`` measures the cap against the grasp's outcome)."""
    palm_stiffness: float = 1000.0
    """The palm, a disc of radius ``palm_radius`` about the z axis in the plane z = 0 of the finger bases, pushes
    a free object that overlaps it back down with this stiffness [N/m] (1 mm of overlap per newton); 0 turns it
    off. Without it an object pushed up by the fingers would pass the clamped nodes and be crushed against the
    finger roots. It only pushes, and its force is continuous at first touch (``docs/contact.md``)."""
    palm_radius: float = 0.03
    """Radius of the palm disc [m]: the finger roots (the two clamped nodes reach 0.021 m) and a little more."""
    palm_damping_depth: float = 1e-3
    """The overlap [m] over which the palm's damping grows from zero to critical for the object's mass: a damping
    switched on at first touch would be a jump in force."""
    palm_friction: float = DEFAULT_FRICTION
    """Coulomb friction coefficient μ between the palm and the object (dimensionless); 0 is frictionless."""
    finger_thickness: bool = True
    """Contact between the fingers' surfaces and the object's: node i touches at the object's radius plus the
    finger's radius there (its radius profile, so a variable-stiffness finger too). False puts contact on the
    fingers' centre lines, as the paper does (:func:`~.scene.paper_scene` keeps that for its figures)."""
    finger_contact_stiffness: float = 2000.0
    """The fingers' surfaces keep out of each other's with this force per overlap [N/m] (0.5 mm of overlap per
    newton; of the order of the silicone's Young's modulus times one edge's length, ``docs/contact.md``); 0 lets
    them pass through each other, as the paper's fingers do."""
    finger_friction: float = DEFAULT_FRICTION
    """Coulomb friction coefficient μ between two fingers (dimensionless); 0 is frictionless."""

    def __post_init__(self) -> None:
        if not isinstance(self.max_corrector_iterations, (int, np.integer)) or \
                not 0 <= self.max_corrector_iterations <= 100:
            raise ValueError(f"ContactSettings.max_corrector_iterations = {self.max_corrector_iterations!r} is "
                             f"outside the allowed range [0, 100] (integer count)")
        if self.friction_passes is not None and (
                not isinstance(self.friction_passes, (int, np.integer)) or isinstance(self.friction_passes, bool)
                or not 0 <= self.friction_passes <= 100):
            raise ValueError(f"ContactSettings.friction_passes = {self.friction_passes!r} is outside the allowed "
                             f"range: None or an integer count in [0, 100]")
        check_range("ContactSettings", "palm_stiffness", self.palm_stiffness, "N/m", 0.0, 1e9, low_inclusive=True)
        check_range("ContactSettings", "palm_radius", self.palm_radius, "m", 0.0, 10.0, low_inclusive=True)
        check_range("ContactSettings", "palm_damping_depth", self.palm_damping_depth, "m", 0.0, 1.0,
                    low_inclusive=True)
        if not isinstance(self.finger_thickness, (bool, np.bool_)):
            raise ValueError(f"ContactSettings.finger_thickness = {self.finger_thickness!r} must be True or False")
        check_range("ContactSettings", "palm_friction", self.palm_friction, "(dimensionless)", 0.0, 1e6,
                    low_inclusive=True)
        check_range("ContactSettings", "finger_contact_stiffness", self.finger_contact_stiffness, "N/m", 0.0, 1e9,
                    low_inclusive=True)
        check_range("ContactSettings", "finger_friction", self.finger_friction, "(dimensionless)", 0.0, 1e6,
                    low_inclusive=True)


__all__ = ["PENETRATION_TOLERANCE", "PENETRATION_ACCELERATION", "penetration_tolerance", "DEFAULT_FRICTION",
           "Sphere", "Capsule", "GraspedObject", "PAPER_BALL",
           "ContactSettings"]
