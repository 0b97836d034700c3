"""Newton's method for every rod of a batch, and for rods and a free body together: one compiled loop.

Backward Euler on the free DOFs q of a rod (the integrators build every other scheme from it,
:mod:`.integrators`):

    M·(q − q_old − Δt·v_old)/Δt² − f(q, (q − q_old)/Δt) = 0,

solved from the predictor q_old + Δt·v_old plus the last step's motion, Δt²·a_old. :func:`newton` runs the loop for
every gripper of a batch in one call:

- **Rods on their own, or held on an object that does not move** (no object, or a fixed one): each rod is its own
  system and stops iterating as soon as its own residual meets the tolerance, so its result does not depend on what
  else shares its batch. Nodes held by contact are fixed DOFs that the corrector has put on the object's surface.
- **Rods and a free body**: held nodes move with the body, x_h = c + R·r_h, so a gripper's rods and its body form
  one system. Each rod's free DOFs are eliminated with its own banded factorisation (:func:`eliminate_rods`), which
  leaves a 6×6 system for the body per gripper (a Schur complement); the gripper iterates until all of it
  converges, with a backtracking line search on the body's step (a new hold far from the body can throw Newton off;
  the body is the only coupling, so rods on their own need none). A staggered scheme, which would move the body
  with last iteration's reactions, is unstable for a body as light as the water it displaces; this one is not.

One iteration is the same named steps in both cases (:func:`_rod_residual`, :func:`eliminate_rods`,
:func:`_body_step`, :func:`_apply_step`); the body's own equations are :mod:`..kernels.body`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..kernels.assembly import StepInputs, assemble_rod, named_rods
from ..kernels.body import BodyArrays, BodyMotion, admissible_rotation, body_residual, turned
from ..kernels.compiled import kernel
from ..kernels.contact import along_surface, onto_surface, rotate_node, tangent_basis
from ..kernels.finger_contact import any_near, finger_scratch, near_fingers_of_gripper
from ..kernels.linalg import (
    factor_banded_symmetric,
    solve_dense,
    solve_factored,
    solve_factored_six_columns,
    symmetric_band_entry,
)
from ..kernels.local import local_array
from ..kernels.rod_3d import elastic_scratch
from ..scene.forces import ForceTerms


class SolverArrays(NamedTuple):
    """Newton's and the corrector's settings for steps of one length, as the kernels take them."""

    mass_term: np.ndarray
    """M/Δt² of every DOF of one rod [kg/s² or kg·m²/s²], (n,)."""
    tolerance_inverse: np.ndarray
    """1/tolerance of every DOF of every rod [1/N or 1/(N·m)], (R, n); 0 on clamped DOFs."""
    clamp_free: np.ndarray
    """The DOFs the clamp leaves free, (R, n) bool."""
    body_tolerance: np.ndarray
    """The body's force and moment tolerances [N, N·m], (6,)."""
    max_iterations: int
    """Newton iterations (linear solves) allowed per solve."""
    n_fingers: int
    """Rods per gripper F."""
    max_corrector_iterations: int
    """Re-solves of one step allowed for new contacts and releases."""
    friction_passes: int
    """Re-solves in which a moved friction alone solves again (at most ``max_corrector_iterations``)."""
    first_free_node: int
    """The first node contact is searched for (the clamped nodes belong to the palm)."""
    force_tolerance: float
    """Newton's tolerance on a force DOF [N]: a reaction pulling by less is zero to that tolerance."""
    finger_length: float
    """L [m], for the reach test of the contact search."""
    penetration_tolerance: float
    """How deep a free node may end a step inside the object [m] (:func:`~..scene.objects.penetration_tolerance`)."""


class SolveResult(NamedTuple):
    """What a solve writes, per rod (R,); with a free body, each rod of a gripper carries the gripper's values."""

    converged: np.ndarray
    """Whether the residual met its tolerance, bool."""
    iterations: np.ndarray
    """Linear solves (Newton iterations), int."""
    ratio: np.ndarray
    """The largest free-DOF residual divided by its tolerance (dimensionless; inf where a factorisation failed)."""
    residual: np.ndarray
    """M·(q − q_pred)/Δt² − f at the solution, (R, n) [N, N·m]: on held DOFs, the contact reaction."""
    corrector: np.ndarray
    """The corrector's re-solves, int."""
    changed: np.ndarray
    """Whether the corrector's last test still changed the rod's contacts, bool."""


class Holds(NamedTuple):
    """The nodes in contact with the object, stuck or sliding, and how each rod sees the world and the object."""

    held: np.ndarray
    """Nodes in contact with the object, (R, N) bool: stuck to a point of it, or sliding on it."""
    offsets: np.ndarray
    """Each stuck node's offset from a free body's centre in the body's frame [m], (R, N, 3)."""
    projection: np.ndarray
    """Rod coordinates from world vectors, (R, D, 3)."""
    sliding: np.ndarray
    """Held nodes that slide, (R, N) bool: they stay on the object's surface and move along it against
    ``friction``."""
    friction: np.ndarray
    """The friction force on each sliding node, in its rod's coordinates [N], (R, N, D), held fixed through a solve
    (the corrector updates it); its part along the surface at the node's current point acts."""
    measured: np.ndarray
    """The DOFs whose residual Newton's test measures as they are, (R, n) bool: the free DOFs of nodes that do not
    slide (a sliding node's are measured in its surface's frame)."""
    starts: np.ndarray
    """The object's segment as each rod sees it, one end [m], (R, D); for a fixed object (a free body's follows the
    body through the solve)."""
    ends: np.ndarray
    """The other end [m], (R, D)."""
    radii: np.ndarray
    """The distance from the segment at which each node touches a fixed object [m], (R, N)."""
    finger_radius: np.ndarray
    """The finger's radius that contact adds to the object's at each node [m], (N,) (a free body's touching
    distances follow it through the solve)."""


