"""docs/training.md's Python runs as written: the SB3 quick start (with a training budget of one rollout instead of
600,000 steps), the shipped policy in a user's own loop, and the CleanRL-style vector loop."""

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
BLOCKS = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "training.md").read_text(), re.S)


def _run(block: str) -> dict:
    namespace: dict = {}
    exec(compile(block, "docs/training.md", "exec"), namespace)  # noqa: S102 - our own documentation
    return namespace


def test_the_page_has_its_three_examples():
    assert len(BLOCKS) == 3
    assert "model.learn(total_timesteps=600_000)" in BLOCKS[0]


@pytest.mark.slow
def test_the_sb3_quick_start_trains_and_saves(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    namespace = _run(BLOCKS[0].replace("total_timesteps=600_000", "total_timesteps=256"))
    assert namespace["model"].num_timesteps == 128 * 32  # one rollout
    assert (tmp_path / "out/my_ppo/ppo_model.zip").exists() and (tmp_path / "out/my_ppo/vecnormalize.pkl").exists()
    namespace["env"].close()


def test_the_shipped_policy_runs_in_a_users_loop(monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    namespace = _run(BLOCKS[1])
    assert namespace["done"]
    assert namespace["env"].unwrapped.task.touching_closing_rate == 0.15
    assert capsys.readouterr().out.startswith("success: ")


def test_the_vector_loop_keeps_only_real_transitions():
    """Run as written, with a recorder after each step: the steps the loop drops are exactly the autoreset steps
    (reward 0, neither terminated nor truncated), and there are some (episodes last at most 80 of its 100 steps)."""
    recorded = []
    record = "    observation = next_observation\n"
    assert record in BLOCKS[2]
    block = BLOCKS[2].replace(record, record + "    _record(keep, reward, terminated, truncated)\n")
    namespace = {"_record": lambda *arrays: recorded.append([np.array(a) for a in arrays])}
    exec(compile(block, "docs/training.md", "exec"), namespace)  # noqa: S102 - our own documentation
    keep, reward, terminated, truncated = (np.array(column) for column in zip(*recorded, strict=True))
    assert keep.shape == (100, 8) and (~keep).any()
    dropped = ~keep
    assert np.all(reward[dropped] == 0.0) and not terminated[dropped].any() and not truncated[dropped].any()
    assert np.array_equal(dropped[1:], terminated[:-1] | truncated[:-1])  # the step after an episode ends
