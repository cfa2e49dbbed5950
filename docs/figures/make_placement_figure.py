"""The camera placement figure of the scene XML reference (docs/figures/placement.png).

A camera placed by ``target`` / ``azimuth_deg`` / ``elevation_deg`` / ``distance_mm`` in the
laser-sheet frame (``laser_direction`` e1 = x, ``sheet_normal`` e3 = z, e2 = e3 x e1 = y, the
defaults), drawn from what :func:`mitpiv.physics.camera.place_camera` returns: the camera's
position, its optical axis (towards the target) and the image's up vector and right.

    .venv/bin/python docs/figures/make_placement_figure.py [OUT.png]
"""

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from mitpiv.physics.camera import place_camera  # noqa: E402

AZ, EL, D = 50.0, 38.0, 1.0  # the drawn placement (distance in units of distance_mm)
E1, E3 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
E2 = np.cross(E3, E1)


def arc(u, v, radius, angle_deg, n=60):
    """Points of the arc from direction u towards v (orthonormal), radius, angle."""
    t = np.radians(np.linspace(0.0, angle_deg, n))
    return radius * (np.outer(np.cos(t), u) + np.outer(np.sin(t), v))


def arrow(ax, start, vec, color, lw=2.0, ratio=0.12):
    ax.quiver(*start, *vec, color=color, lw=lw, arrow_length_ratio=ratio)


def _panel_3d(ax, rot, pos):
    target = np.zeros(3)
    axis, right, up = rot[2], rot[0], -rot[1]  # OpenCV rows: x right, y down, z forward (the optical axis)
    ground = np.array([pos[0], pos[1], 0.0])  # the camera's foot in the sheet plane
    h = ground / np.linalg.norm(ground)
    ax.view_init(elev=24, azim=-38)
    ax.set_axis_off()

    # the laser sheet (mid-plane) and the laser along e1
    xx, yy = np.meshgrid([-0.7, 0.85], [-0.5, 0.9])
    ax.plot_surface(xx, yy, np.zeros_like(xx), color="tab:green", alpha=0.10, linewidth=0)
    ax.quiver(-1.2, 0.0, 0.0, 0.45, 0.0, 0.0, color="tab:green", lw=5, arrow_length_ratio=0.3)
    ax.text(-1.25, 0.0, 0.08, "laser", color="tab:green", fontsize=11)
    ax.text(0.55, -0.5, 0.02, "laser sheet", color="tab:green", fontsize=10)

    # world axes = the sheet frame (defaults) from the target
    L = 0.6
    for vec, lab, off in ((E1, "x = e1", (0.03, -0.02, -0.08)), (E2, "y = e2", (0.0, 0.04, 0.0)),
                          (E3, "z = e3", (0.0, 0.0, 0.04))):
        arrow(ax, target, L * vec, "0.2", lw=1.4, ratio=0.1)
        ax.text(*(L * vec + np.array(off)), lab, color="0.1", fontsize=11)

    ax.scatter(*target, color="k", s=45, depthshade=False)
    ax.text(-0.05, -0.2, -0.06, "target", fontsize=11, weight="bold", ha="right")
    ax.plot(*np.column_stack([target, ground]), color="0.45", lw=1.0, ls="--")
    ax.plot(*np.column_stack([ground, pos]), color="0.45", lw=1.0, ls="--")
    ax.plot(*np.column_stack([target, pos]), color="tab:blue", lw=1.4)
    ax.text(*(0.62 * pos + np.array([-0.06, -0.02, 0.05])), "distance_mm", color="tab:blue", fontsize=11,
            ha="right")

    a = arc(E1, E2, 0.34, AZ)
    ax.plot(a[:, 0], a[:, 1], a[:, 2], color="tab:red", lw=2.6)
    ax.text(*(arc(E1, E2, 0.38, AZ * 0.4)[-1] + np.array([0.0, 0.0, -0.09])), "azimuth_deg", color="tab:red",
            fontsize=11)
    e = arc(h, E3, 0.48, EL)
    ax.plot(e[:, 0], e[:, 1], e[:, 2], color="tab:purple", lw=2.6)
    ax.text(*(arc(h, E3, 0.5, EL * 0.4)[-1] + np.array([0.04, 0.0, 0.0])), "elevation_deg", color="tab:purple",
            fontsize=11)

    _camera(ax, pos, axis, right, up)
    ax.set_xlim(-1.1, 1.0)
    ax.set_ylim(-0.5, 1.0)
    ax.set_zlim(-0.3, 0.95)
    ax.set_box_aspect((2.1, 1.5, 1.25), zoom=1.22)


