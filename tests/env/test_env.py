"""SoftGripperUnderwater-v0: registration, the Gymnasium and SB3 contracts, determinism, the vector env, the
scripted baseline against the core simulator, rendering, and bad input."""

import math
import pickle
import subprocess
import sys
import warnings
from dataclasses import replace

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import soft_gripper_env
from agents.scripted import APPROACH_RATE, PAPER_RATE, RampPolicy, ReactivePolicy
from soft_gripper_env.env import (
    DEFAULT_MAX_EPISODE_STEPS,
    SoftGripperUnderwaterEnv,
    SoftGripperUnderwaterVectorEnv,
    observation_bounds,
    observation_slices,
)
from soft_gripper_env.grasp_task import MODEL_DEFAULTS, GraspTask, task_episode
from soft_gripper_env.physics import PAPER_BALL, NewtonSettings, current_at, paper_scene, run_ramp
from soft_gripper_env.physics import simulator as simulator_module

SUCCESS_SEED = 2
"""A seed the reactive controller takes in both rod models at their defaults (it succeeds on about three seeds in
four; seed 1, used before, failed in 3-D once friction was capped at four passes)."""
BELOW_LIMIT_SEED = 1
"""A seed on which the reactive controller's planar grip stays below the specimen's fragility limit."""

ENV_ID = soft_gripper_env.ENV_ID


@pytest.fixture
def env():
    environment = gym.make(ENV_ID)
    yield environment
    environment.close()


def rollout(env, actions, seed, options=None):
    obs, _ = env.reset(seed=seed, options=options)
    out = [obs]
    rewards = []
    for action in actions:
        obs, reward, terminated, truncated, _ = env.step(action)
        out.append(obs)
        rewards.append(reward)
        if terminated or truncated:
            break
    return np.array(out), np.array(rewards)


def test_make_without_import_registers_and_sets_the_time_limit():
    code = ("import gymnasium as gym; env = gym.make('soft_gripper_env:SoftGripperUnderwater-v0'); "
            "print(env.spec.max_episode_steps, env.observation_space.shape)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["80", f"({observation_bounds(GraspTask())[0].size},)"]


def test_gymnasium_and_sb3_checkers_pass_without_warnings(env):
    from gymnasium.utils.env_checker import check_env as gym_check
    from stable_baselines3.common.env_checker import check_env as sb3_check

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        gym_check(env.unwrapped)
        sb3_check(SoftGripperUnderwaterEnv(), warn=True)


def test_same_seed_same_rollout_and_other_seed_another(env):
    actions = np.random.default_rng(0).uniform(-1, 1, (8, 3))
    first, rewards = rollout(env, actions, seed=3)
    second, rewards_again = rollout(env, actions, seed=3)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(rewards, rewards_again)
    other, _ = rollout(env, actions, seed=4)
    assert np.abs(other[0] - first[0]).max() > 1e-4  # another sphere


def test_pickled_env_continues_identically(env):
    env.reset(seed=5)
    for _ in range(3):
        env.step(np.array([-0.5, -0.5, -0.5]))
    copy = pickle.loads(pickle.dumps(env))
    for _ in range(3):
        a = env.step(np.array([-0.2, 0.1, -0.4]))
        b = copy.step(np.array([-0.2, 0.1, -0.4]))
        np.testing.assert_array_equal(a[0], b[0])
        assert a[1] == b[1]


def test_reward_terms_sum_to_the_reward_and_info_types(env):
    obs, info = env.reset(seed=1)
    assert set(info["reward_terms"]) == {"reach", "contact", "hold", "rest", "pressure", "effort", "harm", "success"}
    policy = RampPolicy(rate=-GraspTask().max_curvature_rate)  # the action −1, the fastest closing
    touched = False
    reach = []
    for _ in range(20):
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        reach.append(info["reward_terms"]["reach"])
        assert isinstance(reward, float) and isinstance(terminated, bool) and isinstance(truncated, bool)
        assert reward == pytest.approx(sum(info["reward_terms"].values()), abs=1e-12)
        assert info["reward_terms"]["effort"] == pytest.approx(-0.05 * 1.0)
        assert info["reward_terms"]["success"] == 0.0 and info["reward_terms"]["pressure"] <= 0.0
        touched |= info["reward_terms"]["contact"] > 0
        assert isinstance(info["is_success"], bool) and not info["solver_failure"]
    assert touched  # the contact term was exercised, not only zeros
    assert 0.0 <= min(reach) and max(reach) <= 0.25 and max(reach) > reach[0] + 0.05  # closing fingers reach


@pytest.mark.slow
def test_thousand_random_steps_stay_finite_and_inside_the_space():
    env = gym.make(ENV_ID, max_episode_steps=25)
    env.action_space.seed(0)
    obs, _ = env.reset(seed=0)
    for _ in range(1000):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample() * 1.5)  # beyond ±1: clipped
        assert obs.dtype == np.float32 and np.isfinite(obs).all() and env.observation_space.contains(obs)
        assert np.isfinite(reward)
        if terminated or truncated:
            obs, _ = env.reset()


def test_paper_scene_with_the_scripted_ramp_reproduces_the_core_simulator():
    """The env rollout of the paper's exact scene (fixed ball, Stokes drag, no buoyancy) with the constant rate
    −0.15 1/s equals the core simulator's direct run of that scene to 1e-9 m at every control step (at the paper's
    Δt and the core's Newton tolerance, and with a linear action map: the float32 action's rounding, cubed, would
    move the rate by 1e-8 of itself)."""
    env = gym.make(ENV_ID, model="planar", physics_dt=0.01, newton=NewtonSettings(), action_exponent=1.0)
    obs, _ = env.reset(seed=0, options={"scene": "paper"})
    policy = RampPolicy(GraspTask(action_exponent=1.0))
    layout = observation_slices(GraspTask(model="planar"))
    reference = run_ramp(replace(paper_scene(grasped_object=PAPER_BALL), natural_curvature_rate=PAPER_RATE))
    positions = [obs[layout["node_positions"]]]
    for _ in range(20):  # 1 s
        obs, *_ = env.step(policy(obs))
        positions.append(obs[layout["node_positions"]])
    env_planar = np.array(positions, dtype=np.float64).reshape(21, 3, 20, 2)
    ref = reference.positions[::5, 0]  # (21, F, N, 3) world, every 0.05 s
    directions = np.array([[np.cos(a), np.sin(a), 0.0] for a in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)])
    ref_planar = np.stack([np.einsum("tfnk,fk->tfn", ref, directions), ref[..., 2]], axis=-1)
    assert np.abs(ref_planar).max() > 0.1
    # the observation is float32: compare at its resolution, and the env's float64 state at 1e-9 m
    np.testing.assert_allclose(env_planar, ref_planar, atol=2e-8, rtol=0)
    state = env.unwrapped._batch.state
    world = env.unwrapped._batch.sim.world_positions(state)[0]
    np.testing.assert_allclose(world, reference.positions[-1, 0], atol=1e-9, rtol=0)
    assert obs[layout["normal_forces"]].sum() > 0.1  # it touched the ball


