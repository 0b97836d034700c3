"""Compiled kernels of a free rigid body (sphere or capsule) moved by the fingers' contact reactions.

Notation (per gripper):

========  ================================================================  ==========
symbol    meaning                                                           unit
========  ================================================================  ==========
c, u      centre and velocity of the body                                   m, m/s
R, ω      orientation (body → world) and angular velocity                   1, rad/s
θ         rotation over the step: R = exp([θ]×)·R_old, ω = θ/Δt            rad
r_h       a held node's offset from the centre, in the body frame           m
a_h       the same offset in the world frame, R·r_h                         m
M_t       mass plus added mass, m + C_a·ρ_w·V                               kg
I         rotational inertia (⅖·m·R² for a sphere), world frame R·I_b·Rᵀ  kg·m²
========  ================================================================  ==========

Backward Euler for the body, M_t·(c − c_old − Δt·u_old)/Δt² = F_ext(u) − Σ_h R_h and
(I·ω − I_old·ω_old)/Δt = −Σ_h a_h × R_h, where R_h is the reaction of the body on held node h (the node's residual)
and held nodes move with the body, x_h = c + a_h. Rods and body are solved together by Newton's method: the rods'
free DOFs are eliminated rod by rod (one banded factorisation, seven right-hand sides), which leaves a 6×6 system
for the body per gripper (a Schur complement). A staggered scheme, which would move the body with last iteration's
reactions, is unstable for a body as light as the water it displaces; this one is not.

The palm, a disc in the plane z = 0, pushes back on a body that overlaps it, with a stiffness and critical damping
(:attr:`~..scene.objects.ContactSettings.palm_stiffness`; the overlap's dependence on the horizontal position and the
orientation is left out of the Newton matrix). External loads come from the scene's force models through
:class:`~..scene.forces.BodyLoads`: gravity, buoyancy, and with Morison drag quadratic drag on the velocity relative
to the current: ½·ρ_w·C_d·π·r²·|w|·w for a sphere (C_d = 0.47, Re ≈ 10³–10⁵) or a capsule's two end caps, plus
½·ρ_w·C_n·D·h·|w_n|·w_n across a capsule's cylinder; with added mass, C_a = 0.5 of a sphere's volume, and
C_a·ρ_w·π·r²·h across a capsule's cylinder, on the body's acceleration relative to an accelerating current, and the
Froude–Krylov force ρ_w·V·a_w of that current's pressure gradient. A turning body feels the creeping-flow torque
8π·η·R³·ω plus a laminar boundary layer's, and a capsule's cylinder turning across its axis the strip-theory drag
of its cross-section.

These are the body's kernels; Newton's method on rods and body together is :func:`~..solvers.newton.newton`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .compiled import kernel
from .contact import STICK_SPEED
from .local import local_array


class BodyArrays(NamedTuple):
    """The grasped objects of a batch of B grippers, one each, as the kernels take them (body frame = world at
    t = 0), and the palm they may be pushed against."""

    mass: np.ndarray
    """m [kg], (B,)."""
    inertia: np.ndarray
    """Rotational inertia about the centre, body frame [kg·m²], (B, 3, 3)."""
    added_mass: np.ndarray
    """Added-mass tensor, body frame [kg], (B, 3, 3)."""
    weight: np.ndarray
    """Net weight along −z, (m − ρ_w·V)·g [N], (B,)."""
    normal_drag: np.ndarray
    """½·ρ_w·C_n·D·h of a capsule's cylinder, on the velocity normal to its axis [kg/m], (B,); 0 for a sphere."""
    isotropic_drag: np.ndarray
    """½·ρ_w·C_d·π·r² of the sphere (or a capsule's two end caps together) [kg/m], (B,)."""
    displaced_mass: np.ndarray
    """ρ_w·V of the Froude–Krylov force ρ_w·V·a_w [kg], (B,)."""
    spin_damping: np.ndarray
    """8π·η·R³: the creeping-flow torque on the turning body is −this·ω [N·m·s], (B,)."""
    spin_drag: np.ndarray
    """The boundary layer's torque is −this·√|ω|·ω [N·m·s^(3/2)], (B,)."""
    tumble_drag: np.ndarray
    """A capsule's cylinder turning across its axis feels −this·|ω⊥|·ω⊥ [N·m·s²], (B,); 0 for a sphere."""
    axis: np.ndarray
    """The capsule's axis in the body frame, (B, 3); any unit vector for a sphere."""
    segment_start: np.ndarray
    """One end of the object's segment relative to its centre, body frame [m], (B, 3) (zero for a sphere)."""
    segment_end: np.ndarray
    """The other end [m], (B, 3)."""
    radius: np.ndarray
    """Radius of each body [m], (B,)."""
    palm_stiffness: float
    """k of the palm disc in the plane z = 0 [N/m]."""
    palm_radius: float
    """Its radius [m]."""
    palm_damping_depth: float
    """The overlap over which the palm's damping grows to critical [m]."""
    palm_friction: float
    """μ between the palm and the body (dimensionless)."""


