"""Compiled contact geometry: the grasped object as each finger's rod sees it, nodes inside it, and the normal part
of a reaction. The corrector that uses them is :mod:`..solvers.corrector`; ``docs/contact.md`` describes the method.

An object is a capsule, the points within a radius of a segment (a sphere is a capsule of zero length), so one set
of kernels serves both. Contact is between the object's surface and the finger's: node i of a finger of radius
r_i touches an object of radius R when its centre line is R + r_i from the object's segment
(``ContactSettings.finger_thickness``; without it, as in the paper, the centre line itself touches). Contact is
node-based: the surface between two nodes outside the object may still cut into it, by at most the sag of an edge
of length Δl over the curvature, Δl²/(8·(R + r)) (0.07 mm for the paper's finger and ball on the centre line).

In the planar model a finger sees the object's section by its own vertical plane: a sphere of radius R whose centre
is a distance d from the plane is a circle of radius √(R² − d²) there, and node i touches it at √((R + r_i)² − d²)
from its centre.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..scene.objects import GraspedObject
from .compiled import kernel
from .linalg import symmetric_band_entry
from .local import local_array

STICK_SPEED = 1e-3
"""The slip speed [m/s] below which a regularised friction (the palm's, and the fingers' on each other) grows in
proportion to the slip instead of at the full μ·N, so that it has a derivative for Newton's method. A surface held
by it under a tangential load below μ·N creeps at most this fast."""


class ObjectView(NamedTuple):
    """The grasped object as each rod sees it, in the rod's coordinates (R rods, D coordinates)."""

    starts: np.ndarray
    """One end of the object's segment [m], (R, D)."""
    ends: np.ndarray
    """The other end [m], (R, D)."""
    radii: np.ndarray
    """The distance from the object's segment at which each node's centre line touches it [m], (R, N): the
    object's radius as the rod sees it plus the finger's radius at the node (:func:`object_in_rod_frames`)."""
    searched: np.ndarray
    """Whether the rod can reach the object at all, (R,) bool (:func:`within_reach`)."""
    shift: np.ndarray
    """The object's displacement over the step [m], (R, D); zero for a fixed object."""


def object_in_rod_frames(obj: GraspedObject, finger_directions: np.ndarray, finger_radius: np.ndarray,
                         planar: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The object as each finger's rod sees it: its segment's ends (F, D) and (F, D), and the distance from the
    segment at which each node's centre line touches it, (F, N) [m]: the object's radius plus the finger's at the
    node, ``finger_radius`` (N,) (zeros for contact on the centre lines).

    In 3-D that is the object itself. In the planar model a sphere's section by the finger's plane is a circle (a
    segment of zero length); see the module notes.
    """
    start, end = obj.segment
    n_fingers = len(finger_directions)
    reach = obj.radius + np.asarray(finger_radius, dtype=float)
    if not planar:
        return np.tile(start, (n_fingers, 1)), np.tile(end, (n_fingers, 1)), np.tile(reach, (n_fingers, 1))
    center = start  # a sphere: the planar model refuses a capsule (Scene validation)
    plane_normals = np.stack([-finger_directions[:, 1], finger_directions[:, 0], np.zeros(n_fingers)], axis=1)
    distance = plane_normals @ center
    radius = np.sqrt(np.maximum(reach[None, :] ** 2 - distance[:, None] ** 2, 0.0))
    centers = np.stack([finger_directions @ center, np.full(n_fingers, center[2])], axis=1)
    return centers, centers, radius


@kernel(python=True)
def contact_reactions(q, residual, held, friction, starts, ends, finger_directions, reaction, normal):
    """The object's force on every node at a step's solution, as the step reports it: the unbalanced force of a
    held node's equation of motion (its Newton ``residual`` (R, n) where ``held`` (R, N)) plus its ``friction``
    (R, N, D) [N], written into ``reaction`` (R, N, 3) in the world frame (a planar rod's (s, z) along its finger's
    direction (F, 3) and up); and the component along the outward normal of the rod's object at the node (the
    direction from the nearest point of the segment ``starts``–``ends`` (R, D) to the node at ``q`` (R, N, S)),
    written into ``normal`` (R, N)."""
    n_rods, n_nodes, stride = q.shape
    dim = friction.shape[2]
    n_fingers = finger_directions.shape[0]
    local = local_array(3)[:dim]
    nearest = local_array(3)[:dim]
    unit = local_array(3)[:dim]
    acting = local_array(3)[:dim]
    for r in range(n_rods):
        start, end = starts[r], ends[r]
        for i in range(n_nodes):
            rubbing = False
            for k in range(dim):
                rubbing |= friction[r, i, k] != 0.0
            # A node neither held nor rubbing feels nothing of the object: its reaction is the zero below, so the
            # geometry is skipped. On the segment itself (a planar section shrunk to a point) the normal is undefined
            # and the object's surface there faces out of the finger's plane: no normal reaction within it.
            on_surface = (held[r, i] or rubbing) and outward_normal(q[r, i, :dim], start, end, nearest, unit)
            if on_surface:  # a sliding node's friction acts along the surface at its current point, as in the solve
                along_surface(friction[r, i], unit, acting)
            for k in range(dim):
                local[k] = residual[r, i * stride + k] * held[r, i] + (acting[k] if on_surface else friction[r, i, k])
            if dim == 3:
                for k in range(3):
                    reaction[r, i, k] = local[k]
            else:
                for k in range(3):
                    reaction[r, i, k] = local[0] * finger_directions[r % n_fingers, k]
                reaction[r, i, 2] += local[1]
            normal[r, i] = 0.0
            if on_surface:
                for k in range(dim):
                    normal[r, i] += local[k] * unit[k]


@kernel(python=True)
def within_reach(starts, ends, radii, length, reach):
    """Which rods can touch an object given as they see it (segment ends (R, D), touching distances (R, N)), into
    ``reach`` (R,) bool: the object must exist in the rod's frame (some distance > 0) and its
    segment lie within ``length`` plus the largest distance of the palm, the rods' origin."""
    n_rods, dim = starts.shape
    palm = local_array(3)[:dim]
    palm[:] = 0.0
    nearest = local_array(3)[:dim]
    for r in range(n_rods):
        largest = radii[r, 0]
        for i in range(1, radii.shape[1]):
            largest = max(largest, radii[r, i])
        reach[r] = largest > 0.0 and distance_to_segment(palm, starts[r], ends[r], nearest) < length + largest


