"""Many backward-Euler steps with contact in one compiled call: the hot path of a control interval.

A control interval of the task is several physics steps with one natural-curvature rate per finger. Stepping them
one call at a time from Python cost more than the physics itself (building the step's records, the holds, the
water, the reports). :func:`take_steps` runs the same steps as the simulator's one-step path, in the same order
and with the same arithmetic: the predictor, the corrector around Newton's method
(:func:`~.corrector.solve_with_contact`), the end of the step, the 3-D frames carried along, the contact
reactions. Per gripper it sums what a control interval reads (Newton iterations, the impulses of the contact
reactions) and ramps κ̄ at its rate (:func:`commit_step`).

A step that a gripper does not settle (Newton failed or the corrector spent its budget) is taken again as two half
steps, each of which may be halved again, as the simulator's adaptive path does, with the water at each half step's
time (:func:`~..kernels.current.current_velocity`). A batch of one gripper (a GPU thread's, or one environment's)
does it right there. A larger batch leaves the gripper ``pending`` while the others take the step, and returns; the
simulator then gives each pending gripper that step as a batch of one of its own (views of its rows, the same
compiled function), which takes it in halves, and calls :func:`take_steps` again for the batch from the next step.
So a gripper's trajectory does not depend on what else shares its batch, and matches the adaptive path of
``Simulator.step`` to the bit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..kernels.assembly import FINGERS_FIELD
from ..kernels.compiled import kernel
from ..kernels.contact import contact_reactions
from ..kernels.current import current_velocity
from ..kernels.forces import project_water
from ..kernels.rod_3d import rod3d_update_frames
from ..kernels.typed_none import none_or
from ..scene.scene import STEP_HALVINGS_LIMIT
from .corrector import CorrectorWork, correct_contacts, corrector_work
from .newton import finish, predict


class WorkingState(NamedTuple):
    """The batch's state as a run of steps updates it in place, per rod R = B·F (the simulator's
    :class:`~.records.RodState` flattened). Fields a scene does not have are empty arrays."""

    q: np.ndarray
    """Coordinates [m, rad], (R, N, S)."""
    velocity: np.ndarray
    """[m/s, rad/s], (R, N, S)."""
    acceleration: np.ndarray
    """The last step's mean acceleration [m/s², rad/s²], (R, N, S) (zero before the first: the predictor alone)."""
    held: np.ndarray
    """Nodes held on the object, (R, N) bool."""
    hold_offset: np.ndarray
    """A free body's held nodes' offsets in its frame [m], (R, N, 3); (0, 0, 3) for a fixed object."""
    tangent: np.ndarray
    """3-D edge tangents, (R, N − 1, 3); (0, 0, 3) in the planar model."""
    director: np.ndarray
    """3-D first directors, (R, N − 1, 3); (0, 0, 3) in the planar model."""
    reference_twist: np.ndarray
    """3-D reference twist [rad], (R, N); (0, 0) in the planar model."""
    body_position: np.ndarray
    """A free body's centre [m], (B, 3); (0, 3) for a fixed object."""
    body_velocity: np.ndarray
    """[m/s], (B, 3)."""
    body_orientation: np.ndarray
    """Body to world, (B, 3, 3)."""
    body_angular_velocity: np.ndarray
    """[rad/s], (B, 3)."""


N_ROD_STATE_FIELDS = WorkingState._fields.index("body_position")
""":class:`WorkingState`'s first fields, which have a row per rod (R = B·F); the others have one per gripper (B)."""


