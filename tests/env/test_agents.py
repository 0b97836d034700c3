"""The SB3 adapter, the evaluation script and the PPO training script."""

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import soft_gripper_env
from agents.sb3_vec_env import SoftGripperSB3VecEnv
from agents.scripted import ConstantPolicy, RampPolicy, RandomPolicy, ReactivePolicy
from soft_gripper_env.env import observation_bounds, observation_slices
from soft_gripper_env.grasp_task import GraspTask, task_episode

ROOT = Path(__file__).resolve().parents[2]


def test_sb3_vec_env_autoresets_in_the_same_step_and_reports_truncation():
    env = SoftGripperSB3VecEnv(num_envs=2, seed=3, max_episode_steps=3)
    obs = env.reset()
    assert obs.shape == (2, observation_bounds(GraspTask())[0].size) and obs.dtype == np.float32
    for _ in range(3):
        env.step_async(np.full((2, 3), -0.3, dtype=np.float32))
        obs, reward, done, infos = env.step_wait()
    assert done.all() and reward.dtype == np.float32
    for info in infos:
        assert info["TimeLimit.truncated"] and "terminal_observation" in info
        assert not np.array_equal(info["terminal_observation"], obs[0])  # the new episode's first observation
    curvature = observation_slices(GraspTask())["natural_curvature"]
    np.testing.assert_array_equal(obs[:, curvature], 0.0)  # κ̄ back to zero after the same-step reset
    assert env.get_attr("render_mode") == [None, None] and env.env_is_wrapped(object) == [False, False]


@pytest.mark.parametrize("num_threads", [1, 2])
def test_sb3_vec_env_seeds_like_single_envs(num_threads):
    env = SoftGripperSB3VecEnv(num_envs=2, seed=7, num_threads=num_threads)
    obs = env.reset()
    single, _ = gym.make(soft_gripper_env.ENV_ID).reset(seed=8)
    np.testing.assert_allclose(obs[1], single, atol=1e-7)


