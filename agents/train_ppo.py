"""Train PPO (Stable-Baselines3's MlpPolicy) on SoftGripperUnderwater-v0 from scratch.

    python -m agents.train_ppo --out DIR [--timesteps 600000] [--seed 0] [--num-envs 32] [--num-threads 2]
        [--model 3d] [--observation sensors] [--validate-every 50000] [--eval-episodes 200]
        [--touching-closing-rate RATE] [--approach-slowing-gap M] [--final-pressure-weight 12]
        [--pressure-ramp 200000 400000] [--checkpoint-every 100000] [--residual-to reactive_tuned]
        [--residual-rate 0.1] [--residual-gust-hold] [--residual-press-limit FRACTION] [--residual-close-untouched]
        [--residual-press-taper FRACTION]
        [--oversample-radius LOW HIGH SHARE] [--init-from POLICY] [--pressure-onset C]

By default PPO trains in the env's default rod model (3-D; ``--model planar`` costs about a third per step) on the
sensors' observation (``GraspTask.observation``), whose readings mean the same in both models, so a policy trained
in one runs in the other (``agents.evaluate --model``).
All episodes of one rollout are stepped in one batched simulator (agents/sb3_vec_env.py), on ``--num-threads``
threads; observations and rewards are normalised by VecNormalize. The reward's pressure warning grows once PPO
has begun to grasp (``--final-pressure-weight``, ``--pressure-ramp``: ``PressureWarningRamp``). DIR receives,
together: the model (ppo_model.zip), its VecNormalize statistics (vecnormalize.pkl) and the run's configuration
(config.json), which ``python -m agents.evaluate --policy DIR`` loads; TensorBoard logs (DIR/tensorboard:
``tensorboard --logdir DIR``); checkpoints every ``--checkpoint-every`` steps (DIR/checkpoints/steps_N, each
the run as a run of ``--timesteps N`` would end it, loadable the same way); the training episodes' success and
return, and the deterministic policy's success on validation seeds every ``--validate-every`` steps, against env
steps and training wall time (curve.json, learning_curve.png); and, with ``--eval-episodes``, the trained policy and the
scripted controllers on held-out seeds (evaluation.json; seeds from 1,000,000, which training never draws).

With ``--residual-to CONTROLLER`` PPO learns a correction to a scripted controller instead (agents/residual.py):
its action adds up to ``--residual-rate`` [1/s] to the controller's rate, finger by finger, and the folder's
config.json records the controller, so ``agents.evaluate --policy DIR`` runs the two together.
``--residual-gust-hold`` forbids the correction to open a finger while a gust may blow,
``--residual-press-limit F`` to close one that presses above F times the specimen's fragility limit,
``--residual-press-taper F`` scales its closing by the margin left to F times the limit, and
``--residual-close-untouched`` forbids it to open one that does not touch the specimen
(:class:`agents.residual.ResidualAction`'s guards; config.json records them too).

``--oversample-radius LOW HIGH SHARE`` draws the specimen's radius of a share SHARE of the training episodes from
[LOW, HIGH] m instead of the task's whole range (:class:`RadiusOversampling`): most failed grasps are of the smallest
spheres. Validation and evaluation draw as the task does.

``--init-from POLICY`` starts from a trained policy (``pretrained``, ``pretrained_planar`` or a train_ppo folder)
instead of a fresh network: its weights, its optimiser's state and its VecNormalize statistics, which go on
adapting. It fine-tunes, for example, the planar-trained policy in the 3-D model; the policy must observe what this
run observes and correct the same controller (or none), and its network is kept. ``--pressure-onset C`` moves the
load at which the reward's pressure warning starts (``GraspTask.pressure_onset``, 0.7 by default) for the training
episodes only: validation and evaluation report the task's own reward.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor, VecNormalize
from tqdm import tqdm

import soft_gripper_env
from agents.evaluate import (
    TRAINING_REFLEXES,
    add_reflexes,
    evaluate,
    load_ppo,
    make_policy,
    policy_folder,
    ppo_policy,
    reflex_settings,
    run_config,
    task_from_arguments,
)
from agents.learning_curves import load_run, plot_learning_curves
from agents.residual import RESIDUAL_BASES, ResidualAction, ResidualVecEnv, residual_policy
from agents.sb3_vec_env import SoftGripperSB3VecEnv
from agents.scripted import ReactivePolicy
from agents.tune_controller import parse_grid
from soft_gripper_env.grasp_task import MODELS, GraspTask, RewardWeights

HELD_OUT_SEED = 1_000_000
"""First seed of the held-out evaluation: training episodes are drawn from the generators of seeds seed … seed +
num_envs − 1, never from these."""
VALIDATION_SEED = 500_000
"""First seed of the validation episodes that measure the deterministic policy during training (the learning
curves): neither training's nor the held-out evaluation's."""
VALIDATION_EPISODES = 64
"""Validation episodes per measure (``--validation-episodes``)."""
PPO_SETTINGS = {"n_steps": 128, "n_epochs": 10, "learning_rate": 3e-4, "gamma": 0.99, "gae_lambda": 0.95,
                "ent_coef": 0.0, "clip_range": 0.2}
"""PPO's hyperparameters (batch size: 1024 or the rollout, whichever is smaller)."""
FINAL_PRESSURE_WEIGHT = 12.0
PRESSURE_RAMP = (200_000, 400_000)
"""The pressure warning's curriculum (``PressureWarningRamp``): its weight 1 until 200,000 env steps, when PPO
has begun to grasp, then growing to 12 at 400,000. Against a constant weight 1 (three seeds each, the same
settings and seeds, 200 held-out seeds) a ramp to 4 made the policies both gentler and more successful; a weight
of 3 from the start kept two seeds of three from learning to close; heavier final weights trade success for
force along one line, and with the closing reflexes 12 is the weight whose three seeds meet the goals
(docs/training.md; docs/notes/ppo_experiments.md)."""
POLICY_SETTINGS = {"net_arch": [128, 128], "log_std_init": 0.0}
"""MlpPolicy's network and initial action spread (std 1, SB3's default). Narrower starts keep more of a good
policy's holds (the reactive controller with per-step noise of std 0.2 keeps 50 % of its success, with 0.37 only
5 %), but the cubic action map turns a narrow start into no motion at all: with std 0.2, PPO's return stayed at
the passive policy's (about 7) for 200,000 steps, while with std 1 it rose to 75 within 300,000 (seed 0, 3-D;
docs/notes/ppo_experiments.md)."""
RESIDUAL_RATE = 0.1
"""The largest correction a residual policy adds to its controller's rate [1/s] (``--residual-rate``): a third of
the fastest closing, enough to stop or double the controller's slowed approach and many times its grip's press rate
(0.02 1/s)."""
RESIDUAL_POLICY_SETTINGS = {**POLICY_SETTINGS, "log_std_init": float(np.log(0.2))}
"""A residual policy's network and initial spread: std 0.2, so that its exploration (0.02 1/s at the default
``--residual-rate``) is about the controller's own press rate, and its first rollouts keep most of the
controller's grasps rather than shaking them loose."""


