"""Finite-difference checks of every energy's gradient and Hessian, planar and 3-D, at random curved configurations,
and of the force models' Jacobians."""

import numpy as np
import pytest

from soft_gripper_env.physics import (
    WATER,
    GripperDesign,
    MassProportionalDamping,
    Scene,
    StepContext,
    StokesDrag,
    cantilever_scene,
    evaluate_force,
    paper_finger,
)
from soft_gripper_env.physics.kernels.rod_3d import elastic_scratch, rod3d_elastic, rod3d_update_frames
from soft_gripper_env.physics.kernels.rod_planar import planar_elastic


def evaluate_force_model(model, disc, q, q_old, q_pred, dt, fluid=WATER):
    """One force model's force (flat) and dense Newton-matrix contribution at coordinates q (1, N, S) of a
    backward-Euler step of length dt from q_old with predictor q_pred, in ``fluid``."""
    D = disc.dim
    force = np.zeros(q.shape)
    band = np.zeros((1, disc.n_dofs, disc.band_width + 1))
    ctx = StepContext(time=0.3, start_positions=q_old[..., :D], velocity_derivative=1 / dt,
                      acceleration_derivative=1 / dt**2)
    evaluate_force(model, disc, fluid, ctx, q[..., :D], (q - q_old)[..., :D] / dt, (q - q_pred)[..., :D] / dt**2,
                   force[..., :D], band)
    return force.ravel(), band_to_dense(band[0])


def band_to_dense(band):
    n, kd1 = band.shape
    kd = kd1 - 1
    dense = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            dense[i, j] = dense[j, i] = band[i, kd - (i - j)]
    return dense


def rod_parameters(n_nodes, rng):
    """Non-uniform stiffnesses, so that an index slip in any stencil shows."""
    rest = rng.uniform(0.04, 0.06, n_nodes - 1)
    return dict(rest=rest, ea=rng.uniform(2.0, 4.0, n_nodes - 1), ei=rng.uniform(0.1, 0.3, n_nodes),
                gj=rng.uniform(0.1, 0.2, n_nodes), voronoi=rng.uniform(0.04, 0.06, n_nodes))


class PlanarRod:
    def __init__(self, rng, n_nodes=7):
        self.p = rod_parameters(n_nodes, rng)
        s = np.concatenate([[0.0], np.cumsum(self.p["rest"])])
        self.q = np.stack([s, np.zeros(n_nodes)], axis=1)[None] + rng.normal(scale=0.015, size=(1, n_nodes, 2))
        self.kappa_bar = np.array([rng.uniform(-0.6, 0.6)])
        self.n_nodes = n_nodes

    def evaluate(self, q, hessian=True):
        p = self.p
        force = np.zeros_like(q)
        band = np.zeros((1, q.size, 6))
        energy = planar_elastic(q, p["rest"], p["ea"], p["ei"], p["voronoi"], self.kappa_bar, force, band, hessian)
        return energy[0], -force.ravel(), band_to_dense(band[0])


class Rod3D:
    """A random curved, twisted rod whose start-of-step frames are adapted to it (tangents match, random directors)."""

    def __init__(self, rng, n_nodes=6):
        self.p = rod_parameters(n_nodes, rng)
        s = np.concatenate([[0.0], np.cumsum(self.p["rest"])])
        q = np.zeros((1, n_nodes, 4))
        q[0, :, 0] = s
        q[0, :, :3] += rng.normal(scale=0.012, size=(n_nodes, 3))
        q[0, :-1, 3] = rng.normal(scale=0.4, size=n_nodes - 1)
        self.q = q
        t = np.diff(q[0, :, :3], axis=0)
        t /= np.linalg.norm(t, axis=1)[:, None]
        a = rng.normal(size=t.shape)
        a -= np.sum(a * t, axis=1)[:, None] * t
        a /= np.linalg.norm(a, axis=1)[:, None]
        self.tangent, self.director = t[None], a[None]
        ref_twist = np.empty((1, n_nodes))
        rod3d_update_frames(q, self.tangent, self.director, np.zeros((1, n_nodes)), np.empty_like(self.tangent),
                            np.empty_like(self.director), ref_twist, elastic_scratch(n_nodes))
        self.ref_twist = ref_twist
        self.kappa_bar = np.array([rng.uniform(-0.6, 0.6)])
        self.n_nodes = n_nodes

    def evaluate(self, q, hessian=True):
        p = self.p
        force = np.zeros_like(q)
        band = np.zeros((1, q.size, 11))
        energy = rod3d_elastic(q, self.tangent, self.director, self.ref_twist, p["rest"], p["ea"], p["ei"], p["gj"],
                               p["voronoi"], self.kappa_bar, force, band, hessian)
        return energy[0], -force.ravel(), band_to_dense(band[0])