@pytest.mark.slow
def test_sb3_subproc_vec_env_runs_the_single_env():
    """SB3's SubprocVecEnv (one process per env) steps the registered env like its DummyVecEnv."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    make = [lambda: gym.make(soft_gripper_env.ENV_ID, model="planar", max_episode_steps=3) for _ in range(2)]
    actions = np.random.default_rng(3).uniform(-1, 1, (4, 2, 3)).astype(np.float32)
    results = []
    for vector in (SubprocVecEnv(make), DummyVecEnv(make)):
        vector.seed(9)
        outputs = [vector.reset()]
        for action in actions:
            obs, reward, done, infos = vector.step(action)
            outputs += [obs, reward, done, np.array([info.get("is_success", False) for info in infos])]
        vector.close()
        results.append(outputs)
    for a, b in zip(*results, strict=True):  # DummyVecEnv keeps rewards in float32, SubprocVecEnv in float64
        np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=1e-6, atol=0)
    assert results[0][11].all()  # done at the third step (episodes of 3), so the autoresets were compared too


def test_a_checkpoint_is_the_shorter_run_it_passes_through(tmp_path):
    """Checkpoint N of a run equals the run stopped at N steps: the same weights, statistics and config, so one
    run measures the shorter budgets."""
    import pickle

    import torch
    from stable_baselines3 import PPO

    from agents import train_ppo

    rollout = 4 * train_ppo.PPO_SETTINGS["n_steps"]  # env steps per rollout with 4 envs
    common = ["--num-envs", "4", "--eval-episodes", "0", "--validate-every", str(rollout), "--validation-episodes", "2",
              "--seed", "3", "--model", "planar"]
    train_ppo.main(["--out", str(tmp_path / "long"), "--timesteps", str(3 * rollout),
                    "--checkpoint-every", str(2 * rollout - 24), *common])
    train_ppo.main(["--out", str(tmp_path / "short"), "--timesteps", str(2 * rollout), "--checkpoint-every", "0",
                    *common])
    checkpoints = sorted(path.name for path in (tmp_path / "long" / "checkpoints").iterdir())
    assert checkpoints == [f"steps_{2 * rollout}"]  # first boundary past the interval; none at the end
    checkpoint, short = tmp_path / "long" / "checkpoints" / f"steps_{2 * rollout}", tmp_path / "short"
    assert not (short / "checkpoints").exists()
    weights = [PPO.load(folder / "ppo_model.zip").policy.state_dict() for folder in (checkpoint, short)]
    for name, value in weights[0].items():
        assert torch.equal(value, weights[1][name]), name
    statistics = [pickle.loads((folder / "vecnormalize.pkl").read_bytes()) for folder in (checkpoint, short)]
    np.testing.assert_array_equal(statistics[0].obs_rms.mean, statistics[1].obs_rms.mean)
    np.testing.assert_array_equal(statistics[0].ret_rms.var, statistics[1].ret_rms.var)
    configs = [json.loads((folder / "config.json").read_text()) for folder in (checkpoint, short)]
    for config in configs:
        del config["training_wall_s"], config["validation_wall_s"]
    assert configs[0] == configs[1] and configs[0]["timesteps"] == 2 * rollout
    curves = [json.loads((folder / "curve.json").read_text()) for folder in (checkpoint, short)]
    for key, columns in (("episodes", (0, 2, 3)), ("validation", ("steps", "success_rate", "mean_return"))):
        # the same episodes and validations (not the same wall times): the curve of the run stopped there
        assert [[entry[c] for c in columns] for entry in curves[0][key]] == \
            [[entry[c] for c in columns] for entry in curves[1][key]]
    assert [point["steps"] for point in curves[0]["validation"]] == [rollout, 2 * rollout]
    assert len(json.loads((tmp_path / "long" / "curve.json").read_text())["validation"]) == 3
    long_weights = PPO.load(tmp_path / "long" / "ppo_model.zip").policy.state_dict()
    assert not all(torch.equal(value, long_weights[name]) for name, value in weights[0].items())


def test_ppo_trains_in_the_envs_default_model_by_default():
    from agents import train_ppo
    from soft_gripper_env.grasp_task import GraspTask

    assert train_ppo.build_parser().parse_args(["--out", "x"]).model == GraspTask().model == "3d"


def test_ppo_trains_saves_together_and_is_evaluated_against_the_baselines(tmp_path):
    import torch

    from agents import train_ppo

    results = train_ppo.main(["--out", str(tmp_path), "--timesteps", "256", "--num-envs", "4", "--model", "planar",
                              "--eval-episodes", "1", "--validate-every", "128", "--validation-episodes", "2"])
    saved = json.loads((tmp_path / "evaluation.json").read_text())
    for name in ("ppo", "ramp", "reactive", "reactive_graded"):
        assert 0.0 <= saved[name]["success_rate"] <= 1.0 and np.isfinite(saved[name]["mean_return"])
    assert results["ppo"] == saved["ppo"]
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["timesteps"] == 256 and config["task"]["model"] == "planar"
    import soft_gripper_env

    assert config["package_version"] == soft_gripper_env.__version__
    assert config["git_commit"] is None or re.fullmatch(r"[0-9a-f]{40}(-dirty)?", config["git_commit"])
    assert config["torch_threads"] == torch.get_num_threads()  # needed to reproduce the run bit for bit
    assert config["pressure_ramp"] == {"initial": 1.0, "final": train_ppo.FINAL_PRESSURE_WEIGHT,
                                       "start_steps": 200_000, "end_steps": 400_000}
    assert config["oversample_radius"] is None
    assert {name: config["task"][name] for name in train_ppo.TRAINING_REFLEXES} == train_ppo.TRAINING_REFLEXES
    assert (tmp_path / "vecnormalize.pkl").exists() and (tmp_path / "ppo_model.zip").exists()
    assert any((tmp_path / "tensorboard").rglob("events.out.tfevents.*"))
    assert (tmp_path / "learning_curve.png").stat().st_size > 5000
    curve = json.loads((tmp_path / "curve.json").read_text())
    steps = [point["steps"] for point in curve["validation"]]  # PPO stops at the end of a rollout (4 × 128)
    assert steps == [128, 256, 384, 512] and len(curve["episodes"]) >= 4  # each env ended an 80-step episode
    assert all(0.0 <= point["success_rate"] <= 1.0 for point in curve["validation"])
    assert 0 < config["training_wall_s"] and config["validation_wall_s"] > 0
    out = run_script("-m", "agents.evaluate", "--policy", str(tmp_path), "--episodes", "2", "--seed", "5",
                     "--json", str(tmp_path / "eval.json"))  # trained planar, acting in 3-D: the same sensors
    assert out.returncode == 0, out.stderr
    result = json.loads((tmp_path / "eval.json").read_text())
    assert {"success_rate", "mean_return", "mean_peak_contact_force_N", "endings"} <= set(result)
    assert result["episodes"] == 2 and result["first_seed"] == 5 and sum(result["endings"].values()) == 2
    assert result["model"] == "3d"
    assert "| policy | model |" in out.stdout
    assert config["observation"] == config["task"]["observation"] == "sensors" and result["observation"] == "sensors"
    out = run_script("-m", "agents.evaluate", "--policy", str(tmp_path), "--episodes", "1", "--model", "planar",
                     "--json", str(tmp_path / "planar.json"))
    assert out.returncode == 0, out.stderr
    assert json.loads((tmp_path / "planar.json").read_text())["model"] == "planar"
    config["task"]["observation"] = "full"  # as if trained on node states: it cannot act in the other model
    (tmp_path / "config.json").write_text(json.dumps(config))
    out = run_script("-m", "agents.evaluate", "--policy", str(tmp_path), "--episodes", "1", "--model", "planar")
    assert out.returncode == 2 and "acts only in the rod model it was trained in" in out.stderr


def test_radius_oversampling_draws_its_share_of_episodes_from_its_band_and_refuses_bad_bands(capsys):
    from agents.train_ppo import RadiusOversampling, main

    curriculum = RadiusOversampling(0.045, 0.05, 0.25, task_range=(0.045, 0.06))
    draws = [curriculum(np.random.default_rng(seed)) for seed in range(2000)]
    radii = [d["object_radius"] for d in draws if d]
    assert len(radii) / len(draws) == pytest.approx(0.25, abs=0.03)  # binomial sd 0.01
    assert min(radii) >= 0.045 and max(radii) < 0.05 and np.mean(radii) == pytest.approx(0.0475, abs=3e-4)
    assert all(d == {} for d in draws if not d)
    assert curriculum.config() == {"low_m": 0.045, "high_m": 0.05, "share": 0.25}
    for values, message in ((["0.04", "0.05", "0.3"], "low = 0.04 and high = 0.05 m must satisfy 0.045 <= low"),
                            (["0.05", "0.05", "0.3"], "must satisfy 0.045 <= low < high <= 0.06"),
                            (["0.045", "0.05", "0"], "share = 0 is outside (0, 1]")):
        with pytest.raises(SystemExit):
            main(["--out", "unused", "--oversample-radius", *values])
        error = capsys.readouterr().err
        assert "--oversample-radius LOW HIGH SHARE: " in error and message in error
        # the class itself refuses the same band, for a caller building the curriculum in Python
        with pytest.raises(ValueError, match=re.escape(message)):
            RadiusOversampling(*map(float, values), task_range=(0.045, 0.06))


def test_a_run_started_from_a_trained_policy_starts_from_its_weights_and_statistics(tmp_path, monkeypatch):
    """--init-from: before any update the run's network, optimiser and observation statistics are the starting
    policy's; training then goes on adapting its statistics, and --pressure-onset reaches the training reward
    only."""
    import pickle

    import torch
    from stable_baselines3 import PPO

    from agents import train_ppo
    from agents.evaluate import SHIPPED

    planar = SHIPPED["pretrained_planar"]  # a policy of its own, no correction
    shipped = PPO.load(planar / "ppo_model.zip", device="cpu")
    shipped_statistics = pickle.loads((planar / "vecnormalize.pkl").read_bytes())
    with monkeypatch.context() as patch:
        patch.setattr(PPO, "learn", lambda self, *args, **kwargs: self)  # no rollout, no update
        patch.setattr(train_ppo.ProgressAndCurve, "training_wall", lambda self: 0.0)  # its clock never started
        train_ppo.main(["--out", str(tmp_path / "untrained"), "--init-from", "pretrained_planar", "--timesteps",
                        "256", "--num-envs", "2", "--num-threads", "1", "--model", "planar", "--eval-episodes", "0",
                        "--validate-every", "0", "--checkpoint-every", "0"])
    started = PPO.load(tmp_path / "untrained" / "ppo_model.zip", device="cpu")
    for name, value in shipped.policy.state_dict().items():
        assert torch.equal(value, started.policy.state_dict()[name]), name
    moments = [model.policy.optimizer.state_dict()["state"] for model in (shipped, started)]
    assert moments[0] and all(torch.equal(moments[0][k]["exp_avg"], moments[1][k]["exp_avg"]) for k in moments[0])
    statistics = pickle.loads((tmp_path / "untrained" / "vecnormalize.pkl").read_bytes())
    np.testing.assert_array_equal(statistics.obs_rms.mean, shipped_statistics.obs_rms.mean)
    assert statistics.ret_rms.var == shipped_statistics.ret_rms.var

    train_ppo.main(["--out", str(tmp_path / "tuned"), "--init-from", str(planar), "--timesteps", "256",
                    "--num-envs", "2", "--num-threads", "1", "--model", "planar", "--eval-episodes", "0",
                    "--validate-every", "0", "--checkpoint-every", "0", "--pressure-onset", "0.5"])
    statistics = pickle.loads((tmp_path / "tuned" / "vecnormalize.pkl").read_bytes())
    assert statistics.obs_rms.count == pytest.approx(shipped_statistics.obs_rms.count + 256 + 2)  # + the reset
    tuned = PPO.load(tmp_path / "tuned" / "ppo_model.zip", device="cpu").policy.state_dict()
    assert not all(torch.equal(value, tuned[name]) for name, value in shipped.policy.state_dict().items())
    config = json.loads((tmp_path / "tuned" / "config.json").read_text())
    shipped_config = json.loads((planar / "config.json").read_text())
    assert config["init_from"] == {"policy": str(planar), "model": "planar", "timesteps": 600_000,
                                   "seed": shipped_config["seed"], "git_commit": shipped_config.get("git_commit"),
                                   "training_wall_s": shipped_config["training_wall_s"]}
    assert config["policy"] == shipped_config["policy"]
    assert config["training_pressure_onset"] == 0.5 and config["task"]["pressure_onset"] == 0.7  # the task's own


def test_a_run_refuses_to_start_from_a_policy_that_reads_or_means_something_else(tmp_path, capsys):
    from agents.train_ppo import main

    for extra, message in ((["--observation", "full"], "--init-from pretrained_planar: it observes 'sensors', this "
                                                       "run 'full' (--observation)"),
                           (["--residual-to", "reactive_tuned"], "--init-from pretrained_planar: it corrects None, "
                                                                 "this run {'base': 'reactive_tuned'"),
                           (["--pressure-onset", "1"], "--pressure-onset = 1 is outside [0, 1)")):
        with pytest.raises(SystemExit):
            main(["--out", str(tmp_path / "refused"), "--init-from", "pretrained_planar", *extra])
        assert message in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "refused"), "--init-from", str(tmp_path)])
    assert f"--init-from {tmp_path}: {tmp_path} lacks ppo_model.zip, vecnormalize.pkl, config.json" in \
        capsys.readouterr().err
    assert not (tmp_path / "refused").exists()  # refused before anything is written


def test_the_pressure_warning_ramp_sets_each_rollouts_weight():
    """The ramp holds the task's weight until START, grows linearly to the final weight at END and holds it; PPO's
    env gets each rollout's weight when the rollout begins."""
    from stable_baselines3 import PPO

    from agents.train_ppo import PressureWarningRamp, ramped

    assert [ramped(steps, 100, 300, 1.0, 3.0) for steps in (0, 100, 200, 250, 300, 1000)] == [1.0, 1.0, 2.0, 2.5,
                                                                                              3.0, 3.0]
    assert ramped(50, 50, 50, 1.0, 3.0) == 3.0  # a step up at START
    env = SoftGripperSB3VecEnv(2, seed=0, max_episode_steps=3, model="planar")
    ramp = PressureWarningRamp(env.venv.task.reward, 4.0, start=8, end=24)
    seen = []
    original = env.venv.set_reward_weights
    env.venv.set_reward_weights = lambda weights: (seen.append(weights.pressure), original(weights))
    PPO("MlpPolicy", env, n_steps=4, batch_size=8, n_epochs=1, seed=0, device="cpu").learn(32, callback=ramp)
    assert seen == [1.0, 1.0, 2.5, 4.0]  # rollouts of 2 envs x 4 steps begin at 0, 8, 16 and 24
    assert env.venv.task.reward.pressure == 4.0 and env.venv.task.reward.hold == GraspTask().reward.hold