@pytest.mark.parametrize("num_threads", [1, 2])
def test_vector_env_matches_single_envs_including_autoreset(num_threads):
    """make_vec (one batched simulator, or two shards on two threads) against Gymnasium's SyncVectorEnv of single
    envs, same seeds and actions, with episodes short enough that every env autoresets twice."""
    n, steps = 3, 10
    vector = gym.make_vec(ENV_ID, num_envs=n, max_episode_steps=4, num_threads=num_threads)
    assert isinstance(vector.unwrapped, SoftGripperUnderwaterVectorEnv)
    assert len(vector.unwrapped._shards) == num_threads
    reference = gym.vector.SyncVectorEnv([lambda: gym.make(ENV_ID, max_episode_steps=4) for _ in range(n)])
    actions = np.random.default_rng(1).uniform(-1, 1, (steps, n, 3))
    obs, info = vector.reset(seed=11)
    ref_obs, ref_info = reference.reset(seed=11)
    np.testing.assert_allclose(obs, ref_obs, atol=1e-9, rtol=0)
    ended = np.zeros(n, dtype=int)
    for k in range(steps):
        obs, reward, terminated, truncated, info = vector.step(actions[k])
        ended += terminated | truncated
        ref_obs, ref_reward, ref_terminated, ref_truncated, ref_info = reference.step(actions[k])
        np.testing.assert_allclose(obs, ref_obs, atol=1e-6, rtol=0)
        np.testing.assert_allclose(reward, ref_reward, atol=1e-9, rtol=0)
        np.testing.assert_array_equal(terminated, ref_terminated)
        np.testing.assert_array_equal(truncated, ref_truncated)
        np.testing.assert_array_equal(info["is_success"], ref_info["is_success"])
        np.testing.assert_allclose(info["reward_terms"]["contact"], ref_info["reward_terms"]["contact"], atol=1e-9)
    assert np.all(ended >= 2)  # every env ended twice, so both autoresets were compared
    vector.close()


def test_threads_give_the_one_thread_results_bitwise():
    """Shards on threads step each env exactly as one batch does, autoresets and infos included."""
    runs = []
    for num_threads in (1, 2, 5):
        vector = gym.make_vec(ENV_ID, num_envs=5, max_episode_steps=3, num_threads=num_threads, model="planar")
        actions = np.random.default_rng(4).uniform(-1, 1, (7, 5, 3))
        outputs = [vector.reset(seed=21)[0]]
        for action in actions:
            obs, reward, terminated, truncated, info = vector.step(action)
            outputs += [obs, reward, terminated, truncated, info["finger_forces_N"], info["reward_terms"]["reach"],
                        info["_is_success"]]
        outputs.append(vector.unwrapped.reset_done())
        vector.close()
        runs.append(outputs)
    for other in runs[1:]:
        assert all(np.array_equal(a, b) for a, b in zip(runs[0], other, strict=True))


def test_gymnasium_async_vector_env_matches_the_sync_one():
    """The single env works in Gymnasium's AsyncVectorEnv (one process per env): same results as SyncVectorEnv."""
    make = [lambda: gym.make(ENV_ID, model="planar", max_episode_steps=3) for _ in range(2)]
    actions = np.random.default_rng(2).uniform(-1, 1, (4, 2, 3)).astype(np.float32)
    results = []
    for vector in (gym.vector.AsyncVectorEnv(make), gym.vector.SyncVectorEnv(make)):
        outputs = [vector.reset(seed=5)[0]]
        for action in actions:
            obs, reward, terminated, truncated, _ = vector.step(action)
            outputs += [obs, reward, terminated, truncated]
        vector.close()
        results.append(outputs)
    assert all(np.array_equal(a, b) for a, b in zip(*results, strict=True))


def test_solver_failure_truncates_and_keeps_the_last_good_state(env, monkeypatch):
    """A gripper whose step fails (its halvings spent) stops with the state before that step, as the compiled steps
    leave it (tests/physics/test_advance.py); the env then truncates the episode and reports the failure."""
    obs, _ = env.reset(seed=2)

    def failing(first, *arguments):  # every running gripper fails its first step
        interval = arguments[-1]
        interval.failed[:] = interval.running
        interval.running[:] = False
        return first

    monkeypatch.setattr(simulator_module, "take_steps", failing)
    after, reward, terminated, truncated, info = env.step(np.zeros(3))
    assert truncated and not terminated and info["solver_failure"]
    np.testing.assert_array_equal(after, obs)
    assert np.isfinite(reward)


def test_observation_maps_nan_to_zero_and_clips_infinities(env):
    """A value that is not finite never reaches the agent: NaN reads as 0 (clipped into the space), ±inf as the
    bound; the other entries are untouched."""
    from soft_gripper_env.env import _observations

    obs, _ = env.reset(seed=3)
    inner = env.unwrapped
    batch, where = inner._batch, observation_slices(inner.task)["natural_curvature"]
    batch.natural_curvature[0] = [np.nan, np.inf, -np.inf]
    low, high = inner.observation_space.low[where], inner.observation_space.high[where]
    after = _observations(batch, inner._low, inner._high)[0]
    np.testing.assert_array_equal(after[where], [np.clip(0.0, low[0], high[0]), high[1], low[2]])
    rest = np.ones(len(obs), dtype=bool)
    rest[where] = False
    np.testing.assert_array_equal(after[rest], obs[rest])
    assert after.dtype == np.float32


