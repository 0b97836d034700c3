"""The frames: fingers drawn as tubes of their own radius, framed on the gripper and the object, forces as arrows."""

import numpy as np

from soft_gripper_env.rendering import FORCE_COLOUR, FrameRenderer, finger_tube


def test_a_finger_is_drawn_as_a_tube_of_its_radius_profile():
    """Every point of a node's ring lies at that node's radius from it, across the finger's centre line."""
    s = np.linspace(0.0, 1.0, 20)
    positions = np.stack([0.2 * np.sin(s), np.zeros(20), -0.2 * (1 - np.cos(s))], axis=1)
    radius = np.linspace(0.02, 0.001, 20)
    x, y, z = finger_tube(positions, radius)
    surface = np.stack([x, y, z], axis=-1)
    offsets = surface - positions[:, None, :]
    np.testing.assert_allclose(np.linalg.norm(offsets, axis=-1), radius[:, None] * np.ones(x.shape), rtol=1e-12)
    tangent = np.gradient(positions, axis=0)
    along = np.einsum("nmk,nk->nm", offsets, tangent / np.linalg.norm(tangent, axis=1, keepdims=True))
    assert np.abs(along).max() < 1e-12


def _reddish(frame):
    target = np.array(FORCE_COLOUR) * 255
    return int((np.abs(frame.astype(float) - target).max(axis=-1) < 40).sum())


def test_contact_forces_show_as_arrows_and_the_view_frames_a_small_object():
    """A frame with a contact force has the arrows' colour where one without has none; a small sphere far from
    the palm is still in view (the view is framed on fingers and object, not fixed)."""
    renderer = FrameRenderer(240, 240)
    s = np.linspace(0.0, 0.2, 20)
    positions = np.stack([np.stack([s * np.cos(a), s * np.sin(a), -0.3 * s], axis=1)
                          for a in (0.0, 2.1, 4.2)])
    radius = np.linspace(0.02, 0.001, 20)
    force = np.zeros((3, 20, 3))
    quiet = renderer.draw(positions, radius, np.array([0.0, 0.0, -0.12]), 0.01, force, 0.0, np.zeros(3))
    force[0, 15] = [0.0, 0.0, 2.0]
    loud = renderer.draw(positions, radius, np.array([0.0, 0.0, -0.12]), 0.01, force, 0.0, np.zeros(3))
    assert _reddish(loud) > _reddish(quiet) + 20
    without = renderer.draw(positions, radius, np.array([0.0, 0.0, -0.12]), 1e-9, np.zeros((3, 20, 3)), 0.0,
                            np.zeros(3))
    assert (np.abs(quiet.astype(int) - without.astype(int)).max(axis=-1) > 10).sum() > 50  # the sphere is in view
