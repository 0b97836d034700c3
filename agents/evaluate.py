"""Evaluate a policy on SoftGripperUnderwater-v0 over fixed seeds: success rate, mean return, peak finger force,
and how the episodes ended.

    python -m agents.evaluate
        --policy random|ramp|reactive|reactive_tuned|reactive_graded|pretrained|pretrained_planar|PATH
        [--episodes 200] [--seed 1000] [--json FILE] [--model planar|3d]

Episodes use seeds seed, seed + 1, ...: every policy sees the same specimens, currents and gusts, so their numbers
compare directly. PATH is a folder that ``agents.train_ppo`` wrote (its model and VecNormalize statistics);
``pretrained`` is the policy shipped in ``agents/pretrained/`` (trained in 3-D), ``pretrained_planar`` the one
trained in the planar model (``agents/pretrained_planar/``). The episodes run batched, ``--num-envs`` at a time,
each exactly as a single env with its seed would run it.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from dataclasses import asdict, fields
from pathlib import Path

import numpy as np
from tqdm import tqdm

from agents.scripted import GRADED_3D_GAINS, TUNED_3D_GAINS, RampPolicy, RandomPolicy, ReactivePolicy
from soft_gripper_env.env import SoftGripperUnderwaterVectorEnv, observation_bounds, observation_slices
from soft_gripper_env.grasp_task import GraspTask, RewardWeights

PRETRAINED = Path(__file__).resolve().parent / "pretrained"
"""The shipped PPO policy (trained in the default 3-D model): its model, VecNormalize statistics and config."""
SHIPPED = {"pretrained": PRETRAINED, "pretrained_planar": PRETRAINED.with_name("pretrained_planar")}
"""The trained policies shipped with the package, by the name ``--policy`` gives them: the default one, and the one
trained in the planar model before it."""
ENDINGS = ("success", "harmed", "lost", "solver_failure", "not_all_touching", "off_grasp_point", "moving",
           "not_held_through_gust")
"""How an episode can end, in the order :func:`episode_ending` tests them."""


def episode_ending(task: GraspTask, observation: np.ndarray, terminated: bool, info: dict) -> str:
    """Why an episode ended as it did, from its last observation and info: ``"success"``; ``"harmed"`` (a finger
    pressed above the specimen's fragility limit); ``"lost"`` (the object beyond ``lost_distance``);
    ``"solver_failure"``; or, at the episode's end, the first condition of a hold that failed there:
    ``"not_all_touching"`` (a finger pressing less than ``contact_force``), ``"off_grasp_point"`` (farther than
    ``hold_distance``), ``"moving"`` (faster than ``rest_speed``), else ``"not_held_through_gust"`` (held at the
    end, but not without a break since the gust began)."""
    if info["is_success"]:
        return "success"
    if info["harmed"]:
        return "harmed"
    if terminated:
        return "lost"
    if info["solver_failure"]:
        return "solver_failure"
    if np.any(np.asarray(info["finger_forces_N"]) < task.contact_force):
        return "not_all_touching"
    layout = observation_slices(task)
    if np.linalg.norm(np.asarray(observation[layout["object_offset"]], dtype=float)) > task.hold_distance:
        return "off_grasp_point"
    if np.linalg.norm(np.asarray(observation[layout["object_velocity"]], dtype=float)) > task.rest_speed:
        return "moving"
    return "not_held_through_gust"


def evaluate(policy: Callable[[np.ndarray], np.ndarray], episodes: int, seed: int = 1000, progress: bool = True,
             num_envs: int = 16, **settings) -> dict:
    """Runs ``episodes`` episodes with seeds seed, seed + 1, ..., ``num_envs`` at a time (``policy`` acts on a
    batch of observations); ``settings`` are :class:`~soft_gripper_env.grasp_task.GraspTask` fields. Returns the
    success rate, mean and standard deviation of the return, the mean over episodes of each reward term's sum
    (what the return is made of), the mean episode length, the mean over episodes of the peak finger force [N]
    (the largest sum of one finger's normal forces, averaged over a control interval), the mean peak load (that
    peak over the specimen's fragility limit, dimensionless) and the fraction of episodes whose peak passed the
    limit (harm needs the sustained force to pass it; a brief squeeze does not), how many episodes ended each way
    (:func:`episode_ending`), the wall time [s], and per episode: success, return, peak force, peak load, ending,
    the object's final offset from the grasp point [m], its radius [m] (as observed) and its fragility limit [N]."""
    num_envs = max(1, min(num_envs, episodes))
    venv = SoftGripperUnderwaterVectorEnv(num_envs, **settings)
    task = venv.task
    check_action_map(policy, task)
    layout = observation_slices(task)
    offset_part, radius_part = layout["object_offset"], layout["object_radius"]
    term_names = [term.name for term in fields(RewardWeights)]
    records: list[dict] = []
    start = time.perf_counter()
    with tqdm(total=episodes, desc="episodes", unit="episode", disable=not progress) as bar:
        for first in range(seed, seed + episodes, num_envs):
            count = min(num_envs, seed + episodes - first)
            observations, _ = venv.reset(seed=[first + k for k in range(num_envs)])
            radii = observations[:, radius_part][:, 0].astype(float)
            returns, peaks, loads = np.zeros(num_envs), np.zeros(num_envs), np.zeros(num_envs)
            term_sums = np.zeros((len(term_names), num_envs))
            lengths = np.zeros(num_envs, dtype=np.int64)
            running = np.arange(num_envs) < count
            ended: dict[int, dict] = {}
            while running.any():
                observations, reward, terminated, truncated, info = venv.step(policy(observations))
                returns[running] += reward[running]
                term_sums[:, running] += np.array([info["reward_terms"][name] for name in term_names])[:, running]
                lengths[running] += 1
                force = info["finger_forces_N"].max(axis=1)
                peaks[running] = np.maximum(peaks[running], force[running])
                loads[running] = np.maximum(loads[running], (force / info["fragile_force_N"])[running])
                for k in np.nonzero(running & (terminated | truncated))[0]:
                    single = {key: info[key][k] for key in ("is_success", "harmed", "solver_failure",
                                                            "finger_forces_N")}
                    ended[k] = {"success": bool(single["is_success"]), "return": float(returns[k]),
                                "length": int(lengths[k]), "peak": float(peaks[k]), "load": float(loads[k]),
                                "terms": term_sums[:, k].copy(),
                                "ending": episode_ending(task, observations[k], bool(terminated[k]), single),
                                "offset": [float(x) for x in observations[k][offset_part]],
                                "radius": float(radii[k]), "limit": float(info["fragile_force_N"][k])}
                    running[k] = False
            records += [ended[k] for k in range(count)]
            bar.update(count)
    seconds = time.perf_counter() - start
    venv.close()
    column = {key: [record[key] for record in records] for key in records[0]}
    mean_terms = np.mean(column["terms"], axis=0)
    return {"episodes": episodes, "first_seed": seed, "success_rate": float(np.mean(column["success"])),
            "mean_return": float(np.mean(column["return"])), "std_return": float(np.std(column["return"])),
            "mean_reward_terms": {name: float(value) for name, value in zip(term_names, mean_terms, strict=True)},
            "mean_length": float(np.mean(column["length"])),
            "mean_peak_contact_force_N": float(np.mean(column["peak"])),
            "mean_peak_load": float(np.mean(column["load"])),
            "fraction_peak_above_limit": float(np.mean(np.array(column["load"]) > 1.0)),
            "endings": {name: column["ending"].count(name) for name in ENDINGS}, "seconds": seconds,
            "successes": column["success"], "returns": column["return"], "peak_contact_forces_N": column["peak"],
            "peak_loads": column["load"], "episode_endings": column["ending"], "final_object_offsets": column["offset"],
            "object_radii_m": column["radius"], "fragile_forces_N": column["limit"]}


def load_ppo(model_dir: Path) -> Callable[[np.ndarray], np.ndarray]:
    """A trained PPO policy with its observation normalisation (both saved by agents/train_ppo.py), acting
    deterministically on one observation or a batch."""
    import pickle

    from stable_baselines3 import PPO

    model_dir = Path(model_dir)
    missing = [name for name in ("ppo_model.zip", "vecnormalize.pkl") if not (model_dir / name).exists()]
    if missing:
        raise FileNotFoundError(f"policy folder {model_dir} lacks {', '.join(missing)} (agents.train_ppo --out "
                                f"writes both)")
    model = PPO.load(model_dir / "ppo_model.zip", device="cpu")
    with open(model_dir / "vecnormalize.pkl", "rb") as f:
        normalize = pickle.load(f)
    normalize.training = False

    act = ppo_policy(model, normalize, f"the policy in {model_dir}")
    config = run_config(model_dir)
    act.trained_task = config.get("task", {})
    act.observation = act.trained_task.get("observation", "full")
    residual = config.get("residual")
    if residual:  # a correction to a scripted controller (agents.train_ppo --residual-to): run the two together
        from agents.residual import ResidualAction, residual_policy

        task = GraspTask(**{name: act.trained_task[name] for name in ("model", "observation", *REFLEXES)})
        act = residual_policy(act, ResidualAction(task, residual_base(residual, task), residual["rate"],
                                                  gust_hold=residual.get("gust_hold", False),
                                                  press_limit=residual.get("press_limit"),
                                                  close_untouched=residual.get("close_untouched", False),
                                                  press_taper=residual.get("press_taper")))
    return act


def residual_base(residual: dict, task: GraspTask) -> ReactivePolicy:
    """The controller that a correction's config.json (its ``residual``) corrects, in ``task``: built from the
    settings the run recorded (``base_settings``), so that a later change of the named preset's gains cannot
    change what a trained correction does; a config without them (written before they were recorded) names only
    the preset, which is built as it is today."""
    settings = residual.get("base_settings")
    return make_policy(residual["base"], task, 0) if settings is None else ReactivePolicy(task, **settings)


def run_config(model_dir: Path) -> dict:
    """A policy folder's config.json (what ``agents.train_ppo`` wrote), or {} without one."""
    config_file = Path(model_dir) / "config.json"
    return json.loads(config_file.read_text()) if config_file.exists() else {}


def trained_task(model_dir: Path) -> dict:
    """The task a policy folder's config.json says it was trained on (its ``task``), or {} without one."""
    return run_config(model_dir).get("task", {})


ACTION_MAP = ("control_dt", "max_curvature_rate", "action_exponent", "curvature_range", "touching_closing_rate",
              "approach_slowing_gap")
"""The task's settings that say what an action does: a policy trained with other values would act wrongly, not
differently, so :func:`check_action_map` refuses it (for :func:`evaluate` and :func:`main`)."""


def action_map_mismatch(trained_task: dict, task: GraspTask) -> str | None:
    """Where a policy's training task (its config.json's ``task``) maps actions otherwise than ``task``: a sentence
    naming each differing setting of :data:`ACTION_MAP` with both values, or None."""
    today = asdict(task)

    def same(trained, value) -> bool:  # None (no bound) equals only None
        if trained is None or value is None:
            return trained is None and value is None
        return bool(np.allclose(trained, value, rtol=1e-12, atol=0.0))

    differing = [f"{name} = {trained_task[name]!r} (today {today[name]!r})" for name in ACTION_MAP
                 if name in trained_task and not same(trained_task[name], today[name])]
    return ", ".join(differing) or None


def check_action_map(policy: Callable[[np.ndarray], np.ndarray], task: GraspTask) -> None:
    """Raises ValueError where a trained policy (one with a ``trained_task``, as :func:`load_ppo` gives) would act
    in ``task`` otherwise than it was trained to (:func:`action_map_mismatch`): it would act wrongly, silently."""
    mismatch = action_map_mismatch(getattr(policy, "trained_task", {}), task)
    if mismatch:
        raise ValueError(f"the policy was trained on a task whose actions act otherwise: {mismatch}; run it with "
                         f"the settings (the closing reflexes among them) and the version of the package it was "
                         f"trained with")


def ppo_policy(model, normalize, name: str = "the policy") -> Callable[[np.ndarray], np.ndarray]:
    """A PPO model acting deterministically on one observation or a batch, through ``normalize`` (a VecNormalize
    whose statistics it reads and never updates)."""
    size = normalize.obs_rms.mean.shape[0]

    def act(observation: np.ndarray) -> np.ndarray:
        observation = np.asarray(observation)
        if observation.shape[-1] != size:
            raise ValueError(f"{name} takes observations of {size} values, got {observation.shape[-1]} (observation "
                             f"= 'full' holds node states of 2 components in the planar model and 3 in 3-D; "
                             f"'sensors' is the same in both)")
        batch = observation.reshape(-1, observation.shape[-1])
        action, _ = model.predict(normalize.normalize_obs(batch), deterministic=True)
        return action.reshape(observation.shape[:-1] + action.shape[-1:])

    act.observation_size = size
    return act


SCRIPTED = ("random", "ramp", "reactive", "reactive_tuned", "reactive_graded")
"""The scripted policies ``--policy`` names (no config.json, no reflexes of their own)."""


def policy_folder(name: str) -> Path:
    """The folder of a trained policy that ``--policy`` names: one of :data:`SHIPPED` or a path."""
    return SHIPPED.get(name, Path(name))


def make_policy(name: str, task: GraspTask, seed: int) -> Callable[[np.ndarray], np.ndarray]:
    """``random`` (seeded by ``seed``), ``ramp``, ``reactive``, ``reactive_tuned`` (:data:`TUNED_3D_GAINS`),
    ``reactive_graded`` (:data:`GRADED_3D_GAINS`), one of :data:`SHIPPED` or the path of a trained policy."""
    if name == "random":
        return RandomPolicy(task, seed)
    if name == "ramp":
        return RampPolicy(task)
    if name == "reactive":
        return ReactivePolicy(task)
    if name == "reactive_tuned":
        return ReactivePolicy(task, **TUNED_3D_GAINS)
    if name == "reactive_graded":
        return ReactivePolicy(task, **GRADED_3D_GAINS)
    return load_ppo(policy_folder(name))


REFLEXES = ("touching_closing_rate", "approach_slowing_gap")
"""The task's closing reflexes that the command lines set (each an option named after it)."""
TRAINING_REFLEXES = {"touching_closing_rate": 0.15, "approach_slowing_gap": 0.01}
"""The closing reflexes the policies train with (``--touching-closing-rate``, ``--approach-slowing-gap``): a
touching finger closes at most at 0.15 1/s, and within 1 cm of the specimen a finger's fastest closing falls
linearly from 0.3 1/s to that bound. With them, and the warning grown to 12, PPO holds more gently than the
reactive controller and more often (docs/training.md); the fair baselines get them too."""


def bound_or_none(text: str) -> float | None:
    """A reflex option's value: a number, or ``none`` for no reflex."""
    return None if text.strip().lower() == "none" else float(text)


class _FromPolicy:
    def __repr__(self) -> str:
        return "a trained policy's, from its config.json; none for random, ramp and reactive"


FROM_POLICY = _FromPolicy()
"""The evaluate script's default reflexes: a trained policy's from its config.json, none for the scripted ones."""


def add_reflexes(parser: argparse.ArgumentParser, more: str = "", defaults: dict | None = None) -> None:
    """``--touching-closing-rate RATE`` and ``--approach-slowing-gap M``, the task's :data:`REFLEXES` (for this
    script and train_ppo), each ``none`` or a number; ``defaults`` maps a reflex to its default (None: none)."""
    defaults = defaults or {}
    rate, gap = (defaults.get(name) for name in REFLEXES)

    def shown(default) -> str:
        return "none" if default is None else f"{default:g}" if isinstance(default, float) else repr(default)

    parser.add_argument("--touching-closing-rate", type=bound_or_none, default=rate, metavar="RATE",
                        help="the fastest a touching finger closes [1/s] (GraspTask.touching_closing_rate; none: no "
                             f"bound; default: {shown(rate)}){more}")
    parser.add_argument("--approach-slowing-gap", type=bound_or_none, default=gap, metavar="M",
                        help="within this gap [m] a finger's fastest closing falls linearly to the touching bound "
                             "(GraspTask.approach_slowing_gap; needs --touching-closing-rate; none: no slowing; "
                             f"default: {shown(gap)}){more}")


def reflex_settings(args: argparse.Namespace) -> dict:
    """The :data:`REFLEXES` as the command line set them."""
    return {name: getattr(args, name) for name in REFLEXES}


def task_from_arguments(parser: argparse.ArgumentParser, **settings) -> GraspTask:
    """The task of the command line's settings, or the parser's error naming the option that is out of range."""
    try:
        return GraspTask(**settings)
    except ValueError as error:
        message = str(error)
        for name in REFLEXES:
            message = message.replace(f"GraspTask.{name}", "--" + name.replace("_", "-"))
        parser.error(message)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--policy", required=True,
                        help="random, ramp, reactive, reactive_tuned (its gains tuned in 3-D), reactive_graded (with "
                             "a graded touch, tuned in 3-D), pretrained (trained in 3-D), pretrained_planar, or a "
                             "train_ppo folder")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1000, help="the first episode's seed")
    parser.add_argument("--json", type=Path, help="write the results here")
    parser.add_argument("--model", choices=("planar", "3d"), default="3d", help="rod model (default 3d)")
    parser.add_argument("--num-envs", type=int, default=16, help="episodes run at a time (default 16)")
    add_reflexes(parser, "; a trained policy runs only with the reflexes it was trained with",
                 defaults=dict.fromkeys(REFLEXES, FROM_POLICY))
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes = {args.episodes} must be at least 1")
    if args.num_envs < 1:
        parser.error(f"--num-envs = {args.num_envs} must be at least 1")
    if args.policy not in (*SCRIPTED, *SHIPPED) and not Path(args.policy).is_dir():
        parser.error(f"--policy = {args.policy!r} is not {', '.join((*SCRIPTED, *SHIPPED))} or a folder")
    reflexes = reflex_settings(args)
    trained = {} if args.policy in SCRIPTED else \
        trained_task(policy_folder(args.policy))
    from_policy = {name: trained.get(name) for name in REFLEXES if reflexes[name] is FROM_POLICY}
    reflexes.update(from_policy)
    if any(value is not None for value in from_policy.values()):
        print("the closing reflexes from the policy's config.json: "
              + ", ".join(f"--{name.replace('_', '-')} {value:g}" for name, value in from_policy.items()
                          if value is not None))
    task = task_from_arguments(parser, model=args.model, **reflexes)
    try:
        policy = make_policy(args.policy, task, args.seed)
    except FileNotFoundError as error:
        parser.error(str(error))
    observation = getattr(policy, "observation", "full")  # a trained policy observes what it was trained on
    expected = observation_bounds(GraspTask(model=args.model, observation=observation))[0].size
    if getattr(policy, "observation_size", expected) != expected:
        parser.error(f"--policy {args.policy} takes observations of {policy.observation_size} values, and the "
                     f"{args.model} model gives {expected} (a policy trained on observation = 'full' acts only in "
                     f"the rod model it was trained in; one trained on 'sensors' acts in both)")
    try:
        check_action_map(policy, task)
    except ValueError as error:
        parser.error(f"--policy {args.policy}: {error} (--touching-closing-rate, --approach-slowing-gap)")
    result = evaluate(policy, args.episodes, args.seed, num_envs=args.num_envs, model=args.model,
                      observation=observation, **reflexes)
    result.update(policy=args.policy, model=args.model, observation=observation, **reflexes)
    print("| policy | model | episodes | success | mean return | mean peak finger force [N] | mean peak / limit | "
          "peak above the limit |\n|---|---|---|---|---|---|---|---|\n"
          f"| {args.policy} | {args.model} | {args.episodes} (seeds {args.seed}–{args.seed + args.episodes - 1}) | "
          f"{result['success_rate']:.3f} | {result['mean_return']:.2f} ± {result['std_return']:.2f} | "
          f"{result['mean_peak_contact_force_N']:.2f} | {result['mean_peak_load']:.2f} | "
          f"{result['fraction_peak_above_limit']:.0%} of episodes |")
    print("endings: " + ", ".join(f"{name} {count}" for name, count in result["endings"].items() if count))
    if reflexes["touching_closing_rate"] is not None:
        print(f"a touching finger closed at most at {reflexes['touching_closing_rate']:g} 1/s "
              f"(--touching-closing-rate)")
    if reflexes["approach_slowing_gap"] is not None:
        print(f"within {reflexes['approach_slowing_gap']:g} m a finger closed at most at a rate falling to that "
              f"bound (--approach-slowing-gap)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json}")
    return result


if __name__ == "__main__":
    main()