def test_rgb_frame_and_recorded_video(tmp_path):
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(12):
        env.step(np.full(3, -1.0))
    frame = env.render()
    assert frame.shape == (480, 480, 3) and frame.dtype == np.uint8
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 50  # a picture, not a blank canvas
    assert env.metadata["render_fps"] == pytest.approx(20.0)
    recorded = gym.wrappers.RecordVideo(gym.make(ENV_ID, render_mode="rgb_array", max_episode_steps=5),
                                        str(tmp_path / "videos"), disable_logger=True)
    recorded.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = recorded.step(np.full(3, -0.3))
        done = terminated or truncated
    recorded.close()
    videos = list((tmp_path / "videos").glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 1000


@pytest.mark.parametrize("action, pattern", [
    (np.array([np.nan, 0.0, 0.0]), r"must be finite"),
    (np.array([0.0, np.inf, 0.0]), r"must be finite"),
    (np.zeros(2), r"shape \(2,\); expected \(3,\)"),
    (np.zeros((1, 3)), r"shape \(1, 3\); expected \(3,\)"),
    ("close", r"not numeric"),
])
def test_bad_actions_raise(env, action, pattern):
    env.reset(seed=0)
    with pytest.raises(ValueError, match=pattern):
        env.step(action)


@pytest.mark.parametrize("options, pattern", [
    ({"radius": 0.05}, r"reset options \['radius'\] are unknown"),
    ({"object_radius": 0.5}, r"object_radius = 0\.5 m is outside the allowed range \[0\.01, 0\.09\)"),
    ({"object_density": float("nan")}, r"object_density = nan"),
    ({"object_offset": (0.0, 0.0)}, r"object_offset = \(0\.0, 0\.0\) must have 3 components"),
    ({"current_velocity": (0.0, 2.0, 0.0)}, r"current_velocity = 2\.0 m/s is outside"),
    ({"scene": "lake"}, r"scene = 'lake' is not one of 'task', 'paper'"),
    ("paper", r"reset options must be a dict or None"),
])
def test_bad_reset_options_raise(env, options, pattern):
    with pytest.raises(ValueError, match=pattern):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("settings_, pattern", [
    ({"model": "2d"}, r"GraspTask\.model = '2d' is not one of 'planar', '3d'"),
    ({"observation": "nodes"}, r"GraspTask\.observation = 'nodes' is not one of 'full', 'sensors'"),
    ({"control_dt": 0.0135}, r"control_dt = 0\.0135 s must be a whole multiple of physics_dt"),
    ({"physics_dt": 0.0}, r"physics_dt = 0\.0 s is outside the allowed range"),
    ({"physics_dt": 0.06, "control_dt": 0.06}, r"physics_dt = 0\.06 s is outside the allowed range \(0, 0\.05\] s"),
    ({"curvature_range": (-3.0, 0.0)}, r"curvature_range = -3\.0 \(dimensionless\) is outside"),
    ({"curvature_range": (-0.1, -0.05)}, r"must contain 0"),
    ({"object_radius": (0.06, 0.04)}, r"object_radius = \(0\.06, 0\.04\) must be a \(low, high\) pair"),
    ({"render_mode": "ascii"}, r"render_mode = 'ascii' is not one of"),
    ({"fragile_force": (-1.0, 1.0)}, r"fragile_force = -1\.0 N is outside"),
    ({"object_friction": -0.1}, r"object_friction = -0\.1 is outside the allowed range \[0, inf\]"),
    ({"newton": 1e-6}, r"GraspTask\.newton must be a NewtonSettings, got float"),
    ({"pressure_onset": 1.0}, r"GraspTask\.pressure_onset = 1\.0 \(dimensionless\) is outside the allowed range"),
    ({"friction_passes": -1}, r"GraspTask\.friction_passes = -1 is outside the allowed range: None or an integer"),
    ({"friction_passes": 2.5}, r"GraspTask\.friction_passes = 2\.5 is outside the allowed range"),
])
def test_bad_settings_raise(settings_, pattern):
    with pytest.raises(ValueError, match=pattern):
        SoftGripperUnderwaterEnv(**settings_)


def test_the_newton_setting_reaches_the_solver():
    """GraspTask.newton sets the simulator's stopping rule: a looser tolerance takes fewer Newton iterations."""
    iterations = {}
    for tolerance in (1e-9, 1e-3):
        env = SoftGripperUnderwaterEnv(model="planar", newton=NewtonSettings(relative_tolerance=tolerance))
        env.reset(seed=0)
        assert env.unwrapped._batch.sim.scene.newton.relative_tolerance == tolerance
        iterations[tolerance] = sum(env.step(np.full(3, -1.0))[4]["newton_iterations"] for _ in range(5))
    assert iterations[1e-3] < iterations[1e-9]


def test_each_rod_model_takes_its_own_default_step_and_friction_passes():
    """physics_dt and friction_passes default to the model's (MODEL_DEFAULTS: 1.25 ms with four passes in 3-D,
    0.625 ms with two planar); given ones are kept, None included."""
    assert MODEL_DEFAULTS == {"3d": {"physics_dt": 0.00125, "friction_passes": 4},
                              "planar": {"physics_dt": 0.000625, "friction_passes": 2}}
    three_d, planar = GraspTask(), GraspTask(model="planar")
    assert (three_d.physics_dt, three_d.friction_passes, three_d.substeps) == (0.00125, 4, 40)
    assert (planar.physics_dt, planar.friction_passes, planar.substeps) == (0.000625, 2, 80)
    given = GraspTask(model="planar", physics_dt=0.01, friction_passes=None)
    assert (given.physics_dt, given.friction_passes) == (0.01, None)
    assert GraspTask(friction_passes=1).friction_passes == 1
    env = SoftGripperUnderwaterEnv()
    env.reset(seed=0)
    assert env.task.physics_dt == 0.00125
    assert env.unwrapped._batch.sim.scene.contact.friction_passes == 4


def test_the_largest_physics_step_is_allowed():
    """physics_dt may be 0.05 s, the documented limit, itself."""
    env = SoftGripperUnderwaterEnv(physics_dt=0.05)
    assert env.task.substeps == 1


def test_vector_env_bad_input_and_step_before_reset():
    vector = SoftGripperUnderwaterVectorEnv(num_envs=2)
    with pytest.raises(gym.error.ResetNeeded):
        vector.step(np.zeros((2, 3)))
    vector.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(3,\); expected \(2, 3\)"):
        vector.step(np.zeros(3))
    with pytest.raises(ValueError, match=r"scene = 'paper' is for the single env"):
        vector.reset(options={"scene": "paper"})
    with pytest.raises(ValueError, match=r"num_threads = 3 is outside the allowed range \[1, 2\]"):
        SoftGripperUnderwaterVectorEnv(num_envs=2, num_threads=3)
    with pytest.raises(ValueError, match=r"num_threads = 0 is outside the allowed range"):
        SoftGripperUnderwaterVectorEnv(num_envs=2, num_threads=0)
    with pytest.raises(ValueError, match=r"num_envs = 0 is outside the allowed range"):
        SoftGripperUnderwaterVectorEnv(num_envs=0)
    with pytest.raises(gym.error.ResetNeeded):
        SoftGripperUnderwaterEnv().step(np.zeros(3))


def test_a_curriculum_draws_each_new_episodes_options_from_the_envs_generator():
    """``episode_options`` is called with each env's own generator before its episode's draws, at the first reset and
    at every autoreset; what it returns fixes the episode as ``reset``'s options would, and explicit options win."""

    def small_half(rng):
        return {"object_radius": float(rng.uniform(0.045, 0.05))} if rng.random() < 0.5 else {}

    vector = SoftGripperUnderwaterVectorEnv(num_envs=6, num_threads=2, max_episode_steps=1, episode_options=small_half,
                                            model="planar")
    radius = observation_slices(vector.task)["object_radius"]
    observations, _ = vector.reset(seed=40)
    rngs = [np.random.default_rng(40 + i) for i in range(6)]

    def by_hand():  # the same draws made by hand: the curriculum's first, then the episode's own
        return [task_episode(GraspTask(), rng, small_half(rng)).scene.grasped_object.radius for rng in rngs]

    first = by_hand()
    assert observations[:, radius][:, 0] == pytest.approx(first, rel=1e-6)
    assert 0 < sum(r < 0.05 for r in first) < 6
    vector.step(np.zeros((6, 3)))  # every episode ends after one step; the next step resets them
    observations, *_ = vector.step(np.zeros((6, 3)))
    assert observations[:, radius][:, 0] == pytest.approx(by_hand(), rel=1e-6)
    fixed, _ = vector.reset(seed=40, options={"object_radius": 0.055})
    assert fixed[:, radius][:, 0] == pytest.approx(0.055)
    everyone = SoftGripperUnderwaterVectorEnv(num_envs=4, episode_options=lambda rng: {"object_radius": 0.046},
                                              model="planar")
    assert everyone.reset(seed=1)[0][:, radius][:, 0] == pytest.approx(0.046)
    with pytest.raises(TypeError, match="episode_options must be a function"):
        SoftGripperUnderwaterVectorEnv(num_envs=2, episode_options={"object_radius": 0.05})
    with pytest.raises(ValueError, match="object_radius"):
        SoftGripperUnderwaterVectorEnv(num_envs=2, episode_options=lambda rng: {"object_radius": 0.5}).reset(seed=0)
    with pytest.raises(ValueError, match="episode_options drew scene = 'paper'"):
        SoftGripperUnderwaterVectorEnv(num_envs=2, episode_options=lambda rng: {"scene": "paper"}).reset(seed=0)


def test_reset_options_fix_the_scene(env):
    options = {"object_radius": 0.045, "object_density": 1003.0, "object_offset": (0.01, -0.01, 0.0),
               "current_velocity": (0.01, 0.0, 0.0), "current_oscillation": (0.0, 0.0, 0.0), "fragile_force": 1.5,
               "gust_velocity": (0.0, 0.1, 0.0), "gust_start": 2.2}
    task = GraspTask()
    layout = observation_slices(task)
    for seed in (0, 1):
        obs, info = env.reset(seed=seed, options=options)
        start = np.add(task.start_point, (0.01, -0.01, 0.0))
        np.testing.assert_allclose(obs[layout["object_offset"]], start - np.asarray(task.grasp_point), atol=1e-7)
        assert obs[layout["fragile_force"]][0] == pytest.approx(1.5) and info["fragile_force_N"] == 1.5
        assert obs[layout["object_radius"]][0] == pytest.approx(0.045) and obs[layout["episode_fraction"]][0] == 0.0
        scene = env.unwrapped._batch.sim.scenes[0]
        assert scene.grasped_object.radius == 0.045 and scene.grasped_object.density == 1003.0
        current = scene.fluid.current
        assert current.gust_velocity == (0.0, 0.1, 0.0) and current.gust_start == 2.2
        # the gust at its peak, on top of the mean current
        np.testing.assert_allclose(current_at(current, 2.2 + task.gust_duration / 2), [0.01, 0.1, 0.0], atol=1e-12)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(actions=st.lists(st.lists(st.floats(-5.0, 5.0, allow_nan=False), min_size=3, max_size=3), min_size=1,
                        max_size=4),
       radius=st.floats(0.01, 0.0899), density=st.floats(500.0, 2999.0),
       offset=st.lists(st.floats(-0.05, 0.0499), min_size=3, max_size=3),
       current=st.lists(st.floats(-0.5, 0.4999), min_size=3, max_size=3))
def test_fuzzed_actions_and_options_give_valid_observations(env, actions, radius, density, offset, current):
    obs, _ = env.reset(seed=0, options={"object_radius": radius, "object_density": density, "object_offset": offset,
                                        "current_velocity": current})
    assert env.observation_space.contains(obs)
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(np.array(action))
        assert env.observation_space.contains(obs) and np.isfinite(reward)
        if terminated or truncated:
            break


def test_reactive_policy_approaches_cages_and_regulates_the_force():
    task = GraspTask()
    policy = ReactivePolicy(task, grip=0.3, gust_grip=0.4, gain=0.2, press_rate=0.02, slow_gap=0.02, slowest=0.2)
    layout = observation_slices(task)

    def rates(forces, touching, gaps=(0.05, 0.05, 0.05), limit=2.0, fraction=0.1):
        obs = np.zeros(observation_bounds(task)[0].size, dtype=np.float32)
        obs[layout["finger_forces"]] = forces
        obs[layout["touching"]] = touching
        obs[layout["finger_gaps"]] = gaps
        obs[layout["fragile_force"]] = limit
        obs[layout["episode_fraction"]] = fraction
        return task.curvature_rate(policy(obs).astype(float))

    np.testing.assert_allclose(rates(0, 0), APPROACH_RATE, rtol=1e-5)  # far from the specimen: closing fast
    np.testing.assert_allclose(rates(0, 0, gaps=(0.01, 0.002, 0.0)), APPROACH_RATE * np.array([0.5, 0.2, 0.2]),
                               rtol=1e-5)  # slowing within 2 cm, to a fifth of the rate
    # one finger touches below its target: it waits while the others close; above its target it backs off
    np.testing.assert_allclose(rates([0.2, 0, 0], [1, 0, 0]), [0.0, APPROACH_RATE, APPROACH_RATE], rtol=1e-5)
    np.testing.assert_allclose(rates([1.2, 0, 0], [1, 0, 0])[0], 0.02, rtol=1e-5)
    # all touch: each regulates towards 0.3 × 2 N, proportionally, at most 0.02 1/s either way
    expected = np.clip(0.2 * task.max_curvature_rate * (np.array([0.55, 0.6, 0.9]) - 0.6) / 0.6, -0.02, 0.02)
    np.testing.assert_allclose(rates([0.55, 0.6, 0.9], [1, 1, 1]), expected, rtol=1e-5, atol=1e-7)
    # while a gust may blow, the target is 0.4 × 2 N: 0.6 N is now too little
    assert np.all(rates([0.6, 0.6, 0.6], [1, 1, 1], fraction=0.6) < 0.0)
    batch = np.stack([np.zeros(observation_bounds(task)[0].size, dtype=np.float32)] * 2)
    assert policy(batch).shape == (2, 3)
    with pytest.raises(ValueError, match=r"rate = -2\.0 1/s is outside"):
        RampPolicy(rate=-2.0)
    with pytest.raises(ValueError, match=r"ReactivePolicy\.grip = 1\.5 \(dimensionless\) is outside"):
        ReactivePolicy(task, grip=1.5)
    with pytest.raises(ValueError, match=r"ReactivePolicy\.press_rate = 0\.0 1/s is outside"):
        ReactivePolicy(task, press_rate=0.0)
    with pytest.raises(ValueError, match=r"ReactivePolicy\.approach_rate = 0\.0 1/s is outside the allowed range "
                                         r"\[-0\.3, 0\)"):
        ReactivePolicy(task, approach_rate=0.0)


def test_a_graded_touch_makes_the_reactive_controller_continuous_in_the_force():
    """With ``touch_force`` the controller blends approach, wait and grip by a touch weight F / touch_force: at 0 N
    and at or above touch_force it acts as the on-off controller does at those forces, between them its rate
    moves by no more than the force's change allows (no jump at a threshold), and the touch flag is not read."""
    task = GraspTask()
    gains = {"grip": 0.3, "gust_grip": 0.4, "gain": 0.2, "press_rate": 0.02, "slow_gap": 0.02, "slowest": 0.2}
    graded, switched = ReactivePolicy(task, touch_force=0.05, **gains), ReactivePolicy(task, **gains)
    layout = observation_slices(task)

    def rates(policy, forces, touching):
        obs = np.zeros((len(forces), observation_bounds(task)[0].size), dtype=np.float32)
        obs[:, layout["finger_forces"]] = forces
        obs[:, layout["touching"]] = touching
        obs[:, layout["finger_gaps"]] = 0.05
        obs[:, layout["fragile_force"]] = 2.0
        obs[:, layout["episode_fraction"]] = 0.1
        return task.curvature_rate(policy(obs).astype(float))

    ends = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0], [0.55, 0.6, 0.9], [1.2, 0.0, 0.0]])
    np.testing.assert_allclose(rates(graded, ends, 0.0), rates(switched, ends, ends >= 0.05), rtol=1e-6, atol=1e-9)
    # the middle finger's force swept from 0 to 0.1 N with the others pressing: one finger approaches, then all grip
    sweep = np.linspace(0.0, 0.1, 1001)
    forces = np.stack([np.full_like(sweep, 0.5), sweep, np.full_like(sweep, 0.7)], axis=1)
    swept = rates(graded, forces, 1.0)
    assert swept[0, 1] == pytest.approx(APPROACH_RATE, rel=1e-5) and np.all(swept[-1] >= -0.02 - 1e-6)
    steps = np.abs(np.diff(swept, axis=0)).max()
    assert steps < 0.01 * abs(APPROACH_RATE), f"the rate jumps by {steps} 1/s for a 0.1 mN change of force"
    assert np.abs(np.diff(rates(switched, forces, forces >= 0.05), axis=0)).max() > 0.5 * abs(APPROACH_RATE)
    with pytest.raises(ValueError, match=r"ReactivePolicy\.touch_force = 0\.0 N is outside"):
        ReactivePolicy(task, touch_force=0.0)