@kernel(python=True, inline=True)
def distance_to_segment(point, start, end, nearest):
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


@kernel
def find_penetrations(positions, old_positions, view, held, first_free_node, tolerance, new_hold, hold_at, found):
    """Marks in ``new_hold`` (R, N) every free node from ``first_free_node`` on of a searched rod that lies inside its
    object (``view``, :class:`ObjectView`: for node i of rod r, the points within ``radii[r, i]`` of the segment
    ``starts``–``ends``, so that the finger's surface, not its centre line, touches the object's) by more
    than ``tolerance`` [m], and writes where it is held into ``hold_at`` (R, N, D): the point where its path over the
    step, relative to the object, entered the surface. ``old_positions`` (R, N, D) are the nodes at the start of the
    step and ``view.shift`` (R, D) the object's displacement over it. A node already inside at the start is
    projected radially instead. Writes the number found per rod into ``found`` (R,) int."""
    starts, ends, radii, searched, shifts = view
    n_rods, n_nodes, dim = positions.shape
    nearest = local_array(3)[:dim]
    point = local_array(3)[:dim]
    begin = local_array(3)[:dim]
    for r in range(n_rods):
        found[r] = 0
        if not searched[r]:
            continue
        start, end = starts[r], ends[r]  # views taken once per rod
        for i in range(first_free_node, n_nodes):
            radius = radii[r, i]
            if held[r, i] or radius <= 0.0:
                continue
            distance = distance_to_segment(positions[r, i], start, end, nearest)
            if not (distance < radius - tolerance and distance > 0.0):
                continue
            for k in range(dim):
                begin[k] = old_positions[r, i, k] + shifts[r, k]  # the start of the path, relative to the object
                point[k] = positions[r, i, k]
            if distance_to_segment(begin, start, end, nearest) > radius:
                low, high = 0.0, 1.0  # bisect for the entry: outside at `low`, inside at `high`
                for _ in range(40):
                    middle = 0.5 * (low + high)
                    for k in range(dim):
                        point[k] = begin[k] + middle * (positions[r, i, k] - begin[k])
                    if distance_to_segment(point, start, end, nearest) > radius:
                        low = middle
                    else:
                        high = middle
                for k in range(dim):
                    point[k] = begin[k] + low * (positions[r, i, k] - begin[k])
            distance = distance_to_segment(point, start, end, nearest)
            if distance == 0.0:
                continue
            new_hold[r, i] = True
            found[r] += 1
            # onto_surface's projection, in another order of rounding: that order changes a grasp's trajectory
            # after a few hundred steps (a 1-ulp move of a hold point grows through stick-slip), so it stays.
            for k in range(dim):
                hold_at[r, i, k] = nearest[k] + (point[k] - nearest[k]) * radius / distance


@kernel(inline=True)
def outward_normal(point, start, end, nearest, normal):
    """The unit direction from the segment start–end to ``point`` (D,), into ``normal`` (D,), with the segment's
    nearest point in ``nearest`` (D,); returns False (and leaves ``normal``) where the point lies on the segment
    itself, whose normal is undefined (a planar finger's section of a sphere that has left its plane shrinks to a
    point)."""
    distance = distance_to_segment(point, start, end, nearest)
    if distance == 0.0:
        return False
    for k in range(point.size):
        normal[k] = (point[k] - nearest[k]) / distance
    return True


