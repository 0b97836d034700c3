"""The banded solve and the elimination of the rods from the coupled Newton system, against dense linear algebra."""

import numpy as np
import pytest

from soft_gripper_env.physics.kernels.linalg import (
    factor_banded_symmetric,
    solve_banded_symmetric_rod,
    solve_dense,
    solve_factored,
    solve_factored_six_columns,
)
from soft_gripper_env.physics.solvers.newton import eliminate_rods

N_NODES = 20


def _system(stride: int, seed: int, shape: tuple[int, int] | None = None):
    """A symmetric positive definite Newton matrix of one rod, dense (n, n) and in band storage (n, kd+1); ``shape``
    (n, kd) overrides the rod's."""
    rng = np.random.default_rng(seed)
    n, kd = shape if shape is not None else (N_NODES * stride, 3 * stride - 1)
    dense = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            dense[i, j] = dense[j, i] = rng.normal()
    dense += np.eye(n) * 4.0 * (kd + 1)  # diagonally dominant, as the mass term makes it
    band = np.zeros((n, kd + 1))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            band[i, kd - i + j] = dense[i, j]
    return dense, band, rng


def _dense_solve(dense, rhs, free):
    """A_FF⁻¹·rhs_F, zero on fixed DOFs."""
    x = np.zeros_like(rhs)
    x[free] = np.linalg.solve(dense[np.ix_(free, free)], rhs[free])
    return x


@pytest.mark.parametrize("stride", [2, 4])
def test_banded_solve_matches_dense(stride):
    dense, band, rng = _system(stride, 1)
    n = dense.shape[0]
    free = np.ones(n, dtype=bool)
    free[:2 * stride] = False  # the clamp
    free[rng.choice(n, 5, replace=False)] = False
    rhs = rng.normal(size=n)
    x = rhs.copy()
    assert solve_banded_symmetric_rod(band.copy(), x, free)
    np.testing.assert_allclose(x, _dense_solve(dense, rhs, free), rtol=1e-12, atol=1e-14)


def _assert_solves_from_first_rows(dense, band, free, firsts, rng):
    """For right-hand sides zero above each row in ``firsts``: the solve from that row has the bits of the solve
    from row 0, and both the dense solution."""
    n = dense.shape[0]
    factored = band.copy()
    assert factor_banded_symmetric(factored, free, np.empty(band.shape[1]))
    for first in firsts:
        rhs = np.zeros(n)
        rhs[first:] = rng.normal(size=n - first)
        full, partial = rhs.copy(), rhs.copy()
        solve_factored(factored, full, free, 0)
        solve_factored(factored, partial, free, first)
        np.testing.assert_array_equal(partial, full)
        np.testing.assert_allclose(full, _dense_solve(dense, rhs, free), rtol=1e-11, atol=1e-13)


def test_solve_from_a_first_row_is_the_full_solve():
    """A right-hand side zero above row ``first`` solves to the same bits from there as from row 0."""
    dense, band, rng = _system(4, 2)
    n = dense.shape[0]
    _assert_solves_from_first_rows(dense, band, np.ones(n, dtype=bool), (0, 1, 37, n - 1), rng)


@pytest.mark.parametrize("shape", [(1, 0), (5, 0), (2, 1), (7, 1), (9, 2), (10, 3), (3, 5), (41, 5), (79, 10)])
def test_paired_rows_at_every_edge(shape):
    """The triangular passes take two rows at a time: odd and even sizes, a band as wide as the matrix or of zero
    width, and every first row give the dense solution (and the same bits whatever the first row)."""
    dense, band, rng = _system(1, 5, shape)
    n = shape[0]
    _assert_solves_from_first_rows(dense, band, rng.random(n) > 0.2, range(n), rng)