N_BODY_ARRAYS = BodyArrays._fields.index("palm_stiffness")
"""How many of :class:`BodyArrays`' fields are per-body arrays (the palm's numbers follow them)."""


class BodyState(NamedTuple):
    """The bodies' state at one instant (the start of a step)."""

    position: np.ndarray
    """Centre [m], (B, 3)."""
    velocity: np.ndarray
    """Velocity [m/s], (B, 3)."""
    orientation: np.ndarray
    """Orientation, body to world, (B, 3, 3)."""
    angular_velocity: np.ndarray
    """Angular velocity [rad/s], (B, 3)."""


class BodyMotion(NamedTuple):
    """The free bodies' unknowns over a step, what they start from, and the water around them."""

    position: np.ndarray
    """The centre c at the end of the step [m], (B, 3): Newton's start on entry, the solution on return."""
    rotation: np.ndarray
    """The rotation θ over the step [rad], R = exp([θ]×)·R_old, (B, 3): start and solution, as ``position``."""
    orientation: np.ndarray
    """R at the solution, (B, 3, 3), written by the solve."""
    old: BodyState
    """The bodies at the start of the step."""
    water: np.ndarray
    """The current at each body [m/s], (B, 3)."""
    water_acceleration: np.ndarray
    """The current's mean acceleration over the step at each body [m/s²], (B, 3)."""


@kernel
def _translational_mass(b, body, orientation_old, mass):
    """Mass plus added mass of body b in the world frame, m·I + R_old·A·R_oldᵀ [kg], into ``mass`` (3, 3)."""
    added = body.added_mass
    for i in range(3):
        for j in range(3):
            total = body.mass[b] if i == j else 0.0
            for k in range(3):
                for m in range(3):
                    total += orientation_old[b, i, k] * added[b, k, m] * orientation_old[b, j, m]
            mass[i, j] = total


