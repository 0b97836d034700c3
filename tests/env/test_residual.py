"""Residual policies: a learnt correction to a scripted controller's natural-curvature rate (agents/residual.py)."""

import json

import numpy as np
import pytest

from agents.residual import ResidualAction, ResidualVecEnv, residual_policy
from agents.sb3_vec_env import SoftGripperSB3VecEnv
from agents.scripted import GRADED_3D_GAINS, TUNED_3D_GAINS, ReactivePolicy
from soft_gripper_env.grasp_task import GraspTask

SENSORS = GraspTask(observation="sensors", touching_closing_rate=0.15, approach_slowing_gap=0.01)


def observations(count: int, seed: int = 0) -> np.ndarray:
    """Observations of real episodes (the sensors' layout), some touching and some not."""
    env = SoftGripperSB3VecEnv(num_envs=count, seed=seed, observation="sensors")
    obs = env.reset()
    controller = ReactivePolicy(SENSORS)
    seen = [obs]
    for _ in range(40):
        env.step_async(controller(obs))
        obs = env.step_wait()[0]
        seen.append(obs)
    return np.concatenate(seen)


def test_a_residual_adds_its_rate_to_the_controllers_and_nothing_when_zero():
    controller = ReactivePolicy(SENSORS, **TUNED_3D_GAINS)
    combine = ResidualAction(SENSORS, controller, 0.1)
    obs = observations(2)
    base = controller(obs)
    np.testing.assert_allclose(combine(obs, np.zeros_like(base)), base, rtol=0, atol=1e-6)
    residual = np.random.default_rng(1).uniform(-1, 1, base.shape)
    rate = SENSORS.curvature_rate(combine(obs, residual).astype(float))
    wanted = np.clip(SENSORS.curvature_rate(base.astype(float)) + 0.1 * residual, -SENSORS.max_curvature_rate,
                     SENSORS.max_curvature_rate)
    np.testing.assert_allclose(rate, wanted, rtol=1e-5, atol=1e-7)  # float32 actions
    assert np.abs(rate - SENSORS.curvature_rate(base.astype(float))).max() > 0.05  # it does act
    # a residual outside [−1, 1] is clipped, as an env clips an action
    np.testing.assert_array_equal(combine(obs, 3 * np.ones_like(base)), combine(obs, np.ones_like(base)))
    with pytest.raises(ValueError, match="ResidualAction.rate"):
        ResidualAction(SENSORS, controller, 0.5)


def test_the_residual_vec_env_gives_the_controller_each_envs_raw_observation_after_autoresets():
    seen = []

    def base(observation):  # records what it acts on, and closes
        seen.append(np.array(observation))
        return np.full((len(observation), 3), -0.5, dtype=np.float32)

    inner = SoftGripperSB3VecEnv(num_envs=2, seed=3, max_episode_steps=3, observation="sensors")
    env = ResidualVecEnv(inner, ResidualAction(GraspTask(observation="sensors"), base, 0.1))
    with pytest.raises(RuntimeError, match="before reset"):
        env.step_async(np.zeros((2, 3)))
    returned = [env.reset()]
    for _ in range(4):
        env.step_async(np.zeros((2, 3), dtype=np.float32))
        obs, _, done, _ = env.step_wait()
        returned.append(obs)
    assert len(seen) == 4
    for given, obs in zip(seen, returned, strict=False):  # the observation the step before returned: after the
        np.testing.assert_array_equal(given, obs)  # third step's autoreset, the next episode's first