def finite_difference_jacobian(function, q, h):
    """Central differences −∂f/∂q, column by column, of a function returning a flat force (or gradient) vector."""
    columns = []
    for j in range(q.size):
        dq = np.zeros(q.size)
        dq[j] = h
        columns.append(-(function(q + dq.reshape(q.shape)) - function(q - dq.reshape(q.shape))) / (2 * h))
    return np.stack(columns, axis=1)


def energy_gradient_fd(rod, h=1e-6):
    q0 = rod.q.ravel()
    grad = np.zeros(q0.size)
    for j in range(q0.size):
        dq = np.zeros(q0.size)
        dq[j] = h
        grad[j] = (rod.evaluate((q0 + dq).reshape(rod.q.shape), False)[0]
                   - rod.evaluate((q0 - dq).reshape(rod.q.shape), False)[0]) / (2 * h)
    return grad


def energy_hessian_fd(rod, h):
    """Second central differences of the energy itself, Richardson-extrapolated (error O(h⁴))."""
    q0 = rod.q.ravel()
    n = q0.size

    def second_difference(step):
        energy = lambda d: rod.evaluate((q0 + d).reshape(rod.q.shape), False)[0]  # noqa: E731
        out = np.zeros((n, n))
        for i in range(n):
            for j in range(i, n):
                di = np.zeros(n)
                dj = np.zeros(n)
                di[i] = step
                dj[j] = step
                out[i, j] = out[j, i] = (energy(di + dj) - energy(di - dj) - energy(dj - di)
                                         + energy(-di - dj)) / (4 * step * step)
        return out

    return (4 * second_difference(h / 2) - second_difference(h)) / 3


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_planar_gradient_and_hessian(seed):
    rod = PlanarRod(np.random.default_rng(seed))
    _, grad, hess = rod.evaluate(rod.q)
    assert np.abs(grad).max() > 1.0  # a curved, stretched configuration: the check is not vacuous
    np.testing.assert_allclose(grad, energy_gradient_fd(rod), rtol=0, atol=1e-6 * np.abs(grad).max())
    # No frames in the planar model: the analytic gradient is exact everywhere, so difference it directly.
    fd = -finite_difference_jacobian(lambda q: rod.evaluate(q)[1], rod.q, 1e-6)
    np.testing.assert_allclose(hess, fd, rtol=0, atol=1e-6 * np.abs(hess).max())


@pytest.mark.parametrize("seed", [0, 1])
def test_3d_gradient_and_hessian(seed):
    rod = Rod3D(np.random.default_rng(seed))
    _, grad, hess = rod.evaluate(rod.q)
    assert np.abs(grad[3::4][:-1]).max() > 1e-2  # twist moments are exercised
    np.testing.assert_allclose(grad, energy_gradient_fd(rod), rtol=0, atol=1e-6 * np.abs(grad).max())
    # The frames are transported from the base configuration, so the analytic gradient is the true gradient only
    # there; compare the Hessian with second differences of the energy instead.
    np.testing.assert_allclose(hess, energy_hessian_fd(rod, 2e-4), rtol=0, atol=1e-5 * np.abs(hess).max())


