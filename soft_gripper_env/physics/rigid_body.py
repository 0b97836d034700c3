"""A free rigid body (sphere or capsule) moved by the fingers' contact reactions, coupled implicitly to them.

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
(:attr:`~.contact.ContactSettings.palm_stiffness`; the overlap's dependence on the horizontal position and the
orientation is left out of the Newton matrix). External loads come from the scene's own force models: gravity from
:class:`~.forces.Gravity`, buoyancy from :class:`~.forces.Buoyancy`, and when :class:`~.hydrodynamics.MorisonDrag`
is present quadratic drag on the velocity relative to the current: ½·ρ_w·C_d·π·r²·|w|·w for a sphere (C_d = 0.47,
Re ≈ 10³–10⁵) or a capsule's two end caps, plus ½·ρ_w·C_n·D·h·|w_n|·w_n across a capsule's cylinder. With
:class:`~.hydrodynamics.AddedMass`, added mass C_a = 0.5 of a sphere's volume, and C_a·ρ_w·π·r²·h across a
capsule's cylinder. The water's torque on a turning body is neglected.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .assembly import assemble_rod
from .contact import contact_changes, corrector_continues, release_held, update_holds, within_reach
from .forces import Buoyancy, Gravity
from .hydrodynamics import AddedMass, MorisonDrag
from .linalg import factor_banded_symmetric, solve_factored

SPHERE_DRAG_COEFFICIENT = 0.47
"""C_d of a sphere at Re ≈ 10³–10⁵ (dimensionless)."""
SPHERE_ADDED_MASS_COEFFICIENT = 0.5
"""C_a of a sphere (dimensionless): its added mass is half the displaced fluid's."""
MAX_STEP_HALVINGS = 6
"""How often the coupled Newton solve may halve a step that made its residual worse (a backtracking line search)."""


