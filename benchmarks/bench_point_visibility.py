"""Point-only visibility per view: the CPU rasteriser (numba) beside the GPU one (OpenGL point
sprites), and Open3D's hidden point removal as the baseline (prints a Markdown table; not a test).

One shipped mesh (default ``chair_0001``), N points sampled from it (``zo.sample_surface``, seed
0), no normals (estimated, as the registered method ``point-splat``).  The surfels are prepared
once per N (``zo.point_surfels``: the neighbour search and the normals; its time is reported
apart, after a warm-up cloud), then each pose runs ``surfels.visible(camera, backend=...)`` for
both backends, interleaved pose by pose (the order alternates, so that a shared machine's load
hits both alike), after one warm-up pose (numba's and the shaders' compilation).  Reported per
N: the median wall ms per view over the poses, and the share of point-views whose masks agree
between the backends.

Open3D's ``hidden_point_removal`` (Katz et al. 2007) at radius factor 100 (Open3D's example, the
``open3d-hpr`` method's default) runs on the same points and poses when ``import open3d`` works.

The load average is printed before and after: the numbers are indicative on a shared machine.
On Mesa llvmpipe the "GPU" is the CPU too; the renderer is printed.

Usage::

    .venv/bin/python benchmarks/bench_point_visibility.py                    # 2,048 / 10,000 / 100,000 points, 16 poses
    .venv/bin/python benchmarks/bench_point_visibility.py --points 2048 --poses fibonacci:4
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

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MESH = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
WARMUP_POSE = (-40.0, 10.0)
#: Open3D's example radius, in diameters of the cloud.
HPR_FACTOR = 100.0
BACKENDS = ("cpu", "gpu")


def load_average() -> str:
    return ", ".join(f"{v:.2f}" for v in os.getloadavg())


def hpr_view(points: np.ndarray, camera: zo.Camera) -> tuple[float, np.ndarray]:
    """Wall ms of one Open3D HPR call (cloud built outside the timing), and its mask."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    start = time.perf_counter()
    _, kept = cloud.hidden_point_removal(camera.eye, diameter * HPR_FACTOR)
    elapsed = 1e3 * (time.perf_counter() - start)
    mask = np.zeros(len(points), dtype=bool)
    mask[np.asarray(kept, dtype=np.int64)] = True
    return elapsed, mask


def bench_n(mesh, n: int, cameras: list, with_hpr: bool) -> dict:
    points, _ = zo.sample_surface(mesh, n, seed=0)
    start = time.perf_counter()
    surfels = zo.point_surfels(points)
    prepare_ms = 1e3 * (time.perf_counter() - start)
    warm = zo.camera_on_sphere(*WARMUP_POSE)
    for backend in BACKENDS:
        surfels.visible(warm, backend=backend)
    times: dict[str, list[float]] = {b: [] for b in BACKENDS}
    hpr_ms: list[float] = []
    agree = total = 0
    for index, camera in enumerate(cameras):
        masks = {}
        for backend in BACKENDS if index % 2 == 0 else BACKENDS[::-1]:
            start = time.perf_counter()
            masks[backend] = surfels.visible(camera, backend=backend)
            times[backend].append(1e3 * (time.perf_counter() - start))
        agree += int(np.count_nonzero(masks["cpu"] == masks["gpu"]))
        total += n
        if with_hpr:
            hpr_ms.append(hpr_view(points, camera)[0])
    row = {"n": n, "prepare_ms": prepare_ms, "agree": agree / total}
    row.update({b: statistics.median(times[b]) for b in BACKENDS})
    row["hpr"] = statistics.median(hpr_ms) if hpr_ms else None
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, default=DEFAULT_MESH)
    parser.add_argument("--points", type=int, nargs="+", default=[2048, 10_000, 100_000])
    parser.add_argument("--poses", default="fibonacci:16", help="a zo.view_schedule spec (default fibonacci:16)")
    parser.add_argument("--no-hpr", action="store_true", help="skip Open3D's hidden point removal")
    args = parser.parse_args(argv)
    try:
        import open3d  # noqa: F401
    except ImportError:
        with_hpr = False
    else:
        with_hpr = not args.no_hpr
    from zbuf_occlude.render.context import context_info
    from zbuf_occlude.render.point_sprites import shared_point_sprites

    info = context_info()
    sprites = shared_point_sprites()
    mesh = zo.load_mesh(args.mesh)
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule(args.poses)]
    zo.point_surfels(zo.sample_surface(mesh, 256, seed=1)[0])  # numba's compilation is not preparation
    print(f"mesh {args.mesh.name}, {len(cameras)} poses ({args.poses}), no normals (estimated)")
    print(f"OpenGL: {info['renderer']} ({info['backend']}, {info['version']}); "
          f"largest point size {sprites.max_point_size:g} px")
    print(f"CPU cores: {len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()}; "
          f"load average (1, 5, 15 min) before: {load_average()}")
    print()
    print("| N | prepare (`zo.point_surfels`) ms | CPU ms/view | GPU ms/view | CPU / GPU | masks equal | "
          "Open3D HPR ms/view | HPR / CPU | HPR / GPU |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n in args.points:
        row = bench_n(mesh, n, cameras, with_hpr)
        hpr = "n/a" if row["hpr"] is None else f"{row['hpr']:.1f}"
        ratios = ("n/a", "n/a")
        if row["hpr"] is not None:
            ratios = (f"{row['hpr'] / row['cpu']:.1f}×", f"{row['hpr'] / row['gpu']:.1f}×")
        print(f"| {n:,} | {row['prepare_ms']:.1f} | {row['cpu']:.1f} | {row['gpu']:.1f} | "
              f"{row['cpu'] / row['gpu']:.2f}× | "
              f"{row['agree']:.3%} | {hpr} | {ratios[0]} | {ratios[1]} |", flush=True)
    print()
    print(f"load average (1, 5, 15 min) after: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
