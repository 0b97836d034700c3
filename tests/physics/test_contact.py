"""Contact with fixed objects (the paper's ball, a capsule): compression only, no penetration, bounded corrector."""

import math
from dataclasses import replace

import numpy as np
import pytest

from soft_gripper_env.physics import (
    ELASTOSIL_MA_4601,
    PAPER_BALL,
    PENETRATION_ACCELERATION,
    PENETRATION_TOLERANCE,
    SOFT_TRANSLUCENT_SILICONE,
    Capsule,
    ContactSettings,
    Simulator,
    Sphere,
    paper_scene,
    penetration_tolerance,
    run_ramp,
)
from soft_gripper_env.physics.kernels.contact import contact_reactions, object_in_rod_frames, within_reach


def reachable(obj, finger_directions, length, planar):
    """Which fingers the corrector searches for contact with ``obj`` (on the fingers' centre lines)."""
    reach = np.empty(finger_directions.shape[0], dtype=bool)
    within_reach(*object_in_rod_frames(obj, finger_directions, np.zeros(20), planar), length, reach)
    return reach


def segment_distance(points, start, end):
    """Distance [m] of each point (R, N, 3) from its rod's segment start–end (R, 3), computed here apart from the
    contact kernels."""
    axis = end - start
    length2 = np.maximum(np.sum(axis**2, axis=-1), 1e-300)
    along = np.einsum("rnd,rd->rn", points - start[:, None, :], axis) / length2[:, None]
    nearest = start[:, None, :] + np.clip(along, 0.0, 1.0)[..., None] * axis[:, None, :]
    return np.linalg.norm(points - nearest, axis=-1)


@pytest.fixture(scope="module")
def ball_runs():
    return {(model, material.name): run_ramp(paper_scene(model, material=material, grasped_object=PAPER_BALL))
            for model in ("planar", "3d") for material in (ELASTOSIL_MA_4601, SOFT_TRANSLUCENT_SILICONE)}


def test_fingers_touch_the_ball(ball_runs):
    for run in ball_runs.values():
        held_steps = [report.held.any() for report in run.contacts]
        assert any(held_steps)
        assert run.converged.all()


def test_no_adhesive_normal_reaction(ball_runs):
    for run in ball_runs.values():
        for report in run.contacts:
            assert report.resolved.all()
            assert np.all(report.normal_reaction[report.held] >= 0.0)
            assert np.all(report.reaction[~report.held] == 0.0)
        assert max(report.normal_reaction.max() for report in run.contacts) > 0.1


def test_no_penetration_beyond_tolerance(ball_runs):
    for run in ball_runs.values():
        distance = np.linalg.norm(run.positions - np.asarray(PAPER_BALL.center), axis=-1)
        assert distance.min() >= PAPER_BALL.radius - PENETRATION_TOLERANCE


def test_corrector_iterations_are_bounded_and_reported(ball_runs):
    counts = np.concatenate([[r.corrector_iterations[0] for r in run.contacts] for run in ball_runs.values()])
    assert counts.max() <= ContactSettings().max_corrector_iterations
    assert counts.max() >= 1  # new contacts really are re-solved
    # at most a few re-solves per step on the paper's ball (reported in the issue notes)
    assert counts.max() <= 4


def test_reactions_identical_up_to_rotation(ball_runs):
    run = ball_runs[("3d", ELASTOSIL_MA_4601.name)]
    for report in run.contacts:
        for k, angle in enumerate(paper_scene().gripper.finger_angles):
            c, s = math.cos(-angle), math.sin(-angle)
            rotation = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
            np.testing.assert_array_equal(report.held[0, k], report.held[0, 0])
            np.testing.assert_allclose(report.reaction[0, k] @ rotation.T, report.reaction[0, 0], atol=1e-8)


@pytest.mark.parametrize("material", [ELASTOSIL_MA_4601, SOFT_TRANSLUCENT_SILICONE])
def test_planar_and_3d_agree_with_the_ball_on_axis(ball_runs, material):
    planar, spatial = ball_runs[("planar", material.name)], ball_runs[("3d", material.name)]
    assert np.abs(planar.positions - spatial.positions).max() <= 1e-6
    for a, b in zip(planar.contacts, spatial.contacts, strict=True):
        np.testing.assert_array_equal(a.held, b.held)
        np.testing.assert_allclose(a.reaction, b.reaction, atol=1e-4)


