"""Contact between finger nodes and a grasped object: the paper's predictor–corrector, done right.

The step is solved; every free node found inside the object by more than :data:`PENETRATION_TOLERANCE` is projected
radially onto its surface and held there, and the step is solved again with those nodes fixed. The reaction on a
held node is the unbalanced force of its equation of motion, R = M·a − f (physics.md §1). Contact is
compression-only: a held node whose normal reaction R·n turns adhesive (pulls it into the object, R·n < 0) is
released and the step solved again. The corrector repeats until nothing changes, at most
:attr:`ContactSettings.max_corrector_iterations` times. Held nodes stick: they stay where they were held until
released, so the contact transmits tangential force without sliding (a frictional-sliding model would replace the
stick rule here). The base clamp is kept throughout.

Contact is node-based: an edge between two nodes outside the object may still cut through it, by at most the sag of
an edge of length Δl over the object's curvature, Δl²/(8·R) (0.07 mm for the paper's finger and ball).

In the planar model a finger sees the object's section by its own vertical plane: a sphere of radius R whose centre
is a distance d from the plane is a circle of radius √(R² − d²) there. The finger is rigid out of its plane, so
the out-of-plane part of a contact force is carried by it and not reported. While the object stays on the gripper's
axis the section is a great circle and the planar and 3-D models agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .validation import check_range

PENETRATION_TOLERANCE = 1e-6
"""No free node ends a step deeper inside the object than this [m]."""


@dataclass(frozen=True)
class Sphere:
    """A rigid sphere, fixed in space (the paper's ball is :data:`PAPER_BALL`)."""

    radius: float
    """Radius [m]."""
    center: tuple[float, float, float]
    """Centre in the world frame [m]."""

    def __post_init__(self) -> None:
        check_range("Sphere", "radius", self.radius, "m", 0.0)
        center = tuple(float(c) for c in self.center)
        if len(center) != 3:
            raise ValueError(f"Sphere.center = {self.center!r} must have 3 components [m]")
        for c in center:
            check_range("Sphere", "center", c, "m", -1e3, 1e3)
        object.__setattr__(self, "center", center)


PAPER_BALL = Sphere(radius=0.065, center=(0.0, 0.0, -0.09))
"""The paper's ball: R = 0.065 m, centre (0, 0, −0.09) m, fixed."""


@dataclass(frozen=True)
class ContactSettings:
    max_corrector_iterations: int = 10
    """Re-solves of one step allowed for new contacts and releases."""

    def __post_init__(self) -> None:
        if not isinstance(self.max_corrector_iterations, (int, np.integer)) or \
                not 0 <= self.max_corrector_iterations <= 100:
            raise ValueError(f"ContactSettings.max_corrector_iterations = {self.max_corrector_iterations!r} is "
                             f"outside the allowed range [0, 100] (integer count)")


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

    @property
    def finger_reaction(self) -> np.ndarray:
        """Sum of the reactions on each finger [N], (B, F, 3)."""
        return self.reaction.sum(axis=2)

    @property
    def total_reaction(self) -> np.ndarray:
        """Sum of the reactions on the gripper [N], (B, 3)."""
        return self.reaction.sum(axis=(1, 2))


def sphere_in_rod_frames(sphere: Sphere, finger_directions: np.ndarray, planar: bool) -> tuple[np.ndarray, np.ndarray]:
    """Centre (F, D) and radius (F,) of the object as each finger's rod sees it [m] (see the module notes)."""
    center = np.asarray(sphere.center)
    n_fingers = len(finger_directions)
    if not planar:
        return np.tile(center, (n_fingers, 1)), np.full(n_fingers, sphere.radius)
    plane_normals = np.stack([-finger_directions[:, 1], finger_directions[:, 0], np.zeros(n_fingers)], axis=1)
    distance = plane_normals @ center
    radius = np.sqrt(np.maximum(sphere.radius**2 - distance**2, 0.0))
    centers = np.stack([finger_directions @ center, np.full(n_fingers, center[2])], axis=1)
    return centers, radius


def reachable(sphere: Sphere, finger_directions: np.ndarray, length: float, planar: bool) -> np.ndarray:
    """Which fingers can touch the object at all: those whose base (the palm centre) lies within L + R of the
    section's centre (F,) bool. Contact is never searched for the others."""
    centers, radius = sphere_in_rod_frames(sphere, finger_directions, planar)
    return (np.linalg.norm(centers, axis=1) < length + radius) & (radius > 0)


@njit(cache=True)
def find_penetrations(positions, centers, radii, held, searched, first_free_node, tolerance, new_hold, hold_at):
    """Marks in ``new_hold`` (R, N) every free node of a searched rod that lies inside its object by more than
    ``tolerance`` [m], and writes its radial projection onto the surface into ``hold_at`` (R, N, D). Returns the
    number found per rod."""
    n_rods, n_nodes, dim = positions.shape
    found = np.zeros(n_rods, dtype=np.int64)
    for r in range(n_rods):
        if not searched[r]:
            continue
        radius = radii[r]
        for i in range(first_free_node, n_nodes):
            if held[r, i]:
                continue
            distance2 = 0.0
            for k in range(dim):
                d = positions[r, i, k] - centers[r, k]
                distance2 += d * d
            distance = math.sqrt(distance2)
            if distance < radius - tolerance and distance > 0.0:
                new_hold[r, i] = True
                found[r] += 1
                for k in range(dim):
                    hold_at[r, i, k] = centers[r, k] + (positions[r, i, k] - centers[r, k]) * radius / distance
    return found
