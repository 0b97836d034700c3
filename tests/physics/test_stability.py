"""Hard cases: each completes with no NaN and a documented outcome (docs/speed_vs_error.md, "Stability")."""

import math
from dataclasses import replace

import numpy as np
import pytest

from soft_gripper_env.physics import (
    ELASTOSIL_MA_4601,
    NATURAL_CURVATURE_LIMIT,
    NewtonSettings,
    Simulator,
    cantilever_scene,
    paper_scene,
)


def run_ramp_checked(scene, rate=None, steps=None):
    """Runs κ̄ = rate·t (clipped to the allowed range); returns the final state, the worst substep count and the
    lowest tip z. Every step must converge and stay finite."""
    sim = Simulator(scene)
    state = sim.initial_state()
    rate = scene.natural_curvature_rate if rate is None else rate
    substeps, lowest = 1, 0.0
    for _ in range(steps or scene.n_steps):
        kbar = np.clip(rate * state.time, -NATURAL_CURVATURE_LIMIT, NATURAL_CURVATURE_LIMIT)
        result = sim.step(state, kbar)
        assert result.converged.all(), f"step at t = {state.time:.3f} s failed"
        state = result.state
        assert np.isfinite(state.q).all() and np.isfinite(state.velocity).all()
        substeps = max(substeps, int(result.substeps.max()))
        lowest = min(lowest, float(sim.world_positions(state)[..., 2].min()))
    return state, substeps, lowest


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_soft_material_100_kpa(model):
    soft = replace(ELASTOSIL_MA_4601, youngs_modulus=100e3)
    _, _, lowest = run_ramp_checked(paper_scene(model, material=soft))
    assert lowest > -0.2  # sags deep but stays shorter than the finger


@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_variable_stiffness_ratio_1_6e5(dt):
    run_ramp_checked(replace(paper_scene(variable_stiffness=True), time_step=dt))


@pytest.mark.parametrize("dt", [0.05, 0.1])
@pytest.mark.parametrize("medium", ["stokes", "water"])
def test_large_time_steps(dt, medium):
    state, _, _ = run_ramp_checked(replace(paper_scene(medium=medium), time_step=dt))
    assert state.time == pytest.approx(1.0)


def test_stiff_material_100_mpa():
    """260 times stiffer: gravity hardly bends it, so it follows its natural (gravity-free) arc closely."""
    stiff = replace(ELASTOSIL_MA_4601, youngs_modulus=100e6)
    scene = paper_scene(material=stiff)
    state, _, _ = run_ramp_checked(scene)
    finger = scene.gripper.finger
    kbar = scene.natural_curvature_rate * (scene.duration - scene.time_step)  # κ̄ of the last step
    heading = -np.concatenate([[0.0], np.cumsum(np.full(finger.n_nodes - 2, 2 * np.arctan(abs(kbar) / 2)))])
    arc_tip_z = finger.edge_length * np.sin(heading).sum()
    tip_z = Simulator(scene).world_positions(state)[0, 0, -1, 2]
    assert tip_z == pytest.approx(arc_tip_z, abs=1e-3)


def test_maximum_actuation_rate():
    """The fastest ramp the range allows within 0.1 s: κ̄ from 0 to −2 (1620° of natural curl) at −20 1/s."""
    state, substeps, _ = run_ramp_checked(replace(paper_scene(), duration=0.5), rate=-20.0)
    assert substeps <= 2 ** NewtonSettings().max_step_halvings


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_curl_past_180_degrees(model):
    """κ̄ = −0.6 asks each node for 33° (600° in all); the finger curls past 180° into a spiral (no self-contact is
    modelled) and every turning angle stays below 180°, where κ would be singular."""
    scene = replace(paper_scene(model), duration=2.0)
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(scene.n_steps):
        result = sim.step(state, -0.6)
        assert result.converged.all()
        state = result.state
    x = sim.world_positions(state)[0, 0]
    e = np.diff(x, axis=0)
    turning = np.arctan2(np.linalg.norm(np.cross(e[:-1], e[1:]), axis=1), np.sum(e[:-1] * e[1:], axis=1))
    assert turning.sum() > np.pi
    assert turning.max() < np.pi / 2


def test_natural_curvature_beyond_the_limit_is_refused():
    sim = Simulator(paper_scene())
    with pytest.raises(ValueError, match=r"natural_curvature = -2\.5 .* \[−2, 2\].* singular at a turning angle"):
        sim.step(sim.initial_state(), -2.5)


def energy_history(integrator, duration=10.0, dt=0.01):
    scene = replace(cantilever_scene(20, "accurate"), time_step=dt, integrator=integrator)
    sim = Simulator(scene)
    state = sim.initial_state()
    energy = [sim.mechanical_energy(state, 0.0)[0]]
    for _ in range(int(round(duration / dt))):
        result = sim.step(state, 0.0)
        assert result.converged.all()
        state = result.state
        energy.append(sim.mechanical_energy(state, 0.0)[0])
    return np.array(energy)


@pytest.mark.slow
def test_backward_euler_never_gains_energy_without_drag():
    energy = energy_history("backward_euler")
    swing = energy[0] - energy.min()
    assert np.all(np.diff(energy) <= 1e-9 * swing)
    assert energy[-1] < energy[0]


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki"])
def test_symplectic_integrators_keep_the_energy_bounded_without_drag(integrator):
    """Released straight (E = 0 J), the rod trades potential for elastic and kinetic energy and back. The energy
    it would release by settling, E_static, sets the scale: the midpoint rule and its compositions keep E within
    2 % of that over 10 s."""
    energy = energy_history(integrator)
    sim = Simulator(cantilever_scene(20, "accurate"))
    settled = sim.equilibrium(sim.initial_state(), 0.0).state
    scale = abs(sim.mechanical_energy(settled, 0.0)[0])
    assert scale > 1e-4
    assert np.abs(energy - energy[0]).max() <= 0.02 * scale


@pytest.mark.parametrize("friction", [math.inf, 0.3])
@pytest.mark.parametrize("model", ["planar", "3d"])
@pytest.mark.parametrize("time_step", [0.02, 0.05])
def test_grasp_in_water_at_large_steps(model, time_step, friction):
    """Fingers close on a free sphere in water (κ̄ = −0.6·t, held at −0.25) at 2 and 5 times the physics step:
    every step converges and resolves, and no node is left inside the sphere (before the coupled solve's line search,
    this diverged at Δt ≥ 0.02 s). Stuck contact holds the sphere to the end; with μ = 0.3 it slides out of this
    loose grasp, as it should."""
    from soft_gripper_env.physics import PENETRATION_TOLERANCE, Sphere

    sphere = Sphere(0.05, (0.0, 0.0, -0.1), density=1100.0, friction=friction)
    scene = replace(paper_scene(model, medium="water", grasped_object=sphere), time_step=time_step)
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(int(round(1.5 / time_step))):
        result = sim.step(state, max(-0.6 * state.time, -0.25))
        assert result.converged.all() and result.contact.resolved.all()
        state = result.state
        assert np.isfinite(state.q).all() and np.isfinite(state.body_position).all()
        distance = np.linalg.norm(sim.world_positions(state)[:, :, 2:] - state.body_position[:, None, None, :],
                                  axis=-1)
        assert distance.min() >= sphere.radius - PENETRATION_TOLERANCE
    if friction == math.inf:
        assert state.held[0].any(axis=1).all()
