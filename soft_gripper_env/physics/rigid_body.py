"""A free rigid sphere moved by the fingers' contact reactions, coupled implicitly to them.

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
I         rotational inertia of a solid sphere, ⅖·m·R²                      kg·m²
========  ================================================================  ==========

Backward Euler for the body, M_t·(c − c_old − Δt·u_old)/Δt² = F_ext(u) − Σ_h R_h and
I·(θ − Δt·ω_old)/Δt² = −Σ_h a_h × R_h, where R_h is the reaction of the body on held node h (the node's residual)
and held nodes move with the body, x_h = c + a_h. Rods and body are solved together by Newton's method: the rods'
free DOFs are eliminated rod by rod (one banded factorisation, seven right-hand sides), which leaves a 6×6 system
for the body per gripper (a Schur complement). A staggered scheme, which would move the body with last iteration's
reactions, is unstable for a body as light as the water it displaces; this one is not.

External loads come from the scene's own force models: gravity from :class:`~.forces.Gravity`, buoyancy from
:class:`~.forces.Buoyancy`, quadratic drag ½·ρ_w·C_d·π·R²·|w|·w (C_d = 0.47, a sphere at Re ≈ 10³–10⁵) on the
velocity relative to the current when :class:`~.hydrodynamics.MorisonDrag` is present, and added mass C_a = 0.5
when :class:`~.hydrodynamics.AddedMass` is. The torque of the water on a spinning sphere is neglected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from .forces import Buoyancy, Gravity
from .hydrodynamics import AddedMass, Current, MorisonDrag
from .linalg import factor_banded_symmetric, solve_factored

SPHERE_DRAG_COEFFICIENT = 0.47
"""C_d of a sphere at Re ≈ 10³–10⁵ (dimensionless)."""
SPHERE_ADDED_MASS_COEFFICIENT = 0.5
"""C_a of a sphere (dimensionless): its added mass is half the displaced fluid's."""


@dataclass(frozen=True, eq=False)
class BodyModel:
    """Mass properties and external loads of a free sphere in a scene."""

    mass: float
    """m [kg]."""
    translational_inertia: float
    """M_t = m + added mass [kg]."""
    rotational_inertia: float
    """⅖·m·R² [kg·m²]."""
    weight: float
    """Net weight along −z, (m − ρ_w·V)·g [N]."""
    drag: float
    """½·ρ_w·C_d·π·R² [kg/m]; 0 without Morison drag."""
    current: Current | None

    @classmethod
    def from_scene(cls, sphere, forces) -> BodyModel:
        volume = 4.0 / 3.0 * math.pi * sphere.radius**3
        mass = sphere.density * volume
        gravity = sum(f.acceleration for f in forces if isinstance(f, Gravity))
        buoyancy = sum(f.fluid_density * f.acceleration * volume for f in forces if isinstance(f, Buoyancy))
        added = sum(SPHERE_ADDED_MASS_COEFFICIENT * f.fluid_density * volume for f in forces
                    if isinstance(f, AddedMass))
        morison = [f for f in forces if isinstance(f, MorisonDrag)]
        drag = sum(0.5 * f.fluid_density * SPHERE_DRAG_COEFFICIENT * math.pi * sphere.radius**2 for f in morison)
        return cls(mass=mass, translational_inertia=mass + added, rotational_inertia=0.4 * mass * sphere.radius**2,
                   weight=mass * gravity - buoyancy, drag=drag, current=morison[0].current if morison else None)

    def residual(self, c, c_old, u_old, theta, w_old, dt, time):
        """The body's own residual (B, 6) (inertia minus external loads) and the diagonal blocks of its Jacobian,
        (B, 3, 3) for translation and a scalar for rotation."""
        u = (c - c_old) / dt
        force = np.zeros_like(c)
        force[:, 2] -= self.weight
        jacobian = np.broadcast_to(np.eye(3) * self.translational_inertia / dt**2, c.shape[:1] + (3, 3)).copy()
        if self.drag:
            w = u - (self.current.at(time) if self.current is not None else 0.0)
            speed = np.linalg.norm(w, axis=1, keepdims=True)
            force -= self.drag * speed * w
            safe = np.where(speed > 0, speed, 1.0)
            outer = w[:, :, None] * w[:, None, :] / safe[..., None]
            jacobian += self.drag / dt * (speed[..., None] * np.eye(3) + outer)
        residual = np.concatenate([self.translational_inertia * (c - c_old - dt * u_old) / dt**2 - force,
                                   self.rotational_inertia * (theta - dt * w_old) / dt**2], axis=1)
        return residual, jacobian, self.rotational_inertia / dt**2


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


@njit(cache=True)
def eliminate_rods(band, residual, coupling, free, active, x0, x_coupling, body_block, body_rhs):
    """Eliminates each active rod's free DOFs from the coupled Newton system.

    ``band`` (R, n, kd+1): the rod's Newton matrix A (overwritten by its factors); ``residual`` (R, n): G;
    ``coupling`` (R, n, 6): S, the motion of each held DOF per unit body motion (zero on other DOFs); ``free``
    (R, n): the DOFs solved for. Writes x0 = A_FF⁻¹·G_F (R, n), X = A_FF⁻¹·(A·S)_F (R, n, 6), the rod's part of the
    body's matrix Sᵀ·A·S − (A·S)_Fᵀ·X into ``body_block`` (R, 6, 6), and (A·S)_Fᵀ·x0 into ``body_rhs`` (R, 6).
    Returns the number of rods whose factorisation failed.
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
