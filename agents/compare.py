"""Paired tests between policies evaluated on the same seeds: is one more successful, is it gentler?

    python -m agents.compare BASELINE.json POLICY.json [POLICY.json ...] [--json FILE] [--plot FILE]

Each file is what ``agents.evaluate --json`` wrote. Every policy is compared with the baseline specimen by
specimen (the seeds must be the same): success by McNemar's exact test (the specimens only one of the two grasped
decide it), peak finger force by a paired t-test, and the endings side by side. With several policies (training
seeds of one setting, say), a pooled line compares each specimen's mean over them with the baseline (paired t on
success and on force), the test a claim about the setting rather than one run needs. Where the evaluations recorded
each specimen's radius, a second table gives every policy's success in four equal bands of it, where the task is
hard, and ``--plot`` draws it.
"""

from __future__ import annotations

import argparse
import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
from scipy import stats

from agents.evaluate import ENDINGS


def mcnemar_exact(wins: int, losses: int) -> float:
    """Two-sided p-value of McNemar's exact test: ``wins`` specimens only the policy grasped, ``losses`` only the
    baseline; under the null each discordant specimen is a fair coin."""
    if wins < 0 or losses < 0:
        raise ValueError(f"mcnemar_exact: wins = {wins} and losses = {losses} must be counts (≥ 0)")
    discordant = wins + losses
    if discordant == 0:
        return 1.0
    tail = sum(math.comb(discordant, k) for k in range(min(wins, losses) + 1)) / 2.0 ** discordant
    return min(1.0, 2.0 * tail)


def paired_t(differences: np.ndarray) -> tuple[float, float]:
    """Student's paired t statistic of ``differences`` and its two-sided p-value; (0, 1) when all are equal."""
    differences = np.asarray(differences, dtype=float)
    if differences.size < 2:
        raise ValueError(f"paired_t: needs at least 2 differences, got {differences.size}")
    spread = differences.std(ddof=1)
    if spread == 0.0:
        return (0.0, 1.0) if differences.mean() == 0.0 else (math.copysign(math.inf, differences.mean()), 0.0)
    t = differences.mean() / (spread / math.sqrt(differences.size))
    return float(t), float(2.0 * stats.t.sf(abs(t), differences.size - 1))


def _seeds(result: dict) -> range:
    return range(result["first_seed"], result["first_seed"] + result["episodes"])


def check_paired(baseline: dict, other: dict, name: str) -> None:
    """Refuses a pair of evaluations that did not run the same specimens (same seeds and rod model)."""
    if _seeds(baseline) != _seeds(other):
        raise ValueError(f"{name}: seeds {_seeds(other).start}–{_seeds(other).stop - 1} are not the baseline's "
                         f"{_seeds(baseline).start}–{_seeds(baseline).stop - 1}; a paired test needs the same ones")
    if baseline.get("model") != other.get("model"):
        raise ValueError(f"{name}: model {other.get('model')!r} is not the baseline's {baseline.get('model')!r}")


def compare(baseline: dict, policy: dict) -> dict:
    """One policy against the baseline on the same specimens: success rates, McNemar's wins, losses and p, the mean
    peak force difference [N] with its paired t and p, and both policies' endings."""
    check_paired(baseline, policy, policy.get("policy", "policy"))
    ours, theirs = np.array(policy["successes"], bool), np.array(baseline["successes"], bool)
    wins, losses = int(np.sum(ours & ~theirs)), int(np.sum(~ours & theirs))
    force = np.array(policy["peak_contact_forces_N"]) - np.array(baseline["peak_contact_forces_N"])
    t, p = paired_t(force)
    return {"policy": policy.get("policy"), "success_rate": float(ours.mean()),
            "baseline_success_rate": float(theirs.mean()), "wins": wins, "losses": losses,
            "mcnemar_p": mcnemar_exact(wins, losses),
            "mean_peak_force_N": float(np.mean(policy["peak_contact_forces_N"])),
            "baseline_mean_peak_force_N": float(np.mean(baseline["peak_contact_forces_N"])),
            "force_difference_N": float(force.mean()), "force_t": t, "force_p": p,
            "endings": {name: policy["episode_endings"].count(name) for name in ENDINGS},
            "baseline_endings": {name: baseline["episode_endings"].count(name) for name in ENDINGS}}


RADIUS_BANDS = 4
"""How many equal bands of the specimens' radius :func:`by_radius` splits them into."""


