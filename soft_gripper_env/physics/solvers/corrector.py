"""The contact corrector: one compiled loop around Newton's method, for fixed objects and free bodies alike.

The step is solved (:func:`~.newton.newton`); every free node found inside the object by more than
:data:`~..scene.objects.PENETRATION_TOLERANCE` is held on its surface, and the step is solved again with those nodes
held. The paper projects the node radially; we hold it where its path over the step (relative to the object)
entered the surface, which is the same for a slow node and keeps a fast impact (a node 1 cm inside after a step at
1 m/s) from stretching its edges by the projection. The reaction on a held node is the unbalanced force of its
equation of motion, R = M·a − f. Contact is compression-only: a held node whose normal reaction R·n turns adhesive
(pulls it into the object, R·n < 0) is released (a reaction pulling by less than Newton's force tolerance is zero to
that tolerance and stays) and the step solved again, from the last solution. The corrector repeats until nothing
changes, at most :attr:`~..scene.objects.ContactSettings.max_corrector_iterations` times; if nodes are still inside
the object then, it holds them, releasing nothing, until none is (the step then reports ``resolved = False``).
Held nodes stick: they stay where they were held until released, so the contact transmits tangential force without
sliding. The base clamp is kept throughout.

A fixed object is a body that does not move: its held nodes stay on the points where they were held, and only the
rods whose contacts changed are solved again. A free body moves with the rods that hold it: a held node keeps its
offset in the body's frame, and a gripper whose contacts changed is solved again whole, body included.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..kernels.assembly import RodArrays, StepInputs
from ..kernels.body import BodyArrays, BodyMotion, BodyState, body_in_rod_frames, planar_body_basis, turned
from ..kernels.contact import ObjectView, find_penetrations, normal_reactions, within_reach
from ..scene.forces import ForceTerms
from ..scene.objects import PENETRATION_TOLERANCE
from .newton import BodyCoupling, Holds, SolverArrays, SolveResult, newton


class ContactGeometry(NamedTuple):
    """The object as each rod sees it, and how the rods lie around the palm."""

    starts: np.ndarray
    """One end of the object's segment in each rod's coordinates [m], (R, D): given for a fixed object, written at
    the solution for a free one."""
    ends: np.ndarray
    """The other end [m], (R, D)."""
    radii: np.ndarray
    """The distance from the segment at which each node's centre line touches the object [m], (R, N)
    (:class:`~..kernels.contact.ObjectView`)."""
    finger_radius: np.ndarray
    """Each node's finger radius that contact adds to the object's [m], (N,): zeros for contact on the centre
    lines."""
    finger_directions: np.ndarray
    """Unit radial direction of each finger, (F, 3)."""
    plane_normals: np.ndarray
    """Normal of each finger's vertical plane, (F, 3)."""
    any_motion: np.ndarray
    """A 3-D free body's admissible motions, the identity per gripper (B, 6, 6); empty for planar fingers, whose
    basis depends on the holds (:func:`~..kernels.body.planar_body_basis`)."""


class ContactChanges(NamedTuple):
    """What the corrector's test finds after a solve."""

    adhesive: np.ndarray
    """Holds whose normal reaction pulls, (R, N) bool."""
    new_hold: np.ndarray
    """Free nodes inside the object, (R, N) bool."""
    hold_at: np.ndarray
    """Where each node is held, in its rod's coordinates [m], (R, N, D); written for the new holds."""
    changed: np.ndarray
    """Rods with either, (R,) bool."""


