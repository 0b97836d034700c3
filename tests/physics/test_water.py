"""Water: buoyancy, Morison drag and added mass, each checked against a closed form or a symmetry."""

import math
from dataclasses import replace

import numpy as np
import pytest
from test_derivatives import band_to_dense, evaluate_force_model, finite_difference_jacobian

from soft_gripper_env.physics import (
    WATER_DENSITY,
    AddedMass,
    Buoyancy,
    Current,
    FingerDesign,
    Fluid,
    Gravity,
    GripperDesign,
    Material,
    MorisonDrag,
    NewtonSettings,
    Scene,
    Simulator,
    StepContext,
    cantilever_scene,
    evaluate_force,
    paper_finger,
    paper_scene,
    run_ramp,
)
from soft_gripper_env.physics.kernels.current import CurrentBatch, current_at

CURRENT = Current(velocity=(0.05, -0.12, 0.03), oscillation=(0.02, 0.0, 0.01), period=0.7)


def random_state(disc, rng, scale=0.01):
    q = disc.rest_q[:1] + rng.normal(scale=scale, size=disc.rest_q[:1].shape)
    if disc.stride == 4:
        q[..., 3] = 0.0
    return q


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_morison_velocity_jacobian(model):
    """With the tangents held, the drag's Jacobian equals −∂f/∂v·∂v/∂q by finite differences."""
    scene = Scene(GripperDesign(paper_finger(), finger_angles=(0.4,)), forces=(), model=model)
    disc = scene.discretization()
    rng = np.random.default_rng(7)
    q_old = random_state(disc, rng)
    q = q_old + rng.normal(scale=3e-3, size=q_old.shape)  # velocities of order 0.3 m/s at Δt = 0.01 s
    drag, fluid = MorisonDrag(), Fluid(current=CURRENT)
    D, dt = disc.dim, 0.01

    def force_at(q_new):
        force = np.zeros(q.shape)
        band = np.zeros((1, disc.n_dofs, disc.band_width + 1))
        ctx = StepContext(0.3, q_old[..., :D], 1 / dt, 1 / dt**2)
        evaluate_force(drag, disc, fluid, ctx, q[..., :D], (q_new - q_old)[..., :D] / dt,
                       np.zeros_like(q[..., :D]), force[..., :D], band)
        return force.ravel(), band_to_dense(band[0])

    f0, jacobian = force_at(q)
    assert np.abs(f0).max() > 1e-3
    fd = finite_difference_jacobian(lambda x: force_at(x)[0], q, 1e-8)
    np.testing.assert_allclose(jacobian, fd, rtol=1e-5, atol=1e-7 * np.abs(jacobian).max())


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_added_mass_jacobian(model):
    scene = Scene(GripperDesign(paper_finger(), finger_angles=(1.1,)), forces=(), model=model)
    disc = scene.discretization()
    rng = np.random.default_rng(8)
    q_old = random_state(disc, rng)
    q_pred = q_old + rng.normal(scale=1e-3, size=q_old.shape)
    q = q_pred + rng.normal(scale=1e-4, size=q_old.shape)
    model_ = AddedMass()
    f0, jacobian = evaluate_force_model(model_, disc, q, q_old, q_pred, 0.01)
    assert np.abs(f0).max() > 0
    fd = finite_difference_jacobian(lambda x: evaluate_force_model(model_, disc, x, q_old, q_pred, 0.01)[0], q, 1e-7)
    np.testing.assert_allclose(jacobian, fd, rtol=1e-6, atol=1e-9 * np.abs(jacobian).max())
    # the added-mass matrix is positive semi-definite: it only ever adds inertia
    assert np.linalg.eigvalsh(jacobian).min() > -1e-9 * np.abs(jacobian).max()


