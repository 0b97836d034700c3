"""Water acting on the fingers: Morison-type strip theory per edge, added mass, and uniform currents.

A finger 2–4 cm across moving at 0.05–1 m/s in water works at Re ≈ 10³–10⁴, where drag is quadratic in the
velocity relative to the water and the water entrained by the finger adds inertia (physics.md §3). Per edge of
diameter D = 2r (r the mean radius of its nodes) and rest length l̄, with t the edge tangent and w the velocity of
the edge (mean of its nodes) relative to the water:

==========================  ===========================================================  =======
term                        force on the edge                                            unit
==========================  ===========================================================  =======
normal drag                 −½·ρ_w·C_n·D·l̄·|w_n|·w_n,  w_n = (I − t tᵀ)·w                 N
tangential (skin) drag      −½·ρ_w·C_t·π·D·l̄·|w_t|·w_t,  w_t = (t·w)·t                    N
added mass                  −C_a·ρ_w·(π·D²/4)·l̄·(I − t tᵀ)·a                              N
==========================  ===========================================================  =======

Each edge force is shared equally by its two nodes. Both models enter the implicit solve with their Jacobians with
respect to the velocity and the acceleration, which are exact and symmetric. Two approximations keep the Newton
matrix symmetric. First, the added-mass matrix uses each edge's tangent at the start of the step. Second, the
drag's dependence on the tangent turning within a step is left out of the Newton matrix, though not out of the force.
Newton still converges in a few iterations (tests/physics/test_water.py).

In the planar model each finger sees the current's component in its own vertical plane; the component across the
plane would push a finger that cannot move that way, so it is dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from .forces import Buoyancy, ForceModel, StokesDrag, _check_positive
from .validation import check_range

if TYPE_CHECKING:
    from .discretization import Discretization

WATER_DENSITY = 1000.0
"""Density of fresh water [kg/m³] (sea water is about 1025)."""


@dataclass(frozen=True)
class Current:
    """A uniform water current u(t) = velocity + oscillation·sin(2π·t/period + phase) [m/s], world frame."""

    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Mean current [m/s]."""
    oscillation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Amplitude of the oscillating part [m/s]."""
    period: float = 1.0
    """Period of the oscillating part [s]."""
    phase: float = 0.0
    """Phase of the oscillating part at t = 0 [rad]."""

    def __post_init__(self) -> None:
        for name in ("velocity", "oscillation"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3:
                raise ValueError(f"Current.{name} = {getattr(self, name)!r} must have 3 components [m/s]")
            for v in value:
                check_range("Current", name, v, "m/s", -100.0, 100.0, low_inclusive=True)
            object.__setattr__(self, name, value)
        check_range("Current", "period", self.period, "s", 0.0)
        check_range("Current", "phase", self.phase, "rad", -1e3, 1e3, low_inclusive=True)

    def at(self, time: float) -> np.ndarray:
        """Current velocity at ``time`` [m/s], (3,)."""
        return CurrentBatch.of((self,)).at(time)[0]


class CurrentBatch:
    """The currents of a batch of grippers, as arrays: mean and amplitude (B, 3) [m/s], period (B,) [s], phase (B,)
    [rad], and the batch time at which each gripper's own clock reads 0 (B,) [s]. A gripper's entry is replaced with
    :meth:`load`."""

    def __init__(self, batch_size: int) -> None:
        self.velocity = np.zeros((batch_size, 3))
        self.oscillation = np.zeros((batch_size, 3))
        self.period = np.ones(batch_size)
        self.phase = np.zeros(batch_size)
        self.start_time = np.zeros(batch_size)

    @classmethod
    def of(cls, currents) -> CurrentBatch:
        batch = cls(len(currents))
        for index, current in enumerate(currents):
            batch.load(index, current)
        return batch

    def load(self, index: int, current: Current) -> None:
        self.velocity[index] = current.velocity
        self.oscillation[index] = current.oscillation
        self.period[index] = current.period
        self.phase[index] = current.phase

    def at(self, time: float) -> np.ndarray:
        """The water's velocity at every gripper at ``time`` [m/s], (B, 3)."""
        angle = 2 * math.pi * (time - self.start_time) / self.period + self.phase
        return self.velocity + self.oscillation * np.sin(angle)[:, None]


