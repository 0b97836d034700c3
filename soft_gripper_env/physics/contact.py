"""Contact between finger nodes and a grasped object: the paper's predictor–corrector, done right.

The step is solved; every free node found inside the object by more than :data:`PENETRATION_TOLERANCE` is held on its
surface, and the step is solved again with those nodes fixed. The paper projects the node radially; we hold it where
its path over the step (relative to the object) entered the surface, which is the same for a slow node and keeps a
fast impact (a node 1 cm inside after a step at 1 m/s) from stretching its edges by the projection. The reaction on a
held node is the unbalanced force of its equation of motion, R = M·a − f (physics.md §1). Contact is
compression-only: a held node whose normal reaction R·n turns adhesive (pulls it into the object, R·n < 0) is
released (a reaction pulling by less than Newton's force tolerance is zero to that tolerance and stays) and the
step solved again, from the last solution. The corrector repeats until nothing changes, at most
:attr:`ContactSettings.max_corrector_iterations` times; if nodes are still inside the object then, it holds them,
releasing nothing, until none is (the step then reports ``resolved = False``). Held nodes stick: they stay where
they were held until released, so the contact transmits tangential force without sliding (a frictional-sliding
model would replace the stick rule here). The base clamp is kept throughout.

Objects are fixed in space: a :class:`Sphere`, or a :class:`Capsule` (the points within a radius of a segment; a
sphere is a capsule of zero length, and one kernel serves both). Contact is node-based: an edge between two nodes
outside the object may still cut through it, by at most the sag of an edge of length Δl over the object's
curvature, Δl²/(8·R) (0.07 mm for the paper's finger and ball).

In the planar model a finger sees the object's section by its own vertical plane: a sphere of radius R whose centre
is a distance d from the plane is a circle of radius √(R² − d²) there. The finger is rigid out of its plane, so
the out-of-plane part of a contact force is carried by it and not reported. A free sphere held by planar fingers
translates but does not turn: turning would carry held points out of the fingers' planes, and the torque it would
take is the fingers' out-of-plane stiffness, which the planar model treats as rigid. While the object stays on the
gripper's axis the section is a great circle and the planar and 3-D models agree. A free object pushed up against
the palm meets a compliant disc (:attr:`ContactSettings.palm_stiffness`; :mod:`.rigid_body`), not the clamped nodes.
"""

from __future__ import annotations

import math
from dataclasses import KW_ONLY, dataclass

import numpy as np
from numba import njit

from .validation import check_range

PENETRATION_TOLERANCE = 1e-6
"""No free node ends a step deeper inside the object than this [m]."""


@dataclass(frozen=True)
class _Body:
    """What a grasped object has whether it is a sphere or a capsule: fixed, or free with a density."""

    _: KW_ONLY
    density: float | None = None
    """Mass density [kg/m³] of a free object; None for an object fixed in space."""
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Initial velocity of a free object [m/s]."""

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
    """Validates the ``density`` and initial ``velocity`` of a sphere or capsule."""
    kind = type(obj).__name__
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

PAPER_BALL = Sphere(radius=0.065, center=(0.0, 0.0, -0.09))
"""The paper's ball: R = 0.065 m, centre (0, 0, −0.09) m, fixed."""


@dataclass(frozen=True)
class ContactSettings:
    max_corrector_iterations: int = 10
    """Re-solves of one step allowed for new contacts and releases."""
    palm_stiffness: float = 1000.0
    """The palm, a disc of radius ``palm_radius`` about the z axis in the plane z = 0 of the finger bases, pushes
    a free object that overlaps it back down with this stiffness [N/m] (1 mm of overlap per newton), critically
    damped for the object's mass; 0 turns it off. Contact is node-based, so the palm, like the fingers, is its
    centre plane. Without it an object pushed up by the fingers would pass the clamped nodes and be crushed
    against the finger roots."""
    palm_radius: float = 0.03
    """Radius of the palm disc [m]: the finger roots (the two clamped nodes reach 0.021 m) and a little more."""

    def __post_init__(self) -> None:
        if not isinstance(self.max_corrector_iterations, (int, np.integer)) or \
                not 0 <= self.max_corrector_iterations <= 100:
            raise ValueError(f"ContactSettings.max_corrector_iterations = {self.max_corrector_iterations!r} is "
                             f"outside the allowed range [0, 100] (integer count)")
        check_range("ContactSettings", "palm_stiffness", self.palm_stiffness, "N/m", 0.0, 1e9, low_inclusive=True)
        check_range("ContactSettings", "palm_radius", self.palm_radius, "m", 0.0, 10.0, low_inclusive=True)