def by_radius(baseline: dict, policies: list[dict]) -> dict | None:
    """Success of the baseline and of each policy in :data:`RADIUS_BANDS` equal bands of the specimens' radius
    (from the smallest to the largest the baseline met), or None where an evaluation did not record the radii
    (``object_radii_m``, written by agents.evaluate since it records them). Refuses evaluations whose specimens'
    radii differ, which paired seeds cannot give."""
    if any("object_radii_m" not in result for result in (baseline, *policies)):
        return None
    radii = np.array(baseline["object_radii_m"], float)
    for policy in policies:
        if not np.allclose(policy["object_radii_m"], radii, rtol=0.0, atol=1e-6):
            raise ValueError(f"{policy.get('policy', 'policy')}: its specimens' radii are not the baseline's")
    edges = np.linspace(radii.min(), radii.max(), RADIUS_BANDS + 1)
    band = np.clip(np.searchsorted(edges, radii, side="right") - 1, 0, RADIUS_BANDS - 1)
    counts = np.bincount(band, minlength=RADIUS_BANDS)

    def successes(result: dict) -> list[int]:
        return np.bincount(band, weights=np.array(result["successes"], float), minlength=RADIUS_BANDS).astype(
            int).tolist()

    def rates(band_successes: list[int]) -> list[float | None]:
        return [won / count if count else None for won, count in zip(band_successes, counts.tolist(), strict=True)]

    columns: dict[str, list[int]] = {}
    seen: Counter[str] = Counter()
    for policy in policies:  # one column each, even for two evaluations of one policy
        name = str(policy.get("policy"))
        seen[name] += 1
        columns[name if seen[name] == 1 else f"{name} ({seen[name]})"] = successes(policy)
    baseline_won = successes(baseline)
    return {"edges_m": edges.tolist(), "specimens": counts.tolist(), "baseline": rates(baseline_won),
            "policies": {name: rates(won) for name, won in columns.items()},
            "baseline_successes": baseline_won, "policy_successes": columns}


def radius_table(baseline_name: str, bands: dict) -> str:
    """A markdown table of :func:`by_radius`'s bands: one row per band, one column per policy."""
    names = [baseline_name, *bands["policies"]]
    lines = ["success by specimen radius", "| radius [cm] | specimens | " + " | ".join(names) + " |",
             "|---|---|" + "---|" * len(names)]
    edges = bands["edges_m"]
    for k, count in enumerate(bands["specimens"]):
        values = [bands["baseline"][k], *(rates[k] for rates in bands["policies"].values())]
        cells = " | ".join("—" if value is None else f"{value:.2f}" for value in values)
        lines.append(f"| {100 * edges[k]:.2f}–{100 * edges[k + 1]:.2f} | {count} | {cells} |")
    return "\n".join(lines)