def rod_water_velocity(disc: Discretization, water_velocity: np.ndarray) -> np.ndarray:
    """The water's velocity per gripper (B, 3) as each rod sees it, (R, D) [m/s]: world (3-D) or in the finger's
    vertical plane (planar; the component across the plane would push a finger that cannot move that way)."""
    if disc.dim == 3:
        return np.repeat(water_velocity, len(disc.finger_directions), axis=0)
    rods = np.empty((len(water_velocity), len(disc.finger_directions), 2))
    rods[..., 0] = water_velocity @ disc.finger_directions.T
    rods[..., 1] = water_velocity[:, 2:3]
    return rods.reshape(-1, 2)


def _edge_diameter(disc: Discretization) -> np.ndarray:
    return disc.node_radius[:-1] + disc.node_radius[1:]


@dataclass(frozen=True)
class MorisonDrag(ForceModel):
    """Quadratic normal and tangential drag per edge, on the velocity relative to the water (see module notes)."""

    normal_coefficient: float = 1.2
    """C_n, dimensionless; 1.0–1.2 for a circular cylinder at Re ≈ 10³–10⁴ (physics.md §3)."""
    tangential_coefficient: float = 0.01
    """C_t on the wetted perimeter π·D, dimensionless. The skin-friction coefficient of a long cylinder in axial
    flow; line-dynamics practice uses about 0.008–0.01 (e.g. the axial drag coefficient of offshore mooring
    codes), about 1/100 of the normal drag per unit area."""
    fluid_density: float = WATER_DENSITY
    """ρ_w [kg/m³]."""
    current: Current = field(default_factory=Current)

    def __post_init__(self) -> None:
        _check_positive("MorisonDrag", "normal_coefficient", self.normal_coefficient, "(dimensionless)")
        _check_positive("MorisonDrag", "tangential_coefficient", self.tangential_coefficient, "(dimensionless)")
        _check_positive("MorisonDrag", "fluid_density", self.fluid_density, "kg/m³")
        if not isinstance(self.current, Current):
            raise ValueError(f"MorisonDrag.current must be a Current, got {type(self.current).__name__}")

    def terms(self, disc):
        """½·ρ_w·C_n·D·l̄ and ½·ρ_w·C_t·π·D·l̄ of every edge [kg/m], (N − 1,) each."""
        half_density_area = 0.5 * self.fluid_density * _edge_diameter(disc) * disc.rest_edge_length
        return {"drag_normal": half_density_area * self.normal_coefficient,
                "drag_tangential": half_density_area * (math.pi * self.tangential_coefficient)}

    def standalone_water_velocity(self, disc, time, n_rods):
        """The model's own current at every rod (R, D) [m/s]."""
        n_grippers = n_rods // len(disc.finger_directions)
        return rod_water_velocity(disc, np.tile(self.current.at(time), (n_grippers, 1)))


@dataclass(frozen=True)
class AddedMass(ForceModel):
    """The inertia of the water a finger carries along: C_a·ρ_w·(π·D²/4) per unit length on normal accelerations."""

    coefficient: float = 1.0
    """C_a, dimensionless; 1 for a circular cylinder."""
    fluid_density: float = WATER_DENSITY
    """ρ_w [kg/m³]."""

    def __post_init__(self) -> None:
        _check_positive("AddedMass", "coefficient", self.coefficient, "(dimensionless)")
        _check_positive("AddedMass", "fluid_density", self.fluid_density, "kg/m³")

    def terms(self, disc):
        """Added mass of each edge for motion normal to it [kg], (N − 1,)."""
        return {"added_mass": self.coefficient * self.fluid_density * math.pi / 4 * _edge_diameter(disc) ** 2
                * disc.rest_edge_length}


@njit(cache=True, error_model="numpy")
def _add_edge_block(band_r, stride, i, dim, block, scale):
    """Add scale·[[B, B], [B, B]] over the position DOFs of nodes i and i+1 to one rod's band (lower part)."""
    kd = band_r.shape[1] - 1
    for a in range(dim):
        for b in range(dim):
            value = scale * block[a, b]
            row_i = stride * i + a
            col_i = stride * i + b
            row_j = row_i + stride
            col_j = col_i + stride
            if row_i >= col_i:
                band_r[row_i, kd - row_i + col_i] += value
                band_r[row_j, kd - row_j + col_j] += value
            band_r[row_j, kd - row_j + col_i] += value


