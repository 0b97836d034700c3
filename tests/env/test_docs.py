"""docs/environment.md states the code's defaults, ranges, sizes and info keys: each table is read and checked
against the code, so a changed default makes the page fail here rather than go stale."""

import ast
import math
import re
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from soft_gripper_env.env import SoftGripperUnderwaterEnv, observation_bounds
from soft_gripper_env.grasp_task import MODEL_DEFAULTS, GraspTask, RewardWeights
from soft_gripper_env.physics import NewtonSettings

PAGE = (Path(__file__).resolve().parents[2] / "docs" / "environment.md").read_text()


def _table(marker: str) -> list[list[str]]:
    """The rows (cells stripped) of the Markdown table that follows the HTML comment ``marker``."""
    start = PAGE.index(f"<!-- {marker}")
    rows = []
    for line in PAGE[start:].splitlines()[1:]:
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in re.split(r"(?<!\\)\|", line)[1:-1]])
    return rows[2:]  # header and rule


ARGUMENTS = {row[0].strip("`"): row for row in _table("arguments-table")}


def _literal(cell: str):
    return ast.literal_eval(cell.strip("`").replace("−", "-"))


def _number(text: str) -> float:
    return math.inf if text == "inf" else float(text.replace("−", "-"))


def test_the_arguments_table_lists_every_task_field():
    assert set(ARGUMENTS) == {f.name for f in fields(GraspTask)}


@pytest.mark.parametrize("name", sorted(ARGUMENTS))
def test_each_stated_default_is_the_code_default(name):
    default_cell = ARGUMENTS[name][1]
    task = GraspTask()
    if default_cell == "the model's (below)":
        assert name in MODEL_DEFAULTS["3d"]
    elif name == "gripper":
        assert task.gripper.n_fingers == 3 and task.gripper.finger.n_nodes == 20
    elif name == "newton":
        assert task.newton == NewtonSettings(relative_tolerance=1e-4)
        assert default_cell == "`NewtonSettings(relative_tolerance=1e-4)`"
    elif name == "reward":
        stated = dict(re.findall(r"(\w+) ([\d.]+)", default_cell.split(":", 1)[1]))
        assert {k: float(v) for k, v in stated.items()} == {f.name: getattr(RewardWeights(), f.name)
                                                           for f in fields(RewardWeights)}
    else:
        assert _literal(default_cell) == getattr(task, name)


def _interval(text: str):
    """(low, high, low_inclusive, high_inclusive) of the first interval in ``text``, or None."""
    match = re.search(r"([\[(])\s*([−\-\d.e]+|inf)\s*,\s*([−\-\d.e]+|inf)\s*([\])])", text)
    if match is None:
        return None
    return _number(match[2]), _number(match[3]), match[1] == "[", match[4] == "]"


def _with(name: str, value):
    """The task with field ``name`` set to ``value`` shaped as the field is (scalar, pair, 3-vector)."""
    default = getattr(GraspTask(), name)
    if isinstance(default, tuple) and len(default) == 3:
        value = (value, 0.0, 0.0)
    elif isinstance(default, tuple):
        value = (value, value)
    elif isinstance(default, int) and math.isfinite(value) and value == int(value):
        value = int(value)
    # the slowing needs the touching bound set, or every value would be refused for that instead of its range
    context = {"touching_closing_rate": 0.1} if name == "approach_slowing_gap" else {}
    return GraspTask(**{name: value}, **context)


RANGED = sorted(name for name, row in ARGUMENTS.items() if _interval(row[3]) is not None
                and name not in ("curvature_range", "reward"))


@pytest.mark.parametrize("name", RANGED)
def test_each_stated_range_is_the_code_range(name):
    """Just outside a stated bound is refused with a message naming the field; at a closed bound, or just inside
    an open one, the value is not refused for its range (another field's rule may still object, e.g. a whole
    number of steps per action)."""
    low, high, low_inclusive, high_inclusive = _interval(ARGUMENTS[name][3])
    step = 1 if name == "friction_passes" else 1e-9 * max(1.0, abs(low), abs(high) if math.isfinite(high) else 1.0)
    outside = [low - step if low_inclusive else low]
    inside = [low if low_inclusive else low + step]
    if math.isfinite(high):
        outside.append(high + step if high_inclusive else high)
        inside.append(high if high_inclusive else high - step)
    elif not high_inclusive:
        outside.append(math.inf)
    for value in outside:
        with pytest.raises(ValueError, match=f"GraspTask.{name} = .* (outside the allowed range|must)"):
            _with(name, value)
    for value in inside:
        try:
            _with(name, value)
        except ValueError as error:
            assert "outside the allowed range" not in str(error) or f"GraspTask.{name} =" not in str(error), error
    if ARGUMENTS[name][3].startswith("`None` or"):
        assert getattr(_with_none(name), name) is None


def _with_none(name):
    if name == "approach_slowing_gap":
        return GraspTask(approach_slowing_gap=None, touching_closing_rate=0.1)
    return GraspTask(**{name: None})


def test_the_model_defaults_table_is_model_defaults():
    rows = _table("model-defaults-table")
    stated = {row[0].strip('`"'): row for row in rows}
    assert set(stated) == set(MODEL_DEFAULTS)
    for model, row in stated.items():
        task = GraspTask(model=model)
        assert float(row[1]) == MODEL_DEFAULTS[model]["physics_dt"] == task.physics_dt
        assert int(row[2]) == MODEL_DEFAULTS[model]["friction_passes"] == task.friction_passes
        assert int(row[3]) == task.substeps


def test_the_stated_observation_sizes_are_the_spaces():
    full_3d, full_planar, sensors = map(int, re.search(
        r"(\d+) values in 3-D, (\d+) planar \(`observation=\"full\"`\); (\d+) with `observation=\"sensors\"`",
        PAGE).groups())
    assert observation_bounds(GraspTask(model="3d"))[0].size == full_3d
    assert observation_bounds(GraspTask(model="planar"))[0].size == full_planar
    for model in ("3d", "planar"):
        assert observation_bounds(GraspTask(model=model, observation="sensors"))[0].size == sensors


def test_the_info_table_lists_every_info_key():
    start = PAGE.index("## Info")
    keys = set(re.findall(r"^\| `(\w+)` \|", PAGE[start:PAGE.index("\n## ", start + 1)], re.M))
    env = SoftGripperUnderwaterEnv(model="planar")
    _, info = env.reset(seed=0)
    assert keys == set(info)
    assert set(info["reward_terms"]) == {f.name for f in fields(RewardWeights)}
    assert np.asarray(info["finger_forces_N"]).shape == (3,)


def test_the_stated_time_limit_is_the_registered_one():
    import gymnasium as gym

    import soft_gripper_env  # noqa: F401 - registers the id

    spec = gym.spec("SoftGripperUnderwater-v0")
    task = GraspTask()
    assert spec.max_episode_steps == round(task.episode_duration / task.control_dt) == 80
    assert "80 actions of 0.05 s (4 s)" in PAGE
