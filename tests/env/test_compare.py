"""Paired tests between evaluated policies (agents/compare.py), against scipy's own tests as the independent
computation, on evaluations made up so that the answer is known."""

import json

import numpy as np
import pytest
from scipy import stats

from agents.compare import by_radius, compare, main, mcnemar_exact, paired_t, pooled, wilson_interval


def evaluation(successes, forces, endings=None, first_seed=1_000_000, model="3d", policy="p") -> dict:
    """An ``agents.evaluate --json`` result with only what a comparison reads."""
    endings = endings or ["success" if s else "lost" for s in successes]
    return {"policy": policy, "model": model, "first_seed": first_seed, "episodes": len(successes),
            "successes": [bool(s) for s in successes], "peak_contact_forces_N": [float(f) for f in forces],
            "episode_endings": endings}


@pytest.mark.parametrize(("wins", "losses"), [(21, 8), (16, 6), (0, 5), (7, 7), (1, 0), (40, 3)])
def test_mcnemars_exact_p_is_the_two_sided_binomial_test_on_the_discordant_specimens(wins, losses):
    expected = stats.binomtest(wins, wins + losses, 0.5).pvalue
    assert mcnemar_exact(wins, losses) == pytest.approx(expected, rel=1e-12)


def test_mcnemar_without_discordant_specimens_has_nothing_to_say_and_refuses_negative_counts():
    assert mcnemar_exact(0, 0) == 1.0
    with pytest.raises(ValueError, match="wins = -1"):
        mcnemar_exact(-1, 3)


