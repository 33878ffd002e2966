"""Make ``docs/figure.png``: one real mesh's full sampled cloud and its occluded clouds from 4 poses.

As in Figs. 10-11 of Sryamkin, Msallam & Klestov (2023): for each pose, the points the camera sees
(``visible_mask(..., method="zbuffer")``) are drawn twice, from one fixed viewpoint shared by all
poses (the hidden side is missing) and from the camera's own viewpoint (the cloud looks complete).
Colour is linear depth from that pose's camera (near = dark/blue, far = yellow).

The matplotlib view uses the camera convention of :func:`zbuf_occlude.camera_on_sphere` (z up,
eye along ``(cos el cos az, cos el sin az, sin el)``), which is also matplotlib's ``view_init``
convention, and a perspective with the camera's field of view.

Usage::

    .venv/bin/python docs/make_figure.py [MESH] [--out docs/figure.png] [--points 20000]

Needs matplotlib (``pip install -e '.[plot]'``).
"""

from __future__ import annotations

import argparse
import io
import math
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: no display on CI machines
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from PIL import Image  # noqa: E402  (a matplotlib dependency)

import zbuf_occlude as zo  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]
#: Default mesh: shipped with the repository; the copy in ../shared is used if the samples are absent.
DEFAULT_MESHES = (
    REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off",
    REPO_ROOT.parent / "shared" / "data" / "modelnet_subset" / "release_unknown" / "chair" / "train" / "chair_0001.off",
)
DEFAULT_OUT = REPO_ROOT / "docs" / "figure.png"
DEFAULT_POINTS = 20_000
DEFAULT_RESOLUTION = 1024
#: (elevation_deg, azimuth_deg) of the 4 cameras.
POSES = ((30.0, 45.0), (0.0, 180.0), (60.0, 270.0), (-30.0, 90.0))
#: The viewpoint shared by the "fixed" row: a three-quarter view from above, away from every
#: camera, so each occluded cloud shows the side its camera did not see as missing.
FIXED_VIEW = (20.0, -60.0)
#: Figure size in inches at DPI: 1600 x 720 pixels.
FIGSIZE_IN = (16.0, 7.2)
DPI = 100
MARKER_SIZE = 0.6  # points², small enough that 20k points stay legible
COLORMAP = "viridis"
#: The camera-direction arrow runs from this distance from the origin to the next (object units).
ARROW_FROM, ARROW_TO = 0.78, 0.55
#: Colours kept when the PNG is written with a palette (keeps the file a few hundred KB).
PALETTE_COLORS = 256
#: Half-width of the plotted box, object units (the mesh fits in [-0.5, 0.5]³).
AXIS_HALF_WIDTH = 0.5
#: matplotlib fits the whole box, corners included, into each panel; the mesh rarely fills its
#: box, so zoom in (points are not clipped at the box).
ZOOM = 1.5


def _default_mesh() -> Path:
    for path in DEFAULT_MESHES:
        if path.is_file():
            return path
    raise SystemExit(f"no default mesh found (looked for {', '.join(map(str, DEFAULT_MESHES))}); pass a MESH path")


def _setup_axes(ax, elevation_deg: float, azimuth_deg: float, camera: zo.Camera) -> None:
    ax.view_init(elev=elevation_deg, azim=azimuth_deg)
    # matplotlib's focal length is 1 / tan(fov / 2), with the fov spanning the axes box.
    ax.set_proj_type("persp", focal_length=1.0 / math.tan(math.radians(camera.yfov_deg) / 2.0))
    for setter in (ax.set_xlim, ax.set_ylim, ax.set_zlim):
        setter(-AXIS_HALF_WIDTH, AXIS_HALF_WIDTH)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=ZOOM)
    ax.set_axis_off()


def _scatter(ax, points: np.ndarray, depth: np.ndarray, vmin: float, vmax: float) -> None:
    # Draw far points first so near ones end on top (matplotlib paints in call order).
    order = np.argsort(-depth)
    ax.scatter(
        *points[order].T,
        c=depth[order],
        cmap=COLORMAP,
        vmin=vmin,
        vmax=vmax,
        s=MARKER_SIZE,
        linewidths=0,
        depthshade=False,
        rasterized=True,
    )


