"""The physics core imports and runs without torch, gymnasium or stable-baselines3."""

import subprocess
import sys
import textwrap


def test_core_imports_without_rl_stack():
    code = textwrap.dedent("""
        import sys
        class Block:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in ('torch', 'gymnasium', 'stable_baselines3', 'gym'):
                    raise ImportError('blocked: ' + name)
        sys.meta_path.insert(0, Block())
        import soft_gripper_env, soft_gripper_env.physics as p
        sim = p.Simulator(p.paper_scene())
        assert sim.step(sim.initial_state(), -0.01).converged.all()
        assert not any(m.split('.')[0] in ('torch', 'gymnasium', 'stable_baselines3') for m in sys.modules)
        print('ok')
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ok"
