"""The one linear solve of the simulator: many small symmetric banded systems, one per rod.

This is the only place that depends on how the solve is done, so a GPU back end replaces this function alone.
Band storage is LAPACK's lower form: ``band[r, k, j]`` holds A[j + k, j] of rod r, k = 0 … kd.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def solve_banded_symmetric(band, rhs, free, active):
    """Solve A·x = rhs for every active rod in place (``rhs`` becomes x; ``band`` is overwritten by its factors).

    Rows and columns of DOFs where ``free`` is False are replaced by the identity with a zero right-hand side, so
    fixed DOFs get no update. A symmetric LDLᵀ factorisation without pivoting: the Newton matrix of an implicit step
    is dominated by its positive mass term, and LDLᵀ costs about a third less than a general band LU.

    band: (R, kd+1, n); rhs: (R, n); free: (n,) bool; active: (R,) bool. Returns the number of rods whose
    factorisation met a zero or non-finite pivot (their solution is set to NaN).
    """
    n_rods, kd1, n = band.shape
    kd = kd1 - 1
    failures = 0
    for r in range(n_rods):
        if not active[r]:
            continue
        a = band[r]
        x = rhs[r]
        for j in range(n):
            if not free[j]:
                for k in range(kd1):
                    a[k, j] = 0.0
                for k in range(1, min(kd, j) + 1):
                    a[k, j - k] = 0.0
                a[0, j] = 1.0
                x[j] = 0.0
        ok = True
        for j in range(n):
            d = a[0, j]
            for k in range(max(0, j - kd), j):
                ljk = a[j - k, k]
                d -= ljk * ljk * a[0, k]
            if d == 0.0 or not np.isfinite(d):
                ok = False
                break
            a[0, j] = d
            for i in range(j + 1, min(n, j + kd1)):
                s = a[i - j, j]
                for k in range(max(0, i - kd), j):
                    s -= a[i - k, k] * a[j - k, k] * a[0, k]
                a[i - j, j] = s / d
        if not ok:
            failures += 1
            x[:] = np.nan
            continue
        for j in range(n):  # L y = b
            s = x[j]
            for k in range(max(0, j - kd), j):
                s -= a[j - k, k] * x[k]
            x[j] = s
        for j in range(n):  # D z = y
            x[j] /= a[0, j]
        for j in range(n - 1, -1, -1):  # Lᵀ x = z
            s = x[j]
            for i in range(j + 1, min(n, j + kd1)):
                s -= a[i - j, j] * x[i]
            x[j] = s
    return failures
