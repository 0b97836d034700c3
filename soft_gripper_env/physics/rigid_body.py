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

from .forces import Buoyancy, Gravity
from .hydrodynamics import AddedMass, MorisonDrag
from .linalg import factor_banded_symmetric, solve_factored

SPHERE_DRAG_COEFFICIENT = 0.47
"""C_d of a sphere at Re ≈ 10³–10⁵ (dimensionless)."""
SPHERE_ADDED_MASS_COEFFICIENT = 0.5
"""C_a of a sphere (dimensionless): its added mass is half the displaced fluid's."""


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

    def residual(self, c, c_old, u_old, theta, w_old, orientation, orientation_old, dt, water_velocity):
        """The body's own residual (B, 6) (inertia minus external loads), and the diagonal blocks of its Jacobian
        for translation and rotation, (B, 3, 3) each. ``orientation`` is the end-of-step R, (B, 3, 3);
        ``water_velocity`` the current at each body (B, 3) [m/s]."""
        u = (c - c_old) / dt
        # translational inertia with the start-of-step orientation, as for the rods' added mass
        mass = self.mass[:, None, None] * np.eye(3) + orientation_old @ self.added_mass @ orientation_old.transpose(
            0, 2, 1)
        force = np.zeros_like(c)
        force[:, 2] -= self.weight
        jacobian = mass / dt**2
        w = u - water_velocity
        axis = np.einsum("bij,bj->bi", orientation, self.axis)
        for coefficient, normal_only in ((self.isotropic_drag, False), (self.normal_drag, True)):
            if not coefficient.any():
                continue
            part = w - np.sum(w * axis, axis=1, keepdims=True) * axis if normal_only else w
            speed = np.linalg.norm(part, axis=1, keepdims=True)
            force -= coefficient[:, None] * speed * part
            projector = np.eye(3) - axis[:, :, None] * axis[:, None, :] if normal_only else np.eye(3)
            safe = np.where(speed > 0, speed, 1.0)
            jacobian = jacobian + (coefficient / dt)[:, None, None] * (
                speed[..., None] * projector + part[:, :, None] * part[:, None, :] / safe[..., None])
        if self.palm_stiffness:
            push, stiffness = self._palm(c, u, orientation, mass[:, 2, 2], dt)
            force[:, 2] -= push
            jacobian[:, 2, 2] += stiffness
        inertia_new = orientation @ self.inertia @ orientation.transpose(0, 2, 1)
        inertia_old = orientation_old @ self.inertia @ orientation_old.transpose(0, 2, 1)
        momentum_change = (np.einsum("bij,bj->bi", inertia_new, theta / dt)
                           - np.einsum("bij,bj->bi", inertia_old, w_old)) / dt
        residual = np.concatenate([np.einsum("bij,bj->bi", mass, c - c_old - dt * u_old) / dt**2 - force,
                                   momentum_change], axis=1)
        return residual, jacobian, inertia_new / dt**2


    def palm_reaction(self, c, c_old, orientation, orientation_old, dt) -> np.ndarray:
        """The force of each body on the palm [N], (B, 3), over a step from ``c_old`` to ``c`` of ``dt`` [s]."""
        vertical_mass = self.mass + np.einsum("bi,bij,bj->b", orientation_old[:, 2], self.added_mass,
                                              orientation_old[:, 2])
        reaction = np.zeros_like(c)
        if self.palm_stiffness:
            reaction[:, 2] = self._palm(c, (c - c_old) / dt, orientation, vertical_mass, dt)[0]
        return reaction

    def _palm(self, c, u, orientation, vertical_mass, dt):
        """The palm's push down on each body [N] (B,), k·overlap + critical damping 2·√(k·M)·v_z where the body
        rises above the disc (its highest end sphere counts), and the push's derivative by the body's height over
        the step [N/m], (B,)."""
        ends = [c + np.einsum("bij,bj->bi", orientation, end) for end in self.segment]
        end = np.where((ends[0][:, 2] >= ends[1][:, 2])[:, None], ends[0], ends[1])
        outside = np.maximum(np.hypot(end[:, 0], end[:, 1]) - self.palm_radius, 0.0)  # past the disc's rim
        reach = np.sqrt(np.maximum(self.radius**2 - outside**2, 0.0))
        top = end[:, 2] + reach
        touching = (top > 0.0) & (outside < self.radius)
        damping = 2.0 * np.sqrt(self.palm_stiffness * vertical_mass)
        return (touching * (self.palm_stiffness * top + damping * u[:, 2]),
                touching * (self.palm_stiffness + damping / dt))


def rotation_exp(theta: np.ndarray) -> np.ndarray:
    """Rotation matrices exp([θ]×) of rotation vectors (B, 3) [rad], by Rodrigues' formula."""
    angle = np.linalg.norm(theta, axis=1)
    k = np.zeros((len(theta), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -theta[:, 2], theta[:, 1], -theta[:, 0]
    k = k - k.transpose(0, 2, 1)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    a = np.where(small, 1.0 - angle**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - angle**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a[:, None, None] * k + b[:, None, None] * (k @ k)


@njit(cache=True, error_model="numpy")
def eliminate_rods(band, residual, coupling, free, active, coupled, x0, x_coupling, body_block, body_rhs):
    """Eliminates each active rod's free DOFs from the coupled Newton system.

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
        if not active[r]:
            continue
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
