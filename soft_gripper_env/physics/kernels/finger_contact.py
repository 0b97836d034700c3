"""Compiled contact between the fingers of one gripper: each finger's surface keeps out of the others', sides and
tips, with Coulomb friction (``docs/contact.md``).

A finger is a chain of capsules: the edge from node j to j + 1, with the radius varying linearly from r_j to
r_{j+1}. A node i of one finger touches another finger when its distance d to that finger's centre line is less
than the reach ρ = r_i + r(t), r(t) the other's radius at the nearest point (t along its nearest edge).

**A penalty with a stiffness, not a hold.** Two fingers in contact couple two rods, which the solvers keep apart
(each rod has its own banded system; :mod:`..solvers.newton`). So each finger sees the others as they were at the
start of the step, and a node that overlaps one is pushed out with N = k·δ (``ContactSettings.
finger_contact_stiffness``; δ the overlap). A rod sees only its own motion; if it took the whole overlap on itself,
two fingers closing on each other would each back off by all of it, and the pair would bounce from step to step
(an implicit step against an explicit partner). Each finger takes its share as if the other moved as its mirror
image, closing the gap as fast as it does: the overlap it sees is

    δ = ρ − d_0 − 2·(d − d_0),

with d_0 the distance at the start of the step. Two identical fingers closing on each other are then exactly
implicit; against a finger that does not move, a node takes half of what remains at each step, and never
overshoots. At rest (d = d_0), δ is the true overlap and N = k·δ the true contact force, action and reaction alike.
The energy (k/4)·δ² gives N along the normal, and its Newton matrix 2·k·n·nᵀ (the normal's turning left out).

Friction −μ·N_0·u_t/|u_t|_s opposes u_t, the node's slip against the other finger's surface: its velocity over the
step less the other's at the start of the step, along the surface's tangent plane there; |u|_s = √(|u|² + v_s²)
with v_s = :data:`~.contact.STICK_SPEED` regularises the stick (a load below μ·N creeps at most v_s). N_0 is the
normal force at the start of the step (the same at rest; a node has no friction on the step it first touches):
with today's N, the friction's derivative by the normal motion (2·k·μ, more than a node's inertia) would make
Newton's matrix unsymmetric, and left out, throws Newton off. The law saturates like a tanh, on which Newton's
steps can overshoot back and forth across the stick; a rod whose fingers touch therefore backs off a step that
made its residual worse (a line search, :mod:`..solvers.newton`).

Which pairs may touch is decided once, at rest: the fingers share the palm at their roots, so a node and another
finger's edge that overlap, or nearly, when the fingers are straight never count (:func:`FingerContact.of`).
Which of them are near is decided once per step (:func:`find_near_fingers`), so a solve only looks at a few edges
around the nearest.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..scene.discretization import Discretization
from .compiled import kernel
from .contact import STICK_SPEED, distance_to_segment

SEARCH_WINDOW = 2
"""Edges on each side of the nearest one at the start of the step that a solve searches for the nearest point."""

CHUNK_EDGES = 4
"""Edges per run that the search for near fingers first tests as a whole, by a sphere around it."""

NEAR_MARGIN = 5e-3
"""Least distance beyond contact [m] within which a node counts as near another finger at the start of a step (the
motion over the step comes on top)."""


class FingerContact(NamedTuple):
    """The constants of contact between a gripper's fingers, as the kernels take them."""

    stiffness: float
    """k: the normal force per overlap [N/m]; 0 turns finger–finger contact off."""
    friction: float
    """Coulomb friction coefficient μ between two fingers (dimensionless)."""
    radius: np.ndarray
    """The finger's radius at each node [m], (N,)."""
    eligible: np.ndarray
    """Whether node i of finger f may touch the edge j of finger o, (F, N, F, N − 1) bool: not a clamped node, and
    clear of that edge by more than twice :data:`NEAR_MARGIN` when the fingers are straight."""
    axes: np.ndarray
    """Each finger's coordinate axes in the world, (F, D, 3): a node's world position is Σ_d q_d·axes[d], and its
    coordinates are axes·x."""

    @classmethod
    def of(cls, disc: Discretization, stiffness: float, friction: float, first_free_node: int) -> FingerContact:
        """The contact of fingers discretized as ``disc`` with ``stiffness`` [N/m] and ``friction`` μ; nodes below
        ``first_free_node`` are clamped and never count. Where no pair of nodes and edges may touch (one finger, or
        ``stiffness`` 0), the stiffness is 0: contact is off."""
        n_fingers, n_nodes = len(disc.finger_directions), disc.n_nodes
        if disc.dim == 3:
            axes = np.broadcast_to(np.eye(3), (n_fingers, 3, 3)).copy()
        else:
            axes = np.stack([disc.finger_directions, np.tile([0.0, 0.0, 1.0], (n_fingers, 1))], axis=1)
        eligible = np.zeros((n_fingers, n_nodes, n_fingers, n_nodes - 1), dtype=bool)
        if stiffness > 0.0 and n_fingers > 1:
            rest = disc.world_positions(disc.rest_q[None])[0]  # (F, N, 3)
            radius = disc.node_radius
            nearest = np.empty(3)
            for f in range(n_fingers):
                for o in range(n_fingers):
                    if o == f:
                        continue
                    for i in range(first_free_node, n_nodes):
                        for j in range(n_nodes - 1):
                            distance = distance_to_segment(rest[f, i], rest[o, j], rest[o, j + 1], nearest)
                            reach = radius[i] + max(radius[j], radius[j + 1])
                            eligible[f, i, o, j] = distance > reach + 2.0 * NEAR_MARGIN
        # one finger, or no pair that may touch: stiffness 0, which the kernels read as off
        stiffness = float(stiffness) if eligible.any() else 0.0
        return cls(stiffness, float(friction), disc.node_radius.copy(), eligible, np.ascontiguousarray(axes))