@dataclass(frozen=True, eq=False)
class ContactReport:
    """Contact of one step, in the world frame. Arrays are per gripper (B), finger (F) and node (N)."""

    held: np.ndarray
    """Nodes held on the object's surface at the end of the step, (B, F, N) bool."""
    reaction: np.ndarray
    """Force of the object on each node [N], (B, F, N, 3); zero where not held."""
    normal_reaction: np.ndarray
    """Its component along the outward surface normal [N], (B, F, N); ≥ 0 (compression only)."""
    corrector_iterations: np.ndarray
    """Re-solves the step needed, (B,)."""
    resolved: np.ndarray
    """Whether the corrector ended with no penetrating node and no adhesive hold, (B,)."""
    palm_reaction: np.ndarray | None = None
    """Force of a free object on the palm [N], (B, 3); zero where it does not touch; None for a fixed object."""

    @property
    def finger_reaction(self) -> np.ndarray:
        """Sum of the reactions on each finger [N], (B, F, 3)."""
        return self.reaction.sum(axis=2)

    @property
    def total_reaction(self) -> np.ndarray:
        """Sum of the reactions on the gripper, fingers and palm [N], (B, 3)."""
        total = self.reaction.sum(axis=(1, 2))
        return total if self.palm_reaction is None else total + self.palm_reaction