@kernel
def onto_surface(point, start, end, radius, normal):
    """Moves ``point`` (D,) in place along the normal to the surface at ``radius`` from the segment start–end, and
    writes that outward unit normal into ``normal`` (D,); returns False (and leaves both) where the point lies on
    the segment itself (:func:`outward_normal`)."""
    nearest = local_array(3)[:point.size]
    if not outward_normal(point, start, end, nearest, normal):
        return False
    for k in range(point.size):
        point[k] = nearest[k] + radius * normal[k]
    return True


@kernel(inline=True)
def along_surface(friction, normal, out):
    """The friction force ``friction`` (D,) turned into the tangent plane of ``normal`` (D,), keeping its size: the
    force a sliding node's friction exerts at its current point, whatever the surface's normal was when it was set."""
    size = 0.0
    along = 0.0
    for d in range(friction.size):
        size += friction[d] ** 2
        along += friction[d] * normal[d]
    tangential = 0.0
    for d in range(friction.size):
        out[d] = friction[d] - along * normal[d]
        tangential += out[d] ** 2
    scale = math.sqrt(size / tangential) if tangential > 0.0 else 0.0
    for d in range(friction.size):
        out[d] *= scale


@kernel(python=True)
def tangent_basis(normal, basis):
    """An orthonormal basis (D, D) whose first column is the unit ``normal`` (D,) and whose others span its tangent
    plane, into ``basis``; the same normal always gives the same basis."""
    dim = normal.size
    if dim == 2:
        basis[0, 0], basis[1, 0] = normal[0], normal[1]
        basis[0, 1], basis[1, 1] = -normal[1], normal[0]
        return
    least = 0  # the axis least aligned with the normal, crossed with it, gives the first tangent
    for k in range(1, 3):
        if abs(normal[k]) < abs(normal[least]):
            least = k
    axis = local_array(3)
    axis[:] = 0.0
    axis[least] = 1.0
    first = local_array(3)
    first[0] = axis[1] * normal[2] - axis[2] * normal[1]
    first[1] = axis[2] * normal[0] - axis[0] * normal[2]
    first[2] = axis[0] * normal[1] - axis[1] * normal[0]
    norm = math.sqrt(first[0] ** 2 + first[1] ** 2 + first[2] ** 2)
    for k in range(3):
        basis[k, 0] = normal[k]
        basis[k, 1] = first[k] / norm
    basis[0, 2] = normal[1] * basis[2, 1] - normal[2] * basis[1, 1]
    basis[1, 2] = normal[2] * basis[0, 1] - normal[0] * basis[2, 1]
    basis[2, 2] = normal[0] * basis[1, 1] - normal[1] * basis[0, 1]


@kernel(python=True)
def rotate_node(band, first, basis):
    """Expresses one node's D DOFs ``first`` … ``first`` + D − 1 of a rod's symmetric band (n, kd+1) in the
    ``basis`` (D, D) (x = Q·ξ): A ← Tᵀ·A·T with T the identity but for Q on that node's block, in place."""
    n, kd1 = band.shape
    kd = kd1 - 1
    dim = basis.shape[0]
    last = first + dim
    old = local_array(3)[:dim]
    # A node couples to nodes at most two away, all within the band (kd = 3·S − 1), so no rotated entry falls
    # outside it.
    for j in range(max(0, first - kd), min(n, last + kd)):  # every other DOF the node's block couples to
        if first <= j < last:
            continue
        for a in range(dim):  # A[node, j] ← Qᵀ·A[node, j]
            i = first + a
            if abs(i - j) > kd:
                old[a] = 0.0
            else:
                old[a] = symmetric_band_entry(band, i, j)
        for a in range(dim):
            i = first + a
            if abs(i - j) > kd:
                continue
            value = 0.0
            for m in range(dim):
                value += basis[m, a] * old[m]
            if j <= i:
                band[i, kd - i + j] = value
            else:
                band[j, kd - j + i] = value
    block = local_array((3, 3))[:dim, :dim]
    for a in range(dim):
        for m in range(dim):
            i, k = first + max(a, m), first + min(a, m)
            block[a, m] = band[i, kd - i + k]
    for a in range(dim):
        for m in range(a + 1):
            value = 0.0
            for x in range(dim):
                for y in range(dim):
                    value += basis[x, a] * block[x, y] * basis[y, m]
            band[first + a, kd - a + m] = value


__all__ = ["ObjectView", "along_surface", "object_in_rod_frames", "contact_reactions", "within_reach",
           "find_penetrations", "distance_to_segment", "onto_surface", "tangent_basis", "rotate_node"]