def test_the_cubic_action_map_and_its_inverse():
    """An action a sets the rate max_curvature_rate·sign(a)·|a|³; action_for_rate inverts it (and clips)."""
    task = GraspTask()
    actions = np.linspace(-1.0, 1.0, 41)
    assert task.max_curvature_rate == 0.3  # the fastest closing, 1/s
    np.testing.assert_allclose(task.curvature_rate(actions), 0.3 * np.sign(actions) * np.abs(actions) ** 3)
    np.testing.assert_allclose(task.action_for_rate(task.curvature_rate(actions)), actions, atol=1e-12)
    assert task.action_for_rate(-2.0) == -1.0
    linear = GraspTask(action_exponent=1.0, max_curvature_rate=0.5)
    np.testing.assert_allclose(linear.curvature_rate(actions), 0.5 * actions)


@pytest.mark.parametrize("slowing_gap", [None, 0.02])
def test_the_closing_reflexes_bound_each_fingers_closing(slowing_gap):
    """With ``touching_closing_rate`` b, the fastest closing (−1) moves a finger that touches at the start of the
    interval by b·Δt; with ``approach_slowing_gap`` G as well, one that does not by (b + (r − b)·min(gap/G, 1))·Δt,
    gap read at the start of the interval and r the fastest rate (without G: r·Δt); so a finger far away closes at
    r and one in contact but not yet touching at b. Opening is never bounded."""
    bound = 0.05
    env = gym.make(ENV_ID, model="planar", touching_closing_rate=bound, approach_slowing_gap=slowing_gap)
    env.reset(seed=5000)
    batch = env.unwrapped._batch
    dt, full = batch.task.control_dt, batch.task.max_curvature_rate
    closing = {"touching", "far"} | ({"near"} if slowing_gap else set())
    seen = set()
    for _ in range(60):
        touching, gap = batch.touching[0].copy(), batch.finger_gap[0].copy()
        before = batch.natural_curvature[0].copy()
        action = np.array([1.0, -1.0, -1.0]) if closing <= seen else np.full(3, -1.0)
        env.step(action.astype(np.float32))
        change = batch.natural_curvature[0] - before
        for f in range(3):
            kind = "touching" if touching[f] else "far" if gap[f] >= (slowing_gap or 0.0) else "near"
            if action[f] > 0:
                rate, kind = full, kind + " opening"
            elif touching[f]:
                rate = -bound
            else:
                rate = -(bound + (full - bound) * min(gap[f] / slowing_gap, 1.0) if slowing_gap else full)
            expected = np.clip(before[f] + rate * dt, *batch.task.curvature_range) - before[f]
            assert change[f] == pytest.approx(expected, abs=1e-12), (f, kind, gap[f])
            seen.add(kind)
        if "touching opening" in seen:
            break
    assert closing | {"touching opening"} <= seen, seen
    env.close()


