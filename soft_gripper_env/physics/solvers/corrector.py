"""The contact corrector: one compiled loop around Newton's method, for fixed objects and free bodies alike.

The step is solved (:func:`~.newton.newton`); every free node found inside the object by more than
:func:`~..scene.objects.penetration_tolerance` is held on its surface, and the step is solved again with those nodes
held. The paper projects the node radially; we hold it where its path over the step (relative to the object)
entered the surface, which is the same for a slow node and keeps a fast impact (a node 1 cm inside after a step at
1 m/s) from stretching its edges by the projection. The reaction on a held node is the unbalanced force of its
equation of motion, R = M·a − f. Contact is compression-only: a held node whose normal reaction R·n turns adhesive
(pulls it into the object, R·n < 0) is released (a reaction pulling by less than Newton's force tolerance is zero to
that tolerance and stays) and the step solved again, from the last solution. Every step starts with its holds
stuck, and a stuck hold's reaction also stops the node along the surface, which can pull it in: such a hold (one
held since the step began) slides first, and is let go if it still pulls.

Contact has Coulomb friction μ (the object's): a held node is stuck to a point of the object while its tangential
reaction is within μ·R_n, and otherwise slides along the surface against a friction μ·R_n opposite to its slip
(solved in its surface's frame, :func:`~.newton.newton`); a sliding node whose slip turns back against its friction
sticks again. Friction is held fixed through a solve and updated here until it settles (:data:`FRICTION_TOLERANCE`).
The corrector repeats until nothing changes, at most
:attr:`~..scene.objects.ContactSettings.max_corrector_iterations` times; if nodes are still inside the object then,
it holds them, releasing nothing and changing no friction, until none is (the step then reports
``resolved = False``). The base clamp is kept throughout. ``docs/contact.md`` describes the method and why.

A fixed object is a body that does not move: its stuck nodes stay on the points where they were held, and only the
rods whose contacts changed are solved again. A free body moves with the rods that hold it: a stuck node keeps its
offset in the body's frame, and a gripper whose contacts changed is solved again whole, body included.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..kernels.assembly import StepInputs, named_rods
from ..kernels.body import BodyArrays, BodyMotion, BodyState, body_in_rod_frames, planar_body_basis, turned
from ..kernels.compiled import kernel
from ..kernels.contact import ObjectView, find_penetrations, outward_normal, within_reach
from ..kernels.finger_contact import find_near_fingers
from ..kernels.local import local_array
from ..kernels.typed_none import none_or
from ..scene.forces import ForceTerms
from .newton import BodyCoupling, Holds, NewtonWork, SolverArrays, SolveResult, new_work, newton


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
    friction: np.ndarray
    """The Coulomb friction coefficient μ of each rod's object (dimensionless), (R,); inf sticks."""
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
    slide: np.ndarray
    """Which held nodes slide in the next solve, (R, N) bool."""
    friction: np.ndarray
    """The friction force on each node that slides in the next solve [N], (R, N, D)."""
    stuck_again: np.ndarray
    """Sliding nodes that stick again where they are, (R, N) bool (their hold points are in ``hold_at``)."""
    changed: np.ndarray
    """Rods with any of these, (R,) bool."""
    let_go_if_pulling: np.ndarray
    """Holds let go at once if their normal reaction pulls, (R, N) bool, kept from one solve of a step to the next:
    nodes caught in this step, and nodes a pull has already made slide in it. Any other stuck hold that pulls slides
    first."""


