"""External force models: each one adds its generalized force and its Jacobian to the implicit system.

Every model implements :meth:`ForceModel.accumulate`. The simulator sums the models a scene lists, and nothing else:
a scene without drag pays nothing for drag. Arrays follow the layout of :class:`~.discretization.Discretization`:

=================  ===============================================================  ============
name               meaning                                                          shape
=================  ===============================================================  ============
``positions``      node positions, planar (s, z) or 3-D (x, y, z) [m]               (R, N, D)
``velocities``     node velocities [m/s]                                            (R, N, D)
``accelerations``  node accelerations [m/s²]                                        (R, N, D)
``force``          generalized force, accumulated into [N]                          (R, N, D)
``system_band``    band of the Newton matrix (see ``linalg``), accumulated into     (R, n, kd+1)
=================  ===============================================================  ============

R counts rods (batch × fingers, finger index = r mod F), N nodes, D = 2 (planar) or 3, n the DOFs per rod. A model
adds its force f to ``force`` and −(∂f/∂q + ∂f/∂v·∂v/∂q + ∂f/∂a·∂a/∂q) to ``system_band``. The integrator supplies
∂v/∂q and ∂a/∂q in the :class:`StepContext` (1/Δt and 1/Δt² for backward Euler), so models need not know which
integrator runs them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from .validation import check_range

if TYPE_CHECKING:
    from .discretization import Discretization


def _check_positive(owner: str, name: str, value: float, unit: str, allow_zero: bool = True) -> None:
    check_range(owner, name, value, unit, 0.0, low_inclusive=allow_zero)


@dataclass(frozen=True, eq=False)
class StepContext:
    """What the integrator tells the force models about the step being solved."""

    time: float
    """Time at the start of the step [s]."""
    start_positions: np.ndarray
    """Node positions at the start of the step [m], (R, N, D)."""
    velocity_derivative: float
    """∂v/∂q of the integrator [1/s]."""
    acceleration_derivative: float
    """∂a/∂q of the integrator [1/s²]."""
    water_velocity: np.ndarray | None = None
    """The water's velocity at every rod in its coordinates [m/s], (R, D): the simulator fills it from each
    gripper's own current. None (a model evaluated on its own) means the model's own current."""


class ForceModel:
    """Interface of every external force. Subclasses are frozen dataclasses holding their parameters in SI units."""

    def accumulate(self, disc: Discretization, ctx: StepContext, positions: np.ndarray, velocities: np.ndarray,
                   accelerations: np.ndarray, force: np.ndarray, system_band: np.ndarray) -> None:
        """Add this model's force [N] to ``force`` and its negated Jacobian to ``system_band``."""
        raise NotImplementedError

    def potential_energy(self, disc: Discretization, positions: np.ndarray) -> np.ndarray | None:
        """Potential energy of a conservative force per rod [J], (R,); None for a force that has none."""
        return None


@dataclass(frozen=True)
class Gravity(ForceModel):
    """Weight of every node, m_i·g along −z. Position-independent, so its Jacobian is zero."""

    acceleration: float = 9.81
    """Gravitational acceleration g [m/s²]."""

    def __post_init__(self) -> None:
        _check_positive("Gravity", "acceleration", self.acceleration, "m/s²")

    def accumulate(self, disc, ctx, positions, velocities, accelerations, force, system_band):
        force[..., disc.vertical_axis] -= disc.node_mass * self.acceleration

    def potential_energy(self, disc, positions):
        return positions[..., disc.vertical_axis] @ (disc.node_mass * self.acceleration)


@dataclass(frozen=True)
class Buoyancy(ForceModel):
    """Archimedes' lift of every submerged node, ρ_fluid·V_i·g along +z (V_i the node's lumped volume)."""

    fluid_density: float = 1000.0
    """Density of the surrounding fluid ρ_fluid [kg/m³]; zero in the paper's scene."""
    acceleration: float = 9.81
    """Gravitational acceleration g [m/s²]; must match the scene's :class:`Gravity`."""

    def __post_init__(self) -> None:
        _check_positive("Buoyancy", "fluid_density", self.fluid_density, "kg/m³")
        _check_positive("Buoyancy", "acceleration", self.acceleration, "m/s²")

    def accumulate(self, disc, ctx, positions, velocities, accelerations, force, system_band):
        force[..., disc.vertical_axis] += disc.node_volume * (self.fluid_density * self.acceleration)

    def potential_energy(self, disc, positions):
        return -positions[..., disc.vertical_axis] @ (disc.node_volume * (self.fluid_density * self.acceleration))


