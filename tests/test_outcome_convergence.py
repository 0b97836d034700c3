"""benchmarks/outcome_convergence.py: its statistics against independent computations, its definition of converged,
and a small study end to end, resumed from its kept pieces."""

import json

import numpy as np
import pytest
from scipy.stats import chi2_contingency

from benchmarks import outcome_convergence as study


def run_of(successes, endings=None, peaks=None, offsets=None):
    n = len(successes)
    rng = np.random.default_rng(n)
    return {"successes": [bool(s) for s in successes],
            "endings": endings or ["success" if s else "lost" for s in successes],
            "peak_forces_N": list(rng.uniform(1.0, 3.0, n) if peaks is None else peaks),
            "final_offsets_m": (rng.normal(0.0, 0.01, (n, 3)) if offsets is None else np.asarray(offsets)).tolist()}


def flipped_run(labels, like: dict, count: int, start: int = 0) -> dict:
    """A run of ``labels`` with ``count`` of them flipped from the ``start``-th of each kind on, half of them successes
    (so that the success rate stays), its peak forces and final places those of the run ``like``."""
    changed = labels.copy()
    for value in (True, False):
        which = np.flatnonzero(labels == value)[start:start + count // 2]
        changed[which] = not value
    return run_of(changed, peaks=like["peak_forces_N"], offsets=like["final_offsets_m"])


@pytest.mark.parametrize("a, b", [((40, 100), (55, 100)), ((380, 400), (350, 400)), ((7, 9), (7, 9))])
def test_two_proportion_test_is_the_chi_square_test_of_the_two_by_two_table(a, b):
    table = [[a[0], a[1] - a[0]], [b[0], b[1] - b[0]]]
    expected = chi2_contingency(table, correction=False).pvalue if a != b else 1.0
    assert study.two_proportion_p(a[0], a[1], b[0], b[1]) == pytest.approx(expected, rel=1e-9)


def test_endings_test_tells_one_distribution_from_two():
    same = ["success"] * 60 + ["lost"] * 30 + ["harmed"] * 10
    assert study.endings_p(same, list(reversed(same))) == pytest.approx(1.0)
    assert study.endings_p(same, ["success"] * 30 + ["lost"] * 30 + ["harmed"] * 40) < 1e-6
    assert study.endings_p(["success"] * 5, ["success"] * 5) == 1.0


def test_a_run_converges_to_itself_and_not_to_a_run_with_many_labels_flipped():
    rng = np.random.default_rng(0)
    labels = rng.random(400) < 0.8
    reference = run_of(labels)
    itself = study.converged(reference, reference, floor=1.0)
    assert itself["passes"] and itself["label_agreement"] == 1.0 and itself["median_position_gap_m"] == 0.0
    flipped = labels.copy()
    flipped[:120] = ~flipped[:120]  # 30 % of labels: the success rate moves too
    worse = study.converged(run_of(flipped, offsets=reference["final_offsets_m"],
                                   peaks=reference["peak_forces_N"]), reference, floor=0.95)
    assert not worse["passes"] and worse["label_agreement"] == pytest.approx(0.7)


def test_label_agreement_below_the_floor_fails_even_where_the_statistics_agree():
    labels = np.arange(400) % 5 != 0  # 0.8
    swapped = np.roll(labels, 1)  # the same rate, each label moved to the next seed: 40 % of labels differ
    reference = run_of(labels)
    test = study.converged(run_of(swapped, endings=list(np.roll(reference["endings"], 1)),
                                  peaks=reference["peak_forces_N"], offsets=reference["final_offsets_m"]),
                           reference, floor=0.9)
    assert test["success_p"] == 1.0 and test["endings_p"] == pytest.approx(1.0)
    assert test["label_agreement"] == pytest.approx(0.6) and not test["passes"]
    assert study.converged(run_of(swapped, endings=list(np.roll(reference["endings"], 1)),
                                  peaks=reference["peak_forces_N"], offsets=reference["final_offsets_m"]),
                           reference, floor=0.61)["passes"]


def test_a_shifted_force_distribution_fails_the_ks_test():
    reference = run_of(np.ones(400, dtype=bool))
    pressed = run_of(np.ones(400, dtype=bool), peaks=np.asarray(reference["peak_forces_N"]) + 0.3,
                     offsets=reference["final_offsets_m"])
    test = study.converged(pressed, reference, floor=1.0)
    assert test["peak_force_ks_p"] < 1e-3 and not test["passes"]


def test_the_largest_converged_step_needs_every_finer_step_to_pass():
    rows = {f"{dt:g}": {"against_reference": None if dt == 0.001 else {"passes": passes}}
            for dt, passes in ((0.001, None), (0.002, True), (0.004, False), (0.008, True))}
    assert study.largest_converged(rows, 0.001) == 0.002


def test_the_dts_option_is_checked():
    assert study.parse_dts("planar=0.01,0.005", ["3d", "planar"])["planar"] == (0.01, 0.005)
    with pytest.raises(ValueError, match="--dts names model"):
        study.parse_dts("2d=0.01,0.005", ["3d"])
    with pytest.raises(ValueError, match="at least two steps"):
        study.parse_dts("3d=0.05,0.01", ["3d"])


def test_command_line_refusals_name_the_option(capsys):
    for argv, name in ((["--models", "2d"], "--models"), (["--controllers", "random"], "--controllers"),
                       (["--episodes", "1"], "--episodes"), (["--workers", "0"], "--workers"),
                       (["--stop-after", "0"], "--stop-after")):
        with pytest.raises(SystemExit):
            study.main(argv)
        assert name in capsys.readouterr().err


def test_the_graded_controller_is_a_controller_of_the_study_but_not_of_its_default():
    assert "reactive_graded" in study.CONTROLLERS and "reactive_graded" not in study.DEFAULT_CONTROLLERS
    result = study.run_piece(study.Piece("planar", "reactive_graded", 0.01, "base", 3_000_000, 1))
    assert len(result["successes"]) == 1 and np.isfinite(result["peak_forces_N"]).all()


def test_the_perturbed_run_moves_only_the_spheres_start():
    from soft_gripper_env.grasp_task import GraspTask

    base = study.task_settings(study.Piece("3d", "reactive", 0.0025, "base", 0, 2))
    perturbed = study.task_settings(study.Piece("3d", "reactive", 0.0025, "perturbed", 0, 2))
    assert set(perturbed) - set(base) == {"start_point"}
    moved = np.subtract(perturbed["start_point"], GraspTask.start_point)
    assert moved[0] == pytest.approx(study.PERTURBATION_M, rel=1e-6) and not moved[1:].any()


@pytest.mark.slow
def test_a_small_study_runs_and_resumes_from_its_kept_pieces(tmp_path, capsys, monkeypatch):
    argv = ["--models", "planar", "--controllers", "ramp", "--dts", "planar=0.01,0.005", "--episodes", "3",
            "--workers", "1", "--runs", str(tmp_path / "runs"), "--json", str(tmp_path / "study.json"),
            "--plot", str(tmp_path / "study.png")]
    monkeypatch.setattr(study, "PIECE", 2)  # two pieces per condition: 2 seeds and 1
    summary = study.main(argv)
    assert "0 of 8 pieces kept" in capsys.readouterr().out
    written = json.loads((tmp_path / "study.json").read_text())
    assert written["complete"] and (tmp_path / "study.png").stat().st_size > 10_000
    rows = written["models"]["planar"]["ramp"]["dts"]
    assert set(rows) == {"0.01", "0.005"} and rows["0.005"]["against_reference"] is None
    assert rows["0.01"]["episodes"] == 3 and 0.0 <= rows["0.01"]["chaos_floor"]["label_agreement"] <= 1.0
    again = study.main(argv)
    assert "8 of 8 pieces kept" in capsys.readouterr().out and again["models"] == summary["models"]
    # a piece run by other code is not taken
    kept = next((tmp_path / "runs").glob("*.json"))
    record = json.loads(kept.read_text())
    kept.write_text(json.dumps({**record, "code": "another"}))
    piece = study.Piece(**record["piece"])
    assert study.kept_piece(tmp_path / "runs", piece, study.code_fingerprint()) is None


def test_a_variants_changes_reach_the_task_and_compose():
    piece = study.Piece("3d", "reactive", 0.00125, "friction settled, tolerance 1e-6, perturbed", 0, 2)
    settings = study.task_settings(piece)
    assert settings["friction_passes"] is None and settings["newton"].relative_tolerance == 1e-6
    assert settings["physics_dt"] == 0.00125 and settings["start_point"][0] == pytest.approx(study.PERTURBATION_M)
    assert study.with_change("base", "perturbed") == "perturbed"
    assert study.with_change("friction settled", "perturbed") == "friction settled, perturbed"
    with pytest.raises(ValueError, match="'stiffer' is not one of"):
        study.task_settings(study.Piece("3d", "reactive", 0.0025, "perturbed, stiffer", 0, 2))
    names = {study.Piece("3d", "reactive", 0.0025, v, 0, 2).file_name()
             for v in ("base", "perturbed", "friction settled", "friction settled, perturbed")}
    assert len(names) == 4  # the variants' pieces are kept apart


def test_the_gaps_order_is_the_slope_on_a_log_log_scale():
    rows = {f"{dt:g}": {"against_reference": None if dt == 0.001 else {"median_position_gap_m": 3.0 * dt ** 1.5}}
            for dt in (0.001, 0.002, 0.004, 0.008)}
    assert study.gap_order(rows) == pytest.approx(1.5)
    assert study.gap_order({k: v for k, v in rows.items() if k in ("0.001", "0.002")}) is None


def test_without_a_floor_no_verdict_is_given():
    reference = run_of(np.ones(50, dtype=bool))
    assert study.converged(reference, reference, floor=None)["passes"] is None


@pytest.mark.slow
def test_a_study_of_a_change_without_a_floor_runs_apart_from_the_defaults(tmp_path, capsys, monkeypatch):
    argv = ["--models", "planar", "--controllers", "ramp", "--dts", "planar=0.01,0.005", "--episodes", "2",
            "--workers", "1", "--runs", str(tmp_path / "runs"), "--json", str(tmp_path / "study.json"),
            "--plot", str(tmp_path / "study.png")]
    study.main(argv)
    summary = study.main(argv + ["--change", "friction settled", "--no-floor"])
    assert "0 of 2 pieces kept" in capsys.readouterr().out  # none of the defaults' pieces is taken for it
    assert summary["variant"] == "friction settled"
    rows = summary["models"]["planar"]["ramp"]["dts"]
    assert rows["0.01"]["chaos_floor"] is None and rows["0.01"]["against_reference"]["passes"] is None
    assert len(list((tmp_path / "runs").glob("*friction_settled*"))) == 2


@pytest.mark.slow
def test_the_physics_probe_runs_and_compares_each_step_with_the_finest(tmp_path):
    from benchmarks import physics_convergence as probe

    summary = probe.main(["--model", "planar", "--seeds", "2", "--dts", "0.01,0.005,0.0025", "--workers", "1",
                          "--json", str(tmp_path / "p.json"), "--plot", str(tmp_path / "p.png")])
    rows = summary["dts"]
    assert list(rows) == ["0.01", "0.005", "0.0025"] and rows["0.0025"]["against_reference"] is None
    gaps = [rows[k]["against_reference"]["median_position_gap_m"] for k in ("0.01", "0.005")]
    assert all(0.0 <= gap < 0.05 for gap in gaps)  # the sphere stays in the grasp, within centimetres
    assert all(row["median_holds_made_per_s"] >= 0 and row["failed"] == 0 for row in rows.values())
    run = summary["runs"]["0/0.01"]
    assert len(run["final_position_m"]) == 3 and run["holds_made"] >= 0
    assert (tmp_path / "p.png").stat().st_size > 10_000


def test_the_physics_probe_refuses_steps_it_cannot_compare(capsys):
    from benchmarks import physics_convergence as probe

    for dts, message in (("0.01,0.005", "at least three steps"), ("0.01,0.005,0.003", "divide the control"),
                         ("0.01,x,0.005", "comma-separated")):
        with pytest.raises(SystemExit):
            probe.main(["--dts", dts])
        assert message in capsys.readouterr().err


def test_step_traces_halve_the_gap_with_the_step_before_contact(tmp_path):
    """Before the fingers touch (the first 0.15 s), backward Euler is first order: the median gap of the sphere's
    place between 5 and 2.5 ms is twice that between 2.5 and 1.25 ms (to 25 %), open loop and with the controller
    alike; the traces, the JSON and the figure are written."""
    from benchmarks import step_traces

    for controller in step_traces.CONTROLLERS:
        summary = step_traces.main(["--controller", controller, "--seeds", "2", "--dts", "0.005,0.0025,0.00125",
                                    "--until", "0.15", "--workers", "1", "--json", str(tmp_path / "t.json"),
                                    "--plot", str(tmp_path / "t.png")])
        coarse, fine = (np.asarray(summary["median_gaps_m"][pair]) for pair in ("0.005-0.0025", "0.0025-0.00125"))
        assert summary["times_s"] == pytest.approx([0.05, 0.1, 0.15])
        assert np.all(fine > 0.0)
        assert coarse[-1] / fine[-1] == pytest.approx(2.0, rel=0.25)
        assert np.asarray(summary["traces_m"]["0.005"]).shape == (3, 2, 3)
        assert json.loads((tmp_path / "t.json").read_text())["controller"] == controller
        assert (tmp_path / "t.png").stat().st_size > 10_000


def test_step_traces_refuse_what_they_cannot_compare(capsys):
    from benchmarks import step_traces

    for options, message in ((["--dts", "0.01"], "at least two steps"), (["--dts", "0.01,0.003"], "divide the"),
                             (["--until", "20"], "--until"), (["--friction", "-1"], "--friction"),
                             (["--controller", "ramp"], "--controller")):
        with pytest.raises(SystemExit):
            step_traces.main(options)
        assert message in capsys.readouterr().err


def test_the_planar_model_is_compared_with_3d_at_its_finest_step(capsys):
    """Each planar Δt against 3-D's finest Δt, with 3-D's chaos floor: a planar run equal to 3-D's finest is a
    stand-in, one with a third of its labels flipped is not, and without 3-D there is no comparison."""
    rng = np.random.default_rng(1)
    labels = rng.random(400) < 0.8
    finest, coarse = run_of(labels), run_of(np.roll(labels, 1))
    flipped = labels.copy()
    flipped[:130] = ~flipped[:130]
    joined = {("3d", "reactive", 0.001, "base", "cpu"): finest, ("3d", "reactive", 0.001, "perturbed", "cpu"): finest,
              ("3d", "reactive", 0.002, "base", "cpu"): coarse, ("3d", "reactive", 0.002, "perturbed", "cpu"): coarse,
              ("planar", "reactive", 0.002, "base", "cpu"): finest,
              ("planar", "reactive", 0.004, "base", "cpu"): run_of(flipped, peaks=finest["peak_forces_N"],
                                                                   offsets=finest["final_offsets_m"])}
    dts = {"3d": (0.002, 0.001), "planar": (0.004, 0.002)}
    compared = study.planar_against_3d(joined, ["reactive"], dts)["reactive"]
    assert compared["reference_3d_dt_s"] == 0.001
    assert compared["dts"]["0.002"]["against_3d"]["passes"]
    assert compared["dts"]["0.004"]["against_3d"]["label_agreement"] == pytest.approx(270 / 400)
    assert not compared["dts"]["0.004"]["against_3d"]["passes"]
    assert "| 4 | " in capsys.readouterr().out
    assert study.planar_against_3d({k: v for k, v in joined.items() if k[0] == "planar"}, ["reactive"], dts) == {}


def test_a_tolerance_floor_runs_at_the_finest_step_only_and_the_verdict_takes_the_lower_floor(capsys):
    """Newton's tolerance twin runs at the finest Δt alone; where it flips more labels than the 1 nm shift, the
    verdicts are judged against it: a coarse run 8 points off passes a floor of 0.90 and fails one of 1.00."""
    dts = {"3d": (0.002, 0.001)}
    pieces = study.plan(["3d"], ["reactive"], dts, 4, 0, floor=True, tolerance_floor=True)
    twins = {(p.dt, p.variant) for p in pieces}
    assert twins == {(0.002, "base"), (0.002, "perturbed"), (0.001, "base"), (0.001, "perturbed"),
                     (0.001, "tolerance 1e-6")}
    rng = np.random.default_rng(2)
    labels = rng.random(400) < 0.8

    def flipped(count: int) -> dict:
        return flipped_run(labels, finest, count)

    finest = run_of(labels)
    joined = {("3d", "reactive", 0.001, "base", "cpu"): finest, ("3d", "reactive", 0.001, "perturbed", "cpu"): finest,
              ("3d", "reactive", 0.002, "base", "cpu"): flipped(32), ("3d", "reactive", 0.002, "perturbed", "cpu"):
              flipped(32)}
    alone = study.summarize(joined, ["3d"], ["reactive"], dts, 400, 0)["models"]["3d"]["reactive"]
    assert alone["floors"] == {"start_moved_1nm": 1.0, "newton_tolerance_1e-6": None} and alone["floor"] == 1.0
    assert not alone["dts"]["0.002"]["against_reference"]["passes"]
    joined[("3d", "reactive", 0.001, "tolerance 1e-6", "cpu")] = flipped(40)
    both = study.summarize(joined, ["3d"], ["reactive"], dts, 400, 0)["models"]["3d"]["reactive"]
    assert both["floors"]["newton_tolerance_1e-6"] == pytest.approx(0.9) and both["floor"] == pytest.approx(0.9)
    assert both["dts"]["0.002"]["against_reference"]["label_agreement"] == pytest.approx(0.92)
    assert both["dts"]["0.002"]["against_reference"]["passes"]
    assert "the lowest of start_moved_1nm 1.000, newton_tolerance_1e-6 0.900" in capsys.readouterr().out


def test_a_tolerance_floor_of_a_variant_at_that_tolerance_is_refused(capsys):
    with pytest.raises(SystemExit):
        study.main(["--change", "tolerance 1e-6", "--tolerance-floor"])
    assert "--tolerance-floor" in capsys.readouterr().err


def test_a_run_whose_own_twin_disagrees_is_judged_against_its_own_lower_floor():
    """A coarse run 8 points off the finest Δt fails where a 1 nm shift changes nothing at either step, and passes
    where the shift flips 18 % of the coarse run's own labels: the bar is the lower of the two runs' floors."""
    dts = {"3d": (0.002, 0.001)}
    rng = np.random.default_rng(3)
    labels = rng.random(400) < 0.8
    finest = run_of(labels)

    def flipped(start: int, count: int) -> dict:
        return flipped_run(labels, finest, count, start)

    coarse = flipped(0, 32)
    joined = {("3d", "reactive", 0.001, "base", "cpu"): finest, ("3d", "reactive", 0.001, "perturbed", "cpu"): finest,
              ("3d", "reactive", 0.002, "base", "cpu"): coarse, ("3d", "reactive", 0.002, "perturbed", "cpu"): coarse}
    steady = study.summarize(joined, ["3d"], ["reactive"], dts, 400, 0)["models"]["3d"]["reactive"]["dts"]["0.002"]
    assert steady["against_reference"]["label_agreement"] == pytest.approx(0.92)
    assert steady["against_reference"]["floor"] == 1.0 and not steady["against_reference"]["passes"]
    joined[("3d", "reactive", 0.002, "perturbed", "cpu")] = flipped(40, 40)  # 328 of 400 alike
    chaotic = study.summarize(joined, ["3d"], ["reactive"], dts, 400, 0)["models"]["3d"]["reactive"]["dts"]["0.002"]
    assert chaotic["chaos_floor"]["label_agreement"] == pytest.approx(0.82)
    assert chaotic["against_reference"]["floor"] == pytest.approx(0.82) and chaotic["against_reference"]["passes"]


def test_verdict_floor_is_the_lower_of_the_two_and_the_reference_alone_without_a_twin():
    assert study.verdict_floor(1.0, {"label_agreement": 0.97}) == 0.97
    assert study.verdict_floor(0.95, {"label_agreement": 0.99}) == 0.95
    assert study.verdict_floor(0.95, None) == 0.95 and study.verdict_floor(None, {"label_agreement": 0.9}) is None