@pytest.mark.parametrize("name, model", [("pretrained", "3d"), ("pretrained", "planar"),
                                         ("pretrained_planar", "planar")])
def test_the_shipped_policies_load_and_beat_random(name, model):
    """agents/pretrained holds a PPO policy (model, statistics and config) trained in the env's default model, with
    the package version and commit it was trained at; agents/pretrained_planar one trained planar. Both observe the
    sensors, so act in both rod models, and on 8 seeds no training or tuning saw succeed where random actions do
    not."""
    from agents.evaluate import REFLEXES, SHIPPED, evaluate, make_policy, run_config

    folder = SHIPPED[name]
    assert {"ppo_model.zip", "vecnormalize.pkl", "config.json"} <= {path.name for path in folder.iterdir()}
    assert sum(path.stat().st_size for path in folder.iterdir()) < 2_000_000  # small enough to ship
    config = run_config(folder)
    assert config["model"] == (GraspTask().model if name == "pretrained" else "planar")
    if name == "pretrained":
        assert config["package_version"] and re.fullmatch(r"[0-9a-f]{40}", config["git_commit"])
    task = GraspTask(model=model, observation="sensors")
    policy = make_policy(name, task, 0)
    assert policy.observation == "sensors"
    reflexes = {name: policy.trained_task.get(name) for name in REFLEXES}  # the reflexes it was trained with
    trained = evaluate(policy, 8, 40_000, progress=False, num_envs=8, model=model, observation="sensors",
                       **reflexes)
    random = evaluate(RandomPolicy(task, 0), 8, 40_000, progress=False, num_envs=8, model=model,
                      observation="sensors")
    assert trained["success_rate"] >= 0.5 > random["success_rate"]
    assert trained["mean_return"] > random["mean_return"] + 30


