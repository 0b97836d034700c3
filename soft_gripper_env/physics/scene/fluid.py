"""The fluid the gripper works in: one scene-level description that the rods' forces and the free body both read.

A :class:`Fluid` has a density, a viscosity and a :class:`Current`. The force models (:mod:`.forces`) take the
density and viscosity from it, and the simulator moves the water at every gripper with its current, so one scene
has one fluid and nothing keeps a second copy of its constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .validation import check_range

WATER_DENSITY = 1000.0
"""Density of fresh water [kg/m³] (sea water is about 1025)."""
WATER_VISCOSITY = 1.0e-3
"""Dynamic viscosity of water at about 20 °C [Pa·s]."""


@dataclass(frozen=True)
class Current:
    """A uniform water current u(t) = velocity + oscillation·sin(2π·t/period + phase) + gust(t) [m/s], world frame.

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

    def at(self, time: float) -> np.ndarray:
        """Current velocity at ``time`` [m/s], (3,)."""
        return CurrentBatch.of((self,)).at(time)[0]


class CurrentBatch:
    """The currents of a batch of grippers, as arrays: mean and amplitude (B, 3) [m/s], period (B,) [s], phase (B,)
    [rad], the gust's peak (B, 3) [m/s], start and duration (B,) [s] (a gripper without a gust has a zero peak over
    1 s), and the batch time at which each gripper's own clock reads 0 (B,) [s]. A gripper's entry is replaced with
    :meth:`load`, its clock with :meth:`set_clock`; the arrays are read-only otherwise, since :meth:`at` remembers
    what it computed."""

    def __init__(self, batch_size: int) -> None:
        self.velocity = np.zeros((batch_size, 3))
        self.oscillation = np.zeros((batch_size, 3))
        self.period = np.ones(batch_size)
        self.phase = np.zeros(batch_size)
        self.gust_velocity = np.zeros((batch_size, 3))
        self.gust_start = np.zeros(batch_size)
        self.gust_duration = np.ones(batch_size)
        self.start_time = np.zeros(batch_size)
        self._remembered: dict[float, np.ndarray] = {}

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
        gust = current.has_gust
        self.gust_velocity[index] = current.gust_velocity if gust else 0.0
        self.gust_start[index] = current.gust_start
        self.gust_duration[index] = current.gust_duration if gust else 1.0
        self._remembered.clear()

    def set_clock(self, index, start_time) -> None:
        """Sets the batch time [s] at which the clocks of grippers ``index`` (an index, slice or index array) read 0."""
        self.start_time[index] = start_time
        self._remembered.clear()

    def at(self, time: float) -> np.ndarray:
        """The water's velocity at every gripper at ``time`` [m/s], (B, 3). The last two times asked for are
        remembered: a simulator asks for a step's start and end, and a step's end is the next one's start."""
        velocity = self._remembered.get(time)
        if velocity is None:
            if len(self._remembered) >= 2:
                del self._remembered[next(iter(self._remembered))]  # the oldest
            velocity = self._remembered[time] = self.at_times(np.array([time]))[0]
        return velocity

    def at_times(self, times: np.ndarray) -> np.ndarray:
        """The water's velocity at every gripper at each of ``times`` (K,) [s], (K, B, 3) [m/s]; the one formula
        of :meth:`at`."""
        clock = np.asarray(times, dtype=float)[:, None] - self.start_time  # (K, B)
        angle = 2 * math.pi * clock / self.period + self.phase
        velocity = self.velocity + self.oscillation * np.sin(angle)[..., None]
        through = (clock - self.gust_start) / self.gust_duration  # 0 … 1 while the gust blows
        blowing = (through >= 0.0) & (through <= 1.0) & self.gust_velocity.any(axis=1)
        if blowing.any():
            pulse = np.where(blowing, np.sin(math.pi * through) ** 2, 0.0)
            velocity = velocity + self.gust_velocity * pulse[..., None]
        return velocity

    def mean_acceleration(self, time: float, dt: float) -> np.ndarray:
        """The water's mean acceleration over [time, time + dt] at every gripper, (u(t + Δt) − u(t))/Δt [m/s²],
        (B, 3): a force proportional to it gives exactly the impulse of the current's change over the step."""
        return (self.at(time + dt) - self.at(time)) / dt


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

__all__ = ["WATER_DENSITY", "WATER_VISCOSITY", "Current", "CurrentBatch", "Fluid", "WATER"]
