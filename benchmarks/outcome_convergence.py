"""Grasp outcomes against the physics step Δt: whether each rod model's outcomes have converged, against the chaos
floor that no step size removes.

    python -m benchmarks.outcome_convergence [--models 3d,planar]
        [--controllers reactive,ramp,pretrained[,reactive_graded,pretrained_planar]] [--dts 3d=0.01,...;planar=...]
        [--tolerance-floor] [--episodes 400] [--seed 3000000] [--workers 2] [--stop-after MINUTES]
        [--runs out/outcome_convergence_runs] [--json out/outcome_convergence.json]
        [--plot out/outcome_convergence.png] [--time]

For each model, controller and Δt (halved from 10 ms: :data:`DEFAULT_DTS`) it runs the env's own task on
``--episodes`` seeds from ``--seed`` (3,000,000 by default: seeds no controller or policy was tuned or trained on),
all other settings at the model's defaults. Each condition runs twice: as it is, and with the sphere's start moved by
:data:`PERTURBATION_M` (1 nm along x, ``GraspTask.start_point``), a change far below any physical scale. How often
the two runs' success labels agree is the **chaos floor** at that Δt: the agreement no step size can beat.
``--tolerance-floor`` also runs the finest Δt with Newton's relative tolerance 1e-6 instead of the task's 1e-4: every
Δt runs at 1e-4, so two runs cannot be asked to agree more often than the tolerance alone lets them. A verdict
compares two runs, a Δt's and the finest Δt's, and neither can be asked to agree with the other more often than with
its own twin, so the floor a verdict uses is the lowest of the floors measured at the finest Δt and the floor at the
Δt judged.

Per condition the study reports the success rate with its 95 % (Wilson) interval, the endings, and the peak-force
and final-position distributions; against the finest Δt, seed by seed, how often the success labels agree and how far
apart the sphere ends (median and 90th percentile); and the tests of :func:`converged`, which say whether a Δt's
outcomes are those of the finest Δt within sampling error.

**In pieces.** The episodes run in pieces of :data:`PIECE` seeds, ``--workers`` processes at a time, each kept in
``--runs`` as it finishes (with the task it ran and a fingerprint of the code that ran it). A later call takes every
kept piece whose task and code are today's, so an interrupted study resumes where it stopped, and ``--stop-after``
ends a call after so many minutes (pieces under way finish). The summary is written from the conditions whose
pieces are all there; where the finest Δt is not there yet, the finest one that is stands in as the reference, and
the JSON says so (``reference_dt_s``). ``--time`` also times one env per model and Δt under the reactive controller
against Gymnasium's ``Ant-v5`` in the same run, for the cost side of each Δt.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from agents.compare import wilson_interval

from ._timing import save_plot

MODELS = ("3d", "planar")
CONTROLLERS = ("reactive", "ramp", "pretrained", "reactive_graded", "pretrained_planar")
"""The controllers a study may run (``agents.evaluate``'s names); the first three by default."""
DEFAULT_CONTROLLERS = CONTROLLERS[:3]
DEFAULT_DTS = {"3d": (0.01, 0.005, 0.0025, 0.00125, 0.000625, 0.0003125),
               "planar": (0.01, 0.005, 0.0025, 0.00125, 0.000625, 0.0003125)}
"""Each model's physics steps [s], halved from 10 ms down to the finest, which is the reference."""
FIRST_SEED = 3_000_000
"""The study's first seed: above every range that tuned or trained a controller, and apart from the evaluation's
held-out sets (1,000,000 and 2,000,000 onwards)."""
PERTURBATION_M = 1e-9
"""How far the perturbed run moves the sphere's start [m], along x: far below any physical scale of the task (the
fingers' radius is millimetres, Newton's tolerance moves nodes by more)."""
CHANGES = {"perturbed": "the sphere's start moved by PERTURBATION_M along x",
           "tolerance 1e-6": "Newton's relative tolerance 1e-6 instead of the task's 1e-4",
           "friction settled": "the corrector settles friction within its whole budget (friction_passes None)"}
"""What a run can change from the model's defaults (other than Δt), by name. A run's variant is "base" (none of
them) or the names of its changes joined by ", ": a chaos floor compares a variant with itself changed by one of
:data:`FLOOR_CHANGES`."""
FLOOR_CHANGES = {"perturbed": "start_moved_1nm", "tolerance 1e-6": "newton_tolerance_1e-6"}
"""The changes far below any physical scale whose twin runs measure a chaos floor, and each floor's key in the
summary: the sphere's start moved (at every Δt) and Newton's tolerance tightened (at the finest Δt)."""
PIECE = 80
"""Seeds per piece: five batches of the evaluation's 16 envs, about a minute of one core in 3-D at 2.5 ms."""
SIGNIFICANCE = 0.05
"""A test passes where its p-value is above this."""
FLOOR_MARGIN = 0.02
"""A Δt's label agreement with the finest Δt may fall this far (2 points) below the chaos floor."""
CODE = ("soft_gripper_env", "agents/scripted.py", "agents/evaluate.py", "agents/pretrained", "agents/pretrained_planar")
"""What a piece's outcomes depend on, fingerprinted (:func:`code_fingerprint`): a kept piece is taken only if none
of it has changed since. The GPU back end's own module is left out: the study runs on the CPU, which never runs
it."""
NOT_RUN = ("soft_gripper_env/physics/solvers/gpu.py",)
ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Piece:
    """Episodes on seeds ``first_seed`` … ``first_seed + episodes − 1`` of one condition: a model, a controller, a
    physics step [s], a variant (:data:`CHANGES`), and the device the physics runs on ("cpu" or "cuda")."""

    model: str
    controller: str
    dt: float
    variant: str
    first_seed: int
    episodes: int
    device: str = "cpu"

    @property
    def condition(self) -> tuple[str, str, float, str, str]:
        return self.model, self.controller, self.dt, self.variant, self.device

    def file_name(self) -> str:
        device = "" if self.device == "cpu" else f"_{self.device}"
        variant = self.variant.replace(", ", "+").replace(" ", "_")
        seeds = f"{self.first_seed}_{self.episodes}"
        return f"{self.model}_{self.controller}_dt{self.dt:.7f}_{variant}_{seeds}{device}.json"


def changes_of(variant: str) -> list[str]:
    """A variant's changes (:data:`CHANGES`), or a ValueError naming the one that is not a change."""
    changes = [] if variant == "base" else [change.strip() for change in variant.split(",")]
    for change in changes:
        if change not in CHANGES:
            raise ValueError(f"variant {variant!r}: {change!r} is not one of {', '.join(CHANGES)}")
    return changes


def with_change(variant: str, change: str) -> str:
    """``variant`` with ``change`` added."""
    return change if variant == "base" else f"{variant}, {change}"


def code_fingerprint() -> str:
    """A SHA-256 of the source (and the shipped policy) that decide an episode's outcome (:data:`CODE`)."""
    digest = hashlib.sha256()
    for entry in CODE:
        path = ROOT / entry
        files = sorted(p for p in path.rglob("*") if p.is_file() and p.suffix in (".py", ".zip", ".pkl", ".json")) \
            if path.is_dir() else [path]
        for file in files:
            if str(file.relative_to(ROOT)) in NOT_RUN:
                continue
            digest.update(str(file.relative_to(ROOT)).encode())
            digest.update(file.read_bytes())
    return digest.hexdigest()[:16]


def task_settings(piece: Piece) -> dict:
    """The :class:`~soft_gripper_env.grasp_task.GraspTask` fields a piece runs with: the model's defaults but for
    Δt and the changes of the piece's variant (:data:`CHANGES`), and a trained policy's own observation and closing
    reflexes (its config.json)."""
    from dataclasses import replace

    from agents.evaluate import REFLEXES, SHIPPED, trained_task
    from soft_gripper_env.grasp_task import GraspTask

    changes = changes_of(piece.variant)
    settings = {"model": piece.model, "physics_dt": piece.dt}
    if "perturbed" in changes:
        x, y, z = GraspTask.start_point
        settings["start_point"] = (x + PERTURBATION_M, y, z)
    if "tolerance 1e-6" in changes:
        settings["newton"] = replace(GraspTask(model=piece.model).newton, relative_tolerance=1e-6)
    if "friction settled" in changes:
        settings["friction_passes"] = None
    if piece.controller in SHIPPED:
        trained = trained_task(SHIPPED[piece.controller])
        settings.update({name: trained.get(name) for name in REFLEXES}, observation=trained.get("observation", "full"))
    return settings


def run_piece(piece: Piece) -> dict:
    """Runs one piece (in a worker process): per seed its success, ending, peak finger force [N] and the sphere's
    final offset from the grasp point [m], with the task it ran. On the GPU all its episodes run at once."""
    from agents.evaluate import evaluate, make_policy
    from soft_gripper_env.grasp_task import GraspTask

    settings = task_settings(piece)
    task = GraspTask(**settings)
    policy = make_policy(piece.controller, task, piece.first_seed)
    on_gpu = {"num_envs": piece.episodes, "device": piece.device} if piece.device != "cpu" else {}
    result = evaluate(policy, piece.episodes, piece.first_seed, progress=False, **on_gpu, **settings)
    return {"piece": asdict(piece), "task": repr(task), "successes": result["successes"],
            "endings": result["episode_endings"], "peak_forces_N": result["peak_contact_forces_N"],
            "final_offsets_m": result["final_object_offsets"], "seconds": result["seconds"]}


def seed_ranges(seed: int, episodes: int) -> list[tuple[int, int]]:
    """The pieces' seeds, ``episodes`` from ``seed`` in pieces of :data:`PIECE`: (first seed, how many) each."""
    return [(first, min(PIECE, seed + episodes - first)) for first in range(seed, seed + episodes, PIECE)]


def plan(models: list[str], controllers: list[str], dts: dict[str, tuple[float, ...]], episodes: int, seed: int,
         variant: str = "base", floor: bool = True, tolerance_floor: bool = False) -> list[Piece]:
    """Every piece of the study of ``variant``, in the order they run: by controller, model, Δt from coarse to fine
    (the cheap first), the variant before its perturbed twin (without ``floor``, none) and, at the finest Δt with
    ``tolerance_floor``, its twin at Newton's tolerance 1e-6."""
    def variants(model: str, dt: float) -> list[str]:
        twins = [with_change(variant, "perturbed")] if floor else []
        if tolerance_floor and dt == min(dts[model]):
            twins.append(with_change(variant, "tolerance 1e-6"))
        return [variant, *twins]

    return [Piece(model, controller, dt, run, first, count)
            for controller in controllers for model in models for dt in sorted(dts[model], reverse=True)
            for run in variants(model, dt) for first, count in seed_ranges(seed, episodes)]


def kept_piece(runs: Path, piece: Piece, fingerprint: str) -> dict | None:
    """The piece's kept result if it ran the same task with today's code, else None."""
    from soft_gripper_env.grasp_task import GraspTask

    path = runs / piece.file_name()
    if not path.exists():
        return None
    kept = json.loads(path.read_text())
    same = kept.get("code") == fingerprint and kept.get("task") == repr(GraspTask(**task_settings(piece)))
    return kept if same else None


def kept_results(pieces: list[Piece], runs: Path, fingerprint: str) -> dict[Piece, dict]:
    """The pieces of ``pieces`` kept in ``runs`` that ran today's task with the code of ``fingerprint``
    (:func:`code_fingerprint`, :func:`kept_piece`)."""
    return {piece: kept for piece in pieces if (kept := kept_piece(runs, piece, fingerprint)) is not None}


def run_study(pieces: list[Piece], runs: Path, workers: int, stop_after_s: float = math.inf) -> dict[Piece, dict]:
    """Every piece's result: kept ones from ``runs``, the others run ``workers`` processes at a time (0: one at a
    time in this process, as the GPU's pieces run) and kept there as each finishes; no piece starts after
    ``stop_after_s`` seconds. Returns the pieces that are there."""
    runs.mkdir(parents=True, exist_ok=True)
    fingerprint = code_fingerprint()
    results = kept_results(pieces, runs, fingerprint)
    missing = [piece for piece in pieces if piece not in results]
    print(f"{len(results)} of {len(pieces)} pieces kept from earlier calls; {len(missing)} to run, "
          f"{max(workers, 1)} at a time (code {fingerprint})", flush=True)
    if not missing:
        return results
    start = time.monotonic()
    with (ProcessPoolExecutor(workers) if workers else ThreadPoolExecutor(1)) as pool, \
            tqdm(total=sum(p.episodes for p in missing), desc="episodes", unit="episode", file=sys.stdout) as bar:
        queue = iter(missing)
        running = {}

        def submit() -> None:
            if time.monotonic() - start < stop_after_s and (piece := next(queue, None)) is not None:
                running[pool.submit(run_piece, piece)] = piece

        for _ in range(max(workers, 1)):
            submit()
        while running:
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                piece = running.pop(future)
                result = {**future.result(), "code": fingerprint}
                (runs / piece.file_name()).write_text(json.dumps(result))
                results[piece] = result
                bar.update(piece.episodes)
                bar.write(f"  {piece.model} {piece.controller} Δt {1e3 * piece.dt:g} ms"
                          f"{'' if piece.variant == 'base' else ', ' + piece.variant}"
                          f"{'' if piece.device == 'cpu' else ' on ' + piece.device}, "
                          f"seeds {piece.first_seed}+{piece.episodes}: "
                          f"success {np.mean(result['successes']):.2f}, {result['seconds']:.0f} s")
                submit()
    if len(results) < len(pieces):
        print(f"stopped after {(time.monotonic() - start) / 60:.0f} min with {len(pieces) - len(results)} pieces "
              "to run: call again to go on", flush=True)
    return results


def conditions(results: dict[Piece, dict], pieces: list[Piece]) -> dict[tuple, dict]:
    """Each condition whose pieces are all there, its pieces' results joined in seed order."""
    by_condition: dict[tuple, list[Piece]] = {}
    for piece in pieces:
        by_condition.setdefault(piece.condition, []).append(piece)
    joined = {}
    for condition, members in by_condition.items():
        if all(piece in results for piece in members):
            members = sorted(members, key=lambda p: p.first_seed)
            joined[condition] = {key: [x for piece in members for x in results[piece][key]]
                                 for key in ("successes", "endings", "peak_forces_N", "final_offsets_m")}
    return joined


def two_proportion_p(successes_a: int, n_a: int, successes_b: int, n_b: int) -> float:
    """Two-sided p-value of the two-proportion z-test (pooled) that two success rates are equal."""
    from scipy.stats import norm

    pooled = (successes_a + successes_b) / (n_a + n_b)
    spread = math.sqrt(pooled * (1 - pooled) * (1 / n_a + 1 / n_b))
    if spread == 0.0:
        return 1.0
    return float(2 * norm.sf(abs(successes_a / n_a - successes_b / n_b) / spread))


def endings_p(endings_a: list[str], endings_b: list[str]) -> float:
    """p-value of the χ² test that two runs' endings come from one distribution (endings neither run had left
    out; 1 where both runs end one way only)."""
    from scipy.stats import chi2_contingency

    kinds = sorted(set(endings_a) | set(endings_b))
    if len(kinds) < 2:
        return 1.0
    table = [[endings.count(kind) for kind in kinds] for endings in (endings_a, endings_b)]
    return float(chi2_contingency(table, correction=False).pvalue)


def ks_p(a, b) -> float:
    """p-value of the two-sample Kolmogorov–Smirnov test that ``a`` and ``b`` come from one distribution."""
    from scipy.stats import ks_2samp

    return float(ks_2samp(a, b).pvalue)


def agreement(a: dict, b: dict) -> dict:
    """Two runs on the same seeds, seed by seed: the share of equal success labels, and the median and 90th
    percentile of the distance between the sphere's final places [m]."""
    gap = np.linalg.norm(np.subtract(a["final_offsets_m"], b["final_offsets_m"]), axis=1)
    return {"label_agreement": float(np.mean(np.equal(a["successes"], b["successes"]))),
            "median_position_gap_m": float(np.median(gap)), "p90_position_gap_m": float(np.percentile(gap, 90))}


def success_text(described: dict) -> str:
    """A run's success rate with its 95 % interval (:func:`describe`), as the tables print it."""
    low, high = described["success_interval_95"]
    return f"{described['success_rate']:.3f} ({low:.3f}–{high:.3f})"


def describe(run: dict) -> dict:
    """One run's outcome statistics: success rate and interval, endings, peak force and final distance from the
    grasp point."""
    n = len(run["successes"])
    successes = int(np.sum(run["successes"]))
    distance = np.linalg.norm(run["final_offsets_m"], axis=1)
    peaks = np.asarray(run["peak_forces_N"])
    return {"episodes": n, "success_rate": successes / n, "success_interval_95": wilson_interval(successes, n),
            "endings": {kind: run["endings"].count(kind) for kind in sorted(set(run["endings"]))},
            "mean_peak_force_N": float(peaks.mean()), "median_peak_force_N": float(np.median(peaks)),
            "median_final_distance_m": float(np.median(distance)),
            "p90_final_distance_m": float(np.percentile(distance, 90))}


def converged(run: dict, reference: dict, floor: float | None) -> dict:
    """Whether ``run``'s outcomes are ``reference``'s (the finest Δt's) within sampling error, on the same seeds:

    - success rate: two-proportion z-test, p > :data:`SIGNIFICANCE`;
    - endings: χ² test on the counts of each ending, p > :data:`SIGNIFICANCE`;
    - peak finger force and the sphere's final distance from the grasp point: two-sample Kolmogorov–Smirnov tests,
      p > :data:`SIGNIFICANCE`;
    - per-seed success labels: agreement with the reference at least the chaos ``floor`` (:func:`verdict_floor`)
      less :data:`FLOOR_MARGIN`.

    Returns each test's value and ``passes``, all of them (None without a ``floor``: the study ran none)."""
    n, m = len(run["successes"]), len(reference["successes"])
    tests = {"success_p": two_proportion_p(int(np.sum(run["successes"])), n, int(np.sum(reference["successes"])), m),
             "endings_p": endings_p(run["endings"], reference["endings"]),
             "peak_force_ks_p": ks_p(run["peak_forces_N"], reference["peak_forces_N"]),
             "final_distance_ks_p": ks_p(np.linalg.norm(run["final_offsets_m"], axis=1),
                                         np.linalg.norm(reference["final_offsets_m"], axis=1)),
             **agreement(run, reference), "floor": floor}
    tests["passes"] = None if floor is None else bool(
        all(tests[key] > SIGNIFICANCE for key in ("success_p", "endings_p", "peak_force_ks_p", "final_distance_ks_p"))
        and tests["label_agreement"] >= floor - FLOOR_MARGIN)
    return tests


def summarize(joined: dict[tuple, dict], models: list[str], controllers: list[str],
              dts: dict[str, tuple[float, ...]], episodes: int, seed: int, variant: str = "base",
              floor: bool = True) -> dict:
    """The study's summary of ``variant`` (and its perturbed twin, with ``floor``) from the complete conditions
    ``joined`` (:func:`conditions`); prints its table."""
    perturbed = with_change(variant, "perturbed")
    summary = {"episodes": episodes, "first_seed": seed, "variant": variant, "perturbation_m": PERTURBATION_M,
               "significance": SIGNIFICANCE, "floor_margin": FLOOR_MARGIN, "code": code_fingerprint(), "models": {}}
    print("\n| model | controller | Δt [ms] | success (95 % interval) | labels agree with the finest | floor at this "
          "Δt | median gap [mm] | success p | endings p | peak-force KS p | final-distance KS p | converged |\n"
          "|---|---|---|---|---|---|---|---|---|---|---|---|")
    for model in models:
        summary["models"][model] = {}
        for controller in controllers:
            there = complete_dts(joined, model, controller, dts, variant, floor)
            if not there:
                continue
            reference_dt = there[0]
            reference = joined[(model, controller, reference_dt, variant, "cpu")]
            floors = reference_floors(joined, model, controller, reference_dt, variant)
            chaos = lowest_floor(floors)
            rows = {}
            for dt in there:
                run = joined[(model, controller, dt, variant, "cpu")]
                twin = agreement(run, joined[(model, controller, dt, perturbed, "cpu")]) if floor else None
                row = {**describe(run), "chaos_floor": twin,
                       "against_reference": None if dt == reference_dt
                       else converged(run, reference, verdict_floor(chaos, twin))}
                rows[f"{dt:g}"] = row
                test = row["against_reference"]
                print(f"| {model} | {controller} | {1e3 * dt:g} | {success_text(row)} | "
                      + ("reference |" if test is None else f"{test['label_agreement']:.3f} |")
                      + (f" {twin['label_agreement']:.3f} | " if floor else " — | ")
                      + ("— | — | — | — | — | — |" if test is None else test_cells(test)))
            finest = min(dts[model])
            if reference_dt != finest:
                print(f"  ({model}, {controller}: Δt = {1e3 * finest:g} ms is not there yet; "
                      f"{1e3 * reference_dt:g} ms stands in as the reference)")
            passing = [float(dt) for dt in rows if rows[dt]["against_reference"] is not None
                       and rows[dt]["against_reference"]["passes"]]
            order = gap_order(rows)
            if order is not None:
                print(f"  ({model}, {controller}: the median gap to the finest Δt falls as Δt^{order:.2f})")
            if chaos is not None:
                print(f"  ({model}, {controller}: the floor at {1e3 * reference_dt:g} ms is {chaos:.3f}, the lowest of "
                      + ", ".join(f"{name} {value:.3f}" for name, value in floors.items() if value is not None) + ")")
            summary["models"][model][controller] = {
                "reference_dt_s": reference_dt, "finest_dt_s": finest, "dts": rows, "median_gap_order": order,
                "floors": floors, "floor": chaos,
                "largest_converged_dt_s": largest_converged(rows, reference_dt) if passing else None}
    return summary


def reference_floors(joined: dict[tuple, dict], model: str, controller: str, reference_dt: float,
                     variant: str) -> dict[str, float | None]:
    """The chaos floors at the reference Δt, by :data:`FLOOR_CHANGES`' keys: the reference's label agreement with
    each twin that ran (None where it did not)."""
    reference = joined[(model, controller, reference_dt, variant, "cpu")]
    floors = {}
    for change, key in FLOOR_CHANGES.items():
        twin = joined.get((model, controller, reference_dt, with_change(variant, change), "cpu"))
        floors[key] = None if twin is None else agreement(reference, twin)["label_agreement"]
    return floors


def lowest_floor(floors: dict[str, float | None]) -> float | None:
    """The floor a verdict uses: the lowest that was measured (None if none was)."""
    measured = [value for value in floors.values() if value is not None]
    return min(measured) if measured else None


def verdict_floor(reference_floor: float | None, twin: dict | None) -> float | None:
    """The chaos floor a comparison of a run with the reference is judged against: the lower of the reference's floor
    (:func:`lowest_floor`) and the run's own agreement with its perturbed twin (:func:`agreement`; None where it has
    none). Labels that a 1 nm shift flips in either run cannot be asked to agree across the two."""
    if reference_floor is None or twin is None:
        return reference_floor
    return min(reference_floor, twin["label_agreement"])


def complete_dts(joined: dict[tuple, dict], model: str, controller: str, dts: dict[str, tuple[float, ...]],
                 variant: str, floor: bool) -> list[float]:
    """The Δt of ``model`` and ``controller`` whose condition is complete in ``joined`` (with its perturbed twin,
    with ``floor``), finest first."""
    perturbed = with_change(variant, "perturbed")
    return [dt for dt in sorted(dts.get(model, ())) if (model, controller, dt, variant, "cpu") in joined
            and (not floor or (model, controller, dt, perturbed, "cpu") in joined)]


def test_cells(test: dict) -> str:
    """A comparison's columns (:func:`converged`) from the median gap to the verdict, as the tables print them."""
    verdict = {True: "yes", False: "no", None: "— (no floor)"}[test["passes"]]
    return (f"{1e3 * test['median_position_gap_m']:.2f} | {test['success_p']:.2f} | {test['endings_p']:.2f} | "
            f"{test['peak_force_ks_p']:.2f} | {test['final_distance_ks_p']:.2f} | {verdict} |")


def planar_against_3d(joined: dict[tuple, dict], controllers: list[str], dts: dict[str, tuple[float, ...]],
                      variant: str = "base", floor: bool = True) -> dict:
    """Whether the planar model stands in for 3-D: each planar Δt's outcomes against the 3-D model's at its finest
    Δt on the same seeds, by the same tests (:func:`converged`) and against the lower of 3-D's chaos floor and the
    planar run's own (where its perturbed twin ran: :func:`verdict_floor`); prints its table. Empty unless both
    models ran."""
    compared = {}
    for controller in controllers:
        finest = complete_dts(joined, "3d", controller, dts, variant, floor)
        planar = complete_dts(joined, "planar", controller, dts, variant, False)
        if not finest or not planar:
            continue
        reference = joined[("3d", controller, finest[0], variant, "cpu")]
        chaos = lowest_floor(reference_floors(joined, "3d", controller, finest[0], variant))
        reference_text = success_text(describe(reference))
        print(f"\n| planar Δt [ms] ({controller}) | success | 3-D at {1e3 * finest[0]:g} ms | labels agree | "
              "median gap [mm] | success p | endings p | peak-force KS p | final-distance KS p | a stand-in |\n"
              "|---|---|---|---|---|---|---|---|---|---|")
        rows = {}
        for dt in planar:
            run = joined[("planar", controller, dt, variant, "cpu")]
            twin = joined.get(("planar", controller, dt, with_change(variant, "perturbed"), "cpu"))
            test = converged(run, reference, verdict_floor(chaos, None if twin is None else agreement(run, twin)))
            rows[f"{dt:g}"] = {**describe(run), "against_3d": test}
            print(f"| {1e3 * dt:g} | {success_text(rows[f'{dt:g}'])} | {reference_text} | "
                  f"{test['label_agreement']:.3f} | {test_cells(test)}")
        compared[controller] = {"reference_3d_dt_s": finest[0], "dts": rows}
    return compared


def gap_order(rows: dict) -> float | None:
    """The order p of the median gap to the finest Δt, gap ∝ Δt^p, fitted on a log–log scale over the Δt compared
    with the finest (None with fewer than two, or a gap of zero)."""
    tested = [(float(k), row["against_reference"]["median_position_gap_m"]) for k, row in rows.items()
              if row["against_reference"] is not None]
    if len(tested) < 2 or min(gap for _, gap in tested) <= 0.0:
        return None
    dt, gap = np.log(np.array(tested)).T
    return float(np.polyfit(dt, gap, 1)[0])


def largest_converged(rows: dict, reference_dt: float) -> float:
    """The largest Δt that passes with every finer Δt passing too (an outlier that passes above a failing Δt does
    not count)."""
    largest = reference_dt
    for key in sorted(rows, key=float):
        test = rows[key]["against_reference"]
        if test is None:
            continue
        if not test["passes"]:
            break
        largest = float(key)
    return largest


def time_dts(models: list[str], dts: dict[str, tuple[float, ...]], seed: int, steps: int = 240,
             repeats: int = 3) -> dict:
    """One env's steps per second under the reactive controller per model and Δt (the best of ``repeats`` over
    ``steps`` actions from ``seed``), and Ant-v5's in the same run."""
    import gymnasium as gym

    import soft_gripper_env
    from agents.scripted import ReactivePolicy
    from benchmarks.env_speed import steps_per_second, time_ant
    from soft_gripper_env.grasp_task import GraspTask

    def once(model: str, dt: float) -> float:
        env = gym.make(soft_gripper_env.ENV_ID, model=model, physics_dt=dt)
        return steps_per_second(env, steps, ReactivePolicy(GraspTask(model=model, physics_dt=dt)), seed)

    timing = {"ant_v5_steps_per_s": max(time_ant() for _ in range(repeats)), "env_steps_per_s": {}}
    for model in models:
        once(model, max(dts[model]))  # compiles or loads the kernels
        timing["env_steps_per_s"][model] = {f"{dt:g}": max(once(model, dt) for _ in range(repeats))
                                            for dt in tqdm(dts[model], desc=f"timing {model}", file=sys.stdout)}
    return timing


def plot(summary: dict, path: Path) -> None:
    """Per model (a row): the success rate and its interval against Δt, the label agreement with the finest Δt
    beside the chaos floor, and the sphere's median final gap to the finest Δt beside the floor's; a filled marker
    where a Δt passes :func:`converged`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    models = [m for m in summary["models"] if summary["models"][m]]
    fig, axes = plt.subplots(len(models), 3, figsize=(15, 4.2 * len(models)), squeeze=False)
    colours = dict(zip(CONTROLLERS, ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"), strict=True))
    for row, model in enumerate(models):
        success, agree, gap = axes[row]
        for controller, study in summary["models"][model].items():
            rows = study["dts"]
            dt = np.array([float(k) for k in rows]) * 1e3
            colour = colours.get(controller, "k")
            rate = np.array([rows[k]["success_rate"] for k in rows])
            interval = np.array([rows[k]["success_interval_95"] for k in rows])
            success.errorbar(dt, rate, yerr=[rate - interval[:, 0], interval[:, 1] - rate], color=colour,
                             marker="o", capsize=3, label=controller)
            tested = [k for k in rows if rows[k]["against_reference"] is not None]
            t = np.array([float(k) for k in tested]) * 1e3
            passes = np.array([bool(rows[k]["against_reference"]["passes"]) for k in tested], dtype=bool)
            for axis, key, scale in ((agree, "label_agreement", 1.0), (gap, "median_position_gap_m", 1e3)):
                values = np.array([rows[k]["against_reference"][key] for k in tested]) * scale
                axis.plot(t, values, color=colour, label=f"{controller}: against {1e3 * study['reference_dt_s']:g} ms")
                axis.scatter(t[passes], values[passes], color=colour, zorder=3)  # None (no floor) draws open
                axis.scatter(t[~passes], values[~passes], facecolors="white", edgecolors=colour, zorder=3)
                if all(rows[k]["chaos_floor"] is not None for k in rows):
                    axis.plot(dt, [rows[k]["chaos_floor"][key] * scale for k in rows], color=colour,
                              linestyle="--", marker="x", label=f"{controller}: chaos floor (start moved 1 nm)")
            tolerance = (study.get("floors") or {}).get(FLOOR_CHANGES["tolerance 1e-6"])
            if tolerance is not None:
                agree.scatter([1e3 * study["reference_dt_s"]], [tolerance], color=colour, marker="P", s=60,
                              label=f"{controller}: floor by Newton's tolerance 1e-6")
            if study.get("floor") is not None:
                agree.axhline(study["floor"] - FLOOR_MARGIN, color=colour, linestyle=":", linewidth=1,
                              label=f"{controller}: passes above (floor − {FLOOR_MARGIN:g})")
        success.set(ylabel="success rate (95 % interval)", title=f"{model}: success against Δt")
        agree.set(ylabel="share of seeds with the same label", title=f"{model}: labels against the finest Δt")
        gap.set(ylabel="median gap of the sphere's final place [mm]", yscale="log",
                title=f"{model}: final place against the finest Δt")
        steps = sorted({1e3 * float(k) for study in summary["models"][model].values() for k in study["dts"]})
        for axis in axes[row]:
            axis.set(xscale="log", xlabel="physics step Δt [ms]")
            axis.set_xticks(steps, [f"{dt:g}" for dt in steps])
            axis.minorticks_off()
            axis.grid(True, alpha=0.3)
        success.legend(fontsize=8)
        agree.legend(fontsize=7)
    variant = "" if summary["variant"] == "base" else f" ({summary['variant']})"
    fig.suptitle(f"Grasp outcomes against Δt{variant}, {summary['episodes']} seeds from {summary['first_seed']} "
                 "(filled: converged by every test; open: not)")
    save_plot(fig, path)
    plt.close(fig)


def parse_dts(text: str | None, models: list[str]) -> dict[str, tuple[float, ...]]:
    """``--dts``: "3d=0.01,0.005;planar=0.01" (a model not named keeps :data:`DEFAULT_DTS`)."""
    dts = {model: DEFAULT_DTS[model] for model in models}
    if text:
        for part in text.split(";"):
            model, _, values = part.partition("=")
            if model.strip() not in dts:
                raise ValueError(f"--dts names model {model.strip()!r}, not one of --models {models}")
            steps = tuple(float(v) for v in values.split(","))
            if len(steps) < 2 or any(not 0.0 < dt <= 0.02 for dt in steps):
                raise ValueError(f"--dts for {model.strip()}: at least two steps, each in (0, 0.02] s, got {steps}")
            dts[model.strip()] = steps
    return dts


def add_study_options(parser: argparse.ArgumentParser, name: str, episodes: int, seed: int) -> None:
    """The options of an outcome study run in pieces (this one and :mod:`benchmarks.gpu_outcomes`): --models,
    --episodes, --seed, --workers, --stop-after, --runs out/NAME_runs, --json out/NAME.json, --plot out/NAME.png."""
    parser.add_argument("--models", default=",".join(MODELS), help="comma-separated, of 3d, planar (default both)")
    parser.add_argument("--episodes", type=int, default=episodes, help=f"seeds per condition (default {episodes})")
    parser.add_argument("--seed", type=int, default=seed, help=f"the first seed (default {seed})")
    parser.add_argument("--workers", type=int, default=2, help="processes running CPU pieces (default 2)")
    parser.add_argument("--stop-after", type=float, default=math.inf, metavar="MINUTES",
                        help="start no CPU piece after this many minutes (default: run them all)")
    parser.add_argument("--runs", type=Path, default=Path("out") / f"{name}_runs",
                        help=f"where each finished piece is kept (default out/{name}_runs)")
    parser.add_argument("--json", type=Path, default=Path("out") / f"{name}.json")
    parser.add_argument("--plot", type=Path, default=Path("out") / f"{name}.png")


def study_models(parser: argparse.ArgumentParser, args: argparse.Namespace) -> list[str]:
    """The models of :func:`add_study_options`' parsed options, each option checked (the parser's error names the
    option that is out of range)."""
    models = [m.strip() for m in args.models.split(",") if m.strip()]
    if not models or any(m not in MODELS for m in models):
        parser.error(f"--models = {args.models!r}: each must be one of {', '.join(MODELS)}")
    if args.episodes < 2:
        parser.error(f"--episodes = {args.episodes} must be at least 2")
    if args.workers < 1:
        parser.error(f"--workers = {args.workers} must be at least 1")
    if not args.stop_after > 0:
        parser.error(f"--stop-after = {args.stop_after} must be a positive number of minutes")
    return models


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_study_options(parser, "outcome_convergence", 400, FIRST_SEED)
    parser.add_argument("--controllers", default=",".join(DEFAULT_CONTROLLERS),
                        help="comma-separated, of " + ", ".join(CONTROLLERS) + " (default: "
                             + ", ".join(DEFAULT_CONTROLLERS) + ")")
    parser.add_argument("--dts", help="steps [s] per model, e.g. '3d=0.01,0.005;planar=0.01,0.005' "
                                      "(default: halved from 0.01 to 0.0003125 s in both)")
    parser.add_argument("--change", action="append", default=[], choices=[c for c in CHANGES if c != "perturbed"],
                        help="run every condition with this change from the defaults (repeatable), to see what it "
                             "does to convergence; the runs are kept apart from the defaults' own")
    parser.add_argument("--no-floor", action="store_true",
                        help="run no perturbed twins (half the cost; no chaos floor, so no verdict)")
    parser.add_argument("--tolerance-floor", action="store_true",
                        help="also run the finest Δt at Newton's tolerance 1e-6: a second floor; the verdicts use "
                             "the lower")
    parser.add_argument("--time", action="store_true", help="also time each model and Δt against Ant-v5")
    args = parser.parse_args(argv)
    models = study_models(parser, args)
    controllers = [c.strip() for c in args.controllers.split(",") if c.strip()]
    if not controllers or any(c not in CONTROLLERS for c in controllers):
        parser.error(f"--controllers = {args.controllers!r}: each must be one of {', '.join(CONTROLLERS)}")
    try:
        dts = parse_dts(args.dts, models)
    except ValueError as error:
        parser.error(str(error))
    variant = ", ".join(args.change) or "base"
    if args.tolerance_floor and "tolerance 1e-6" in args.change:
        parser.error("--tolerance-floor: the variant already runs at Newton's tolerance 1e-6 (--change)")
    pieces = plan(models, controllers, dts, args.episodes, args.seed, variant, not args.no_floor,
                  args.tolerance_floor)
    results = run_study(pieces, args.runs, args.workers, 60 * args.stop_after)
    joined = conditions(results, pieces)
    summary = summarize(joined, models, controllers, dts, args.episodes, args.seed, variant, not args.no_floor)
    summary["planar_against_3d"] = planar_against_3d(joined, controllers, dts, variant, not args.no_floor)
    summary["complete"] = len(results) == len(pieces)
    if args.time:
        summary["timing"] = time_dts(models, dts, args.seed)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(summary, indent=1))
    print(f"wrote {args.json}")
    if any(summary["models"].values()):
        plot(summary, args.plot)
    return summary


if __name__ == "__main__":
    main()