class CorrectorWork(NamedTuple):
    """The corrector's scratch for a batch of R rods of N nodes (n DOFs each) in B grippers: made once per call of a
    CPU entry point (:func:`corrector_work`), the thread's own arrays for one gripper on the GPU. Nothing in it
    carries from one step to the next."""

    solve: np.ndarray
    """The rods the next solve is for, (R,) bool."""
    free: np.ndarray
    """The DOFs Newton solves for, (R, n) bool."""
    shift: np.ndarray
    """A free body's displacement over the step in each rod's coordinates [m], (R, D)."""
    adhesive: np.ndarray
    """:attr:`ContactChanges.adhesive`, (R, N) bool."""
    new_hold: np.ndarray
    """:attr:`ContactChanges.new_hold`, (R, N) bool."""
    slide: np.ndarray
    """:attr:`ContactChanges.slide`, (R, N) bool."""
    friction: np.ndarray
    """:attr:`ContactChanges.friction` [N], (R, N, D)."""
    stuck_again: np.ndarray
    """:attr:`ContactChanges.stuck_again`, (R, N) bool."""
    let_go_if_pulling: np.ndarray
    """:attr:`ContactChanges.let_go_if_pulling`, (R, N) bool."""
    anchors: np.ndarray
    """Where a free body's held nodes stuck last [m], (R, N, D)."""
    reach: np.ndarray
    """The rods that can touch the object, (R,) bool."""
    found: np.ndarray
    """New holds per rod, (R,) int."""
    basis: np.ndarray
    """A planar free body's admissible motions, (B, 6, 6) (empty for a fixed object or in 3-D)."""
    newton: NewtonWork
    """Newton's scratch for one gripper."""


@kernel(runtime=True)  # it allocates
def corrector_work(q, dim, n_fingers, free_body, finger_contact):
    """:class:`CorrectorWork` for the rods of ``q`` (R, N, S) with ``dim`` position coordinates and ``n_fingers``
    rods per gripper, against a ``free_body`` or a fixed object, with or without ``finger_contact``."""
    n_rods, n_nodes, stride = q.shape
    flags = np.empty((5, n_rods, n_nodes), dtype=np.bool_)
    points = np.empty((2, n_rods, n_nodes, dim))
    n_bases = n_rods // n_fingers if free_body and dim == 2 else 0
    return CorrectorWork(np.empty(n_rods, dtype=np.bool_), np.empty((n_rods, n_nodes * stride), dtype=np.bool_),
                         np.zeros((n_rods, dim)), flags[0], flags[1], flags[2], points[0], flags[3], flags[4],
                         points[1], np.empty(n_rods, dtype=np.bool_), np.empty(n_rods, dtype=np.int64),
                         np.empty((n_bases, 6, 6)), new_work(q, dim, n_fingers, free_body, True, finger_contact))


@kernel(python=True, runtime=True)  # its scratch is allocated here
def solve_with_contact(q, step, rods, terms, solver, holds, hold_at, geometry, free_body, result):
    """The predictor–corrector for every gripper of a batch (see the module notes): :func:`correct_contacts` with
    its scratch made here. Every bundle arrives as its fields in plain tuples (:func:`~.newton.plain`)."""
    work = corrector_work(q, step[3].shape[1], solver[5], free_body is not None, step[5].size > 0)
    correct_contacts(q, step, rods, terms, solver, holds, hold_at, geometry, free_body, result, work)


@kernel(inline=True)
def correct_contacts(q, step, rods, terms, solver, holds, hold_at, geometry, free_body, result, work):
    """The predictor–corrector for every gripper of a batch (see the module notes), with the scratch ``work``
    (:class:`CorrectorWork`).

    ``q`` (R, N, S) holds Newton's start and receives the solution; ``holds`` (:class:`~.newton.Holds`) the holds at
    the start of the step (``held`` (R, N), and for a free body their ``offsets``), updated in place; ``hold_at``
    (R, N, D) where each held node is held in its rod's coordinates, the start of the step's positions on entry.
    ``geometry`` is :class:`ContactGeometry`; ``free_body`` None for a fixed object, else the bodies' arrays
    (:class:`~..kernels.body.BodyArrays`) and their unknowns (:class:`~..kernels.body.BodyMotion`, start and solution).
    Writes per rod the Newton results, the corrector's solves and whether the last test still changed the rod's
    contacts into ``result`` (:class:`~.newton.SolveResult`). Every bundle arrives as its fields in plain tuples
    (:func:`~.newton.plain`) and is named again here; the loop is compiled apart for fixed and free objects.
    """
    step, rods, terms, solver = StepInputs(*step), named_rods(rods), ForceTerms(*terms), SolverArrays(*solver)
    find_near_fingers(step.q_old, step.q_pred, rods.fingers, step.near, work.newton.fingers)
    holds, geometry, result = Holds(*holds), ContactGeometry(*geometry), SolveResult(*result)
    _correct(q, step, rods, terms, solver, holds, hold_at, geometry, named_free_body(free_body), result, work)