class Interval(NamedTuple):
    """What a run of steps ramps and sums per gripper, in place."""

    natural_curvature: np.ndarray
    """κ̄ of every rod (dimensionless), (R,): held through a step, then ramped by its rate."""
    curvature_rate: np.ndarray
    """dκ̄/dt of every rod [1/s], (R,)."""
    curvature_low: float
    """The least κ̄ the ramp reaches (dimensionless)."""
    curvature_high: float
    """The largest."""
    running: np.ndarray
    """Grippers still stepping, (B,) bool: a gripper whose step fails stops (its state stays that of its last good
    step) and is marked ``failed``."""
    failed: np.ndarray
    """Grippers whose step failed in this run, (B,) bool."""
    clock: np.ndarray
    """Each gripper's own clock [s], (B,): advanced by Δt for every step it takes."""
    newton_iterations: np.ndarray
    """Newton iterations of the slowest finger, summed over the steps taken, (B,) int."""
    normal_impulse: np.ndarray
    """Σ max(R_n, 0)·Δt of every node over the steps taken [N·s], (R, N)."""
    impulse: np.ndarray
    """Σ R·Δt of every node, world frame [N·s], (R, N, 3)."""
    pending: np.ndarray
    """Running grippers of a batch of more than one that did not settle the step where :func:`take_steps` returned,
    (B,) bool: each takes that step in halves as a batch of one."""
    halve: bool
    """Whether a step that a gripper does not settle is halved (``NewtonSettings.max_step_halvings`` > 0); if not,
    it is taken as it is when Newton converged (the corrector's budget spent) and fails otherwise. A half step at
    the deepest level allowed is taken in the same way."""


class StepWork(NamedTuple):
    """The scratch of :func:`step_batch` for a batch of R rods of N nodes (n DOFs each, D position coordinates) in B
    grippers: made once per call of :func:`take_steps` on the CPU (:func:`step_work`), the thread's own arrays for
    its gripper on the GPU (:mod:`.gpu`). Nothing in it carries from one step to the next."""

    q_pred: np.ndarray
    """The predictor [m, rad], (R, N, S)."""
    new: WorkingState
    """The step's end, before it is committed."""
    saved: WorkingState
    """A batch of one's state at the start of a step it halves, kept should a half step fail."""
    level_start: np.ndarray
    """The start [s] of the (half) step being taken at each level of halving, (STEP_HALVINGS_LIMIT + 1,)."""
    gripper_water: np.ndarray
    """The current at each gripper at the step's start [m/s], (B, 3)."""
    water: np.ndarray
    """The current as each rod sees it [m/s], (R, D)."""
    water_acceleration: np.ndarray
    """The current's mean acceleration over the step at each gripper [m/s²], (B, 3)."""
    near: np.ndarray
    """The fingers near each other (:attr:`~..kernels.assembly.StepInputs.near`), (R, N, F) int; empty without
    finger contact."""
    sliding: np.ndarray
    """(R, N) bool."""
    friction: np.ndarray
    """[N], (R, N, D)."""
    measured: np.ndarray
    """(R, n) bool."""
    hold_at: np.ndarray
    """[m], (R, N, D)."""
    converged: np.ndarray
    """(R,) bool."""
    changed: np.ndarray
    """(R,) bool."""
    iterations: np.ndarray
    """(R,) int."""
    corrector: np.ndarray
    """(R,) int."""
    ratio: np.ndarray
    """(R,)."""
    residual: np.ndarray
    """[N, N·m], (R, n)."""
    reaction: np.ndarray
    """The object's force on every node [N], (R, N, 3)."""
    normal_reaction: np.ndarray
    """[N], (R, N)."""
    ok: np.ndarray
    """(B,) bool."""
    most: np.ndarray
    """(B,) int."""
    every: np.ndarray
    """0 … B − 1, (B,) int."""
    corrector_work: CorrectorWork


@kernel(runtime=True)  # it allocates
def step_work(state, n_fingers, dim, finger_contact, free_body):
    """:class:`StepWork` for the batch of ``state`` (:class:`WorkingState`) with ``n_fingers`` rods per gripper and
    ``dim`` position coordinates, with or without ``finger_contact``, against a ``free_body`` or a fixed object."""
    n_rods, n_nodes, stride = state.q.shape
    n_grippers = n_rods // n_fingers
    return StepWork(np.empty_like(state.q), _like(state), _like(state), np.empty(STEP_HALVINGS_LIMIT + 1),
                    np.empty((n_grippers, 3)), np.empty((n_rods, dim)), np.empty((n_grippers, 3)),
                    np.empty((n_rods, n_nodes, n_fingers) if finger_contact else (0, 0, 0), dtype=np.int64),
                    np.empty((n_rods, n_nodes), dtype=np.bool_), np.empty((n_rods, n_nodes, dim)),
                    np.empty((n_rods, n_nodes * stride), dtype=np.bool_), np.empty((n_rods, n_nodes, dim)),
                    np.empty(n_rods, dtype=np.bool_), np.empty(n_rods, dtype=np.bool_),
                    np.empty(n_rods, dtype=np.int64), np.empty(n_rods, dtype=np.int64), np.empty(n_rods),
                    np.empty((n_rods, n_nodes * stride)), np.empty((n_rods, n_nodes, 3)), np.empty((n_rods, n_nodes)),
                    np.empty(n_grippers, dtype=np.bool_), np.zeros(n_grippers, dtype=np.int64),
                    np.arange(n_grippers), corrector_work(state.q, dim, n_fingers, free_body, finger_contact))


