"""Frames of the gripper for ``render_mode="rgb_array"`` and ``"human"``: a 3-D view of the fingers (as tubes of their
own radius profile) and the object in water, framed on both, with the contact forces as arrows. Drawn with
matplotlib's object API on an Agg canvas, so it needs no display and never changes the user's pyplot back end."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

WATER_TINT = (0.82, 0.91, 0.97)
FINGER_COLOUR = (0.15, 0.35, 0.6)
FORCE_COLOUR = (0.8, 0.1, 0.1)
LONGEST_ARROW = 0.35
"""The largest contact force's arrow, as a fraction of the view's span (every arrow is scaled alike)."""


def finger_tube(positions: np.ndarray, radius: np.ndarray, sides: int = 12) -> tuple[np.ndarray, ...]:
    """The surface of one finger, a tube of ``radius`` (N,) [m] about its centre line ``positions`` (N, 3) [m]:
    X, Y, Z of shape (N, sides + 1)."""
    tangent = np.gradient(positions, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    helper = np.where(np.abs(tangent[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    first = np.cross(tangent, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    second = np.cross(tangent, first)
    angle = np.linspace(0.0, 2 * np.pi, sides + 1)
    ring = np.cos(angle)[None, :, None] * first[:, None, :] + np.sin(angle)[None, :, None] * second[:, None, :]
    surface = positions[:, None, :] + radius[:, None, None] * ring
    return surface[..., 0], surface[..., 1], surface[..., 2]


class FrameRenderer:
    """Draws frames of ``width`` × ``height`` pixels."""

    def __init__(self, width: int = 480, height: int = 480) -> None:
        self.figure = Figure(figsize=(width / 100, height / 100), dpi=100, facecolor=WATER_TINT)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = self.figure.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d")

    def draw(self, positions: np.ndarray, node_radius: np.ndarray, center: np.ndarray, radius: float,
             contact_force: np.ndarray, time: float, natural_curvature: np.ndarray) -> np.ndarray:
        """An H×W×3 uint8 frame. ``positions`` (F, N, 3) node positions [m] and ``node_radius`` (N,) the fingers'
        radius profile [m]; ``center`` (3,) and ``radius`` of the sphere [m]; ``contact_force`` (F, N, 3) the
        object's force on each node [N], drawn as an arrow from the node."""
        ax = self.axes
        ax.clear()
        ax.set_facecolor(WATER_TINT)
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
        ax.plot_surface(center[0] + radius * np.cos(u) * np.sin(v), center[1] + radius * np.sin(u) * np.sin(v),
                        center[2] + radius * np.cos(v), color=(0.95, 0.6, 0.3), alpha=0.45, linewidth=0)
        for finger in positions:
            ax.plot_surface(*finger_tube(finger, node_radius), color=FINGER_COLOUR, alpha=0.55, linewidth=0)
        # framed on the fingers and the object, equal scales on every axis
        points = np.concatenate([positions.reshape(-1, 3) - node_radius.max(), positions.reshape(-1, 3)
                                 + node_radius.max(), center[None] - radius, center[None] + radius, np.zeros((1, 3))])
        low, high = points.min(axis=0), points.max(axis=0)
        middle, span = 0.5 * (low + high), 1.1 * float((high - low).max())
        magnitude = np.linalg.norm(contact_force, axis=-1)
        largest = float(magnitude.max()) if magnitude.size else 0.0
        if largest > 0.0:
            pushing = magnitude > 1e-3 * largest
            arrows = contact_force[pushing] * (LONGEST_ARROW * span / largest)
            ax.quiver(*positions[pushing].T, *arrows.T, color=FORCE_COLOUR, linewidth=2.0, arrow_length_ratio=0.25)
        ax.scatter([0], [0], [0], color="k", s=40, marker="s")
        for axis, set_limits in enumerate((ax.set_xlim, ax.set_ylim, ax.set_zlim)):
            set_limits(middle[axis] - 0.5 * span, middle[axis] + 0.5 * span)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=12, azim=-60)
        ax.set_axis_off()
        ax.text2D(0.03, 0.95, f"t = {time:.2f} s   κ̄ = {', '.join(f'{k:+.3f}' for k in natural_curvature)}",
                  transform=ax.transAxes, fontsize=9)
        ax.text2D(0.03, 0.90, f"largest contact force {largest:.2f} N (arrows to scale)" if largest > 0 else
                  "no contact", transform=ax.transAxes, fontsize=9, color=FORCE_COLOUR)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()