def test_the_closing_reflexes_refuse_settings_out_of_range():
    with pytest.raises(ValueError, match=r"GraspTask\.touching_closing_rate = -0\.1 1/s is outside the allowed "
                                         r"range \(0, 100\)"):
        GraspTask(touching_closing_rate=-0.1)
    with pytest.raises(ValueError, match=r"GraspTask\.approach_slowing_gap = 0\.01 m slows the approach to "
                                         r"GraspTask\.touching_closing_rate, which must then be set"):
        GraspTask(approach_slowing_gap=0.01)
    with pytest.raises(ValueError, match=r"at most GraspTask\.max_curvature_rate = 0\.3 1/s \(got 0\.5\)"):
        GraspTask(approach_slowing_gap=0.01, touching_closing_rate=0.5)
    with pytest.raises(ValueError, match=r"GraspTask\.approach_slowing_gap = 0\.0 m is outside the allowed range "
                                         r"\(0, 0\.1\]"):
        GraspTask(approach_slowing_gap=0.0, touching_closing_rate=0.05)


def test_reactive_grasp_succeeds_once_held_through_the_gust():
    """On a seed the reactive controller takes, is_success turns on only after the gust has passed and the hold
    has lasted 1 s, and the episode ends truncated at 4 s with the success bonus."""
    env = gym.make(ENV_ID)
    policy = ReactivePolicy()
    obs, info = env.reset(seed=SUCCESS_SEED)
    gust = env.unwrapped._batch.sim.scenes[0].fluid.current
    flags, holds, times = [], [], []
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        flags.append(info["is_success"])
        holds.append(info["hold_time_s"])
        times.append(info["time_s"])
        done = terminated or truncated
    assert flags[-1] and truncated and not terminated and not info["harmed"]
    assert info["reward_terms"]["success"] == GraspTask().reward.success
    first = flags.index(True)
    assert times[first] >= gust.gust_start + gust.gust_duration - 1e-9 and holds[first] >= 1.0 - 1e-9
    assert times[-1] == pytest.approx(GraspTask().episode_duration)
    assert all(holds[k] == pytest.approx(holds[k - 1] + 0.05) or holds[k] == 0.0 for k in range(1, len(holds)))