@kernel(runtime=True)  # it allocates
def _like(state):
    """A :class:`WorkingState` of new arrays shaped as ``state``'s."""
    return WorkingState(np.empty_like(state.q), np.empty_like(state.q), np.empty_like(state.q),
                        np.empty_like(state.held), np.empty_like(state.hold_offset), np.empty_like(state.tangent),
                        np.empty_like(state.director), np.empty_like(state.reference_twist),
                        np.empty_like(state.body_position), np.empty_like(state.body_velocity),
                        np.empty_like(state.body_orientation), np.empty_like(state.body_angular_velocity))


@kernel
def copy_gripper(source, j, target, b, n_fingers):
    """Copies gripper ``j``'s state in ``source`` into gripper ``b``'s in ``target`` (both :class:`WorkingState`),
    element by element: the GPU build copies no array into another by slice."""
    n_nodes, stride = target.q.shape[1], target.q.shape[2]
    for f in range(n_fingers):
        r, s = b * n_fingers + f, j * n_fingers + f
        for i in range(n_nodes):
            for k in range(stride):
                target.q[r, i, k] = source.q[s, i, k]
                target.velocity[r, i, k] = source.velocity[s, i, k]
                target.acceleration[r, i, k] = source.acceleration[s, i, k]
            target.held[r, i] = source.held[s, i]
            if target.hold_offset.shape[0] > 0:
                for k in range(3):
                    target.hold_offset[r, i, k] = source.hold_offset[s, i, k]
            if target.tangent.shape[0] > 0:
                target.reference_twist[r, i] = source.reference_twist[s, i]
                if i < n_nodes - 1:
                    for k in range(3):
                        target.tangent[r, i, k] = source.tangent[s, i, k]
                        target.director[r, i, k] = source.director[s, i, k]
    if target.body_position.shape[0] > 0:
        for k in range(3):
            target.body_position[b, k] = source.body_position[j, k]
            target.body_velocity[b, k] = source.body_velocity[j, k]
            target.body_angular_velocity[b, k] = source.body_angular_velocity[j, k]
            for m in range(3):
                target.body_orientation[b, k, m] = source.body_orientation[j, k, m]


@kernel(python=True)
def commit_step(dt, grippers, ok, new, iterations, normal_reaction, reaction, state, interval):
    """Takes a step of length ``dt`` [s] into the running grippers ``grippers`` (m,) of ``state``
    (:class:`WorkingState`) from the m grippers of ``new``, those the step left ``ok`` (m,) bool: copies their state,
    adds their Newton ``iterations`` (m,) and the impulses of their ``normal_reaction`` (m·F, N) and ``reaction``
    (m·F, N, 3) [N] into ``interval`` (:class:`Interval`), ramps their κ̄ and advances their clocks. A running gripper
    that the step did not leave ok stops and fails; a ``pending`` one is left as it is."""
    n_fingers = state.q.shape[0] // interval.running.shape[0]
    for j in range(grippers.shape[0]):
        b = grippers[j]
        if not interval.running[b] or interval.pending[b]:  # stopped, or left for the adaptive path
            continue
        if not ok[j]:
            interval.running[b] = False
            interval.failed[b] = True
            continue
        copy_gripper(new, j, state, b, n_fingers)
        for f in range(n_fingers):
            r, s = b * n_fingers + f, j * n_fingers + f  # the rod in state and in new
            for i in range(normal_reaction.shape[1]):
                interval.normal_impulse[r, i] += max(normal_reaction[s, i], 0.0) * dt
                for d in range(3):
                    interval.impulse[r, i, d] += reaction[s, i, d] * dt
            ramped = interval.natural_curvature[r] + interval.curvature_rate[r] * dt
            interval.natural_curvature[r] = min(max(ramped, interval.curvature_low), interval.curvature_high)
        interval.newton_iterations[b] += iterations[j]
        interval.clock[b] += dt


