"""How far the recipes' own tools are from the exact first surface (prints a table; not a test).

For each mesh, with the protocols' poses (seed 0):

* ModelNet40-C occlusion (severity 3): Open3D's ``Visualizer`` culls back faces (its default
  ``mesh_show_back_face=False``).  Pixels whose depth changes when faces are culled
  (:func:`zbuf_occlude.protocols.render_depth_image` with ``cull_back_faces=True``) against
  the exact two-sided first hit (Embree, float64 on the face): there the recipe sees through
  a face wound away from the camera, onto a surface the exact view hides.
* PCN: ``process_exr.py::depth2pcd`` puts the principal point half a pixel off the image
  centre.  Mean and maximum distance from each partial point to the mesh (the exact
  back-projection of the same pixel lies on it to float32 rounding).

    python benchmarks/accuracy_protocols.py                 # the shipped meshes
    python benchmarks/accuracy_protocols.py ../shared/data/modelnet_subset/*/test/*.off
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import trimesh

import zbuf_occlude as zo
from zbuf_occlude.protocols import PinholeView, pcn, render_depth_image
from zbuf_occlude.protocols import modelnet40c as mc

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("meshes", nargs="*")
    p.add_argument("--severity", type=int, default=3)
    args = p.parse_args()
    paths = [Path(m) for m in args.meshes] or sorted(SAMPLES.rglob("*.off"))
    print("#", subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip())
    print("| mesh | MN40-C pixels | changed by culling | points off the exact surface (> 1e-4) | PCN mean / max distance to mesh |")
    print("|---|---:|---:|---:|---:|")
    for path in paths:
        mesh = zo.load_mesh(path)
        theirs = trimesh.Trimesh(mc.normalize(np.asarray(mesh.vertices)), mesh.faces, process=False)
        view = PinholeView(mc.intrinsics(), mc.occlusion_pose(args.severity, np.random.RandomState(0))[:3], mc.WIDTH, mc.HEIGHT)
        exact = render_depth_image(theirs, view)
        culled = render_depth_image(theirs, view, cull_back_faces=True)
        hit = (exact.depth > 0) | (culled.depth > 0)
        changed = hit & (np.abs(exact.depth - culled.depth) > 1e-6 * np.maximum(exact.depth, 1.0))
        # culled-view points that are not on the exactly visible surface: > 1e-4 behind the exact depth
        behind = (culled.depth > 0) & ((exact.depth == 0) | (culled.depth > exact.depth + 1e-4))
        m = pcn.pcn_mesh(mesh)
        views = pcn.pcn_views(m, np.random.RandomState(0))
        _, dist, _ = trimesh.proximity.closest_point(m, views["partial"].astype(np.float64)[::10])
        print(f"| {path.stem} | {int(hit.sum())} | {100 * changed.sum() / max(hit.sum(), 1):.2f} % | "
              f"{100 * behind.sum() / max((culled.depth > 0).sum(), 1):.2f} % | {dist.mean():.2e} / {dist.max():.2e} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