def test_without_a_gust_success_asks_only_for_the_hold():
    """An episode whose gust is still (or the paper's scene, which has none) is judged by the hold alone: nothing
    to keep the specimen through."""
    env = gym.make(ENV_ID)
    env.reset(seed=0, options={"gust_velocity": (0.0, 0.0, 0.0), "gust_start": 0.0})
    batch = env.unwrapped._batch
    assert not batch.has_gust[0]  # a gust at 0 s would need every finger touching at once; a still one does not
    for _ in range(3):
        env.step(np.zeros(3))
    assert batch.kept_through_gust[0]
    env.reset(seed=0, options={"scene": "paper"})
    assert not batch.has_gust[0] and batch.fragile_force[0] == math.inf


def test_pressing_above_the_fragility_limit_harms_and_ends_the_episode():
    env = gym.make(ENV_ID)
    obs, info = env.reset(seed=0, options={"fragile_force": 0.05, "object_offset": (0.0, 0.0, 0.0)})
    done, steps = False, 0
    while not done:
        obs, reward, terminated, truncated, info = env.step(-np.ones(3))
        done = terminated or truncated
        steps += 1
    assert terminated and info["harmed"] and not info["is_success"] and steps < 40
    assert info["reward_terms"]["harm"] == -GraspTask().reward.harm
    sustained = env.unwrapped._batch.sustained_force
    assert sustained.max() > 0.05


