"""The water's current at every gripper of a batch: one compiled formula, for the host and for every kernel.

A :class:`~..scene.fluid.Current` describes one gripper's current; :class:`CurrentBatch` holds a batch's as arrays,
each gripper on its own clock. The formula, :func:`current_velocity`, is compiled, so the host's arrays of the water
at the control interval's step times and a kernel that needs the water between them (a halved step's half steps, on
the CPU or in a GPU thread) compute it with the same arithmetic, to the bit.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..scene.fluid import Current
from .compiled import kernel


class CurrentArrays(NamedTuple):
    """A batch's currents as the kernels take them (B grippers)."""

    velocity: np.ndarray
    """Mean current [m/s], (B, 3)."""
    oscillation: np.ndarray
    """Amplitude of the oscillating part [m/s], (B, 3)."""
    period: np.ndarray
    """Period of the oscillating part [s], (B,)."""
    phase: np.ndarray
    """Its phase at the gripper's clock 0 [rad], (B,)."""
    gust_velocity: np.ndarray
    """The gust's peak [m/s], (B, 3); zero where no gust blows."""
    gust_start: np.ndarray
    """When the gust begins on the gripper's clock [s], (B,)."""
    gust_duration: np.ndarray
    """How long it blows [s], (B,); 1 where no gust blows."""
    start_time: np.ndarray
    """The batch time at which each gripper's clock reads 0 [s], (B,)."""


@kernel(python=True)  # the CUDA simulator's threads of the rods' kernel call it from Python
def current_velocity(currents, b, time, velocity):
    """The water's velocity at gripper ``b`` at the batch time ``time`` [s] into ``velocity`` (3,) [m/s]: the
    :class:`~..scene.fluid.Current` formula, u = mean + oscillation·sin(2π·t/period + phase) + gust(t), with the gust
    gust_velocity·sin²(π·(t − gust_start)/gust_duration) while it blows. ``currents``: :class:`CurrentArrays`'
    fields (a plain tuple, as every kernel takes its bundles)."""
    velocity_mean, oscillation, period, phase, gust_velocity, gust_start, gust_duration, start_time = currents
    clock = time - start_time[b]
    angle = 2 * math.pi * clock / period[b] + phase[b]
    wave = math.sin(angle)
    through = (clock - gust_start[b]) / gust_duration[b]  # 0 … 1 while the gust blows
    gust = gust_velocity[b, 0] != 0.0 or gust_velocity[b, 1] != 0.0 or gust_velocity[b, 2] != 0.0
    blowing = gust and 0.0 <= through <= 1.0
    pulse = math.sin(math.pi * through) ** 2 if blowing else 0.0
    for d in range(3):
        velocity[d] = velocity_mean[b, d] + oscillation[b, d] * wave
        if blowing:
            velocity[d] += gust_velocity[b, d] * pulse


@kernel(python=True)
def currents_at_times(currents, times, velocities):
    """:func:`current_velocity` at every gripper at each of ``times`` (K,) [s] into ``velocities`` (K, B, 3)."""
    for k in range(times.shape[0]):
        for b in range(velocities.shape[1]):
            current_velocity(currents, b, times[k], velocities[k, b])


class CurrentBatch:
    """The currents of a batch of grippers (:class:`CurrentArrays`, :attr:`arrays`; a gripper without a gust has a
    zero peak over 1 s). A gripper's entry is replaced with :meth:`load`, its clock with :meth:`set_clock`; the
    arrays are read-only otherwise, since :meth:`at` remembers what it computed."""

    def __init__(self, batch_size: int) -> None:
        self.arrays = CurrentArrays(np.zeros((batch_size, 3)), np.zeros((batch_size, 3)), np.ones(batch_size),
                                    np.zeros(batch_size), np.zeros((batch_size, 3)), np.zeros(batch_size),
                                    np.ones(batch_size), np.zeros(batch_size))
        self._remembered: dict[float, np.ndarray] = {}

    @classmethod
    def of(cls, currents) -> CurrentBatch:
        batch = cls(len(currents))
        for index, current in enumerate(currents):
            batch.load(index, current)
        return batch

    @property
    def start_time(self) -> np.ndarray:
        """The batch time at which each gripper's clock reads 0 [s], (B,)."""
        return self.arrays.start_time

    def load(self, index: int, current: Current) -> None:
        arrays = self.arrays
        arrays.velocity[index] = current.velocity
        arrays.oscillation[index] = current.oscillation
        arrays.period[index] = current.period
        arrays.phase[index] = current.phase
        gust = current.has_gust
        arrays.gust_velocity[index] = current.gust_velocity if gust else 0.0
        arrays.gust_start[index] = current.gust_start
        arrays.gust_duration[index] = current.gust_duration if gust else 1.0
        self._remembered.clear()

    def set_clock(self, index, start_time) -> None:
        """Sets the batch time [s] at which the clocks of grippers ``index`` (an index, slice or index array) read 0."""
        self.arrays.start_time[index] = start_time
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

    def at_times(self, times) -> np.ndarray:
        """The water's velocity at every gripper at each of ``times`` (K,) [s], (K, B, 3) [m/s]."""
        times = np.ascontiguousarray(times, dtype=float).reshape(-1)
        velocities = np.empty((times.shape[0], self.arrays.period.shape[0], 3))
        currents_at_times(tuple(self.arrays), times, velocities)
        return velocities

    def mean_acceleration(self, time: float, dt: float) -> np.ndarray:
        """The water's mean acceleration over [time, time + dt] at every gripper, (u(t + Δt) − u(t))/Δt [m/s²],
        (B, 3): a force proportional to it gives exactly the impulse of the current's change over the step."""
        return (self.at(time + dt) - self.at(time)) / dt


def current_at(current: Current, time: float) -> np.ndarray:
    """One :class:`~..scene.fluid.Current`'s velocity at ``time`` [s] on its own clock [m/s], (3,)."""
    return CurrentBatch.of((current,)).at(time)[0]


__all__ = ["CurrentArrays", "current_velocity", "currents_at_times", "CurrentBatch", "current_at"]
