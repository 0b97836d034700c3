"""Contact between the fingers of one gripper (kernels/finger_contact.py): fingers closed on nothing come to rest
finger on finger, the penalty and its friction against closed forms, planar = 3-D."""

from __future__ import annotations

import math

import numpy as np
import pytest

from soft_gripper_env.physics import PENETRATION_TOLERANCE, Simulator, Sphere
from soft_gripper_env.physics.kernels.contact import STICK_SPEED, distance_to_segment
from soft_gripper_env.physics.kernels.finger_contact import (
    FingerContact,
    find_near_fingers,
    finger_contact_rod,
    finger_scratch,
)
from soft_gripper_env.physics.scene.design import ELASTOSIL_MA_4601, FingerDesign, GripperDesign, paper_finger
from soft_gripper_env.physics.scene.forces import Gravity, fluid_forces
from soft_gripper_env.physics.scene.objects import ContactSettings
from soft_gripper_env.physics.scene.scene import Scene

FULL_ACTUATION = -0.2
"""The env's largest natural curvature, at which fingers closed on nothing meet past the gripper's axis."""


def _scratch(contact: FingerContact):
    """The contact kernels' work arrays for ``contact``'s fingers."""
    return finger_scratch(contact.eligible.shape[0], contact.eligible.shape[1])


def _surface_gap(positions: np.ndarray, radius: np.ndarray) -> float:
    """The least distance between two fingers' surfaces [m] (negative: overlap), away from the shared roots, from
    world node positions (F, N, 3), computed here node against edge."""
    n_fingers, n_nodes, _ = positions.shape
    nearest = np.empty(3)
    gap = math.inf
    for f in range(n_fingers):
        for o in range(n_fingers):
            if o != f:
                for i in range(4, n_nodes):  # nodes 0–3 share the palm with the other fingers' roots
                    for j in range(3, n_nodes - 1):
                        distance = distance_to_segment(positions[f, i], positions[o, j], positions[o, j + 1], nearest)
                        gap = min(gap, distance - radius[i] - max(radius[j], radius[j + 1]))
    return gap


def _close_on_nothing(model: str, stiffness: float, dt: float = 0.01, duration: float = 2.0):
    """The env's gripper in water, ramped to full actuation over 1 s and held: the surface gap after every step, and
    whether every step converged."""
    scene = Scene(gripper=GripperDesign(paper_finger()), forces=(Gravity(),) + fluid_forces("water"), model=model,
                  time_step=dt, contact=ContactSettings(finger_contact_stiffness=stiffness))
    sim = Simulator(scene)
    state = sim.initial_state()
    gaps, converged = [], True
    for _ in range(int(round(duration / dt))):
        result = sim.step(state, FULL_ACTUATION * min(state.time / 1.0, 1.0))
        state = result.state
        converged &= bool(result.converged.all())
        gaps.append(_surface_gap(sim.world_positions(state)[0], sim.disc.node_radius))
    return np.array(gaps), converged, sim.world_positions(state)[0]


@pytest.fixture(scope="module")
def closed():
    return {model: _close_on_nothing(model, ContactSettings().finger_contact_stiffness) for model in ("planar", "3d")}


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_fingers_closed_on_nothing_never_overlap(closed, model):
    """At full actuation the fingers come to rest on each other: their surfaces overlap by less than 1 mm (the
    penalty's 0.5 mm per newton), where without finger contact they pass through each other by centimetres."""
    gaps, converged, _ = closed[model]
    assert converged
    assert gaps.min() > -1.0e-3
    assert gaps[-1] < 0.0  # they do touch
    through, _, _ = _close_on_nothing(model, 0.0, duration=1.2)
    assert through.min() < -0.03


def test_closed_on_nothing_planar_equals_3d(closed):
    """The scene is symmetric about each finger's plane, so the planar and 3-D models agree on it."""
    planar, three_d = closed["planar"][2], closed["3d"][2]
    assert np.abs(planar - three_d).max() < 1e-3


@pytest.mark.parametrize("dt, deepest", [(0.02, 1.0e-3), (0.05, 1.25e-3)])
def test_closed_on_nothing_converges_at_long_steps(dt, deepest):
    """At 8 and 20 times the 2.5 ms default step every step converges and the penalty still keeps the fingers apart:
    the deepest overlap is 0.75 mm at 20 ms as at 10 ms, and 1.02 mm at 50 ms, where the fingers meet while the
    actuation still ramps (the penalty's 0.5 mm per newton), against centimetres without it."""
    gaps, converged, _ = _close_on_nothing("planar", ContactSettings().finger_contact_stiffness, dt=dt)
    assert converged
    assert gaps.min() > -deepest


def _two_opposed_fingers(stiffness=2000.0, friction=0.3):
    """Two straight 3-D fingers pointing along +x and −x, and their contact constants."""
    finger = FingerDesign(length=0.2, n_nodes=20, radius=0.01, material=ELASTOSIL_MA_4601)
    scene = Scene(gripper=GripperDesign(finger, finger_angles=(0.0, math.pi)), model="3d")
    disc = scene.discretization()
    return disc, FingerContact.of(disc, stiffness, friction, first_free_node=2)