class BodyModel:
    """Mass properties and external loads of the free spheres or capsules of a batch of B grippers, one each, as
    arrays with a leading batch axis (body frame = world at t = 0). :meth:`load` sets one gripper's body."""

    def __init__(self, forces, batch_size: int, palm_stiffness: float = 0.0, palm_radius: float = 0.0) -> None:
        self.palm_stiffness = palm_stiffness
        """k of the palm disc in the plane z = 0 [N/m] (:class:`~.contact.ContactSettings`)."""
        self.palm_radius = palm_radius
        """Its radius [m]."""
        self._gravity = sum(f.acceleration for f in forces if isinstance(f, Gravity))
        self._buoyancy = sum(f.fluid_density * f.acceleration for f in forces if isinstance(f, Buoyancy))
        added = [f for f in forces if isinstance(f, AddedMass)]
        self._added_mass = (sum(f.coefficient * f.fluid_density for f in added),
                            sum(SPHERE_ADDED_MASS_COEFFICIENT * f.fluid_density for f in added))
        morison = [f for f in forces if isinstance(f, MorisonDrag)]
        self._drag = (sum(0.5 * f.fluid_density * f.normal_coefficient for f in morison),
                      sum(0.5 * f.fluid_density * SPHERE_DRAG_COEFFICIENT for f in morison))
        B = batch_size
        self.radius = np.zeros(B)
        """Radius of each body [m], (B,)."""
        self.mass = np.zeros(B)
        """m [kg], (B,)."""
        self.inertia = np.zeros((B, 3, 3))
        """Rotational inertia about the centre, body frame [kg·m²], (B, 3, 3)."""
        self.added_mass = np.zeros((B, 3, 3))
        """Added-mass tensor, body frame [kg], (B, 3, 3)."""
        self.weight = np.zeros(B)
        """Net weight along −z, (m − ρ_w·V)·g [N], (B,)."""
        self.normal_drag = np.zeros(B)
        """½·ρ_w·C_n·D·h of a capsule's cylinder, on the velocity normal to its axis [kg/m]; 0 for a sphere."""
        self.isotropic_drag = np.zeros(B)
        """½·ρ_w·C_d·π·r² of the sphere (or a capsule's two end caps together) [kg/m]."""
        self.axis = np.tile([0.0, 0.0, 1.0], (B, 1))
        """The capsule's axis in the body frame (B, 3); any unit vector for a sphere."""
        self.segment = (np.zeros((B, 3)), np.zeros((B, 3)))
        """The object's segment ends relative to its centre, body frame [m], (B, 3) each (zero for a sphere)."""

    def load(self, index: int, obj) -> None:
        """Sets gripper ``index``'s body to the free :class:`~.contact.Sphere` or :class:`~.contact.Capsule`
        ``obj``."""
        r = obj.radius
        start, end = (np.asarray(p, dtype=float) for p in obj.segment)
        center = 0.5 * (start + end)
        length = float(np.linalg.norm(end - start))
        axis = (end - start) / length if length > 0 else np.array([0.0, 0.0, 1.0])
        along = np.outer(axis, axis)
        across = np.eye(3) - along
        cylinder, caps = math.pi * r**2 * length, 4.0 / 3.0 * math.pi * r**3
        m_cylinder, m_caps = obj.density * cylinder, obj.density * caps
        self.radius[index] = r
        self.mass[index] = m_cylinder + m_caps
        self.inertia[index] = (m_cylinder * r**2 / 2 + m_caps * 2 * r**2 / 5) * along + (
            m_cylinder * (length**2 / 12 + r**2 / 4) + m_caps * (2 * r**2 / 5 + length**2 / 4 + 3 * length * r / 8)
        ) * across
        self.added_mass[index] = self._added_mass[0] * cylinder * across + self._added_mass[1] * caps * np.eye(3)
        self.weight[index] = (m_cylinder + m_caps) * self._gravity - self._buoyancy * (cylinder + caps)
        self.normal_drag[index] = self._drag[0] * 2 * r * length
        self.isotropic_drag[index] = self._drag[1] * math.pi * r**2
        self.axis[index] = axis
        self.segment[0][index] = start - center
        self.segment[1][index] = end - center

    def arrays(self) -> tuple:
        """The bodies' arrays in the order the compiled kernels take them: mass, inertia, added mass, weight, normal
        and isotropic drag, axis, the segment's two ends, radius; then the palm's stiffness and radius."""
        return ((self.mass, self.inertia, self.added_mass, self.weight, self.normal_drag, self.isotropic_drag,
                 self.axis, self.segment[0], self.segment[1], self.radius),
                (float(self.palm_stiffness), float(self.palm_radius)))

    def palm_reaction(self, c, c_old, orientation, orientation_old, dt) -> np.ndarray:
        """The force of each body on the palm [N], (B, 3), over a step from ``c_old`` to ``c`` of ``dt`` [s]."""
        reaction = np.zeros_like(c)
        palm_reactions(*self.arrays(), c, c_old, orientation, orientation_old, dt, reaction)
        return reaction


@njit(cache=True, error_model="numpy")
def _translational_mass(b, body, orientation_old, mass):
    """Mass plus added mass of body b in the world frame, m·I + R_old·A·R_oldᵀ [kg], into ``mass`` (3, 3)."""
    added = body[2]
    for i in range(3):
        for j in range(3):
            total = body[0][b] if i == j else 0.0
            for k in range(3):
                for m in range(3):
                    total += orientation_old[b, i, k] * added[b, k, m] * orientation_old[b, j, m]
            mass[i, j] = total


