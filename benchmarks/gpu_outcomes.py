"""The GPU back end's grasp outcomes against the CPU path's, on the same seeds: whether ``device="cuda"`` grasps as
the CPU does.

    python -m benchmarks.gpu_outcomes --part cpu [--models 3d,planar] [--episodes 1000] [--seed 4000000]
        [--workers 2] [--stop-after MINUTES] [--runs out/gpu_outcomes_runs]
    python -m benchmarks.gpu_outcomes --part cuda [the same options] [--json out/gpu_outcomes.json]
        [--plot out/gpu_outcomes.png]

Per model, at its default Δt, with the reactive controller, on ``--episodes`` seeds from ``--seed`` (4,000,000 by
default; no controller was tuned on them):

- ``--part cpu`` runs the CPU path twice, as it is and with Newton's relative tolerance 1e-6 instead of the task's
  1e-4. How often those two agree on an episode's success label, seed by seed, is the floor: what rounding and
  tolerance alone move, and so the agreement the GPU cannot be asked to beat. It runs in pieces kept in ``--runs``
  (see :mod:`benchmarks.outcome_convergence`), so it can run on another machine than the GPU's, and resumes.
- ``--part cuda`` runs the same seeds with ``device="cuda"``, every episode of a model at once, and writes the
  summary from the kept CPU pieces: success rates with their 95 % intervals, the GPU's per-seed agreement with the
  CPU against the floor, and the tests of :func:`benchmarks.outcome_convergence.converged` (success rate, endings,
  peak-force and final-distance distributions, labels within 2 points of the floor). In Numba's CUDA simulator
  (``NUMBA_ENABLE_CUDASIM=1``) it runs without a GPU, slowly, for tests.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ._timing import save_plot
from .outcome_convergence import (
    FLOOR_MARGIN,
    Piece,
    add_study_options,
    agreement,
    code_fingerprint,
    conditions,
    converged,
    describe,
    kept_results,
    run_study,
    seed_ranges,
    study_models,
    success_text,
)

CONTROLLER = "reactive"
FIRST_SEED = 4_000_000
"""The first seed: apart from the seeds that tuned a controller, the evaluation's held-out sets (1,000,000 and
2,000,000 onwards) and the Δt study's (3,000,000)."""


def default_dt(model: str) -> float:
    """The model's default physics step [s]."""
    from soft_gripper_env.grasp_task import GraspTask

    return GraspTask(model=model).physics_dt


def plan(models: list[str], episodes: int, seed: int, part: str) -> list[Piece]:
    """The pieces of one part: on the CPU, each model's run and its tolerance-1e-6 twin in pieces; on the GPU, each
    model's run as one piece."""
    if part == "cpu":
        return [Piece(model, CONTROLLER, default_dt(model), variant, first, count)
                for model in models for variant in ("base", "tolerance 1e-6")
                for first, count in seed_ranges(seed, episodes)]
    return [Piece(model, CONTROLLER, default_dt(model), "base", seed, episodes, "cuda") for model in models]