N_SCRATCH_POINTS = 10
"""3-vectors in the finger contact's work buffer (:func:`finger_views`)."""


@kernel(python=True)
def finger_scratch_size(n_fingers, n_nodes):
    """Elements of the work buffer of the contact between ``n_fingers`` fingers of ``n_nodes`` nodes (0 for 0
    fingers: a gripper without finger contact)."""
    if n_fingers == 0:
        return 0
    n_chunks = (n_nodes - 2) // CHUNK_EDGES + 1
    return 3 * N_SCRATCH_POINTS + 3 * n_nodes + 9 + 4 * n_fingers * n_nodes + 5 * n_fingers * n_chunks


@kernel(python=True, runtime=True)  # it allocates
def finger_scratch(n_fingers, n_nodes):
    """The finger contact's work buffer (:func:`finger_views`), passed in so that the search and the forces allocate
    nothing (a GPU thread has no heap to allocate from); empty without finger contact (``n_fingers`` 0)."""
    return np.empty(finger_scratch_size(n_fingers, n_nodes))


@kernel(inline=True)
def finger_views(buffer, n_fingers, n_nodes):
    """The work arrays in ``buffer`` (:func:`finger_scratch`): 3-vectors, one a row (:data:`N_SCRATCH_POINTS`, 3),
    another finger's world nodes at the start of the step (N, 3), a 3×3 matrix, every finger's world nodes at the
    start (F, N, 3), each node's predicted displacement over the step [m] (F, N), and the centre (F, runs, 3), radius
    (F, runs) and most motion of a node (F, runs) of each finger's runs of :data:`CHUNK_EDGES` edges."""
    n_chunks = (n_nodes - 2) // CHUNK_EDGES + 1
    at = 0
    points = buffer[at:at + 3 * N_SCRATCH_POINTS].reshape((N_SCRATCH_POINTS, 3))
    at += 3 * N_SCRATCH_POINTS
    other = buffer[at:at + 3 * n_nodes].reshape((n_nodes, 3))
    at += 3 * n_nodes
    matrix = buffer[at:at + 9].reshape((3, 3))
    at += 9
    old = buffer[at:at + 3 * n_fingers * n_nodes].reshape((n_fingers, n_nodes, 3))
    at += 3 * n_fingers * n_nodes
    motion = buffer[at:at + n_fingers * n_nodes].reshape((n_fingers, n_nodes))
    at += n_fingers * n_nodes
    centres = buffer[at:at + 3 * n_fingers * n_chunks].reshape((n_fingers, n_chunks, 3))
    at += 3 * n_fingers * n_chunks
    bounds = buffer[at:at + n_fingers * n_chunks].reshape((n_fingers, n_chunks))
    at += n_fingers * n_chunks
    chunk_motion = buffer[at:at + n_fingers * n_chunks].reshape((n_fingers, n_chunks))
    return points, other, matrix, old, motion, centres, bounds, chunk_motion