def test_learning_curves_of_several_runs_and_a_folder_without_a_curve(tmp_path):
    """Two runs' validation curves make one figure (each run, their mean and spread); a folder that train_ppo did
    not write is refused by name."""
    for seed, rates in ((0, [0.1, 0.5, 0.7]), (1, [0.2, 0.4, 0.9])):
        run = tmp_path / f"seed{seed}"
        run.mkdir()
        validation = [{"steps": 50_000 * (k + 1), "training_wall_s": 300.0 * (k + 1), "success_rate": rate,
                       "mean_return": 0.0, "mean_peak_contact_force_N": 1.0} for k, rate in enumerate(rates)]
        (run / "curve.json").write_text(json.dumps({"episodes": [], "validation": validation}))
        (run / "evaluation.json").write_text(json.dumps({"ppo": {"success_rate": rates[-1]},
                                                         "reactive": {"success_rate": 0.8}}))
    out = run_script("-m", "agents.learning_curves", str(tmp_path / "seed0"), str(tmp_path / "seed1"),
                     "--out", str(tmp_path / "curves.png"))
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "curves.png").stat().st_size > 20_000
    out = run_script("-m", "agents.learning_curves", str(tmp_path), "--out", str(tmp_path / "none.png"))
    assert out.returncode == 2 and "has no curve.json" in out.stderr and not (tmp_path / "none.png").exists()


def test_learning_curves_draw_a_controller_evaluated_on_the_validation_seeds(tmp_path):
    """``--baseline LABEL=FILE`` draws an agents.evaluate result as a line; a file that is not one is refused."""
    from agents.learning_curves import load_run, plot_learning_curves

    run = tmp_path / "seed0"
    run.mkdir()
    validation = [{"steps": 50_000, "training_wall_s": 300.0, "success_rate": 0.5, "mean_return": 0.0,
                   "mean_peak_contact_force_N": 1.0}]
    (run / "curve.json").write_text(json.dumps({"episodes": [], "validation": validation}))
    controller = {"success_rate": 0.84, "episodes": 64, "first_seed": 500_000}
    (tmp_path / "reactive.json").write_text(json.dumps(controller))
    plot_learning_curves([load_run(run)], tmp_path / "direct.png", {"reactive": controller})
    import matplotlib.image

    lines = matplotlib.image.imread(tmp_path / "direct.png")
    plot_learning_curves([load_run(run)], tmp_path / "without.png")
    assert lines.shape == matplotlib.image.imread(tmp_path / "without.png").shape
    assert not np.array_equal(lines, matplotlib.image.imread(tmp_path / "without.png"))  # the line is drawn
    out = run_script("-m", "agents.learning_curves", str(run), "--out", str(tmp_path / "curves.png"),
                     "--baseline", f"reactive={tmp_path / 'reactive.json'}")
    assert out.returncode == 0, out.stderr
    (tmp_path / "other.json").write_text(json.dumps({"validation": []}))
    out = run_script("-m", "agents.learning_curves", str(run), "--out", str(tmp_path / "bad.png"),
                     "--baseline", f"reactive={tmp_path / 'other.json'}")
    assert out.returncode == 2 and "is not an agents.evaluate --json result" in out.stderr


