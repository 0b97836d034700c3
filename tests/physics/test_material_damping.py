"""The material's Kelvin–Voigt damping (``Material.retardation_time``): a mode's free decay against the closed form,
and its Newton matrix against finite differences."""

from dataclasses import replace

import numpy as np
import pytest
from test_derivatives import band_to_dense, finite_difference_jacobian
from test_integrators import CANTILEVER, first_mode, tip_history

from soft_gripper_env.physics import Material, Simulator


def with_retardation(scene, retardation_time):
    """``scene`` with its fingers' material given the retardation time τ [s]."""
    finger = scene.gripper.finger
    material = replace(finger.material, retardation_time=retardation_time)
    return replace(scene, gripper=replace(scene.gripper, finger=replace(finger, material=material)))


def decay_rate(history, sample_dt):
    """The exponential decay rate σ [1/s] of an oscillation about zero, from a straight-line fit of the logarithm of
    its peaks |z| against their times."""
    magnitude = np.abs(history)
    peaks = np.flatnonzero((magnitude[1:-1] > magnitude[:-2]) & (magnitude[1:-1] >= magnitude[2:])) + 1
    assert len(peaks) >= 6, "too few half periods to fit a decay"
    slope = np.polyfit(peaks * sample_dt, np.log(magnitude[peaks]), 1)[0]
    return -slope


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_a_bending_mode_decays_at_the_kelvin_voigt_rate(model):
    """Stress E·(ε + τ·ε̇) gives the damping force −τ·K·v, proportional to the stiffness: each mode of the rod keeps
    its shape and decays as exp(−ζ·ω·t) with ζ = τ·ω/2, so at the rate σ = τ·ω²/2. The cantilever without gravity
    starts at rest in its first discrete mode (ω = 31.6 rad/s) at 1 cm/s, small enough to stay linear, and the
    implicit midpoint rule, which adds no damping of its own to a linear oscillator, steps it at Δt = 1 ms
    (ω·Δt = 0.03). Without τ it keeps its amplitude; with τ = 2 and 4 ms its peaks fall at σ within 1 %."""
    undamped = replace(CANTILEVER, forces=(), model=model)
    omega, velocity = first_mode(undamped, 0.01)
    dt, duration = 1e-3, 1.5
    rates = {}
    for retardation_time in (0.0, 2e-3, 4e-3):
        scene = with_retardation(undamped, retardation_time)
        rates[retardation_time] = decay_rate(tip_history(scene, "implicit_midpoint", dt, duration, dt, velocity), dt)
    assert abs(rates[0.0]) < 0.005 * rates[2e-3]
    for retardation_time in (2e-3, 4e-3):
        assert rates[retardation_time] == pytest.approx(retardation_time * omega**2 / 2, rel=0.01), (omega, rates)


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_backward_euler_counts_its_own_damping_in_the_materials(model):
    """A backward-Euler step damps a mode of ω·Δt ≪ 1 as a Kelvin–Voigt material of τ = Δt would, so the step
    applies the material's τ less Δt: the cantilever's first mode (ω = 31.6 rad/s) then decays at the material's
    rate τ·ω²/2 at every step up to τ, within 2 % at Δt = 2 ms (ω·Δt = 0.063), where the full τ on top of the
    step's own damping decayed 24 % too fast; a step longer than τ damps by its own part alone, Δt·ω²/2, the
    rate it has without any material damping."""
    undamped = replace(CANTILEVER, forces=(), model=model)
    omega, velocity = first_mode(undamped, 0.01)
    retardation_time, duration = 8e-3, 1.5
    for dt in (2e-3, 1e-3):
        rate = decay_rate(tip_history(with_retardation(undamped, retardation_time), "backward_euler", dt, duration,
                                      dt, velocity), dt)
        assert rate == pytest.approx(retardation_time * omega**2 / 2, rel=0.02), (dt, omega, rate)
    dt = 2e-3
    elastic = decay_rate(tip_history(undamped, "backward_euler", dt, duration, dt, velocity), dt)
    lighter = decay_rate(tip_history(with_retardation(undamped, 1e-3), "backward_euler", dt, duration, dt, velocity),
                         dt)
    assert elastic == pytest.approx(dt * omega**2 / 2, rel=0.05), (omega, elastic)
    assert lighter == elastic


def test_the_damped_newton_matrix_is_the_jacobian_of_the_damped_force():
    """With τ the elastic force is evaluated at q* = q + (τ'/Δt)·(q − q_old) and its matrix scaled by 1 + τ'/Δt, with
    τ' = τ − Δt (backward Euler's own damping counted in τ): −∂f/∂q
    of the planar rod (whose analytic gradient is exact everywhere) by central differences, at a curved
    configuration moved off the step's start."""
    scene = with_retardation(replace(CANTILEVER, forces=()), 5e-3)
    sim = Simulator(scene)
    rng = np.random.default_rng(5)
    q_old = sim.initial_state().q.reshape(1, scene.gripper.finger.n_nodes, -1)
    q_old = q_old + rng.normal(scale=2e-3, size=q_old.shape) * sim.disc.free.reshape(q_old.shape)
    q = q_old + rng.normal(scale=1e-4, size=q_old.shape) * sim.disc.free.reshape(q_old.shape)
    dt, kappa = 1e-3, np.array([3.0])

    def force(x):
        return sim._assemble(x, q_old, q_old, None, kappa, 0.0, dt)[0].ravel()

    free = sim.disc.free
    band = band_to_dense(sim._assemble(q, q_old, q_old, None, kappa, 0.0, dt)[1][0])[np.ix_(free, free)]
    fd = finite_difference_jacobian(force, q, 1e-8)[np.ix_(free, free)]
    undamped = Simulator(with_retardation(scene, 0.0))
    assert np.abs(band).max() > 4.0 * np.abs(band_to_dense(undamped._assemble(q, q_old, q_old, None, kappa, 0.0,
                                                                                dt)[1][0])).max()  # 1 + τ'/Δt = 5
    np.testing.assert_allclose(band, fd, rtol=0, atol=1e-6 * np.abs(band).max())


@pytest.mark.parametrize("value", [-1e-3, 1.0, float("nan")])
def test_a_retardation_time_out_of_range_is_refused(value):
    with pytest.raises(ValueError, match=r"Material\.retardation_time = .* s .*\[0, 1\) s"):
        Material("x", youngs_modulus=1e5, density=1000.0, retardation_time=value)