@kernel(inline=True)
def _world(q_node, axes, out):
    """A node's world position (3,) [m] from its coordinates ``q_node`` (≥ D,) on a finger with ``axes`` (D, 3)."""
    for k in range(3):
        out[k] = 0.0
        for d in range(axes.shape[0]):
            out[k] += q_node[d] * axes[d, k]


@kernel(inline=True)
def _nearest_on_finger(point, finger, eligible, first_edge, last_edge, nearest, candidate):
    """The nearest point of a finger's centre line, world nodes ``finger`` (N, 3), on its ``eligible`` (N − 1,)
    edges from ``first_edge`` to ``last_edge``: returns (distance [m], edge, t) and writes the point to ``nearest``
    (3,); edge −1 where none is eligible. ``candidate`` (3,) is scratch."""
    best, best_edge, best_t = np.inf, -1, 0.0
    for j in range(first_edge, last_edge + 1):
        if not eligible[j]:
            continue
        distance = distance_to_segment(point, finger[j], finger[j + 1], candidate)
        if distance < best:
            length2 = 0.0
            along = 0.0
            for k in range(3):
                length2 += (finger[j + 1, k] - finger[j, k]) ** 2
                along += (candidate[k] - finger[j, k]) * (finger[j + 1, k] - finger[j, k])
            best, best_edge, best_t = distance, j, along / length2 if length2 > 0.0 else 0.0
            for k in range(3):  # element by element: the GPU build copies no array into another
                nearest[k] = candidate[k]
    return best, best_edge, best_t


@kernel
def _onto_tangent_plane(vector, normal):
    """Removes from ``vector`` (3,) its part along the unit ``normal`` (3,)."""
    along = vector[0] * normal[0] + vector[1] * normal[1] + vector[2] * normal[2]
    for k in range(3):
        vector[k] -= along * normal[k]


@kernel(inline=True)
def _finger_world(q_rod, axes, out):
    """A finger's world node positions (N, 3) [m] from its coordinates (N, ≥D)."""
    for i in range(q_rod.shape[0]):
        _world(q_rod[i], axes, out[i])


@kernel(python=True)
def find_near_fingers(q_old, q_pred, contact, near, scratch):
    """:func:`near_fingers_of_gripper` for every gripper, with the work buffer ``scratch``
    (:func:`finger_scratch`)."""
    if contact.stiffness == 0.0:
        return
    n_fingers = contact.eligible.shape[0]
    for first_rod in range(0, q_old.shape[0], n_fingers):
        near_fingers_of_gripper(first_rod, q_old, q_pred, contact, near, scratch)