def test_straight_fingers_at_their_shared_root_do_not_touch():
    """Fingers share the palm at their roots: the pairs that overlap when straight never count."""
    disc, contact = _two_opposed_fingers()
    assert contact.eligible.any()
    assert not contact.eligible[:, :2].any()  # clamped nodes
    # nodes 2 and 3 are 21 and 32 mm from the other's root: within and beyond two radii (20 mm) plus 10 mm
    assert not contact.eligible[0, 2, 1, 0] and contact.eligible[0, 3, 1, 0]
    paper = Scene(gripper=GripperDesign(paper_finger()), model="3d").discretization()
    roots = FingerContact.of(paper, 2000.0, 0.3, first_free_node=2).eligible
    assert not roots[0, 2:5, 1, 0].any() and roots[0, 5, 1, 0]  # 21, 32, 42 mm < 40 + 10 mm < 53 mm
    q = disc.rest_q.copy()
    near = np.empty((2, disc.n_nodes, 2), dtype=np.int64)
    find_near_fingers(q, q, contact, near, _scratch(contact))
    force = np.zeros((disc.n_nodes, disc.stride))
    band = np.zeros((disc.n_dofs, disc.band_width + 1))
    finger_contact_rod(0, q, q, q, 0.01, contact, near, True, force, band, _scratch(contact))
    assert not force.any()


@pytest.mark.parametrize("slip_speed", [0.0, 1e-4, 0.1])
def test_penalty_and_friction_against_closed_forms(slip_speed):
    """A node of finger 0 bent over finger 1 (which lies still along −x) overlaps it by δ₀ and slides along it at
    u: the normal force is k·δ₀ (the node's slip keeps its distance), and the friction is
    −μ·k·δ₀·u/√(u² + v_s²), its full μ·N for u ≫ v_s; the Newton matrix holds 2·k along the normal."""
    stiffness, friction, dt, overlap = 2000.0, 0.3, 0.01, 0.4e-3
    disc, contact = _two_opposed_fingers(stiffness, friction)
    q_old = disc.rest_q.copy()
    node = 15
    q_old[0, node, :3] = (-0.1, 0.0, 0.02 - overlap)  # two radii less the overlap above finger 1's centre line
    q = q_old.copy()
    q[0, node, 0] += slip_speed * dt
    near = np.empty((2, disc.n_nodes, 2), dtype=np.int64)
    find_near_fingers(q_old, q_old, contact, near, _scratch(contact))  # both at rest at the start of the step
    assert near[0, node, 1] >= 0
    force = np.zeros((disc.n_nodes, disc.stride))
    band = np.zeros((disc.n_dofs, disc.band_width + 1))
    finger_contact_rod(0, q, q_old, q_old, dt, contact, near, True, force, band, _scratch(contact))
    normal = stiffness * overlap
    expected_friction = -friction * normal * slip_speed / math.hypot(slip_speed, STICK_SPEED)
    assert force[node, 2] == pytest.approx(normal, rel=1e-9)
    assert force[node, 0] == pytest.approx(expected_friction, rel=1e-9, abs=1e-15)
    assert force[node, 1] == pytest.approx(0.0, abs=1e-15)
    other_nodes = np.delete(np.arange(disc.n_nodes), node)
    assert not force[other_nodes].any()
    kd = disc.band_width
    assert band[disc.stride * node + 2, kd] == pytest.approx(2.0 * stiffness, rel=1e-9)


def test_mirror_share_of_the_overlap():
    """A node that closes on a finger by Δ over the step sees the overlap grow by 2·Δ (the other finger is taken to
    close by as much), so two identical fingers closing on each other are exactly implicit."""
    stiffness, dt, start_overlap, closing = 2000.0, 0.01, 0.2e-3, 0.1e-3
    disc, contact = _two_opposed_fingers(stiffness, 0.0)
    q_old = disc.rest_q.copy()
    node = 15
    q_old[0, node, :3] = (-0.1, 0.0, 0.02 - start_overlap)
    q = q_old.copy()
    q[0, node, 2] -= closing
    near = np.empty((2, disc.n_nodes, 2), dtype=np.int64)
    find_near_fingers(q_old, q_old, contact, near, _scratch(contact))
    force = np.zeros((disc.n_nodes, disc.stride))
    band = np.zeros((disc.n_dofs, disc.band_width + 1))
    finger_contact_rod(0, q, q_old, q_old, dt, contact, near, False, force, band, _scratch(contact))
    assert force[node, 2] == pytest.approx(stiffness * (start_overlap + 2.0 * closing), rel=1e-9)