@kernel(runtime=True)  # its bundle goes to the step's entry points, which have the runtime
def _named_free_body(free_body):
    """The bodies' arrays and their unknowns as plain tuples, named (:class:`~..kernels.body.BodyArrays`,
    :class:`~..kernels.body.BodyMotion`)."""
    body, motion = free_body
    return (BodyArrays(*body), BodyMotion(motion[0], motion[1], motion[2], BodyState(*motion[3]), motion[4],
                                          motion[5]))


named_free_body = none_or(_named_free_body)
""":func:`_named_free_body`, or None for a fixed object (chosen as the kernel compiles:
:mod:`~..kernels.typed_none`)."""


@kernel
def _body_coupling(moving, geometry, held, dim, basis_work):
    """What couples the rods to the ``moving`` bodies in Newton's method (:class:`~.newton.BodyCoupling`): in 3-D
    every motion of a body, planar the motions in the plane that its held nodes leave it."""
    if dim == 3:
        return BodyCoupling(moving[0], moving[1], geometry.any_motion)
    planar_body_basis(held, geometry.plane_normals, basis_work)
    return BodyCoupling(moving[0], moving[1], basis_work)


body_coupling = none_or(_body_coupling)
""":func:`_body_coupling`, or None for a fixed object (chosen as the kernel compiles)."""


@kernel
def _correct(q, step, rods, terms, solver, holds, hold_at, geometry, moving, result, work):
    """The corrector's loop; ``moving`` is None for a fixed object, else (bodies, their motion), and every branch
    on the body tests it, so that a fixed object's loop is compiled without them."""
    n_rods, n_nodes, _ = q.shape
    dim = step.water.shape[1]
    n_fingers = solver.n_fingers
    held, sliding = holds.held, holds.sliding
    starts, ends, radii = geometry.starts, geometry.ends, geometry.radii
    solve, free, shift, new_hold = work.solve, work.free, work.shift, work.new_hold
    solve[:] = True
    shift[:, :] = 0.0
    rotation = local_array((3, 3))
    work.slide[:, :] = False
    work.friction[:, :, :] = 0.0
    work.stuck_again[:, :] = False
    work.let_go_if_pulling[:, :] = False
    changes = ContactChanges(work.adhesive, new_hold, hold_at, work.slide, work.friction, work.stuck_again,
                             result.changed, work.let_go_if_pulling)
    positions, old_positions = q[:, :, :dim], step.q_old[:, :, :dim]
    result.corrector[:] = 0
    result.residual[:, :] = 0.0
    for k in range(solver.max_corrector_iterations + n_nodes + 1):  # holds-only solves end by N
        contact_masks(solver.clamp_free, held, sliding, dim, free, holds.measured)
        if moving is None:  # a fixed object's stuck nodes stay where they were held; solved from the last solution
            _hold_in_place(positions, held, sliding, hold_at, solve)
        newton(q, step, rods, terms, solver, free, holds, body_coupling(moving, geometry, held, dim, work.basis), solve,
               result, work.newton)
        if moving is not None:
            _body_at_solution(step, solver, holds, geometry, moving[0], moving[1], rotation, shift)
        within_reach(starts, ends, radii, solver.finger_length, work.reach)
        view = ObjectView(starts, ends, radii, work.reach, shift)
        within_budget = k < solver.max_corrector_iterations
        anchors = hold_at if moving is None else _anchors(holds, moving[1], n_fingers, work.anchors)
        contact_changes(positions, old_positions, anchors, result.residual, holds, view, geometry.friction, solver,
                        within_budget, k < solver.friction_passes, changes, work.found)
        if not corrector_continues(within_budget, new_hold, result.changed, solve):
            break
        if moving is not None:
            _body_frame_offsets(new_hold, changes.stuck_again, hold_at, holds, moving[1], n_fingers)
        update_holds(within_budget, holds, changes, solve, n_fingers, moving is not None)
        for r in range(n_rods):
            if solve[r]:
                result.corrector[r] += 1
    if moving is not None:  # a sliding node stops where it is, on the body, when the step ends
        new_hold[:, :] = False  # (no longer read: no new holds, so only the sliding nodes' offsets are set)
        _body_frame_offsets(new_hold, sliding, positions, holds, moving[1], n_fingers)