def plot_by_radius(baseline_name: str, bands: dict, path: Path) -> None:
    """:func:`by_radius`'s bands as a figure: each policy's success in each band of radius, with a 95 % Wilson
    interval, the baseline first; the number of specimens under each band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    edges = 100 * np.array(bands["edges_m"])
    centres, width = (edges[:-1] + edges[1:]) / 2, np.diff(edges)
    counts = np.array(bands["specimens"])
    series = {baseline_name: bands["baseline_successes"], **bands["policy_successes"]}
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    step = 0.8 * width / len(series)
    have = counts > 0
    for k, (name, won) in enumerate(series.items()):
        x = centres - 0.4 * width + (k + 0.5) * step
        rate = np.where(have, np.array(won, float) / np.maximum(counts, 1), np.nan)
        low, high = np.array([wilson_interval(w, n) if n else (np.nan, np.nan)
                              for w, n in zip(won, counts, strict=True)]).T
        ax.bar(x[have], rate[have], step[have], color=f"C{k}", alpha=0.85, label=name)
        ax.errorbar(x[have], rate[have], yerr=[(rate - low)[have], (high - rate)[have]], fmt="none", ecolor="0.2",
                    capsize=2, lw=0.8)
    ax.set_xticks(centres)
    ax.set_xticklabels([f"{low:.2f}–{high:.2f}\n{count} specimens"
                        for low, high, count in zip(edges[:-1], edges[1:], counts, strict=True)])
    ax.set_xlabel("specimen radius [cm]")
    ax.set_ylabel("success rate (95 % interval)")
    ax.set_ylim(0, 1.15)
    ax.set_yticks(np.linspace(0, 1, 6))
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", ncol=len(series))
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval of a success rate, ``successes`` of ``n`` (95 % by default)."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"wilson_interval: successes = {successes} of n = {n} must satisfy 0 <= successes <= n, "
                         f"n >= 1")
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return min(max(0.0, centre - half), p), max(min(1.0, centre + half), p)  # rounding cannot leave p outside


def _spread(values: list[float]) -> float:
    """Sample standard deviation, 0 for a single value."""
    return float(np.std(values, ddof=1)) if len(values) > 1 else 0.0


def pooled(baseline: dict, policies: list[dict]) -> dict:
    """Each specimen's mean over the policies against the baseline: success and peak-force differences with
    their paired t and p, and the policies' success rates' mean and sample standard deviation."""
    for policy in policies:
        check_paired(baseline, policy, policy.get("policy", "policy"))
    success = np.mean([policy["successes"] for policy in policies], axis=0) - np.array(baseline["successes"], float)
    force = (np.mean([policy["peak_contact_forces_N"] for policy in policies], axis=0)
             - np.array(baseline["peak_contact_forces_N"]))
    rates = [float(np.mean(policy["successes"])) for policy in policies]
    forces = [float(np.mean(policy["peak_contact_forces_N"])) for policy in policies]
    success_t, success_p = paired_t(success)
    force_t, force_p = paired_t(force)
    return {"policies": len(policies), "success_rate_mean": float(np.mean(rates)), "success_rate_sd": _spread(rates),
            "mean_peak_force_N_mean": float(np.mean(forces)), "mean_peak_force_N_sd": _spread(forces),
            "success_difference": float(success.mean()), "success_t": success_t, "success_p": success_p,
            "force_difference_N": float(force.mean()), "force_t": force_t, "force_p": force_p}


def table(baseline_name: str, rows: list[dict], pool: dict | None) -> str:
    """A markdown table of :func:`compare`'s rows (and the pooled line)."""
    lines = [f"against {baseline_name} (success {rows[0]['baseline_success_rate']:.3f}, peak "
             f"{rows[0]['baseline_mean_peak_force_N']:.2f} N)",
             "| policy | success | peak [N] | McNemar p (wins vs losses) | Δforce [N], t | harmed | lost | "
             "not held through gust |", "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['policy']} | {row['success_rate']:.3f} | {row['mean_peak_force_N']:.2f} | "
                     f"{row['mcnemar_p']:.3g} ({row['wins']} vs {row['losses']}) | "
                     f"{row['force_difference_N']:+.2f}, {row['force_t']:.1f} | {row['endings']['harmed']} | "
                     f"{row['endings']['lost']} | {row['endings']['not_held_through_gust']} |")
    lines.append(f"| ({baseline_name}) | {rows[0]['baseline_success_rate']:.3f} | "
                 f"{rows[0]['baseline_mean_peak_force_N']:.2f} | | | {rows[0]['baseline_endings']['harmed']} | "
                 f"{rows[0]['baseline_endings']['lost']} | {rows[0]['baseline_endings']['not_held_through_gust']} |")
    if pool is not None:
        lines.append(f"pooled over {pool['policies']} policies: success {pool['success_rate_mean']:.3f} ± "
                     f"{pool['success_rate_sd']:.3f}, peak {pool['mean_peak_force_N_mean']:.2f} ± "
                     f"{pool['mean_peak_force_N_sd']:.2f} N; per specimen against the baseline: success "
                     f"{pool['success_difference']:+.3f} (paired t {pool['success_t']:.2f}, p "
                     f"{pool['success_p']:.3g}), force {pool['force_difference_N']:+.3f} N (t {pool['force_t']:.2f},"
                     f" p {pool['force_p']:.3g})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("baseline", type=Path, help="agents.evaluate --json of the baseline")
    parser.add_argument("policies", type=Path, nargs="+", help="agents.evaluate --json of each policy")
    parser.add_argument("--json", type=Path, help="write the comparison here")
    parser.add_argument("--plot", type=Path, help="draw the success by specimen radius here (PNG; needs evaluations "
                                                  "that recorded the radii)")
    args = parser.parse_args(argv)
    results = {}
    for path in (args.baseline, *args.policies):
        if not path.is_file():
            parser.error(f"{path} is not a file (give what agents.evaluate --json wrote)")
        results[path] = json.loads(path.read_text())
        results[path].setdefault("policy", path.stem)
    baseline = results[args.baseline]
    policies = [results[path] for path in args.policies]
    try:
        rows = [compare(baseline, policy) for policy in policies]
        pool = pooled(baseline, policies) if len(policies) > 1 else None
        bands = by_radius(baseline, policies)
    except ValueError as error:
        parser.error(str(error))
    if args.plot and bands is None:
        parser.error("--plot draws the success by specimen radius, which these evaluations did not record (run "
                     "agents.evaluate again)")
    print(table(str(baseline["policy"]), rows, pool))
    if bands is not None:
        print(radius_table(str(baseline["policy"]), bands))
        if args.plot:
            plot_by_radius(str(baseline["policy"]), bands, args.plot)
    summary = {"baseline": str(args.baseline), "comparisons": rows, "pooled": pool, "by_radius": bands}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(summary, indent=2))
        print(f"wrote {args.json}")
    return summary


if __name__ == "__main__":
    main()
