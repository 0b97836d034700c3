"""Closed-form and converged reference solutions the simulator is checked against."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_bvp


def cantilever_elastica_tip(length: float, load_per_length: float, bending_stiffness: float) -> tuple[float, float]:
    """Tip of an inextensible cantilever (elastica) clamped horizontally, under a uniform vertical load.

    ``length`` L [m], ``load_per_length`` w [N/m] acting along −z, ``bending_stiffness`` EI [N·m²]. With θ(s) the
    tangent's angle below the horizontal, the moment balance EI·θ'' = −w·(L − s)·cos θ with θ(0) = 0 and θ'(L) = 0 is
    solved as a boundary-value problem. Returns the tip position (x, z) [m], z negative.
    """
    s = np.linspace(0.0, length, 201)

    def rhs(s, y):  # y = (θ, θ', x, z)
        return np.vstack([y[1], -load_per_length / bending_stiffness * (length - s) * np.cos(y[0]),
                          np.cos(y[0]), -np.sin(y[0])])

    def boundary(ya, yb):
        return np.array([ya[0], yb[1], ya[2], ya[3]])

    guess = np.zeros((4, s.size))
    guess[2] = s
    solution = solve_bvp(rhs, boundary, s, guess, tol=1e-10, max_nodes=100_000)
    if not solution.success:
        raise RuntimeError(f"elastica boundary-value solve failed: {solution.message}")
    tip = solution.sol(length)
    return float(tip[2]), float(tip[3])