def test_evaluate_runs_seeds_as_single_envs_do():
    """Batched evaluation gives each seed the episode a single env with that seed gives: the same return."""
    from agents.evaluate import ENDINGS, evaluate

    result = evaluate(RampPolicy(), episodes=3, seed=1000, progress=False, num_envs=2, max_episode_steps=5)
    assert result["episodes"] == 3 and result["mean_length"] == 5
    assert result["mean_return"] == pytest.approx(np.mean(result["returns"]))
    assert sum(result["mean_reward_terms"].values()) == pytest.approx(result["mean_return"], abs=1e-9)
    assert result["mean_reward_terms"]["reach"] > 0 and result["mean_reward_terms"]["success"] == 0
    assert result["episode_endings"] == ["not_all_touching"] * 3  # after 0.25 s the fingers have not closed
    assert set(result["endings"]) == set(ENDINGS) and sum(result["endings"].values()) == 3
    env = gym.make(soft_gripper_env.ENV_ID, max_episode_steps=5)
    for k, expected in enumerate(result["returns"]):
        obs, _ = env.reset(seed=1000 + k)
        total = 0.0
        for _ in range(5):
            obs, reward, *_ = env.step(RampPolicy()(obs))
            total += reward
        assert total == pytest.approx(expected, abs=1e-9)


def test_evaluate_reports_each_episodes_peak_force_and_its_ratio_to_the_specimens_limit():
    """The peak finger force and peak load of each episode are those a single env's infos give (the fastest constant
    closing presses past the limit of some specimens within 0.6 s and not of others), and each specimen's radius
    and limit are those its seed draws."""
    from agents.evaluate import evaluate

    closing = ConstantPolicy(action=-1.0)
    result = evaluate(closing, episodes=3, seed=70, progress=False, num_envs=3, max_episode_steps=12)
    env = gym.make(soft_gripper_env.ENV_ID, max_episode_steps=12)
    loads = []
    for k in range(3):
        obs, info = env.reset(seed=70 + k)
        drawn = task_episode(GraspTask(), np.random.default_rng(70 + k), {})
        assert result["object_radii_m"][k] == pytest.approx(drawn.scene.grasped_object.radius, rel=1e-6)  # float32
        assert result["fragile_forces_N"][k] == drawn.fragile_force == info["fragile_force_N"]
        peak, load, done = 0.0, 0.0, False
        while not done:
            obs, _, terminated, truncated, info = env.step(closing(obs))
            done = terminated or truncated
            peak = max(peak, float(np.max(info["finger_forces_N"])))
            load = max(load, float(np.max(info["finger_forces_N"]) / info["fragile_force_N"]))
        assert result["peak_contact_forces_N"][k] == pytest.approx(peak, rel=1e-12)
        assert result["peak_loads"][k] == pytest.approx(load, rel=1e-12)
        loads.append(load)
    assert result["mean_peak_load"] == pytest.approx(np.mean(loads))
    assert result["fraction_peak_above_limit"] == pytest.approx(np.mean(np.array(loads) > 1.0))
    assert 0.0 < result["fraction_peak_above_limit"] < 1.0


def test_episode_ending_names_the_first_failed_condition():
    from agents.evaluate import episode_ending

    task = GraspTask()
    layout = observation_slices(task)
    observation = np.zeros(observation_bounds(task)[0].size, dtype=np.float32)
    held = {"is_success": False, "harmed": False, "solver_failure": False,
            "finger_forces_N": np.full(3, 2 * task.contact_force)}

    def ending(terminated=False, offset=0.0, speed=0.0, **info):
        obs = observation.copy()
        obs[layout["object_offset"].start] += offset
        obs[layout["object_velocity"].start] = speed
        return episode_ending(task, obs, terminated, {**held, **info})

    assert ending() == "not_held_through_gust"
    assert ending(is_success=True) == "success"
    assert ending(terminated=True, harmed=True) == "harmed"
    assert ending(terminated=True, solver_failure=True) == "lost"
    assert ending(solver_failure=True) == "solver_failure"
    assert ending(finger_forces_N=np.array([1.0, 0.5 * task.contact_force, 1.0])) == "not_all_touching"
    assert ending(offset=1.5 * task.hold_distance, speed=2 * task.rest_speed) == "off_grasp_point"
    assert ending(offset=0.5 * task.hold_distance, speed=2 * task.rest_speed) == "moving"


