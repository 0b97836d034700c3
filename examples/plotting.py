"""Figures of gripper runs: fingertip height against time, and 3-D time-lapses. Uses matplotlib's Agg back end."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from soft_gripper_env.physics import Trajectory  # noqa: E402


def plot_tip_height(ax, trajectory: Trajectory, label: str, finger: int = 0, **style) -> None:
    """Tip z [m] of one finger against time [s]."""
    ax.plot(trajectory.times, trajectory.positions[:, 0, finger, -1, 2], label=label, **style)
    ax.set_xlabel("time t [s]")
    ax.set_ylabel("fingertip z [m]")
    ax.grid(True, alpha=0.3)


def plot_timelapse(ax, trajectory: Trajectory, every: float = 0.1) -> None:
    """Every finger at times 0, every, 2·every, … [s], coloured from light (early) to dark (late), on a 3-D axis."""
    dt = trajectory.times[1] - trajectory.times[0]
    stride = max(1, int(round(every / dt)))
    frames = range(0, len(trajectory.times), stride)
    colours = plt.cm.viridis(np.linspace(0.9, 0.0, len(frames)))
    for colour, k in zip(colours, frames, strict=True):
        for finger in trajectory.positions[k, 0]:
            ax.plot(finger[:, 0], finger[:, 1], finger[:, 2], color=colour, lw=1.6)
            ax.scatter(*finger[-1], color=colour, s=6)
    ax.scatter([0], [0], [0], color="k", s=25, marker="s", label="palm")
    span = np.abs(trajectory.positions[..., :2]).max()
    ax.set_xlim(-span, span)
    ax.set_ylim(-span, span)
    ax.set_zlim(min(trajectory.positions[..., 2].min() * 1.05, -span * 0.8), span * 0.3)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_zlabel("z [m]")
    ax.view_init(elev=14, azim=-30)  # no finger points along the line of sight
    sm = plt.cm.ScalarMappable(cmap="viridis_r", norm=plt.Normalize(trajectory.times[0], trajectory.times[-1]))
    ax.figure.colorbar(sm, ax=ax, shrink=0.6, pad=0.1, label="time [s]")


def plot_sphere(ax, sphere, **style) -> None:
    """A wireframe of a :class:`~soft_gripper_env.physics.Sphere` on a 3-D axis."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 25), np.linspace(0, np.pi, 13))
    c = sphere.center
    ax.plot_wireframe(c[0] + sphere.radius * np.cos(u) * np.sin(v), c[1] + sphere.radius * np.sin(u) * np.sin(v),
                      c[2] + sphere.radius * np.cos(v), color=style.pop("color", "0.6"), lw=0.4, **style)


def plot_contact_forces(ax, positions: np.ndarray, report, step: int = -1, scale: float = 0.02) -> None:
    """Reaction arrows [N → m by ``scale`` m/N] at the held nodes of gripper 0, on a 3-D axis."""
    held = report.held[0]
    x = positions[held]
    f = report.reaction[0][held] * scale
    if len(x):
        ax.quiver(x[:, 0], x[:, 1], x[:, 2], f[:, 0], f[:, 1], f[:, 2], color="crimson", lw=1.5,
                  label=f"contact reaction ({scale * 100:g} cm per N)")


def new_figure(n_panels: int = 1, three_d: tuple[bool, ...] | None = None, width: float = 5.5):
    """A figure with ``n_panels`` side by side; ``three_d`` marks which are 3-D axes."""
    three_d = three_d or (False,) * n_panels
    fig = plt.figure(figsize=(width * n_panels, 4.3))
    axes = [fig.add_subplot(1, n_panels, i + 1, projection="3d" if is3d else None) for i, is3d in enumerate(three_d)]
    return fig, axes


def save(fig, path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
