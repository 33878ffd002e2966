"""How much of a PointNet-style point set one pose sees, and how many samples of ``--points N`` repeat points.

PointNet's ``modelnet40_ply_hdf5_2048`` clouds are 2,048 points drawn uniformly on ModelNet meshes.
This draws such clouds on the meshes given (``sample_surface``, seed 1), decides their visibility
from the points alone (``point-splat``, normals estimated) from each pose of ``grid25`` at the
default radius, and prints the visible share per pose (mean, median, 5th and 1st percentile,
minimum) and, for each ``--points`` of a list, the share of poses that see fewer points than that
(each of their samples repeats points).  The figures behind
``zbuf_occlude.mesh.inputs.kinds.POINT_SET_VISIBLE_SHARE`` and ``DEFAULT_POINT_SET_POINTS``.

Usage::

    python benchmarks/point_set_visible.py MESH_FOLDER [--meshes 40] [--points 2048]
"""

from __future__ import annotations

import argparse

import numpy as np

from zbuf_occlude.geometry.cameras import view_schedule
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.mesh.inputs.discovery import find_meshes
from zbuf_occlude.mesh.load import load_mesh
from zbuf_occlude.pipeline import CameraSphere
from zbuf_occlude.visibility.point_splats import point_surfels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder")
    parser.add_argument("--meshes", type=int, default=40, help="at most this many meshes, drawn with seed 0")
    parser.add_argument("--points", type=int, default=2048, help="points per cloud (PointNet's: 2048)")
    args = parser.parse_args()
    files = [path for path, _ in find_meshes([args.folder])]
    rng = np.random.default_rng(0)
    files = [files[i] for i in sorted(rng.choice(len(files), size=min(args.meshes, len(files)), replace=False))]
    poses, cameras = view_schedule("grid25"), CameraSphere()
    shares = []
    for path in files:
        surfels = point_surfels(sample_surface(load_mesh(path), count=args.points, seed=1)[0], None)
        shares += [surfels.visible(cameras.camera(el, az)).sum() / len(surfels.points) for el, az in poses]
    share = np.asarray(shares)
    print(
        f"{len(files)} meshes x {len(poses)} poses, {args.points}-point clouds: visible share mean {share.mean():.3f}, "
        f"median {np.median(share):.3f}, p5 {np.quantile(share, 0.05):.3f}, p1 {np.quantile(share, 0.01):.3f}, min {share.min():.3f}"
    )
    for n in (1024, 512, 384, 256, 128):
        print(f"--points {n}: {np.mean(share * args.points < n):.1%} of poses give padded samples")


if __name__ == "__main__":
    main()