def test_a_residual_run_saves_its_controller_and_evaluates_as_the_two_together(tmp_path):
    from agents import train_ppo
    from agents.evaluate import load_ppo, ppo_policy

    train_ppo.main(["--out", str(tmp_path), "--timesteps", "128", "--num-envs", "4", "--model", "planar",
                    "--residual-to", "reactive_tuned", "--residual-rate", "0.05", "--eval-episodes", "0",
                    "--validate-every", "0", "--checkpoint-every", "0"])
    config = json.loads((tmp_path / "config.json").read_text())
    recorded = ReactivePolicy(SENSORS, **TUNED_3D_GAINS).settings()
    assert recorded["grip"] == TUNED_3D_GAINS["grip"] and recorded["touch_force"] is None
    assert config["residual"] == {"base": "reactive_tuned", "base_settings": recorded, "rate": 0.05,
                                  "gust_hold": False, "press_limit": None, "close_untouched": False,
                                  "press_taper": None}
    assert config["policy"]["log_std_init"] == pytest.approx(np.log(0.2))
    policy = load_ppo(tmp_path)
    import pickle

    from stable_baselines3 import PPO

    with open(tmp_path / "vecnormalize.pkl", "rb") as f:
        normalize = pickle.load(f)
    alone = ppo_policy(PPO.load(tmp_path / "ppo_model.zip", device="cpu"), normalize)
    obs = observations(2, seed=7)
    controller = ReactivePolicy(SENSORS, **TUNED_3D_GAINS)
    wanted = ResidualAction(SENSORS, controller, 0.05)(obs, alone(obs))
    np.testing.assert_array_equal(policy(obs), wanted)

    # the controller is rebuilt from the settings the run recorded, not from today's preset of that name
    config["residual"]["base_settings"] = {**recorded, "grip": 0.5, "gust_grip": 0.6}
    (tmp_path / "config.json").write_text(json.dumps(config))
    other = ReactivePolicy(SENSORS, **{**TUNED_3D_GAINS, "grip": 0.5, "gust_grip": 0.6})
    assert not np.array_equal(other(obs), controller(obs))
    np.testing.assert_array_equal(load_ppo(tmp_path)(obs), ResidualAction(SENSORS, other, 0.05)(obs, alone(obs)))
    del config["residual"]["base_settings"]  # a config from before the settings were recorded: the preset
    (tmp_path / "config.json").write_text(json.dumps(config))
    np.testing.assert_array_equal(load_ppo(tmp_path)(obs), wanted)
    assert policy.observation == "sensors" and policy.trained_task["model"] == "planar"
    assert not np.allclose(policy(obs), controller(obs), atol=1e-3)  # the residual is there


def test_a_residual_policy_keeps_what_the_evaluation_reads():
    def alone(observation):
        return np.zeros((len(observation), 3))

    alone.observation, alone.trained_task = "sensors", {"model": "3d"}
    policy = residual_policy(alone, ResidualAction(SENSORS, ReactivePolicy(SENSORS), 0.1))
    assert policy.observation == "sensors" and policy.trained_task == {"model": "3d"}
    obs = observations(1)
    np.testing.assert_allclose(policy(obs), ReactivePolicy(SENSORS)(obs), atol=1e-6)


def test_the_guards_stop_a_correction_opening_in_the_gust_window_and_closing_near_the_limit():
    from agents.scripted import gust_window
    from soft_gripper_env.env import observation_slices

    controller = ReactivePolicy(SENSORS, **TUNED_3D_GAINS)
    layout = observation_slices(SENSORS)
    obs = observations(2)
    free, guarded = ResidualAction(SENSORS, controller, 0.1), ResidualAction(SENSORS, controller, 0.1, True, 0.5)
    rng = np.random.default_rng(4)
    obs = np.repeat(obs, 2, axis=0)
    low, high = gust_window(SENSORS)
    obs[:, layout["episode_fraction"]] = rng.uniform(0.0, 1.0, (len(obs), 1))  # in and out of the window
    obs[:, layout["fragile_force"]] = 2.0
    obs[:, layout["finger_forces"]] = rng.uniform(0.0, 2.0, (len(obs), 3))  # below and above half the limit
    residual = rng.uniform(-1.0, 1.0, (len(obs), 3))

    def correction(combine):
        return SENSORS.curvature_rate(combine(obs, residual).astype(float)) \
            - SENSORS.curvature_rate(controller(obs).astype(float))

    fraction = obs[:, layout["episode_fraction"]]
    gusty = np.broadcast_to((fraction >= low) & (fraction <= high), residual.shape)
    pressing = obs[:, layout["finger_forces"]] > 1.0
    unguarded, kept = correction(free), correction(guarded)
    assert (gusty & (residual > 0)).any() and (pressing & (residual < 0)).any() and (~gusty & ~pressing).any()
    assert np.all(kept[gusty] <= 1e-6)  # no opening while a gust may blow
    assert np.all(kept[pressing] >= -1e-6)  # no closing above half the limit
    np.testing.assert_allclose(kept[~gusty & ~pressing], unguarded[~gusty & ~pressing], atol=1e-6)
    assert np.abs(unguarded[gusty & (residual > 0)]).max() > 0.01  # the guard is what removed it
    with pytest.raises(ValueError, match="ResidualAction.press_limit"):
        ResidualAction(SENSORS, controller, 0.1, press_limit=1.5)


