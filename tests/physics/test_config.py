"""Bad configurations raise ValueError naming the field, its unit and the allowed range."""

from dataclasses import replace

import numpy as np
import pytest

from soft_gripper_env.physics import (
    ELASTOSIL_MA_4601,
    Buoyancy,
    FingerDesign,
    Fluid,
    Gravity,
    GripperDesign,
    MassProportionalDamping,
    Material,
    NewtonSettings,
    Scene,
    Simulator,
    StokesDrag,
    paper_finger,
    paper_scene,
)


@pytest.mark.parametrize("make, pattern", [
    (lambda: Material("x", youngs_modulus=-1.0, density=1000.0), r"Material\.youngs_modulus = -1\.0 Pa .*\(0, inf\)"),
    (lambda: Material("x", youngs_modulus=1e5, density=float("nan")), r"Material\.density = nan kg/m³"),
    (lambda: FingerDesign(0.0, 20, 0.02, ELASTOSIL_MA_4601), r"FingerDesign\.length = 0\.0 m"),
    (lambda: FingerDesign(0.2, 3, 0.02, ELASTOSIL_MA_4601), r"FingerDesign\.n_nodes = 3 .*\[4, 10000\]"),
    (lambda: FingerDesign(0.2, 20.5, 0.02, ELASTOSIL_MA_4601), r"FingerDesign\.n_nodes"),
    (lambda: FingerDesign(0.2, 20, 0.3, ELASTOSIL_MA_4601), r"FingerDesign\.radius = 0\.3 m .*\(0, 0\.2\)"),
    (lambda: FingerDesign(0.2, 20, (0.02,) * 19, ELASTOSIL_MA_4601), r"FingerDesign\.radius has 19 values"),
    (lambda: FingerDesign(0.2, 5, (0.02, 0.01, 0.0, 0.01, 0.01), ELASTOSIL_MA_4601), r"FingerDesign\.radius = 0\.0"),
    (lambda: FingerDesign(0.2, 20, 0.02, ELASTOSIL_MA_4601, clamp="glued"), r"FingerDesign\.clamp = 'glued'"),
    (lambda: GripperDesign(paper_finger(), finger_angles=()), r"GripperDesign\.finger_angles"),
    (lambda: Scene(GripperDesign(paper_finger()), time_step=0.0), r"Scene\.time_step = 0\.0 s"),
    (lambda: Scene(GripperDesign(paper_finger()), model="2d"), r"Scene\.model = '2d'"),
    (lambda: Scene(GripperDesign(paper_finger()), forces=("gravity",)), r"Scene\.forces must hold ForceModel"),
    (lambda: NewtonSettings(relative_tolerance=2.0), r"NewtonSettings\.relative_tolerance = 2\.0"),
    (lambda: NewtonSettings(max_iterations=0), r"NewtonSettings\.max_iterations = 0"),
    (lambda: StokesDrag(viscosity=-1e-3), r"StokesDrag\.viscosity = -0\.001 Pa·s .*\[0, inf\)"),
    (lambda: Gravity(acceleration=float("inf")), r"Gravity\.acceleration = inf m/s²"),
    (lambda: Fluid(density=-1.0), r"Fluid\.density = -1\.0 kg/m³"),
    (lambda: Buoyancy(acceleration=-1.0), r"Buoyancy\.acceleration = -1\.0 m/s²"),
    (lambda: MassProportionalDamping(rate="fast"), r"MassProportionalDamping\.rate = 'fast' is not a number"),
    (lambda: Simulator(paper_scene(), batch_size=0), r"Simulator\.batch_size = 0"),
    (lambda: StokesDrag(nodes=(2, -1)), r"StokesDrag\.nodes = \(2, -1\) must be None or non-negative"),
    (lambda: paper_scene(medium=(StokesDrag(nodes=(25,)),)), r"StokesDrag\.nodes = \(25,\) names node 25; .* 0 … 19"),
    (lambda: paper_scene(medium="honey"), r"medium = 'honey' is not one of 'air', 'stokes', 'water'"),
])
def test_bad_configuration_raises_clear_error(make, pattern):
    with pytest.raises(ValueError, match=pattern):
        make()


@pytest.mark.parametrize("curvature, pattern", [
    (np.zeros(2), r"natural_curvature has shape \(2,\); expected a scalar, \(F,\) = \(3,\)"),
    (np.nan, r"natural_curvature \(dimensionless\) must be finite"),
    (np.array([0.0, np.inf, 0.0]), r"must be finite"),
])
def test_bad_natural_curvature_raises(curvature, pattern):
    sim = Simulator(paper_scene())
    with pytest.raises(ValueError, match=pattern):
        sim.step(sim.initial_state(), curvature)


def test_configs_are_frozen_and_replaceable():
    scene = paper_scene()
    with pytest.raises(AttributeError):
        scene.time_step = 0.1
    assert replace(scene, time_step=0.02).time_step == 0.02
    with pytest.raises(ValueError, match="Scene.time_step"):
        replace(scene, time_step=-0.02)


def test_variable_stiffness_preset_matches_paper():
    finger = paper_finger(variable_stiffness=True)
    np.testing.assert_allclose(finger.node_radius, 0.001 * (20 - np.arange(20)))

    disc = paper_scene(variable_stiffness=True).discretization()
    ei = disc.bend_stiffness
    assert ei[0] == pytest.approx(4.86e-2, rel=1e-3) and ei[-1] == pytest.approx(3.04e-7, rel=1e-2)
    assert ei[0] / ei[-1] == pytest.approx(1.6e5)