@njit(cache=True, error_model="numpy")
def _palm_push(b, body, palm, c, vertical_velocity, orientation, vertical_mass, dt):
    """The palm's push down on body b [N], k·overlap + critical damping 2·√(k·M)·v_z where the body rises above
    the disc (its highest end sphere counts), and the push's derivative by the body's height over the step [N/m].
    ``orientation`` (3, 3)."""
    stiffness, palm_radius = palm
    if stiffness == 0.0:
        return 0.0, 0.0
    radius = body[9][b]
    top_end = np.empty(3)
    highest = -np.inf
    for segment in (body[7], body[8]):
        end = np.empty(3)
        for i in range(3):
            end[i] = c[b, i] + orientation[i, 0] * segment[b, 0] + orientation[i, 1] * segment[b, 1] \
                + orientation[i, 2] * segment[b, 2]
        if end[2] > highest:
            highest = end[2]
            top_end[:] = end
    outside = max(math.hypot(top_end[0], top_end[1]) - palm_radius, 0.0)  # past the disc's rim
    top = top_end[2] + math.sqrt(max(radius * radius - outside * outside, 0.0))
    if not (top > 0.0 and outside < radius):
        return 0.0, 0.0
    damping = 2.0 * math.sqrt(stiffness * vertical_mass)
    return stiffness * top + damping * vertical_velocity, stiffness + damping / dt


@njit(cache=True, error_model="numpy")
def palm_reactions(body, palm, c, c_old, orientation, orientation_old, dt, reaction):
    """Writes the force of every body on the palm (B, 3) [N] into ``reaction``."""
    mass = np.empty((3, 3))
    for b in range(c.shape[0]):
        _translational_mass(b, body, orientation_old, mass)
        reaction[b, 2] = _palm_push(b, body, palm, c, (c[b, 2] - c_old[b, 2]) / dt, orientation[b], mass[2, 2],
                                    dt)[0]


@njit(cache=True, error_model="numpy")
def body_residual(b, body, palm, c, theta, body_old, orientation, dt, water, residual, matrix):
    """Body b's own residual (6,) (inertia minus external loads) into ``residual``, and the diagonal blocks of its
    Jacobian, translation and rotation, into ``matrix`` (6, 6). ``orientation`` (3, 3) is the end-of-step R;
    ``water`` (B, 3) the current at each body [m/s]."""
    c_old, u_old, orientation_old, w_old = body_old
    inertia, weight, normal_drag, isotropic_drag, axis_body = body[1], body[3], body[4], body[5], body[6]
    mass = np.empty((3, 3))
    _translational_mass(b, body, orientation_old, mass)  # with the start-of-step orientation, as the rods' added mass
    u = np.empty(3)
    w = np.empty(3)
    axis = np.empty(3)
    part = np.empty(3)
    force = np.zeros(3)
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
    push, stiffness = _palm_push(b, body, palm, c, u[2], orientation, mass[2, 2], dt)
    force[2] -= push
    matrix[2, 2] += stiffness
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
            matrix[3 + i, 3 + j] = new / (dt * dt)
        residual[3 + i] = momentum / dt


@njit(cache=True, error_model="numpy")
def _rotation_exp(theta, out):
    """exp([θ]×) of one rotation vector (3,) [rad] into ``out`` (3, 3), by Rodrigues' formula."""
    angle = math.sqrt(theta[0] ** 2 + theta[1] ** 2 + theta[2] ** 2)
    if angle < 1e-8:
        a = 1.0 - angle**2 / 6.0
        b = 0.5 - angle**2 / 24.0
    else:
        a = math.sin(angle) / angle
        b = (1.0 - math.cos(angle)) / angle**2
    k = np.zeros((3, 3))
    k[0, 1], k[0, 2], k[1, 2] = -theta[2], theta[1], -theta[0]
    k[1, 0], k[2, 0], k[2, 1] = theta[2], -theta[1], theta[0]
    for i in range(3):
        for j in range(3):
            kk = k[i, 0] * k[0, j] + k[i, 1] * k[1, j] + k[i, 2] * k[2, j]
            out[i, j] = (1.0 if i == j else 0.0) + a * k[i, j] + b * kk


