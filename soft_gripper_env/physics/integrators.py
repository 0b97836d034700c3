"""Time integrators, chosen by name from :data:`INTEGRATORS`. They differ only in how they use the implicit step.

======================== ===== =======================================================================
name                     order behaviour
======================== ===== =======================================================================
``backward_euler``       1     L-stable: damps every oscillation, strongly at large Δt (the paper's choice)
``implicit_midpoint``    2     symplectic: keeps oscillations at large Δt, with no numerical damping
``midpoint_triple_jump`` 4     three midpoint steps of γ₁Δt, γ₂Δt, γ₁Δt (Yoshida's symmetric composition):
                               symplectic, and its phase error falls as Δt⁴; three solves per step
======================== ===== =======================================================================

The implicit midpoint rule, M·(v₁ − v₀)/Δt = f(q_½, v_½) with q_½ = (q₀ + q₁)/2 and v_½ = (q₁ − q₀)/Δt, is exactly a
backward-Euler step of Δt/2 to the midpoint followed by a linear extrapolation: q₁ = 2·q_½ − q₀, v₁ = 2·v_½ − v₀.
So all integrators share one Newton solver, one set of forces and one set of Jacobians.

The triple jump composes the midpoint rule Φ as Φ(γ₁Δt)∘Φ(γ₂Δt)∘Φ(γ₁Δt) with γ₁ = 1/(2 − 2^⅓) ≈ 1.351 and
γ₂ = 1 − 2γ₁ ≈ −1.702 (H. Yoshida, Phys. Lett. A 150, 1990): a symmetric method of order 2 composed this way is of
order 4. The middle step runs backward in time, so a dissipative force (drag, damping) is anti-dissipative there;
the method suits conservative or lightly damped scenes, where the midpoint rule's phase drift is what limits Δt.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    from .simulator import RodState, Simulator, StepResult


Record = TypeVar("Record")


def evolve(record: Record, **changes) -> Record:
    """A copy of one of the step's frozen records (:class:`~.simulator.RodState`, :class:`~.simulator.StepResult`,
    :class:`~.contact.ContactReport`) with ``changes``: ``dataclasses.replace`` without its per-call field
    introspection and ``__init__``, which cost more than a small scene's whole step. The records hold arrays
    only, so there is nothing to validate."""
    copy = object.__new__(type(record))
    vars(copy).update(vars(record), **changes)
    return copy


class BackwardEuler:
    """Backward (implicit) Euler: one implicit step of Δt."""

    order = 1

    def advance(self, sim: Simulator, state: RodState, kbar: np.ndarray, dt: float) -> StepResult:
        return sim._advance(state, kbar, dt, state.velocity)


class ImplicitMidpoint:
    """The implicit midpoint rule: a backward-Euler half step to the midpoint, then extrapolation to the end."""

    order = 2

    def advance(self, sim: Simulator, state: RodState, kbar: np.ndarray, dt: float) -> StepResult:
        return sim._advance(state, kbar, 0.5 * dt, state.velocity, midpoint=True)


class MidpointTripleJump:
    """Yoshida's fourth-order symmetric composition of three implicit-midpoint steps."""

    order = 4
    outer = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
    inner = 1.0 - 2.0 * outer

    def advance(self, sim: Simulator, state: RodState, kbar: np.ndarray, dt: float) -> StepResult:
        results = []
        current = state
        for fraction in (self.outer, self.inner, self.outer):
            results.append(MIDPOINT.advance(sim, current, kbar, fraction * dt))
            current = results[-1].state
        end = evolve(current, time=state.time + dt, acceleration=(current.velocity - state.velocity) / dt)
        return evolve(results[-1], state=end, converged=np.logical_and.reduce([r.converged for r in results]),
                       newton_iterations=sum(r.newton_iterations for r in results),
                       residual=np.maximum.reduce([r.residual for r in results]),
                       substeps=np.maximum.reduce([r.substeps for r in results]))


MIDPOINT = ImplicitMidpoint()
INTEGRATORS = {"backward_euler": BackwardEuler(), "implicit_midpoint": MIDPOINT,
               "midpoint_triple_jump": MidpointTripleJump()}
"""Every integrator, by the name a :class:`~.config.Scene` gives in ``integrator``."""
