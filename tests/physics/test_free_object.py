"""A free sphere moved by gravity, buoyancy, drag, added mass and the fingers' reactions (implicit coupling)."""

import math

import numpy as np
import pytest

from soft_gripper_env.physics import PENETRATION_TOLERANCE, WATER_DENSITY, Capsule, Simulator, Sphere, paper_scene
from soft_gripper_env.physics.config import replace
from soft_gripper_env.physics.rigid_body import SPHERE_DRAG_COEFFICIENT


def run(scene, steps, curvature=lambda t: 0.0, batch_size=1):
    """Steps the scene, checking every step; returns the last state and result and the body's velocity history."""
    sim = Simulator(scene, batch_size)
    state = sim.initial_state()
    velocities = []
    for _ in range(steps):
        result = sim.step(state, curvature(state.time))
        assert result.converged.all() and result.contact.resolved.all()
        state = result.state
        assert np.isfinite(state.q).all() and np.isfinite(state.body_position).all()
        distance = np.linalg.norm(sim.world_positions(state) - state.body_position[:, None, None, :], axis=-1)
        assert distance.min() >= scene.grasped_object.radius - PENETRATION_TOLERANCE
        assert np.all(result.contact.normal_reaction[state.held] >= 0)
        velocities.append(state.body_velocity[0].copy())
    return sim, state, result, np.array(velocities)


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_released_object_sinks_at_terminal_speed(model):
    radius, density = 0.03, 1200.0
    scene = paper_scene(model, medium="water", grasped_object=Sphere(radius, (0.0, 0.0, -0.6), density=density))
    _, state, result, _ = run(scene, 200)
    # ½·ρ_w·C_d·π·R²·v² = (ρ − ρ_w)·(4/3)·π·R³·g
    terminal = math.sqrt(8 * radius * (density - WATER_DENSITY) * 9.81 / (3 * WATER_DENSITY * SPHERE_DRAG_COEFFICIENT))
    assert -state.body_velocity[0, 2] == pytest.approx(terminal, rel=0.02)
    assert not result.contact.held.any()


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_thrown_sphere_bounces_off_a_finger(model):
    """A neutrally buoyant sphere (as light as the water it displaces) thrown up at finger 1 at 1 m/s, Δt = 0.01 s:
    the finger stops it and throws it back down; every step converges and no force blows up."""
    sphere = Sphere(0.03, (0.12, 0.0, -0.1), density=WATER_DENSITY, velocity=(0.0, 0.0, 1.0))
    scene = replace(paper_scene(model, medium="water", grasped_object=sphere), duration=0.6)
    sim = Simulator(scene)
    state = sim.initial_state()
    touched, largest = False, 0.0
    for _ in range(60):
        result = sim.step(state, 0.0)
        assert result.converged.all() and result.contact.resolved.all()
        state = result.state
        touched |= bool(state.held.any())
        largest = max(largest, float(np.abs(result.contact.reaction).max()))
    assert touched
    assert state.body_velocity[0, 2] < -0.05  # on its way back down
    assert largest < 10.0  # the impact on a 0.11 kg sphere at 1 m/s stays a few newtons


@pytest.fixture(scope="module")
def grasp():
    """Three fingers close on a sphere slightly heavier than water and hold it below the palm (the palm itself is
    not a contact surface): κ̄ ramps at −0.6 1/s to −0.25 and stays there; 3.5 s."""
    sphere = Sphere(0.05, (0.0, 0.0, -0.1), density=1100.0)
    runs = {model: run(paper_scene(model, medium="water", grasped_object=sphere), 350,
                       lambda t: max(-0.6 * t, -0.25)) for model in ("planar", "3d")}
    return sphere, runs


def test_held_object_balances_its_net_weight(grasp):
    sphere, runs = grasp
    volume = 4 / 3 * math.pi * sphere.radius**3
    net_weight = (sphere.density - WATER_DENSITY) * volume * 9.81
    for _, _, result, velocities in runs.values():
        assert result.contact.held[0].any(axis=1).all()  # all three fingers hold it
        assert np.abs(velocities[-1]).max() < 1e-3  # at rest
        total = result.contact.total_reaction[0]
        assert total[2] == pytest.approx(-net_weight, rel=0.02)
        assert np.abs(total[:2]).max() < 0.02 * net_weight


