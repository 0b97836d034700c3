"""Time integrators, chosen by name from :data:`INTEGRATORS`. They differ only in how they use the implicit step.

======================== ===== =======================================================================
name                     order behaviour
======================== ===== =======================================================================
``backward_euler``       1     L-stable: damps every oscillation, strongly at large Δt (the paper's choice)
``implicit_midpoint``    2     symplectic: keeps oscillations at large Δt, with no numerical damping
``midpoint_triple_jump`` 4     three midpoint steps of γ₁Δt, γ₂Δt, γ₁Δt (Yoshida's symmetric composition):
                               symplectic, and its phase error falls as Δt⁴; three solves per step
``midpoint_suzuki``      4     five midpoint steps of pΔt, pΔt, (1 − 4p)Δt, pΔt, pΔt (Suzuki's fractal
                               composition): as the triple jump, with every substep shorter than Δt and a
                               smaller error at large Δt; five solves per step
======================== ===== =======================================================================

The implicit midpoint rule, M·(v₁ − v₀)/Δt = f(q_½, v_½) with q_½ = (q₀ + q₁)/2 and v_½ = (q₁ − q₀)/Δt, is exactly a
backward-Euler step of Δt/2 to the midpoint followed by a linear extrapolation: q₁ = 2·q_½ − q₀, v₁ = 2·v_½ − v₀.
So all integrators share one Newton solver, one set of forces and one set of Jacobians.

The triple jump composes the midpoint rule Φ as Φ(γ₁Δt)∘Φ(γ₂Δt)∘Φ(γ₁Δt) with γ₁ = 1/(2 − 2^⅓) ≈ 1.351 and
γ₂ = 1 − 2γ₁ ≈ −1.702 (H. Yoshida, Phys. Lett. A 150, 1990): a symmetric method of order 2 composed this way is of
order 4. The middle step runs backward in time, so a dissipative force (drag, damping) is anti-dissipative there;
the method suits conservative or lightly damped scenes, where the midpoint rule's phase drift is what limits Δt.
Its substeps of 1.35·Δt and −1.70·Δt are longer than the step itself, so its error grows fast with Δt. Suzuki's
five-step composition, p = 1/(4 − 4^⅓) ≈ 0.4145 and 1 − 4p ≈ −0.658 (M. Suzuki, Phys. Lett. A 146, 1990), is
of the same order with substeps all shorter than Δt and a smaller backward one: it keeps the undamped cantilever
within 2.4 % at Δt = 2e-2 s, where the triple jump is off by 29 % (tests/physics/test_integrators.py). A second-order
method cannot do that: the midpoint rule's period is too long by (ωΔt)²/12 per period, which over ten 5 Hz
periods at Δt = 1e-2 s is a quarter of the oscillation.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..scene.scene import INTEGRATOR_NAMES
from .records import RodState, StepResult, evolve


class ImplicitStepper(Protocol):
    """What an integrator steps with: one implicit (backward-Euler) step of any length (the simulator's
    :meth:`~..simulator.Simulator.implicit_step`)."""

    def implicit_step(self, state: RodState, natural_curvature: np.ndarray, dt: float, velocity_old: np.ndarray,
                      midpoint: bool = False) -> StepResult:
        """A backward-Euler step of ``dt`` [s] from ``state`` with κ̄ per rod and the old velocity ``velocity_old``;
        with ``midpoint``, the implicit midpoint rule's half step, extrapolated to the end of its step of 2·dt."""


class BackwardEuler:
    """Backward (implicit) Euler: one implicit step of Δt."""

    order = 1
    numerical_retardation = 1.0
    """Its step damps a mode of ω·Δt ≪ 1 as a Kelvin–Voigt material of retardation time Δt would, in units of Δt
    (the material's own damping is applied less this; :func:`~..kernels.assembly.assemble_rod`)."""

    def advance(self, stepper: ImplicitStepper, state: RodState, natural_curvature: np.ndarray,
                dt: float) -> StepResult:
        return stepper.implicit_step(state, natural_curvature, dt, state.velocity)


class ImplicitMidpoint:
    """The implicit midpoint rule: a backward-Euler half step to the midpoint, then extrapolation to the end."""

    order = 2
    numerical_retardation = 0.0
    """It adds no damping to a linear oscillator."""

    def advance(self, stepper: ImplicitStepper, state: RodState, natural_curvature: np.ndarray,
                dt: float) -> StepResult:
        return stepper.implicit_step(state, natural_curvature, 0.5 * dt, state.velocity, midpoint=True)


class MidpointComposition:
    """A symmetric composition of implicit-midpoint steps of ``fractions``·Δt (summing to 1), of order ``order``."""

    numerical_retardation = 0.0
    """Composed of midpoint steps, it adds no damping to a linear oscillator either."""

    def __init__(self, fractions: tuple[float, ...], order: int) -> None:
        self.fractions, self.order = fractions, order

    def advance(self, stepper: ImplicitStepper, state: RodState, natural_curvature: np.ndarray,
                dt: float) -> StepResult:
        results = []
        current = state
        for fraction in self.fractions:
            results.append(MIDPOINT.advance(stepper, current, natural_curvature, fraction * dt))
            current = results[-1].state
        end = evolve(current, time=state.time + dt, acceleration=(current.velocity - state.velocity) / dt)
        return evolve(results[-1], state=end, converged=np.logical_and.reduce([r.converged for r in results]),
                      newton_iterations=sum(r.newton_iterations for r in results),
                      residual=np.maximum.reduce([r.residual for r in results]),
                      substeps=np.maximum.reduce([r.substeps for r in results]))


MIDPOINT = ImplicitMidpoint()
_YOSHIDA = 1.0 / (2.0 - 2.0 ** (1.0 / 3.0))
_SUZUKI = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
INTEGRATORS = {"backward_euler": BackwardEuler(), "implicit_midpoint": MIDPOINT,
               "midpoint_triple_jump": MidpointComposition((_YOSHIDA, 1.0 - 2.0 * _YOSHIDA, _YOSHIDA), order=4),
               "midpoint_suzuki": MidpointComposition((_SUZUKI, _SUZUKI, 1.0 - 4.0 * _SUZUKI, _SUZUKI, _SUZUKI),
                                                      order=4)}
"""Every integrator, by the name a :class:`~..scene.scene.Scene` gives in ``integrator``."""
assert tuple(INTEGRATORS) == INTEGRATOR_NAMES, "the scene's integrator names and the integrators differ"