@njit(cache=True, error_model="numpy")
def _turned(theta, orientation_old, rotation, out):
    """The body's orientation after turning by ``theta`` (3,) [rad] over the step, exp([θ]×)·R_old, into ``out``
    (3, 3); ``rotation`` (3, 3) is scratch."""
    _rotation_exp(theta, rotation)
    for i in range(3):
        for j in range(3):
            out[i, j] = rotation[i, 0] * orientation_old[0, j] + rotation[i, 1] * orientation_old[1, j] \
                + rotation[i, 2] * orientation_old[2, j]


@njit(cache=True, error_model="numpy")
def eliminate_rods(band, residual, coupling, free, coupled, x0, x_coupling, body_block, body_rhs):
    """Eliminates each rod's free DOFs from the coupled Newton system.

    ``band`` (R, n, kd+1): the rod's Newton matrix A (overwritten by its factors); ``residual`` (R, n): G;
    ``coupling`` (R, n, 6): S, the motion of each held DOF per unit body motion (zero on other DOFs); ``free``
    (R, n): the DOFs solved for. Writes x0 = A_FF⁻¹·G_F (R, n), X = A_FF⁻¹·(A·S)_F (R, n, 6), the rod's part of the
    body's matrix Sᵀ·A·S − (A·S)_Fᵀ·X into ``body_block`` (R, 6, 6), and (A·S)_Fᵀ·x0 into ``body_rhs`` (R, 6).
    A rod that holds nothing (``coupled`` False, S = 0) only solves for x0, and leaves the other outputs as given
    (zero). Returns the number of rods whose factorisation failed.
    """
    n_rods, n, kd1 = band.shape
    kd = kd1 - 1
    product = np.empty((n, 6))
    column = np.empty(n)
    failures = 0
    for r in range(n_rods):
        a = band[r]
        s = coupling[r]
        if coupled[r]:  # Sᵀ·A·S needs A before it is factored
            product[:, :] = 0.0  # A·S from the symmetric lower band
            for i in range(n):
                for j in range(max(0, i - kd), i + 1):
                    value = a[i, kd - i + j]
                    if value == 0.0:
                        continue
                    for k in range(6):
                        product[i, k] += value * s[j, k]
                        if i != j:
                            product[j, k] += value * s[i, k]
            for k in range(6):
                for m in range(6):
                    total = 0.0
                    for i in range(n):
                        total += s[i, k] * product[i, m]
                    body_block[r, k, m] = total
        if not factor_banded_symmetric(a, free[r]):
            failures += 1
            x0[r, :] = np.nan
            continue
        x0[r, :] = residual[r]
        solve_factored(a, x0[r], free[r])
        if not coupled[r]:
            continue
        for k in range(6):
            for i in range(n):
                column[i] = product[i, k] if free[r, i] else 0.0
            solve_factored(a, column, free[r])
            x_coupling[r, :, k] = column
        for k in range(6):
            total = 0.0
            for i in range(n):
                if free[r, i]:
                    total += product[i, k] * x0[r, i]
            body_rhs[r, k] = total
            for m in range(6):
                total = 0.0
                for i in range(n):
                    if free[r, i]:
                        total += product[i, k] * x_coupling[r, i, m]
                body_block[r, k, m] -= total
    return failures



@njit(cache=True, error_model="numpy")
def admissible_rotation(basis, theta):
    """Projects one gripper's rotation over the step ``theta`` (3,) [rad], in place, onto the rotations its
    ``basis`` (6, 6; orthonormal columns) allows. Newton moves the body only along the basis, so a rotation it
    forbids would otherwise keep the predictor's Δt·ω_old step after step: a body that spun before planar fingers
    in two planes caught it would turn on at that rate for ever, carrying its holds (and the fingertips on them)
    around with it. Locking the rotation is the same inelastic impact that stick contact is for translation."""
    projected = np.zeros(3)
    for k in range(6):
        along = 0.0
        for i in range(3):
            along += basis[3 + i, k] * theta[i]
        for i in range(3):
            projected[i] += along * basis[3 + i, k]
    theta[:] = projected