@kernel
def near_fingers_of_gripper(first_rod, q_old, q_pred, contact, near, scratch):
    """For the gripper whose rods start at ``first_rod``: the nearest eligible edge of each other finger o to each
    node i of each rod r at the start of the step, into ``near[r, i, o]`` where the node is within the reach plus
    :data:`NEAR_MARGIN` plus twice the node's and the other finger's nearby nodes' predicted motion, else
    −1. Arrays (R, N, S); ``contact`` is
    :class:`FingerContact`; ``near`` (R, N, F) int (empty, and left alone, without finger contact); ``scratch``
    the work buffer (:func:`finger_scratch`)."""
    stiffness, radius, eligible, axes = contact.stiffness, contact.radius, contact.eligible, contact.axes
    if stiffness == 0.0:
        return
    n_fingers, n_nodes = eligible.shape[0], eligible.shape[1]
    for f in range(n_fingers):
        near[first_rod + f, :, :] = -1
    points, _, _, old, motion, centres, bounds, chunk_motion = finger_views(scratch, n_fingers, n_nodes)
    point, nearest, candidate = points[0], points[1], points[2]
    for f in range(n_fingers):
        _finger_world(q_old[first_rod + f], axes[f], old[f])
        for i in range(n_nodes):
            _world(q_pred[first_rod + f, i], axes[f], point)
            motion[f, i] = math.sqrt((point[0] - old[f, i, 0]) ** 2 + (point[1] - old[f, i, 1]) ** 2
                                     + (point[2] - old[f, i, 2]) ** 2)
    # each finger's edges in runs of CHUNK_EDGES, each within a sphere (centre, radius with the finger's): a node
    # far from a run's sphere skips its edges, which makes the search cheap while the fingers are apart
    n_chunks = (n_nodes - 2) // CHUNK_EDGES + 1
    chunk_motion[:, :] = 0.0
    for o in range(n_fingers):
        for c in range(n_chunks):
            first_node, last_node = c * CHUNK_EDGES, min((c + 1) * CHUNK_EDGES, n_nodes - 1)
            for k in range(3):
                centres[o, c, k] = 0.5 * (old[o, first_node, k] + old[o, last_node, k])
            bound = 0.0
            for j in range(first_node, last_node + 1):
                apart = math.sqrt((old[o, j, 0] - centres[o, c, 0]) ** 2 + (old[o, j, 1] - centres[o, c, 1]) ** 2
                                  + (old[o, j, 2] - centres[o, c, 2]) ** 2)
                bound = max(bound, apart + radius[j])
                chunk_motion[o, c] = max(chunk_motion[o, c], motion[o, j])
            bounds[o, c] = bound
    for f in range(n_fingers):
        for i in range(n_nodes):
            node = old[f, i]  # views taken out of the loops below
            for o in range(n_fingers):
                if o == f:
                    continue
                other, allowed = old[o], eligible[f, i, o]
                best, best_edge, best_t, best_motion = np.inf, -1, 0.0, 0.0
                for c in range(n_chunks):
                    allowance = radius[i] + NEAR_MARGIN + 2.0 * (motion[f, i] + chunk_motion[o, c])
                    to_centre = math.sqrt((old[f, i, 0] - centres[o, c, 0]) ** 2
                                          + (old[f, i, 1] - centres[o, c, 1]) ** 2
                                          + (old[f, i, 2] - centres[o, c, 2]) ** 2)
                    if to_centre - bounds[o, c] > allowance:
                        continue
                    last_edge = min((c + 1) * CHUNK_EDGES, n_nodes - 1) - 1
                    distance, edge, t = _nearest_on_finger(node, other, allowed, c * CHUNK_EDGES, last_edge, nearest,
                                                           candidate)
                    if distance < best:
                        best, best_edge, best_t, best_motion = distance, edge, t, chunk_motion[o, c]
                if best_edge < 0:
                    continue
                reach = radius[i] + (1.0 - best_t) * radius[best_edge] + best_t * radius[best_edge + 1]
                if best < reach + NEAR_MARGIN + 2.0 * (motion[f, i] + best_motion):
                    near[first_rod + f, i, o] = best_edge


@kernel(inline=True)
def any_near(near, r):
    """Whether any node of rod r is near another finger (``near`` (R, N, F) from :func:`find_near_fingers`)."""
    found = False
    for i in range(near.shape[1]):
        for o in range(near.shape[2]):
            found |= near[r, i, o] >= 0
    return found