@pytest.mark.slow
def test_the_task_needs_feedback_and_returns_rank_policies_by_success():
    """On 24 seeds: the feedback controller succeeds more often than any constant action of a grid and the
    open-loop ramp (which stay at or below half), and the mean returns of random, two constants, the ramp and the
    feedback controller come out in the order of their success rates, wherever two rates differ by more than twice
    the standard error of their difference (closer ones are ties on 24 seeds)."""
    from agents.evaluate import evaluate
    from agents.scripted import ConstantPolicy, RandomPolicy, ReactivePolicy

    task = GraspTask()
    policies = {"random": RandomPolicy(task, 0), "constant -1": ConstantPolicy(task, -1.0),
                "constant -0.5": ConstantPolicy(task, -0.5), "ramp": RampPolicy(task),
                "reactive": ReactivePolicy(task)}
    results = {name: evaluate(policy, 24, 20_000, progress=False, num_envs=24, num_threads=2)  # both of CI's cores
               for name, policy in policies.items()}
    success = {name: r["success_rate"] for name, r in results.items()}
    assert success["reactive"] >= 0.6
    assert all(success[name] <= 0.5 for name in policies if name != "reactive")
    for first in policies:
        for second in policies:
            pooled = (success[first] + success[second]) / 2
            error = math.sqrt(max(pooled * (1 - pooled), 1e-12) * 2 / 24)
            if success[first] - success[second] > 2 * error:
                assert results[first]["mean_return"] > results[second]["mean_return"], (first, second, results)


def run_script(*args, timeout=600):
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=timeout, cwd=ROOT)


@pytest.mark.slow
def test_record_video_example_writes_an_mp4_a_gif_and_a_frame(tmp_path):
    out = run_script("-m", "examples.record_video", "--out", str(tmp_path), "--policy", "reactive", "--seed", "3",
                     "--gif", "--frame-at", "1")
    assert out.returncode == 0, out.stderr
    video = tmp_path / "reactive-episode-0.mp4"
    assert video.exists() and video.stat().st_size > 10_000
    assert "success" in out.stdout
    from PIL import Image

    with Image.open(tmp_path / "reactive-episode-0.gif") as gif:
        # 81 frames (the reset and 80 steps: held to the end), every second one, at half size
        assert gif.n_frames == 41 and gif.size == (240, 240)
    with Image.open(tmp_path / "reactive-episode-0-1s.png") as frame:
        assert frame.size == (480, 480) and len(set(frame.getdata())) > 50
    refused = run_script("-m", "examples.record_video", "--out", str(tmp_path), "--frame-at", "5")
    assert refused.returncode == 2 and "--frame-at 5.0 is outside the episode, [0, 4.0] s" in refused.stderr


@pytest.mark.slow
def test_env_speed_benchmark_writes_json_and_plot(tmp_path):
    """The issue's JSON keys are there, every ratio is its figure over the anchor's, and the plot is written."""
    out = run_script("-m", "benchmarks.env_speed", "--json", str(tmp_path / "speed.json"), "--plot",
                     str(tmp_path / "speed.png"), "--quick", "--steps", "2")
    assert out.returncode == 0, out.stderr
    results = json.loads((tmp_path / "speed.json").read_text())
    required = {"ant_v5_steps_per_s", "single_steps_per_s", "vec64_steps_per_s", "single_3d_steps_per_s",
                "vec64_3d_steps_per_s", "vec64_two_threads_steps_per_s", "single_grasping_steps_per_s",
                "vec64_grasping_steps_per_s", "single_3d_grasping_steps_per_s", "vec64_3d_grasping_steps_per_s"}
    assert required <= set(results) and all(results[key] > 0 for key in required)
    ant = results["ant_v5_steps_per_s"]
    for key in required - {"ant_v5_steps_per_s"}:
        ratio = results["ratios_to_ant_v5"][key.removesuffix("_steps_per_s") + "_vs_ant_v5"]
        assert ratio == pytest.approx(results[key] / ant)
    assert {"paper_scene_planar_ms", "paper_scene_3d_ms", "batched_planar_us_per_gripper_step"} <= set(
        results["goals"])
    for model in ("planar", "3d"):  # the fingers alone take about one Newton solve per step: the least there is
        ceiling = results["ceiling"][model]
        assert ceiling["fingers_alone_us_per_gripper_step"] > 0 and 0.5 < ceiling["newton_iterations_per_step"] < 2
        assert ceiling["vs_ant_v5"] == pytest.approx(ceiling["env_steps_per_s_at_most"] / ant)
    assert (tmp_path / "speed.png").stat().st_size > 5000