@njit(cache=True, error_model="numpy")
def coupled_newton(q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, band_width, mass_term,
                   tolerance_inverse, free, held, offsets, projection, body, palm, c, theta, body_old, body_water,
                   basis, body_tolerance, grippers, max_iterations, converged, iterations, ratio, residual):
    """Newton's method on the rods and the free body of every gripper where ``grippers`` (B,) is True, each gripper
    on its own until it converges (see the module notes).

    Rod arrays as in :func:`~.assembly.newton_solve`; ``held`` (R, N) marks the nodes held on the body, at
    ``offsets`` (R, N, 3) from its centre in its frame; ``projection`` (R, D, 3) takes world vectors to each rod's
    coordinates. ``c`` and ``theta`` (B, 3), the body's centre and its rotation over the step, hold the start and
    receive the solution; ``body_old`` = (c_old, u_old, R_old, ω_old) at the start of the step; ``body_water``
    (B, 3) the current at each body [m/s]; ``basis`` (B, 6, 6) the body's admissible motions (zero columns unused;
    the start's rotation is projected onto them, :func:`admissible_rotation`); ``body_tolerance`` (6,) [N, N·m].
    Writes per gripper ``converged``, ``iterations`` and the largest residual ratio (B,), and every solved rod's
    final residual (R, n): on held DOFs, the reaction.
    """
    n_rods, n_nodes, stride = q.shape
    n = n_nodes * stride
    dim = water.shape[1]
    n_fingers = n_rods // c.shape[0]
    orientation_old = body_old[2]
    force = np.empty((n_nodes, stride))
    velocity = np.empty((n_nodes, dim))
    acceleration = np.empty((n_nodes, dim))
    bands = np.empty((n_fingers, n, band_width + 1))
    coupling = np.empty((n_fingers, n, 6))
    x0 = np.empty((n_fingers, n))
    x_coupling = np.empty((n_fingers, n, 6))
    block = np.empty((n_fingers, 6, 6))
    rhs = np.empty((n_fingers, 6))
    touching = np.empty(n_fingers, dtype=np.bool_)
    orientation = np.empty((3, 3))
    world = np.empty(3)
    a = np.empty(3)
    cross = np.empty((3, 3))
    own = np.empty(6)
    matrix = np.empty((6, 6))
    total = np.empty(6)
    reduced = np.empty((6, 6))
    reduced_rhs = np.empty(6)
    step = np.empty(6)
    rod_delta = np.zeros((n_fingers, n))
    rotation = np.empty((3, 3))
    for b in range(c.shape[0]):
        if not grippers[b]:
            continue
        rods = slice(b * n_fingers, (b + 1) * n_fingers)
        converged[b] = False
        iterations[b] = 0
        ratio[b] = np.inf
        halvings = 0
        admissible_rotation(basis[b], theta[b])  # Newton's start, as Newton's steps, within the basis
        for f in range(n_fingers):
            touching[f] = held[b * n_fingers + f].any()
        for it in range(max_iterations + 1):
            _turned(theta[b], orientation_old[b], rotation, orientation)
            body_residual(b, body, palm, c, theta, body_old, orientation, dt, body_water, own, matrix)
            largest = 0.0
            for f in range(n_fingers):
                r = b * n_fingers + f
                coupling[f] = 0.0
                if touching[f]:  # held nodes move with the body: x = P·(c + R·r_h); S = P·[I, −[a]×]
                    for i in range(n_nodes):
                        if not held[r, i]:
                            continue
                        for k in range(3):
                            a[k] = orientation[k, 0] * offsets[r, i, 0] + orientation[k, 1] * offsets[r, i, 1] \
                                + orientation[k, 2] * offsets[r, i, 2]
                            world[k] = c[b, k] + a[k]
                        cross[0, 0], cross[0, 1], cross[0, 2] = 0.0, -a[2], a[1]
                        cross[1, 0], cross[1, 1], cross[1, 2] = a[2], 0.0, -a[0]
                        cross[2, 0], cross[2, 1], cross[2, 2] = -a[1], a[0], 0.0
                        for d in range(dim):
                            row = stride * i + d
                            q[r, i, d] = projection[r, d, 0] * world[0] + projection[r, d, 1] * world[1] \
                                + projection[r, d, 2] * world[2]
                            for k in range(3):
                                coupling[f, row, k] = projection[r, d, k]
                                coupling[f, row, 3 + k] = -(projection[r, d, 0] * cross[0, k]
                                                            + projection[r, d, 1] * cross[1, k]
                                                            + projection[r, d, 2] * cross[2, k])
                assemble_rod(r, q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, True,
                             force, bands[f], velocity, acceleration)
                q_r = q[r].reshape(n)
                q_pred_r = q_pred[r].reshape(n)
                force_r = force.reshape(n)
                for j in range(n):
                    residual[r, j] = mass_term[j] * (q_r[j] - q_pred_r[j]) - force_r[j]
                    scaled = abs(residual[r, j]) * tolerance_inverse[r, j] if free[r, j] else 0.0
                    if not scaled <= largest:  # also catches NaN
                        largest = scaled
                    if touching[f]:  # the reactions load the body
                        for k in range(6):
                            own[k] += coupling[f, j, k] * residual[r, j]
            for k in range(6):  # the residual in the admissible motions
                total[k] = 0.0
                for i in range(6):
                    total[k] += basis[b, i, k] * own[i]
                scaled = abs(total[k]) / body_tolerance[k]
                if not scaled <= largest:
                    largest = scaled
            if largest <= 1.0:
                ratio[b] = largest
                converged[b] = True
                break
            if it > 0 and not largest < ratio[b] and halvings < MAX_STEP_HALVINGS:
                # the last step made the residual worse (a new hold far from the body can throw Newton off): go
                # back and take half of it
                halvings += 1
                for f in range(n_fingers):
                    r = b * n_fingers + f
                    q_r = q[r].reshape(n)
                    for j in range(n):
                        q_r[j] -= 0.5 ** halvings * rod_delta[f, j]
                for k in range(3):
                    c[b, k] -= 0.5 ** halvings * step[k]
                    theta[b, k] -= 0.5 ** halvings * step[3 + k]
                continue
            ratio[b] = largest
            halvings = 0
            if it == max_iterations:
                break
            for f in range(n_fingers):
                for j in range(n):
                    bands[f, j, band_width] += mass_term[j]
            block[:, :, :] = 0.0
            rhs[:, :] = 0.0
            if eliminate_rods(bands, residual[rods], coupling, free[rods], touching, x0, x_coupling, block, rhs):
                ratio[b] = np.inf
                break
            for f in range(n_fingers):
                for i in range(6):
                    for j in range(6):
                        matrix[i, j] += block[f, i, j]
            for k in range(6):  # Bᵀ·A·B δ = −Bᵀ·G + Bᵀ·Σ rhs, unused columns: identity
                used = False
                for i in range(6):
                    if basis[b, i, k] != 0.0:
                        used = True
                value = -total[k]
                for f in range(n_fingers):
                    for i in range(6):
                        value += basis[b, i, k] * rhs[f, i]
                reduced_rhs[k] = value
                for m in range(6):
                    value = 0.0
                    for i in range(6):
                        for j in range(6):
                            value += basis[b, i, k] * matrix[i, j] * basis[b, j, m]
                    reduced[k, m] = value + (1.0 if k == m and not used else 0.0)
            solution = np.linalg.solve(reduced, reduced_rhs)
            for i in range(6):
                step[i] = 0.0
                for k in range(6):
                    step[i] += basis[b, i, k] * solution[k]
            for f in range(n_fingers):
                r = b * n_fingers + f
                q_r = q[r].reshape(n)
                for j in range(n):
                    delta = 0.0
                    if free[r, j]:
                        delta = -x0[f, j]
                        if touching[f]:
                            for k in range(6):
                                delta -= x_coupling[f, j, k] * step[k]
                    rod_delta[f, j] = delta
                    q_r[j] += delta
            for k in range(3):
                c[b, k] += step[k]
                theta[b, k] += step[3 + k]
            iterations[b] += 1