@kernel
def _hold_in_place(positions, held, sliding, hold_at, solve):
    """Puts the stuck nodes of the rods to be solved on their hold points (a fixed object's holds)."""
    for r in range(positions.shape[0]):
        if not solve[r]:
            continue
        for i in range(positions.shape[1]):
            if held[r, i] and not sliding[r, i]:
                for d in range(positions.shape[2]):
                    positions[r, i, d] = hold_at[r, i, d]


@kernel
def _body_at_solution(step, solver, holds, geometry, body, motion, rotation, shift):
    """After a solve with free bodies: their orientation at the solution, the object as each rod sees it there, and
    its displacement over the step in each rod's coordinates (``shift`` (R, D))."""
    c, c_old = motion.position, motion.old.position
    for b in range(c.shape[0]):
        turned(motion.rotation[b], motion.old.orientation[b], rotation, motion.orientation[b])
    body_in_rod_frames(c, motion.orientation, body.segment_start, body.segment_end, body.radius,
                       geometry.finger_radius, geometry.finger_directions, geometry.plane_normals, geometry.starts,
                       geometry.ends, geometry.radii)  # (the same arrays as holds.starts, .ends and .radii)
    projection = holds.projection
    for r in range(shift.shape[0]):
        b = r // solver.n_fingers
        for d in range(shift.shape[1]):
            shift[r, d] = projection[r, d, 0] * (c[b, 0] - c_old[b, 0]) \
                + projection[r, d, 1] * (c[b, 1] - c_old[b, 1]) + projection[r, d, 2] * (c[b, 2] - c_old[b, 2])


@kernel
def _anchors(holds, motion, n_fingers, anchors):
    """Where each held node of a free body's rods stuck last, P·(c + R·r_h) at the body's pose after the last solve,
    into ``anchors`` (R, N, D), which it returns."""
    projection, orientation, c = holds.projection, motion.orientation, motion.position
    for r in range(anchors.shape[0]):
        b = r // n_fingers
        for i in range(anchors.shape[1]):
            if not holds.held[r, i]:
                continue
            for d in range(anchors.shape[2]):
                value = 0.0
                for k in range(3):
                    world = c[b, k]
                    for m in range(3):
                        world += orientation[b, k, m] * holds.offsets[r, i, m]
                    value += projection[r, d, k] * world
                anchors[r, i, d] = value
    return anchors


@kernel
def _body_frame_offsets(new_hold, stuck_again, hold_at, holds, motion, n_fingers):
    """The offset of each new hold, and each sliding node that sticks again, in its body's frame at the end of the
    last solve [m], into ``holds.offsets``."""
    projection, orientation, c = holds.projection, motion.orientation, motion.position
    dim = hold_at.shape[2]
    for r in range(new_hold.shape[0]):
        b = r // n_fingers
        for i in range(new_hold.shape[1]):
            if not (new_hold[r, i] or stuck_again[r, i]):
                continue
            for m in range(3):
                value = 0.0
                for j in range(3):
                    world = 0.0
                    for d in range(dim):
                        world += projection[r, d, j] * hold_at[r, i, d]
                    value += orientation[b, j, m] * (world - c[b, j])
                holds.offsets[r, i, m] = value


FRICTION_TOLERANCE = 5e-3
"""A sliding node's friction is solved again when its Coulomb value μ·R_n (and direction) moved by more than this
fraction since the solve (plus Newton's force tolerance)."""


