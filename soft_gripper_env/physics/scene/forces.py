"""External force models: frozen descriptions of what acts on the fingers and on a free body, in SI units.

Each model declares the terms it adds to a rod's implicit system (:meth:`ForceModel.terms`) and the loads it puts on
a free rigid body (:meth:`ForceModel.body_loads`), both read from the scene's :class:`~.fluid.Fluid` where the fluid
matters. :class:`ForceTerms` sums the models a scene lists into one set of per-node and per-edge arrays, which the
compiled kernels (:mod:`..kernels.forces`) evaluate together with the elastic forces; :class:`BodyLoads` sums their
constants for the body. A term no model gives is an empty array and costs nothing: a scene without drag pays nothing
for drag.

==================  =====================================================  =========  ========
term                force on the rod                                       unit       shape
==================  =====================================================  =========  ========
``node_force``      a constant force per node (weight, buoyancy)            N          (N, D)
``damping``         −c_i·v_i, linear and isotropic per node                 N·s/m      (N,)
``drag_normal``     Morison drag per edge, ½·ρ_w·C_n·D·l̄                    kg/m       (N − 1,)
``drag_tangential`` its tangential part, ½·ρ_w·C_t·π·D·l̄                    kg/m       (N − 1,)
``added_mass``      the water an edge carries normal to itself              kg         (N − 1,)
==================  =====================================================  =========  ========

The water's forces are Morison-type strip theory per edge (``docs/water.md``). A finger 2–4 cm across moving at
0.05–1 m/s in water works at Re ≈ 10³–10⁴, where drag is quadratic in the velocity relative to the water and the
water entrained by the finger adds inertia. Per edge of diameter D = 2r (r the mean radius of its nodes) and rest
length l̄, with t the edge tangent and w the velocity of the edge relative to the water: normal drag
−½·ρ_w·C_n·D·l̄·|w_n|·w_n, tangential (skin) drag −½·ρ_w·C_t·π·D·l̄·|w_t|·w_t, added mass
−C_a·ρ_w·(π·D²/4)·l̄·(I − t tᵀ)·a, each shared equally by the edge's two nodes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np

from .design import FingerDesign
from .discretization import Discretization
from .fluid import Fluid
from .validation import check_range


def _check_positive(owner: str, name: str, value: float, unit: str, allow_zero: bool = True) -> None:
    check_range(owner, name, value, unit, 0.0, low_inclusive=allow_zero)


class ForceModel:
    """Interface of every external force. Subclasses are frozen dataclasses holding their parameters in SI units."""

    def terms(self, disc: Discretization, fluid: Fluid) -> dict[str, np.ndarray]:
        """This model's terms on a rod, by the names of :class:`ForceTerms`' fields."""
        raise NotImplementedError

    def check_finger(self, finger: FingerDesign) -> None:
        """Raise ValueError if this model cannot act on ``finger``; any finger by default."""

    def body_loads(self, fluid: Fluid) -> BodyLoads:
        """This model's constants for a free rigid body (:class:`BodyLoads`); none by default."""
        return BodyLoads()

    def potential_energy(self, disc: Discretization, positions: np.ndarray, fluid: Fluid) -> np.ndarray | None:
        """Potential energy of a conservative force per rod [J], (R,), for node positions (R, N, D) [m]; None for a
        force that has none."""
        return None