@kernel
def _palm_contact(b, body, c, velocity, omega, orientation, vertical_mass, dt, load, matrix):
    """Adds the palm's force and torque on body b (6,) [N, N·m] to ``load``, and their negated derivatives by the
    body's unknowns over the step (centre and rotation, (6, 6)) to ``matrix``.

    The palm is the disc of radius ``palm_radius`` in the plane z = 0; the body's highest end sphere counts. With
    the overlap δ > 0 above the plane, it pushes down with N = max(0, k·δ + d(δ)·u_z), where the damping
    d(δ) = 2·√(k·M)·min(δ/δ_d, 1) (critical for the body's vertical mass M once δ ≥ δ_d, ``palm_damping_depth``)
    grows from zero with the overlap: the force is continuous at first touch and never pulls. Coulomb friction
    −μ·N·s/√(|s|² + v_s²) opposes the slip s, the horizontal velocity of the body's point on the palm
    (v_s = :data:`~.contact.STICK_SPEED`). The overlap's dependence on the horizontal position and the orientation is
    left out of the derivatives. ``velocity`` and ``omega`` (3,) are the body's over the step, ``orientation``
    (3, 3) its R."""
    stiffness, palm_radius = body.palm_stiffness, body.palm_radius
    if stiffness == 0.0:
        return
    radius = body.radius[b]
    top_end = local_array(3)
    end = local_array(3)
    highest = -np.inf
    for segment in (body.segment_start, body.segment_end):
        for i in range(3):
            end[i] = c[b, i] + orientation[i, 0] * segment[b, 0] + orientation[i, 1] * segment[b, 1] \
                + orientation[i, 2] * segment[b, 2]
        if end[2] > highest:
            highest = end[2]
            for i in range(3):
                top_end[i] = end[i]
    outside = max(math.hypot(top_end[0], top_end[1]) - palm_radius, 0.0)  # past the disc's rim
    cap = math.sqrt(max(radius * radius - outside * outside, 0.0))
    overlap = top_end[2] + cap
    if not (overlap > 0.0 and outside < radius):
        return
    critical = 2.0 * math.sqrt(stiffness * vertical_mass)
    depth = body.palm_damping_depth
    ramp = min(overlap / depth, 1.0) if depth > 0.0 else 1.0
    push = stiffness * overlap + critical * ramp * velocity[2]
    if push <= 0.0:  # separating faster than the overlap pushes: no pull
        return
    d_push = stiffness + critical * ramp / dt + (critical * velocity[2] / depth if 0.0 < overlap < depth else 0.0)
    arm = local_array(3)  # from the centre to the body's point on the palm
    for i in range(3):
        arm[i] = top_end[i] - c[b, i]
    arm[2] += cap
    d_force = local_array((3, 6))  # ∂(force on the body)/∂(c, θ)
    d_force[:, :] = 0.0
    d_force[2, 2] = -d_push
    mu = body.palm_friction
    force = local_array(3)
    force[:] = 0.0
    force[2] = -push
    if mu > 0.0:
        slip = local_array(2)  # u + ω × a, horizontal
        slip[0] = velocity[0] + omega[1] * arm[2] - omega[2] * arm[1]
        slip[1] = velocity[1] + omega[2] * arm[0] - omega[0] * arm[2]
        norm = math.sqrt(slip[0] ** 2 + slip[1] ** 2 + STICK_SPEED**2)
        d_slip = local_array((2, 6))  # ∂slip/∂(c, θ): u = (c − c_old)/Δt, ω = θ/Δt
        d_slip[:, :] = 0.0
        d_slip[0, 0] = d_slip[1, 1] = 1.0 / dt
        d_slip[0, 4], d_slip[0, 5] = arm[2] / dt, -arm[1] / dt
        d_slip[1, 5], d_slip[1, 3] = arm[0] / dt, -arm[2] / dt
        for i in range(2):
            force[i] = -mu * push * slip[i] / norm
            for m in range(6):
                total = 0.0
                for j in range(2):
                    total += ((1.0 if i == j else 0.0) / norm - slip[i] * slip[j] / norm**3) * d_slip[j, m]
                d_force[i, m] = -mu * push * total
            d_force[i, 2] -= mu * d_push * slip[i] / norm
    for i in range(3):
        load[i] += force[i]
    load[3] += arm[1] * force[2] - arm[2] * force[1]
    load[4] += arm[2] * force[0] - arm[0] * force[2]
    load[5] += arm[0] * force[1] - arm[1] * force[0]
    for m in range(6):
        for i in range(3):
            matrix[i, m] -= d_force[i, m]
        matrix[3, m] -= arm[1] * d_force[2, m] - arm[2] * d_force[1, m]
        matrix[4, m] -= arm[2] * d_force[0, m] - arm[0] * d_force[2, m]
        matrix[5, m] -= arm[0] * d_force[1, m] - arm[1] * d_force[0, m]