@kernel(python=True)
def contact_changes(positions, old_positions, anchors, residual, holds, view, friction, solver, within_budget,
                    settle_friction, changes, found):
    """The corrector's test after a solve, for rods whose nodes are at ``positions`` (R, N, D) and whose residual
    (R, n) holds the reactions on held DOFs, against the object as each rod sees it (``view``,
    :class:`~..kernels.contact.ObjectView`), with Coulomb friction ``friction`` μ (R,) (:class:`ContactChanges`).
    ``anchors`` (R, N, D) are the points where the sliding nodes were stuck last, on the object as it is now:

    - ``adhesive``: held nodes whose normal reaction R_n pulls by more than Newton's force tolerance
      ``solver.force_tolerance`` [N] (a reaction is known to that tolerance: one pulling by less is zero, and
      releasing it would only make the corrector cycle), and held nodes on the segment itself, where a planar
      finger's section of a sphere that has left its plane has shrunk to a point. A stuck hold that pulls is let go
      only if it was caught in this step or a pull already made it slide (``let_go_if_pulling``); otherwise it
      slides first, without friction, within the budget and for finite μ;
    - ``new_hold``: free nodes that penetrate the object, with their hold points in ``hold_at``
      (:func:`~..kernels.contact.find_penetrations`);
    - ``slide`` and ``friction``: a stuck node whose tangential reaction exceeds μ·R_n slides, against a friction of
      μ·R_n along that reaction; a sliding node keeps sliding while it has moved from its anchor against its
      friction, which becomes μ·R_n against that motion, and otherwise is ``stuck_again`` on the surface where it
      is.
      Only within the budget (``within_budget``);
    - ``changed``: rods with any of these, or, while ``settle_friction``, whose friction moved by more than
      :data:`FRICTION_TOLERANCE` (:attr:`~..scene.objects.ContactSettings.friction_passes`).

    ``found`` (R,) int is scratch.
    """
    # the bundles' members taken out once, for the branches below
    adhesive, new_hold, changed = changes.adhesive, changes.new_hold, changes.changed
    slide, new_friction, stuck_again, hold_at = changes.slide, changes.friction, changes.stuck_again, changes.hold_at
    held, sliding, old_friction = holds.held, holds.sliding, holds.friction
    let_go_if_pulling = changes.let_go_if_pulling
    starts, ends, radii = view.starts, view.ends, view.radii
    n_rods, n_nodes, dim = positions.shape
    stride = residual.shape[1] // n_nodes
    force_tolerance = solver.force_tolerance
    new_hold[:, :] = False
    stuck_again[:, :] = False
    find_penetrations(positions, old_positions, view, held, solver.first_free_node, solver.penetration_tolerance,
                      new_hold, hold_at, found)
    nearest = local_array(3)[:dim]
    normal = local_array(3)[:dim]
    reaction = local_array(3)[:dim]
    slip = local_array(3)[:dim]
    for r in range(n_rods):
        changed[r] = found[r] > 0
        mu = friction[r]
        for i in range(n_nodes):
            adhesive[r, i] = False
            slide[r, i] = False
            if not held[r, i]:
                continue
            if not outward_normal(positions[r, i], starts[r], ends[r], nearest, normal):
                # Held on the segment itself, a section shrunk to a point: it cannot hold a node, so it lets go.
                adhesive[r, i] = True
                changed[r] = True
                continue
            normal_reaction = 0.0
            for d in range(dim):
                reaction[d] = residual[r, stride * i + d]
                normal_reaction += reaction[d] * normal[d]
            if normal_reaction < -force_tolerance:
                if within_budget and not sliding[r, i] and not let_go_if_pulling[r, i] and mu != np.inf:
                    # Every step starts with its holds stuck, and stopping a node that slid along the surface can
                    # pull it in: let go, it would be caught again at its entry point and let go, until the budget
                    # is spent and the step halved (ever more often as Δt falls). Only the normal reaction of a
                    # hold free along the surface says whether contact pulls, so such a node slides first (without
                    # friction: μ·R_n is zero while R_n pulls). A node caught in this step is let go at once: a
                    # fast impact's entry points are no sliding contact.
                    slide[r, i] = True
                    let_go_if_pulling[r, i] = True  # once: stuck again, it would slide again, and so on
                    changed[r] = True
                    for d in range(dim):
                        new_friction[r, i, d] = 0.0
                    continue
                adhesive[r, i] = True
                changed[r] = True
                continue
            if not within_budget or mu == np.inf:
                slide[r, i] = sliding[r, i]
                for d in range(dim):
                    new_friction[r, i, d] = old_friction[r, i, d]
                continue
            limit = mu * max(normal_reaction, 0.0)
            if not sliding[r, i]:  # stuck: within the cone, or slides along its tangential reaction
                tangential = 0.0
                for d in range(dim):
                    tangential += (reaction[d] - normal_reaction * normal[d]) ** 2
                tangential = math.sqrt(tangential)
                if tangential > limit + force_tolerance:
                    slide[r, i] = True
                    changed[r] = True
                    for d in range(dim):
                        new_friction[r, i, d] = limit * (reaction[d] - normal_reaction * normal[d]) / tangential
                continue
            along = 0.0  # sliding: how far it has slid from where it stuck, along the surface
            for d in range(dim):
                slip[d] = positions[r, i, d] - anchors[r, i, d]
                along += slip[d] * normal[d]
            size = 0.0
            against = 0.0
            for d in range(dim):
                slip[d] -= along * normal[d]
                size += slip[d] ** 2
                against += slip[d] * old_friction[r, i, d]
            size = math.sqrt(size)
            if against > 0.0:  # its friction no longer opposes its motion: it has stopped and turned back
                stuck_again[r, i] = True
                changed[r] = True
                # On the surface where it is: a sliding node moved along the tangent plane of its solve, off a
                # curved surface by slip²/2r (µm at 10 ms), and a stuck hold must not keep it inside.
                radius = radii[r, i]
                for d in range(dim):
                    hold_at[r, i, d] = nearest[d] + radius * normal[d]
                continue
            slide[r, i] = True
            old_size = 0.0
            for d in range(dim):
                old_size += old_friction[r, i, d] ** 2
            old_size = math.sqrt(old_size)
            moved = 0.0
            for d in range(dim):  # against the motion; a node that did not move keeps its friction's direction
                if size > 0.0:
                    new_friction[r, i, d] = -limit * slip[d] / size
                elif old_size > 0.0:
                    new_friction[r, i, d] = limit * old_friction[r, i, d] / old_size
                else:
                    new_friction[r, i, d] = 0.0
                moved += (new_friction[r, i, d] - old_friction[r, i, d]) ** 2
            if settle_friction and math.sqrt(moved) > FRICTION_TOLERANCE * limit + force_tolerance:
                changed[r] = True


