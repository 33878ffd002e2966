"""Point-only visibility: the one call, its preparation and a prepared view, beside Open3D's hidden
point removal (prints a Markdown table; not a test).

One shipped mesh (default ``chair_0001``), N points sampled from it (``zo.sample_surface``, seed
0), no normals (estimated, as the registered method ``point-splat``).  For each pose, interleaved
(the order reversed every other pose, so that a shared machine's load hits all alike), after a
warm-up (numba's compilation): the one call users make (``zo.visible_mask_points(points,
camera)``, preparation included), the preparation alone (``zo.point_surfels(points)``: the
neighbour search and the normals), one view of a prepared cloud (``surfels.visible(camera)``),
and Open3D's ``hidden_point_removal`` (Katz et al. 2007) at radius factor 100 (Open3D's
example, the ``open3d-hpr`` method's default) when ``import open3d`` works.  Reported per N: the
median wall ms over the poses and the ratios.  ``--gpu`` adds the GPU backend's view (an OpenGL
compute shader; on Mesa llvmpipe the "GPU" is the CPU too) and the share of point-views whose
masks agree with the CPU's.

The load average and numba's thread count are printed: the numbers are indicative on a shared
machine.

Usage::

    .venv/bin/python benchmarks/bench_point_visibility.py                    # 2,048 / 10,000 / 100,000 points, 16 poses
    .venv/bin/python benchmarks/bench_point_visibility.py --points 2048 --poses fibonacci:4 --gpu
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

import zbuf_occlude as zo

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MESH = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
WARMUP_POSE = (-40.0, 10.0)
#: Open3D's example radius, in diameters of the cloud.
HPR_FACTOR = 100.0


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


def _timed(fn, *args, **kwargs) -> float:
    start = time.perf_counter()
    fn(*args, **kwargs)
    return 1e3 * (time.perf_counter() - start)


def bench_n(mesh, n: int, cameras: list, with_hpr: bool, backends: tuple[str, ...]) -> dict:
    """Median wall ms per pose of: the one call (``zo.visible_mask_points``, preparation included),
    the preparation alone (``zo.point_surfels``), one prepared view per backend, and HPR; all
    interleaved pose by pose, the order reversed every other pose."""
    points, _ = zo.sample_surface(mesh, n, seed=0)
    surfels = zo.point_surfels(points)
    warm = zo.camera_on_sphere(*WARMUP_POSE)
    for backend in backends:
        surfels.visible(warm, backend=backend)
    times: dict[str, list[float]] = {}
    agree = total = 0
    for index, camera in enumerate(cameras):
        masks = {}

        def view(backend, camera=camera, masks=masks):
            start = time.perf_counter()
            masks[backend] = surfels.visible(camera, backend=backend)
            return 1e3 * (time.perf_counter() - start)

        tasks = {"one call": lambda camera=camera: _timed(zo.visible_mask_points, points, camera),
                 "prepare": lambda: _timed(zo.point_surfels, points)}  # fmt: skip
        tasks.update({b: (lambda b=b: view(b)) for b in backends})
        if with_hpr:
            tasks["hpr"] = lambda camera=camera: hpr_view(points, camera)[0]
        for name in list(tasks) if index % 2 == 0 else list(tasks)[::-1]:
            times.setdefault(name, []).append(tasks[name]())
        if "gpu" in masks:
            agree += int(np.count_nonzero(masks["cpu"] == masks["gpu"]))
            total += n
    row = {name: statistics.median(values) for name, values in times.items()}
    row.update(n=n, agree=agree / total if total else None)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh", type=Path, default=DEFAULT_MESH)
    parser.add_argument("--points", type=int, nargs="+", default=[2048, 10_000, 100_000])
    parser.add_argument("--poses", default="fibonacci:16", help="a zo.view_schedule spec (default fibonacci:16)")
    parser.add_argument("--no-hpr", action="store_true", help="skip Open3D's hidden point removal")
    parser.add_argument("--gpu", action="store_true", help="also the GPU backend (an OpenGL compute shader) and its agreement")
    args = parser.parse_args(argv)
    try:
        import open3d  # noqa: F401
    except ImportError:
        with_hpr = False
    else:
        with_hpr = not args.no_hpr
    backends = ("cpu", "gpu") if args.gpu else ("cpu",)
    mesh = zo.load_mesh(args.mesh)
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule(args.poses)]
    zo.point_surfels(zo.sample_surface(mesh, 256, seed=1)[0])  # numba's compilation is not preparation
    print(f"mesh {args.mesh.name}, {len(cameras)} poses ({args.poses}), no normals (estimated)")
    if args.gpu:
        from zbuf_occlude.render.context import context_info

        info = context_info()
        print(f"OpenGL: {info['renderer']} ({info['backend']}, {info['version']})")
    print(
        f"CPU cores: {len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()}; "
        f"numba threads: {numba.get_num_threads()}; load average (1, 5, 15 min) before: {load_average()}"
    )
    print()
    head = ["N", "one call ms", "its preparation ms", "one view, prepared (CPU) ms"]
    if args.gpu:
        head += ["GPU view ms", "masks equal, CPU vs GPU"]
    if with_hpr:
        head += ["HPR ×100 ms", "one call / HPR", "HPR / prepared view"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---:|" * len(head))
    for n in args.points:
        row = bench_n(mesh, n, cameras, with_hpr, backends)
        cells = [f"{n:,}", f"{row['one call']:.1f}", f"{row['prepare']:.1f}", f"{row['cpu']:.1f}"]
        if args.gpu:
            cells += [f"{row['gpu']:.1f}", f"{row['agree']:.3%}"]
        if with_hpr:
            cells += [f"{row['hpr']:.1f}", f"{row['one call'] / row['hpr']:.2f}×", f"{row['hpr'] / row['cpu']:.1f}×"]
        print("| " + " | ".join(cells) + " |", flush=True)
    print()
    print(f"load average (1, 5, 15 min) after: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