def _camera_marker(ax, camera: zo.Camera) -> None:
    """An arrow beside the object, pointing from the camera's direction towards the origin."""
    direction = camera.eye / np.linalg.norm(camera.eye)
    start, end = ARROW_FROM * direction, ARROW_TO * direction
    ax.quiver(*start, *(end - start), color="crimson", linewidth=1.5, arrow_length_ratio=0.35)


def make_figure(mesh_path: Path, out: Path, *, n_points: int = DEFAULT_POINTS, resolution: int = DEFAULT_RESOLUTION, seed: int = 0) -> None:
    """Render the figure to ``out`` (PNG)."""
    mesh = zo.load_mesh(mesh_path)
    points, face_index = zo.sample_surface(mesh, count=n_points, seed=seed)
    fixed_cam = zo.camera_on_sphere(*FIXED_VIEW)

    fig = plt.figure(figsize=FIGSIZE_IN, dpi=DPI)
    grid = fig.add_gridspec(2, 1 + len(POSES), wspace=0.0, hspace=0.08, left=0.0, right=1.0, top=0.88, bottom=0.0)

    ax = fig.add_subplot(grid[:, 0], projection="3d")
    _setup_axes(ax, *FIXED_VIEW, fixed_cam)
    _, depth = fixed_cam.project(points)
    _scatter(ax, points, depth, depth.min(), depth.max())
    ax.set_title(
        f"full sampled cloud\n{n_points:,} points, {len(mesh.faces):,} faces\n(colour: depth from this view)",
        fontsize=11,
    )

    with zo.VisibilitySession(mesh, points, face_index, method="zbuffer") as scene:
        for col, (el, az) in enumerate(POSES, start=1):
            camera = zo.camera_on_sphere(el, az, resolution=resolution)
            visible = scene.visible(camera)
            _, depth = camera.project(points)
            vis_pts, vis_depth = points[visible], depth[visible]
            # Same colour scale for both views of a pose: the depth range of the whole cloud.
            vmin, vmax = depth.min(), depth.max()

            top = fig.add_subplot(grid[0, col], projection="3d")
            _setup_axes(top, *FIXED_VIEW, fixed_cam)
            _scatter(top, vis_pts, vis_depth, vmin, vmax)
            _camera_marker(top, camera)
            top.set_title(f"el {el:g}°, az {az:g}°: {100 * visible.mean():.0f} % visible", fontsize=11)

            bottom = fig.add_subplot(grid[1, col], projection="3d")
            _setup_axes(bottom, el, az, camera)
            _scatter(bottom, vis_pts, vis_depth, vmin, vmax)

    row_x = grid[0, 1].get_position(fig).x0 + 0.005
    for row, label in enumerate(
        (
            f"from a fixed viewpoint (el {FIXED_VIEW[0]:g}°, az {FIXED_VIEW[1]:g}°)\nred arrow: camera direction",
            "from the camera's own viewpoint",
        )
    ):
        box = grid[row, 1].get_position(fig)
        fig.text(row_x, (box.y0 + box.y1) / 2, label, rotation=90, ha="left", va="center", fontsize=10, color="0.3")
    fig.suptitle(
        f"{mesh_path.name}: z-buffer hidden surface removal at {resolution}², colour = depth from each camera (near: blue, far: yellow)",
        fontsize=13,
        y=0.975,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=DPI, format="png")
    plt.close(fig)
    # Scattered points compress poorly as RGBA; a palette image of a few colour maps' worth of
    # colours looks the same at a fraction of the size.
    image = Image.open(buffer).convert("RGB").quantize(colors=PALETTE_COLORS, method=Image.Quantize.MEDIANCUT)
    image.save(out, optimize=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh", nargs="?", type=Path, default=None, help="mesh file (default: a shipped sample chair)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="PNG to write (default %(default)s)")
    parser.add_argument("--points", type=int, default=DEFAULT_POINTS)
    parser.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    mesh = args.mesh or _default_mesh()
    make_figure(mesh, args.out, n_points=args.points, resolution=args.resolution, seed=args.seed)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