def test_success_force_figure_summarizes_groups_per_model_and_seed_set(tmp_path):
    """Groups of evaluate JSONs give each panel's per-group mean and sample sd of success and peak force; results
    of another model or seed set go in their own panel; bad groups are refused by name."""
    def result(model, first_seed, success, force):
        data = {"success_rate": success, "mean_peak_contact_force_N": force, "model": model,
                "first_seed": first_seed, "episodes": 200}
        path = tmp_path / f"{model}_{first_seed}_{success}_{force}.json"
        path.write_text(json.dumps(data))
        return str(path)

    ppo = [result("planar", 1000, s, f) for s, f in ((0.9, 2.0), (0.8, 1.6), (0.85, 1.9))]
    ppo_3d = result("3d", 1000, 0.7, 2.5)
    reactive = result("planar", 1000, 0.75, 2.1)
    out = run_script("-m", "agents.success_force", "--group", "ppo", *ppo, ppo_3d, "--group", "reactive", reactive,
                     "--reference", "reactive", "--out", str(tmp_path / "frontier.png"))
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "frontier.png").stat().st_size > 20_000

    from agents.success_force import load_evaluation, summarize
    table = summarize({"ppo": [load_evaluation(f) for f in (*ppo, ppo_3d)], "reactive": [load_evaluation(reactive)]})
    planar, solid = table["planar, seeds 1,000–1,199"], table["3d, seeds 1,000–1,199"]
    assert planar["ppo"]["runs"] == 3 and solid["ppo"]["runs"] == 1 and "reactive" not in solid
    assert math.isclose(planar["ppo"]["success_mean"], 0.85) and math.isclose(planar["ppo"]["success_sd"], 0.05)
    assert math.isclose(planar["ppo"]["force_N_mean"], 5.5 / 3)
    assert math.isclose(planar["ppo"]["force_N_sd"], float(np.std([2.0, 1.6, 1.9], ddof=1)))
    assert solid["ppo"]["force_N_sd"] == 0.0 and planar["reactive"]["success_mean"] == 0.75

    out = run_script("-m", "agents.success_force", "--group", "ppo", *ppo, "--reference", "reactive",
                     "--out", str(tmp_path / "bad.png"))
    assert out.returncode == 2 and "reference = 'reactive' is not one of the groups: ppo" in out.stderr
    (tmp_path / "other.json").write_text(json.dumps({"success_rate": 0.5}))
    out = run_script("-m", "agents.success_force", "--group", "x", str(tmp_path / "other.json"),
                     "--out", str(tmp_path / "bad.png"))
    assert out.returncode == 2 and "lacks mean_peak_contact_force_N" in out.stderr
    assert not (tmp_path / "bad.png").exists()


def test_scripts_reject_bad_arguments(tmp_path):
    out = run_script("-m", "agents.evaluate", "--policy", "ramp", "--episodes", "0")
    assert out.returncode == 2 and "--episodes = 0 must be at least 1" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path), "--timesteps", "0")
    assert out.returncode == 2 and "--timesteps = 0 must be at least 1" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path), "--num-envs", "2", "--num-threads", "3")
    assert out.returncode == 2 and "--num-threads = 3 must be at most --num-envs = 2" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "bound"), "--touching-closing-rate", "-1")
    assert out.returncode == 2 and "--touching-closing-rate = -1.0 1/s is outside the allowed range" in out.stderr
    assert not (tmp_path / "bound").exists()  # refused before anything is written
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "bound"), "--approach-slowing-gap", "0.01",
                     "--touching-closing-rate", "none")
    assert out.returncode == 2 and "--approach-slowing-gap = 0.01 m slows the approach to --touching-closing-rate, " \
        "which must then be set" in out.stderr, out.stderr
    assert not (tmp_path / "bound").exists()
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "ramp"), "--final-pressure-weight", "3",
                     "--pressure-ramp", "400000", "200000")
    assert out.returncode == 2 and "--pressure-ramp = 400000 200000 must satisfy 0 <= START <= END" in out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "ramp"), "--final-pressure-weight", "-1")
    assert out.returncode == 2 and "--final-pressure-weight = -1.0 is outside [0, 1e6]" in out.stderr
    assert not (tmp_path / "ramp").exists()
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "residual"), "--residual-to", "reactive",
                     "--residual-rate", "0.4")
    assert out.returncode == 2 and "--residual-rate = 0.4 is outside (0, 0.3] 1/s" in out.stderr, out.stderr
    out = run_script("-m", "agents.train_ppo", "--out", str(tmp_path / "residual"), "--residual-to", "ramp")
    assert out.returncode == 2
    assert "invalid choice: 'ramp' (choose from 'reactive', 'reactive_tuned', 'reactive_graded')" in out.stderr
    assert not (tmp_path / "residual").exists()


def test_evaluate_refuses_a_policy_trained_on_another_action_map(tmp_path):
    """A policy whose training task mapped actions to other curvature rates would act wrongly under today's map:
    agents.evaluate names the setting and both values instead of evaluating it."""
    import shutil

    from agents.evaluate import REFLEXES, action_map_mismatch

    folder = tmp_path / "policy"
    shutil.copytree(ROOT / "agents" / "pretrained", folder)
    config = json.loads((folder / "config.json").read_text())
    reflexes = {name: config["task"].get(name) for name in REFLEXES}
    assert action_map_mismatch(config["task"], GraspTask(**reflexes)) is None  # the shipped policy fits today's task
    config["task"]["max_curvature_rate"] = 0.5
    config["task"]["curvature_range"] = [-0.25, 0.0]
    (folder / "config.json").write_text(json.dumps(config))
    out = run_script("-m", "agents.evaluate", "--policy", str(folder), "--episodes", "1")
    assert out.returncode == 2, out.stderr
    assert "max_curvature_rate = 0.5 (today 0.3)" in out.stderr and "curvature_range = [-0.25, 0.0]" in out.stderr


