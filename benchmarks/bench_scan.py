"""Speed of ``zbuf_occlude.sensors.scan`` (not a test; prints a Markdown table).

Scenes: a shipped mesh (``data/samples/table/test/table_0393.off``, 5344 faces) stretched to
car size (4.5 × 2.0 × 2.0 m) 10 m from the sensor on a ground plane.  For each sensor preset
and backend: rays cast, returns, median wall and CPU time per scan over ``--repeats`` scans
(after one warm-up scan, which builds the Embree BVH or the GL buffers), returns per second.
Full revolutions for the LiDARs (every firing of one turn), the full image for the camera.

    python benchmarks/bench_scan.py                  # all presets, both backends
    python benchmarks/bench_scan.py --sensors hdl32e --backends embree --repeats 5
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

from zbuf_occlude.sensors import DepthCamera, Lidar, ScanScene, ZBufferView, look_at_pose, scan
from zbuf_occlude.sensors.patterns.depth_camera import DEPTH_CAMERA_PRESETS
from zbuf_occlude.sensors.patterns.spinning import LIDAR_PRESETS

MESH = Path(__file__).resolve().parents[1] / "data" / "samples" / "table" / "test" / "table_0393.off"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sensors", default=",".join([*LIDAR_PRESETS, *DEPTH_CAMERA_PRESETS]))
    ap.add_argument("--backends", default="embree,zbuffer")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--resolution", type=int, default=2048, help="zbuffer view size, pixels")
    args = ap.parse_args()
    scene = ScanScene().add(str(MESH), class_name="table", position_m=(10.0, 0.0), yaw_deg=20.0, size_m=(2.0, 4.5, 2.0))
    print(f"# bench_scan: {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs "
          f"(load {os.getloadavg()[0]:.1f}; the machine is shared, so wall times vary), {scene.build().mesh.faces.shape[0]} faces\n")  # fmt: skip
    print("| sensor | backend | rays | returns | ms per scan (wall) | ms per scan (CPU) | returns/s (wall) | Embree fallback rays |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.sensors.split(","):
        sensor = Lidar.preset(name) if name in LIDAR_PRESETS else DepthCamera.preset(name)
        pose = None if isinstance(sensor, Lidar) else look_at_pose([7.0, 0, 1.5], [10, 0, 1.0])  # 3 m, inside its range
        for backend in args.backends.split(","):
            kw = dict(backend=backend, zbuffer=ZBufferView(resolution=args.resolution))
            s = scan(scene, sensor, pose, seed=0, **kw)  # warm-up: BVH / GL context
            wall, cpu = [], []
            for k in range(args.repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                s = scan(scene, sensor, pose, seed=k, **kw)
                wall.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
            w, c = statistics.median(wall), statistics.median(cpu)
            print(
                f"| {name} | {backend} | {s.meta['n_rays']} | {len(s)} | {1e3 * w:.0f} | {1e3 * c:.0f} | {len(s) / w:,.0f} | {s.meta.get('n_fallback', '-')} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