@njit(cache=True, error_model="numpy")
def planar_body_basis(held, plane_normals):
    """The motions a free body held by planar fingers may make, (B, 6, 6), padded with zero columns: any
    translation; any rotation while no finger touches; while every touching finger's plane has the same normal,
    rotation about it; else none (a rotation about another axis would carry held points out of a plane the finger
    cannot leave). ``held`` (R, N) marks held nodes, ``plane_normals`` (F, 3) the fingers' planes."""
    n_fingers = plane_normals.shape[0]
    n_grippers = held.shape[0] // n_fingers
    basis = np.zeros((n_grippers, 6, 6))
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
    return basis


@njit(cache=True, error_model="numpy")
def body_in_rod_frames(c, orientation, segment_start, segment_end, radius, finger_directions, plane_normals, starts,
                       ends, radii):
    """Each gripper's free body (centre ``c`` (B, 3), ``orientation`` (B, 3, 3), segment ends in its frame (B, 3)
    each, ``radius`` (B,)) as each of its rods sees it: the segment's ends (R, D) and radius (R,), written into
    ``starts``, ``ends`` and ``radii``. In 3-D, world coordinates. A planar finger sees the section of the sphere by
    its vertical plane: a circle centred (c·d, c_z) in the plane's (s, z), of radius √(R² − (c·n)²)."""
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
                radii[r] = radius[b]
            else:
                along = 0.0
                across = 0.0
                for k in range(3):
                    along += c[b, k] * finger_directions[f, k]
                    across += c[b, k] * plane_normals[f, k]
                starts[r, 0] = ends[r, 0] = along
                starts[r, 1] = ends[r, 1] = c[b, 2]
                radii[r] = math.sqrt(max(radius[b] ** 2 - across**2, 0.0))