@kernel(python=True, runtime=True)  # it allocates
def palm_reactions(body, c, c_old, theta, orientation, orientation_old, dt, reaction):
    """Writes the force of every body on the palm (B, 3) [N] into ``reaction``, for bodies moved from ``c_old`` to
    ``c`` and turned by ``theta`` (B, 3) over the step; ``body`` holds the fields of :class:`BodyArrays` as a plain
    tuple (an entry point: numba types plain tuples faster)."""
    body = BodyArrays(*body)
    mass = np.empty((3, 3))
    load = np.empty(6)
    scratch = np.zeros((6, 6))
    velocity = np.empty(3)
    omega = np.empty(3)
    for b in range(c.shape[0]):
        _translational_mass(b, body, orientation_old, mass)
        for i in range(3):
            velocity[i] = (c[b, i] - c_old[b, i]) / dt
            omega[i] = theta[b, i] / dt
        load[:] = 0.0
        _palm_contact(b, body, c, velocity, omega, orientation[b], mass[2, 2], dt, load, scratch)
        for i in range(3):
            reaction[b, i] = -load[i]


@kernel(python=True)
def body_residual(b, body, motion, orientation, dt, residual, matrix):
    """Body b's own residual (6,) (inertia minus external loads) into ``residual``, and the diagonal blocks of its
    Jacobian, translation and rotation, into ``matrix`` (6, 6). ``body`` is :class:`BodyArrays`, ``motion``
    :class:`BodyMotion` (at Newton's current iterate); ``orientation`` (3, 3) is the end-of-step R."""
    c, theta, water = motion.position, motion.rotation, motion.water
    c_old, u_old, orientation_old, w_old = motion.old
    inertia, weight, normal_drag, isotropic_drag, axis_body = body.inertia, body.weight, body.normal_drag, \
        body.isotropic_drag, body.axis
    mass = local_array((3, 3))
    _translational_mass(b, body, orientation_old, mass)  # with the start-of-step orientation, as the rods' added mass
    u = local_array(3)
    w = local_array(3)
    axis = local_array(3)
    part = local_array(3)
    force = local_array(3)
    force[:] = 0.0
    force[2] = -weight[b]
    matrix[:, :] = 0.0
    for i in range(3):
        u[i] = (c[b, i] - c_old[b, i]) / dt
        w[i] = u[i] - water[b, i]
        axis[i] = orientation[i, 0] * axis_body[b, 0] + orientation[i, 1] * axis_body[b, 1] \
            + orientation[i, 2] * axis_body[b, 2]
        for j in range(3):
            matrix[i, j] = mass[i, j] / (dt * dt)
    along = w[0] * axis[0] + w[1] * axis[1] + w[2] * axis[2]
    for normal_only in (False, True):
        coefficient = normal_drag[b] if normal_only else isotropic_drag[b]
        if coefficient == 0.0:
            continue
        for i in range(3):
            part[i] = w[i] - along * axis[i] if normal_only else w[i]
        speed = math.sqrt(part[0] ** 2 + part[1] ** 2 + part[2] ** 2)
        safe = speed if speed > 0.0 else 1.0
        for i in range(3):
            force[i] -= coefficient * speed * part[i]
            for j in range(3):
                projector = (1.0 if i == j else 0.0) - (axis[i] * axis[j] if normal_only else 0.0)
                matrix[i, j] += coefficient / dt * (speed * projector + part[i] * part[j] / safe)
    palm = local_array(6)
    palm[:] = 0.0
    omega = local_array(3)
    for i in range(3):
        omega[i] = theta[b, i] / dt
    _palm_contact(b, body, c, u, omega, orientation, mass[2, 2], dt, palm, matrix)
    for i in range(3):
        force[i] += palm[i]
    # the water's inertia in an accelerating current: the Froude–Krylov force ρ_w·V·a_w and the added mass's share of
    # the relative acceleration, A·a_w (A·u̇ is in ``mass``)
    for i in range(3):
        force[i] += body.displaced_mass[b] * motion.water_acceleration[b, i]
        for j in range(3):
            force[i] += (mass[i, j] - (body.mass[b] if i == j else 0.0)) * motion.water_acceleration[b, j]
    for i in range(3):
        total = -force[i]
        for j in range(3):
            total += mass[i, j] * (c[b, j] - c_old[b, j] - dt * u_old[b, j]) / (dt * dt)
        residual[i] = total
    # (I·ω − I_old·ω_old)/Δt with I = R·I_b·Rᵀ
    for i in range(3):
        momentum = 0.0
        for j in range(3):
            new = 0.0
            old = 0.0
            for k in range(3):
                for m in range(3):
                    new += orientation[i, k] * inertia[b, k, m] * orientation[j, m]
                    old += orientation_old[b, i, k] * inertia[b, k, m] * orientation_old[b, j, m]
            momentum += new * theta[b, j] / dt - old * w_old[b, j]
            matrix[3 + i, 3 + j] += new / (dt * dt)
        residual[3 + i] = momentum / dt - palm[3 + i]
    _water_torque(b, body, theta[b], axis, dt, residual, matrix)