def plain(bundle: tuple) -> tuple:
    """A bundle's fields as plain tuples, all the way down, for a call into a compiled entry point, which names them
    again (:func:`advance_rods`, :func:`~.corrector.solve_with_contact`). Numba types a plain tuple at every call
    several times faster than a named one, whose field names it reads each time."""
    return tuple(plain(value) if isinstance(value, tuple) else value for value in bundle)


class BodyCoupling(NamedTuple):
    """What couples a gripper's rods to a free body in Newton's method. Where no body moves (rods on their own, or
    held on a fixed object) the solvers get None instead, and compile the loop without the body's code."""

    body: BodyArrays
    """The bodies (:class:`~..kernels.body.BodyArrays`)."""
    motion: BodyMotion
    basis: np.ndarray
    """The bodies' admissible motions, (B, 6, 6) (zero columns unused)."""


def for_one_gripper(solver: tuple, n_fingers: int) -> tuple:
    """A batch's solver fields (:class:`SolverArrays`, plain) cut to one gripper's ``n_fingers`` rods: a batch of
    one taken out of it (each gripper's rods have the same settings)."""
    fields = SolverArrays(*solver)
    return tuple(fields._replace(tolerance_inverse=fields.tolerance_inverse[:n_fingers],
                                 clamp_free=fields.clamp_free[:n_fingers]))


MAX_STEP_HALVINGS = 6
"""How often the coupled Newton solve may halve a step that made its residual worse (a backtracking line search)."""



@kernel(python=True)
def eliminate_rods(band, coupling, free, coupled, active, x0, x_coupling, body_block, body_rhs, factored, scratch):
    """Eliminates each rod's free DOFs from the coupled Newton system.

    ``band`` (R, n, kd+1): the rod's Newton matrix A (overwritten by its factors); ``x0`` (R, n): −G, the negated
    residual, on entry; ``coupling`` (R, n, 6): S, the motion of each held DOF per unit body motion (zero on other
    DOFs); ``free`` (R, n): the DOFs solved for. Writes x0 = −A_FF⁻¹·G_F, the rod's own Newton step (R, n),
    X = A_FF⁻¹·(A·S)_F (R, n, 6), the rod's part of the body's matrix Sᵀ·A·S − (A·S)_Fᵀ·X into ``body_block``
    (R, 6, 6), and (A·S)_Fᵀ·x0 into ``body_rhs`` (R, 6). ``scratch`` holds work arrays: A·S (n, 6) and a band row
    (kd+1,).
    A rod that holds nothing (``coupled`` False, S = 0) only solves for x0, and leaves the other outputs as given
    (zero); a rod that is not ``active`` is left alone. Writes whether each rod's factorisation succeeded into
    ``factored`` and returns the number that failed.

    S is non-zero only on the held nodes' rows, a few of the rod's, so A·S, Sᵀ·A·S and the products with (A·S)_F
    visit only the rows within a bandwidth of them, and X's forward substitution starts there: the same sums in the
    same order less their zero terms, so the same bits, at about half the cost of a touching rod's elimination.
    """
    n_rods, n, kd1 = band.shape
    kd = kd1 - 1
    product, row = scratch
    failures = 0
    for r in range(n_rods):
        if not active[r]:
            continue
        a, rod_free = band[r], free[r]
        first, last = n, -1  # the rows where A·S may be non-zero: S's (the held DOFs) widened by the band
        if coupled[r]:  # Sᵀ·A·S needs A before it is factored
            s = coupling[r]
            held_first, held_last = _nonzero_rows(s)
            if held_last >= 0:
                first, last = max(0, held_first - kd), min(n - 1, held_last + kd)
            product[:, :] = 0.0
            for i in range(first, last + 1):  # A·S from the symmetric lower band, each sum in ascending column
                for j in range(max(i - kd, held_first), min(i + kd, held_last) + 1):
                    value = symmetric_band_entry(a, i, j)
                    if value == 0.0:
                        continue
                    for k in range(6):
                        product[i, k] += value * s[j, k]
            for k in range(6):
                t0, t1, t2, t3, t4, t5 = _six_sums(s, k, product, held_first, held_last, None)
                body_block[r, k, 0], body_block[r, k, 1], body_block[r, k, 2] = t0, t1, t2
                body_block[r, k, 3], body_block[r, k, 4], body_block[r, k, 5] = t3, t4, t5
        factored[r] = factor_banded_symmetric(a, rod_free, row)
        if not factored[r]:
            failures += 1
            x0[r, :] = np.nan
            continue
        solve_factored(a, x0[r], rod_free, 0)
        if not coupled[r]:
            continue
        columns = x_coupling[r]
        for i in range(n):
            for k in range(6):
                columns[i, k] = product[i, k] if rod_free[i] else 0.0
        solve_factored_six_columns(a, columns, rod_free, first)
        for k in range(6):  # (A·S)_Fᵀ·x0 and (A·S)_Fᵀ·X
            total = 0.0
            for i in range(first, last + 1):
                if rod_free[i]:
                    total += product[i, k] * x0[r, i]
            body_rhs[r, k] = total
            t0, t1, t2, t3, t4, t5 = _six_sums(product, k, columns, first, last, rod_free)
            body_block[r, k, 0] -= t0
            body_block[r, k, 1] -= t1
            body_block[r, k, 2] -= t2
            body_block[r, k, 3] -= t3
            body_block[r, k, 4] -= t4
            body_block[r, k, 5] -= t5
    return failures


@kernel(inline=True)
def _six_sums(a, k, b, first, last, rows):
    """Σ_i a[i, k]·b[i, m] for m = 0 … 5, over the rows first … last (those where ``rows`` is True, or all where it is
    None), each sum in ascending i. The six together, as six chains the CPU overlaps where one sum at a time waited
    on each addition; the same bits as one at a time."""
    t0 = t1 = t2 = t3 = t4 = t5 = 0.0
    for i in range(first, last + 1):
        if rows is None or rows[i]:
            p = a[i, k]
            t0 += p * b[i, 0]
            t1 += p * b[i, 1]
            t2 += p * b[i, 2]
            t3 += p * b[i, 3]
            t4 += p * b[i, 4]
            t5 += p * b[i, 5]
    return t0, t1, t2, t3, t4, t5