@kernel(python=True, runtime=True)  # its scratch is allocated here
def take_steps(first, n_steps, dt, times, currents, state, rods, terms, solvers, geometry, projection, body,
               interval):
    """:func:`step_batch` with its scratch made here: the CPU's entry point."""
    work = step_work(state, solvers[0][5], geometry[0].shape[1], rods[FINGERS_FIELD][0] > 0.0, body is not None)
    return step_batch(first, n_steps, dt, times, currents, state, rods, terms, solvers, geometry, projection, body,
                      interval, work)


@kernel(python=True, inline=True, runtime=True)  # inlined into take_steps; the CUDA simulator's threads call it
def step_batch(first, n_steps, dt, times, currents, state, rods, terms, solvers, geometry, projection, body,
               interval, work):
    """Steps ``first`` … ``n_steps`` − 1 of length ``dt`` [s] of every running gripper, from and into ``state``
    (:class:`WorkingState`), starting at the batch times ``times`` (n_steps + 1,) [s], with the current at every
    gripper from ``currents`` (:class:`~..kernels.current.CurrentArrays`); ramps and sums into ``interval``
    (:class:`Interval`). ``rods`` (with ``state``'s frames in 3-D), ``terms`` and ``geometry`` are the plain fields
    that :func:`~.corrector.solve_with_contact` takes, ``solvers`` its solver fields for steps of ``dt``, ``dt``/2, …
    (one per level of halving the scene allows, and one more), ``projection`` (R, D, 3) rod coordinates from world
    vectors; ``body`` the free bodies' arrays, or None for a fixed object; ``work`` the scratch (:class:`StepWork`).

    A step that a gripper does not settle is halved: in place in a batch of one, else left ``pending`` (module
    docstring); a batch of one whose gripper is ``pending`` on entry takes step ``first`` in halves. Returns the
    index of the step where it stopped: ``n_steps`` when it took them all; a step that some running grippers of a
    larger batch did not settle, which the others took and the ``pending`` ones (``interval.pending``) have still to
    take; or a step that no gripper runs to take. The GPU runs this for one gripper per thread."""
    n_rods, n_nodes, stride = state.q.shape
    n_fingers = solvers[0][5]
    n_grippers = n_rods // n_fingers
    dim = geometry[0].shape[1]
    planar = state.tangent.shape[0] == 0
    q_pred, new, water, water_acceleration, near = work.q_pred, work.new, work.water, work.water_acceleration, \
        work.near
    sliding, friction, measured, hold_at = work.sliding, work.friction, work.measured, work.hold_at
    converged, changed, iterations, corrector = work.converged, work.changed, work.iterations, work.corrector
    ratio, residual, reaction, normal_reaction = work.ratio, work.residual, work.reaction, work.normal_reaction
    ok, most, every, start = work.ok, work.most, work.every, work.level_start
    gripper_water, water_end = work.gripper_water, work.water_acceleration  # the end's water, then its change
    deepest = len(solvers) - 1
    halve_here = n_grippers == 1 and interval.halve
    resume = halve_here and interval.pending[0]  # a larger batch left this gripper's first step to be halved
    interval.pending[:] = False
    for k in range(first, n_steps):
        if not interval.running.any():
            return k
        level = 0  # how many times the step being taken was halved
        start[0] = times[k]
        if resume and k == first:
            copy_gripper(state, 0, work.saved, 0, n_fingers)
            start[1] = start[0]
            level = 1
        done = 0  # of the step, in steps of dt / 2**deepest
        taken_iterations = 0
        while True:
            h = dt
            for _ in range(level):
                h *= 0.5
            solver = solvers[level]
            for b in range(n_grippers):
                current_velocity(currents, b, start[level], gripper_water[b])
            project_water(geometry[5], gripper_water, water)
            predict(state.q, state.velocity, state.acceleration, h, q_pred, new.q)
            for r in range(n_rods):  # element by element: the GPU build copies no array into another by slice
                for i in range(n_nodes):
                    new.held[r, i] = state.held[r, i]
                    sliding[r, i] = False
                    for d in range(dim):
                        friction[r, i, d] = 0.0
                        hold_at[r, i, d] = state.q[r, i, d]
                    if body is not None:
                        for d in range(3):
                            new.hold_offset[r, i, d] = state.hold_offset[r, i, d]
            changed[:] = False
            corrector[:] = 0
            step = (state.q, q_pred, interval.natural_curvature, water, h, near)
            result = (converged, iterations, ratio, residual, corrector, changed)
            holds = (new.held, new.hold_offset, projection, sliding, friction, measured, geometry[0], geometry[1],
                     geometry[2], geometry[3])
            if body is not None:
                for b in range(n_grippers):
                    current_velocity(currents, b, start[level] + h, water_end[b])
                    for d in range(3):
                        new.body_position[b, d] = state.body_position[b, d] + h * state.body_velocity[b, d]
                        new.body_angular_velocity[b, d] = h * state.body_angular_velocity[b, d]  # θ, the rotation
                        water_acceleration[b, d] = (water_end[b, d] - gripper_water[b, d]) / h
            old = (state.body_position, state.body_velocity, state.body_orientation, state.body_angular_velocity)
            motion = (new.body_position, new.body_angular_velocity, new.body_orientation, old, gripper_water,
                      water_acceleration)  # (empty arrays for a fixed object, and not used)
            correct_contacts(new.q, step, rods, terms, solver, holds, hold_at, geometry, with_motion(body, motion),
                             result, work.corrector_work)
            finish(new.q, state.q, state.velocity, h, new.velocity, new.acceleration)
            if body is not None:
                for b in range(n_grippers):
                    for d in range(3):
                        new.body_velocity[b, d] = (new.body_position[b, d] - state.body_position[b, d]) / h
                        new.body_angular_velocity[b, d] = new.body_angular_velocity[b, d] / h
            if not planar:
                rod3d_update_frames(new.q, state.tangent, state.director, state.reference_twist, new.tangent,
                                    new.director, new.reference_twist, work.corrector_work.newton.elastic)
            any_pending, again = False, False
            for b in range(n_grippers):
                all_converged, resolved, finite = True, True, True
                most[b] = 0
                for r in range(b * n_fingers, (b + 1) * n_fingers):
                    all_converged = all_converged and converged[r]
                    resolved = resolved and not changed[r]
                    most[b] = max(most[b], iterations[r])
                    for i in range(n_nodes):
                        for s in range(stride):
                            finite = finite and math.isfinite(new.q[r, i, s]) \
                                and math.isfinite(new.velocity[r, i, s])
                if body is not None:
                    for d in range(3):
                        finite = finite and math.isfinite(new.body_position[b, d]) \
                            and math.isfinite(new.body_velocity[b, d])
                # as the adaptive path: a step not settled is halved, or at the deepest level (and without
                # halvings) kept if Newton converged
                settled = all_converged and resolved
                again = halve_here and not settled and level < deepest
                interval.pending[b] = interval.running[b] and interval.halve and not settled and not halve_here
                any_pending = any_pending or interval.pending[b]
                ok[b] = all_converged and not interval.pending[b] and not again and finite
            if again:  # a batch of one takes the step again as two halves, from the state it started from
                if level == 0:
                    copy_gripper(state, 0, work.saved, 0, n_fingers)
                start[level + 1] = start[level]
                level += 1
                continue
            if halve_here and level > 0:
                if not ok[0]:  # a half step failed: the gripper stops at the state before the whole step
                    copy_gripper(work.saved, 0, state, 0, n_fingers)
                    commit_step(dt, every, ok, new, most, normal_reaction, reaction, state, interval)
                    break
                taken_iterations += most[0]
                done += 1 << (deepest - level)
                if done < 1 << deepest:  # on to the next half step, at the level of the last one it completes
                    copy_gripper(new, 0, state, 0, n_fingers)
                    remaining = done
                    level = deepest
                    while remaining % 2 == 0:
                        remaining //= 2
                        level -= 1
                    h = dt
                    for _ in range(level):
                        h *= 0.5
                    start[level] += h
                    continue
                most[0] = taken_iterations
            contact_reactions(new.q, residual, new.held, friction, geometry[0], geometry[1], geometry[5], reaction,
                              normal_reaction)
            commit_step(dt, every, ok, new, most, normal_reaction, reaction, state, interval)
            if any_pending:  # the others took the step; the pending ones keep their state for the adaptive path
                return k
            break
    return n_steps