@njit(cache=True, error_model="numpy")
def solve_with_contact(q, step, rods, terms, solver, holds, hold_at, geometry, free_body, result):
    """The predictor–corrector for every gripper of a batch (see the module notes).

    ``q`` (R, N, S) holds Newton's start and receives the solution; ``holds`` (:class:`~.newton.Holds`) the holds at
    the start of the step (``held`` (R, N), and for a free body their ``offsets``), updated in place; ``hold_at``
    (R, N, D) where each held node is held in its rod's coordinates, the start of the step's positions on entry.
    ``geometry`` is :class:`ContactGeometry`; ``free_body`` None for a fixed object, else the bodies' arrays
    (:class:`~..kernels.body.BodyArrays`) and their unknowns (:class:`~..kernels.body.BodyMotion`, start and solution).
    Writes per rod the Newton results, the corrector's solves and whether the last test still changed the rod's
    contacts into ``result`` (:class:`~.newton.SolveResult`). Every bundle arrives as its fields in plain tuples
    (:func:`~.newton.plain`) and is named again here; the loop is compiled apart for fixed and free objects.
    """
    step, rods, terms, solver = StepInputs(*step), RodArrays(*rods), ForceTerms(*terms), SolverArrays(*solver)
    holds, geometry, result = Holds(*holds), ContactGeometry(*geometry), SolveResult(*result)
    if free_body is None:
        _correct(q, step, rods, terms, solver, holds, hold_at, geometry, None, result)
    else:
        body, motion = free_body
        moving = (BodyArrays(*body), BodyMotion(motion[0], motion[1], motion[2], BodyState(*motion[3]), motion[4],
                                                    motion[5]))
        _correct(q, step, rods, terms, solver, holds, hold_at, geometry, moving, result)


@njit(cache=True, error_model="numpy", inline="always")
def _correct(q, step, rods, terms, solver, holds, hold_at, geometry, moving, result):
    """The corrector's loop; ``moving`` is None for a fixed object, else (bodies, their motion), and every branch
    on the body tests it, so that a fixed object's loop is compiled without them."""
    n_rods, n_nodes, _ = q.shape
    dim = step.water.shape[1]
    n_fingers = solver.n_fingers
    held = holds.held
    starts, ends, radii = geometry.starts, geometry.ends, geometry.radii
    solve = np.ones(n_rods, dtype=np.bool_)
    free = np.empty_like(solver.clamp_free)
    rotation = np.empty((3, 3))
    shift = np.zeros((n_rods, dim))
    new_hold = np.empty((n_rods, n_nodes), dtype=np.bool_)
    adhesive = np.empty((n_rods, n_nodes), dtype=np.bool_)
    changes = ContactChanges(adhesive, new_hold, hold_at, result.changed)
    positions, old_positions = q[:, :, :dim], step.q_old[:, :, :dim]
    result.corrector[:] = 0
    result.residual[:, :] = 0.0
    for k in range(solver.max_corrector_iterations + n_nodes + 1):  # holds-only solves end by N
        free[:, :] = solver.clamp_free
        release_held(free, held, dim)
        if moving is not None:
            basis = geometry.any_motion if dim == 3 else planar_body_basis(held, geometry.plane_normals)
            newton(q, step, rods, terms, solver, free, BodyCoupling(holds, moving[0], moving[1], basis), solve, result)
            _body_at_solution(step, solver, holds, geometry, moving[0], moving[1], rotation, shift)
        else:  # a fixed object's holds stay where they were held; solved from the last solution, warm
            _hold_in_place(positions, held, hold_at, solve)
            newton(q, step, rods, terms, solver, free, None, solve, result)
        view = ObjectView(starts, ends, radii, within_reach(starts, ends, radii, solver.finger_length), shift)
        contact_changes(positions, old_positions, result.residual, held, view, solver, changes)
        within_budget = k < solver.max_corrector_iterations
        if not corrector_continues(within_budget, new_hold, result.changed, solve):
            break
        if moving is not None:
            _body_frame_offsets(new_hold, hold_at, holds, moving[1], n_fingers)
        update_holds(within_budget, held, adhesive, new_hold)
        for r in range(n_rods):
            if solve[r]:
                result.corrector[r] += 1