def _camera(ax, pos, axis, right, up):
    """A small frustum at ``pos`` looking along ``axis``, its optical axis, image up and right."""
    c = 0.07
    corners = [pos + c * (sx * right + sy * up) + 1.5 * c * axis for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    for k in range(4):
        ax.plot(*np.column_stack([pos, corners[k]]), color="k", lw=1.0)
        ax.plot(*np.column_stack([corners[k], corners[(k + 1) % 4]]), color="k", lw=1.0)
    ax.scatter(*pos, color="k", s=30, depthshade=False)
    ax.text(*(pos + np.array([0.05, 0.0, 0.06])), "camera", fontsize=11, weight="bold")
    arrow(ax, pos, 0.36 * axis, "tab:orange", lw=3.0, ratio=0.2)
    ax.text(*(pos + 0.3 * axis + np.array([0.05, 0.0, -0.02])), "optical axis", color="tab:orange", fontsize=11)
    arrow(ax, pos, 0.28 * up, "darkcyan", lw=3.0, ratio=0.25)
    ax.text(*(pos + 0.3 * up + np.array([-0.05, 0.0, 0.03])), "image up", color="darkcyan", fontsize=11,
            ha="right")


def _panel_top(ax, pos):
    """The sheet plane seen from +e3: azimuth from the laser direction towards e2."""
    ax.set_title("seen along -z (the sheet plane): azimuth", fontsize=10.5)
    ax.axhspan(-0.15, 0.15, color="tab:green", alpha=0.0)
    ax.annotate("", xy=(-0.45, 0.0), xytext=(-1.0, 0.0), arrowprops=dict(color="tab:green", lw=4, arrowstyle="-|>"))
    ax.text(-1.0, 0.06, "laser", color="tab:green", fontsize=10)
    for vec, lab in (((0.8, 0.0), "x = e1\n(laser_direction)"), ((0.0, 0.8), "y = e2 = e3 x e1")):
        ax.annotate("", xy=vec, xytext=(0, 0), arrowprops=dict(color="0.2", lw=1.3, arrowstyle="->"))
        ax.text(vec[0] + 0.03, vec[1] + (0.0 if vec[0] else 0.03), lab, fontsize=9.5,
                ha="left" if vec[0] else "center", va="center" if vec[0] else "bottom")
    g = pos[:2]
    ax.plot([0, g[0]], [0, g[1]], color="0.45", ls="--", lw=1.0)
    ax.plot(*g, "ks", ms=6)
    ax.text(g[0] + 0.04, g[1], "camera (above)", fontsize=9.5, va="center")
    t = np.radians(np.linspace(0, AZ, 50))
    ax.plot(0.3 * np.cos(t), 0.3 * np.sin(t), color="tab:red", lw=2.4)
    m = np.radians(AZ / 2)
    ax.text(0.34 * np.cos(m), 0.34 * np.sin(m), "azimuth_deg", color="tab:red", fontsize=10.5)
    ax.plot(0, 0, "ko", ms=6)
    ax.text(0.02, -0.1, "target", fontsize=10, weight="bold")
    ax.text(-1.0, -0.32, "0: forward scatter (downstream)\n180: backward scatter", fontsize=9, color="0.3")
    ax.set_xlim(-1.05, 1.15)
    ax.set_ylim(-0.45, 0.95)
    ax.set_aspect("equal")
    ax.axis("off")


def _panel_side(ax, rot, pos):
    """The vertical plane through the target and the camera: elevation, distance, the axis, up."""
    ax.set_title("seen across the camera's vertical plane: elevation", fontsize=10.5)
    ground = np.array([pos[0], pos[1], 0.0])
    h = ground / np.linalg.norm(ground)

    def flat(v):  # world vector -> (along h, along e3)
        return np.array([v @ h, v @ E3])

    ax.plot([-0.3, 1.0], [0, 0], color="tab:green", lw=6, alpha=0.25, solid_capstyle="butt")
    ax.text(1.0, -0.09, "laser sheet (edge on)", color="tab:green", fontsize=9, ha="right")
    c = flat(pos)
    ax.plot([0, c[0]], [0, c[1]], color="tab:blue", lw=1.4)
    n = np.array([np.sin(np.radians(EL)), -np.cos(np.radians(EL))])  # below the line
    ax.text(*(0.6 * c + 0.04 * n), "distance_mm", color="tab:blue", fontsize=10.5, rotation=EL,
            ha="center", va="top", rotation_mode="anchor")
    ax.plot([c[0], c[0]], [0, c[1]], color="0.45", ls="--", lw=1.0)
    t = np.radians(np.linspace(0, EL, 50))
    ax.plot(0.35 * np.cos(t), 0.35 * np.sin(t), color="tab:purple", lw=2.4)
    ax.text(0.38, 0.06, "elevation_deg", color="tab:purple", fontsize=10.5)
    ax.annotate("", xy=(0, 0.75), xytext=(0, 0), arrowprops=dict(color="0.2", lw=1.3, arrowstyle="->"))
    ax.text(0.02, 0.77, "z = e3 (sheet_normal)", fontsize=9.5)
    axis, up = flat(rot[2]), flat(-rot[1])
    ax.annotate("", xy=c + 0.32 * axis, xytext=c, arrowprops=dict(color="tab:orange", lw=3, arrowstyle="-|>"))
    ax.text(*(c + 0.2 * axis + np.array([-0.03, 0.05])), "optical axis (camera +z)", color="tab:orange",
            fontsize=9.5, ha="right")
    ax.annotate("", xy=c + 0.25 * up, xytext=c, arrowprops=dict(color="darkcyan", lw=3, arrowstyle="-|>"))
    ax.text(*(c + 0.25 * up + np.array([0.04, 0.0])), "image up\n(e3 projected)", color="darkcyan",
            fontsize=9.5, ha="left", va="center")
    ax.plot(*c, "ks", ms=6)
    ax.text(c[0] + 0.04, c[1] - 0.02, "camera", fontsize=10, weight="bold")
    ax.plot(0, 0, "ko", ms=6)
    ax.text(0.02, -0.1, "target", fontsize=10, weight="bold")
    ax.set_xlim(-0.35, 1.2)
    ax.set_ylim(-0.15, 1.0)
    ax.set_aspect("equal")
    ax.axis("off")


def main(out: Path) -> None:
    rot, pos = place_camera(target_mm=(0.0, 0.0, 0.0), azimuth_deg=AZ, elevation_deg=EL, distance_mm=D,
                            laser_direction=E1, sheet_normal=E3)
    assert np.allclose(rot[2], -pos / np.linalg.norm(pos))  # the optical axis points at the target

    fig = plt.figure(figsize=(13.0, 6.6))
    ax3 = fig.add_axes((0.0, 0.0, 0.56, 0.86), projection="3d")
    _panel_3d(ax3, rot, pos)
    _panel_top(fig.add_axes((0.57, 0.45, 0.42, 0.4)), pos)
    _panel_side(fig.add_axes((0.57, 0.0, 0.42, 0.44)), rot, pos)
    fig.suptitle(f"Camera placement around a target: azimuth {AZ:g} deg, elevation {EL:g} deg, default "
                 f"laser_direction (1, 0, 0) = e1 and sheet_normal (0, 0, 1) = e3\n"
                 f"camera = target + distance_mm (cos el cos az e1 + cos el sin az e2 + sin el e3), looking at "
                 f"the target\nimage up: e3 projected on the image plane (e2 when the camera looks within 8.1 deg "
                 f"of e3)", fontsize=10.5, y=0.99)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_name("placement.png"))