def pressure_term(task: GraspTask, load: float) -> float:
    """The pressure term written out: −weight/2 · clip((load − c)/(1 − c), 0, 2)."""
    onset = task.pressure_onset
    return -task.reward.pressure / 2 * min(max((load - onset) / (1.0 - onset), 0.0), 2.0)


@pytest.mark.parametrize("onset", [0.0, 0.1, 0.7])
def test_the_pressure_penalty_grows_from_its_onset_to_the_limit(onset):
    """The pressure term is −weight/2 · clip((F/F_max − c)/(1 − c), 0, 2), F the largest finger force of the
    control interval, at every step of a reactive grasp, which pays it only for onsets below its grip's load."""
    env = SoftGripperUnderwaterEnv(model="planar", pressure_onset=onset)
    policy = ReactivePolicy(env.task)
    obs, _ = env.reset(seed=BELOW_LIMIT_SEED)
    terms, loads = [], []
    for _ in range(60):
        obs, _, terminated, truncated, info = env.step(policy(obs))
        load = info["finger_forces_N"].max() / info["fragile_force_N"]
        assert info["reward_terms"]["pressure"] == pytest.approx(pressure_term(env.task, load), rel=1e-12,
                                                                 abs=1e-15)
        terms.append(info["reward_terms"]["pressure"])
        loads.append(load)
        assert not terminated
    assert 0.05 < max(loads) < 1.0  # a grip below the limit
    assert (min(terms) < 0.0) == (onset < max(loads))
    if onset == 0.0:
        assert min(terms) == pytest.approx(-env.task.reward.pressure / 2 * max(loads))


def test_the_pressure_penalty_keeps_growing_past_the_limit():
    """Closing at full rate squeezes the specimen: the interval's force passes the fragility limit before the
    harm rule's filtered force does, and the penalty there exceeds half its weight, up to the whole weight."""
    env = SoftGripperUnderwaterEnv(model="planar")
    obs, _ = env.reset(seed=SUCCESS_SEED)
    loads, terms = [], []
    terminated = truncated = False
    while not (terminated or truncated):
        obs, _, terminated, truncated, info = env.step(np.full(3, -1.0, dtype=np.float32))
        loads.append(info["finger_forces_N"].max() / info["fragile_force_N"])
        terms.append(info["reward_terms"]["pressure"])
        assert terms[-1] == pytest.approx(pressure_term(env.task, loads[-1]), rel=1e-12, abs=1e-15)
    beyond = [term for load, term in zip(loads, terms, strict=True) if load > 1.0 + 1e-9]
    assert beyond and all(term < -env.task.reward.pressure / 2 for term in beyond)
    assert min(terms) >= -env.task.reward.pressure


def test_reward_weights_changed_mid_episode_scale_their_term_and_nothing_else():
    """``set_reward_weights`` on a vector env (two shards) weighs the pressure warning anew from the next step, in
    every env, and leaves the dynamics, observations and the other terms as they were."""
    envs = [SoftGripperUnderwaterVectorEnv(4, num_threads=2, model="planar") for _ in range(2)]
    for env in envs:
        env.reset(seed=SUCCESS_SEED)
    weights = replace(envs[0].task.reward, pressure=3.0)
    action = np.full((4, 3), -1.0, dtype=np.float32)
    changed = False
    for step in range(30):
        if step == 5:
            envs[1].set_reward_weights(weights)
        (obs_a, reward_a, *_, info_a), (obs_b, reward_b, *_, info_b) = (env.step(action) for env in envs)
        np.testing.assert_array_equal(obs_a, obs_b)
        factor = 3.0 if step >= 5 else 1.0
        for name, term in info_a["reward_terms"].items():
            np.testing.assert_allclose(info_b["reward_terms"][name], term * (factor if name == "pressure" else 1.0),
                                       rtol=1e-12, atol=0)
        np.testing.assert_allclose(reward_b, reward_a + (factor - 1.0) * info_a["reward_terms"]["pressure"],
                                   rtol=1e-12, atol=1e-12)
        changed |= bool(step >= 5 and (info_a["reward_terms"]["pressure"] < 0).any())
    assert changed  # the warning was paid after the change, so the comparison could fail
    assert envs[1].task.reward.pressure == 3.0 and envs[1].task.model == "planar"
    with pytest.raises(TypeError, match="weights must be a RewardWeights"):
        envs[1].set_reward_weights({"pressure": 3.0})
    for env in envs:
        env.close()


def test_object_swept_away_by_the_current_terminates_the_episode():
    env = gym.make(ENV_ID)
    env.reset(seed=0, options={"current_velocity": (0.45, 0.0, 0.0), "current_oscillation": (0.0, 0.0, 0.0)})
    layout = observation_slices(GraspTask())
    steps = 0
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(np.zeros(3))
        steps += 1
    assert terminated and not truncated and steps < 60 and not info["harmed"]
    assert np.linalg.norm(obs[layout["object_offset"]]) > 0.15


def test_three_dimensional_fingers():
    env = gym.make(ENV_ID, model="3d")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (441,) and env.observation_space.contains(obs)
    layout = observation_slices(GraspTask(model="3d"))
    for _ in range(5):
        obs, reward, terminated, truncated, info = env.step(np.full(3, -1.0))
        assert env.observation_space.contains(obs)
    tips = obs[layout["node_positions"]].reshape(3, 20, 3)[:, -1]
    assert np.all(tips[:, 2] < -1e-3)  # every fingertip curls down