@njit(cache=True, error_model="numpy")
def _hold_in_place(positions, held, hold_at, solve):
    """Puts the held nodes of the rods to be solved on their hold points (a fixed object's holds)."""
    for r in range(positions.shape[0]):
        if not solve[r]:
            continue
        for i in range(positions.shape[1]):
            if held[r, i]:
                for d in range(positions.shape[2]):
                    positions[r, i, d] = hold_at[r, i, d]


@njit(cache=True, error_model="numpy")
def _body_at_solution(step, solver, holds, geometry, body, motion, rotation, shift):
    """After a solve with free bodies: their orientation at the solution, the object as each rod sees it there, and
    its displacement over the step in each rod's coordinates (``shift`` (R, D))."""
    c, c_old = motion.position, motion.old.position
    for b in range(c.shape[0]):
        turned(motion.rotation[b], motion.old.orientation[b], rotation, motion.orientation[b])
    body_in_rod_frames(c, motion.orientation, body.segment_start, body.segment_end, body.radius,
                       geometry.finger_radius, geometry.finger_directions, geometry.plane_normals, geometry.starts,
                       geometry.ends, geometry.radii)
    projection = holds.projection
    for r in range(shift.shape[0]):
        b = r // solver.n_fingers
        for d in range(shift.shape[1]):
            shift[r, d] = projection[r, d, 0] * (c[b, 0] - c_old[b, 0]) \
                + projection[r, d, 1] * (c[b, 1] - c_old[b, 1]) + projection[r, d, 2] * (c[b, 2] - c_old[b, 2])


@njit(cache=True, error_model="numpy")
def _body_frame_offsets(new_hold, hold_at, holds, motion, n_fingers):
    """The offset of each new hold in its body's frame at the end of the last solve [m], into ``holds.offsets``."""
    projection, orientation, c = holds.projection, motion.orientation, motion.position
    dim = hold_at.shape[2]
    for r in range(new_hold.shape[0]):
        b = r // n_fingers
        for i in range(new_hold.shape[1]):
            if not new_hold[r, i]:
                continue
            for m in range(3):
                value = 0.0
                for j in range(3):
                    world = 0.0
                    for d in range(dim):
                        world += projection[r, d, j] * hold_at[r, i, d]
                    value += orientation[b, j, m] * (world - c[b, j])
                holds.offsets[r, i, m] = value


@njit(cache=True, error_model="numpy")
def contact_changes(positions, old_positions, residual, held, view, solver, changes):
    """The corrector's test after a solve, for rods whose nodes are at ``positions`` (R, N, D) and whose residual
    (R, n) holds the reactions on held DOFs, against the object as each rod sees it (``view``,
    :class:`~..kernels.contact.ObjectView`). Marks in ``changes.adhesive`` (R, N) the holds whose normal reaction
    pulls by more than Newton's force tolerance ``solver.force_tolerance`` [N] (a reaction is known to that
    tolerance: one pulling by less is zero, and releasing it would only make the corrector cycle), in
    ``changes.new_hold`` (R, N) the free nodes that penetrate the object, with their hold points in
    ``changes.hold_at`` (:func:`~..kernels.contact.find_penetrations`), and in ``changes.changed`` (R,) the rods
    with either (:class:`ContactChanges`)."""
    adhesive, new_hold, changed = changes.adhesive, changes.new_hold, changes.changed
    n_rods, n_nodes, dim = positions.shape
    stride = residual.shape[1] // n_nodes
    reaction = np.zeros((n_rods, n_nodes, dim))
    for r in range(n_rods):
        for i in range(n_nodes):
            if held[r, i]:
                for d in range(dim):
                    reaction[r, i, d] = residual[r, stride * i + d]
    normal = normal_reactions(positions, reaction, view.starts, view.ends)
    new_hold[:, :] = False
    found = find_penetrations(positions, old_positions, view, held, solver.first_free_node, PENETRATION_TOLERANCE,
                              new_hold, changes.hold_at)
    force_tolerance = solver.force_tolerance
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


__all__ = ["ContactGeometry", "solve_with_contact", "contact_changes", "corrector_continues", "update_holds",
           "release_held"]