def object_in_rod_frames(obj: GraspedObject, finger_directions: np.ndarray,
                         planar: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The object as each finger's rod sees it: its segment's ends (F, D) and (F, D), and its radius (F,) [m].

    In 3-D that is the object itself. In the planar model a sphere's section by the finger's plane is a circle (a
    segment of zero length); see the module notes.
    """
    start, end = obj.segment
    n_fingers = len(finger_directions)
    if not planar:
        return np.tile(start, (n_fingers, 1)), np.tile(end, (n_fingers, 1)), np.full(n_fingers, obj.radius)
    center = start  # a sphere: the planar model refuses a capsule (Scene validation)
    plane_normals = np.stack([-finger_directions[:, 1], finger_directions[:, 0], np.zeros(n_fingers)], axis=1)
    distance = plane_normals @ center
    radius = np.sqrt(np.maximum(obj.radius**2 - distance**2, 0.0))
    centers = np.stack([finger_directions @ center, np.full(n_fingers, center[2])], axis=1)
    return centers, centers, radius


@njit(cache=True, error_model="numpy")
def normal_reactions(positions, reactions, starts, ends):
    """The component of each node's reaction (R, N, D) [N] along the outward normal of its rod's object there (the
    direction from the nearest point of the segment ``starts``–``ends`` (R, D) to the node (R, N, D)), (R, N)."""
    n_rods, n_nodes, dim = positions.shape
    normal = np.empty((n_rods, n_nodes))
    nearest = np.empty(dim)
    for r in range(n_rods):
        for i in range(n_nodes):
            distance = _distance_to_segment(positions[r, i], starts[r], ends[r], nearest)
            along = 0.0
            for k in range(dim):
                along += reactions[r, i, k] * (positions[r, i, k] - nearest[k])
            normal[r, i] = along / distance
    return normal


def reachable(obj: GraspedObject, finger_directions: np.ndarray, length: float, planar: bool) -> np.ndarray:
    """Which fingers can touch the object at all, (F,) bool: those whose base (the palm centre) lies within L + R
    of the object's segment, as the rod sees it. Contact is never searched for the others."""
    return within_reach(*object_in_rod_frames(obj, finger_directions, planar), length)


@njit(cache=True, error_model="numpy")
def within_reach(starts, ends, radii, length):
    """Which rods (R,) can touch an object given as they see it (segment ends (R, D), radius (R,)): the object
    must exist in the rod's frame (radius > 0) and its segment lie within ``length`` + radius of the palm, the
    rods' origin."""
    n_rods, dim = starts.shape
    reach = np.empty(n_rods, dtype=np.bool_)
    palm = np.zeros(dim)
    nearest = np.empty(dim)
    for r in range(n_rods):
        reach[r] = radii[r] > 0.0 and _distance_to_segment(palm, starts[r], ends[r], nearest) < length + radii[r]
    return reach


@njit(cache=True, error_model="numpy")
def _distance_to_segment(point, start, end, nearest):
    """Distance from ``point`` to the segment start–end; writes the segment's nearest point into ``nearest``."""
    dim = point.size
    length2 = 0.0
    along = 0.0
    for k in range(dim):
        length2 += (end[k] - start[k]) ** 2
        along += (point[k] - start[k]) * (end[k] - start[k])
    along = min(max(along / length2, 0.0), 1.0) if length2 > 0.0 else 0.0
    distance2 = 0.0
    for k in range(dim):
        nearest[k] = start[k] + along * (end[k] - start[k])
        distance2 += (point[k] - nearest[k]) ** 2
    return math.sqrt(distance2)


@njit(cache=True, error_model="numpy")
def find_penetrations(positions, old_positions, shifts, starts, ends, radii, held, searched, first_free_node,
                      tolerance, new_hold, hold_at):
    """Marks in ``new_hold`` (R, N) every free node of a searched rod that lies inside its object (the points within
    ``radii`` of the segment ``starts``–``ends``, (R, D) each) by more than ``tolerance`` [m], and writes where it is
    held into ``hold_at`` (R, N, D): the point where its path over the step, relative to the object, entered the
    surface. ``old_positions`` (R, N, D) are the nodes at the start of the step and ``shifts`` (R, D) the object's
    displacement over it. A node already inside at the start is projected radially instead. Returns the number found
    per rod."""
    n_rods, n_nodes, dim = positions.shape
    found = np.zeros(n_rods, dtype=np.int64)
    nearest = np.empty(dim)
    point = np.empty(dim)
    begin = np.empty(dim)
    for r in range(n_rods):
        if not searched[r]:
            continue
        radius = radii[r]
        for i in range(first_free_node, n_nodes):
            if held[r, i]:
                continue
            distance = _distance_to_segment(positions[r, i], starts[r], ends[r], nearest)
            if not (distance < radius - tolerance and distance > 0.0):
                continue
            for k in range(dim):
                begin[k] = old_positions[r, i, k] + shifts[r, k]  # the start of the path, relative to the object
                point[k] = positions[r, i, k]
            if _distance_to_segment(begin, starts[r], ends[r], nearest) > radius:
                low, high = 0.0, 1.0  # bisect for the entry: outside at `low`, inside at `high`
                for _ in range(40):
                    middle = 0.5 * (low + high)
                    for k in range(dim):
                        point[k] = begin[k] + middle * (positions[r, i, k] - begin[k])
                    if _distance_to_segment(point, starts[r], ends[r], nearest) > radius:
                        low = middle
                    else:
                        high = middle
                for k in range(dim):
                    point[k] = begin[k] + low * (positions[r, i, k] - begin[k])
            distance = _distance_to_segment(point, starts[r], ends[r], nearest)
            if distance == 0.0:
                continue
            new_hold[r, i] = True
            found[r] += 1
            for k in range(dim):
                hold_at[r, i, k] = nearest[k] + (point[k] - nearest[k]) * radius / distance
    return found


@njit(cache=True, error_model="numpy")
def contact_changes(positions, old_positions, residual, held, starts, ends, radii, searched, shifts, first_free_node,
                    force_tolerance, adhesive, new_hold, hold_at, changed):
    """The corrector's test after a solve, for rods whose nodes are at ``positions`` (R, N, D) and whose residual
    (R, n) holds the reactions on held DOFs: marks in ``adhesive`` (R, N) the holds whose normal reaction pulls by
    more than ``force_tolerance`` [N] (a reaction is known to Newton's tolerance: one pulling by less is zero, and
    releasing it would only make the corrector cycle), in ``new_hold`` (R, N) the free nodes that penetrate the
    object, with their hold points in ``hold_at`` (:func:`find_penetrations`), and in ``changed`` (R,) the rods with
    either."""
    n_rods, n_nodes, dim = positions.shape
    stride = residual.shape[1] // n_nodes
    reaction = np.zeros((n_rods, n_nodes, dim))
    for r in range(n_rods):
        for i in range(n_nodes):
            if held[r, i]:
                for d in range(dim):
                    reaction[r, i, d] = residual[r, stride * i + d]
    normal = normal_reactions(positions, reaction, starts, ends)
    new_hold[:, :] = False
    found = find_penetrations(positions, old_positions, shifts, starts, ends, radii, held, searched, first_free_node,
                              PENETRATION_TOLERANCE, new_hold, hold_at)
    for r in range(n_rods):
        changed[r] = found[r] > 0
        for i in range(n_nodes):
            adhesive[r, i] = held[r, i] and normal[r, i] < -force_tolerance
            changed[r] |= adhesive[r, i]


@njit(cache=True, error_model="numpy")
def corrector_continues(within_budget, new_hold, changed, again):
    """The corrector's decision after a test: whether to solve again, and which rods (``again`` (R,)). Within the
    budget, every rod that changed. Once the budget is spent, only while nodes are inside the object, and only
    those rods: then holds only grow, so the solves end with no node inside, since a hold that pulls for one step is
    a smaller error than a node left inside the object, from which the next step may not recover (the step reports
    resolved = False either way)."""
    if not changed.any():
        return False
    for r in range(changed.shape[0]):
        again[r] = changed[r] if within_budget else new_hold[r].any()
    return again.any()


@njit(cache=True, error_model="numpy")
def update_holds(within_budget, held, adhesive, new_hold):
    """The holds of the next solve, in place: new penetrations held, and within the budget adhesive holds released."""
    for r in range(held.shape[0]):
        for i in range(held.shape[1]):
            held[r, i] = (held[r, i] and not (within_budget and adhesive[r, i])) or new_hold[r, i]


@njit(cache=True, error_model="numpy")
def release_held(free, held, dim):
    """Marks the position DOFs of every held node (R, N) as not free in ``free`` (R, n), in place: a held node
    moves with its object, not on its own."""
    stride = free.shape[1] // held.shape[1]
    for r in range(held.shape[0]):
        for i in range(held.shape[1]):
            if held[r, i]:
                for d in range(dim):
                    free[r, stride * i + d] = False