@dataclass(frozen=True)
class StokesDrag(ForceModel):
    """The paper's per-node Stokes drag f_i = −6π·r_i·η·v_i (each node treated as a sphere of the rod's radius).

    A low-Reynolds law, kept for reproducing the paper; at water's viscosity it is negligible (physics.md §3).
    ``nodes`` restricts it to some nodes: the paper's published curves came from η = 1000 Pa·s acting on nodes 2–4
    only (physics.md §2), which ``StokesDrag(viscosity=1000.0, nodes=(2, 3, 4))`` reproduces.
    """

    viscosity: float = 1.0e-3
    """Dynamic viscosity η [Pa·s]."""
    nodes: tuple[int, ...] | None = None
    """Indices of the nodes it acts on; None for every node."""

    def __post_init__(self) -> None:
        _check_positive("StokesDrag", "viscosity", self.viscosity, "Pa·s")
        if self.nodes is not None:
            nodes = tuple(self.nodes)
            if not nodes or any(not isinstance(i, (int, np.integer)) or i < 0 for i in nodes):
                raise ValueError(f"StokesDrag.nodes = {self.nodes!r} must be None or non-negative node indices")
            object.__setattr__(self, "nodes", nodes)

    def check_nodes(self, n_nodes: int) -> None:
        """Raise ValueError if ``nodes`` names a node beyond a finger of ``n_nodes`` nodes."""
        if self.nodes is not None and max(self.nodes) >= n_nodes:
            raise ValueError(f"StokesDrag.nodes = {self.nodes!r} names node {max(self.nodes)}; the finger has nodes "
                             f"0 … {n_nodes - 1}")

    def accumulate(self, disc, ctx, positions, velocities, accelerations, force, system_band):
        coefficient = 6.0 * math.pi * self.viscosity * disc.node_radius  # [N·s/m], shape (N,)
        if self.nodes is not None:
            selected = np.zeros_like(coefficient)
            selected[list(self.nodes)] = coefficient[list(self.nodes)]
            coefficient = selected
        _add_linear_damping(disc, coefficient, velocities, force, system_band, ctx.velocity_derivative)


@dataclass(frozen=True)
class MassProportionalDamping(ForceModel):
    """Linear damping f_i = −γ·m_i·v_i on every node, a numerical damping used by benchmarks."""

    rate: float = 10.0
    """Damping rate γ [1/s]."""

    def __post_init__(self) -> None:
        _check_positive("MassProportionalDamping", "rate", self.rate, "1/s")

    def accumulate(self, disc, ctx, positions, velocities, accelerations, force, system_band):
        _add_linear_damping(disc, self.rate * disc.node_mass, velocities, force, system_band,
                            ctx.velocity_derivative)


def _add_linear_damping(disc: Discretization, coefficient: np.ndarray, velocities: np.ndarray, force: np.ndarray,
                        system_band: np.ndarray, velocity_derivative: float) -> None:
    """f = −c_i·v_i per node, isotropic; Jacobian −c_i·∂v/∂q on the diagonal."""
    linear_damping(coefficient, velocities, velocity_derivative, disc.stride, force, system_band)


@njit(cache=True, error_model="numpy")
def linear_damping(coefficient, velocities, velocity_derivative, stride, force, band):
    """Adds −c_i·v_i to ``force`` (R, N, D) and c_i·∂v/∂q to the position diagonal of ``band`` (R, n, kd+1)."""
    n_rods, n_nodes, dim = velocities.shape
    kd = band.shape[2] - 1
    for r in range(n_rods):
        for i in range(n_nodes):
            c = coefficient[i]
            for k in range(dim):
                force[r, i, k] -= c * velocities[r, i, k]
                band[r, stride * i + k, kd] += c * velocity_derivative


__all__ = ["ForceModel", "StepContext", "Gravity", "Buoyancy", "StokesDrag", "MassProportionalDamping"]
