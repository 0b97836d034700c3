"""Success against force: where policies lie on the two goals that pull against each other, succeeding and pressing
gently. Each point is one ``agents.evaluate --json`` result (its success rate and mean peak finger force); a group
(a training setting's seeds, or a controller) is drawn as its runs and their mean ± sample sd, one panel per rod
model and seed set (two to a row). With ``--reference``, the region that beats that group on both counts and reaches
``--success-goal`` is shaded: the issue's goal for the policy.

    python -m agents.success_force --group "weight 4" s0.json s1.json s2.json --group reactive r.json \\
        --reference reactive --out FIGURE.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

REQUIRED_KEYS = ("success_rate", "mean_peak_contact_force_N", "model", "first_seed", "episodes")


def load_evaluation(path: Path) -> dict:
    """One ``agents.evaluate --json`` result, checked for the keys this figure reads."""
    result = json.loads(Path(path).read_text())
    missing = [key for key in REQUIRED_KEYS if key not in result]
    if missing:
        raise ValueError(f"{path} lacks {', '.join(missing)}: it is not an agents.evaluate --json result")
    return result


def panel_of(result: dict) -> str:
    """The panel a result belongs in: its rod model and seed set."""
    last = result["first_seed"] + result["episodes"] - 1
    return f"{result['model']}, seeds {result['first_seed']:,}–{last:,}"


def summarize(groups: dict[str, list[dict]]) -> dict[str, dict[str, dict]]:
    """Per panel and group: the runs' success rates and mean peak forces [N], their means and sample sds (0 for
    one run) and the run count."""
    table: dict[str, dict[str, dict]] = {}
    for name, results in groups.items():
        for result in results:
            entry = table.setdefault(panel_of(result), {}).setdefault(name, {"success": [], "force_N": []})
            entry["success"].append(float(result["success_rate"]))
            entry["force_N"].append(float(result["mean_peak_contact_force_N"]))
    for entries in table.values():
        for entry in entries.values():
            for key in ("success", "force_N"):
                values = np.array(entry[key])
                entry[f"{key}_mean"] = float(values.mean())
                entry[f"{key}_sd"] = float(values.std(ddof=1)) if values.size > 1 else 0.0
            entry["runs"] = len(entry["success"])
    return table


def plot_success_force(groups: dict[str, list[dict]], path: Path, reference: str | None = None,
                       success_goal: float = 0.9) -> dict[str, dict[str, dict]]:
    """Draws :func:`summarize`'s table, one panel per rod model and seed set, and returns it. ``reference`` names
    the group whose success and force a goal must beat; its region (success ≥ ``success_goal`` and above the
    reference's, force below it) is shaded in each panel where the reference was measured."""
    if reference is not None and reference not in groups:
        raise ValueError(f"reference = {reference!r} is not one of the groups: {', '.join(groups)}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    table = summarize(groups)
    panels = list(table)  # in the order the groups' results name them
    columns = min(2, len(panels))
    rows = -(-len(panels) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(6.0 * columns, 4.6 * rows), squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    colors = {name: f"C{k}" for k, name in enumerate(groups)}
    runs = {name: max(entries[name]["runs"] for entries in table.values() if name in entries) for name in groups}
    labels = {name: f"{name} ({count} run{'s' if count > 1 else ''})" for name, count in runs.items()}
    for ax, panel in zip(axes.flat, panels, strict=False):  # the grid may hold a spare panel
        entries = table[panel]
        forces = [f for entry in entries.values() for f in entry["force_N"]]
        low, high = min(forces) - 0.15, max(forces) + 0.15
        if reference in entries:
            ref = entries[reference]
            ax.fill_between([low, ref["force_N_mean"]], max(success_goal, ref["success_mean"]), 1.0, color="C2",
                            alpha=0.12, label=f"goal: ≥ {success_goal:.0%}, above and gentler than {reference}")
        for name, entry in entries.items():
            color = colors[name]
            ax.scatter(entry["force_N"], entry["success"], s=18, color=color, alpha=0.55)
            ax.errorbar(entry["force_N_mean"], entry["success_mean"], xerr=entry["force_N_sd"],
                        yerr=entry["success_sd"], fmt="o", ms=8, color=color, capsize=3,
                        label=labels[name])  # one legend entry per group, whatever a panel holds
        ax.axhline(success_goal, color="0.4", lw=0.8, ls=":")
        ax.set_xlim(low, high)
        ax.set_title(panel, fontsize=10)
        ax.set_xlabel("mean peak finger force [N] (lower is gentler)")
        ax.set_ylabel("success rate")
        ax.grid(True, alpha=0.3)
    handles = {label: handle for ax in axes.flat for handle, label in zip(*ax.get_legend_handles_labels(), strict=True)}
    legend_columns = min(3, len(handles))
    legend_rows = -(-len(handles) // legend_columns)
    fig.legend(handles.values(), handles.keys(), loc="lower center", ncol=legend_columns, fontsize=8)
    fig.tight_layout(rect=(0, 0.02 + 0.03 * legend_rows, 1, 1))  # the axes end above the legend's rows
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")
    return table


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--group", nargs="+", action="append", required=True, metavar=("NAME", "JSON"),
                        help="a group's name, then its agents.evaluate --json results (repeat per group)")
    parser.add_argument("--reference", help="the group a goal must beat (e.g. reactive)")
    parser.add_argument("--success-goal", type=float, default=0.9, help="the success a goal needs (default 0.9)")
    parser.add_argument("--out", type=Path, required=True, help="the figure (PNG)")
    args = parser.parse_args(argv)
    if not 0.0 <= args.success_goal <= 1.0:
        parser.error(f"--success-goal = {args.success_goal!r} is outside the allowed range [0, 1]")
    groups: dict[str, list[dict]] = {}
    for name, *files in args.group:
        if not files:
            parser.error(f"--group {name!r} names no agents.evaluate --json file")
        if name in groups:
            parser.error(f"--group {name!r} is given twice")
        try:
            groups[name] = [load_evaluation(Path(file)) for file in files]
        except (OSError, ValueError) as error:
            parser.error(str(error))
    try:
        return plot_success_force(groups, args.out, args.reference, args.success_goal)
    except ValueError as error:
        parser.error(str(error))


if __name__ == "__main__":
    main()