@njit(cache=True, error_model="numpy")
def _edge_tangent(positions, e, t):
    """Writes the unit tangent of edge e of one rod (positions (N, D)) into ``t`` (D,)."""
    length2 = 0.0
    for k in range(t.size):
        t[k] = positions[e + 1, k] - positions[e, k]
        length2 += t[k] * t[k]
    inverse_length = 1.0 / math.sqrt(length2)
    for k in range(t.size):
        t[k] *= inverse_length


@njit(cache=True, error_model="numpy")
def morison_drag(positions, velocities, current, normal, tangential, velocity_derivative, stride, force, band):
    """Morison drag of every edge of one rod: adds the force to ``force`` (N, D) and its velocity Jacobian to
    ``band`` (n, kd+1).

    ``normal``, ``tangential``: ½·ρ_w·C·D·l̄ per edge [kg/m] (the tangential one with π·D); ``current`` (D,).
    """
    n_nodes, dim = positions.shape
    t = np.empty(dim)
    w = np.empty(dim)
    wn = np.empty(dim)
    block = np.empty((dim, dim))
    for e in range(n_nodes - 1):
        _edge_tangent(positions, e, t)
        s = 0.0
        for k in range(dim):
            w[k] = 0.5 * (velocities[e, k] + velocities[e + 1, k]) - current[k]
            s += w[k] * t[k]
        speed_n2 = 0.0
        for k in range(dim):
            wn[k] = w[k] - s * t[k]
            speed_n2 += wn[k] * wn[k]
        speed_n = math.sqrt(speed_n2)
        cn = normal[e]
        ct = tangential[e]
        for k in range(dim):
            f = -cn * speed_n * wn[k] - ct * abs(s) * s * t[k]
            force[e, k] += 0.5 * f
            force[e + 1, k] += 0.5 * f
        # ∂(edge force)/∂w = −[C_n·(|w_n|·P + w_n w_nᵀ/|w_n|) + 2·C_t·|s|·t tᵀ], P = I − t tᵀ
        for a in range(dim):
            for b in range(dim):
                projector = (1.0 if a == b else 0.0) - t[a] * t[b]
                value = cn * speed_n * projector + 2.0 * ct * abs(s) * t[a] * t[b]
                if speed_n > 0.0:
                    value += cn * wn[a] * wn[b] / speed_n
                block[a, b] = value
        # w = (v_e + v_{e+1})/2 and each node takes half the force: a factor ¼ on every node pair
        _add_edge_block(band, stride, e, dim, block, 0.25 * velocity_derivative)


@njit(cache=True, error_model="numpy")
def added_mass(start_positions, accelerations, edge_mass, acceleration_derivative, stride, force, band):
    """Added-mass force −Σ ½·m_a·(I − t tᵀ)·a_node of every edge of one rod, with tangents at the start of the
    step; adds the force to ``force`` (N, D) and ½·m_a·(I − t tᵀ)·∂a/∂q on the node blocks of ``band``."""
    n_nodes, dim = start_positions.shape
    t = np.empty(dim)
    block = np.empty((dim, dim))
    kd = band.shape[1] - 1
    for e in range(n_nodes - 1):
        _edge_tangent(start_positions, e, t)
        half = 0.5 * edge_mass[e]
        for a in range(dim):
            for b in range(dim):
                block[a, b] = half * ((1.0 if a == b else 0.0) - t[a] * t[b])
        for node in (e, e + 1):
            for a in range(dim):
                f = 0.0
                for b in range(dim):
                    f -= block[a, b] * accelerations[node, b]
                force[node, a] += f
                row = stride * node + a
                for b in range(a + 1):
                    band[row, kd - a + b] += acceleration_derivative * block[a, b]


def fluid_forces(medium: str) -> tuple[ForceModel, ...]:
    """The fluid force models of a medium: ``"air"`` (none), ``"stokes"`` (the paper's per-node Stokes drag at
    water's viscosity) or ``"water"`` (buoyancy, Morison drag and added mass in still fresh water)."""
    if medium == "air":
        return ()
    if medium == "stokes":
        return (StokesDrag(),)
    if medium == "water":
        return (Buoyancy(WATER_DENSITY), MorisonDrag(), AddedMass())
    raise ValueError(f"medium = {medium!r} is not one of 'air', 'stokes', 'water'")


__all__ = ["WATER_DENSITY", "Current", "CurrentBatch", "rod_water_velocity", "MorisonDrag", "AddedMass",
           "fluid_forces", "morison_drag", "added_mass"]