def test_reaction_balances_the_held_nodes_equations_of_motion():
    """At a node held since the previous step (at rest), the reaction equals minus the sum of all other forces."""
    sim = Simulator(paper_scene("planar", grasped_object=PAPER_BALL))
    state = sim.initial_state()
    for _ in range(100):
        previous = state
        result = sim.step(state, -0.15 * state.time)
        state = result.state
    held = result.contact.held[0] & previous.held[0]
    assert held.any()
    # the step's own start: the material's damping acts on the elastic force through the rod's motion in it
    start = previous.q.reshape(3, 20, 2)
    force, _ = sim._assemble(state.q.reshape(3, 20, 2), start, start + 0.01 * previous.velocity.reshape(3, 20, 2),
                             None, np.full(3, -0.15 * previous.time), previous.time, 0.01)
    in_plane = -force[held]  # at rest: R = −f
    world = result.contact.reaction[0][held]
    np.testing.assert_allclose(np.linalg.norm(world, axis=-1), np.linalg.norm(in_plane, axis=-1), rtol=1e-6)


def test_far_fingers_are_not_searched():
    """A finger is searched only if the object is within its reach (L + R from the palm) and, in the planar model,
    cuts its plane at all."""
    angles = paper_scene().gripper.finger_angles
    d = np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)
    in_plane_of_finger_1 = Sphere(0.03, (0.15, 0.0, -0.05))
    assert reachable(in_plane_of_finger_1, d, 0.2, planar=True).tolist() == [True, False, False]
    assert reachable(in_plane_of_finger_1, d, 0.2, planar=False).tolist() == [True, True, True]
    out_of_reach = Sphere(0.03, (0.35, 0.0, -0.05))
    assert not reachable(out_of_reach, d, 0.2, planar=False).any()
    sim = Simulator(replace(paper_scene("planar"), grasped_object=out_of_reach))
    state = sim.initial_state()
    for _ in range(100):
        result = sim.step(state, -0.15 * state.time)
        state = result.state
    assert not result.contact.held.any() and result.contact.resolved.all()


def test_scene_without_object_reports_no_contact():
    sim = Simulator(paper_scene())
    result = sim.step(sim.initial_state(), -0.1)
    assert result.contact is None and result.state.held is None


def test_batch_members_with_contact_are_independent():
    scene = paper_scene("planar", material=SOFT_TRANSLUCENT_SILICONE, grasped_object=PAPER_BALL)
    rates = np.array([-0.15, -0.3])
    batched = Simulator(scene, batch_size=2)
    state = batched.initial_state()
    singles = [Simulator(scene) for _ in rates]
    single_states = [sim.initial_state() for sim in singles]
    for _ in range(80):
        state = batched.step(state, (rates * state.time)[:, None] * np.ones(3)).state
        single_states = [sim.step(st, rate * st.time).state for sim, st, rate in zip(singles, single_states, rates,
                                                                                    strict=True)]
    assert state.held.any()
    for b, single in enumerate(single_states):
        np.testing.assert_array_equal(state.q[b], single.q[0])
        np.testing.assert_array_equal(state.held[b], single.held[0])