def ramped(steps: int, start: int, end: int, initial: float, final: float) -> float:
    """``initial`` until ``start`` env steps, then linearly to ``final`` at ``end``, and ``final`` after."""
    if steps >= end:
        return final
    return initial + (final - initial) * max(0.0, (steps - start) / (end - start))


@dataclass(frozen=True)
class RadiusOversampling:
    """A training curriculum, the vector env's ``episode_options``: each new episode, with probability ``share``,
    draws its specimen's radius uniformly from [``low``, ``high``] m instead of the task's range; the others draw it
    as the task does. Its draws come from the env's own generator, so a seeded run repeats.

    ``task_range`` is the task's ``object_radius`` range [m], which the band must lie within (a radius the task
    never draws would train on specimens no evaluation meets); ``share`` is in (0, 1]."""

    low: float
    high: float
    share: float
    task_range: tuple[float, float]

    def __post_init__(self) -> None:
        smallest, largest = self.task_range
        if not smallest <= self.low < self.high <= largest:
            raise ValueError(f"low = {self.low:g} and high = {self.high:g} m must satisfy {smallest:g} <= low < high "
                             f"<= {largest:g} (the task's object_radius range)")
        if not 0.0 < self.share <= 1.0:
            raise ValueError(f"share = {self.share:g} is outside (0, 1]")

    def __call__(self, rng: np.random.Generator) -> dict:
        if rng.random() < self.share:
            return {"object_radius": float(rng.uniform(self.low, self.high))}
        return {}

    def config(self) -> dict:
        """The curriculum as config.json records it (key ``oversample_radius``)."""
        return {"low_m": float(self.low), "high_m": float(self.high), "share": float(self.share)}