@kernel
def _nonzero_rows(s):
    """The first and last rows of ``s`` (n, 6) with a non-zero entry; (n, −1) when there is none."""
    first, last = s.shape[0], -1
    for i in range(s.shape[0]):
        for k in range(6):
            if s[i, k] != 0.0:
                first, last = min(first, i), i
                break
    return first, last


@kernel
def newton(q, step, rods, terms, solver, free, holds, coupling, solve, result, work):
    """Newton's method for the rods where ``solve`` (R,) is True, each gripper at once (see the module notes).

    ``q`` (R, N, S) holds the start and receives the solution; only DOFs where ``free`` (R, n) is True move. With the
    residual r = M·(q − q_pred)/Δt² − f, a rod (or, with a free body, a gripper, whose rods are then all solved) has
    converged when its largest |r|·tolerance_inverse over free DOFs, and the body's residual over its tolerance, is
    ≤ 1. ``step`` is :class:`~..kernels.assembly.StepInputs`, ``rods`` :class:`~..kernels.assembly.RodArrays`,
    ``terms`` the scene's :class:`~..scene.forces.ForceTerms`, ``solver`` :class:`SolverArrays`, ``holds`` the
    contacts (:class:`Holds`; None for rods on their own), ``coupling`` a :class:`BodyCoupling` with free bodies,
    else None. A sliding node's DOFs are solved for in its surface's frame (normal fixed, tangents free; ``free``
    then reads in that frame). Writes every solved rod's ``converged``, ``iterations``, ``ratio`` and ``residual``
    into ``result`` (:class:`SolveResult`). A rod whose factorisation fails stops with ratio inf. ``work`` is one
    gripper's scratch (:class:`NewtonWork`, :func:`new_work`), reused from gripper to gripper and call to call.
    """
    for b in range(q.shape[0] // solver.n_fingers):
        _solve_gripper(b, q, step, rods, terms, solver, free, holds, coupling, solve, result, work)


class NewtonWork(NamedTuple):
    """Scratch of one gripper's solve: allocated once per call of a CPU entry point (:func:`new_work`), the thread's
    own arrays on the GPU (:mod:`.gpu`). Nothing in it carries from one solve to the next."""

    force: np.ndarray
    strained: np.ndarray
    """Where the elastic force is evaluated with material damping (:func:`~..kernels.assembly.assemble_rod`)."""
    velocity: np.ndarray
    acceleration: np.ndarray
    elastic: np.ndarray
    """The 3-D energy's work buffer (:func:`~..kernels.rod_3d.elastic_scratch`; empty in the planar model)."""
    fingers: np.ndarray
    """The finger contact's work buffer (:func:`~..kernels.finger_contact.finger_scratch`; empty without it)."""
    bands: np.ndarray
    coupling: np.ndarray
    x0: np.ndarray
    x_coupling: np.ndarray
    block: np.ndarray
    rhs: np.ndarray
    rod_delta: np.ndarray
    rod_ratio: np.ndarray
    active: np.ndarray
    touching: np.ndarray
    factored: np.ndarray
    body_residual: np.ndarray
    body_matrix: np.ndarray
    body_total: np.ndarray
    body_step: np.ndarray
    rotation: np.ndarray
    product: np.ndarray
    band_row: np.ndarray
    normals: np.ndarray
    basis: np.ndarray
    rubbing: np.ndarray
    last_ratio: np.ndarray


@kernel(runtime=True)  # it allocates
def new_work(q, dim, n_fingers, coupled, contact, fingers):
    """The work arrays; those only a body's solve (``coupled``), a contact's (``contact``) or the line search of
    fingers touching each other (``fingers``) uses are empty, and shared, otherwise: every allocation counts in the
    rods' own step, a few tens of microseconds."""
    n_nodes, stride = q.shape[1], q.shape[2]
    n = n_nodes * stride
    band_width = 3 * stride - 1
    vector = np.empty(0)
    matrix, tensor = vector.reshape((0, 0)), vector.reshape((0, 0, 6))  # views: no allocation of their own
    # per-rod flags and ratios as rows of two arrays: rod_ratio, last_ratio; active, touching, factored, rubbing
    ratios, flags = np.empty((2, n_fingers)), np.zeros((4, n_fingers), dtype=np.bool_)
    motion = np.empty((2, n_nodes, dim))  # velocity and acceleration
    coordinates = np.empty((2, n_nodes, stride))  # force and strained
    rods = (coordinates[0], coordinates[1], motion[0], motion[1], elastic_scratch(n_nodes if stride == 4 else 0),
            finger_scratch(n_fingers if fingers else 0, n_nodes), np.empty((n_fingers, n, band_width + 1)))
    surface = (np.zeros((n_fingers, n_nodes, dim)), np.empty((dim, dim))) if contact else (tensor, matrix)
    surface = surface + (flags[3], ratios[1])
    if coupled:
        return NewtonWork(*rods, np.zeros((n_fingers, n, 6)), np.empty((n_fingers, n)), np.empty((n_fingers, n, 6)),
                          np.empty((n_fingers, 6, 6)), np.empty((n_fingers, 6)), np.zeros((n_fingers, n)),
                          ratios[0], flags[0], flags[1], flags[2], np.empty(6), np.empty((6, 6)), np.empty(6),
                          np.empty(6), np.empty((3, 3)), np.empty((n, 6)), np.empty(band_width + 1),
                          *surface)
    rod_delta = np.zeros((n_fingers, n)) if fingers else matrix
    return NewtonWork(*rods, tensor, np.empty((n_fingers, n)), tensor, tensor, matrix, rod_delta, ratios[0], flags[0],
                      flags[1], flags[2], vector, matrix, vector, vector, matrix, matrix,
                      np.empty(band_width + 1), *surface)


@kernel(inline=True)
def _solve_gripper(b, q, step, rods, terms, solver, free, holds, coupling, solve, result, work):
    """Newton's method for gripper b's rods where ``solve`` is True (all of them, and the body, with a free body)."""
    # arrays taken out of their bundles once, before the loops
    active, touching, rod_ratio, factored = work.active, work.touching, work.rod_ratio, work.factored
    converged, iterations_of, ratio = result.converged, result.iterations, result.ratio
    residual, mass_term, bands, x0 = result.residual, solver.mass_term, work.bands, work.x0
    scratch = (work.force, work.strained, work.velocity, work.acceleration, work.elastic, work.fingers)
    rubbing, last_ratio = work.rubbing, work.last_ratio
    measured = free if holds is None else holds.measured
    n_fingers = solver.n_fingers
    first = b * n_fingers
    coupled = coupling is not None  # every branch on the body tests ``coupling`` itself, so None prunes them
    fingers_touch = step.near.size > 0
    any_rod = False
    for f in range(n_fingers):
        active[f] = coupled or solve[first + f]
        any_rod |= solve[first + f]
    if not any_rod:
        return
    for f in range(n_fingers):
        if active[f]:
            converged[first + f] = False
            iterations_of[first + f] = 0
            ratio[first + f] = np.inf
        touching[f] = False
        if coupling is not None:
            touching[f] = holds.held[first + f].any()
        elif fingers_touch:  # a rod near another finger takes a line search (kernels/finger_contact.py)
            rubbing[f] = any_near(step.near, first + f)
    gripper_ratio = np.inf
    halvings = 0
    iterations = 0
    if coupling is not None:  # Newton's start, as Newton's steps, within the basis
        admissible_rotation(coupling.basis[b], coupling.motion.rotation[b])
    for it in range(solver.max_iterations + 1):
        largest = 0.0
        # in 3-D, after a Newton step the test assembles the forces alone and the matrices of what iterates on
        # come after it (the same forces again: the arithmetic is as before). A step usually meets the tolerance
        # there, and the elastic Hessian costs 1.7 times the forces; the planar one costs a third of them, so a
        # test that fails (while grasping, often) would cost more than the matrices it saves
        matrices = it == 0 or q.shape[2] == 2
        if coupling is not None:
            motion = coupling.motion
            turned(motion.rotation[b], motion.old.orientation[b], work.rotation, motion.orientation[b])
            body_residual(b, coupling.body, motion, motion.orientation[b], step.dt, work.body_residual,
                          work.body_matrix)
        # the rods' equations have one call site, for Numba inlines them whole at each: the first pass assembles
        # the residuals (and the matrices when ``matrices``), and in 3-D, after a test that fails, a second pass
        # the matrices
        after_test = 0  # 0: take a Newton step; 1: go on to the next iteration; 2: stop iterating
        for matrix_pass in range(2):
            for f in range(n_fingers):
                if not active[f]:
                    continue
                if matrix_pass == 0 and holds is not None and coupling is not None and touching[f]:
                    _place_held_nodes(b, first + f, q, holds, coupling, work.coupling[f], work.normals[f],
                                      work.body_residual)
                backing_off = matrix_pass == 0 and coupling is None and rubbing[f] and it > 0  # a rubbing rod
                halving = 0  # backs off a step that made its residual worse, by halves
                while True:
                    rod_ratio_now, largest_now = _rod_system(first + f, q, step, rods, terms, solver, measured,
                                                             holds, matrix_pass == 0 and not coupled,
                                                             residual[first + f], x0[f], largest, bands[f], scratch,
                                                             work.normals[f], work.basis, matrices or matrix_pass == 1)
                    if matrix_pass == 1:
                        break
                    rod_ratio[f], largest = rod_ratio_now, largest_now
                    if not backing_off or rod_ratio[f] < last_ratio[f] or halving >= MAX_STEP_HALVINGS:
                        break
                    halving += 1
                    _back_off_rod(first + f, q, work.rod_delta[f], 0.5**halving)
                if matrix_pass == 1:
                    continue
                if coupling is None and rubbing[f]:
                    last_ratio[f] = rod_ratio[f]
                if coupling is not None:
                    if touching[f]:
                        _load_body(x0[f], work.coupling[f], work.body_residual)
            if matrix_pass == 1:
                break
            if coupling is not None:
                largest = _body_residual_in_basis(coupling.basis[b], solver.body_tolerance, work.body_residual,
                                                  work.body_total, largest)
                if largest <= 1.0:
                    gripper_ratio = largest
                    _finish_gripper(first, n_fingers, True, iterations, gripper_ratio, result)
                    return
                if it > 0 and not largest < gripper_ratio and halvings < MAX_STEP_HALVINGS:
                    # the last step made the residual worse (a new hold far from the body can throw Newton off):
                    # go back and take half of it
                    halvings += 1
                    _back_off(b, first, q, coupling.motion, work, 0.5**halvings)
                    after_test = 1
                    break
                gripper_ratio = largest
                halvings = 0
                if it == solver.max_iterations:
                    after_test = 2
                    break
            elif not _rods_continue(first, it, solver.max_iterations, result, work):
                return
            if matrices:
                break
        if after_test == 1:
            continue
        if after_test == 2:
            break
        for f in range(n_fingers):
            if active[f]:
                band = work.bands[f]
                diagonal = band.shape[1] - 1
                for j in range(band.shape[0]):
                    band[j, diagonal] += mass_term[j]
        if coupling is not None:
            work.block[:, :, :] = 0.0
            work.rhs[:, :] = 0.0
        rods_in = slice(first, first + n_fingers)
        failures = eliminate_rods(work.bands, work.coupling, free[rods_in], touching, active, work.x0,
                                  work.x_coupling, work.block, work.rhs, factored,
                                  (work.product, work.band_row))
        if holds is not None:
            _unrotate_steps(first, holds, work)
        if coupling is not None:
            if failures or not _body_step(b, coupling.basis[b], work):
                gripper_ratio = np.inf
                break
        else:
            for f in range(n_fingers):
                if active[f] and not factored[f]:
                    ratio[first + f] = np.inf
                    active[f] = False
        _apply_step(b, first, q, coupling, work)
        iterations += 1
        if not coupled:
            for f in range(n_fingers):
                if active[f]:
                    iterations_of[first + f] += 1
    if coupled:
        _finish_gripper(first, n_fingers, False, iterations, gripper_ratio, result)


@kernel(inline=True)
def _rod_system(r, q, step, rods, terms, solver, measured, holds, fixed_object, residual, right_hand_side, largest,
                band, scratch, normals, basis, matrix):
    """Rod r's Newton system at ``q``: its sliding nodes put onto the object's surface where the object is
    ``fixed_object`` (a free body's follow the body instead), then :func:`_rod_equations`. Returns the rod's largest
    scaled residual and ``largest``."""
    # whether the object is fixed comes as a flag, not as the coupling itself, whose two dozen arrays this would
    # bind once per rod and Newton iteration
    if holds is not None and fixed_object:
        _slide_on_fixed_object(r, q, holds, normals)
    return _rod_equations(r, q, step, rods, terms, solver, measured, holds, residual, right_hand_side, largest, band,
                          scratch, normals, basis, matrix)


@kernel(inline=True)
def _rod_equations(r, q, step, rods, terms, solver, measured, holds, residual, right_hand_side, largest, band, scratch,
                   normals, basis, matrix):
    """Rod r's residual and right-hand side at ``q`` as it is, and its Newton matrix when ``matrix`` (else the band
    holds only the external forces' part): :func:`_rod_residual`, then :func:`_slide_rows`. Returns the rod's
    largest scaled residual and ``largest``."""
    own, largest = _rod_residual(r, q, step, rods, terms, solver, measured, residual, right_hand_side, largest, band,
                                 scratch, matrix)
    # a rod with no sliding node has nothing to turn: the test costs less than binding the call's arrays
    if holds is not None and holds.sliding[r].any():
        own, largest = _slide_rows(r, holds, normals, residual, right_hand_side, band, solver.tolerance_inverse, own,
                                   largest, basis)
    return own, largest


@kernel
def _back_off_rod(r, q, rod_delta, fraction):
    """Takes ``fraction`` of rod r's last Newton step ``rod_delta`` (n,) back."""
    stride = q.shape[2]
    for i in range(q.shape[1]):
        for s in range(stride):
            q[r, i, s] -= fraction * rod_delta[i * stride + s]


@kernel
def _place_held_nodes(b, r, q, holds, coupling, rod_coupling, normals, body_residual):
    """Puts rod r's stuck nodes on the free body, x = P·(c + R·r_h), and its sliding nodes onto the body's surface
    at their current point; writes S = P·[I, −[a]×], the motion of each held DOF per unit body motion, into
    ``rod_coupling`` (n, 6) (zero rows elsewhere; a sliding node's rows in its surface's frame, where only the
    normal follows the body), the sliding nodes' normals into ``normals`` (N, D), and adds the reaction of their
    friction on the body to ``body_residual`` (6,)."""
    motion, body = coupling.motion, coupling.body
    stride = q.shape[2]
    projection = holds.projection[r]
    dim = projection.shape[0]
    orientation = motion.orientation[b]
    c = motion.position
    a = local_array(3)
    world = local_array(3)
    cross = local_array((3, 3))
    motion_rows = local_array((3, 6))[:dim]  # P·[I, −[a]×] of one node
    rod_coupling[:, :] = 0.0
    start, end = local_array(3)[:dim], local_array(3)[:dim]  # the body's segment as the rod sees it now
    for d in range(dim):
        start[d] = end[d] = 0.0
        for k in range(3):
            centre_start, centre_end = c[b, k], c[b, k]
            for m in range(3):
                centre_start += orientation[k, m] * body.segment_start[b, m]
                centre_end += orientation[k, m] * body.segment_end[b, m]
            start[d] += projection[d, k] * centre_start
            end[d] += projection[d, k] * centre_end
    across = 0.0  # a planar finger: the centre's distance from its plane, whose normal is (−d_y, d_x, 0)
    if dim == 2:
        across = -projection[0, 1] * c[b, 0] + projection[0, 0] * c[b, 1]
    scratch_normal = local_array(3)[:dim]
    friction = local_array(3)[:dim]
    for i in range(q.shape[1]):
        if not holds.held[r, i]:
            continue
        sliding = holds.sliding[r, i]
        reach = body.radius[b] + holds.finger_radius[i]  # where the node touches the body now (the planar section's)
        radius = reach if dim == 3 else math.sqrt(max(reach * reach - across * across, 0.0))
        if sliding:  # onto the surface, then its world point relative to the centre
            onto_surface(q[r, i, :dim], start, end, radius, normals[i])
            for k in range(3):
                world[k] = 0.0
                for d in range(dim):
                    world[k] += projection[d, k] * q[r, i, d]
                a[k] = world[k] - c[b, k]
        else:
            for k in range(3):
                a[k] = orientation[k, 0] * holds.offsets[r, i, 0] + orientation[k, 1] * holds.offsets[r, i, 1] \
                    + orientation[k, 2] * holds.offsets[r, i, 2]
                world[k] = c[b, k] + a[k]
        cross[0, 0], cross[0, 1], cross[0, 2] = 0.0, -a[2], a[1]
        cross[1, 0], cross[1, 1], cross[1, 2] = a[2], 0.0, -a[0]
        cross[2, 0], cross[2, 1], cross[2, 2] = -a[1], a[0], 0.0
        for d in range(dim):
            for k in range(3):
                motion_rows[d, k] = projection[d, k]
                motion_rows[d, 3 + k] = -(projection[d, 0] * cross[0, k] + projection[d, 1] * cross[1, k]
                                          + projection[d, 2] * cross[2, k])
        if not sliding:
            for d in range(dim):
                q[r, i, d] = projection[d, 0] * world[0] + projection[d, 1] * world[1] + projection[d, 2] * world[2]
                for k in range(6):
                    rod_coupling[stride * i + d, k] = motion_rows[d, k]
            if dim == 2:  # a held point the body carries out of the finger's plane: back onto the section
                onto_surface(q[r, i, :dim], start, end, radius, scratch_normal)
            continue
        along_surface(holds.friction[r, i], normals[i], friction)
        for k in range(6):
            along_normal = 0.0
            load = 0.0
            for d in range(dim):
                along_normal += normals[i, d] * motion_rows[d, k]
                load += motion_rows[d, k] * friction[d]
            rod_coupling[stride * i, k] = along_normal  # ξ_n follows the body; the tangents do not
            body_residual[k] += load  # the friction's reaction on the body: −(−f) on its point


@kernel
def _slide_on_fixed_object(r, q, holds, normals):
    """Puts rod r's sliding nodes onto a fixed object's surface at their current point, their normals into
    ``normals`` (N, D)."""
    dim = holds.starts.shape[1]
    for i in range(q.shape[1]):
        if holds.held[r, i] and holds.sliding[r, i]:
            onto_surface(q[r, i, :dim], holds.starts[r], holds.ends[r], holds.radii[r, i], normals[i])


@kernel
def _slide_rows(r, holds, normals, residual, right_hand_side, band, tolerance_inverse, own, largest, basis):
    """Rod r's sliding nodes in Newton's system: their friction joins the residual (n,) and the right-hand side (n,),
    whose node blocks and the band (n, kd+1) are then turned into each node's surface frame (normal, tangents),
    where the tangents are free and measured against the tolerance. Returns ``own`` and ``largest`` updated."""
    dim = holds.starts.shape[1]
    stride = residual.size // normals.shape[0]
    friction = local_array(3)[:dim]
    rotated = local_array(3)[:dim]
    for i in range(normals.shape[0]):
        if not (holds.held[r, i] and holds.sliding[r, i]):
            continue
        along_surface(holds.friction[r, i], normals[i], friction)
        first = stride * i
        for d in range(dim):
            residual[first + d] -= friction[d]
            right_hand_side[first + d] += friction[d]
        tangent_basis(normals[i], basis)
        for a in range(dim):
            rotated[a] = 0.0
            for d in range(dim):
                rotated[a] += basis[d, a] * right_hand_side[first + d]
        for a in range(dim):
            right_hand_side[first + a] = rotated[a]
            if a > 0:  # the tangents: free
                scaled = abs(rotated[a]) * tolerance_inverse[r, first + a]
                if not scaled <= own:
                    own = scaled
                if not scaled <= largest:
                    largest = scaled
        rotate_node(band, first, basis)
    return own, largest


@kernel
def _unrotate_steps(first_rod, holds, work):
    """Turns the Newton steps of every active rod's sliding nodes, x0 and X (work), from their surface frames back
    into the rod's coordinates."""
    # the bundles' members taken out once, for the branches below
    normals, basis, active, x0, x_coupling = work.normals, work.basis, work.active, work.x0, work.x_coupling
    held, sliding = holds.held, holds.sliding
    dim = basis.shape[0]
    stride = x0.shape[1] // normals.shape[1]
    value = local_array(3)[:dim]
    columns = x_coupling.shape[2] if x_coupling.shape[0] > 0 else 0  # X only with a body
    for f in range(active.size):
        if not active[f]:
            continue
        r = first_rod + f
        for i in range(normals.shape[1]):
            if not (held[r, i] and sliding[r, i]):
                continue
            tangent_basis(normals[f, i], basis)
            first = stride * i
            for column in range(-1, columns):
                for d in range(dim):
                    value[d] = 0.0
                    for a in range(dim):
                        step = x0[f, first + a] if column < 0 else x_coupling[f, first + a, column]
                        value[d] += basis[d, a] * step
                for d in range(dim):
                    if column < 0:
                        x0[f, first + d] = value[d]
                    else:
                        x_coupling[f, first + d, column] = value[d]


@kernel(inline=True)
def _rod_residual(r, q, step, rods, terms, solver, free, residual, right_hand_side, largest, band, scratch, matrix):
    """Assembles rod r and writes its residual (n,) into ``residual`` and its negation, the Newton step's right-hand
    side, into ``right_hand_side`` (n,), its Newton matrix into ``band`` (n, kd+1) (the elastic part when ``matrix``:
    the forces do not depend on it); ``scratch`` holds the work arrays force (N, S), velocity and acceleration
    (N, D) and the 3-D energy's and the finger contact's buffers. Returns the rod's largest scaled residual and
    ``largest`` updated with it (NaN is caught: it never compares as small)."""
    # the caller passes rows and work arrays it took out of their bundles once per solve: this runs once per rod and
    # Newton iteration
    force, strained, velocity, acceleration, elastic, fingers = scratch
    assemble_rod(r, q, step, rods, terms, matrix, force, band, strained, velocity, acceleration, elastic, fingers)
    own = 0.0
    mass_term, tolerance_inverse, q_pred = solver.mass_term, solver.tolerance_inverse, step.q_pred
    n_nodes, stride = force.shape
    for i in range(n_nodes):
        for k in range(stride):
            j = i * stride + k
            value = mass_term[j] * (q[r, i, k] - q_pred[r, i, k]) - force[i, k]
            residual[j] = value
            right_hand_side[j] = -value
            scaled = abs(value) * tolerance_inverse[r, j] if free[r, j] else 0.0
            if not scaled <= own:
                own = scaled
            if not scaled <= largest:
                largest = scaled
    return own, largest


@kernel
def _load_body(right_hand_side, coupling, body_residual):
    """Adds a touching rod's reactions, its residual on held DOFs (the negated Newton right-hand side (n,), in the
    frames the DOFs are solved in) moved by ``coupling`` (n, 6), to the body's residual (6,)."""
    for j in range(right_hand_side.size):
        for k in range(6):
            body_residual[k] -= coupling[j, k] * right_hand_side[j]


@kernel
def _body_residual_in_basis(basis, body_tolerance, own, total, largest):
    """The body's residual ``own`` (6,) in its admissible motions, Bᵀ·own, into ``total``; returns ``largest``
    updated with its scaled entries."""
    for k in range(6):
        total[k] = 0.0
        for i in range(6):
            total[k] += basis[i, k] * own[i]
        scaled = abs(total[k]) / body_tolerance[k]
        if not scaled <= largest:
            largest = scaled
    return largest


@kernel(inline=True)
def _rods_continue(first, it, max_iterations, result, work):
    """For rods on their own: marks the rods that converged (or ran out of iterations) as done; returns whether
    any still iterates."""
    going = False
    active, rod_ratio, ratio, converged = work.active, work.rod_ratio, result.ratio, result.converged
    for f in range(active.size):
        if not active[f]:
            continue
        r = first + f
        ratio[r] = rod_ratio[f]
        if rod_ratio[f] <= 1.0:
            converged[r] = True
            active[f] = False
        elif it == max_iterations:
            active[f] = False
        going |= active[f]
    return going


@kernel
def _body_step(b, basis, work):
    """The body's Newton step (6,) into ``work.body_step``, from the reduced system Bᵀ·A·B δ = −Bᵀ·G + Bᵀ·Σ rhs
    (A the body's matrix plus the rods' Schur complements; unused columns of B get the identity). Returns False,
    with no step, where the system is not finite or is singular."""
    matrix = work.body_matrix
    for f in range(work.block.shape[0]):
        for i in range(6):
            for j in range(6):
                matrix[i, j] += work.block[f, i, j]
    reduced = local_array((6, 6))
    solution = local_array(6)
    total = work.body_total  # Bᵀ·G from _body_residual_in_basis
    step = work.body_step
    for k in range(6):
        used = False
        for i in range(6):
            if basis[i, k] != 0.0:
                used = True
        value = -total[k]
        for f in range(work.rhs.shape[0]):
            for i in range(6):
                value -= basis[i, k] * work.rhs[f, i]  # rhs = (A·S)ᵀ·x0 with x0 = −A⁻¹·G
        solution[k] = value
        for m in range(6):
            value = 0.0
            for i in range(6):
                for j in range(6):
                    value += basis[i, k] * matrix[i, j] * basis[j, m]
            reduced[k, m] = value + (1.0 if k == m and not used else 0.0)
    if not solve_dense(reduced, solution):
        return False  # a diverged iterate, or a singular system: the solve fails instead
    for i in range(6):
        step[i] = 0.0
        for k in range(6):
            step[i] += basis[i, k] * solution[k]
    return True


@kernel(inline=True)
def _apply_step(b, first, q, coupling, work):
    """Moves every active rod by its Newton step, x0 − X·δ (δ the body's step, for rods that touch it; both are zero
    on fixed DOFs), and the body by δ; remembers the rods' steps for the line search."""
    x0, x_coupling, body_step, rod_delta = work.x0, work.x_coupling, work.body_step, work.rod_delta
    active, touching_rods, rubbing = work.active, work.touching, work.rubbing
    n_nodes, stride = q.shape[1], q.shape[2]
    for f in range(active.size):
        if not active[f]:
            continue
        r = first + f
        touching = touching_rods[f]
        for i in range(n_nodes):  # node by node, not through a flat view (see _rod_residual)
            for s in range(stride):
                j = i * stride + s
                delta = x0[f, j]
                if touching:
                    for k in range(6):
                        delta -= x_coupling[f, j, k] * body_step[k]
                if coupling is not None or rubbing[f]:  # for the line search of a body's or a rubbing rod's solve
                    rod_delta[f, j] = delta
                q[r, i, s] += delta
    if coupling is not None:
        for k in range(3):
            coupling.motion.position[b, k] += work.body_step[k]
            coupling.motion.rotation[b, k] += work.body_step[3 + k]


@kernel
def _back_off(b, first, q, motion, work, fraction):
    """Takes ``fraction`` of the last Newton step back, rods and body (the line search of a free body's solve)."""
    for f in range(work.active.size):
        _back_off_rod(first + f, q, work.rod_delta[f], fraction)
    for k in range(3):
        motion.position[b, k] -= fraction * work.body_step[k]
        motion.rotation[b, k] -= fraction * work.body_step[3 + k]


@kernel
def _finish_gripper(first, n_fingers, converged, iterations, ratio, result):
    """Gives every rod of a gripper solved with its body the gripper's outcome."""
    for r in range(first, first + n_fingers):
        result.converged[r] = converged
        result.iterations[r] = iterations
        result.ratio[r] = ratio


@kernel(python=True, runtime=True)  # it allocates
def advance_rods(q_old, velocity_old, acceleration_old, natural_curvature, water, dt, rods, terms, solver, midpoint,
                 q, velocity, acceleration):
    """A whole backward-Euler step of rods that move on their own, in one call (the hot path of a scene without
    an object): for one gripper after another, :func:`predict`, Newton's method from there (:func:`newton`'s loop) and
    :func:`finish`; with ``midpoint``, it is the midpoint rule's half step and :func:`midpoint_end` follows. Arrays
    (R, N, S) as in :class:`~..kernels.assembly.StepInputs`; ``acceleration_old`` empty for Newton's start at the
    predictor. ``rods``, ``terms`` and ``solver`` are the fields of :class:`~..kernels.assembly.RodArrays`,
    :class:`~..scene.forces.ForceTerms` and :class:`SolverArrays` as plain tuples (:func:`plain`). Writes the new
    coordinates, velocities and accelerations (R, N, S); returns :func:`per_gripper`'s summary."""
    rods, terms, solver = named_rods(rods), ForceTerms(*terms), SolverArrays(*solver)
    n_rods, n_nodes, stride = q_old.shape
    dim = water.shape[1]
    near_shape = (n_rods, n_nodes, solver.n_fingers) if rods.fingers.stiffness > 0.0 else (0, 0, 0)
    step = StepInputs(q_old, np.empty(q_old.shape), natural_curvature, water, dt, np.empty(near_shape, np.int64))
    counts, flags = np.zeros((2, n_rods), dtype=np.int64), np.zeros((3, n_rods), dtype=np.bool_)  # fewer allocations
    result = SolveResult(flags[0], counts[0], np.full(n_rods, np.inf), np.empty((n_rods, n_nodes * stride)), counts[1],
                         flags[1])
    every_rod = flags[2]
    every_rod[:] = True
    work = new_work(q, dim, solver.n_fingers, False, False, step.near.size > 0)
    for b in range(n_rods // solver.n_fingers):  # gripper by gripper, while its rods' arrays are in cache
        step_gripper_rods(b, velocity_old, acceleration_old, step, rods, terms, solver, midpoint, q, velocity,
                          acceleration, every_rod, result, work)
    return per_gripper(result.converged, result.iterations, result.ratio, solver.n_fingers)


@kernel(python=True)
def step_gripper_rods(b, velocity_old, acceleration_old, step, rods, terms, solver, midpoint, q, velocity,
                      acceleration, every_rod, result, work):
    """Gripper b's rods, on their own, through one backward-Euler step from ``step.q_old`` (:func:`advance_rods`,
    whose arguments these are, named): :func:`predict` into ``step.q_pred`` and ``q``, the fingers near each other,
    Newton's method (:func:`newton`'s loop, results into ``result``) and :func:`finish` (with ``midpoint``,
    :func:`midpoint_end` too). Allocates nothing (``work`` from :func:`new_work`, or a GPU thread's own arrays)."""
    n_fingers = solver.n_fingers
    q_old, dt = step.q_old, step.dt
    for r in range(b * n_fingers, (b + 1) * n_fingers):
        _predict_rod(r, q_old, velocity_old, acceleration_old, dt, step.q_pred, q)
    if step.near.size > 0:
        near_fingers_of_gripper(b * n_fingers, q_old, step.q_pred, rods.fingers, step.near, work.fingers)
    _solve_gripper(b, q, step, rods, terms, solver, solver.clamp_free, None, None, every_rod, result, work)
    for r in range(b * n_fingers, (b + 1) * n_fingers):
        _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration)
        if midpoint:
            _midpoint_end_rod(r, q_old, velocity_old, q, velocity)


@kernel(python=True)
def predict(q_old, velocity_old, acceleration_old, dt, q_pred, q_start):
    """The predictor q_pred = q_old + Δt·v_old of every rod, and Newton's start q_pred + Δt²·a_old, the last step's
    motion extrapolated (``acceleration_old`` empty: the predictor itself). Arrays (R, N, S)."""
    for r in range(q_old.shape[0]):
        _predict_rod(r, q_old, velocity_old, acceleration_old, dt, q_pred, q_start)


@kernel(inline=True)
def _predict_rod(r, q_old, velocity_old, acceleration_old, dt, q_pred, q_start):
    extrapolate = acceleration_old.size > 0
    for i in range(q_old.shape[1]):
        for k in range(q_old.shape[2]):
            q_pred[r, i, k] = q_old[r, i, k] + dt * velocity_old[r, i, k]
            q_start[r, i, k] = q_pred[r, i, k] + (dt * dt * acceleration_old[r, i, k] if extrapolate else 0.0)


@kernel(python=True)
def finish(q, q_old, velocity_old, dt, velocity, acceleration):
    """The end of a backward-Euler step of every rod: v = (q − q_old)/Δt and the mean acceleration (v − v_old)/Δt."""
    for r in range(q.shape[0]):
        _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration)