@dataclass(frozen=True)
class BodyLoads:
    """The constants a force model contributes to the loads on a free sphere or capsule. They add up over a scene's
    models (:meth:`total`); the body's own size and shape turn them into forces (the simulator's body arrays)."""

    gravity: float = 0.0
    """Gravitational acceleration g [m/s²]."""
    buoyancy: float = 0.0
    """ρ_w·g: the lift per displaced volume [N/m³]."""
    cylinder_added_mass: float = 0.0
    """C_a·ρ_w across a capsule's cylinder [kg/m³]."""
    sphere_added_mass: float = 0.0
    """C_a·ρ_w of a sphere (and a capsule's two end caps) [kg/m³]."""
    normal_drag: float = 0.0
    """½·ρ_w·C_n across a capsule's cylinder [kg/m³]."""
    sphere_drag: float = 0.0
    """½·ρ_w·C_d of a sphere (and a capsule's end caps) [kg/m³]."""
    froude_krylov: float = 0.0
    """ρ_w of the undisturbed flow whose pressure gradient pushes the body with ρ_w·V·a_w in an accelerating current
    (the Froude–Krylov force) [kg/m³]."""
    spin_viscous: float = 0.0
    """8π·η: the creeping-flow torque on a sphere turning at ω is 8π·η·R³·ω [Pa·s]."""
    spin_boundary_layer: float = 0.0
    """½·ρ_w·6.45·√ν: the laminar boundary layer's torque on a sphere turning at ω is this ·R⁴·√|ω|·ω
    [kg/(m²·s^½)]."""

    @classmethod
    def total(cls, models, fluid: Fluid) -> BodyLoads:
        """The sum of the ``models``' loads in ``fluid``."""
        loads = [model.body_loads(fluid) for model in models]
        return cls(**{f.name: sum(getattr(part, f.name) for part in loads) for f in fields(cls)})


class ForceTerms(NamedTuple):
    """The summed terms of a scene's force models (see the module notes); an absent term is an empty array. A named
    tuple, so the compiled kernels take it as it is."""

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
    def of(cls, disc: Discretization, models, fluid: Fluid) -> ForceTerms:
        """The summed terms of ``models`` on fingers discretized as ``disc``, in ``fluid``."""
        parts = [model.terms(disc, fluid) for model in models]

        def total(name: str, ndim: int) -> np.ndarray:
            given = [part[name] for part in parts if name in part]
            return np.ascontiguousarray(sum(given[1:], given[0]), dtype=float) if given else np.zeros((0,) * ndim)

        return cls(node_force=total("node_force", 2), damping=total("damping", 1),
                   drag_normal=total("drag_normal", 1), drag_tangential=total("drag_tangential", 1),
                   added_mass=total("added_mass", 1))


@dataclass(frozen=True)
class Gravity(ForceModel):
    """Weight of every node, m_i·g along −z. Position-independent, so its Jacobian is zero."""

    acceleration: float = 9.81
    """Gravitational acceleration g [m/s²]."""

    def __post_init__(self) -> None:
        _check_positive("Gravity", "acceleration", self.acceleration, "m/s²")

    def terms(self, disc, fluid):
        return {"node_force": _vertical(disc, -disc.node_mass * self.acceleration)}

    def body_loads(self, fluid):
        return BodyLoads(gravity=self.acceleration)

    def potential_energy(self, disc, positions, fluid):
        return positions[..., disc.vertical_axis] @ (disc.node_mass * self.acceleration)


@dataclass(frozen=True)
class Buoyancy(ForceModel):
    """Archimedes' lift of every submerged node, ρ_w·V_i·g along +z (ρ_w the scene's fluid density, V_i the node's
    lumped volume)."""

    acceleration: float = 9.81
    """Gravitational acceleration g [m/s²]; must match the scene's :class:`Gravity`."""

    def __post_init__(self) -> None:
        _check_positive("Buoyancy", "acceleration", self.acceleration, "m/s²")

    def terms(self, disc, fluid):
        return {"node_force": _vertical(disc, disc.node_volume * (fluid.density * self.acceleration))}

    def body_loads(self, fluid):
        return BodyLoads(buoyancy=fluid.density * self.acceleration)

    def potential_energy(self, disc, positions, fluid):
        return -positions[..., disc.vertical_axis] @ (disc.node_volume * (fluid.density * self.acceleration))