@kernel(python=True)
def finger_contact_rod(r, q, q_old, q_pred, dt, contact, near, hessian, force, band, scratch):
    """Adds the other fingers' contact force on rod r's nodes [N] to ``force`` (N, S), in the rod's coordinates, and
    its Newton matrix to ``band`` (n, kd+1) (when ``hessian``), for the step of ``dt`` [s] from ``q_old`` with
    predictor ``q_pred`` (arrays (R, N, S); the other fingers stay where they were at the start of the step, see
    the module notes). ``near`` (R, N, F) from :func:`find_near_fingers`; ``scratch`` the work buffer
    (:func:`finger_scratch`)."""
    if contact.stiffness == 0.0:
        return
    stiffness, mu, radius, eligible, axes = contact.stiffness, contact.friction, contact.radius, contact.eligible, \
        contact.axes
    n_fingers, n_nodes = eligible.shape[0], eligible.shape[1]
    if not any_near(near, r):  # the common case, before any work array is made
        return
    f = r % n_fingers
    first_rod = r - f
    dim = axes.shape[1]
    stride = q.shape[2]
    kd = band.shape[1] - 1
    own_axes = axes[f]
    points, other_old, matrix, _, _, _, _, _ = finger_views(scratch, n_fingers, n_nodes)
    x, x_old, nearest, nearest_old, candidate = points[0], points[1], points[2], points[3], points[4]
    normal, slip, world_force, end_a, end_b = points[5], points[6], points[7], points[8], points[9]
    for o in range(n_fingers):
        if o == f:
            continue
        loaded = False  # the other finger's world nodes, once it is near any node
        for i in range(n_nodes):
            edge0 = near[r, i, o]
            if edge0 < 0:
                continue
            if not loaded:
                _finger_world(q_old[first_rod + o], axes[o], other_old)
                loaded = True
            first_edge = max(edge0 - SEARCH_WINDOW, 0)
            last_edge = min(edge0 + SEARCH_WINDOW, n_nodes - 2)
            _world(q[r, i], own_axes, x)
            _world(q_old[r, i], own_axes, x_old)
            distance, edge, t = _nearest_on_finger(x, other_old, eligible[f, i, o], first_edge, last_edge, nearest,
                                                   candidate)
            distance_old, edge_old, t_old = _nearest_on_finger(x_old, other_old, eligible[f, i, o], first_edge,
                                                               last_edge, nearest_old, candidate)
            reach = radius[i] + (1.0 - t) * radius[edge] + t * radius[edge + 1]
            overlap = reach - distance_old - 2.0 * (distance - distance_old)
            start_push = 0.0  # friction's normal force, the start of the step's (the module notes say why)
            if edge_old >= 0 and distance_old > 0.0:
                start_push = stiffness * (radius[i] + (1.0 - t_old) * radius[edge_old]
                                          + t_old * radius[edge_old + 1] - distance_old)
            pushes = overlap > 0.0 and distance > 0.0
            rubs = mu > 0.0 and start_push > 0.0
            if not (pushes or rubs):
                continue
            world_force[:] = 0.0
            matrix[:, :] = 0.0
            if pushes:
                push = stiffness * overlap
                for k in range(3):
                    normal[k] = (x[k] - nearest[k]) / distance
                for k in range(3):  # the whole normal first: the matrix reads every component
                    world_force[k] = push * normal[k]
                    for m in range(3):
                        matrix[k, m] = 2.0 * stiffness * normal[k] * normal[m]
            if rubs:  # against the other finger's start-of-step velocity at the start's nearest point, along the
                # start's tangent plane
                _world(q_old[first_rod + o, edge_old], axes[o], end_a)
                _world(q_pred[first_rod + o, edge_old], axes[o], end_b)
                for k in range(3):
                    normal[k] = (x_old[k] - nearest_old[k]) / distance_old
                    slip[k] = (x[k] - x_old[k] - (1.0 - t_old) * (end_b[k] - end_a[k])) / dt
                _world(q_old[first_rod + o, edge_old + 1], axes[o], end_a)
                _world(q_pred[first_rod + o, edge_old + 1], axes[o], end_b)
                for k in range(3):
                    slip[k] -= t_old * (end_b[k] - end_a[k]) / dt
                _onto_tangent_plane(slip, normal)
                speed = math.sqrt(slip[0] ** 2 + slip[1] ** 2 + slip[2] ** 2 + STICK_SPEED**2)
                rub = mu * start_push
                for k in range(3):
                    world_force[k] -= rub * slip[k] / speed
                    for m in range(3):
                        tangent_plane = (1.0 if k == m else 0.0) - normal[k] * normal[m]
                        matrix[k, m] += rub / dt * (tangent_plane / speed - slip[k] * slip[m] / speed**3)
            for a in range(dim):
                value = 0.0
                for k in range(3):
                    value += own_axes[a, k] * world_force[k]
                force[i, a] += value
            if not hessian:
                continue
            for a in range(dim):
                row = stride * i + a
                for b in range(a + 1):
                    value = 0.0
                    for k in range(3):
                        for m in range(3):
                            value += own_axes[a, k] * matrix[k, m] * own_axes[b, m]
                    band[row, kd - a + b] += value


__all__ = ["any_near", "SEARCH_WINDOW", "CHUNK_EDGES", "NEAR_MARGIN", "FingerContact", "N_SCRATCH_POINTS",
           "finger_scratch_size", "finger_scratch", "finger_views", "find_near_fingers",
           "near_fingers_of_gripper", "finger_contact_rod"]