@kernel
def _water_torque(b, body, theta, axis, dt, residual, matrix):
    """Adds the water's resistance to the body turning at ω = θ/Δt to its rotational residual (the torque's negation)
    and Jacobian by θ: −(8π·η·R³ + s·√|ω|)·ω on the sphere (or end caps), and −t·|ω⊥|·ω⊥ on a capsule's cylinder
    turning across its axis (``axis`` (3,), world frame)."""
    damping, spin, tumble = body.spin_damping[b], body.spin_drag[b], body.tumble_drag[b]
    omega = local_array(3)
    across = local_array(3)
    for i in range(3):
        omega[i] = theta[i] / dt
    along = omega[0] * axis[0] + omega[1] * axis[1] + omega[2] * axis[2]
    for i in range(3):
        across[i] = omega[i] - along * axis[i]
    rate = math.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    tumbling = math.sqrt(across[0] ** 2 + across[1] ** 2 + across[2] ** 2)
    root = math.sqrt(rate)
    for i in range(3):
        residual[3 + i] += (damping + spin * root) * omega[i] + tumble * tumbling * across[i]
        for j in range(3):
            identity = 1.0 if i == j else 0.0
            projector = identity - axis[i] * axis[j]
            d_torque = (damping + spin * root) * identity  # ∂(−torque)/∂ω
            if rate > 0.0:
                d_torque += spin * omega[i] * omega[j] / (2.0 * root * rate)
            d_torque += tumble * tumbling * projector
            if tumbling > 0.0:
                d_torque += tumble * across[i] * across[j] / tumbling
            matrix[3 + i, 3 + j] += d_torque / dt