@kernel(python=True, runtime=True)  # the host's halving and the CUDA simulator's threads take its views in Python
def gripper_views(b, n_fingers, held_by_body, framed, bodies, moving, state, geometry, interval, currents):
    """Gripper ``b``'s rows of a batch, as a batch of one (views): its :class:`WorkingState`, contact geometry,
    :class:`Interval` and currents, from the batch's (those bundles, or their fields as plain tuples).
    ``held_by_body``, ``framed``, ``bodies`` and ``moving`` are how many rows of hold offsets, 3-D frames, bodies and
    admissible motions a gripper has (``n_fingers`` or 0; 1 or 0), given rather than read from the arrays, since on
    the GPU an array a scene lacks is one placeholder row."""
    first, last = b * n_fingers, (b + 1) * n_fingers
    q, velocity, acceleration, held, hold_offset, tangent, director, twist, position, body_velocity, orientation, \
        angular_velocity = state
    own = WorkingState(q[first:last], velocity[first:last], acceleration[first:last], held[first:last],
                       hold_offset[first:first + held_by_body], tangent[first:first + framed],
                       director[first:first + framed], twist[first:first + framed], position[b:b + bodies],
                       body_velocity[b:b + bodies], orientation[b:b + bodies], angular_velocity[b:b + bodies])
    starts, ends, radii, finger_radius, friction, directions, plane_normals, any_motion = geometry
    own_geometry = (starts[first:last], ends[first:last], radii[first:last], finger_radius, friction[first:last],
                    directions, plane_normals, any_motion[b:b + moving])
    natural_curvature, rate, low, high, running, failed, clock, iterations, normal_impulse, impulse, pending, \
        halve = interval
    own_interval = Interval(natural_curvature[first:last], rate[first:last], low, high, running[b:b + 1],
                            failed[b:b + 1], clock[b:b + 1], iterations[b:b + 1], normal_impulse[first:last],
                            impulse[first:last], pending[b:b + 1], halve)
    own_currents = (currents[0][b:b + 1], currents[1][b:b + 1], currents[2][b:b + 1], currents[3][b:b + 1],
                    currents[4][b:b + 1], currents[5][b:b + 1], currents[6][b:b + 1], currents[7][b:b + 1])
    return own, own_geometry, own_interval, own_currents


