"""The palm: a disc in the plane of the finger bases that only pushes, continuously, with Coulomb friction."""

import math
from dataclasses import replace

import numpy as np
import pytest

from soft_gripper_env.physics import (
    WATER,
    WATER_DENSITY,
    ContactSettings,
    Current,
    Fluid,
    Simulator,
    Sphere,
    paper_scene,
)
from soft_gripper_env.physics.kernels.body import BodyMotion, BodyState, body_residual
from soft_gripper_env.physics.kernels.contact import STICK_SPEED
from soft_gripper_env.physics.scene.forces import BodyLoads, fluid_forces
from soft_gripper_env.physics.simulator import BodyModel

RADIUS, DENSITY = 0.04, 800.0


def body_model(contact=None, density=DENSITY):
    """One free sphere under the palm, in water, as the kernels see it."""
    model = BodyModel(BodyLoads.total(fluid_forces("water"), WATER), 1, contact or ContactSettings())
    model.load(0, Sphere(RADIUS, (0.0, 0.0, -0.1), density=density))
    return model


def palm_force(model, overlap, vertical_speed, dt=0.01):
    """The force of the sphere on the palm [N] (3,), with its top ``overlap`` [m] above the palm and rising at
    ``vertical_speed`` [m/s] over the step."""
    c = np.array([[0.0, 0.0, overlap - RADIUS]])
    c_old = c - np.array([[0.0, 0.0, vertical_speed * dt]])
    eye = np.eye(3)[None]
    return model.palm_reaction(c, c_old, np.zeros((1, 3)), eye, eye, dt)[0]


@pytest.mark.parametrize("speed", [0.02, 0.05, 0.1])
def test_the_palm_never_pulls_a_separating_body(speed):
    """1 mm of overlap while separating at 0.02–0.1 m/s: critical damping on the full overlap would pull (with
    0.12–4.6 N, as the law before this one did); the palm's force is compressive or zero."""
    model = body_model()
    mass = model.mass[0] + model.added_mass[0, 2, 2]
    stiffness = ContactSettings().palm_stiffness
    pulls_without_clamp = stiffness * 1e-3 - 2 * math.sqrt(stiffness * mass) * speed
    force = palm_force(model, 1e-3, -speed)
    assert force[2] >= 0.0
    if pulls_without_clamp < 0:
        assert force[2] == 0.0


def test_the_palm_force_is_continuous_at_first_touch():
    """At first touch the force grows from zero however fast the body arrives: the damping grows with the
    overlap (no jump), and at rest the force is the spring's k·δ."""
    model = body_model()
    stiffness = ContactSettings().palm_stiffness
    for speed in (0.0, 0.1, 1.0):
        assert palm_force(model, -1e-9, speed)[2] == 0.0
        assert 0.0 <= palm_force(model, 1e-9, speed)[2] < 1e-4
    assert palm_force(model, 2e-3, 0.0)[2] == pytest.approx(stiffness * 2e-3, rel=1e-12)
    overlaps = np.linspace(1e-6, 3e-3, 200)
    forces = np.array([palm_force(model, d, 0.05)[2] for d in overlaps])
    assert np.all(np.diff(forces) > 0)  # monotone in the overlap, no step where the damping switches on


def _residual(model, motion, dt):
    """The body's residual and Newton matrix; a sphere's loads do not depend on its orientation, so R = I serves."""
    residual, matrix = np.empty(6), np.empty((6, 6))
    body_residual(0, model.arrays(), motion, np.eye(3), dt, residual, matrix)
    return residual, matrix


@pytest.mark.parametrize("friction", [0.0, 0.3, 2.0])
def test_the_body_jacobian_with_palm_friction_matches_finite_differences(friction):
    """The body's Newton matrix, palm push and friction included, is the derivative of its residual by the centre
    and the rotation over the step (a sphere sliding and turning against the palm in a current)."""
    model = body_model(ContactSettings(palm_friction=friction))
    dt = 0.01
    old = BodyState(np.array([[0.002, -0.001, 1.2e-3 - RADIUS]]), np.array([[0.03, -0.02, 0.01]]),
                    np.eye(3)[None].copy(), np.array([[0.5, -0.3, 0.8]]))
    y = np.array([0.0025, -0.0013, 1.5e-3 - RADIUS, 0.004, -0.002, 0.006])

    def motion_at(y):
        return BodyMotion(y[None, :3].copy(), y[None, 3:].copy(), np.empty((1, 3, 3)), old,
                          np.array([[0.1, 0.05, 0.0]]), np.array([[0.2, 0.0, -0.1]]))

    _, matrix = _residual(model, motion_at(y), dt)
    numeric = np.empty((6, 6))
    h = 1e-8
    for m in range(6):
        step = np.zeros(6)
        step[m] = h
        numeric[:, m] = (_residual(model, motion_at(y + step), dt)[0] - _residual(model, motion_at(y - step), dt)[0]) \
            / (2 * h)
    np.testing.assert_allclose(matrix, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


def _floating_sphere_in_a_current(friction):
    """A buoyant sphere pressed up against the palm, at the axis, with a 5 cm/s current along x; 2 s. The fingers
    lie in the palm's plane at first; contact on their centre lines keeps them off the sphere."""
    sphere = Sphere(RADIUS, (0.0, 0.0, -RADIUS), density=DENSITY)
    scene = paper_scene("3d", medium="water", grasped_object=sphere)
    scene = replace(scene, fluid=Fluid(current=Current((0.05, 0.0, 0.0))),
                    contact=ContactSettings(palm_friction=friction, palm_radius=1.0, finger_thickness=False))
    sim = Simulator(scene)
    state = sim.initial_state()
    for _ in range(200):
        result = sim.step(state, 0.0)
        assert result.converged.all()
        state = result.state
    return state, result


def test_a_floating_sphere_rolls_along_a_frictional_palm_and_slides_along_a_frictionless_one():
    """Pressed against the palm by its buoyancy ((ρ_w − ρ)·V·g = 0.53 N) and carried by a current, a sphere on a
    frictional palm rolls without slipping (its point on the palm is still: u + ω × a = 0 to within the stick
    speed) while on a frictionless one it slides without turning. The palm pushes with the net buoyancy."""
    lift = (WATER_DENSITY - DENSITY) * 4 / 3 * math.pi * RADIUS**3 * 9.81
    state, result = _floating_sphere_in_a_current(ContactSettings().palm_friction)
    u, omega = state.body_velocity[0], state.body_angular_velocity[0]
    contact_point_velocity = u + np.cross(omega, [0.0, 0.0, RADIUS])
    assert u[0] > 0.005  # carried along
    assert abs(contact_point_velocity[0]) < 2 * STICK_SPEED
    assert omega[1] < -0.1  # rolling: ω_y = −u_x/R
    assert result.contact.palm_reaction[0, 2] == pytest.approx(lift, rel=0.02)
    state, _ = _floating_sphere_in_a_current(0.0)
    assert np.abs(state.body_angular_velocity[0]).max() < 1e-9
    assert state.body_velocity[0, 0] > u[0]  # nothing holds it back
