"""Static solutions against closed forms: the circular arc of uniform natural curvature, and the cantilever elastica
(computed here, independently of the library, by shooting)."""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from examples.analytic import cantilever_elastica_tip
from soft_gripper_env.physics import GripperDesign, NewtonSettings, Scene, Simulator, cantilever_scene, paper_finger


def settle(scene, natural_curvature=0.0):
    sim = Simulator(scene)
    result = sim.equilibrium(sim.initial_state(), natural_curvature)
    assert result.converged.all()
    return sim, result.state


@pytest.mark.parametrize("model", ["planar", "3d"])
@pytest.mark.parametrize("kappa_bar", [-0.15, -0.45, 0.3])
def test_uniform_natural_curvature_gives_exact_arc(model, kappa_bar):
    finger = paper_finger(n_nodes=12)
    scene = Scene(GripperDesign(finger, finger_angles=(0.7,)), forces=(), model=model,
                  newton=NewtonSettings(relative_tolerance=1e-12))
    sim, state = settle(scene, kappa_bar)
    x = sim.world_positions(state)[0, 0]
    e = np.diff(x, axis=0)
    cross = np.cross(e[:-1], e[1:])
    angle = np.arctan2(np.linalg.norm(cross, axis=1), np.sum(e[:-1] * e[1:], axis=1))
    expected = 2 * math.atan(abs(kappa_bar) / 2)
    np.testing.assert_allclose(angle, expected, rtol=1e-8, atol=0)
    # Negative κ̄ curls toward −z, positive toward +z, and the arc stays in the finger's vertical plane.
    assert np.sign(x[-1, 2]) == np.sign(kappa_bar)
    direction = np.array([math.cos(0.7), math.sin(0.7), 0.0])
    lateral = x - np.outer(x @ direction, direction) - np.outer(x[:, 2], [0, 0, 1])
    assert np.abs(lateral).max() < 1e-12
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), finger.edge_length, rtol=1e-10)


def elastica_tip_deflection_by_shooting(length, load, stiffness, axial_stiffness=math.inf):
    """Tip z (negative) of a cantilever elastica under uniform weight ``load`` per reference length, by shooting on
    θ'(0). With finite ``axial_stiffness`` EA the rod also stretches by ε = T/EA, T = w·(L − s)·sin θ the tension:
    EI·θ'' = −w·(L − s)·(1 + ε)·cos θ, z' = −(1 + ε)·sin θ, θ(0) = 0, θ'(L) = 0."""

    def rhs(s, y):
        strain = load * (length - s) * math.sin(y[0]) / axial_stiffness
        return [y[1], -load / stiffness * (length - s) * (1 + strain) * math.cos(y[0]), -(1 + strain) * math.sin(y[0])]

    def shoot(curvature_at_root):
        return solve_ivp(rhs, (0.0, length), [0.0, curvature_at_root, 0.0], rtol=1e-12, atol=1e-14).y[:, -1]

    root_curvature = brentq(lambda c: shoot(c)[1], 0.0, 2 * load * length**2 / stiffness, xtol=1e-15)
    return shoot(root_curvature)[2]


def cantilever_exact_tip_z(scene, extensible=False):
    finger = scene.gripper.finger
    area = math.pi * finger.radius**2
    load = finger.material.density * area * 9.81
    stiffness = finger.material.youngs_modulus * math.pi * finger.radius**4 / 4
    axial = finger.material.youngs_modulus * area if extensible else math.inf
    return elastica_tip_deflection_by_shooting(finger.length, load, stiffness, axial)


def cantilever_tip_z(n_nodes, clamp, model="planar"):
    scene = replace(cantilever_scene(n_nodes, clamp, model), newton=NewtonSettings(relative_tolerance=1e-9))
    sim, state = settle(scene)
    return sim.world_positions(state)[0, 0, -1, 2], scene


def test_shooting_elastica_matches_library_bvp_and_published_value():
    scene = cantilever_scene()
    exact = cantilever_exact_tip_z(scene)
    finger = scene.gripper.finger
    load = finger.material.density * math.pi * finger.radius**2 * 9.81
    stiffness = finger.material.youngs_modulus * math.pi * finger.radius**4 / 4
    assert cantilever_elastica_tip(finger.length, load, stiffness)[1] == pytest.approx(exact, rel=1e-7)
    assert exact == pytest.approx(-14.95e-3, abs=0.01e-3)  # ``docs/model.md`` §4


def test_accurate_clamp_within_one_percent_at_20_nodes():
    tip, scene = cantilever_tip_z(20, "accurate")
    exact = cantilever_exact_tip_z(scene)
    assert abs(tip / exact - 1) <= 0.01


def test_paper_clamp_under_deflects_as_documented():
    tip, scene = cantilever_tip_z(20, "paper")
    shortfall = 1 - tip / cantilever_exact_tip_z(scene)
    assert 0.05 < shortfall < 0.15  # ``docs/model.md`` §4: about 10 % at N = 20


def test_accurate_clamp_converges_at_second_order():
    """The discrete rod stretches, so it converges to the extensible elastica, which sits 0.04 % below the classic
    inextensible one here; against it the error falls by 4× per doubling of nodes."""
    exact = cantilever_exact_tip_z(cantilever_scene(), extensible=True)
    nodes = np.array([10, 20, 40, 80, 160])
    errors = np.array([abs(cantilever_tip_z(n, "accurate")[0] / exact - 1) for n in nodes])
    assert np.all(np.diff(errors) < 0), errors
    order = -np.polyfit(np.log(nodes - 1.5), np.log(errors), 1)[0]
    assert 1.8 < order < 2.3, (errors, order)
    assert abs(cantilever_exact_tip_z(cantilever_scene()) / exact - 1) < 1e-3


def test_3d_cantilever_matches_planar():
    planar, _ = cantilever_tip_z(20, "accurate", "planar")
    spatial, _ = cantilever_tip_z(20, "accurate", "3d")
    assert spatial == pytest.approx(planar, abs=1e-9)
