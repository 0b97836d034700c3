"""Tune the reactive controller on tuning seeds: every combination of the settings given, each run over the same
episodes (``agents.evaluate``), with the closing reflexes the trained policies use, as a trained policy's own
settings are tuned.

    python -m agents.tune_controller --grid grip=0.2,0.3 gust_grip=0.3,0.4 gain=0.1,0.2 [touch_force=none,0.1]
        --json FILE [--plot FIGURE.png] [--model 3d] [--seed 5000] [--episodes 200] [--max-force N] [--workers 2]

``--grid`` names :class:`agents.scripted.ReactivePolicy` settings (``none`` for ``touch_force`` is the on–off
touch); a setting left out keeps the controller's default. The seeds 5,000–5,199 are the project's tuning seeds: no
result is reported on them. FILE is written after each setting finishes: the same command run again goes on where
it stopped; another grid into the same FILE adds its settings to those there (it refuses a FILE from other episodes
or another task). The choice, among every setting in FILE, is the most successful (ties: the lower mean peak finger
force), of those whose mean peak force is below ``--max-force`` [N] if given.
"""

from __future__ import annotations

import argparse
import inspect
import itertools
import json
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from agents.evaluate import (
    REFLEXES,
    TRAINING_REFLEXES,
    add_reflexes,
    bound_or_none,
    evaluate,
    reflex_settings,
    task_from_arguments,
)
from agents.scripted import ReactivePolicy
from soft_gripper_env.grasp_task import GraspTask

TUNING_SEED = 5000
"""The first of the tuning seeds (5,000–5,199): settings are chosen on them, and nothing is reported on them."""
SETTINGS = tuple(name for name in inspect.signature(ReactivePolicy).parameters if name != "task")
"""What ``--grid`` may name: :class:`~agents.scripted.ReactivePolicy`'s settings."""
REPORTED = ("success_rate", "mean_peak_contact_force_N", "mean_return", "endings", "successes",
            "peak_contact_forces_N", "seconds")
"""What the JSON keeps of each setting's evaluation (its per-episode lists for paired comparisons)."""


def parse_grid(items: list[str], option: str = "--grid") -> dict[str, list[float | None]]:
    """``NAME=V1,V2,...`` items as {name: values}; raises ValueError naming ``option``, and the bad name or value."""
    grid: dict[str, list[float | None]] = {}
    for item in items:
        name, equals, values = item.partition("=")
        if not equals or not values:
            raise ValueError(f"{option} item {item!r} is not NAME=V1,V2,...")
        if name not in SETTINGS:
            raise ValueError(f"{option} names {name!r}, not a setting of the reactive controller "
                             f"({', '.join(SETTINGS)})")
        if name in grid:
            raise ValueError(f"{option} names {name!r} twice")
        try:
            grid[name] = [bound_or_none(value) for value in values.split(",")]
        except ValueError:
            raise ValueError(f"{option} {name}: {values!r} holds a value that is not a number (or none)") from None
        if None in grid[name] and name != "touch_force":
            raise ValueError(f"{option} {name}: none is a value of touch_force only (the on–off touch)")
    return grid


def settings_of(grid: dict[str, list[float | None]]) -> list[dict]:
    """Every combination of the grid's values, in the order given (the last name varying fastest)."""
    return [dict(zip(grid, values, strict=True)) for values in itertools.product(*grid.values())]


def setting_key(setting: dict) -> str:
    """A setting's name in the JSON: ``name=value`` pairs in the order given."""
    return " ".join(f"{name}={'none' if value is None else f'{value:g}'}" for name, value in setting.items())


def evaluate_setting(setting: dict, task_settings: dict, episodes: int, seed: int) -> dict:
    """One setting's evaluation (what :data:`REPORTED` keeps), on one thread."""
    task = GraspTask(**task_settings)
    result = evaluate(ReactivePolicy(task, **setting), episodes, seed, progress=False, **task_settings)
    return {key: result[key] for key in REPORTED}


def choose(results: dict[str, dict], max_force: float | None) -> str | None:
    """The most successful setting (ties: the lower mean peak force) whose mean peak force [N] is below
    ``max_force`` (None: any); None where none qualifies."""
    allowed = [key for key, result in results.items()
               if max_force is None or result["mean_peak_contact_force_N"] < max_force]
    return min(allowed, key=lambda key: (-results[key]["success_rate"], results[key]["mean_peak_contact_force_N"]),
               default=None)


def table(results: dict[str, dict], chosen: str | None) -> str:
    """The results as a Markdown table, the choice in bold."""
    rows = ["| setting | success | mean peak force [N] | lost | not held through gust | a finger not touching | "
            "harmed |", "|---|---|---|---|---|---|---|"]
    for key, result in results.items():
        endings = result["endings"]
        mark = "**" if key == chosen else ""
        rows.append(f"| {mark}{key}{mark} | {mark}{result['success_rate']:.3f}{mark} | "
                    f"{result['mean_peak_contact_force_N']:.2f} | {endings['lost']} | "
                    f"{endings['not_held_through_gust']} | {endings['not_all_touching']} | {endings['harmed']} |")
    return "\n".join(rows)


def varying_label(key: str, keys: list[str]) -> str:
    """``key`` with only the settings whose values differ among ``keys`` (all of it where none differ)."""
    pairs = [dict(pair.split("=") for pair in other.split()) for other in keys]
    varying = [name for name in pairs[0] if len({pair.get(name) for pair in pairs}) > 1]
    own = dict(pair.split("=") for pair in key.split())
    return " ".join(f"{name}={own[name]}" for name in varying) or key


