"""The simulator's linear solves: many small symmetric banded systems, one per rod, and the small dense system of
a free body's step (:func:`solve_dense`).

The GPU back end (:mod:`..solvers.gpu`) compiles these same functions for the device.
Band storage is row-major: ``band[r, i, kd − (i − j)]`` holds A[i, j] of rod r for i − kd ≤ j ≤ i, so row i of the
lower triangle, diagonal last (``band[r, i, kd]``), is one contiguous run and the factorisation's inner loops are
contiguous dot products.
"""

from __future__ import annotations

import math

import numpy as np

from .compiled import kernel


@kernel(python=True)
def symmetric_band_entry(band, i, j):
    """A[i, j] of one rod's symmetric band (n, kd+1), for |i − j| ≤ kd, read from the stored lower triangle."""
    kd = band.shape[1] - 1
    return band[i, kd - i + j] if j <= i else band[j, kd - j + i]


@kernel
def scatter_contiguous(band, offset, hessian, m):
    """Add the symmetric m×m ``hessian`` of DOFs offset … offset+m−1 into one rod's band (n, kd+1)."""
    kd = band.shape[1] - 1
    for a in range(m):  # indexed in place, no view of each row
        for b in range(a + 1):
            band[offset + a, kd - a + b] += hessian[a, b]


@kernel(python=True)
def factor_banded_symmetric(a, free, row_scratch):
    """Factor one rod's band (n, kd+1) in place as L·D·Lᵀ; returns False at a zero or non-finite pivot.
    ``row_scratch`` (kd+1,) is work space.

    Rows and columns of DOFs where ``free`` is False are replaced by the identity first, so that a solve gives them
    no update. A symmetric LDLᵀ factorisation without pivoting: the Newton matrix of an implicit step is dominated by
    its positive mass term, and LDLᵀ costs about a third less than a general band LU.
    """
    n, kd1 = a.shape
    kd = kd1 - 1
    for i in range(n):
        if not free[i]:
            a[i, :] = 0.0
            a[i, kd] = 1.0
            for k in range(1, min(kd, n - 1 - i) + 1):  # column i below the diagonal
                a[i + k, kd - k] = 0.0
    t = row_scratch
    for i in range(n):  # row-oriented LDLᵀ: t_k = L[i,k]·d_k, then L[i,k] = t_k/d_k
        j0 = max(0, i - kd)
        d = a[i, kd]
        # t_k = A[i,k] − Σ_{m<k} t_m·L[k,m], each sum in ascending m, four k's at a time: their sums share the terms
        # m < k, four chains the CPU overlaps, where one k at a time waits on each subtraction's latency (the same
        # subtractions in the same order). Each t_k's L[i,k] and its term of the pivot d_i follow at once, so that
        # the division overlaps the next sums, where a loop of its own after them waited on each. Row i is indexed
        # in place. Kernel alone, planar
        # and 3-D: two k's at a time and the indexing took a fifth off the factorisation; a while loop instead of a
        # range with a step of 2 a further fifth; the pivot's terms in this loop a seventh planar and a tenth in
        # 3-D; four k's instead of two a further seventh (which, before the while loop, had gained nothing)
        k = j0
        while k + 3 < i:  # a while loop: a range with a step of 2 took a quarter longer here (measured, not explained)
            s0 = a[i, kd - i + k]
            s1 = a[i, kd - i + k + 1]
            s2 = a[i, kd - i + k + 2]
            s3 = a[i, kd - i + k + 3]
            for m in range(j0, k):
                tm = t[m - j0]
                s0 -= tm * a[k, kd - k + m]
                s1 -= tm * a[k + 1, kd - k - 1 + m]
                s2 -= tm * a[k + 2, kd - k - 2 + m]
                s3 -= tm * a[k + 3, kd - k - 3 + m]
            s1 -= s0 * a[k + 1, kd - 1]  # the terms m = k, k+1, k+2 that the four sums take from each other
            s2 -= s0 * a[k + 2, kd - 2]
            s3 -= s0 * a[k + 3, kd - 3]
            s2 -= s1 * a[k + 2, kd - 1]
            s3 -= s1 * a[k + 3, kd - 2]
            s3 -= s2 * a[k + 3, kd - 1]
            t[k - j0] = s0
            t[k + 1 - j0] = s1
            t[k + 2 - j0] = s2
            t[k + 3 - j0] = s3
            lik = s0 / a[k, kd]
            d -= s0 * lik
            a[i, kd - i + k] = lik
            lik = s1 / a[k + 1, kd]
            d -= s1 * lik
            a[i, kd - i + k + 1] = lik
            lik = s2 / a[k + 2, kd]
            d -= s2 * lik
            a[i, kd - i + k + 2] = lik
            lik = s3 / a[k + 3, kd]
            d -= s3 * lik
            a[i, kd - i + k + 3] = lik
            k += 4
        while k < i:  # the last few, one at a time
            s = a[i, kd - i + k]
            for m in range(j0, k):
                s -= t[m - j0] * a[k, kd - k + m]
            t[k - j0] = s
            lik = s / a[k, kd]
            d -= s * lik
            a[i, kd - i + k] = lik
            k += 1
        if d == 0.0 or not math.isfinite(d):  # math's: the GPU build has no NumPy ufuncs
            return False
        a[i, kd] = d
    return True