def test_planar_and_3d_agree_with_a_free_sphere_on_the_axis():
    """Over the first 0.6 s of the grasp, fingertip contact included. Later the 3-D fingertips, squeezing the sphere
    harder than their lateral stiffness resists, let it spin about the vertical axis (f·R > k·R², a squeezed marble
    popping out), which the planar model, its body's rotation locked by three finger planes, cannot do."""
    sphere = Sphere(0.05, (0.0, 0.0, -0.1), density=1100.0)
    runs = {model: run(paper_scene(model, medium="water", grasped_object=sphere), 60, lambda t: -0.6 * t)
            for model in ("planar", "3d")}
    (sim_p, planar, _, _), (sim_3, spatial, _, _) = runs["planar"], runs["3d"]
    assert planar.held.any()
    np.testing.assert_allclose(planar.body_position, spatial.body_position, atol=1e-6)
    assert np.abs(sim_p.world_positions(planar) - sim_3.world_positions(spatial)).max() < 1e-6
    np.testing.assert_array_equal(planar.held, spatial.held)


def test_free_sphere_batch_members_are_independent():
    sphere = Sphere(0.05, (0.0, 0.0, -0.1), density=1100.0)
    scene = paper_scene("planar", medium="water", grasped_object=sphere)
    rates = np.array([-0.6, -0.3])
    batched = Simulator(scene, batch_size=2)
    state = batched.initial_state()
    single = Simulator(scene)
    alone = single.initial_state()
    for _ in range(80):
        state = batched.step(state, (rates * state.time)[:, None] * np.ones(3)).state
        alone = single.step(alone, rates[1] * alone.time).state
    np.testing.assert_array_equal(state.q[1], alone.q[0])
    np.testing.assert_array_equal(state.body_position[1], alone.body_position[0])


@pytest.mark.parametrize("make, pattern", [
    (lambda: Sphere(0.05, (0, 0, 0), velocity=(0, 0, 1)), r"Sphere\.velocity needs Sphere\.density"),
    (lambda: Capsule(0.02, (0, 0, 0), (0, 0, 0.1), velocity=(1, 0, 0)), r"Capsule\.velocity needs Capsule\.density"),
    (lambda: Capsule(0.02, (0, 0, 0), (0, 0, 0.1), density=0.0), r"Capsule\.density = 0\.0 kg/m³"),
    (lambda: Sphere(0.05, (0, 0, 0), density=-1.0), r"Sphere\.density = -1\.0 kg/m³"),
    (lambda: Sphere(0.05, (0, 0, 0), density=1000.0, velocity=(0, 1)), r"Sphere\.velocity = \(0, 1\) must have 3"),
])
def test_bad_free_sphere_raises(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()


def test_free_capsule_sinks_broadside_without_turning():
    """Horizontal in still water: (m − ρ_w·V)·g = (½·ρ_w·C_n·D·h + ½·ρ_w·C_d·π·r²)·v² (cylinder plus end caps)."""
    radius, length, density = 0.02, 0.1, 1300.0
    capsule = Capsule(radius, (-length / 2, 0.0, -0.6), (length / 2, 0.0, -0.6), density=density)
    sim = Simulator(paper_scene("3d", medium="water", grasped_object=capsule))
    state = sim.initial_state()
    for _ in range(200):
        result = sim.step(state, 0.0)
        assert result.converged.all()
        state = result.state
    volume = math.pi * radius**2 * length + 4 / 3 * math.pi * radius**3
    drag = 0.5 * WATER_DENSITY * (1.2 * 2 * radius * length + SPHERE_DRAG_COEFFICIENT * math.pi * radius**2)
    terminal = math.sqrt((density - WATER_DENSITY) * volume * 9.81 / drag)
    assert -state.body_velocity[0, 2] == pytest.approx(terminal, rel=0.02)
    np.testing.assert_allclose(state.body_orientation[0], np.eye(3), atol=1e-9)


def test_fingers_close_on_a_free_capsule():
    """A capsule across the gripper, slightly heavier than water: every step converges with compressive holds on
    its surface and no penetration, and the fingers hold it."""
    from soft_gripper_env.physics.contact import closest_points

    capsule = Capsule(0.04, (0.0, -0.05, -0.1), (0.0, 0.05, -0.1), density=1100.0)
    sim = Simulator(paper_scene("3d", medium="water", grasped_object=capsule))
    state = sim.initial_state()
    for _ in range(150):
        result = sim.step(state, max(-0.6 * state.time, -0.25))
        assert result.converged.all() and result.contact.resolved.all()
        state = result.state
        ends = [np.repeat(state.body_position + state.body_orientation @ p, 3, axis=0) for p in sim._body.segment]
        x = sim.world_positions(state)[0]
        distance = np.linalg.norm(x - closest_points(x, ends[0], ends[1]), axis=-1)
        assert distance.min() >= capsule.radius - PENETRATION_TOLERANCE
        np.testing.assert_allclose(distance[state.held[0]], capsule.radius, atol=1e-9)
        assert np.all(result.contact.normal_reaction[state.held] >= 0)
    assert state.held[0].any(axis=1).all()  # every finger holds it
