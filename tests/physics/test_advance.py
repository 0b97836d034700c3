"""Simulator.advance: many steps in one compiled call give, to the bit, what as many calls of Simulator.step give,
including the steps it hands to the adaptive (halving) path and the grippers that fail or do not run."""

from dataclasses import replace

import numpy as np
import pytest

from soft_gripper_env.grasp_task import GraspTask, task_episode
from soft_gripper_env.physics import NATURAL_CURVATURE_LIMIT, NewtonSettings, Simulator, paper_scene
from soft_gripper_env.physics.scene.objects import PAPER_BALL

STATE_FIELDS = ("q", "velocity", "acceleration", "tangent", "director", "reference_twist", "held", "hold_offset",
                "body_position", "body_velocity", "body_orientation", "body_angular_velocity")


COARSE_STEP = {"planar": 0.005, "3d": 0.0025}
"""Physics steps [s] four and two times the task's default, at which a fast-closing gripper's step with Newton's
iterations capped fails and is halved: the hard cases of the halving tests."""


def task_scenes(model, batch_size, seed=3, physics_dt=None):
    """The grasp task's scenes (free spheres in a current with a gust, fingers of finite thickness touching each
    other, friction passes capped), one per gripper; at the task's default step unless ``physics_dt`` [s] is given."""
    task = GraspTask(model=model) if physics_dt is None else GraspTask(model=model, physics_dt=physics_dt)
    rng = np.random.default_rng(seed)
    return [task_episode(task, rng, {}).scene for _ in range(batch_size)]


def stepped(sim, state, natural_curvature, rate, n_steps, low, high, running, clock):
    """What ``advance`` does, computed with ``Simulator.step`` one step at a time and numpy."""
    B, F = natural_curvature.shape
    natural_curvature, clock, running = natural_curvature.copy(), clock.copy(), running.copy()
    failed, iterations = np.zeros(B, dtype=bool), np.zeros(B, dtype=np.int64)
    normal_impulse = np.zeros((B, F, sim.disc.n_nodes))
    impulse = np.zeros((B, F, sim.disc.n_nodes, 3))
    dt = sim.scene.time_step
    substeps = 0
    for _ in range(n_steps):
        if not running.any():
            break
        result = sim.step(state, natural_curvature)
        substeps = max(substeps, int(result.substeps.max()))
        ok = result.converged & np.isfinite(result.state.q).all(axis=(1, 2, 3)) \
            & np.isfinite(result.state.velocity).all(axis=(1, 2, 3))
        keep = running & ok
        failed |= running & ~ok
        merged = {}
        for name in STATE_FIELDS:
            old, new = getattr(state, name), getattr(result.state, name)
            if new is None:
                continue
            if old is None:
                old = np.zeros_like(new)
            merged[name] = np.where(keep.reshape((-1,) + (1,) * (new.ndim - 1)), new, old)
        state = replace(result.state, **merged)
        if result.contact is not None:
            normal_impulse[keep] += np.maximum(result.contact.normal_reaction[keep], 0.0) * dt
            impulse[keep] += result.contact.reaction[keep] * dt
        natural_curvature[keep] = np.clip(natural_curvature[keep] + rate[keep] * dt, low, high)
        iterations[keep] += result.newton_iterations[keep]
        clock[keep] += dt
        running = keep
    return state, natural_curvature, clock, failed, iterations, normal_impulse, impulse, substeps


def assert_same(sim, state, n_steps, rate, low=-1.5, high=0.2, running=None, clock=None, natural_curvature=None):
    """Checks ``advance`` against :func:`stepped`, bitwise; returns the most substeps a step took."""
    B, F = sim.batch_size, sim.n_fingers
    natural_curvature = np.zeros((B, F)) if natural_curvature is None else natural_curvature
    running = np.ones(B, dtype=bool) if running is None else running
    clock = np.zeros(B) if clock is None else clock
    advanced = sim.advance(state, natural_curvature, rate, n_steps, (low, high), running=running, clock=clock)
    expected_state, expected_curvature, expected_clock, failed, iterations, normal_impulse, impulse, substeps = \
        stepped(sim, state, natural_curvature, rate, n_steps, low, high, running, clock)
    for name in STATE_FIELDS:
        expected = getattr(expected_state, name)
        if expected is not None:
            np.testing.assert_array_equal(getattr(advanced.state, name), expected, err_msg=name)
    assert advanced.state.time == expected_state.time
    np.testing.assert_array_equal(advanced.natural_curvature, expected_curvature)
    np.testing.assert_array_equal(advanced.clock, expected_clock)
    np.testing.assert_array_equal(advanced.failed, failed)
    np.testing.assert_array_equal(advanced.newton_iterations, iterations)
    np.testing.assert_array_equal(advanced.normal_impulse, normal_impulse)
    np.testing.assert_array_equal(advanced.impulse, impulse)
    return advanced, substeps


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_advance_is_bitwise_the_steps_of_a_grasp(model):
    """Four task grippers bent toward their spheres close at different rates through 60 steps of 1.25 ms (contact,
    friction, the current); a fifth does not run and keeps its state."""
    scenes = task_scenes(model, 5, physics_dt=0.00125)  # 75 ms: long enough to reach the spheres in either model
    sim = Simulator(scenes)
    state = sim.initial_state()
    rate = np.linspace(-0.5, -0.1, 15).reshape(5, 3)
    running = np.array([True, True, False, True, True])
    clock = np.linspace(0.0, 0.4, 5)
    advanced, _ = assert_same(sim, state, 60, rate, running=running, clock=clock,
                              natural_curvature=np.full((5, 3), -0.3))
    assert advanced.normal_impulse[running].sum() > 0  # the fingers reached the spheres
    for name in ("q", "body_position"):
        np.testing.assert_array_equal(getattr(advanced.state, name)[2], getattr(state, name)[2])
    assert advanced.clock[2] == clock[2]
    # and on from there, with the ramp pinned at its end
    assert_same(sim, advanced.state, 20, rate, high=-0.05, natural_curvature=advanced.natural_curvature,
                clock=advanced.clock)