class PressureWarningRamp(BaseCallback):
    """Grows the reward's pressure warning (``RewardWeights.pressure``) from its weight in ``weights`` to
    ``final`` between ``start`` and ``end`` env steps, set at the start of every rollout (so one rollout's rewards
    share one weight) and logged to TensorBoard as ``train/pressure_weight``. A heavy warning from the start charges
    the first clumsy grasps more than they earn, and PPO may never learn to close; begun late, it charges the
    squeeze of a policy that already grasps."""

    def __init__(self, weights: RewardWeights, final: float, start: int, end: int) -> None:
        super().__init__()
        self.weights, self.final, self.start, self.end = weights, final, start, end

    def weight(self, steps: int) -> float:
        return ramped(steps, self.start, self.end, self.weights.pressure, self.final)

    def config(self) -> dict:
        """The ramp as config.json records it (key ``pressure_ramp``)."""
        return {"initial": self.weights.pressure, "final": self.final, "start_steps": self.start,
                "end_steps": self.end}

    def _on_rollout_start(self) -> None:
        weight = self.weight(self.num_timesteps)
        self.training_env.env_method("set_reward_weights", replace(self.weights, pressure=weight), indices=[0])
        self.logger.record("train/pressure_weight", weight)

    def _on_step(self) -> bool:
        return True


class ProgressAndCurve(BaseCallback):
    """A tqdm bar over the timesteps; every finished training episode's return and success (from VecMonitor) with
    the env steps and training wall time at its end, also logged to TensorBoard as ``rollout/success_rate``; and
    every ``validate_every`` steps the deterministic policy's success, return and peak finger force on
    ``episodes`` validation seeds from ``VALIDATION_SEED`` (logged as ``validation/success_rate``). Training wall
    time leaves out the validations' own time."""

    def __init__(self, total: int, validate_every: int = 0, episodes: int = VALIDATION_EPISODES,
                 num_threads: int = 1, residual: ResidualAction | None = None, curve_file: Path | None = None,
                 **settings) -> None:
        super().__init__()
        self.residual, self.curve_file = residual, curve_file
        self.total, self.validate_every, self.episodes, self.settings = total, validate_every, episodes, settings
        self.num_threads = min(num_threads, episodes)
        self.curve: list[tuple[int, float, float, float]] = []
        self.validation: list[dict] = []
        self.validating_s = 0.0

    def record(self) -> dict:
        """What curve.json holds: the training episodes (env steps, training wall time [s], return, success) and the
        validations so far."""
        return {"episodes": self.curve, "validation": self.validation}

    def training_wall(self) -> float:
        """Seconds spent training so far [s], without the validations."""
        return time.perf_counter() - self.start - self.validating_s

    def _on_training_start(self) -> None:
        self.start = time.perf_counter()
        self.bar = tqdm(total=self.total, desc="PPO", unit="step")

    def _on_step(self) -> bool:
        num_envs = self.training_env.num_envs
        self.bar.update(num_envs)
        wall = self.training_wall()
        for info in self.locals["infos"]:
            if "episode" in info:
                self.curve.append((self.num_timesteps, wall, float(info["episode"]["r"]),
                                   float(info.get("is_success", 0.0))))
        if self.curve:
            recent = self.curve[-100:]
            success = float(np.mean([s for *_, s in recent]))
            self.logger.record("rollout/success_rate", success)
            self.bar.set_postfix(ret=f"{np.mean([r for _, _, r, _ in recent]):.1f}", success=f"{success:.2f}",
                                 validation=f"{self.validation[-1]['success_rate']:.2f}" if self.validation else "-")
        if self.validate_every and self.num_timesteps // self.validate_every > (self.num_timesteps - num_envs) \
                // self.validate_every:
            self.validate()
        return True

    def validate(self) -> None:
        began = time.perf_counter()
        policy = ppo_policy(self.model, self.training_env, "the policy in training")
        if self.residual:
            policy = residual_policy(policy, self.residual)
        result = evaluate(policy, self.episodes, VALIDATION_SEED, progress=False, num_envs=self.episodes,
                          num_threads=self.num_threads, **self.settings)
        point = {"steps": self.num_timesteps, "training_wall_s": self.training_wall(),
                 **{key: result[key] for key in ("success_rate", "mean_return", "mean_peak_contact_force_N")}}
        self.validation.append(point)
        self.logger.record("validation/success_rate", point["success_rate"])
        self.logger.record("validation/mean_peak_contact_force_N", point["mean_peak_contact_force_N"])
        if self.curve_file is not None:  # a run stopped before its end keeps its curve so far
            self.curve_file.write_text(json.dumps(self.record()))
        self.validating_s += time.perf_counter() - began

    def _on_training_end(self) -> None:
        self.bar.close()