def test_evaluate_runs_a_policy_only_with_the_closing_reflexes_it_was_trained_with(tmp_path):
    """The closing reflexes (a touching finger's bound, the approach's slowing gap) are part of what an action does:
    a policy trained with them runs with them, from its config.json when the command line does not give them, and
    is refused with others (the shipped one too); a bound out of range is refused by name."""
    import shutil

    from agents.evaluate import action_map_mismatch, evaluate, load_ppo

    config = json.loads((ROOT / "agents" / "pretrained" / "config.json").read_text())
    shipped_rate = config["task"]["touching_closing_rate"]
    config["task"].update(touching_closing_rate=None, approach_slowing_gap=None)  # a policy trained without them
    assert "touching_closing_rate = None (today 0.04)" in action_map_mismatch(
        config["task"], GraspTask(touching_closing_rate=0.04))
    before = {key: value for key, value in config["task"].items() if key != "touching_closing_rate"}
    assert action_map_mismatch(before, GraspTask(touching_closing_rate=0.04)) is None  # trained before it existed
    config["task"]["touching_closing_rate"] = 0.04
    assert action_map_mismatch(config["task"], GraspTask(touching_closing_rate=0.04)) is None
    assert "touching_closing_rate = 0.04 (today None)" in action_map_mismatch(config["task"], GraspTask())
    config["task"]["approach_slowing_gap"] = 0.01
    both = GraspTask(touching_closing_rate=0.04, approach_slowing_gap=0.01)
    assert action_map_mismatch(config["task"], both) is None
    assert action_map_mismatch(config["task"], GraspTask(touching_closing_rate=0.04)) == \
        "approach_slowing_gap = 0.01 (today None)"

    folder = tmp_path / "policy"
    shutil.copytree(ROOT / "agents" / "pretrained", folder)
    (folder / "config.json").write_text(json.dumps(config))
    with pytest.raises(ValueError, match=r"touching_closing_rate = 0.04 \(today None\)"):  # the Python API too
        evaluate(load_ppo(folder), 1, progress=False, model="planar", observation="sensors")
    out = run_script("-m", "agents.evaluate", "--policy", str(folder), "--episodes", "1", "--model", "planar",
                     "--touching-closing-rate", "0.05")
    assert out.returncode == 2 and "touching_closing_rate = 0.04 (today 0.05)" in out.stderr, out.stderr
    out = run_script("-m", "agents.evaluate", "--policy", str(folder), "--episodes", "1", "--model", "planar",
                     "--approach-slowing-gap", "none")
    assert out.returncode == 2 and "approach_slowing_gap = 0.01 (today None)" in out.stderr, out.stderr
    for given in ([], ["--touching-closing-rate", "0.04", "--approach-slowing-gap", "0.01"]):
        out = run_script("-m", "agents.evaluate", "--policy", str(folder), "--episodes", "1", "--model", "planar",
                         *given, "--json", str(tmp_path / "result.json"))
        assert out.returncode == 0, out.stderr
        result = json.loads((tmp_path / "result.json").read_text())
        assert (result["touching_closing_rate"], result["approach_slowing_gap"]) == (0.04, 0.01)
        assert "closed at most at 0.04 1/s" in out.stdout and "(--approach-slowing-gap)" in out.stdout
        assert ("the closing reflexes from the policy's config.json: --touching-closing-rate 0.04, "
                "--approach-slowing-gap 0.01" in out.stdout) == (not given)
    out = run_script("-m", "agents.evaluate", "--policy", "pretrained", "--episodes", "1", "--model", "planar",
                     "--approach-slowing-gap", "0.01", "--touching-closing-rate", "0.04")
    assert out.returncode == 2 and f"touching_closing_rate = {shipped_rate!r} (today 0.04)" in out.stderr, out.stderr
    out = run_script("-m", "agents.evaluate", "--policy", "reactive", "--episodes", "1",
                     "--touching-closing-rate", "0")
    assert out.returncode == 2 and "--touching-closing-rate = 0.0 1/s is outside the allowed range" in out.stderr


def test_the_reactive_controller_tuned_in_3d_is_a_named_policy():
    from agents.evaluate import make_policy
    from agents.scripted import TUNED_3D_GAINS

    policy = make_policy("reactive_tuned", GraspTask(), 0)
    assert isinstance(policy, ReactivePolicy)
    gains = (policy.grip, policy.gust_grip, policy.gain)
    assert gains == tuple(TUNED_3D_GAINS[name] for name in ("grip", "gust_grip", "gain"))
    assert (policy.grip, policy.gust_grip, policy.gain) != (ReactivePolicy().grip, ReactivePolicy().gust_grip,
                                                           ReactivePolicy().gain)
    out = run_script("-m", "agents.evaluate", "--policy", "reactive_tuned", "--episodes", "1", "--model", "planar",
                     "--json", "/dev/null")
    assert out.returncode == 0, out.stderr


def test_the_reactive_controller_with_a_graded_touch_is_a_named_policy():
    from agents.evaluate import make_policy
    from agents.scripted import GRADED_3D_GAINS

    policy = make_policy("reactive_graded", GraspTask(), 0)
    assert isinstance(policy, ReactivePolicy)
    assert {name: getattr(policy, name) for name in GRADED_3D_GAINS} == GRADED_3D_GAINS
    assert policy.touch_force is not None and ReactivePolicy().touch_force is None


def test_evaluate_refuses_an_unknown_policy_naming_the_ones_it_knows():
    out = run_script("-m", "agents.evaluate", "--policy", "no_such_policy", "--episodes", "1")
    assert out.returncode == 2
    assert ("'no_such_policy' is not random, ramp, reactive, reactive_tuned, reactive_graded, pretrained, "
            "pretrained_planar or a folder") in out.stderr
