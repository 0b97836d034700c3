"""The package's layers import in one direction only (docs/design.md), checked by import-linter's contracts in
pyproject.toml, and every module of the package sits in one of the layers."""

import sys
from pathlib import Path

import pytest
import tomllib

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]


def test_import_contracts_are_kept(monkeypatch, capsys):
    pytest.importorskip("importlinter")
    from importlinter.cli import lint_imports

    monkeypatch.chdir(ROOT)
    monkeypatch.syspath_prepend(str(ROOT))
    code = lint_imports(config_filename=str(ROOT / "pyproject.toml"), no_cache=True)
    report = capsys.readouterr().out
    assert code == 0, report
    assert "2 kept, 0 broken" in report


def test_every_module_is_in_a_layer():
    layers = next(c for c in CONFIG["contracts"] if c["type"] == "layers")["layers"]
    assert layers[-4:] == ["soft_gripper_env.physics.simulator", "soft_gripper_env.physics.solvers",
                           "soft_gripper_env.physics.kernels", "soft_gripper_env.physics.scene"]
    facades = {"soft_gripper_env", "soft_gripper_env.physics"}  # package __init__s that re-export their layers
    unplaced = []
    for path in sorted((ROOT / "soft_gripper_env").rglob("*.py")):
        module = ".".join(path.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__")
        if module not in facades and not any(module == layer or module.startswith(layer + ".") for layer in layers):
            unplaced.append(module)
    assert not unplaced, f"modules outside every layer of the contract: {unplaced}"


def test_the_core_runs_without_the_rl_stack():
    """The physics core imports and steps with torch, gymnasium and stable-baselines3 blocked."""
    import subprocess
    import textwrap

    code = textwrap.dedent("""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ('torch', 'gymnasium', 'stable_baselines3', 'gym'):
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        import soft_gripper_env.physics as p
        sim = p.Simulator(p.paper_scene())
        assert sim.step(sim.initial_state(), -0.01).converged.all()
        assert not any(m.split('.')[0] in ('torch', 'gymnasium', 'stable_baselines3') for m in sys.modules)
        print('ok')
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