@pytest.mark.parametrize("shape", [(1, 0), (6, 0), (9, 2), (3, 5), (40, 5), (79, 10)])
def test_six_columns_are_six_solves(shape):
    """The six right-hand sides solved together give each column the bits it gets alone, from every first row."""
    _, band, rng = _system(1, 7, shape)
    n = shape[0]
    free = rng.random(n) > 0.2
    factored = band.copy()
    assert factor_banded_symmetric(factored, free, np.empty(band.shape[1]))
    for first in range(n):
        rhs = np.zeros((n, 6))
        rhs[first:] = rng.normal(size=(n - first, 6))
        together = rhs.copy()
        solve_factored_six_columns(factored, together, free, first)
        for k in range(6):
            alone = rhs[:, k].copy()
            solve_factored(factored, alone, free, first)
            np.testing.assert_array_equal(together[:, k], alone)
    with pytest.raises(ValueError, match="6 columns"):
        solve_factored_six_columns(factored, np.zeros((n, 5)), free, 0)


@pytest.mark.parametrize("stride", [2, 4])
@pytest.mark.parametrize("held", [(15, 16, 17), (0, 1), (18, 19), (3, 12), ()])
def test_eliminate_rods_matches_the_dense_schur_complement(stride, held):
    """x0 = A_FF⁻¹·(−G)_F, X = A_FF⁻¹·(A·S)_F, the body's block Sᵀ·A·S − (A·S)_Fᵀ·X and its right-hand side
    (A·S)_Fᵀ·x0, for held nodes anywhere along the rod (the elimination only visits the rows S reaches)."""
    dense, band, rng = _system(stride, 3 + len(held))
    n = dense.shape[0]
    dim = 2 if stride == 2 else 3
    coupling = np.zeros((n, 6))
    free = np.ones(n, dtype=bool)
    free[:2 * stride] = False
    for node in held:
        rows = slice(node * stride, node * stride + dim)
        coupling[rows] = rng.normal(size=(dim, 6))
        free[rows] = False  # a stuck node moves with the body
    minus_g = rng.normal(size=n)
    x0, x_coupling = minus_g[None].copy(), np.zeros((1, n, 6))
    block, rhs, factored = np.zeros((1, 6, 6)), np.zeros((1, 6)), np.zeros(1, dtype=bool)
    scratch = (np.empty((n, 6)), np.empty(band.shape[1]))
    failures = eliminate_rods(band[None].copy(), coupling[None], free[None], np.ones(1, dtype=bool),
                              np.ones(1, dtype=bool), x0, x_coupling, block, rhs, factored, scratch)
    assert failures == 0 and factored[0]
    product = dense @ coupling
    expected_x0 = _dense_solve(dense, minus_g, free)
    expected_x = np.stack([_dense_solve(dense, product[:, k], free) for k in range(6)], axis=1)
    product_free = np.where(free[:, None], product, 0.0)
    np.testing.assert_allclose(x0[0], expected_x0, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(x_coupling[0], expected_x, rtol=1e-11, atol=1e-13)
    np.testing.assert_allclose(block[0], coupling.T @ product - product_free.T @ expected_x, rtol=1e-10,
                               atol=1e-10)
    np.testing.assert_allclose(rhs[0], product_free.T @ expected_x0, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("n", [1, 2, 6])
def test_dense_solve_solves_with_row_swaps(n):
    """A·x = b for random systems whose first pivots are zero or small, so that rows must be swapped, against the
    residual and NumPy's LAPACK solve."""
    rng = np.random.default_rng(n)
    for _ in range(20):
        a = rng.normal(size=(n, n))
        if n > 1:
            a[0, 0] = 0.0  # a zero first pivot: only a row swap gets past it
            a[1, 1] *= 1e-9
        b = rng.normal(size=n)
        x = b.copy()
        assert solve_dense(a.copy(), x)
        scale = np.abs(a).sum(axis=1) * np.abs(x).max()
        assert np.all(np.abs(a @ x - b) <= 1e-13 * scale)
        np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)


def test_dense_solve_refuses_singular_and_non_finite_systems():
    """A singular matrix (a repeated row), a NaN in the matrix, an infinite right-hand side: False, as a failed
    Newton step of the body."""
    singular = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 6.0], [0.0, 1.0, 1.0]])
    assert not solve_dense(singular.copy(), np.ones(3))
    broken = np.eye(3)
    broken[1, 2] = np.nan
    assert not solve_dense(broken, np.ones(3))
    assert not solve_dense(np.eye(3), np.array([1.0, np.inf, 0.0]))