def test_resting_fingers_push_each_other_equally(closed):
    """At rest, the force finger 1 puts on finger 0 and the force finger 0 puts on finger 1, each computed from
    its own nodes against the other's surface, are equal and opposite (to 1 %), and press (about 1 N)."""
    disc = Scene(gripper=GripperDesign(paper_finger()), model="3d").discretization()
    q = np.zeros((3, disc.n_nodes, disc.stride))
    q[..., :3] = closed["3d"][2]
    contact = FingerContact.of(disc, ContactSettings().finger_contact_stiffness, 0.0, first_free_node=2)

    def force_on(a, b):
        """The total force on finger a [N] from finger b alone."""
        eligible = np.zeros_like(contact.eligible)
        eligible[a, :, b, :] = contact.eligible[a, :, b, :]
        pair = contact._replace(eligible=eligible)
        near = np.empty((3, disc.n_nodes, 3), dtype=np.int64)
        find_near_fingers(q, q, pair, near, _scratch(pair))
        force = np.zeros((disc.n_nodes, disc.stride))
        finger_contact_rod(a, q, q, q, 0.01, pair, near, False, force, np.zeros((disc.n_dofs, disc.band_width + 1)),
                           _scratch(pair))
        return force[:, :3].sum(axis=0)

    on_0, on_1 = force_on(0, 1), force_on(1, 0)
    assert np.linalg.norm(on_0) > 0.5
    assert np.linalg.norm(on_0 + on_1) < 0.01 * np.linalg.norm(on_0)


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_fingers_closed_on_a_small_object_touch_it_without_overlapping(model):
    """A fixed 6 mm sphere where the fingertips meet: all three fingers hold it, none enters it, and their surfaces
    stay clear of each other; every step converges."""
    sphere = Sphere(0.006, (0.0, 0.0, -0.124))
    scene = Scene(gripper=GripperDesign(paper_finger()), forces=(Gravity(),) + fluid_forces("water"), model=model,
                  grasped_object=sphere)
    sim = Simulator(scene)
    state = sim.initial_state()
    radius = sim.disc.node_radius
    for _ in range(200):
        result = sim.step(state, FULL_ACTUATION * min(state.time / 1.0, 1.0))
        assert result.converged.all()
        state = result.state
        positions = sim.world_positions(state)[0]
        assert _surface_gap(positions, radius) > -1.0e-3
        surface = np.linalg.norm(positions - np.asarray(sphere.center), axis=-1) - sphere.radius - radius
        assert surface[:, 2:].min() > -PENETRATION_TOLERANCE
    assert result.contact.held[0].any(axis=1).all()


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_newton_blocks_are_the_penalty_hessian_on_oblique_normals(model):
    """Each touching node's block of Newton's matrix is 2·k·n·nᵀ and its force k·δ·n (frictionless, in the rod's
    coordinates), for two nodes with different normals: one above finger 1's side, one beyond its tip (the normal
    tilts along the finger). The fingers point at 45° and 225°, so that a planar rod's coordinates mix the world's
    x and y and every entry of the world block counts."""
    stiffness, dt, overlap = 2000.0, 0.01, 0.3e-3
    finger = FingerDesign(length=0.2, n_nodes=20, radius=0.01, material=ELASTOSIL_MA_4601)
    scene = Scene(gripper=GripperDesign(finger, finger_angles=(math.pi / 4, 5 * math.pi / 4)), model=model)
    disc = scene.discretization()
    contact = FingerContact.of(disc, stiffness, 0.0, first_free_node=2)
    along, up = disc.finger_directions[0], np.array([0.0, 0.0, 1.0])
    # in finger 0's plane: (along its direction, up); finger 1 lies along −along
    directions = {14: np.array([0.0, 1.0]), 15: np.array([-0.6, 0.8])}
    anchors = {14: -0.1, 15: -finger.length}
    q_old = disc.rest_q.copy()
    for node, (a, b) in directions.items():
        world = (anchors[node] + (0.02 - overlap) * a) * along + (0.02 - overlap) * b * up
        q_old[0, node, :disc.dim] = world if model == "3d" else (world @ along, world[2])
    near = np.empty((2, disc.n_nodes, 2), dtype=np.int64)
    find_near_fingers(q_old, q_old, contact, near, _scratch(contact))
    force = np.zeros((disc.n_nodes, disc.stride))
    band = np.zeros((disc.n_dofs, disc.band_width + 1))
    finger_contact_rod(0, q_old, q_old, q_old, dt, contact, near, True, force, band, _scratch(contact))
    kd, dim = disc.band_width, disc.dim
    for node, (a, b) in directions.items():
        normal = a * along + b * up
        if model == "planar":
            normal = np.array([a, b])
        np.testing.assert_allclose(force[node, :dim], stiffness * overlap * normal, rtol=1e-9, atol=1e-15)
        first = disc.stride * node
        block = np.array([[band[first + i, kd - i + j] if j <= i else band[first + j, kd - j + i] for j in range(dim)]
                          for i in range(dim)])
        np.testing.assert_allclose(block, 2.0 * stiffness * np.outer(normal, normal), rtol=1e-9, atol=1e-9)