def plot(results: dict[str, dict], chosen: str | None, path: Path, title: str, max_force: float | None = None) -> None:
    """Success (with its 95 % Wilson interval) against mean peak force, one point per setting labelled by what
    differs between them, the choice ringed, and the force bound [N] of the choice (if any) as a dashed line."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.compare import wilson_interval

    fig, ax = plt.subplots(figsize=(7.5, 5))
    keys = list(results)
    for k, (key, result) in enumerate(results.items()):
        x, y = result["mean_peak_contact_force_N"], result["success_rate"]
        low, high = wilson_interval(sum(result["successes"]), len(result["successes"]))
        ax.errorbar(x, y, yerr=[[y - low], [high - y]], fmt="o", color="C1" if key == chosen else "C0", capsize=3,
                    lw=0.8)
        ax.annotate(varying_label(key, keys), (x, y), fontsize=8, xytext=(5, 4 if k % 2 == 0 else -11),
                    textcoords="offset points")  # alternately above and below: neighbours' labels overlap less
    if max_force is not None:
        ax.axvline(max_force, color="0.4", ls="--", lw=1, label=f"choice among settings below {max_force:g} N")
    if chosen is not None:
        ax.plot(results[chosen]["mean_peak_contact_force_N"], results[chosen]["success_rate"], "o", ms=14,
                mfc="none", color="C1", label=f"chosen: {chosen}")
    if chosen is not None or max_force is not None:
        ax.legend(loc="best", fontsize=8)
    ax.set_xlabel("mean peak finger force [N]")
    ax.set_ylabel("success rate (95 % interval)")
    ax.set_title(title, fontsize=9, wrap=True)
    ax.grid(alpha=0.3)
    ax.margins(x=0.25)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--grid", nargs="+", required=True, metavar="NAME=V1,V2",
                        help=f"settings to combine: {', '.join(SETTINGS)}")
    parser.add_argument("--json", type=Path, required=True, help="results, written after each setting; resumed")
    parser.add_argument("--plot", type=Path, help="success against mean peak force, one point per setting")
    parser.add_argument("--model", choices=("planar", "3d"), default=GraspTask().model)
    parser.add_argument("--seed", type=int, default=TUNING_SEED, help=f"the first seed (default {TUNING_SEED})")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--max-force", type=float, default=None, metavar="N",
                        help="choose among settings whose mean peak finger force is below this [N]")
    parser.add_argument("--workers", type=int, default=2, help="settings evaluated at a time, one process each")
    add_reflexes(parser, defaults=TRAINING_REFLEXES)
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes = {args.episodes} must be at least 1")
    if args.workers < 1:
        parser.error(f"--workers = {args.workers} must be at least 1")
    if args.max_force is not None and not args.max_force > 0:
        parser.error(f"--max-force = {args.max_force} N must be above 0")
    try:
        grid = parse_grid(args.grid)
    except ValueError as error:
        parser.error(str(error))
    task_settings = {"model": args.model, **reflex_settings(args)}
    task = task_from_arguments(parser, **task_settings)
    settings = settings_of(grid)
    for setting in settings:
        try:
            ReactivePolicy(task, **setting)
        except ValueError as error:
            parser.error(f"--grid {setting_key(setting)}: {error}")
    conditions = {"episodes": args.episodes, "first_seed": args.seed, "task": repr(asdict(task))}
    results: dict[str, dict] = {}
    if args.json.exists():
        kept = json.loads(args.json.read_text())
        differing = [name for name in conditions if kept.get("conditions", {}).get(name) != conditions[name]]
        if differing:
            parser.error(f"--json {args.json} holds results of other {', '.join(differing)}: give another file")
        results = kept["results"]
    wanted = [setting for setting in settings if setting_key(setting) not in results]
    print(f"{len(settings)} settings, {len(settings) - len(wanted)} kept in {args.json}; {len(wanted)} to run, "
          f"{args.episodes} episodes each (seeds {args.seed}–{args.seed + args.episodes - 1}), {args.workers} at a "
          f"time", flush=True)

    order = list(results) + [setting_key(s) for s in wanted]  # earlier grids' settings first, then this one's

    def save() -> None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        ordered = {key: results[key] for key in order if key in results}
        args.json.write_text(json.dumps({"conditions": conditions, "max_force_N": args.max_force,
                                         "chosen": choose(ordered, args.max_force), "results": ordered}, indent=1))

    with ProcessPoolExecutor(args.workers) as pool, tqdm(total=len(wanted), desc="settings", unit="setting") as bar:
        running = {pool.submit(evaluate_setting, setting, task_settings, args.episodes, args.seed): setting
                   for setting in wanted}
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                key = setting_key(running.pop(future))
                results[key] = future.result()
                save()
                bar.write(f"{key}: success {results[key]['success_rate']:.3f} at "
                          f"{results[key]['mean_peak_contact_force_N']:.2f} N")
                bar.update()
    shown = {key: results[key] for key in order}
    chosen = choose(shown, args.max_force)
    print(table(shown, chosen))
    print(f"chosen: {chosen}" if chosen else f"no setting presses less than --max-force {args.max_force} N")
    if args.plot:
        title = (f"The reactive controller's settings, {args.model} model, seeds {args.seed}–"
                 f"{args.seed + args.episodes - 1}\nwith the reflexes "
                 + ", ".join(f"{name} {task_settings[name]}" for name in REFLEXES))
        plot(shown, chosen, args.plot, title, args.max_force)
        print(f"wrote {args.plot}")
    return {"chosen": chosen, "results": shown}


if __name__ == "__main__":
    main()