def test_advance_halves_a_step_for_the_grippers_that_need_it(monkeypatch):
    """Two Newton iterations per solve are too few for the impacts: steps are halved on the adaptive path for the
    grippers that did not settle them, while the others take them whole, and advance still gives what the steps
    give."""
    scenes = [replace(scene, newton=NewtonSettings(max_iterations=2)) for scene in task_scenes("planar", 4)]
    sim = Simulator(scenes)
    pending = []
    halve = sim._halve_pending

    def counted(work, interval, k, dt, step_times, body, grippers):
        assert np.array_equal(grippers, np.nonzero(interval.pending)[0])  # the compiled steps left them pending
        pending.append(len(grippers))
        halve(work, interval, k, dt, step_times, body, grippers)

    monkeypatch.setattr(sim, "_halve_pending", counted)
    _, substeps = assert_same(sim, sim.initial_state(), 25, np.array([[-1.0] * 3, [-0.6] * 3, [0.0] * 3, [-1.0] * 3]),
                              natural_curvature=np.array([[-0.1] * 3, [-0.1] * 3, [0.0] * 3, [-0.2] * 3]))
    assert substeps > 1
    assert pending and min(pending) < 4  # some steps were halved for part of the batch only


def _uncalled(*args):
    raise AssertionError("a batch of one left a step to the host's adaptive path")


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_a_batch_of_one_halves_its_steps_in_the_compiled_call(model, monkeypatch):
    """A gripper alone (one env, or a GPU thread) halves a step it does not settle inside the compiled steps, level
    by level, with the water at each half step's time: bitwise what the steps of the adaptive path give, and what
    the same gripper gets from the host's halving when it shares a batch. Planar: Newton capped at four
    iterations; 3-D: no corrector re-solves, so that a step with a new hold is halved down to the deepest level and
    taken there unresolved."""
    scene = task_scenes(model, 1, seed=5, physics_dt=COARSE_STEP[model])[0]
    if model == "planar":
        scene, rate, start = replace(scene, newton=NewtonSettings(max_iterations=4)), -0.5, -0.1
    else:
        scene = replace(scene, newton=NewtonSettings(max_iterations=16),
                        contact=replace(scene.contact, max_corrector_iterations=0))
        rate, start = -0.3, -0.3
    rate = np.array([[rate, 0.8 * rate, rate]])
    alone = Simulator(scene)
    monkeypatch.setattr(alone, "_halve_pending", _uncalled)
    advanced, substeps = assert_same(alone, alone.initial_state(), 60, rate, natural_curvature=np.full((1, 3), start))
    assert substeps >= 4  # halved more than once within a step
    assert not advanced.failed.any() and advanced.normal_impulse.sum() > 0
    batch = Simulator([scene, scene])
    halved = []
    halve = batch._halve_pending
    monkeypatch.setattr(batch, "_halve_pending", lambda *args: (halved.append(len(args[-1])), halve(*args)))
    shared = batch.advance(batch.initial_state(), np.full((2, 3), start), np.repeat(rate, 2, axis=0), 60)
    assert halved  # the batch's steps were halved on the host
    for name in STATE_FIELDS:
        value = getattr(advanced.state, name)
        if value is not None:
            np.testing.assert_array_equal(getattr(shared.state, name)[1], value[0], err_msg=name)
    np.testing.assert_array_equal(shared.impulse[1], advanced.impulse[0])
    np.testing.assert_array_equal(shared.newton_iterations[1], advanced.newton_iterations[0])