def test_wilson_interval_matches_the_closed_form_values():
    assert wilson_interval(50, 100) == pytest.approx((0.4038, 0.5962), abs=1e-4)
    low, high = wilson_interval(0, 10)
    assert low == 0.0 and high == pytest.approx(0.2775, abs=1e-4)
    with pytest.raises(ValueError, match="successes = 11 of n = 10"):
        wilson_interval(11, 10)
    for n in range(1, 300):  # the interval holds its own rate, to the bit (49 of 49 once gave 0.9999999999999999)
        for successes in {0, 1, n // 2, n - 1, n}:
            low, high = wilson_interval(successes, n)
            assert 0.0 <= low <= successes / n <= high <= 1.0


def test_the_paired_t_test_is_scipys():
    rng = np.random.default_rng(3)
    a, b = rng.normal(1.6, 0.3, 200), rng.normal(1.5, 0.3, 200)
    expected = stats.ttest_rel(b, a)
    t, p = paired_t(b - a)
    assert t == pytest.approx(expected.statistic, rel=1e-10)
    assert p == pytest.approx(expected.pvalue, rel=1e-8)
    assert paired_t(np.zeros(5)) == (0.0, 1.0)
    with pytest.raises(ValueError, match="at least 2"):
        paired_t(np.ones(1))


def test_a_comparison_counts_the_specimens_each_grasped_alone_and_the_force_difference():
    baseline = evaluation([1, 1, 0, 0, 1, 0], [2.0, 2.0, 1.0, 1.0, 2.0, 1.0], policy="base")
    policy = evaluation([1, 0, 1, 1, 1, 0], [1.5, 1.9, 1.2, 1.1, 1.8, 0.9],
                        endings=["success", "harmed", "success", "success", "success", "not_held_through_gust"])
    row = compare(baseline, policy)
    assert (row["wins"], row["losses"]) == (2, 1)
    assert row["mcnemar_p"] == pytest.approx(1.0)
    assert row["success_rate"] == pytest.approx(4 / 6) and row["baseline_success_rate"] == pytest.approx(0.5)
    assert row["force_difference_N"] == pytest.approx(np.mean([-0.5, -0.1, 0.2, 0.1, -0.2, -0.1]))
    assert row["endings"]["harmed"] == 1 and row["endings"]["not_held_through_gust"] == 1
    assert row["baseline_endings"]["lost"] == 3


def test_pooling_compares_each_specimens_mean_over_the_policies():
    rng = np.random.default_rng(5)
    baseline = evaluation(rng.random(50) < 0.8, rng.normal(1.6, 0.2, 50))
    policies = [evaluation(rng.random(50) < 0.9, rng.normal(1.5, 0.2, 50), policy=f"s{k}") for k in range(3)]
    pool = pooled(baseline, policies)
    success = np.mean([p["successes"] for p in policies], axis=0) - np.array(baseline["successes"], float)
    assert pool["success_difference"] == pytest.approx(success.mean())
    assert pool["success_p"] == pytest.approx(stats.ttest_rel(success, np.zeros(50)).pvalue, rel=1e-8)
    rates = [np.mean(p["successes"]) for p in policies]
    assert pool["success_rate_sd"] == pytest.approx(np.std(rates, ddof=1))


def test_evaluations_of_other_specimens_are_refused_by_name(tmp_path, capsys):
    baseline = evaluation([1, 0, 1], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="seeds 2000000–2000002 are not the baseline's 1000000–1000002"):
        compare(baseline, evaluation([1, 1, 1], [1.0, 1.0, 1.0], first_seed=2_000_000))
    with pytest.raises(ValueError, match="model 'planar'"):
        compare(baseline, evaluation([1, 1, 1], [1.0, 1.0, 1.0], model="planar"))
    (tmp_path / "a.json").write_text(json.dumps(baseline))
    (tmp_path / "b.json").write_text(json.dumps(evaluation([1, 1, 1], [1.0, 1.0, 1.0], first_seed=5)))
    with pytest.raises(SystemExit):
        main([str(tmp_path / "a.json"), str(tmp_path / "b.json")])
    assert "are not the baseline's" in capsys.readouterr().err


def test_the_command_prints_a_table_and_writes_the_comparison(tmp_path, capsys):
    rng = np.random.default_rng(7)
    files = []
    for k, rate in enumerate((0.8, 0.95, 0.9)):
        path = tmp_path / f"{k}.json"
        path.write_text(json.dumps(evaluation(rng.random(40) < rate, rng.normal(1.5, 0.1, 40), policy=f"run{k}")))
        files.append(str(path))
    summary = main([*files, "--json", str(tmp_path / "out" / "compare.json")])
    printed = capsys.readouterr().out
    assert "| run1 |" in printed and "pooled over 2 policies" in printed
    written = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert written["comparisons"][0]["wins"] == summary["comparisons"][0]["wins"]
    assert written["pooled"]["policies"] == 2


def test_success_by_radius_splits_the_specimens_into_equal_bands_of_radius(tmp_path, capsys):
    radii = [0.045, 0.046, 0.050, 0.052, 0.055, 0.060]  # bands 0.045–0.04875–0.0525–0.05625–0.06
    baseline = evaluation([0, 1, 1, 1, 1, 1], [1.0] * 6, policy="base")
    policy = evaluation([1, 1, 0, 1, 1, 0], [1.0] * 6, policy="ppo")
    for result in (baseline, policy):
        result["object_radii_m"] = radii
    assert list(by_radius(baseline, [policy, policy, policy])["policies"]) == ["ppo", "ppo (2)", "ppo (3)"]
    bands = by_radius(baseline, [policy])
    assert bands["specimens"] == [2, 2, 1, 1]
    assert bands["baseline"] == [0.5, 1.0, 1.0, 1.0]
    assert bands["policies"]["ppo"] == [1.0, 0.5, 1.0, 0.0]
    assert bands["baseline_successes"] == [1, 2, 1, 1] and bands["policy_successes"] == {"ppo": [2, 1, 1, 0]}
    assert bands["edges_m"] == pytest.approx([0.045, 0.04875, 0.0525, 0.05625, 0.06])
    (tmp_path / "a.json").write_text(json.dumps(baseline))
    (tmp_path / "b.json").write_text(json.dumps(policy))
    summary = main([str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--plot", str(tmp_path / "radius.png")])
    assert summary["by_radius"] == bands
    assert "| 4.50–4.88 | 2 | 0.50 | 1.00 |" in capsys.readouterr().out
    assert (tmp_path / "radius.png").stat().st_size > 10_000


def test_success_by_radius_needs_every_evaluation_to_record_the_same_radii(tmp_path, capsys):
    baseline = evaluation([1, 0, 1], [1.0] * 3)
    policy = evaluation([1, 1, 1], [1.0] * 3)
    assert by_radius(baseline, [policy]) is None  # evaluations written before radii were recorded
    (tmp_path / "a.json").write_text(json.dumps(baseline))
    (tmp_path / "b.json").write_text(json.dumps(policy))
    with pytest.raises(SystemExit):
        main([str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--plot", str(tmp_path / "radius.png")])
    assert "did not record" in capsys.readouterr().err and not (tmp_path / "radius.png").exists()
    baseline["object_radii_m"] = [0.05, 0.055, 0.06]
    policy["object_radii_m"] = [0.05, 0.055, 0.059]
    with pytest.raises(ValueError, match="radii are not the baseline's"):
        by_radius(baseline, [policy])
