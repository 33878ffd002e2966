"""Point-only visibility on the GPU, part by part: where a view of ``surfels.visible(camera,
backend="gpu")`` spends its time, beside the CPU backend's whole view (prints Markdown; not a test).

For each point count N: the shipped meshes (``data/samples``, or ``--root``), N points sampled from
each (``zo.sample_surface``, seed 0), prepared once without normals (``zo.point_surfels``).  Then

* **whole views**, interleaved pose by pose (the backends' order alternating): the median wall ms
  of ``visible`` on each backend, with the hull test (the default up to 20,000 points) and without;
* **the GPU view's parts** under ``cProfile``, hull test off: the cumulative ms a view of the calls
  that make it up (the camera frame, the image, the uploads, the buffers' clearing and copies on
  the GPU, the passes' dispatches and barriers, the read-back of the mask, which waits for the
  GPU), and the rest.  A part a profiler cannot see (numba's compiled
  functions on some Python versions) reads 0 and its time is in the rest.  cProfile adds its own cost to Python-heavy
  parts; the whole-view rows are timed without it.

Usage::

    .venv/bin/python benchmarks/profile_point_splats.py                      # 2,048, 10,000, 100,000 points
    .venv/bin/python benchmarks/profile_point_splats.py --points 512 --poses fibonacci:2 --meshes 1
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

import zbuf_occlude as zo
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

REPO_ROOT = Path(__file__).resolve().parents[1]

#: The parts of a GPU view: a label, and the profiled functions (file's end, function name) summed into it.
PARTS = (
    ("frustum test", (("cameras.py", "in_frustum"),)),
    ("camera frame", (("point_kernels.py", "camera_frame"),)),
    ("image extent", (("splat_image.py", "splat_image"),)),
    ("uploads (surfels, points)", (("moderngl/__init__.py", "write"),)),
    ("clearing and copying buffers (GPU copies)", (("moderngl/__init__.py", "copy_buffer"),)),
    ("dispatching the passes (stages, resolve, decision)", (("compute.py", "dispatch"),)),
    ("barriers", (("moderngl/__init__.py", "memory_barrier"),)),
    ("read-back (waits for the GPU)", (("moderngl/__init__.py", "read"), ("moderngl/__init__.py", "read_into"))),
    ("decision on the CPU (a view of several tiles)", (("point_kernels.py", "decide"), ("point_kernels.py", "decide_threaded"))),
)
#: Own time of the function that runs a tile's passes.
UNPACK = ("surfel_zbuffer.py", "_fill_tile")


def load_average() -> str:
    return ", ".join(f"{v:.2f}" for v in os.getloadavg())


def prepared(meshes: list[Path], n: int) -> list:
    out = []
    for path in meshes:
        points, _ = zo.sample_surface(zo.load_mesh(path), n, seed=0)
        out.append(zo.point_surfels(points))
    return out


def whole_views(surfels: list, cameras: list, hull: bool) -> dict[str, float]:
    """Median wall ms of one ``visible`` call per backend, interleaved."""
    seconds: dict[str, list[float]] = {"cpu": [], "gpu": []}
    for s in surfels:
        for k, camera in enumerate(cameras):
            for backend in ("cpu", "gpu") if k % 2 == 0 else ("gpu", "cpu"):
                start = time.perf_counter()
                s.visible(camera, backend=backend, hull_test=hull)
                seconds[backend].append(time.perf_counter() - start)
    return {b: 1e3 * statistics.median(v) for b, v in seconds.items()}


def gpu_parts(surfels: list, cameras: list) -> tuple[dict[str, float], float]:
    """ms a view of each of :data:`PARTS` under cProfile, and of the whole profiled view."""
    profile = cProfile.Profile()
    views = 0
    start = time.perf_counter()
    profile.enable()
    for s in surfels:
        for camera in cameras:
            s.visible(camera, backend="gpu", hull_test=False)
            views += 1
    profile.disable()
    whole = 1e3 * (time.perf_counter() - start) / views
    stats = pstats.Stats(profile).stats  # {(file, line, name): (cc, nc, tt, ct, callers)}
    parts = {}
    for label, functions in PARTS:
        total = sum(
            ct for (file, _, name), (_, _, _, ct, _) in stats.items()
            if any(file.replace("\\", "/").endswith(end) and name == fn for end, fn in functions)
        )  # fmt: skip
        parts[label] = 1e3 * total / views
    own = sum(tt for (file, _, name), (_, _, tt, _, _) in stats.items() if file.endswith(UNPACK[0]) and name == UNPACK[1])
    parts["a tile's own Python (_fill_tile)"] = 1e3 * own / views
    return parts, whole


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=REPO_ROOT / "data" / "samples")
    parser.add_argument("--points", default="2048,10000,100000", help="comma-separated point counts")
    parser.add_argument("--poses", default="fibonacci:16", help="a zo.view_schedule spec (default fibonacci:16)")
    parser.add_argument("--meshes", type=int, default=0, help="use the first this many meshes (default: all)")
    args = parser.parse_args(argv)
    from zbuf_occlude.render.context import context_info

    meshes = sorted(p for p in args.root.rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS)
    meshes = meshes[: args.meshes] if args.meshes > 0 else meshes
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule(args.poses)]
    sizes = [int(v) for v in args.points.split(",")]
    info = context_info()
    print(f"# {len(meshes)} meshes of {args.root.name}, {len(cameras)} poses ({args.poses}), normals estimated")
    print(f"# OpenGL: {info['renderer']} ({info['backend']}, {info['version']}); load average before: {load_average()}")
    print()
    rows = {}
    for n in sizes:
        surfels = prepared(meshes, n)
        whole_views(surfels[:1], cameras[:2], False)  # warm-up: numba, shaders, the render target
        rows[n] = {
            "hull": whole_views(surfels, cameras, True) if n <= 20_000 else None,
            "plain": whole_views(surfels, cameras, False),
            "parts": gpu_parts(surfels, cameras),
        }
    print("## Whole views (median ms a view, backends interleaved)")
    print()
    print("| N | CPU, hull test | GPU, hull test | CPU, splats alone | GPU, splats alone | GPU / CPU, splats alone |")
    print("|---:|---:|---:|---:|---:|---:|")
    for n, row in rows.items():
        hull = row["hull"]
        cells = f"{hull['cpu']:.2f} | {hull['gpu']:.2f}" if hull else "not run | not run"
        plain = row["plain"]
        print(f"| {n:,} | {cells} | {plain['cpu']:.2f} | {plain['gpu']:.2f} | {plain['gpu'] / plain['cpu']:.2f} |")
    print()
    print("## A GPU view's parts (cProfile, ms a view, hull test off)")
    print()
    print("| part | " + " | ".join(f"{n:,}" for n in sizes) + " |")
    print("|---|" + "---:|" * len(sizes))
    for label in [label for label, _ in PARTS] + ["a tile's own Python (_fill_tile)"]:
        print(f"| {label} | " + " | ".join(f"{rows[n]['parts'][0][label]:.2f}" for n in sizes) + " |")
    rest = [rows[n]["parts"][1] - sum(rows[n]["parts"][0].values()) for n in sizes]
    print("| the rest (Python between the parts) | " + " | ".join(f"{v:.2f}" for v in rest) + " |")
    print("| **whole view, profiled** | " + " | ".join(f"{rows[n]['parts'][1]:.2f}" for n in sizes) + " |")
    print()
    print(f"# load average after: {load_average()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