@kernel(inline=True)
def _finish_rod(r, q, q_old, velocity_old, dt, velocity, acceleration):
    for i in range(q.shape[1]):
        for k in range(q.shape[2]):
            velocity[r, i, k] = (q[r, i, k] - q_old[r, i, k]) / dt
            acceleration[r, i, k] = (velocity[r, i, k] - velocity_old[r, i, k]) / dt


@kernel(python=True)
def midpoint_end(q_old, velocity_old, q, velocity):
    """The implicit midpoint rule's end from its backward-Euler half step (see :mod:`.integrators`), in place:
    q₁ = 2·q_½ − q₀, v₁ = 2·v_½ − v₀. Arrays (R, N, S)."""
    for r in range(q.shape[0]):
        _midpoint_end_rod(r, q_old, velocity_old, q, velocity)


@kernel(inline=True)
def _midpoint_end_rod(r, q_old, velocity_old, q, velocity):
    for i in range(q.shape[1]):
        for k in range(q.shape[2]):
            q[r, i, k] = 2.0 * q[r, i, k] - q_old[r, i, k]
            velocity[r, i, k] = 2.0 * velocity[r, i, k] - velocity_old[r, i, k]


@kernel(python=True, runtime=True)  # it allocates
def per_gripper(converged, iterations, ratio, n_fingers):
    """A step's per-rod Newton results (R,) per gripper (B,): whether every finger converged, the most iterations,
    and the largest residual ratio (NaN read as inf)."""
    n_grippers = converged.size // n_fingers
    all_converged = np.ones(n_grippers, dtype=np.bool_)
    most = np.zeros(n_grippers, dtype=np.int64)
    largest = np.zeros(n_grippers)
    for b in range(n_grippers):
        for r in range(b * n_fingers, (b + 1) * n_fingers):
            all_converged[b] &= converged[r]
            most[b] = max(most[b], iterations[r])
            largest[b] = max(largest[b], np.inf if np.isnan(ratio[r]) else ratio[r])
    return all_converged, most, largest


__all__ = ["SolverArrays", "SolveResult", "Holds", "plain", "for_one_gripper", "BodyCoupling", "MAX_STEP_HALVINGS",
           "NewtonWork", "new_work", "eliminate_rods", "newton", "advance_rods", "step_gripper_rods", "predict",
           "finish", "midpoint_end", "per_gripper"]
