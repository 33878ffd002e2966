"""Draw docs/protocols_figure.png: ModelNet40-C's and PCN's depth images and clouds, exact vs the recipe's tool.

python docs/make_protocols_figure.py            # needs the [plot] extra (matplotlib)
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import trimesh  # noqa: E402

import zbuf_occlude as zo  # noqa: E402
from zbuf_occlude.protocols import (  # noqa: E402
    PinholeView,
    back_project,
    pcn,  # noqa: E402
    render_depth_image,
)
from zbuf_occlude.protocols import modelnet40c as mc  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "protocols_figure.png"


def main() -> None:
    table = zo.load_mesh(ROOT / "data/samples/table/test/table_0393.off")
    theirs = trimesh.Trimesh(mc.normalize(np.asarray(table.vertices)), table.faces, process=False)
    view = PinholeView(mc.intrinsics(), mc.occlusion_pose(3, np.random.RandomState(0))[:3], mc.WIDTH, mc.HEIGHT)
    exact = render_depth_image(theirs, view)
    culled = render_depth_image(theirs, view, cull_back_faces=True)
    chair = pcn.pcn_mesh(zo.load_mesh(ROOT / "data/samples/chair/train/chair_0001.off"))
    scans = pcn.pcn_views(chair, np.random.RandomState(0))
    fig = plt.figure(figsize=(16, 4.2))
    hit = (exact.depth > 0) | (culled.depth > 0)
    rows, cols = np.nonzero(hit)
    crop = (slice(rows.min() - 5, rows.max() + 6), slice(cols.min() - 5, cols.max() + 6))
    ax = fig.add_subplot(1, 4, 1)
    im = ax.imshow(np.where(exact.depth > 0, exact.depth, np.nan)[crop], cmap="viridis")
    fig.colorbar(im, ax=ax, shrink=0.7, label="depth")
    ax.set_title("MN40-C occlusion s=3: exact depth", fontsize=9)
    ax.axis("off")
    ax = fig.add_subplot(1, 4, 2)
    both = (exact.depth > 0) & (culled.depth > 0)
    diff = np.where(both, culled.depth - exact.depth, np.nan)
    lim = float(np.nanpercentile(np.abs(diff), 99)) or 1.0
    ax.imshow(np.where(hit & ~both, 0.0, np.nan)[crop], cmap="gray", vmin=0, vmax=1)  # hit in one image only: black
    im = ax.imshow(diff[crop], cmap="coolwarm", vmin=-lim, vmax=lim)
    fig.colorbar(im, ax=ax, shrink=0.7, label="depth difference (black: one image only)")
    ax.set_title("back faces culled (Open3D default) − exact", fontsize=9)
    ax.axis("off")
    ax = fig.add_subplot(1, 4, 3, projection="3d")
    for img, colour, label in ((exact, "tab:blue", "exact"), (culled, "tab:red", "culled")):
        pts = back_project(img.depth, view.K, view.extrinsics)[0][::15]
        ax.scatter(*pts.T, s=0.3, c=colour, label=label)
    ax.set_title("back-projected clouds (their frame)", fontsize=9)
    ax.legend(markerscale=10, fontsize=8)
    ax = fig.add_subplot(1, 4, 4, projection="3d")
    complete, _ = zo.sample_surface(chair, count=pcn.COMPLETE_POINTS, seed=0)
    ax.scatter(*complete[::8].T, s=0.2, c="0.7", label="complete")
    o = scans["partial_offsets"]
    for i in range(3):
        ax.scatter(*scans["partial"][o[i] : o[i + 1]][::3].T, s=0.4, label=f"PCN scan {i}")
    ax.set_title("PCN: 3 of 8 partial scans and the complete cloud", fontsize=9)
    ax.legend(markerscale=10, fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT, dpi=110)
    print(OUT)


if __name__ == "__main__":
    main()
