"""The figure of docs/results/point_visibility.md: one view of a shipped mesh three times, the points
the exact mesh oracle keeps, those point-splat keeps from the points alone, and those HPR keeps.

    python docs/results/point_visibility/make_figure.py          # writes figure.png beside this file

Needs the ``plot`` extra (matplotlib) and Open3D for the HPR panel (``pip install open3d-cpu``).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import zbuf_occlude as zo
from zbuf_occlude.visibility.metrics import agreement

HERE = Path(__file__).resolve().parent
MESH = HERE.parents[2] / "data" / "samples" / "chair" / "train" / "chair_0001.off"
N_POINTS = 10_000
ELEVATION_DEG, AZIMUTH_DEG = 25.0, 35.0
HPR_FACTOR = 1000.0  # the factor best on the tuning meshes (the page's table)


def main() -> None:
    mesh = zo.load_mesh(MESH)
    points, face_index = zo.sample_surface(mesh, N_POINTS, seed=0)
    camera = zo.camera_on_sphere(ELEVATION_DEG, AZIMUTH_DEG)
    truth = zo.visible_mask(mesh, points, camera, method="oracle", face_index=face_index)
    panels = [
        ("exact oracle (mesh)", truth),
        ("point-splat (points alone)", zo.visible_mask_points(points, camera)),
        (f"HPR, radius ×{HPR_FACTOR:g}", zo.visible_mask(mesh, points, camera, method="open3d-hpr", hpr_radius_factor=HPR_FACTOR)),
    ]
    # seen from a fixed viewpoint beside the camera, so that hidden points show too
    side = zo.camera_on_sphere(ELEVATION_DEG + 10.0, AZIMUTH_DEG + 60.0)
    uv, depth = side.project(points)
    order = np.argsort(-depth)
    fig, axes = plt.subplots(1, 3, figsize=(11, 4), dpi=110)
    for ax, (title, visible) in zip(axes, panels):
        colour = np.where(visible, "#1f77b4", "#d0d0d0")
        if visible is not truth:
            colour = np.where(visible & ~truth, "#d62728", colour)  # false visible
            colour = np.where(~visible & truth, "#ff9f1c", colour)  # false hidden
            score = agreement(visible, truth)
            title += f"\naccuracy {score['accuracy']:.3f}, IoU {score['iou']:.3f}"
        else:
            title += f"\n{int(visible.sum()):,} of {N_POINTS:,} visible"
        ax.scatter(uv[order, 0], uv[order, 1], s=1.2, c=colour[order], linewidths=0)
        ax.set_title(title, fontsize=9)
        ax.set_aspect("equal")
        ax.invert_yaxis()
        ax.axis("off")
    fig.suptitle(f"{MESH.stem}, {N_POINTS:,} points, camera at elevation {ELEVATION_DEG:g}°, azimuth "
                 f"{AZIMUTH_DEG:g}°, seen from beside it (blue: kept, grey: hidden, red: false visible, "
                 "orange: false hidden)", fontsize=8)  # fmt: skip
    fig.tight_layout()
    fig.savefig(HERE / "figure.png")


if __name__ == "__main__":
    main()