def test_a_batch_of_one_whose_half_step_fails_keeps_the_state_before_the_step(monkeypatch):
    """With one halving allowed and three Newton iterations, a fast-closing gripper alone takes the first half of
    a step and fails in the second: it stops with the state from before the whole step (not the half step it
    took), as the adaptive path leaves it."""
    scene = replace(task_scenes("planar", 1, physics_dt=COARSE_STEP["planar"])[0],
                    newton=NewtonSettings(max_iterations=3, max_step_halvings=1))
    sim = Simulator(scene)
    monkeypatch.setattr(sim, "_halve_pending", _uncalled)
    advanced, substeps = assert_same(sim, sim.initial_state(), 80, np.array([[-1.0] * 3]),
                                     natural_curvature=np.full((1, 3), -0.05))
    assert advanced.failed[0] and substeps == 2


def test_a_gripper_that_fails_stops_and_the_others_run_on():
    """Without halvings and with four Newton iterations, two grippers bending fast fail part-way (at different
    steps), and a still one runs on; the advance stops each where the steps do."""
    scenes = [replace(scene, newton=NewtonSettings(max_iterations=4, max_step_halvings=0))
              for scene in task_scenes("planar", 3, physics_dt=COARSE_STEP["planar"])]
    sim = Simulator(scenes)
    rate = np.array([[0.0] * 3, [-2.0] * 3, [-0.5] * 3])
    advanced, _ = assert_same(sim, sim.initial_state(), 80, rate,
                              natural_curvature=np.array([[0.0] * 3, [-0.05] * 3, [-0.05] * 3]))
    np.testing.assert_array_equal(advanced.failed, [False, True, True])
    assert advanced.clock[0] > advanced.clock[2] > advanced.clock[1] > 0.0


@pytest.mark.parametrize("grasped_object", [PAPER_BALL, None], ids=["fixed ball", "no object"])
def test_advance_with_a_fixed_object_or_none(grasped_object):
    sim = Simulator(paper_scene("planar", grasped_object=grasped_object), 2)
    assert_same(sim, sim.initial_state(), 40, np.array([[-0.15] * 3, [-0.3] * 3]), low=-NATURAL_CURVATURE_LIMIT)


def test_advance_refuses_bad_input():
    sim = Simulator(paper_scene("planar", grasped_object=PAPER_BALL))
    state = sim.initial_state()
    with pytest.raises(ValueError, match="n_steps = 0"):
        sim.advance(state, 0.0, 0.0, 0)
    with pytest.raises(ValueError, match=r"curvature_range = \(0.5, -0.5\)"):
        sim.advance(state, 0.0, 0.0, 1, (0.5, -0.5))
    with pytest.raises(ValueError, match="curvature_range"):
        sim.advance(state, 0.0, 0.0, 1, (-3.0, 0.0))
    with pytest.raises(ValueError, match="curvature_rate"):
        sim.advance(state, 0.0, np.nan, 1)
    with pytest.raises(ValueError, match="natural_curvature"):
        sim.advance(state, 5.0, 0.0, 1)


def test_put_grippers_replaces_grippers_and_checks_its_input():
    """A new episode's gripper put into a running batch: its rows are the part's, the others' are the batch's,
    the part's missing acceleration is zero (Newton's start from the predictor, as a fresh state's); the batch's
    own arrays are left alone. Bad indices or a part without a field the state has are refused, naming them."""
    task = GraspTask(model="planar")
    sim = Simulator([task_episode(task, np.random.default_rng(seed), {}).scene for seed in range(3)])
    running = sim.advance(sim.initial_state(), 0.0, -0.2, 4).state
    fresh = sim.initial_state()
    part = replace(fresh, q=fresh.q[[1]], velocity=fresh.velocity[[1]], held=fresh.held[[1]],
                   hold_offset=fresh.hold_offset[[1]], body_position=fresh.body_position[[1]] + 0.001,
                   body_velocity=fresh.body_velocity[[1]], body_orientation=fresh.body_orientation[[1]],
                   body_angular_velocity=fresh.body_angular_velocity[[1]])
    before = running.q.copy()
    merged = sim.put_grippers(running, [1], part)
    assert np.array_equal(merged.q[1], fresh.q[1]) and np.array_equal(merged.q[[0, 2]], running.q[[0, 2]])
    assert np.array_equal(merged.body_position[1], fresh.body_position[1] + 0.001)
    assert np.all(merged.acceleration[1] == 0.0) and np.array_equal(merged.acceleration[0], running.acceleration[0])
    assert np.any(running.acceleration[1] != 0.0) and np.array_equal(running.q, before)
    assert merged.time == running.time
    with pytest.raises(ValueError, match=r"indices 3\.\.3 are outside the allowed range \[0, 2\]"):
        sim.put_grippers(running, [3], part)
    with pytest.raises(ValueError, match="part has no held"):
        sim.put_grippers(running, [1], replace(part, held=None))
    with pytest.raises(ValueError, match=r"part has q of shape \(1, 3, .*expected \(2, 3"):
        sim.put_grippers(running, [0, 1], part)
