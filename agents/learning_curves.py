"""Learning curves of one or more PPO runs of ``agents.train_ppo``: the deterministic policy's success on the
validation seeds against env steps and against training wall time, each run and their mean, with the scripted
controllers' and the final policies' held-out success as lines.

    python -m agents.learning_curves DIR [DIR ...] --out FIGURE.png [--baseline LABEL=EVALUATION.json ...]

``--baseline`` draws a controller's success from an ``agents.evaluate --json`` file as a line too: measured on
the validation seeds (``--seed 500000 --episodes 64``), it compares with the curves seed for seed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

BASELINE_COLOURS = ("tab:olive", "tab:cyan", "tab:brown", "tab:pink")
"""The ``--baseline`` lines' colours, apart from the runs' (C0, C1, ...)."""


def load_run(run_dir: Path) -> dict:
    """A train_ppo folder's curve (training episodes and validations) and, where written, its held-out
    evaluation."""
    run_dir = Path(run_dir)
    curve_file = run_dir / "curve.json"
    if not curve_file.exists():
        raise FileNotFoundError(f"{run_dir} has no curve.json (agents.train_ppo --out writes it)")
    run = json.loads(curve_file.read_text())
    evaluation = run_dir / "evaluation.json"
    run["evaluation"] = json.loads(evaluation.read_text()) if evaluation.exists() else {}
    run["name"] = run_dir.name
    return run


def plot_learning_curves(runs: list[dict], path: Path, baselines: dict[str, dict] | None = None) -> None:
    """Validation success against env steps (left) and training wall time (right): one thin line per run, their
    mean in bold where there are several; the held-out success of the scripted controllers (mean over the runs'
    evaluations) and of each final policy as horizontal lines, and each of ``baselines`` (label → an
    ``agents.evaluate`` result) as a line of its own."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for k, run in enumerate(runs):
        points = run.get("validation", [])
        if not points:
            continue
        steps = [p["steps"] for p in points]
        minutes = [p["training_wall_s"] / 60 for p in points]
        success = [p["success_rate"] for p in points]
        style = dict(color=f"C{k}", lw=1.0, alpha=0.8 if len(runs) > 1 else 1.0, marker=".")
        axes[0].plot(steps, success, label=f"PPO {run['name']} (validation seeds)", **style)
        axes[1].plot(minutes, success, **style)
    lengths = {len(run.get("validation", [])) for run in runs}
    if len(runs) > 1 and len(lengths) == 1 and lengths != {0}:
        table = np.array([[p["success_rate"] for p in run["validation"]] for run in runs])
        steps = np.array([[p["steps"] for p in run["validation"]] for run in runs]).mean(axis=0)
        minutes = np.array([[p["training_wall_s"] / 60 for p in run["validation"]] for run in runs]).mean(axis=0)
        for ax, x in zip(axes, (steps, minutes), strict=True):
            ax.plot(x, table.mean(axis=0), color="k", lw=2.2, label=f"mean of {len(runs)} runs")
            ax.fill_between(x, table.min(axis=0), table.max(axis=0), color="0.6", alpha=0.25,
                            label="spread (min–max)")
    for name, style in (("reactive", ":"), ("ramp", "--")):
        rates = [run["evaluation"][name]["success_rate"] for run in runs if name in run["evaluation"]]
        if rates:
            for ax in axes:
                ax.axhline(np.mean(rates), ls=style, color="0.25", lw=1.4, label=f"{name} controller (held-out)")
    for k, (label, result) in enumerate((baselines or {}).items()):
        for ax in axes:
            colour = BASELINE_COLOURS[k % len(BASELINE_COLOURS)]
            ax.axhline(result["success_rate"], ls=(0, (5, 1 + 2 * k)), color=colour, lw=1.8,
                       label=f"{label} ({result['episodes']} seeds from {result['first_seed']:,})")
    finals = [run["evaluation"]["ppo"]["success_rate"] for run in runs if "ppo" in run["evaluation"]]
    if finals:
        for ax in axes:
            ax.axhline(np.mean(finals), ls="-.", color="C3", lw=1.4,
                       label=f"PPO final (held-out{', mean' if len(finals) > 1 else ''})")
    axes[0].set_xlabel("environment steps")
    axes[1].set_xlabel("training wall time [min] (validations left out)")
    axes[0].set_ylabel("success rate (deterministic policy)")
    lowest = min([np.min(line.get_ydata()) for ax in axes for line in ax.get_lines() if len(line.get_ydata())],
                 default=0.0)
    for ax in axes:  # the whole range, unless every line is high: then from a little below the lowest
        ax.set_ylim(-0.02 if lowest < 0.5 else np.floor(10 * lowest - 0.5) / 10, 1.02)
        ax.grid(True, alpha=0.3)
    if axes[0].get_legend_handles_labels()[0]:
        axes[0].legend(fontsize=7, loc="lower right")
    else:  # --validate-every 0 and --eval-episodes 0: say why the panels are empty
        for ax in axes:
            ax.text(0.5, 0.5, "no validations or held-out evaluations in these runs", ha="center",
                    transform=ax.transAxes)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("runs", nargs="+", type=Path, help="train_ppo output folders")
    parser.add_argument("--out", type=Path, required=True, help="the figure (PNG)")
    parser.add_argument("--baseline", action="append", default=[], metavar="LABEL=FILE",
                        help="a controller's agents.evaluate --json result, drawn as a line (repeatable)")
    args = parser.parse_args(argv)
    baselines = {}
    for item in args.baseline:
        label, _, file = item.partition("=")
        if not label or not file:
            parser.error(f"--baseline {item!r} is not LABEL=FILE")
        try:
            result = json.loads(Path(file).read_text())
        except (OSError, ValueError) as error:
            parser.error(f"--baseline {item!r}: cannot read {file}: {error}")
        if not {"success_rate", "episodes", "first_seed"} <= set(result):
            parser.error(f"--baseline {item!r}: {file} is not an agents.evaluate --json result")
        baselines[label] = result
    try:
        runs = [load_run(run) for run in args.runs]
    except FileNotFoundError as error:
        parser.error(str(error))
    plot_learning_curves(runs, args.out, baselines)


if __name__ == "__main__":
    main()