def finger_scene(density, forces, model="planar", clamp="paper", n_nodes=20, angles=(0.0,)):
    material = Material("test", youngs_modulus=386.66e3, density=density)
    finger = FingerDesign(0.2, n_nodes, 0.02, material, clamp)
    return Scene(GripperDesign(finger, finger_angles=angles), forces=forces, model=model,
                 newton=NewtonSettings(relative_tolerance=1e-10))


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_neutrally_buoyant_finger_stays_straight(model):
    scene = finger_scene(WATER_DENSITY, (Gravity(), Buoyancy(), MorisonDrag(), AddedMass()), model)
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(100):
        result = sim.step(state, 0.0)
        assert result.converged.all()
        state = result.state
    assert np.abs(sim.world_positions(state)[..., 2]).max() <= 1e-9


def test_light_finger_mirrors_heavy_finger():
    """ρ = 900 kg/m³ in water lifts as far as a finger of density ρ_w − ρ = 100 kg/m³ sags in air."""
    light = finger_scene(900.0, (Gravity(), Buoyancy()))
    heavy = finger_scene(WATER_DENSITY - 900.0, (Gravity(),))
    tips = []
    for scene in (light, heavy):
        sim = Simulator(scene)
        result = sim.equilibrium(sim.initial_state(), 0.0)
        assert result.converged.all()
        tips.append(sim.world_positions(result.state)[0, 0])
    assert tips[0][-1, 2] > 1e-3
    np.testing.assert_allclose(tips[0][:, 2], -tips[1][:, 2], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(tips[0][:, 0], tips[1][:, 0], rtol=1e-10)


def test_free_rod_sinks_broadside_at_terminal_speed():
    density, radius = 1500.0, 0.01
    scene = Scene(GripperDesign(FingerDesign(0.2, 20, radius, Material("rod", 386.66e3, density), "free"),
                                finger_angles=(0.0,)),
                  forces=(Gravity(), Buoyancy(), MorisonDrag(), AddedMass()), model="planar")
    diameter = 2 * radius
    # ½·ρ_w·C_n·D·v² = (ρ − ρ_w)·(π·D²/4)·g per unit length
    terminal = math.sqrt((density - WATER_DENSITY) * math.pi * diameter**2 / 4 * 9.81
                         / (0.5 * WATER_DENSITY * 1.2 * diameter))
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(300):
        state = sim.step(state, 0.0).state
    velocity = state.velocity[0, 0]
    assert np.abs(velocity[:, 0]).max() < 1e-6 * terminal  # sinks broadside, no drift along the rod
    assert -velocity[:, 1].mean() == pytest.approx(terminal, rel=0.02)
    assert np.ptp(velocity[:, 1]) < 1e-6  # and stays straight


def first_mode_period(scene, dt=1e-3, duration=0.8):
    """Period [s] of the tip's free vibration after release from a small static bend, by zero crossings."""
    sim = Simulator(replace(scene, time_step=dt))
    state = sim.equilibrium(sim.initial_state(), 0.01).state
    z = []
    for _ in range(int(duration / dt)):
        state = sim.step(state, 0.0).state
        z.append(sim.world_positions(state)[0, 0, -1, 2])
    z = np.array(z)
    t = dt * np.arange(1, len(z) + 1)
    crossings = [t[i] - z[i] * dt / (z[i + 1] - z[i]) for i in range(len(z) - 1) if z[i] * z[i + 1] < 0]
    assert len(crossings) >= 3
    return 2 * np.mean(np.diff(crossings))


def test_added_mass_lowers_first_mode_frequency():
    air = replace(cantilever_scene(20, "accurate"), forces=())
    water = replace(air, forces=(AddedMass(),))
    density = air.gripper.finger.material.density
    expected = math.sqrt(density / (density + WATER_DENSITY))  # m/(m + m_a), same cross-section
    ratio = first_mode_period(air) / first_mode_period(water)
    assert ratio == pytest.approx(expected, rel=0.03)
    assert 1 / first_mode_period(air) == pytest.approx(5.0, rel=0.15)  # ``docs/model.md`` §4: about 5 Hz


def test_cross_current_pushes_finger_downstream():
    current = Current(velocity=(0.0, 0.3, 0.0))
    scene = replace(paper_scene("3d"), forces=(Gravity(), Buoyancy(), MorisonDrag(), AddedMass()),
                    fluid=Fluid(current=current))
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(60):
        state = sim.step(state, 0.0).state
    tip_y = sim.world_positions(state)[0, 0, -1, 1]
    assert tip_y > 1e-3  # finger 0 points along +x; the current flows along +y


def test_drag_reverses_with_relative_velocity_and_vanishes_with_the_water():
    disc = replace(paper_scene("3d"), gripper=GripperDesign(paper_finger(), finger_angles=(0.3,))).discretization()
    q = disc.rest_q[:1]
    velocity = np.broadcast_to(np.array([0.1, -0.25, 0.2]), (1, disc.n_nodes, 3))

    def drag_force(current_velocity, node_velocity):
        force = np.zeros(q.shape)
        band = np.zeros((1, disc.n_dofs, disc.band_width + 1))
        ctx = StepContext(0.0, q[..., :3], 100.0, 1e4)
        evaluate_force(MorisonDrag(), disc, Fluid(current=Current(velocity=current_velocity)), ctx, q[..., :3],
                       node_velocity, np.zeros_like(node_velocity), force[..., :3], band)
        return force

    still = np.zeros_like(velocity)
    forward = drag_force((0.1, -0.25, 0.2), still)
    assert np.abs(forward).max() > 1e-3
    np.testing.assert_allclose(drag_force((-0.1, 0.25, -0.2), still), -forward, rtol=1e-12)
    np.testing.assert_allclose(drag_force((0.0, 0.0, 0.0), -velocity), forward, rtol=1e-12)  # only relative counts
    assert np.abs(drag_force((0.1, -0.25, 0.2), velocity)).max() == 0.0


@pytest.mark.parametrize("model", ["planar", "3d"])
@pytest.mark.parametrize("dt", [0.01, 0.05])
def test_newton_converges_on_paper_ramp_in_water(model, dt):
    scene = replace(paper_scene(model, medium="water"), time_step=dt)
    run = run_ramp(scene)
    assert run.converged.all()
    assert run.newton_iterations.max() <= 6
    assert run.positions[-1, 0, 0, -1, 2] < -0.1  # the fingers still close


def test_water_medium_lists_only_fluid_forces_it_uses():
    assert [type(f).__name__ for f in paper_scene(medium="air").forces] == ["Gravity"]
    assert [type(f).__name__ for f in paper_scene(medium="water").forces] == ["Gravity", "Buoyancy", "MorisonDrag",
                                                                              "AddedMass"]


@pytest.mark.parametrize("make, pattern", [
    (lambda: MorisonDrag(normal_coefficient=-1.0), r"MorisonDrag\.normal_coefficient = -1\.0"),
    (lambda: Fluid(current=(0, 1, 0)), r"Fluid\.current must be a Current"),
    (lambda: Fluid(density=float("nan")), r"Fluid\.density = nan kg/m³"),
    (lambda: AddedMass(sphere_coefficient=-0.5), r"AddedMass\.sphere_coefficient = -0\.5"),
    (lambda: Current(velocity=(0.0, 1.0)), r"Current\.velocity = \(0\.0, 1\.0\) must have 3 components"),
    (lambda: Current(period=0.0), r"Current\.period = 0\.0 s"),
    (lambda: Current(phase=float("nan")), r"Current\.phase = nan rad"),
    (lambda: Current(velocity=(0.0, float("inf"), 0.0)), r"Current\.velocity = inf m/s"),
])
def test_bad_water_parameters_raise(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()


def test_current_phase_and_each_grippers_clock():
    current = Current(velocity=(0.1, 0.0, 0.0), oscillation=(0.0, 0.2, 0.0), period=2.0, phase=0.5)
    np.testing.assert_allclose(current_at(current, 0.25), [0.1, 0.2 * math.sin(2 * math.pi * 0.125 + 0.5), 0.0],
                               rtol=1e-15)
    batch = CurrentBatch.of([current, current])
    # remembered, then forgotten below
    np.testing.assert_allclose(batch.at(1.0)[1], current_at(current, 1.0), rtol=1e-15)
    batch.set_clock(1, 0.75)  # gripper 1's episode began at batch time 0.75 s
    np.testing.assert_allclose(batch.at(1.0)[1], current_at(current, 0.25), rtol=1e-14)
    np.testing.assert_allclose(batch.at(1.0)[0], current_at(current, 1.0), rtol=1e-15)
    batch.load(0, Current(velocity=(0.3, 0.0, 0.0)))  # a new current is not read from memory either
    np.testing.assert_allclose(batch.at(1.0)[0], [0.3, 0.0, 0.0], rtol=1e-15)


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_dissipative_forces_add_no_potential_energy(model):
    """Drag, added mass and damping have no potential: a bent finger's mechanical energy in water with all of them
    equals its energy with only gravity and buoyancy, and the buoyancy's potential is the weight's times −ρ_w/ρ."""
    from soft_gripper_env.physics import MassProportionalDamping, StokesDrag

    water = paper_scene(model, medium="water")
    water = replace(water, forces=water.forces + (MassProportionalDamping(), StokesDrag()))
    sim = Simulator(water)
    state = sim.initial_state()
    for _ in range(20):
        state = sim.step(state, -0.15 * state.time).state
    conservative = replace(water, forces=tuple(f for f in water.forces if isinstance(f, (Gravity, Buoyancy))))
    energy = sim.mechanical_energy(state, -0.4)
    np.testing.assert_allclose(energy, Simulator(conservative).mechanical_energy(state, -0.4), rtol=1e-12)
    weight_only = replace(water, forces=(Gravity(),))
    buoyancy_only = replace(water, forces=(Buoyancy(),))
    elastic = Simulator(replace(water, forces=())).mechanical_energy(state, -0.4)
    gravity_part = Simulator(weight_only).mechanical_energy(state, -0.4) - elastic
    buoyancy_part = Simulator(buoyancy_only).mechanical_energy(state, -0.4) - elastic
    density = water.gripper.finger.material.density
    np.testing.assert_allclose(buoyancy_part, -gravity_part * WATER_DENSITY / density, rtol=1e-9)
    assert np.abs(gravity_part).min() > 0


def test_a_gust_is_a_smooth_pulse_on_the_current_and_runs_on_each_grippers_clock():
    """u(t) = mean + oscillation + gust·sin²(π(t − t₀)/T) on [t₀, t₀ + T], closed form; it starts and ends at zero
    with zero slope (the water's acceleration stays finite and continuous), and in a batch each gripper's gust runs
    on its own clock."""
    gust = Current(velocity=(0.01, 0.0, 0.0), gust_velocity=(0.0, 0.12, 0.0), gust_start=2.0, gust_duration=0.5)
    for t in (1.9, 2.0, 2.1, 2.25, 2.4, 2.5, 2.6):
        inside = 2.0 <= t <= 2.5
        expected = np.array([0.01, 0.12 * np.sin(np.pi * (t - 2.0) / 0.5) ** 2 if inside else 0.0, 0.0])
        np.testing.assert_allclose(current_at(gust, t), expected, atol=1e-15)
    for edge in (2.0, 2.5):  # no jump in the acceleration at either end
        slope = (current_at(gust, edge + 1e-6) - current_at(gust, edge - 1e-6)) / 2e-6
        assert abs(slope[1]) < 1e-4
    batch = CurrentBatch.of((gust, gust, Current()))
    batch.set_clock(1, 1.0)  # gripper 1's episode began at batch time 1 s
    at = batch.at(2.25)
    np.testing.assert_allclose(at[0], [0.01, 0.12, 0.0], atol=1e-15)
    np.testing.assert_allclose(at[1], [0.01, 0.0, 0.0], atol=1e-15)  # its clock reads 1.25 s: no gust yet
    np.testing.assert_allclose(at[2], 0.0)
    np.testing.assert_allclose(batch.at(3.25)[1], [0.01, 0.12, 0.0], atol=1e-15)
    with pytest.raises(ValueError, match=r"Current\.gust_duration = -1\.0 s is outside"):
        Current(gust_duration=-1.0)
