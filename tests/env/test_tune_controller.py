"""The reactive controller's tuning script: its grid, its choice, and a run that resumes and accumulates."""

import json

import pytest

from agents.tune_controller import choose, main, parse_grid, setting_key, settings_of


def test_the_grid_combines_every_value_and_refuses_what_the_controller_lacks():
    grid = parse_grid(["grip=0.2,0.3", "touch_force=none,0.1"])
    assert [setting_key(s) for s in settings_of(grid)] == [
        "grip=0.2 touch_force=none", "grip=0.2 touch_force=0.1", "grip=0.3 touch_force=none",
        "grip=0.3 touch_force=0.1"]
    for items, named in ((["grasp=0.2"], "'grasp'"), (["grip=none"], "touch_force only"), (["grip=a"], "not a number"),
                         (["grip"], "NAME=V1"), (["grip=0.2", "grip=0.3"], "twice")):
        with pytest.raises(ValueError, match=named):
            parse_grid(items)


def result(success, force):
    return {"success_rate": success, "mean_peak_contact_force_N": force}


def test_the_choice_is_the_most_successful_then_the_gentler_under_the_force_bound():
    results = {"a": result(0.90, 1.8), "b": result(0.92, 2.1), "c": result(0.92, 1.9), "d": result(0.85, 1.2)}
    assert choose(results, None) == "c"
    assert choose(results, 2.0) == "c"
    assert choose(results, 1.85) == "a"
    assert choose(results, 1.0) is None


def test_a_tuning_run_resumes_adds_another_grid_and_refuses_other_episodes(tmp_path, capsys):
    out = tmp_path / "tune.json"
    common = ["--model", "planar", "--seed", "40000", "--episodes", "2", "--workers", "1", "--json", str(out)]
    first = main(["--grid", "grip=0.2,0.3", "touch_force=0.1", *common, "--plot", str(tmp_path / "tune.png")])
    saved = json.loads(out.read_text())
    assert list(saved["results"]) == ["grip=0.2 touch_force=0.1", "grip=0.3 touch_force=0.1"]
    assert saved["chosen"] == first["chosen"] and (tmp_path / "tune.png").stat().st_size > 10_000
    for kept in saved["results"].values():
        assert len(kept["successes"]) == 2 and kept["success_rate"] == sum(kept["successes"]) / 2
    capsys.readouterr()
    again = main(["--grid", "grip=0.2,0.3", "touch_force=0.1", *common])
    assert "2 kept" in capsys.readouterr().out and again["results"] == first["results"]
    more = main(["--grid", "grip=0.4", "touch_force=0.1", *common])
    assert list(more["results"]) == [*first["results"], "grip=0.4 touch_force=0.1"]
    with pytest.raises(SystemExit):
        main(["--grid", "grip=0.2", *common[:-4], "--episodes", "3", "--workers", "1", "--json", str(out)])
    assert "other episodes" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--grid", "gain=-1", *common])
    assert "ReactivePolicy.gain" in capsys.readouterr().err