@kernel(python=True, runtime=True)  # the host's halving and the CUDA simulator's threads take its views in Python
def gripper_body(body, b):
    """Gripper ``b``'s row of the free bodies' arrays (:class:`~..kernels.body.BodyArrays`' fields)."""
    return (body[0][b:b + 1], body[1][b:b + 1], body[2][b:b + 1], body[3][b:b + 1], body[4][b:b + 1],
            body[5][b:b + 1], body[6][b:b + 1], body[7][b:b + 1], body[8][b:b + 1], body[9][b:b + 1],
            body[10][b:b + 1], body[11][b:b + 1], body[12][b:b + 1], body[13][b:b + 1], body[14], body[15],
            body[16], body[17])


@kernel(runtime=True)  # its bundle goes to the step's entry point, which has the runtime
def _with_motion(body, motion):
    return body, motion


with_motion = none_or(_with_motion)
"""The corrector's ``free_body``: the bodies' arrays and their motion, or None for a fixed object (chosen as the kernel
compiles: :mod:`~..kernels.typed_none`)."""


__all__ = ["WorkingState", "N_ROD_STATE_FIELDS", "Interval", "StepWork", "step_work", "copy_gripper", "commit_step",
           "take_steps", "step_batch", "gripper_views", "gripper_body"]