@pytest.mark.parametrize("model", ["planar", "3d"])
def test_sensors_observation_is_the_full_ones_readings_and_the_same_size_in_both_models(model):
    """The same episode observed both ways: the sensors' observation is the full one without the node parts, value
    for value, and its layout does not depend on the rod model."""
    full, sensors = (SoftGripperUnderwaterEnv(model=model, observation=o) for o in ("full", "sensors"))
    full_layout = observation_slices(full.task)
    sensors_layout = observation_slices(sensors.task)
    assert sensors.observation_space.shape == (21,)
    assert sensors_layout == observation_slices(GraspTask(model="3d" if model == "planar" else "planar",
                                                          observation="sensors"))
    assert set(full_layout) - set(sensors_layout) == {"node_positions", "node_velocities", "normal_forces"}
    policy = ReactivePolicy(full.task)
    observations = [env.reset(seed=SUCCESS_SEED)[0] for env in (full, sensors)]
    for _ in range(30):
        action = policy(observations[0])
        observations = [env.step(action)[0] for env in (full, sensors)]
        assert sensors.observation_space.contains(observations[1])
    for name, part in sensors_layout.items():
        np.testing.assert_array_equal(observations[1][part], observations[0][full_layout[name]], err_msg=name)
    assert observations[1][sensors_layout["finger_forces"]].max() > 0  # the fingers touched: a real comparison
    low, high = observation_bounds(sensors.task)
    full_low, full_high = observation_bounds(full.task)
    for name, part in sensors_layout.items():
        np.testing.assert_array_equal(low[part], full_low[full_layout[name]])
        np.testing.assert_array_equal(high[part], full_high[full_layout[name]])


def test_human_render_mode_draws_without_a_display(monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    env = gym.make(ENV_ID, render_mode="human")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg cannot show a window; the frame is still drawn into the figure
        env.reset(seed=0)
        env.step(np.zeros(3))
    figure, image = env.unwrapped._window
    assert image.get_array().shape == (480, 480, 3)
    env.close()
    assert env.unwrapped._window is None


def test_spec_sheet_quotes_the_task_defaults():
    """The env's docstring is its spec sheet: the numbers it quotes must be the defaults it runs with."""
    sheet = " ".join(SoftGripperUnderwaterEnv.__doc__.split())
    task = GraspTask()
    low, high = task.curvature_range
    quoted = [f"({task.max_curvature_rate:g} 1/s)", f"({low:g} to {high:g}".replace("-", "−"),
              f"within {task.hold_distance:g} m of the grasp point {task.grasp_point}".replace("-", "−"),
              f"slower than {task.rest_speed:g} m/s", f"for the last {task.success_duration:g} s",
              f"more than {task.lost_distance:g} m", f"fragility limit ({task.fragile_force[0]:g}–"
              f"{task.fragile_force[1]:g} N)", f"radius ({task.object_radius[0]:g}–{task.object_radius[1]:g} m)",
              f"{task.gust_speed[0]:g}–{task.gust_speed[1]:g} m/s peak",
              f"begins between {task.gust_start[0]:g} and {task.gust_start[1]:g} s and lasts {task.gust_duration:g} s",
              f"``episode_duration`` = {task.episode_duration:g} s, {DEFAULT_MAX_EPISODE_STEPS} actions",
              "sign(a)·|a|³", f"``start_point`` {task.start_point} m".replace("-", "−")]
    missing = [text for text in quoted if text not in sheet]
    assert not missing, missing


def test_the_objects_friction_reaches_the_physics():
    """The task's object_friction is the sphere's μ and the palm's: with μ = ∞ no contact ever slides, with the
    default some do, on the same seed."""
    sliding = {}
    for friction in (math.inf, GraspTask().object_friction):
        env = gym.make(ENV_ID, object_friction=friction)
        policy = ReactivePolicy(GraspTask(object_friction=friction))
        obs, _ = env.reset(seed=1003)
        batch = env.unwrapped._batch
        assert batch.sim.scenes[0].grasped_object.friction == friction
        assert batch.sim.scenes[0].contact.palm_friction == min(friction, 1e5)
        slid = 0
        for _ in range(40):
            obs, *_ = env.step(policy(obs))
            contact = batch.sim.step(batch.state, batch.natural_curvature).contact
            slid += int(contact.sliding.sum())
        sliding[friction] = slid
    assert sliding[math.inf] == 0 and sliding[GraspTask().object_friction] > 0


def test_finger_gap_follows_the_state_through_steps_and_resets():
    """The task measures the finger gap once per state: after every step and through an autoreset it equals the
    distance from each finger's nearest surface to the sphere's, computed here from the nodes, the radii and the
    sphere's centre."""
    env = gym.make_vec(ENV_ID, num_envs=3, model="planar", max_episode_steps=7)
    env.reset(seed=11)
    batch = env.unwrapped._shards[0].batch
    rng = np.random.default_rng(0)
    changed = 0
    last = None
    for _ in range(12):
        gap = batch.finger_gap
        nodes = batch.sim.world_positions(batch.state)
        radii = np.array([scene.grasped_object.radius for scene in batch.sim.scenes])[:, None, None]
        surface = np.linalg.norm(nodes - batch.state.body_position[:, None, None, :], axis=-1) \
            - batch.sim.finger_contact_radius - radii
        np.testing.assert_allclose(gap, np.maximum(surface.min(axis=2), 0.0), rtol=0, atol=1e-12)
        changed += last is not None and not np.array_equal(gap, last)
        last = gap.copy()
        env.step(rng.uniform(-1.0, -0.5, (3, 3)).astype(np.float32))
    assert changed >= 8  # the gap moved with the fingers, and the comparison above saw new values
    env.close()


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), scale=st.floats(-8.0, 8.0), dtype=st.sampled_from([np.float64, np.float32]))
def test_task_norms_and_finger_means_are_numpys_to_the_bit(seed, scale, dtype):
    """The task's per-step helpers repeat NumPy's arithmetic exactly: norms as ``np.linalg.norm(axis=-1)``, finger
    means as ``mean(axis=1)`` (in float32 for float32 actions, in float64 for bool and integers)."""
    from soft_gripper_env.grasp_task import _finger_mean, _norms

    rng = np.random.default_rng(seed)
    vectors = (rng.normal(size=(5, 3, 20, 3)) * 10.0**scale).astype(dtype)
    np.testing.assert_array_equal(_norms(vectors), np.linalg.norm(vectors, axis=-1))
    values = vectors[:, :, 0, 0]
    # integers near 2**62: summed in int64 they would overflow, as ``mean`` never does
    integers = (values / 10.0**scale * 2.0**60).astype(np.int64)
    for array in (values, values > 0, integers):
        mean, expected = _finger_mean(array), array.mean(axis=1)
        assert mean.dtype == expected.dtype
        np.testing.assert_array_equal(mean, expected)
