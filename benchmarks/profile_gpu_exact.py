"""Where the time of ``zbuffer-exact`` goes: its per-view stages, at several point counts.

For one mesh (default ModelNet10 ``sofa_0001``) and each point count: a kept
:class:`~zbuf_occlude.visibility.gpu_exact.ExactScene`, one warm-up view, then ``--poses``
views twice, interleaved pose by pose:

* unprofiled: the median wall time of ``scene.visible(camera)`` (what a user gets);
* profiled (``ExactMesh.profile``): the GPU is waited for after each stage, so every stage's
  wall time is its own -- the bin count pass, the prefix sum on the CPU (with the count
  read-back), the bin fill pass, the points pass, the read-back of the result bits, and
  their unpacking; the waits add a little to the total.

Also the share of points left to the CPU (float64 near-ties and the frustum border) and the
tile-list statistics.  Markdown on stdout.

Usage::

    python benchmarks/profile_gpu_exact.py                          # 100k, 1M, 10M points
    python benchmarks/profile_gpu_exact.py --points 20000 --poses fibonacci:3   # a quick look
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sofa_mesh import default_mesh  # noqa: E402


def profile(mesh, n_points: int, poses, resolution: int) -> dict:
    import zbuf_occlude as zo
    from zbuf_occlude.visibility.gpu_exact import ExactScene

    points, face_index = zo.sample_surface(mesh, n_points, seed=0)
    cameras = [zo.camera_on_sphere(el, az, resolution=resolution) for el, az in poses]
    t = time.perf_counter()
    scene = ExactScene(mesh, points, face_index)
    setup = time.perf_counter() - t
    with scene:
        scene.visible(zo.camera_on_sphere(-40.0, 10.0, resolution=resolution))  # warm-up
        plain, stages, cpu_share = [], {}, []
        for cam in cameras:
            scene.gpu.profile = False
            t = time.perf_counter()
            scene.visible(cam)
            plain.append(time.perf_counter() - t)
            cpu_share.append(scene.last_cpu_fraction)
            scene.gpu.profile = True
            scene.visible(cam)
            for stage, seconds in scene.gpu.last_timings.items():
                stages.setdefault(stage, []).append(seconds)
        scene.gpu.profile = False
        stats = dict(scene.gpu.last_stats)
    return {
        "n_points": n_points,
        "setup_ms": 1e3 * setup,
        "view_ms": 1e3 * statistics.median(plain),
        "stages_ms": {k: 1e3 * statistics.median(v) for k, v in stages.items()},
        "cpu_share": statistics.mean(cpu_share),
        "stats": stats,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, default=None, help="mesh file (default: sofa_0001)")
    ap.add_argument("--points", default="100000,1000000,10000000", help="comma-separated point counts")
    ap.add_argument("--poses", default="fibonacci:15", help="view schedule (default: fibonacci:15)")
    ap.add_argument("--resolution", type=int, default=1024, help="image side for the tile grid, pixels")
    args = ap.parse_args(argv)

    import zbuf_occlude as zo
    from zbuf_occlude.render.context import shared_context

    mesh_path = args.mesh or default_mesh()
    mesh = zo.load_mesh(mesh_path)
    poses = zo.view_schedule(args.poses)
    rows = [profile(mesh, int(n), poses, args.resolution) for n in args.points.split(",")]
    info = shared_context().info
    print(
        f"# zbuffer-exact, stage by stage\n\n{mesh_path.name} ({len(mesh.faces):,} faces), {len(poses)} poses, "
        f"{args.resolution}² tile grid; OpenGL renderer {info['GL_RENDERER']}; {os.cpu_count()} CPUs; "
        f"load average {os.getloadavg()[0]:.2f}.\n"
    )
    stages = list(rows[0]["stages_ms"])
    print(
        "| points | set-up ms | view ms (unprofiled) | "
        + " | ".join(f"{s} ms" for s in stages)
        + " | decided on the CPU | tile entries | global faces |"
    )
    print("|" + "---:|" * (len(stages) + 6))
    for r in rows:
        cells = " | ".join(f"{r['stages_ms'][s]:.2f}" for s in stages)
        print(
            f"| {r['n_points']:,} | {r['setup_ms']:.0f} | {r['view_ms']:.2f} | {cells} | {100 * r['cpu_share']:.4f} % "
            f"| {r['stats'].get('entries', 0):,} | {r['stats'].get('global_faces', 0)} |"
        )
    print(f"\nCommand: `python benchmarks/profile_gpu_exact.py {' '.join(argv if argv is not None else sys.argv[1:])}`")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