@kernel(python=True)
def solve_factored(a, x, free, first):
    """Solve with a band factored by :func:`factor_banded_symmetric`, in place on ``x`` (n,); fixed DOFs get 0.
    ``x`` is zero above row ``first`` (0 where nothing is known), and so is L⁻¹·x: the forward passes start there.
    """
    n, kd1 = a.shape
    kd = kd1 - 1
    for i in range(n):
        if not free[i]:
            x[i] = 0.0
    # Both triangular passes take two rows at a time, as the factorisation does: each row's sum is a chain that waits
    # on every subtraction, and two rows' chains share their reads of x; the same subtractions in the same order
    # (bitwise the one-row result), about 0.6x the time planar and 3-D
    i = first
    while kd > 0 and i + 1 < n:  # L y = b, rows i and i+1: y_i = b_i − Σ L[i,k]·y_k in ascending k
        s0 = x[i]
        s1 = x[i + 1]
        k0 = i - kd
        if k0 >= 0:  # row i's first term, left of row i+1's band
            s0 -= a[i, 0] * x[k0]
        for k in range(max(0, k0 + 1), i):
            xk = x[k]
            s0 -= a[i, kd - i + k] * xk
            s1 -= a[i + 1, kd - i - 1 + k] * xk
        s1 -= a[i + 1, kd - 1] * s0  # its last term, k = i
        x[i] = s0
        x[i + 1] = s1
        i += 2
    if i < n:
        s = x[i]
        for k in range(max(0, i - kd), i):
            s -= a[i, kd - i + k] * x[k]
        x[i] = s
    for i in range(first, n):  # D z = y
        x[i] /= a[i, kd]
    i = n - 1
    while kd > 0 and i >= 1:  # Lᵀ x = z, rows i and i−1: each x_k takes row i's update, then row i−1's
        xi = x[i]
        xh = x[i - 1] - a[i, kd - 1] * xi
        x[i - 1] = xh
        for k in range(max(0, i - kd), i - 1):
            x[k] = x[k] - a[i, kd - i + k] * xi - a[i - 1, kd - i + 1 + k] * xh
        k = i - 1 - kd
        if k >= 0:  # row i−1's first term, left of row i's band
            x[k] -= a[i - 1, 0] * xh
        i -= 2
    # row 0, if left over, updates nothing (and with kd = 0, L is the identity)


@kernel(python=True)
def solve_factored_six_columns(a, x, free, first):
    """:func:`solve_factored` for six right-hand sides at once (a rigid body's six DOFs), in place on the columns
    of ``x`` (n, 6): each column gets the same operations in the same order as alone, so the same bits.
    """
    n, kd1 = a.shape
    kd = kd1 - 1
    if x.shape[1] != 6:
        raise ValueError("solve_factored_six_columns: x must have 6 columns")
    # six sums per row held in registers: six independent chains where one column waits on each subtraction, and
    # one read of L for all six; about half the time of six paired single solves
    for i in range(n):
        if not free[i]:
            x[i, :] = 0.0
    for i in range(first, n):  # L y = b
        s0, s1, s2, s3, s4, s5 = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5]
        for k in range(max(0, i - kd), i):
            lik = a[i, kd - i + k]
            s0 -= lik * x[k, 0]
            s1 -= lik * x[k, 1]
            s2 -= lik * x[k, 2]
            s3 -= lik * x[k, 3]
            s4 -= lik * x[k, 4]
            s5 -= lik * x[k, 5]
        x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5] = s0, s1, s2, s3, s4, s5
    for i in range(first, n):  # D z = y
        d = a[i, kd]
        for c in range(6):
            x[i, c] /= d
    for i in range(n - 1, -1, -1):  # Lᵀ x = z
        x0, x1, x2, x3, x4, x5 = x[i, 0], x[i, 1], x[i, 2], x[i, 3], x[i, 4], x[i, 5]
        for k in range(max(0, i - kd), i):
            lik = a[i, kd - i + k]
            x[k, 0] -= lik * x0
            x[k, 1] -= lik * x1
            x[k, 2] -= lik * x2
            x[k, 3] -= lik * x3
            x[k, 4] -= lik * x4
            x[k, 5] -= lik * x5


@kernel(python=True, runtime=True)  # it allocates
def solve_banded_symmetric_rod(a, x, free):
    """Solve A·x = b for one rod in place: ``x`` holds b on entry and the solution on return; ``a`` (n, kd+1) is
    overwritten by its factors. Returns False if a pivot was zero or not finite (``x`` is then NaN)."""
    if not factor_banded_symmetric(a, free, np.empty(a.shape[1])):
        x[:] = np.nan
        return False
    solve_factored(a, x, free, 0)
    return True


@kernel(python=True)
def solve_dense(a, x):
    """Solves A·x = b in place by Gaussian elimination with partial pivoting (rows swapped to the largest pivot of
    each column): ``x`` (n,) holds b on entry and the solution on return; ``a`` (n, n) is overwritten. Returns False,
    leaving ``x`` unsolved, where a pivot is zero or an entry is not finite. For the few unknowns of a free body's
    Newton step; the same code on the CPU and the GPU."""
    n = x.shape[0]
    for i in range(n):
        if not math.isfinite(x[i]):
            return False
        for j in range(n):
            if not math.isfinite(a[i, j]):
                return False
    for k in range(n):
        pivot_row = k
        for i in range(k + 1, n):
            if abs(a[i, k]) > abs(a[pivot_row, k]):
                pivot_row = i
        if a[pivot_row, k] == 0.0:
            return False
        if pivot_row != k:
            for j in range(k, n):
                a[k, j], a[pivot_row, j] = a[pivot_row, j], a[k, j]
            x[k], x[pivot_row] = x[pivot_row], x[k]
        for i in range(k + 1, n):
            factor = a[i, k] / a[k, k]
            for j in range(k + 1, n):
                a[i, j] -= factor * a[k, j]
            x[i] -= factor * x[k]
    for k in range(n - 1, -1, -1):
        value = x[k]
        for j in range(k + 1, n):
            value -= a[k, j] * x[j]
        x[k] = value / a[k, k]
    return True