@pytest.mark.parametrize("make, pattern", [
    (lambda: Sphere(-0.1, (0, 0, 0)), r"Sphere\.radius = -0\.1 m"),
    (lambda: Sphere(0.1, (0, 0)), r"Sphere\.center = \(0, 0\) must have 3 components"),
    (lambda: ContactSettings(max_corrector_iterations=-1), r"ContactSettings\.max_corrector_iterations = -1"),
    (lambda: ContactSettings(finger_contact_stiffness=-1.0),
     r"ContactSettings\.finger_contact_stiffness = -1\.0 N/m is outside the allowed range \[0, 1e\+09\)"),
    (lambda: ContactSettings(finger_friction=math.nan), r"ContactSettings\.finger_friction = nan"),
    (lambda: replace(paper_scene(), grasped_object="ball"), r"Scene\.grasped_object must be a Sphere, a Capsule"),
    (lambda: Capsule(0.02, (0, 0), (0, 0, 1)), r"Capsule\.start = \(0, 0\) must have 3 components"),
    (lambda: Capsule(0.0, (0, 0, 0), (0, 0, 1)), r"Capsule\.radius = 0\.0 m"),
    (lambda: paper_scene("planar", grasped_object=Capsule(0.04, (0, -0.05, -0.1), (0, 0.05, -0.1))),
     r"contact with a Capsule needs Scene\.model = '3d'"),
])
def test_bad_contact_configuration_raises(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()


def test_halved_steps_keep_contact_consistent():
    """Newton limited to 3 iterations at Δt = 0.02 s fails some steps while the fingers touch the ball; the halved
    steps still end with no penetration, no adhesion, and the held nodes reported for the whole step."""
    scene = replace(paper_scene("planar", material=SOFT_TRANSLUCENT_SILICONE, grasped_object=PAPER_BALL),
                    time_step=0.02, newton=replace(paper_scene().newton, max_iterations=3))
    sim = Simulator(scene, batch_size=2)
    state = sim.initial_state()
    rates = np.array([[-0.15] * 3, [-0.3] * 3])
    halved_in_contact = False
    for _ in range(50):
        result = sim.step(state, rates * state.time)
        assert result.converged.all() and result.contact.resolved.all()
        state = result.state
        np.testing.assert_array_equal(result.contact.held, state.held)
        assert np.all(result.contact.normal_reaction[state.held] >= 0)
        halved_in_contact |= bool((result.substeps[state.held.any(axis=(1, 2))] > 1).any())
        distance = np.linalg.norm(sim.world_positions(state) - np.asarray(PAPER_BALL.center), axis=-1)
        assert distance.min() >= PAPER_BALL.radius - PENETRATION_TOLERANCE
    assert halved_in_contact


def test_the_penetration_tolerance_tightens_as_the_step_squared():
    """1 µm at 2.5 ms and longer steps; below, the acceleration bound times Δt², 64 times tighter at 0.3125 ms."""
    assert PENETRATION_TOLERANCE == 1e-6 and PENETRATION_ACCELERATION == 0.16
    for time_step in (0.0025, 0.005, 0.05):
        assert penetration_tolerance(time_step) == PENETRATION_TOLERANCE
    assert penetration_tolerance(0.00125) == pytest.approx(PENETRATION_TOLERANCE / 4, rel=1e-12)
    assert penetration_tolerance(0.0003125) == pytest.approx(PENETRATION_TOLERANCE / 64, rel=1e-12)


def test_short_steps_hold_free_nodes_to_their_tighter_tolerance():
    """The task's 3-D grasp (a seed's sphere, still water) closed at κ̄ rate −0.3/s with steps of 0.3125 ms: no free
    node ends a step deeper inside the sphere than that step's tolerance (16 nm). With a fixed 1 µm, nodes sat up to
    1 µm inside on 478 of these 6,400 steps, and were caught onto the surface
    at ~10 m/s², twice as many times."""
    from soft_gripper_env.grasp_task import GraspTask, task_episode

    time_step = 0.0003125
    still = {"current_velocity": (0.0, 0.0, 0.0), "current_oscillation": (0.0, 0.0, 0.0),
             "gust_velocity": (0.0, 0.0, 0.0)}
    scene = task_episode(GraspTask(model="3d", physics_dt=time_step), np.random.default_rng(7), still).scene
    sim = Simulator(scene)
    finger_radius = sim.disc.node_radius
    state, curvature = sim.initial_state(), np.zeros(3)
    deepest, held_any = 0.0, False
    for _ in range(round(2.0 / time_step)):
        advanced = sim.advance(state, curvature, -0.3, 1, (-0.2, 0.0))
        state, curvature = advanced.state, advanced.natural_curvature
        assert not advanced.failed.any()
        centre_distance = np.linalg.norm(sim.world_positions(state) - state.body_position[:, None, None, :], axis=-1)
        clearance = centre_distance - scene.grasped_object.radius - finger_radius
        free = ~np.asarray(state.held)
        free[:, :, :2] = False  # the clamped roots are never searched
        deepest = max(deepest, -clearance[free].min())
        held_any |= bool(np.asarray(state.held).any())
    assert held_any
    assert deepest <= penetration_tolerance(time_step)


def test_a_sphere_squeezed_out_between_sliding_fingertips_converges_in_the_step():
    """The task's planar grasp of one seed (3,000,000), closing at κ̄ rate −0.3/s to −0.2: the fingertips squeeze the
    sphere up and out, sliding on it (μ = 0.3). At 0.15625 ms no step spends the corrector's budget and none is
    halved, and the sphere's height at 0.62 s agrees with the run at 0.625 ms to 1 mm. Before a stuck hold that
    pulls was first made to slide, the fingertip was let go and caught again until the budget was spent, on 49 steps;
    the sphere then rose 9 mm higher than at 0.625 ms."""
    from soft_gripper_env.grasp_task import GraspTask, task_episode

    heights = []
    for time_step in (0.000625, 0.00015625):
        task = GraspTask(model="planar", physics_dt=time_step)
        sim = Simulator(task_episode(task, np.random.default_rng(3_000_000), {}).scene)
        state = sim.initial_state()
        for _ in range(round(0.62 / time_step)):
            result = sim.step(state, max(-0.3 * state.time, -0.2))
            state = result.state
            assert result.converged.all() and result.contact.resolved.all()
            assert result.substeps[0] == 1
            assert result.contact.corrector_iterations[0] < ContactSettings().max_corrector_iterations
        assert state.held.any(axis=(0, 2)).sum() >= 2  # still squeezed between fingertips
        heights.append(state.body_position[0, 2])
    assert abs(heights[1] - heights[0]) < 1e-3


def test_scripted_ramp_saturates_at_the_curvature_limit():
    scene = replace(paper_scene(), duration=15.0, time_step=0.05)  # κ̄ would reach −2.25
    run = run_ramp(scene)
    assert run.converged.all() and np.isfinite(run.positions).all()


@pytest.mark.parametrize("friction", [math.inf, 0.3])
def test_a_capsule_of_zero_length_is_the_sphere(friction):
    ball = paper_scene("3d", grasped_object=replace(PAPER_BALL, friction=friction))
    pill = replace(ball, grasped_object=Capsule(PAPER_BALL.radius, PAPER_BALL.center, PAPER_BALL.center,
                                                friction=friction))
    a, b = run_ramp(ball), run_ramp(pill)
    np.testing.assert_array_equal(a.positions, b.positions)
    for x, y in zip(a.contacts, b.contacts, strict=True):
        np.testing.assert_array_equal(x.reaction, y.reaction)


def test_fingers_close_on_a_horizontal_capsule():
    """A capsule lying along y below the palm: finger 1 (along +x) meets its side, fingers 2 and 3 (at ±120°) meet
    it obliquely; no node penetrates, every hold is compressive and sits on the surface."""
    capsule = Capsule(0.05, (0.0, -0.06, -0.11), (0.0, 0.06, -0.11))
    run = run_ramp(paper_scene("3d", grasped_object=capsule))
    assert run.converged.all()
    held_any = np.zeros(3, dtype=bool)
    for x, report in zip(run.positions[1:, 0], run.contacts, strict=True):
        assert report.resolved.all()
        distance = segment_distance(x, np.tile(capsule.start, (3, 1)), np.tile(capsule.end, (3, 1)))
        assert distance.min() >= capsule.radius - PENETRATION_TOLERANCE
        held = report.held[0]
        np.testing.assert_allclose(distance[held], capsule.radius, atol=1e-12)
        assert np.all(report.normal_reaction[0][held] >= 0)
        held_any |= held.any(axis=1)
    assert held_any.all()
    # the capsule is symmetric under y → −y, which swaps fingers 2 and 3
    last = run.contacts[-1]
    mirror = np.array([1.0, -1.0, 1.0])
    np.testing.assert_allclose(last.reaction[0, 1], last.reaction[0, 2] * mirror, atol=1e-8)


def _surface_run(model, material=ELASTOSIL_MA_4601, variable_stiffness=False, center=(0.0, 0.0, -0.12)):
    """The paper's ramp closing on a fixed sphere with contact on the fingers' surfaces."""
    scene = paper_scene(model, material=material, variable_stiffness=variable_stiffness,
                        grasped_object=Sphere(0.04, center))
    scene = replace(scene, contact=ContactSettings(finger_thickness=True))
    return scene, run_ramp(scene)


@pytest.mark.parametrize("variable_stiffness", [False, True])
@pytest.mark.parametrize("model", ["planar", "3d"])
def test_contact_is_between_the_fingers_surface_and_the_objects(model, variable_stiffness):
    """With ``finger_thickness``, no free node's centre line comes closer to the sphere than its radius plus the
    finger's radius at that node (the radius profile, 20 mm at the base to 1 mm at the tip with variable
    stiffness), and held nodes lie on that offset surface."""
    scene, run = _surface_run(model, variable_stiffness=variable_stiffness)
    finger_radius = scene.discretization().node_radius
    center = np.asarray(scene.grasped_object.center)
    clearance = np.linalg.norm(run.positions - center, axis=-1) - (0.04 + finger_radius)
    held_any = False
    for k, report in enumerate(run.contacts):
        assert clearance[k + 1][:, :, 2:].min() >= -PENETRATION_TOLERANCE
        if report.held.any():
            held_any = True
            assert np.abs(clearance[k + 1][report.held]).max() < 1e-3  # held on the surface, up to the step's slip
        assert np.all(report.normal_reaction[report.held] >= 0.0)
    assert held_any
    assert run.converged.all()


def test_planar_and_3d_agree_with_surface_contact_on_the_axis():
    """A sphere on the gripper's axis makes the scene planar: both models give the same motion and reactions."""
    _, planar = _surface_run("planar")
    _, spatial = _surface_run("3d")
    assert np.abs(planar.positions - spatial.positions).max() <= 1e-6
    for a, b in zip(planar.contacts, spatial.contacts, strict=True):
        np.testing.assert_array_equal(a.held, b.held)
        np.testing.assert_allclose(a.reaction, b.reaction, atol=1e-4)


def test_a_planar_finger_touches_an_off_plane_sphere_where_its_surface_does():
    """In the planar model node i meets a sphere of radius R whose centre is d from the finger's plane on the
    circle of radius √((R + r_i)² − d²): the section of the sphere grown by the finger's radius."""
    radius, offset = 0.05, 0.03
    directions = np.array([[1.0, 0.0, 0.0]])
    finger_radius = np.linspace(0.02, 0.001, 20)
    starts, ends, radii = object_in_rod_frames(Sphere(radius, (0.1, offset, -0.1)), directions, finger_radius, True)
    np.testing.assert_allclose(radii[0], np.sqrt((radius + finger_radius) ** 2 - offset**2), rtol=1e-14)
    np.testing.assert_array_equal(starts, [[0.1, -0.1]])
    _, _, on_centre_line = object_in_rod_frames(Sphere(radius, (0.1, offset, -0.1)), directions, np.zeros(20), True)
    np.testing.assert_allclose(on_centre_line[0], math.sqrt(radius**2 - offset**2), rtol=1e-14)


@pytest.fixture(scope="module")
def friction_runs():
    """The paper's ramp on its fixed ball with stick contact and with Coulomb friction of several μ, planar and
    3-D."""
    return {(model, mu): run_ramp(paper_scene(model, grasped_object=replace(PAPER_BALL, friction=mu)))
            for model in ("planar", "3d") for mu in (math.inf, 1.0, 0.3, 0.0)}


def _cone(report):
    """Normal and tangential parts of every held node's reaction [N], and whether it slides."""
    normal = report.normal_reaction[report.held]
    tangential = np.sqrt(np.maximum(np.sum(report.reaction[report.held] ** 2, axis=-1) - normal**2, 0.0))
    return normal, tangential, report.sliding[report.held]


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_contacts_obey_coulombs_law(friction_runs, model):
    """Every stuck contact lies inside the friction cone, |R_t| ≤ μ·R_n (to Newton's force tolerance), and every
    sliding one on its rim, |R_t| = μ·R_n within 1 %, for μ = 1, 0.3 and 0 (frictionless: no tangential
    reaction at all). Every step converges and resolves."""
    for mu in (1.0, 0.3, 0.0):
        run = friction_runs[(model, mu)]
        assert run.converged.all()
        slid = 0
        for report in run.contacts:
            assert report.resolved.all()
            normal, tangential, sliding = _cone(report)
            assert np.all(normal >= 0.0)
            assert np.all(tangential[~sliding] <= mu * normal[~sliding] + 1e-6)
            np.testing.assert_allclose(tangential[sliding], mu * normal[sliding], rtol=0.01, atol=1e-6)
            slid += int(sliding.sum())
        assert slid > 0  # the ball's contacts do slide at these μ


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_slip_starts_where_the_tangential_reaction_reaches_mu_times_the_normal(friction_runs, model):
    """With stick contact the largest ratio of tangential to normal reaction over the run is μ*. Just above it
    (1.02·μ*) nothing slides and the run is the stuck one exactly; just below (0.98·μ*) a contact slides."""
    stuck = friction_runs[(model, math.inf)]
    ratios = [t / n for report in stuck.contacts for n, t, _ in [_cone(report)] for n, t in zip(n, t, strict=True)
              if n > 1e-3]
    critical = max(ratios)
    above = run_ramp(paper_scene(model, grasped_object=replace(PAPER_BALL, friction=1.02 * critical)))
    np.testing.assert_array_equal(above.positions, stuck.positions)
    assert not any(report.sliding.any() for report in above.contacts)
    below = run_ramp(paper_scene(model, grasped_object=replace(PAPER_BALL, friction=0.98 * critical)))
    assert any(report.sliding.any() for report in below.contacts)


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_friction_never_adds_energy(friction_runs, model):
    """On a fixed object, the friction on every sliding node opposes its motion over the step: its work is never
    positive."""
    for mu in (1.0, 0.3):
        run = friction_runs[(model, mu)]
        worked = 0
        for k, report in enumerate(run.contacts):
            if not report.sliding.any():
                continue
            motion = run.positions[k + 1] - run.positions[k]
            reaction = report.reaction
            normal = report.normal_reaction
            positions = run.positions[k + 1]
            outward = positions - np.asarray(PAPER_BALL.center)
            outward /= np.linalg.norm(outward, axis=-1, keepdims=True)
            friction = reaction - normal[..., None] * outward
            work = np.sum(friction * motion, axis=-1)[report.sliding]
            assert np.all(work <= 1e-12)
            worked += int((work < 0).sum())
        assert worked > 0


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_capped_friction_passes_keep_friction_dissipative_and_the_run_close(friction_runs, model):
    """Capping the re-solves for friction alone (ContactSettings.friction_passes = 1) leaves a sliding node with the
    friction of its last solve: μ·R_n of the pass before, so off the cone's rim by up to a quarter here, but still
    opposing the node's motion (no work), every step resolved, fewer re-solves than settling, and the fingers within
    0.1 mm of the settled run at the end (μ = 0.3)."""
    settled = friction_runs[(model, 0.3)]
    scene = paper_scene(model, grasped_object=replace(PAPER_BALL, friction=0.3))
    capped = run_ramp(replace(scene, contact=replace(scene.contact, friction_passes=1)))
    assert capped.converged.all()
    worked, off_rim = 0, 0.0
    for k, report in enumerate(capped.contacts):
        assert report.resolved.all()
        normal, tangential, sliding = _cone(report)
        off_rim = max(off_rim, float(np.max(np.abs(tangential[sliding] - 0.3 * normal[sliding])
                                            / (0.3 * normal[sliding] + 1e-6), initial=0.0)))
        assert np.all(tangential[~sliding] <= 0.3 * normal[~sliding] + 1e-6)
        if report.sliding.any():
            outward = capped.positions[k + 1] - np.asarray(PAPER_BALL.center)
            outward /= np.linalg.norm(outward, axis=-1, keepdims=True)
            friction = report.reaction - report.normal_reaction[..., None] * outward
            work = np.sum(friction * (capped.positions[k + 1] - capped.positions[k]), axis=-1)[report.sliding]
            assert np.all(work <= 1e-12)
            worked += int((work < 0).sum())
    assert worked > 0
    assert 0.01 < off_rim < 0.3  # the lag shows, and stays bounded
    passes = [sum(int(report.corrector_iterations.sum()) for report in run.contacts) for run in (capped, settled)]
    assert passes[0] < passes[1]
    assert np.abs(capped.positions[-1] - settled.positions[-1]).max() < 1e-4


def test_friction_passes_are_checked():
    """A cap on the friction passes is None or a count in [0, 100]."""
    for bad in (-1, 101, 2.5, True):
        with pytest.raises(ValueError, match=r"ContactSettings\.friction_passes = .*\[0, 100\]"):
            ContactSettings(friction_passes=bad)
    assert ContactSettings(friction_passes=0).friction_passes == 0


@pytest.mark.parametrize("stride, dim", [(2, 2), (4, 3)])
def test_a_sliding_nodes_frame_turns_its_band_exactly(stride, dim):
    """A sliding node is solved in its surface's frame: the band of a rod's symmetric Newton matrix (nodes coupled
    to two neighbours each side) becomes Tᵀ·A·T, T the identity but for the node's orthonormal basis (first column
    the normal), against the dense product; nothing falls outside the band."""
    from soft_gripper_env.physics.kernels.contact import rotate_node, tangent_basis

    rng = np.random.default_rng(3)
    n_nodes = 8
    n, kd = n_nodes * stride, 3 * stride - 1
    dense = np.zeros((n, n))
    for i in range(n_nodes):
        for j in range(max(0, i - 2), min(n_nodes, i + 3)):
            dense[i * stride:(i + 1) * stride, j * stride:(j + 1) * stride] += rng.normal(size=(stride, stride))
    dense += dense.T
    band = np.zeros((n, kd + 1))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            band[i, kd - i + j] = dense[i, j]
    normal = rng.normal(size=dim)
    normal /= np.linalg.norm(normal)
    basis = np.empty((dim, dim))
    tangent_basis(normal, basis)
    np.testing.assert_allclose(basis.T @ basis, np.eye(dim), atol=1e-15)
    np.testing.assert_array_equal(basis[:, 0], normal)
    first = 3 * stride
    turn = np.eye(n)
    turn[first:first + dim, first:first + dim] = basis
    expected = turn.T @ dense @ turn
    rotate_node(band, first, basis)
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            assert band[i, kd - i + j] == pytest.approx(expected[i, j], abs=1e-13)
    assert np.abs(np.tril(expected, -kd - 1)).max() == 0.0


@pytest.mark.parametrize("stride, dim", [(2, 2), (4, 3)])
def test_contact_reactions_match_a_direct_computation(stride, dim):
    """The reported reaction (held nodes' residual plus friction, to the world frame) and its normal part, against
    the same quantities computed node by node in NumPy, for random rods of two grippers. A sliding node's stored
    friction points anywhere here; what it exerts, and what is reported, is the same size turned into the surface's
    tangent plane at the node (as in the solve): the normal part is the residual's alone."""
    rng = np.random.default_rng(11)
    n_fingers, n_rods, n_nodes = 3, 6, 5
    directions = np.array([[math.cos(a), math.sin(a), 0.0] for a in (0.3, 2.4, 4.5)])
    q = rng.normal(size=(n_rods, n_nodes, stride))
    residual = rng.normal(size=(n_rods, n_nodes * stride))
    held = rng.random((n_rods, n_nodes)) < 0.5
    friction = rng.normal(size=(n_rods, n_nodes, dim)) * held[..., None]
    starts, ends = rng.normal(size=(n_rods, dim)), rng.normal(size=(n_rods, dim))
    reaction, normal = np.empty((n_rods, n_nodes, 3)), np.empty((n_rods, n_nodes))
    contact_reactions(q, residual, held, friction, starts, ends, directions, reaction, normal)
    for r in range(n_rods):
        for i in range(n_nodes):
            segment = ends[r] - starts[r]
            t = np.clip(np.dot(q[r, i, :dim] - starts[r], segment) / np.dot(segment, segment), 0.0, 1.0)
            outward = q[r, i, :dim] - (starts[r] + t * segment)
            unit = outward / np.linalg.norm(outward)
            tangential = friction[r, i] - np.dot(friction[r, i], unit) * unit
            acting = tangential * np.linalg.norm(friction[r, i]) / max(np.linalg.norm(tangential), 1e-300)
            own = residual[r, i * stride:i * stride + dim] * held[r, i]
            local = own + acting
            world = local if dim == 3 else local[0] * directions[r % n_fingers] + np.array([0.0, 0.0, local[1]])
            np.testing.assert_allclose(reaction[r, i], world, rtol=1e-12, atol=1e-12)
            assert normal[r, i] == pytest.approx(np.dot(own, unit), rel=1e-12, abs=1e-12)


def test_a_node_held_on_the_object_segment_reports_no_normal_reaction():
    """A planar finger sees a sphere that has left its plane as a section of radius zero, a point: a node held there
    lies on the object's segment, where the normal is undefined. Its reported normal reaction is 0, not 0/0 (which
    once reached a training run's reward as NaN); its reaction is reported as it is."""
    q = np.zeros((1, 3, 2))
    q[0, :, 0] = [0.0, 0.01, 0.02]
    point = q[0, 1, :2].copy()  # the section's centre, on node 1
    residual = np.array([[0.0, 0.0, 0.3, -0.2, 0.0, 0.0]])
    held = np.array([[False, True, False]])
    friction = np.zeros((1, 3, 2))
    reaction, normal = np.empty((1, 3, 3)), np.empty((1, 3))
    contact_reactions(q, residual, held, friction, point[None], point[None], np.array([[1.0, 0.0, 0.0]]), reaction,
                      normal)
    assert np.isfinite(normal).all() and normal[0, 1] == 0.0
    assert np.isfinite(reaction).all() and reaction[0, 1, 0] == 0.3


def _test_one_hold(reaction_y: float, friction: float, let_go_if_pulling: bool = False):
    """The corrector's test after a solve on two rods whose node 1 is held (stuck) at (0.01, 0) [m] with a reaction
    ``reaction_y`` [N] along +y on it: rod 0 sees the object's segment as that very point (a planar section shrunk
    to a point), rod 1 a circle of radius 5 mm around (0.01, −0.005), whose outward normal there is +y. Returns
    the :class:`~soft_gripper_env.physics.solvers.corrector.ContactChanges`."""
    from soft_gripper_env.physics.kernels.contact import ObjectView
    from soft_gripper_env.physics.solvers.corrector import ContactChanges, contact_changes
    from soft_gripper_env.physics.solvers.newton import Holds, SolverArrays

    n_rods, n_nodes, dim = 2, 3, 2
    positions = np.zeros((n_rods, n_nodes, dim))
    positions[:, :, 0] = [0.0, 0.01, 0.02]
    point = np.array([0.01, 0.0])
    starts = np.array([point, [0.01, -0.005]])
    ends = starts.copy()
    radii = np.array([[0.0] * n_nodes, [0.005] * n_nodes])
    stride = 3
    residual = np.zeros((n_rods, n_nodes * stride))
    residual[:, stride * 1 + 1] = reaction_y
    held = np.zeros((n_rods, n_nodes), dtype=np.bool_)
    held[:, 1] = True
    holds = Holds(held, np.zeros((n_rods, n_nodes, 3)), np.zeros((n_rods, dim, 3)), np.zeros_like(held),
                  np.zeros((n_rods, n_nodes, dim)), np.ones((n_rods, n_nodes * stride), dtype=np.bool_), starts, ends,
                  radii, np.zeros(n_nodes))
    solver = SolverArrays(np.ones(n_nodes * stride), np.ones((n_rods, n_nodes * stride)),
                          np.ones((n_rods, n_nodes * stride), dtype=np.bool_), np.ones(6), 10, 1, 5, 2, 1, 1e-6, 0.1,
                          1e-6)
    view = ObjectView(starts, ends, radii, np.ones(n_rods, dtype=np.bool_), np.zeros((n_rods, dim)))
    flags = np.zeros((5, n_rods, n_nodes), dtype=np.bool_)
    flags[4] = let_go_if_pulling
    changes = ContactChanges(flags[0], flags[1], positions.copy(), flags[2], np.full((n_rods, n_nodes, dim), np.nan),
                             flags[3], np.zeros(n_rods, dtype=np.bool_), flags[4])
    contact_changes(positions, positions.copy(), positions.copy(), residual, holds, view, np.full(n_rods, friction),
                    solver, True, True, changes, np.empty(n_rods, dtype=np.int64))
    return changes


def test_the_corrector_lets_go_of_a_node_held_on_the_object_segment():
    """The corrector's test after a solve releases a hold on the object's segment itself (a planar section shrunk to
    a point, which has no outward normal) and marks its rod changed, whatever the hold's reaction; a hold off the
    segment with a pushing reaction stays. Without the release the test divides 0 by 0 there."""
    changes = _test_one_hold(0.2, np.inf)
    assert changes.adhesive[0, 1] and changes.changed[0]
    assert not changes.adhesive[1].any() and not changes.changed[1]


@pytest.mark.parametrize("friction, let_go_if_pulling, slides", [(0.3, False, True), (0.0, False, True),
                                                                 (0.3, True, False), (np.inf, False, False)])
def test_a_stuck_hold_that_pulls_slides_before_it_is_let_go(friction, let_go_if_pulling, slides):
    """A stuck hold whose normal reaction pulls (0.2 N into the object) first slides, without friction, unless it
    was caught in this step or already made to slide by a pull (then it is let go), or always sticks (μ = ∞: let
    go)."""
    changes = _test_one_hold(-0.2, friction, let_go_if_pulling)
    assert changes.changed[1]
    assert changes.slide[1, 1] == slides and changes.adhesive[1, 1] == (not slides)
    if slides:
        assert changes.let_go_if_pulling[1, 1]  # a second pull lets it go
        np.testing.assert_array_equal(changes.friction[1, 1], 0.0)
