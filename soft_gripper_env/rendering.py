"""Frames of the gripper for ``render_mode="rgb_array"`` and ``"human"``: a 3-D view of the fingers and the object
in water, with the contact forces as arrows. Drawn with matplotlib's object API on an Agg canvas, so it needs no
display and never changes the user's pyplot back end."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

WATER_TINT = (0.82, 0.91, 0.97)
FORCE_SCALE = 0.05
"""Arrow length per newton of contact force [m/N]."""


class FrameRenderer:
    """Draws frames of ``width`` × ``height`` pixels."""

    def __init__(self, width: int = 480, height: int = 480) -> None:
        self.figure = Figure(figsize=(width / 100, height / 100), dpi=100, facecolor=WATER_TINT)
        self.canvas = FigureCanvasAgg(self.figure)
        self.axes = self.figure.add_axes((0.0, 0.0, 1.0, 1.0), projection="3d")

    def draw(self, positions: np.ndarray, center: np.ndarray, radius: float, normal_forces: np.ndarray,
             time: float, natural_curvature: np.ndarray) -> np.ndarray:
        """An H×W×3 uint8 frame. ``positions`` (F, N, 3) node positions [m]; ``center`` (3,) and ``radius`` of the
        sphere [m]; ``normal_forces`` (F, N) [N], drawn from each node toward the sphere's centre."""
        ax = self.axes
        ax.clear()
        ax.set_facecolor(WATER_TINT)
        u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(0, np.pi, 12))
        ax.plot_surface(center[0] + radius * np.cos(u) * np.sin(v), center[1] + radius * np.sin(u) * np.sin(v),
                        center[2] + radius * np.cos(v), color=(0.95, 0.6, 0.3), alpha=0.45, linewidth=0)
        for finger in positions:
            ax.plot(finger[:, 0], finger[:, 1], finger[:, 2], color=(0.1, 0.25, 0.45), lw=3)
        pushing = normal_forces > 0
        if pushing.any():
            nodes = positions[pushing]
            inward = center - nodes
            inward /= np.maximum(np.linalg.norm(inward, axis=1, keepdims=True), 1e-12)
            arrows = inward * (FORCE_SCALE * normal_forces[pushing])[:, None]
            ax.quiver(*nodes.T, *arrows.T, color=(0.8, 0.1, 0.1), linewidth=1.5)
        ax.scatter([0], [0], [0], color="k", s=40, marker="s")
        span = 0.22
        ax.set_xlim(-span, span)
        ax.set_ylim(-span, span)
        ax.set_zlim(-0.3, 0.05)
        ax.set_box_aspect((1, 1, 0.35 / 0.44))
        ax.view_init(elev=12, azim=-60)
        ax.set_axis_off()
        ax.text2D(0.03, 0.95, f"t = {time:.2f} s   κ̄ = {', '.join(f'{k:+.3f}' for k in natural_curvature)}",
                  transform=ax.transAxes, fontsize=9)
        self.canvas.draw()
        return np.asarray(self.canvas.buffer_rgba())[..., :3].copy()