@dataclass(frozen=True)
class StokesDrag(ForceModel):
    """The paper's per-node Stokes drag f_i = −6π·r_i·η·v_i (each node treated as a sphere of the rod's radius).

    A low-Reynolds law, kept for reproducing the paper; at water's viscosity it is negligible (``docs/water.md``).
    ``nodes`` restricts it to some nodes: the paper's published curves came from η = 1000 Pa·s acting on nodes 2–4
    only (``docs/paper_reproduction.md``), which ``StokesDrag(viscosity=1000.0, nodes=(2, 3, 4))`` reproduces.
    """

    viscosity: float | None = None
    """Dynamic viscosity η [Pa·s]; None for the scene's fluid's."""
    nodes: tuple[int, ...] | None = None
    """Indices of the nodes it acts on; None for every node."""

    def __post_init__(self) -> None:
        if self.viscosity is not None:
            _check_positive("StokesDrag", "viscosity", self.viscosity, "Pa·s")
        if self.nodes is not None:
            nodes = tuple(self.nodes)
            if not nodes or any(not isinstance(i, (int, np.integer)) or i < 0 for i in nodes):
                raise ValueError(f"StokesDrag.nodes = {self.nodes!r} must be None or non-negative node indices")
            object.__setattr__(self, "nodes", nodes)

    def check_finger(self, finger):
        """Raise ValueError if ``nodes`` names a node beyond the finger's last."""
        if self.nodes is not None and max(self.nodes) >= finger.n_nodes:
            raise ValueError(f"StokesDrag.nodes = {self.nodes!r} names node {max(self.nodes)}; the finger has nodes "
                             f"0 … {finger.n_nodes - 1}")

    def terms(self, disc, fluid):
        viscosity = fluid.viscosity if self.viscosity is None else self.viscosity
        coefficient = 6.0 * math.pi * viscosity * disc.node_radius  # [N·s/m], shape (N,)
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

    def terms(self, disc, fluid):
        return {"damping": self.rate * disc.node_mass}


@dataclass(frozen=True)
class MorisonDrag(ForceModel):
    """Quadratic normal and tangential drag per edge, on the velocity relative to the water (see module notes)."""

    normal_coefficient: float = 1.2
    """C_n, dimensionless; 1.0–1.2 for a circular cylinder at Re ≈ 10³–10⁴ (``docs/water.md``)."""
    tangential_coefficient: float = 0.01
    """C_t on the wetted perimeter π·D, dimensionless. The skin-friction coefficient of a long cylinder in axial
    flow; line-dynamics practice uses about 0.008–0.01 (e.g. the axial drag coefficient of offshore mooring
    codes), about 1/100 of the normal drag per unit area."""
    sphere_drag_coefficient: float = 0.47
    """C_d of a free sphere (and a capsule's end caps), dimensionless; 0.47 at Re ≈ 10³–10⁵."""

    def __post_init__(self) -> None:
        _check_positive("MorisonDrag", "normal_coefficient", self.normal_coefficient, "(dimensionless)")
        _check_positive("MorisonDrag", "tangential_coefficient", self.tangential_coefficient, "(dimensionless)")
        _check_positive("MorisonDrag", "sphere_drag_coefficient", self.sphere_drag_coefficient, "(dimensionless)")

    def terms(self, disc, fluid):
        """½·ρ_w·C_n·D·l̄ and ½·ρ_w·C_t·π·D·l̄ of every edge [kg/m], (N − 1,) each."""
        half_density_area = 0.5 * fluid.density * _edge_diameter(disc) * disc.rest_edge_length
        return {"drag_normal": half_density_area * self.normal_coefficient,
                "drag_tangential": half_density_area * (math.pi * self.tangential_coefficient)}

    def body_loads(self, fluid):
        """Drag on the body's velocity relative to the water, and the water's torque on a turning body: the
        creeping-flow torque 8π·η·R³·ω plus the laminar boundary layer's, ½·ρ_w·ω²·R⁵·C_M with
        C_M = 6.45/√Re_ω, Re_ω = ω·R²/ν (``docs/water.md``)."""
        kinematic_viscosity = fluid.viscosity / fluid.density if fluid.density > 0.0 else 0.0
        return BodyLoads(normal_drag=0.5 * fluid.density * self.normal_coefficient,
                         sphere_drag=0.5 * fluid.density * self.sphere_drag_coefficient,
                         spin_viscous=8.0 * math.pi * fluid.viscosity,
                         spin_boundary_layer=0.5 * fluid.density * SPIN_BOUNDARY_LAYER_COEFFICIENT
                         * math.sqrt(kinematic_viscosity))