def provenance() -> dict:
    """Where a run was trained: the package's version and the git commit of the checkout it runs from (with
    ``-dirty`` where tracked files differ from it; None outside a git checkout), for its config.json."""
    root = Path(soft_gripper_env.__file__).resolve().parents[1]
    commit = None
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=30)
        if head.returncode == 0:
            changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                                     capture_output=True, text=True, timeout=30)
            commit = head.stdout.strip() + ("-dirty" if changed.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        pass
    return {"package_version": soft_gripper_env.__version__, "git_commit": commit}


def save_run(folder: Path, model: PPO, env: VecNormalize, config: dict, curve: dict) -> None:
    """What ``agents.evaluate --policy FOLDER`` loads: the model (ppo_model.zip), its VecNormalize statistics
    (vecnormalize.pkl) and the run's configuration (config.json); and its learning curve so far (curve.json, what
    ``agents.learning_curves`` reads)."""
    folder.mkdir(parents=True, exist_ok=True)
    model.save(folder / "ppo_model.zip")
    env.save(str(folder / "vecnormalize.pkl"))
    (folder / "config.json").write_text(json.dumps(config, indent=1))
    (folder / "curve.json").write_text(json.dumps(curve))


class RolloutCheckpoints(BaseCallback):
    """Saves the run (:func:`save_run`) into ``folder/steps_N`` at the start of the first rollout at or past each
    multiple of ``every`` env steps. There PPO has trained on every rollout collected so far and not yet stepped
    the next, so checkpoint N is the final model, statistics and config of the same run stopped at N steps
    (``--timesteps N``), which lets one run measure the shorter budgets it passes through. (SB3's
    CheckpointCallback saves in the middle of a rollout, a state that no shorter run ends in.)"""

    def __init__(self, folder: Path, every: int, config: Callable[[], dict], curve: Callable[[], dict]) -> None:
        super().__init__()
        self.folder, self.every, self.config, self.curve = folder, every, config, curve
        self.next = every

    def _on_rollout_start(self) -> None:
        if self.num_timesteps >= self.next:
            save_run(self.folder / f"steps_{self.num_timesteps}", self.model, self.model.get_env(),
                     {**self.config(), "timesteps": self.num_timesteps}, self.curve())
            self.next = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        return True


def starting_policy(name: str, settings: dict, residual: dict | None) -> dict:
    """The trained policy that ``--init-from name`` starts from: its folder, its config.json, and what the new
    run's config.json records of it (key ``init_from``). Refuses a policy that observes otherwise than ``settings``
    or corrects another controller than ``residual`` (or the same one with other guards), since its network would
    read or mean something else."""
    folder = policy_folder(name)
    missing = [file for file in ("ppo_model.zip", "vecnormalize.pkl", "config.json") if not (folder / file).exists()]
    if missing:
        raise FileNotFoundError(f"{folder} lacks {', '.join(missing)} (agents.train_ppo --out writes them)")
    config = run_config(folder)
    observation = config.get("task", {}).get("observation", "full")
    if observation != settings["observation"]:
        raise ValueError(f"it observes {observation!r}, this run {settings['observation']!r} (--observation)")
    if config.get("residual") != residual:
        raise ValueError(f"it corrects {config.get('residual')}, this run {residual} (--residual-to and its guards)")
    record = {"policy": name, "model": config.get("model"), "timesteps": config.get("timesteps"),
              "seed": config.get("seed"), "git_commit": config.get("git_commit"),
              "training_wall_s": config.get("training_wall_s")}
    return {"folder": folder, "config": config, "record": record}


def build_parser() -> argparse.ArgumentParser:
    """The command line's options and their defaults."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="folder for the model, statistics, config and logs")
    parser.add_argument("--timesteps", type=int, default=600_000,
                        help="env steps (default 600,000: about an hour in the 3-D model on 2 cores, alone)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-envs", type=int, default=32)
    parser.add_argument("--num-threads", type=int, default=2,
                        help="threads stepping the envs (at most --num-envs; 2 uses both cores of a 2-core machine)")
    parser.add_argument("--model", choices=MODELS, default=GraspTask().model,
                        help="rod model to train in (default: the env's, 3d; planar costs a third per step)")
    parser.add_argument("--observation", choices=("full", "sensors"), default="sensors",
                        help="what the policy observes (GraspTask.observation; default sensors: the same in both rod "
                             "models, so the policy also runs in the other)")
    add_reflexes(parser, defaults=TRAINING_REFLEXES)
    parser.add_argument("--final-pressure-weight", type=float, default=FINAL_PRESSURE_WEIGHT, metavar="W",
                        help="grow the reward's pressure warning (RewardWeights.pressure, 1 at the start) to W over "
                             f"--pressure-ramp (default {FINAL_PRESSURE_WEIGHT:g}; 1 keeps it constant)")
    parser.add_argument("--pressure-ramp", type=int, nargs=2, default=PRESSURE_RAMP, metavar=("START", "END"),
                        help="env steps over which the warning grows to --final-pressure-weight (default "
                             f"{PRESSURE_RAMP[0]} {PRESSURE_RAMP[1]})")
    parser.add_argument("--residual-to", choices=RESIDUAL_BASES, default=None, metavar="CONTROLLER",
                        help="learn a correction to this scripted controller (" + ", ".join(RESIDUAL_BASES)
                             + "; default: none, PPO acts alone)")
    parser.add_argument("--residual-base", nargs="+", default=None, metavar="NAME=VALUE",
                        help="settings of the controller that replace its preset's, one value each, named as "
                             "agents.tune_controller's --grid names them (e.g. grip=0.15 gust_grip=0.15; with "
                             "--residual-to; config.json records the controller's settings)")
    parser.add_argument("--residual-rate", type=float, default=RESIDUAL_RATE, metavar="RATE",
                        help=f"the largest correction added to the controller's rate [1/s] (default {RESIDUAL_RATE:g};"
                             " with --residual-to)")
    parser.add_argument("--residual-gust-hold", action="store_true",
                        help="the correction may not open a finger while a gust may blow (with --residual-to)")
    parser.add_argument("--residual-press-limit", type=float, default=None, metavar="FRACTION",
                        help="the correction may not close a finger pressing above this fraction of the specimen's "
                             "fragility limit, in (0, 1] (with --residual-to; default: no limit)")
    parser.add_argument("--residual-press-taper", type=float, default=None, metavar="FRACTION",
                        help="the correction's closing rate on a finger is scaled by 1 - force / (FRACTION x the "
                             "specimen's fragility limit), clipped to [0, 1]; FRACTION in (0, 1] (with --residual-to; "
                             "default: no taper)")
    parser.add_argument("--residual-close-untouched", action="store_true",
                        help="the correction may not open a finger that does not touch the specimen (with "
                             "--residual-to)")
    parser.add_argument("--oversample-radius", type=float, nargs=3, default=None, metavar=("LOW", "HIGH", "SHARE"),
                        help="draw the specimen's radius of a share SHARE in (0, 1] of the training episodes from "
                             "[LOW, HIGH] m, within the task's range (default: every episode draws from the task's "
                             "range; validation and evaluation always do)")
    parser.add_argument("--init-from", default=None, metavar="POLICY",
                        help="start from this trained policy (pretrained, pretrained_planar or a train_ppo folder): "
                             "its weights, optimiser state and observation statistics (default: a fresh network)")
    parser.add_argument("--pressure-onset", type=float, default=None, metavar="C",
                        help="the load (peak force / fragility limit) at which the training reward's pressure warning"
                             f" starts, in [0, 1) (GraspTask.pressure_onset; default {GraspTask().pressure_onset:g})")
    parser.add_argument("--eval-episodes", type=int, default=200, help="held-out episodes at the end (0: none)")
    parser.add_argument("--validate-every", type=int, default=50_000,
                        help="env steps between measures of the deterministic policy on validation seeds, the "
                             "learning curve (0: none)")
    parser.add_argument("--checkpoint-every", type=int, default=100_000,
                        help="env steps between checkpoints (DIR/checkpoints/steps_N, each loadable by "
                             "agents.evaluate --policy and equal to a run of --timesteps N; 0: none)")
    parser.add_argument("--validation-episodes", type=int, default=VALIDATION_EPISODES,
                        help=f"episodes per validation (default {VALIDATION_EPISODES})")
    return parser


def main(argv: list[str] | None = None) -> dict:
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("timesteps", "num_envs", "num_threads", "validation_episodes"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} = {getattr(args, name)} must be at least 1")
    for name in ("eval_episodes", "validate_every", "checkpoint_every"):
        if getattr(args, name) < 0:
            parser.error(f"--{name.replace('_', '-')} = {getattr(args, name)} must be at least 0")
    if args.num_threads > args.num_envs:
        parser.error(f"--num-threads = {args.num_threads} must be at most --num-envs = {args.num_envs}")
    if not 0.0 <= args.final_pressure_weight <= 1e6:
        parser.error(f"--final-pressure-weight = {args.final_pressure_weight} is outside [0, 1e6]")
    start, end = args.pressure_ramp
    if not 0 <= start <= end:
        parser.error(f"--pressure-ramp = {start} {end} must satisfy 0 <= START <= END")
    settings = {"model": args.model, "observation": args.observation, **reflex_settings(args)}
    task = task_from_arguments(parser, **settings)
    if not 0.0 < args.residual_rate <= task.max_curvature_rate:
        parser.error(f"--residual-rate = {args.residual_rate} is outside (0, {task.max_curvature_rate:g}] 1/s (the "
                     f"fastest closing)")
    if not args.residual_to and (args.residual_gust_hold or args.residual_press_limit is not None
                                 or args.residual_press_taper is not None or args.residual_close_untouched
                                 or args.residual_base is not None):
        parser.error("--residual-base, --residual-gust-hold, --residual-press-limit, --residual-press-taper and "
                     "--residual-close-untouched shape a correction: they need --residual-to")
    for option, fraction in (("--residual-press-limit", args.residual_press_limit),
                             ("--residual-press-taper", args.residual_press_taper)):
        if fraction is not None and not 0.0 < fraction <= 1.0:
            parser.error(f"{option} = {fraction} is outside (0, 1] (a fraction of the fragility limit)")
    oversampling = None
    if args.oversample_radius is not None:
        low, high, share = args.oversample_radius
        try:
            oversampling = RadiusOversampling(low, high, share, task.object_radius)
        except ValueError as error:
            parser.error(f"--oversample-radius LOW HIGH SHARE: {error}")
    training_settings = dict(settings)
    if args.pressure_onset is not None:
        if not 0.0 <= args.pressure_onset < 1.0:
            parser.error(f"--pressure-onset = {args.pressure_onset:g} is outside [0, 1) (a fraction of the fragility "
                         f"limit)")
        training_settings["pressure_onset"] = args.pressure_onset
    residual, combine = None, None
    if args.residual_to:
        base = make_policy(args.residual_to, task, args.seed)
        if args.residual_base is not None:
            try:
                grid = parse_grid(args.residual_base, "--residual-base")
                if any(len(values) != 1 for values in grid.values()):
                    raise ValueError("--residual-base takes one value per setting")
                base = ReactivePolicy(task, **{**base.settings(), **{name: values[0] for name, values in grid.items()}})
            except ValueError as error:
                parser.error(str(error))
        combine = ResidualAction(task, base, args.residual_rate,
                                 gust_hold=args.residual_gust_hold, press_limit=args.residual_press_limit,
                                 close_untouched=args.residual_close_untouched, press_taper=args.residual_press_taper)
        residual = {"base": args.residual_to, "base_settings": combine.base.settings(), **combine.settings()}
    policy_settings = RESIDUAL_POLICY_SETTINGS if residual else POLICY_SETTINGS
    start_from = None
    if args.init_from is not None:
        try:
            start_from = starting_policy(args.init_from, settings, residual)
        except (FileNotFoundError, ValueError) as error:
            parser.error(f"--init-from {args.init_from}: {error}")
        policy_settings = start_from["config"].get("policy", policy_settings)  # its network, not ours
    args.out.mkdir(parents=True, exist_ok=True)

    venv = SoftGripperSB3VecEnv(args.num_envs, seed=args.seed, num_threads=args.num_threads,
                                episode_options=oversampling, **training_settings)
    if combine is not None:
        venv = ResidualVecEnv(venv, combine)
    monitored = VecMonitor(venv, info_keywords=("is_success",))
    if start_from is None:
        env = VecNormalize(monitored, gamma=PPO_SETTINGS["gamma"])
    else:
        env = VecNormalize.load(str(start_from["folder"] / "vecnormalize.pkl"), monitored)
        env.training = True
    model = PPO("MlpPolicy", env, batch_size=min(1024, PPO_SETTINGS["n_steps"] * args.num_envs), **PPO_SETTINGS,
                policy_kwargs=policy_settings, seed=args.seed, verbose=0, device="cpu",
                tensorboard_log=str(args.out / "tensorboard"))
    if start_from is not None:
        model.set_parameters(str(start_from["folder"] / "ppo_model.zip"), exact_match=True, device="cpu")
    progress = ProgressAndCurve(args.timesteps, args.validate_every, episodes=args.validation_episodes,
                                num_threads=args.num_threads, residual=combine, curve_file=args.out / "curve.json",
                                **settings)
    ramp = PressureWarningRamp(task.reward, args.final_pressure_weight, *args.pressure_ramp)

    trained_from = provenance()

    def config() -> dict:
        return {**trained_from, "timesteps": args.timesteps, "seed": args.seed, "num_envs": args.num_envs,
                "num_threads": args.num_threads,
                # PyTorch's thread count changes the last bits of every update (its sums run in another order),
                # and a run then parts from one made with another count: a run reproduces only with the same one.
                "torch_threads": torch.get_num_threads(), "model": args.model, "observation": args.observation,
                "training_wall_s": progress.training_wall(), "validation_wall_s": progress.validating_s,
                "ppo": PPO_SETTINGS, "policy": policy_settings, "pressure_ramp": ramp.config(),
                "residual": residual, "oversample_radius": None if oversampling is None else oversampling.config(),
                "init_from": None if start_from is None else start_from["record"],
                "training_pressure_onset": training_settings.get("pressure_onset", task.pressure_onset),
                "task": json.loads(json.dumps(asdict(task), default=repr))}

    callbacks = [progress, ramp]
    if args.checkpoint_every:
        callbacks.append(RolloutCheckpoints(args.out / "checkpoints", args.checkpoint_every, config, progress.record))
    model.learn(args.timesteps, callback=callbacks, tb_log_name=f"ppo_seed{args.seed}")
    final = config()
    wall = final["training_wall_s"]
    save_run(args.out, model, env, final, progress.record())

    results = {"timesteps": args.timesteps, "seed": args.seed, "training_wall_s": wall}
    if args.eval_episodes:
        policies = {"ppo": load_ppo(args.out)} | {name: make_policy(name, task, args.seed)
                                                  for name in ("ramp", "reactive", "reactive_graded")}
        for name, policy in policies.items():
            result = evaluate(policy, args.eval_episodes, HELD_OUT_SEED, **settings)
            results[name] = {key: result[key] for key in ("success_rate", "mean_return", "mean_peak_contact_force_N",
                                                          "endings")}
            print(f"{name:>9}: success {result['success_rate']:.3f}, return {result['mean_return']:.1f}, "
                  f"peak force {result['mean_peak_contact_force_N']:.2f} N")
        (args.out / "evaluation.json").write_text(json.dumps(results, indent=2))
    plot_learning_curves([load_run(args.out)], args.out / "learning_curve.png")
    return results


if __name__ == "__main__":
    main()