@kernel
def _rotation_exp(theta, out):
    """exp([θ]×) of one rotation vector (3,) [rad] into ``out`` (3, 3), by Rodrigues' formula."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    if angle < 1e-8:
        a = 1.0 - angle**2 / 6.0
        b = 0.5 - angle**2 / 24.0
    else:
        a = math.sin(angle) / angle
        b = (1.0 - math.cos(angle)) / angle**2
    k = local_array((3, 3))
    k[0, 0], k[1, 1], k[2, 2] = 0.0, 0.0, 0.0
    k[0, 1], k[0, 2], k[1, 2] = -theta[2], theta[1], -theta[0]
    k[1, 0], k[2, 0], k[2, 1] = theta[2], -theta[1], theta[0]
    for i in range(3):
        for j in range(3):
            kk = k[i, 0] * k[0, j] + k[i, 1] * k[1, j] + k[i, 2] * k[2, j]
            out[i, j] = (1.0 if i == j else 0.0) + a * k[i, j] + b * kk


@kernel
def turned(theta, orientation_old, rotation, out):
    """The body's orientation after turning by ``theta`` (3,) [rad] over the step, exp([θ]×)·R_old, into ``out``
    (3, 3); ``rotation`` (3, 3) is scratch."""
    _rotation_exp(theta, rotation)
    for i in range(3):
        for j in range(3):
            out[i, j] = rotation[i, 0] * orientation_old[0, j] + rotation[i, 1] * orientation_old[1, j] \
                + rotation[i, 2] * orientation_old[2, j]


@kernel(python=True)
def admissible_rotation(basis, theta):
    """Projects one gripper's rotation over the step ``theta`` (3,) [rad], in place, onto the rotations its
    ``basis`` (6, 6; orthonormal columns) allows. Newton moves the body only along the basis, so a rotation it
    forbids would otherwise keep the predictor's Δt·ω_old step after step: a body that spun before planar fingers
    in two planes caught it would turn on at that rate for ever, carrying its holds (and the fingertips on them)
    around with it. Locking the rotation is the same inelastic impact that stick contact is for translation."""
    projected = local_array(3)
    projected[:] = 0.0
    for k in range(6):
        along = 0.0
        for i in range(3):
            along += basis[3 + i, k] * theta[i]
        for i in range(3):
            projected[i] += along * basis[3 + i, k]
    for i in range(3):
        theta[i] = projected[i]


@kernel(python=True)
def planar_body_basis(held, plane_normals, basis):
    """The motions a free body held by planar fingers may make, into ``basis`` (B, 6, 6), padded with zero columns:
    any translation; any rotation while no finger touches; while every touching finger's plane has the same normal,
    rotation about it; else none (a rotation about another axis would carry held points out of a plane the finger
    cannot leave). ``held`` (R, N) marks held nodes, ``plane_normals`` (F, 3) the fingers' planes."""
    n_fingers = plane_normals.shape[0]
    n_grippers = held.shape[0] // n_fingers
    basis[:, :, :] = 0.0
    for b in range(n_grippers):
        for k in range(3):
            basis[b, k, k] = 1.0
        first = -1
        parallel = True
        for f in range(n_fingers):
            if not held[b * n_fingers + f].any():
                continue
            if first < 0:
                first = f
            else:
                dot = 0.0
                for k in range(3):
                    dot += plane_normals[first, k] * plane_normals[f, k]
                parallel &= abs(abs(dot) - 1.0) < 1e-9
        if first < 0:
            for k in range(3, 6):
                basis[b, k, k] = 1.0
        elif parallel:
            for k in range(3):
                basis[b, 3 + k, 3] = plane_normals[first, k]


@kernel
def body_in_rod_frames(c, orientation, segment_start, segment_end, radius, finger_radius, finger_directions,
                       plane_normals, starts, ends, radii):
    """Each gripper's free body (centre ``c`` (B, 3), ``orientation`` (B, 3, 3), segment ends in its frame (B, 3)
    each, ``radius`` (B,)) as each of its rods sees it: the segment's ends (R, D), written into ``starts`` and
    ``ends``, and for every node the radius its centre line touches at (R, N), written into ``radii``: the body's
    plus the finger's own there, ``finger_radius`` (N,) (zeros for contact on the centre lines). In 3-D, world
    coordinates. A planar finger sees the section by its vertical plane: a circle centred (c·d, c_z) in the plane's
    (s, z), of radius √((R + r_i)² − (c·n)²) for node i."""
    n_fingers = finger_directions.shape[0]
    dim = starts.shape[1]
    for b in range(c.shape[0]):
        for f in range(n_fingers):
            r = b * n_fingers + f
            if dim == 3:
                for k in range(3):
                    starts[r, k] = c[b, k]
                    ends[r, k] = c[b, k]
                    for j in range(3):
                        starts[r, k] += orientation[b, k, j] * segment_start[b, j]
                        ends[r, k] += orientation[b, k, j] * segment_end[b, j]
                for i in range(finger_radius.size):
                    radii[r, i] = radius[b] + finger_radius[i]
            else:
                along = 0.0
                across = 0.0
                for k in range(3):
                    along += c[b, k] * finger_directions[f, k]
                    across += c[b, k] * plane_normals[f, k]
                starts[r, 0] = ends[r, 0] = along
                starts[r, 1] = ends[r, 1] = c[b, 2]
                for i in range(finger_radius.size):
                    radii[r, i] = math.sqrt(max((radius[b] + finger_radius[i]) ** 2 - across**2, 0.0))


__all__ = ["BodyArrays", "N_BODY_ARRAYS", "BodyState", "BodyMotion", "palm_reactions", "body_residual", "turned",
           "admissible_rotation", "planar_body_basis", "body_in_rod_frames"]