def test_the_press_taper_scales_closing_by_the_margin_to_the_limit_and_leaves_opening():
    from soft_gripper_env.env import observation_slices

    controller = ReactivePolicy(SENSORS, **TUNED_3D_GAINS)
    layout = observation_slices(SENSORS)
    forces = np.array([0.0, 0.45, 0.9, 1.2, 0.3, 1.0])  # against 0.5 x 2 N: margins 1, 0.55, 0.1, 0, 0.7, 0
    obs = observations(1)[-len(forces):].copy()  # the last steps: fingers touching
    obs[:, layout["fragile_force"]] = 2.0
    obs[:, layout["finger_forces"]] = forces[:, None]
    residual = np.tile([-1.0, -0.5, 0.8], (len(obs), 1))
    free = ResidualAction(SENSORS, controller, 0.1)
    tapered = ResidualAction(SENSORS, controller, 0.1, press_taper=0.5)
    assert tapered.settings()["press_taper"] == 0.5

    def correction(combine):
        return SENSORS.curvature_rate(combine(obs, residual).astype(float)) \
            - SENSORS.curvature_rate(controller(obs).astype(float))

    margin = np.clip(1.0 - forces / 1.0, 0.0, 1.0)[:, None]
    unguarded, kept = correction(free), correction(tapered)
    assert np.abs(unguarded[:, :2]).min() > 0.01  # the correction closes those two fingers unguarded
    np.testing.assert_allclose(kept[:, :2], unguarded[:, :2] * margin, atol=1e-6)  # closing braked by the margin
    np.testing.assert_allclose(kept[:, 2], unguarded[:, 2], atol=1e-6)  # opening as it was
    with pytest.raises(ValueError, match="ResidualAction.press_taper"):
        ResidualAction(SENSORS, controller, 0.1, press_taper=0.0)


def test_the_untouched_guard_stops_a_correction_holding_back_a_finger_that_does_not_touch():
    from soft_gripper_env.env import observation_slices

    controller = ReactivePolicy(SENSORS, **TUNED_3D_GAINS)
    layout = observation_slices(SENSORS)
    rng = np.random.default_rng(7)
    obs = np.repeat(observations(2), 3, axis=0)
    obs[:, layout["touching"]] = rng.integers(0, 2, (len(obs), 3)).astype(np.float32)
    residual = rng.uniform(-1.0, 1.0, (len(obs), 3))
    free = ResidualAction(SENSORS, controller, 0.1)
    guarded = ResidualAction(SENSORS, controller, 0.1, close_untouched=True)
    assert guarded.settings()["close_untouched"] is True

    def correction(combine):
        return SENSORS.curvature_rate(combine(obs, residual).astype(float)) \
            - SENSORS.curvature_rate(controller(obs).astype(float))

    untouched = obs[:, layout["touching"]] < 0.5
    unguarded, kept = correction(free), correction(guarded)
    assert (untouched & (residual > 0)).any() and (~untouched).any()
    assert np.all(kept[untouched] <= 1e-6)  # an untouched finger is never held back
    np.testing.assert_allclose(kept[untouched & (residual < 0)], unguarded[untouched & (residual < 0)], atol=1e-6)
    np.testing.assert_allclose(kept[~untouched], unguarded[~untouched], atol=1e-6)
    assert np.abs(unguarded[untouched & (residual > 0)]).max() > 0.01  # the guard is what removed it


def test_a_residual_run_trains_on_the_controller_settings_given_and_refuses_bad_ones(tmp_path, capsys):
    from agents import train_ppo

    base = ["--out", str(tmp_path), "--timesteps", "128", "--num-envs", "4", "--model", "planar", "--eval-episodes",
            "0", "--validate-every", "0", "--checkpoint-every", "0"]
    train_ppo.main(base + ["--residual-to", "reactive_graded", "--residual-base", "grip=0.15", "gust_grip=0.12"])
    recorded = json.loads((tmp_path / "config.json").read_text())["residual"]["base_settings"]
    assert recorded == {**ReactivePolicy(SENSORS, **GRADED_3D_GAINS).settings(), "grip": 0.15, "gust_grip": 0.12}
    for extra, named in ((["--residual-base", "grip=0.15"], "need --residual-to"),
                         (["--residual-to", "reactive_graded", "--residual-base", "grasp=0.1"], "'grasp'"),
                         (["--residual-to", "reactive_graded", "--residual-base", "grip=0.1,0.2"], "one value"),
                         (["--residual-to", "reactive_graded", "--residual-base", "grip=1.5"], "grip")):
        with pytest.raises(SystemExit):
            train_ppo.main(base + extra)
        assert named in capsys.readouterr().err