def summarize(joined: dict, models: list[str], episodes: int, seed: int) -> dict:
    """Per model: the CPU's run, its tolerance twin and the GPU's described, the floor, and the GPU against the CPU
    (:func:`~benchmarks.outcome_convergence.converged`). Prints the table."""
    summary = {"episodes": episodes, "first_seed": seed, "controller": CONTROLLER, "floor_margin": FLOOR_MARGIN,
               "models": {}}
    print("\n| model | Δt [ms] | success, CPU | success, CPU at tolerance 1e-6 | success, GPU | labels agree, GPU "
          "and CPU | floor: CPU and CPU at 1e-6 | median gap GPU–CPU [mm] | success p | endings p | peak-force KS p |"
          " same outcomes |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    for model in models:
        dt = default_dt(model)
        cpu, twin, gpu = (joined.get((model, CONTROLLER, dt, variant, device))
                          for variant, device in (("base", "cpu"), ("tolerance 1e-6", "cpu"), ("base", "cuda")))
        if cpu is None or twin is None or gpu is None:
            print(f"| {model} | {1e3 * dt:g} | runs missing: call --part cpu, then --part cuda |")
            continue
        floor = agreement(cpu, twin)
        test = converged(gpu, cpu, floor["label_agreement"])
        row = {"physics_dt_s": dt, "cpu": describe(cpu), "cpu_tolerance_1e-6": describe(twin), "gpu": describe(gpu),
               "floor": floor, "gpu_against_cpu": test}
        summary["models"][model] = row
        print(f"| {model} | {1e3 * dt:g} | {success_text(row['cpu'])} | {success_text(row['cpu_tolerance_1e-6'])} | "
              f"{success_text(row['gpu'])} | {test['label_agreement']:.3f} | {floor['label_agreement']:.3f} | "
              f"{1e3 * test['median_position_gap_m']:.2f} | {test['success_p']:.2f} | {test['endings_p']:.2f} | "
              f"{test['peak_force_ks_p']:.2f} | {'yes' if test['passes'] else 'no'} |")
    return summary


def plot(summary: dict, path: Path) -> None:
    """Per model: the three runs' success rates with their intervals, and the GPU's label agreement with the CPU
    beside the floor."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = list(summary["models"])
    fig, (success, agree) = plt.subplots(1, 2, figsize=(11, 4))
    runs = (("cpu", "CPU", "tab:blue"), ("cpu_tolerance_1e-6", "CPU, tolerance 1e-6", "tab:gray"),
            ("gpu", "GPU", "tab:green"))
    for k, (key, label, colour) in enumerate(runs):
        x = np.arange(len(models)) + (k - 1) * 0.2
        rate = np.array([summary["models"][m][key]["success_rate"] for m in models])
        interval = np.array([summary["models"][m][key]["success_interval_95"] for m in models])
        success.errorbar(x, rate, yerr=[rate - interval[:, 0], interval[:, 1] - rate], fmt="o", capsize=4,
                         color=colour, label=label)
    x = np.arange(len(models))
    agree.bar(x - 0.2, [summary["models"][m]["gpu_against_cpu"]["label_agreement"] for m in models], 0.4,
              color="tab:green", label="GPU against CPU")
    agree.bar(x + 0.2, [summary["models"][m]["floor"]["label_agreement"] for m in models], 0.4, color="tab:gray",
              label="floor: CPU against CPU at tolerance 1e-6")
    for axis in (success, agree):
        axis.set_xticks(x, models)
        axis.grid(True, axis="y", alpha=0.3)
        axis.legend(fontsize=8)
    success.set(ylabel="success rate (95 % interval)", title="success, reactive controller")
    agree.set(ylabel="share of seeds with the same label", ylim=(0.5, 1.01), title="per-seed labels")
    fig.suptitle(f"GPU against CPU, {summary['episodes']} seeds from {summary['first_seed']}")
    save_plot(fig, path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--part", choices=("cpu", "cuda"), required=True,
                        help="cpu: the CPU's runs and the floor, in pieces; cuda: the GPU's runs and the summary")
    add_study_options(parser, "gpu_outcomes", 1000, FIRST_SEED)
    args = parser.parse_args(argv)
    models = study_models(parser, args)
    cpu_pieces = plan(models, args.episodes, args.seed, "cpu")
    if args.part == "cpu":
        results = run_study(cpu_pieces, args.runs, args.workers, 60 * args.stop_after)
        print(f"{len(results)} of {len(cpu_pieces)} CPU pieces are there; then: --part cuda on a GPU")
        return {"complete": len(results) == len(cpu_pieces)}
    kept = kept_results(cpu_pieces, args.runs, code_fingerprint())
    if len(kept) < len(cpu_pieces):
        parser.error(f"{len(cpu_pieces) - len(kept)} of the CPU's {len(cpu_pieces)} pieces are not in {args.runs} "
                     "(or ran other code): run --part cpu first, with the same options, and bring its --runs folder")
    gpu_pieces = plan(models, args.episodes, args.seed, "cuda")
    results = {**kept, **run_study(gpu_pieces, args.runs, 0)}
    summary = summarize(conditions(results, cpu_pieces + gpu_pieces), models, args.episodes, args.seed)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.json}")
    if summary["models"]:
        plot(summary, args.plot)
    return summary


if __name__ == "__main__":
    main()