@kernel
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


@kernel
def update_holds(within_budget, holds, changes, again, n_fingers, whole_gripper):
    """The holds of the next solve, in place (:class:`ContactChanges`): new penetrations held (stuck), within the
    budget adhesive holds released, and every hold stuck or sliding as the test found, with its friction. Only for
    the rods solved again, ``again`` (R,) bool, and with ``whole_gripper`` (a free body, solved with all its
    gripper's rods) every rod of a gripper one of whose rods is: a rod that is not solved again keeps the holds its
    solution was found with, so that the reactions it reports (its friction among them) are those of its own
    solution, whatever the other grippers of its batch do."""
    held, sliding, adhesive, new_hold = holds.held, holds.sliding, changes.adhesive, changes.new_hold
    let_go_if_pulling = changes.let_go_if_pulling
    for r in range(held.shape[0]):
        updated = again[r]
        if whole_gripper:
            first = r - r % n_fingers
            for other in range(first, first + n_fingers):
                updated = updated or again[other]
        if not updated:
            continue
        for i in range(held.shape[1]):
            held[r, i] = (held[r, i] and not (within_budget and adhesive[r, i])) or new_hold[r, i]
            let_go_if_pulling[r, i] = let_go_if_pulling[r, i] or new_hold[r, i]
            sliding[r, i] = held[r, i] and not new_hold[r, i] and changes.slide[r, i]
            for d in range(holds.friction.shape[2]):
                holds.friction[r, i, d] = changes.friction[r, i, d] if sliding[r, i] else 0.0


@kernel(python=True)
def contact_masks(clamp_free, held, sliding, dim, free, measured):
    """The DOFs Newton solves for, ``free`` (R, n), and those its test measures as they are, ``measured`` (R, n),
    from the clamp's ``clamp_free`` (R, n) and the contacts (R, N): a stuck node's position DOFs are fixed (it moves
    with its object); a sliding node's are solved in its surface's frame, the normal fixed and the tangents free,
    and measured there (:func:`~.newton.newton`)."""
    stride = free.shape[1] // held.shape[1]
    for r in range(held.shape[0]):
        for j in range(free.shape[1]):
            free[r, j] = clamp_free[r, j]
            measured[r, j] = clamp_free[r, j]
        for i in range(held.shape[1]):
            if held[r, i]:
                for d in range(dim):
                    free[r, stride * i + d] = sliding[r, i] and d > 0
                    measured[r, stride * i + d] = False


__all__ = ["ContactGeometry", "ContactChanges", "CorrectorWork", "FRICTION_TOLERANCE", "corrector_work",
           "solve_with_contact", "correct_contacts", "contact_changes", "corrector_continues",
           "update_holds", "contact_masks"]
