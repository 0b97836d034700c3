"""Settle the shared cantilever benchmark (``docs/model.md`` §4) and compare its static tip with the exact elastica.

    python -m examples.cantilever --nodes 20 --clamp accurate [--model planar|3d] [--json out/cantilever.json]

Scene (SI): L = 0.1 m free length from the wall at x = 0, r = 0.01 m, E = 386.66 kPa, ρ = 1200 kg/m³,
g = 9.81 m/s² along −z, clamped horizontally. The exact reference is the inextensible elastica under the rod's
uniform weight (14.95 mm; Euler–Bernoulli's small-deflection formula gives 15.22 mm).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import replace
from pathlib import Path

from examples.analytic import cantilever_elastica_tip
from soft_gripper_env.physics import NewtonSettings, Simulator, cantilever_scene


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--nodes", type=int, default=20, help="number of nodes N (4 … 10000, default 20)")
    parser.add_argument("--clamp", choices=("paper", "accurate"), default="accurate",
                        help="clamp convention (default: accurate)")
    parser.add_argument("--model", choices=("planar", "3d"), default="planar", help="rod model (default: planar)")
    parser.add_argument("--json", type=Path, help="also write the result to this JSON file")
    args = parser.parse_args(argv)

    try:
        scene = replace(cantilever_scene(args.nodes, args.clamp, args.model),
                        newton=NewtonSettings(relative_tolerance=1e-9))
    except ValueError as error:
        parser.error(str(error))
    sim = Simulator(scene)
    result = sim.equilibrium(sim.initial_state(), 0.0)
    if not result.converged.all():
        print("the static solve did not converge", file=sys.stderr)
        return 1
    tip = sim.world_positions(result.state)[0, 0, -1]

    finger = scene.gripper.finger
    area = math.pi * finger.radius**2
    load = finger.material.density * area * 9.81
    stiffness = finger.material.youngs_modulus * math.pi * finger.radius**4 / 4
    exact_x, exact_z = cantilever_elastica_tip(finger.length, load, stiffness)
    euler_bernoulli = -load * finger.length**4 / (8 * stiffness)
    error = tip[2] / exact_z - 1

    print(f"cantilever, N = {args.nodes}, {args.clamp} clamp, {args.model} model")
    print(f"  simulated tip z      {tip[2] * 1e3:9.4f} mm")
    print(f"  exact elastica tip z {exact_z * 1e3:9.4f} mm")
    print(f"  relative error       {error * 100:+9.3f} %")
    print(f"  (Euler–Bernoulli     {euler_bernoulli * 1e3:9.4f} mm, small-deflection theory)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({
            "n_nodes": args.nodes, "clamp": args.clamp, "model": args.model,
            "tip_x_m": float(tip[0]), "tip_z_m": float(tip[2]),
            "exact_tip_x_m": exact_x, "exact_tip_z_m": exact_z,
            "relative_error": float(error), "euler_bernoulli_tip_z_m": euler_bernoulli,
        }, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