@dataclass(frozen=True)
class AddedMass(ForceModel):
    """The inertia of the water a finger carries along: C_a·ρ_w·(π·D²/4) per unit length on normal accelerations;
    on a free body, added mass on its acceleration relative to the water and the Froude–Krylov force."""

    coefficient: float = 1.0
    """C_a, dimensionless; 1 for a circular cylinder."""
    sphere_coefficient: float = 0.5
    """C_a of a free sphere (and a capsule's end caps), dimensionless: half the displaced fluid's mass."""

    def __post_init__(self) -> None:
        _check_positive("AddedMass", "coefficient", self.coefficient, "(dimensionless)")
        _check_positive("AddedMass", "sphere_coefficient", self.sphere_coefficient, "(dimensionless)")

    def terms(self, disc, fluid):
        """Added mass of each edge for motion normal to it [kg], (N − 1,)."""
        return {"added_mass": self.coefficient * fluid.density * math.pi / 4 * _edge_diameter(disc) ** 2
                * disc.rest_edge_length}

    def body_loads(self, fluid):
        """The water's inertia on a free body: added mass on its acceleration relative to the water, and the
        Froude–Krylov force ρ_w·V·a_w of an accelerating current (together Morison's inertia term
        (1 + C_a)·ρ_w·V·a_w on a body at rest)."""
        return BodyLoads(cylinder_added_mass=self.coefficient * fluid.density,
                         sphere_added_mass=self.sphere_coefficient * fluid.density, froude_krylov=fluid.density)


SPIN_BOUNDARY_LAYER_COEFFICIENT = 6.45
"""C_M·√Re_ω of a sphere turning in still fluid with a laminar boundary layer (Re_ω = ω·R²/ν ≈ 10²–10⁵), from
Sawatzki's measurements (1970) as quoted in the literature on rotating spheres; dimensionless."""


def _vertical(disc: Discretization, value: np.ndarray) -> np.ndarray:
    """A per-node force (N, D) [N] of vertical component ``value`` (N,)."""
    force = np.zeros((disc.n_nodes, disc.dim))
    force[:, disc.vertical_axis] = value
    return force


def _edge_diameter(disc: Discretization) -> np.ndarray:
    return disc.node_radius[:-1] + disc.node_radius[1:]


def fluid_forces(medium: str) -> tuple[ForceModel, ...]:
    """The fluid force models of a medium: ``"air"`` (none), ``"stokes"`` (the paper's per-node Stokes drag at the
    fluid's viscosity) or ``"water"`` (buoyancy, Morison drag and added mass in the scene's fluid)."""
    if medium == "air":
        return ()
    if medium == "stokes":
        return (StokesDrag(),)
    if medium == "water":
        return (Buoyancy(), MorisonDrag(), AddedMass())
    raise ValueError(f"medium = {medium!r} is not one of 'air', 'stokes', 'water'")


PAPER_DEFECTIVE_DRAG = StokesDrag(viscosity=1000.0, nodes=(2, 3, 4))
"""The drag that produced the paper's published curves (``docs/paper_reproduction.md``): η = 10⁶ × water's, on
nodes 2–4 only."""


__all__ = ["ForceModel", "BodyLoads", "ForceTerms", "Gravity", "Buoyancy", "StokesDrag", "MassProportionalDamping",
           "MorisonDrag", "AddedMass", "fluid_forces", "PAPER_DEFECTIVE_DRAG"]
