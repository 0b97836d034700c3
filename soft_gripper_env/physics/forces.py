"""External force models: each one declares the terms it adds to the implicit system.

A model's :meth:`ForceModel.terms` gives its coefficients; :class:`ForceTerms` sums the models a scene lists into
one set of per-node and per-edge arrays, which the compiled assembly (:mod:`.assembly`) evaluates together with
the elastic forces. A term no model gives is an empty array and costs nothing: a scene without drag pays nothing
for drag.

==================  =====================================================  =========  ========
term                force on the rod                                       unit       shape
==================  =====================================================  =========  ========
``node_force``      a constant force per node (weight, buoyancy)            N          (N, D)
``damping``         −c_i·v_i, linear and isotropic per node                 N·s/m      (N,)
``drag_normal``     Morison drag per edge, ½·ρ_w·C_n·D·l̄ (hydrodynamics)    kg/m       (N − 1,)
``drag_tangential`` its tangential part, ½·ρ_w·C_t·π·D·l̄                    kg/m       (N − 1,)
``added_mass``      the water an edge carries normal to itself              kg         (N − 1,)
==================  =====================================================  =========  ========

:meth:`ForceModel.accumulate` evaluates one model alone through the same kernel, with the array layout of
:class:`~.discretization.Discretization`:

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

    def terms(self, disc: Discretization) -> dict[str, np.ndarray]:
        """This model's terms, by the names of :class:`ForceTerms`' fields."""
        raise NotImplementedError

    def accumulate(self, disc: Discretization, ctx: StepContext, positions: np.ndarray, velocities: np.ndarray,
                   accelerations: np.ndarray, force: np.ndarray, system_band: np.ndarray) -> None:
        """Add this model's force [N] to ``force`` and its negated Jacobian to ``system_band`` (evaluated alone,
        through the kernel the simulator runs)."""
        from .assembly import external_forces  # the assembly imports every model's kernels

        water = ctx.water_velocity
        if water is None:
            water = self.standalone_water_velocity(disc, ctx.time, positions.shape[0])
        external_forces(positions, ctx.start_positions, velocities, accelerations, water,
                        ForceTerms.of(disc, (self,)).arrays(), ctx.velocity_derivative, ctx.acceleration_derivative,
                        disc.stride, force, system_band)

    def standalone_water_velocity(self, disc: Discretization, time: float, n_rods: int) -> np.ndarray:
        """The water's velocity at every rod (R, D) [m/s] when the model is evaluated on its own: still water."""
        return np.zeros((n_rods, disc.dim))

    def potential_energy(self, disc: Discretization, positions: np.ndarray) -> np.ndarray | None:
        """Potential energy of a conservative force per rod [J], (R,); None for a force that has none."""
        return None


@dataclass(frozen=True, eq=False)
class ForceTerms:
    """The summed terms of a scene's force models (see the module notes); an absent term is an empty array."""

    node_force: np.ndarray
    """Constant force per node [N], (N, D)."""
    damping: np.ndarray
    """Linear damping coefficient per node [N·s/m], (N,)."""
    drag_normal: np.ndarray
    """½·ρ_w·C_n·D·l̄ per edge [kg/m], (N − 1,)."""
    drag_tangential: np.ndarray
    """½·ρ_w·C_t·π·D·l̄ per edge [kg/m], (N − 1,)."""
    added_mass: np.ndarray
    """Added mass of each edge for motion normal to it [kg], (N − 1,)."""

    @classmethod
    def of(cls, disc: Discretization, models) -> ForceTerms:
        parts = [model.terms(disc) for model in models]

        def total(name: str, ndim: int) -> np.ndarray:
            given = [part[name] for part in parts if name in part]
            return np.ascontiguousarray(sum(given[1:], given[0]), dtype=float) if given else np.zeros((0,) * ndim)

        return cls(node_force=total("node_force", 2), damping=total("damping", 1),
                   drag_normal=total("drag_normal", 1), drag_tangential=total("drag_tangential", 1),
                   added_mass=total("added_mass", 1))

    def arrays(self) -> tuple[np.ndarray, ...]:
        """The terms in the order the compiled kernels take them."""
        return self.node_force, self.damping, self.drag_normal, self.drag_tangential, self.added_mass


@dataclass(frozen=True)
class Gravity(ForceModel):
    """Weight of every node, m_i·g along −z. Position-independent, so its Jacobian is zero."""

    acceleration: float = 9.81
    """Gravitational acceleration g [m/s²]."""

    def __post_init__(self) -> None:
        _check_positive("Gravity", "acceleration", self.acceleration, "m/s²")

    def terms(self, disc):
        return {"node_force": _vertical(disc, -disc.node_mass * self.acceleration)}

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

    def terms(self, disc):
        return {"node_force": _vertical(disc, disc.node_volume * (self.fluid_density * self.acceleration))}

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

    def terms(self, disc):
        coefficient = 6.0 * math.pi * self.viscosity * disc.node_radius  # [N·s/m], shape (N,)
        if self.nodes is not None:
            selected = np.zeros_like(coefficient)
            selected[list(self.nodes)] = coefficient[list(self.nodes)]
            coefficient = selected
        return {"damping": coefficient}


@dataclass(frozen=True)
class MassProportionalDamping(ForceModel):
    """Linear damping f_i = −γ·m_i·v_i on every node, a numerical damping used by benchmarks."""

    rate: float = 10.0
    """Damping rate γ [1/s]."""

    def __post_init__(self) -> None:
        _check_positive("MassProportionalDamping", "rate", self.rate, "1/s")

    def terms(self, disc):
        return {"damping": self.rate * disc.node_mass}


def _vertical(disc: Discretization, value: np.ndarray) -> np.ndarray:
    """A per-node force (N, D) [N] of vertical component ``value`` (N,)."""
    force = np.zeros((disc.n_nodes, disc.dim))
    force[:, disc.vertical_axis] = value
    return force


@njit(cache=True, error_model="numpy")
def linear_damping(coefficient, velocities, velocity_derivative, stride, force, band):
    """Adds −c_i·v_i to one rod's ``force`` (N, D) and c_i·∂v/∂q to the position diagonal of its ``band``
    (n, kd+1)."""
    n_nodes, dim = velocities.shape
    kd = band.shape[1] - 1
    for i in range(n_nodes):
        c = coefficient[i]
        for k in range(dim):
            force[i, k] -= c * velocities[i, k]
            band[stride * i + k, kd] += c * velocity_derivative


__all__ = ["ForceModel", "ForceTerms", "StepContext", "Gravity", "Buoyancy", "StokesDrag", "MassProportionalDamping"]
