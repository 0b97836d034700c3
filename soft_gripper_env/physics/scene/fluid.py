"""The fluid the gripper works in: one scene-level description that the rods' forces and the free body both read.

A :class:`Fluid` has a density, a viscosity and a :class:`Current`. The force models (:mod:`.forces`) take the
density and viscosity from it, and the simulator moves the water at every gripper with its current, so one scene
has one fluid and nothing keeps a second copy of its constants.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .validation import check_range

WATER_DENSITY = 1000.0
"""Density of fresh water [kg/m³] (sea water is about 1025)."""
WATER_VISCOSITY = 1.0e-3
"""Dynamic viscosity of water at about 20 °C [Pa·s]."""


@dataclass(frozen=True)
class Current:
    """A uniform water current u(t) = velocity + oscillation·sin(2π·t/period + phase) + gust(t) [m/s], world frame
    (computed by :func:`~..kernels.current.current_velocity`).

    The gust is a smooth pulse, gust_velocity·sin²(π·(t − gust_start)/gust_duration) while
    gust_start ≤ t ≤ gust_start + gust_duration and zero otherwise: it rises and falls without a jump, so the water's
    acceleration, which the added mass and the Froude–Krylov force feel, stays finite."""

    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Mean current [m/s]."""
    oscillation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Amplitude of the oscillating part [m/s]."""
    period: float = 1.0
    """Period of the oscillating part [s]."""
    phase: float = 0.0
    """Phase of the oscillating part at t = 0 [rad]."""
    gust_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Peak of the gust [m/s]."""
    gust_start: float = 0.0
    """When the gust begins [s]."""
    gust_duration: float = 0.0
    """How long it blows [s]; 0 is no gust."""

    def __post_init__(self) -> None:
        for name in ("velocity", "oscillation", "gust_velocity"):
            value = tuple(float(v) for v in getattr(self, name))
            if len(value) != 3:
                raise ValueError(f"Current.{name} = {getattr(self, name)!r} must have 3 components [m/s]")
            for v in value:
                check_range("Current", name, v, "m/s", -100.0, 100.0, low_inclusive=True)
            object.__setattr__(self, name, value)
        check_range("Current", "period", self.period, "s", 0.0)
        check_range("Current", "phase", self.phase, "rad", -1e3, 1e3, low_inclusive=True)
        check_range("Current", "gust_start", self.gust_start, "s", 0.0, 1e6, low_inclusive=True)
        check_range("Current", "gust_duration", self.gust_duration, "s", 0.0, 1e6, low_inclusive=True)

    @property
    def has_gust(self) -> bool:
        """Whether a gust blows: it lasts a while and has a peak."""
        return self.gust_duration > 0.0 and any(self.gust_velocity)


@dataclass(frozen=True)
class Fluid:
    """The fluid around the gripper: its density, viscosity and current (SI units)."""

    density: float = WATER_DENSITY
    """ρ_w [kg/m³]."""
    viscosity: float = WATER_VISCOSITY
    """Dynamic viscosity η [Pa·s]."""
    current: Current = field(default_factory=Current)
    """The uniform current the fluid flows with [m/s]."""

    def __post_init__(self) -> None:
        check_range("Fluid", "density", self.density, "kg/m³", 0.0, 1e5, low_inclusive=True)
        check_range("Fluid", "viscosity", self.viscosity, "Pa·s", 0.0, 1e6, low_inclusive=True)
        if not isinstance(self.current, Current):
            raise ValueError(f"Fluid.current must be a Current, got {type(self.current).__name__}")


WATER = Fluid()
"""Still fresh water at about 20 °C."""

__all__ = ["WATER_DENSITY", "WATER_VISCOSITY", "Current", "Fluid", "WATER"]