@pytest.mark.parametrize("rod_kind", [PlanarRod, Rod3D])
def test_forces_do_not_depend_on_assembling_the_hessian(rod_kind):
    """Newton's convergence test assembles the forces alone and the matrix only when it iterates on
    (solvers/newton.py), which keeps trajectories bitwise only if the forces and energy come out the same bits either
    way."""
    for seed in range(3):
        rod = rod_kind(np.random.default_rng(10 + seed))
        energy, grad, hess = rod.evaluate(rod.q, True)
        energy_alone, grad_alone, hess_alone = rod.evaluate(rod.q, False)
        assert np.abs(hess).max() > 0.0 and not hess_alone.any()  # the flag does skip the matrix
        assert energy_alone == energy
        np.testing.assert_array_equal(grad_alone, grad)


@pytest.mark.parametrize("model", ["planar", "3d"])
@pytest.mark.parametrize("force_model", [StokesDrag(viscosity=0.7), MassProportionalDamping(rate=3.0)])
def test_velocity_force_jacobian(model, force_model):
    """The Jacobian a force adds equals −d f/d q along v = (q − q_old)/Δt, by finite differences."""
    scene = Scene(GripperDesign(paper_finger(variable_stiffness=True), finger_angles=(0.0,)), forces=(force_model,),
                  model=model)
    disc = scene.discretization()
    rng = np.random.default_rng(3)
    N, S = disc.n_nodes, disc.stride
    dt = 0.01
    q_old = rng.normal(size=(1, N, S))

    def force_and_band(q):
        return evaluate_force_model(force_model, disc, q, q_old, q_old, dt)

    q = q_old + rng.normal(scale=1e-3, size=q_old.shape)
    f0, jac = force_and_band(q)
    assert np.abs(f0).max() > 0
    fd = finite_difference_jacobian(lambda x: force_and_band(x)[0], q, 1e-7)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-9 * np.abs(jac).max())


def test_gravity_only_has_no_jacobian_and_pulls_down():
    disc = cantilever_scene().discretization()
    q = disc.rest_q[:1]
    (model,) = cantilever_scene().forces
    force, band = evaluate_force_model(model, disc, q, q, q, 0.01)
    assert not band.any()
    np.testing.assert_allclose(force.reshape(-1, 2)[:, 1], -disc.node_mass * 9.81)
    np.testing.assert_allclose(force.reshape(-1, 2)[:, 0], 0.0)


@pytest.mark.parametrize("n, kd", [(12, 5), (40, 10)])
def test_banded_solver_matches_dense_solve(n, kd):
    from soft_gripper_env.physics.kernels.linalg import solve_banded_symmetric_rod

    rng = np.random.default_rng(n)
    dense = np.zeros((n, n))
    for k in range(kd + 1):
        values = rng.normal(size=n - k) * (0.3 if k else 1.0)
        dense += np.diag(values, -k) + (np.diag(values, k) if k else 0)
    dense += np.diag(np.full(n, 2.0 * kd))  # diagonally dominant but with mixed-sign entries
    band = np.zeros((n, kd + 1))
    for i in range(n):
        for j in range(max(0, i - kd), i + 1):
            band[i, kd - (i - j)] = dense[i, j]
    free = np.ones(n, dtype=bool)
    free[[0, 3, n - 1]] = False
    rhs = rng.normal(size=n)
    x = rhs.copy()
    assert solve_banded_symmetric_rod(band.copy(), x, free)
    reduced = dense[np.ix_(free, free)]
    expected = np.zeros(n)
    expected[free] = np.linalg.solve(reduced, rhs[free])
    np.testing.assert_allclose(x, expected, rtol=1e-12, atol=1e-12)
    assert band_to_dense(band) == pytest.approx(dense)
    singular = np.zeros((n, kd + 1))
    x = rhs.copy()
    assert not solve_banded_symmetric_rod(singular, x, free)
    assert np.isnan(x).all()
