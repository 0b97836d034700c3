"""Golden outputs for refactors: record what the simulator and the env produce, and compare two recordings.

    python -m tools.golden_outputs record out/golden/before.npz [--quick]
    python -m tools.golden_outputs compare out/golden/before.npz out/golden/after.npz

A refactor that keeps the arithmetic must reproduce every array bit for bit; one that reorders floating-point
operations must stay within ``--tolerance`` (1e-12 by default, metres for positions). ``compare`` prints, per
array, whether it is bitwise equal, and the largest difference otherwise, and exits 1 if any array differs by more
than the tolerance or is missing.

What is recorded (all through public interfaces, so that an older commit can be recorded by putting it first on
``PYTHONPATH``):

- the paper's scene with the ramp, planar and 3-D: Stokes drag, water, the defective drag, variable stiffness, and
  the fixed paper ball with its contact reactions;
- the cantilever with each integrator;
- a batch of four grippers, each with its own free sphere and current (the env's scene distribution);
- env episodes, planar and 3-D, with the ramp and the reactive policy: observations, rewards and infos.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def _ramp_runs(out: dict, quick: bool) -> None:
    from dataclasses import replace

    from soft_gripper_env.physics import PAPER_BALL, PAPER_DEFECTIVE_DRAG, paper_scene, run_ramp

    for model in ("planar", "3d"):
        cases = {
            "stokes": paper_scene(model),
            "water": paper_scene(model, medium="water"),
            "defective": paper_scene(model, medium=(PAPER_DEFECTIVE_DRAG,)),
            "taper": paper_scene(model, variable_stiffness=True),
            "ball": paper_scene(model, grasped_object=PAPER_BALL),
        }
        if quick:
            cases = {k: replace(v, duration=0.3) for k, v in cases.items()}
        for name, scene in cases.items():
            run = run_ramp(scene)
            key = f"ramp/{model}/{name}"
            out[f"{key}/positions"] = run.positions
            out[f"{key}/newton_iterations"] = run.newton_iterations
            for field in ("q", "velocity"):
                out[f"{key}/final_{field}"] = getattr(run.final_state, field)
            if run.contacts:
                out[f"{key}/reaction"] = np.stack([c.reaction for c in run.contacts])
                out[f"{key}/normal_reaction"] = np.stack([c.normal_reaction for c in run.contacts])
                out[f"{key}/held"] = np.stack([c.held for c in run.contacts])
                out[f"{key}/corrector_iterations"] = np.stack([c.corrector_iterations for c in run.contacts])


def _cantilever(out: dict, quick: bool) -> None:
    from dataclasses import replace

    from soft_gripper_env.physics import Simulator, cantilever_scene

    for integrator in ("backward_euler", "implicit_midpoint", "midpoint_triple_jump", "midpoint_suzuki"):
        for model in ("planar", "3d"):
            scene = replace(cantilever_scene(model=model), integrator=integrator)
            sim = Simulator(scene)
            state = sim.initial_state()
            tips = []
            for _ in range(10 if quick else 50):
                state = sim.step(state, 0.0).state
                tips.append(sim.world_positions(state)[:, :, -1])
            out[f"cantilever/{integrator}/{model}/tips"] = np.stack(tips)
            out[f"cantilever/{integrator}/{model}/final_q"] = state.q
        equilibrium = Simulator(cantilever_scene()).equilibrium(Simulator(cantilever_scene()).initial_state(), 0.0)
        out["cantilever/equilibrium_q"] = equilibrium.state.q


def _free_sphere_batch(out: dict, quick: bool) -> None:
    from soft_gripper_env.grasp_task import GraspTask, task_episode
    from soft_gripper_env.physics import Simulator

    for model in ("planar", "3d"):
        task = GraspTask(model=model)
        rng = np.random.default_rng(7)
        scenes = [task_episode(task, rng, {}).scene for _ in range(4)]
        sim = Simulator(scenes)
        state = sim.initial_state()
        kbar = np.zeros((4, 3))
        rates = np.array([[-0.3, -0.3, -0.3], [-0.2, -0.25, -0.3], [-0.15, -0.15, -0.15], [-0.4, -0.3, -0.2]])
        positions, body, normal = [], [], []
        for _ in range(30 if quick else 120):
            result = sim.step(state, kbar)
            state = result.state
            kbar = np.clip(kbar + rates * task.physics_dt, -0.2, 0.0)
            positions.append(state.q)
            body.append(np.concatenate([state.body_position, state.body_velocity,
                                        state.body_orientation.reshape(4, 9), state.body_angular_velocity], axis=1))
            normal.append(result.contact.normal_reaction)
        key = f"free_sphere/{model}"
        out[f"{key}/q"] = np.stack(positions)
        out[f"{key}/body"] = np.stack(body)
        out[f"{key}/normal_reaction"] = np.stack(normal)


def _episodes(out: dict, quick: bool) -> None:
    import gymnasium as gym

    import soft_gripper_env  # noqa: F401  (registers the env)
    from agents.scripted import RampPolicy, ReactivePolicy
    from soft_gripper_env.grasp_task import GraspTask

    runs = [("planar", 0), ("planar", 1), ("3d", 0)]
    for model, seed in runs:
        for name, policy_class in (("ramp", RampPolicy), ("reactive", ReactivePolicy)):
            env = gym.make("SoftGripperUnderwater-v0", model=model)
            policy = policy_class(GraspTask(model=model))
            obs, info = env.reset(seed=seed)
            observations, rewards, terms, flags = [obs], [], [], []
            for _ in range(20 if quick else 60):
                obs, reward, terminated, truncated, info = env.step(policy(obs))
                observations.append(obs)
                rewards.append(reward)
                terms.append([info["reward_terms"][k] for k in sorted(info["reward_terms"])])
                flags.append([terminated, truncated, info["is_success"]])
                if terminated or truncated:
                    break
            key = f"episode/{model}/{seed}/{name}"
            out[f"{key}/observations"] = np.stack(observations)
            out[f"{key}/rewards"] = np.array(rewards)
            out[f"{key}/reward_terms"] = np.array(terms)
            out[f"{key}/flags"] = np.array(flags)
            env.close()


def record(path: Path, quick: bool) -> None:
    out: dict[str, np.ndarray] = {}
    for part in (_ramp_runs, _cantilever, _free_sphere_batch, _episodes):
        print(f"golden: {part.__name__.strip('_')} …", flush=True)
        part(out, quick)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **out)
    print(f"golden: {len(out)} arrays into {path}")


def compare(before: Path, after: Path, tolerance: float) -> bool:
    a, b = np.load(before), np.load(after)
    ok = True
    bitwise = 0
    for key in sorted(set(a.files) | set(b.files)):
        if key not in a.files or key not in b.files:
            print(f"MISSING  {key} (only in {'after' if key in b.files else 'before'})")
            ok = False
            continue
        x, y = a[key], b[key]
        if x.shape != y.shape:
            print(f"SHAPE    {key}: {x.shape} against {y.shape}")
            ok = False
        elif np.array_equal(x, y, equal_nan=True):
            bitwise += 1
        else:
            gap = float(np.nanmax(np.abs(x.astype(float) - y.astype(float))))
            within = gap <= tolerance
            ok &= within
            print(f"{'CLOSE' if within else 'DIFFERS'}  {key}: largest difference {gap:.3e}")
    print(f"golden: {bitwise} of {len(set(a.files) | set(b.files))} arrays bitwise equal; "
          f"{'all within' if ok else 'NOT all within'} {tolerance:g}")
    return ok


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    commands = parser.add_subparsers(dest="command", required=True)
    rec = commands.add_parser("record", help="record the golden outputs of the code on the path")
    rec.add_argument("path", type=Path)
    rec.add_argument("--quick", action="store_true", help="shorter runs (about a third of the time)")
    cmp = commands.add_parser("compare", help="compare two recordings")
    cmp.add_argument("before", type=Path)
    cmp.add_argument("after", type=Path)
    cmp.add_argument("--tolerance", type=float, default=1e-12)
    args = parser.parse_args(argv)
    if args.command == "record":
        record(args.path, args.quick)
        return 0
    return 0 if compare(args.before, args.after, args.tolerance) else 1


if __name__ == "__main__":
    sys.exit(main())
