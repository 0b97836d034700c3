"""The records a step reads and writes: the batch's state, a step's result and its contact report, and the few
helpers that copy them cheaply or move grippers between batches. Every array field has the batch axis B first."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np


@dataclass(frozen=True, eq=False)
class RodState:
    """The state of B grippers at one instant.

    ``q`` and ``velocity`` are (B, F, N, S) in the layout of :class:`~..scene.discretization.Discretization`
    ([m] and [m/s]; twist angles [rad] and [rad/s]). The 3-D model also carries the reference frame of every edge,
    which is part of the state because it is transported in time: ``tangent`` and ``director`` (B, F, N − 1, 3),
    ``reference_twist`` (B, F, N) [rad]. They are None in the planar model.
    """

    q: np.ndarray
    velocity: np.ndarray
    time: float
    """Simulated time [s]."""
    acceleration: np.ndarray | None = None
    """Mean acceleration over the last step, (v − v_old)/Δt, (B, F, N, S) [m/s²]; None before the first step.
    It only improves Newton's starting guess."""
    tangent: np.ndarray | None = None
    director: np.ndarray | None = None
    reference_twist: np.ndarray | None = None
    held: np.ndarray | None = None
    """Nodes held on the grasped object's surface, (B, F, N) bool; None in a scene without an object."""
    hold_offset: np.ndarray | None = None
    """For a free object: each held node's offset from the object's centre in the object's frame [m], (B, F, N, 3)."""
    body_position: np.ndarray | None = None
    """Centre of a free object [m], (B, 3); None unless the scene's object is free."""
    body_velocity: np.ndarray | None = None
    """Its velocity [m/s], (B, 3)."""
    body_orientation: np.ndarray | None = None
    """Its orientation, body to world, (B, 3, 3)."""
    body_angular_velocity: np.ndarray | None = None
    """Its angular velocity [rad/s], (B, 3)."""


@dataclass(frozen=True, eq=False)
class StepResult:
    """What one implicit step returns. Per-gripper arrays have shape (B,)."""

    state: RodState
    converged: np.ndarray
    """Whether Newton's method met its tolerance on every finger of the gripper."""
    newton_iterations: np.ndarray
    """Linear solves (Newton iterations) the slowest finger needed."""
    residual: np.ndarray
    """Final residual: the largest free-DOF residual divided by its tolerance (≤ 1 when converged; dimensionless)."""
    substeps: np.ndarray
    """Substeps the step took, (B,): 1 unless Newton failed or the contact corrector spent its budget, and the step
    was halved (adaptive substepping)."""
    contact: ContactReport | None = None
    """Contact reactions of the step; None in a scene without an object."""


@dataclass(frozen=True, eq=False)
class ContactReport:
    """Contact of one step, in the world frame. Arrays are per gripper (B), finger (F) and node (N)."""

    held: np.ndarray
    """Nodes in contact with the object's surface at the end of the step, stuck or sliding, (B, F, N) bool."""
    sliding: np.ndarray
    """Held nodes that slide along the surface (Coulomb friction at its limit μ·R_n), (B, F, N) bool."""
    reaction: np.ndarray
    """Force of the object on each node, normal reaction plus friction [N], (B, F, N, 3); zero where not held."""
    normal_reaction: np.ndarray
    """Its component along the outward surface normal [N], (B, F, N); ≥ 0 (compression only)."""
    corrector_iterations: np.ndarray
    """Re-solves the step needed, (B,)."""
    resolved: np.ndarray
    """Whether the corrector ended with no penetrating node and no adhesive hold, (B,)."""
    palm_reaction: np.ndarray | None = None
    """Force of a free object on the palm [N], (B, 3); zero where it does not touch; None for a fixed object."""

    @property
    def finger_reaction(self) -> np.ndarray:
        """Sum of the reactions on each finger [N], (B, F, 3)."""
        return self.reaction.sum(axis=2)

    @property
    def total_reaction(self) -> np.ndarray:
        """Sum of the reactions on the gripper, fingers and palm [N], (B, 3)."""
        total = self.reaction.sum(axis=(1, 2))
        return total if self.palm_reaction is None else total + self.palm_reaction


@dataclass(frozen=True, eq=False)
class Advance:
    """What :meth:`~..simulator.Simulator.advance` returns: several steps with a natural-curvature ramp, per
    gripper (B) and finger (F)."""

    state: RodState
    """The state after the steps (a failed gripper's after its last good step; the batch's clock after all)."""
    natural_curvature: np.ndarray
    """κ̄ after the ramp (dimensionless), (B, F)."""
    clock: np.ndarray
    """Each gripper's clock advanced by the steps it took [s], (B,)."""
    failed: np.ndarray
    """Grippers whose step failed (Newton or a non-finite state, after halving); they took no further step, (B,)."""
    newton_iterations: np.ndarray
    """Newton iterations of the slowest finger, summed over the steps taken, (B,)."""
    normal_impulse: np.ndarray
    """Σ max(R_n, 0)·Δt of every node over the steps taken [N·s], (B, F, N)."""
    impulse: np.ndarray
    """Σ R·Δt of the object's force on every node, world frame [N·s], (B, F, N, 3)."""


Record = TypeVar("Record")


def evolve(record: Record, **changes) -> Record:
    """A copy of one of the step's frozen records (:class:`RodState`, :class:`StepResult`,
    :class:`ContactReport`) with ``changes``: ``dataclasses.replace`` without its per-call field
    introspection and ``__init__``, which cost more than a small scene's whole step. The records hold arrays
    only, so there is nothing to validate."""
    copy = object.__new__(type(record))
    vars(copy).update(vars(record), **changes)
    return copy


def record(kind: type[Record], **fields) -> Record:
    """A new record of ``kind`` with every one of its ``fields`` given, made as :func:`evolve` makes a copy."""
    made = object.__new__(kind)
    vars(made).update(fields)
    return made


def finite(state: RodState) -> np.ndarray:
    """Per gripper, whether every coordinate and velocity and a free body's position and velocity are finite,
    (B,)."""
    ok = np.isfinite(state.q).all(axis=(1, 2, 3)) & np.isfinite(state.velocity).all(axis=(1, 2, 3))
    if state.body_position is not None:
        ok &= np.isfinite(state.body_position).all(axis=1) & np.isfinite(state.body_velocity).all(axis=1)
    return ok


def take_grippers(record, index: np.ndarray):
    """The grippers ``index`` of a state or contact report (every array field has the batch axis first)."""
    return evolve(record, **{name: value[index] for name, value in vars(record).items()
                             if isinstance(value, np.ndarray)})


def put_grippers(record, index: np.ndarray, part):
    """A copy of ``record`` whose grippers ``index`` are taken from ``part``."""
    return evolve(record, **{name: _set(value, index, getattr(part, name)) for name, value in vars(record).items()
                             if isinstance(value, np.ndarray)})


def _set(array: np.ndarray, index: np.ndarray, values: np.ndarray) -> np.ndarray:
    out = array.copy()
    out[index] = values
    return out


__all__ = ["RodState", "StepResult", "ContactReport", "Advance", "evolve", "record", "finite", "take_grippers",
           "put_grippers"]
