"""Point-only visibility: how often the GPU z-buffer (an OpenGL compute shader, ``backend="gpu"``) gives the same
mask and the same buffers as the CPU one (numba, ``backend="cpu"``) (prints a Markdown table; not
a test).

Every shipped mesh (``data/samples``, or ``--root``), N points sampled from it
(``zo.sample_surface``, seed 0), prepared once (``zo.point_surfels``: estimated normals, or the
faces' normals with ``--normals``), then each pose's ``surfels.visible(camera, backend=...)``
for both backends.  Reported per N: the share of point-views whose masks agree, the share of
covered pixels whose winning surfel (id buffer) agrees, and the depth buffers' largest relative
difference where the ids agree; and the median wall ms of one ``visible`` call per backend (the
two interleaved, their order alternating pose by pose: indicative on a shared machine;
``bench_point_visibility.py`` times them beside HPR).

Usage::

    .venv/bin/python benchmarks/agreement_point_splats.py                   # 2,048 and 10,000 points, 16 poses
    .venv/bin/python benchmarks/agreement_point_splats.py --points 256 --poses fibonacci:2 --meshes 1
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import zbuf_occlude as zo
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS
from zbuf_occlude.visibility.point_kernels import camera_frame, splat_surfels
from zbuf_occlude.visibility.splat_image import splat_image

REPO_ROOT = Path(__file__).resolve().parents[1]


def load_average() -> str:
    return ", ".join(f"{v:.2f}" for v in os.getloadavg())


def buffers_of(surfels, camera, splat):
    """The depth and id buffers of one view, as ``surfels.visible`` draws them."""
    points, normals, radius, _, _ = surfels._in_order
    extrinsics = camera.extrinsics
    cam, normal = camera_frame(points, normals, np.ascontiguousarray(extrinsics[:, :3]), extrinsics[:, 3].copy())
    image = splat_image(cam, radius, camera.in_frustum(points), camera)
    return splat(cam, normal, radius, image.pix, image.x0, image.y0, image.width, image.height)


def agreement(meshes: list[Path], n: int, cameras: list[zo.Camera], normals: bool) -> dict[str, float]:
    from zbuf_occlude.render.surfel_zbuffer import shared_surfel_zbuffer
    from zbuf_occlude.visibility.point_kernels import EDGE_ON_COS

    gpu = shared_surfel_zbuffer()
    masks_equal = point_views = ids_equal = covered = 0
    worst_depth = 0.0
    seconds: dict[str, list[float]] = {"cpu": [], "gpu": []}
    for path in meshes:
        mesh = zo.load_mesh(path)
        points, face_index = zo.sample_surface(mesh, n, seed=0)
        surfels = zo.point_surfels(points, mesh.face_normals[face_index] if normals else None)
        for k, camera in enumerate(cameras):
            masks = {}
            for backend in ("cpu", "gpu") if k % 2 == 0 else ("gpu", "cpu"):
                start = time.perf_counter()
                masks[backend] = surfels.visible(camera, backend=backend)
                seconds[backend].append(time.perf_counter() - start)
            masks_equal += int(np.count_nonzero(masks["gpu"] == masks["cpu"]))
            point_views += n
            depth_cpu, ids_cpu = buffers_of(surfels, camera, splat_surfels)
            depth_gpu, ids_gpu = buffers_of(surfels, camera, lambda *a: gpu.splat(*a, edge_on_cos=EDGE_ON_COS))
            any_covered = (ids_cpu >= 0) | (ids_gpu >= 0)
            ids_equal += int(np.count_nonzero((ids_cpu == ids_gpu) & any_covered))
            covered += int(np.count_nonzero(any_covered))
            both = (ids_cpu == ids_gpu) & (ids_cpu >= 0)
            if both.any():
                rel = np.abs(depth_gpu[both] - depth_cpu[both]) / depth_cpu[both]
                worst_depth = max(worst_depth, float(rel.max()))
    return {
        "masks": masks_equal / point_views,
        "ids": ids_equal / max(covered, 1),
        "depth": worst_depth,
        "point_views": point_views,
        **{b: 1e3 * statistics.median(v) for b, v in seconds.items()},
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=REPO_ROOT / "data" / "samples")
    parser.add_argument("--points", default="2048,10000", help="comma-separated point counts (default 2048,10000)")
    parser.add_argument("--poses", default="fibonacci:16", help="a zo.view_schedule spec (default fibonacci:16)")
    parser.add_argument("--meshes", type=int, default=0, help="use the first this many meshes (default: all)")
    parser.add_argument("--normals", action="store_true", help="the faces' normals, not estimated ones")
    args = parser.parse_args(argv)
    from zbuf_occlude.render.context import context_info

    meshes = sorted(p for p in args.root.rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS)
    meshes = meshes[: args.meshes] if args.meshes > 0 else meshes
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule(args.poses)]
    info = context_info()
    print(
        f"# {len(meshes)} meshes of {args.root.name}, {len(cameras)} poses ({args.poses}), "
        f"normals {'of the faces' if args.normals else 'estimated'}"
    )
    print(f"# OpenGL: {info['renderer']} ({info['backend']}, {info['version']}); load average before: {load_average()}")
    print()
    print(
        "| N | point-views | masks equal | winning surfel equal (covered pixels) | depth, largest relative difference "
        "| CPU ms/view | GPU ms/view |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in (int(v) for v in args.points.split(",")):
        row = agreement(meshes, n, cameras, args.normals)
        print(
            f"| {n:,} | {row['point_views']:,} | {row['masks']:.4%} | {row['ids']:.4%} | {row['depth']:.1e} "
            f"| {row['cpu']:.1f} | {row['gpu']:.1f} |",
            flush=True,
        )
    print()
    print(f"# load average after: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