@njit(cache=True, error_model="numpy")
def solve_with_body(q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, band_width, mass_term,
                    tolerance_inverse, clamp_free, held, offsets, projection, body, palm, c, theta, body_old,
                    body_water, any_motion, finger_directions, plane_normals, body_tolerance, max_iterations,
                    finger_length, first_free_node, force_tolerance, max_corrector_iterations,
                    converged, iterations, ratio, residual, corrector, changed):
    """The predictor–corrector with a free body (see ``Simulator._solve_with_body``), every gripper at once.

    Solves rods and body together (:func:`coupled_newton`), then finds the holds whose normal reaction turned adhesive
    (pulling by more than ``force_tolerance`` [N]) and the free nodes that penetrate the body
    (:func:`~.contact.contact_changes`). Within ``max_corrector_iterations`` the adhesive holds are released and the
    new penetrations held, where their path entered the surface, at an offset fixed in the body's frame; after that,
    holds are only added, while nodes are inside (:func:`~.contact.corrector_continues`). Only the grippers whose
    contacts changed are solved again, from their last solution. ``q``, ``offsets`` (R, N, 3), ``c`` and ``theta``
    (B, 3) hold the start and receive the solution; ``held`` (R, N) the holds at the start. Writes per rod
    ``converged``, ``iterations``, ``ratio``, ``residual`` (R, n) (as :func:`coupled_newton`), the corrector's
    solves ``corrector`` and whether the last test still changed the rod's contacts, ``changed`` (R,).
    ``any_motion`` (B, 6, 6) is the 3-D body's basis (empty for planar fingers, whose basis depends on the holds).
    Returns the final holds (R, N), the body's orientation at the solution (B, 3, 3), and the body as each rod sees
    it there (:func:`body_in_rod_frames`: segment starts and ends (R, D))."""
    n_rods, n_nodes, stride = q.shape
    dim = water.shape[1]
    n_grippers = c.shape[0]
    n_fingers = n_rods // n_grippers
    c_old, orientation_old = body_old[0], body_old[2]
    segment_start, segment_end, radius = body[7], body[8], body[9]
    grippers = np.ones(n_grippers, dtype=np.bool_)
    gripper_converged = np.zeros(n_grippers, dtype=np.bool_)
    gripper_iterations = np.zeros(n_grippers, dtype=np.int64)
    gripper_ratio = np.full(n_grippers, np.inf)
    free = np.empty_like(clamp_free)
    orientation = np.empty((n_grippers, 3, 3))
    rotation = np.empty((3, 3))
    starts, ends, radii = np.empty((n_rods, dim)), np.empty((n_rods, dim)), np.empty(n_rods)
    shift = np.empty((n_rods, dim))
    hold_at = np.empty((n_rods, n_nodes, dim))
    new_hold = np.empty((n_rods, n_nodes), dtype=np.bool_)
    adhesive = np.empty((n_rods, n_nodes), dtype=np.bool_)
    again = np.empty(n_rods, dtype=np.bool_)
    positions, old_positions = q[:, :, :dim], q_old[:, :, :dim]
    corrector[:] = 0
    for k in range(max_corrector_iterations + n_nodes + 1):  # holds-only solves end by N
        free[:, :] = clamp_free
        release_held(free, held, dim)
        basis = any_motion if dim == 3 else planar_body_basis(held, plane_normals)
        coupled_newton(q, q_old, q_pred, natural_curvature, water, dt, elastic, frames, terms, band_width, mass_term,
                       tolerance_inverse, free, held, offsets, projection, body, palm, c, theta, body_old, body_water,
                       basis, body_tolerance, grippers, max_iterations, gripper_converged, gripper_iterations,
                       gripper_ratio, residual)
        for b in range(n_grippers):
            _turned(theta[b], orientation_old[b], rotation, orientation[b])
        body_in_rod_frames(c, orientation, segment_start, segment_end, radius, finger_directions, plane_normals,
                           starts, ends, radii)
        for r in range(n_rods):
            b = r // n_fingers
            for d in range(dim):
                shift[r, d] = projection[r, d, 0] * (c[b, 0] - c_old[b, 0]) \
                    + projection[r, d, 1] * (c[b, 1] - c_old[b, 1]) + projection[r, d, 2] * (c[b, 2] - c_old[b, 2])
        searched = within_reach(starts, ends, radii, finger_length)
        contact_changes(positions, old_positions, residual, held, starts, ends, radii, searched, shift,
                        first_free_node, force_tolerance, adhesive, new_hold, hold_at, changed)
        within_budget = k < max_corrector_iterations
        if not corrector_continues(within_budget, new_hold, changed, again):
            break
        # the offset of a new hold, in the body's frame at the end of this solve
        for r in range(n_rods):
            b = r // n_fingers
            for i in range(n_nodes):
                if not new_hold[r, i]:
                    continue
                for m in range(3):
                    value = 0.0
                    for j in range(3):
                        world = 0.0
                        for d in range(dim):
                            world += projection[r, d, j] * hold_at[r, i, d]
                        value += orientation[b, j, m] * (world - c[b, j])
                    offsets[r, i, m] = value
        update_holds(within_budget, held, adhesive, new_hold)
        for r in range(n_rods):
            if again[r]:
                corrector[r] += 1
        for b in range(n_grippers):
            grippers[b] = again[b * n_fingers: (b + 1) * n_fingers].any()
    for r in range(n_rods):
        b = r // n_fingers
        converged[r] = gripper_converged[b]
        iterations[r] = gripper_iterations[b]
        ratio[r] = gripper_ratio[b]
    return held, orientation, starts, ends
