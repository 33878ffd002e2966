"""Cost per pulse of the multi-return scan against today's one-ray, one-return scan (not a test; prints a Markdown table).

Scene: a vegetation mesh (``../shared/data/street_objects/bush/gazebo__oak_tree.dae`` where
present, else the shipped ``data/samples/table/test/table_0393.off``) 4 m tall, 8 m from an
HDL-32E on the ground plane; the scanner fires only in the object's azimuth sector (±``--sector``
degrees), so most pulses meet the object.  Cases:

* ``today``: ``footprint_rays`` 1, ``max_returns`` 1 (the reference: the scan before returns);
* ``K sub-rays``: the multi-return model (``max_returns`` 4, range resolution 0.5 m, divergence
  0.3°) at ``footprint_rays`` K, opaque (first hits only) and with the reflectance table's
  transmittance (``scan(transmittance="table")``: foliage lets 0.3 of each
  sub-ray on, so sub-rays are cast again through the crown);
* ``K sub-rays: directions and cast alone`` (default K): the footprint's sub-ray directions and
  their first hits (Embree, exact float64 ranges), no echoes: the floor of any exact scan of
  that footprint.

Repeats are interleaved (every case once per round, ``--repeats`` rounds after one warm-up
round that builds the Embree BVH), so load changes hit every case alike; the table gives the
median wall time per scan and per pulse, and the ratio of medians to ``today`` from this run.
The load average is printed before and after.

``--profile`` prints, after the table, cProfile's 20 costliest calls (cumulative time) over
``--repeats`` scans of the default footprint, opaque: where the time of the multi-return model
goes (Embree's ``run``, the sub-ray directions, the exact ranges, the echoes).

    python benchmarks/bench_returns.py
    python benchmarks/bench_returns.py --ks 1,7 --repeats 5
    python benchmarks/bench_returns.py --ks 7 --profile
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import statistics
import time
from pathlib import Path

from zbuf_occlude.sensors import Lidar, ScanScene, scan
from zbuf_occlude.sensors.raycast import cast_embree

ROOT = Path(__file__).resolve().parents[1]
BUSH = ROOT.parent / "shared" / "data" / "street_objects" / "bush" / "gazebo__oak_tree.dae"
FALLBACK = ROOT / "data" / "samples" / "table" / "test" / "table_0393.off"
#: The default footprint: scan --footprint's 7 sub-rays.
DEFAULT_K = 7


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load {one:.2f} (1 min), {five:.2f} (5 min)"


def _cast_alone(scene: ScanScene, lidar: Lidar, sector) -> None:
    """The sub-rays of ``lidar``'s footprint and their first hits (Embree, then the exact float64
    range on the hit face), nothing else: what any scan of that footprint pays before its echoes."""
    pose = scene.default_sensor_pose()
    d_sensor, _, _ = lidar.rays(sector)
    cast_embree(scene.build().mesh, pose[:3, 3], lidar.footprint_directions(d_sensor @ pose[:3, :3].T).reshape(-1, 3))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--mesh", default=str(BUSH if BUSH.exists() else FALLBACK), help="the object (default: a shared bush mesh, else a shipped one)"
    )
    ap.add_argument("--ks", default="1,7,19,37", help="footprint sub-ray counts of the multi-return cases")
    ap.add_argument("--repeats", type=int, default=5, help="interleaved rounds after the warm-up")
    ap.add_argument("--sector", type=float, default=20.0, help="half-width of the fired azimuth sector, degrees")
    ap.add_argument("--profile", action="store_true", help="then profile the default footprint's opaque scan (cProfile, 20 calls)")
    args = ap.parse_args()
    scene = ScanScene().add(args.mesh, class_name="bush", position_m=(8.0, 0.0), size_m=4.0)
    built = scene.build()
    base = Lidar.preset("hdl32e")
    multi = {"max_returns": 4, "range_resolution_m": 0.5, "beam_divergence_deg": 0.3}
    cases = [("today (1 ray, 1 return)", base, {})]
    for k in (int(v) for v in args.ks.split(",")):
        lidar = base.with_(footprint_rays=k, **multi)
        cases.append((f"{k} sub-rays, opaque", lidar, {}))
        cases.append((f"{k} sub-rays, transmittance", lidar, {"transmittance": "table"}))
        if k == DEFAULT_K:  # the floor: the sub-rays cast, no echoes
            cases.append((f"{k} sub-rays: directions and cast alone", lidar, None))
    sector = (-args.sector, args.sector)
    print(f"# bench_returns: {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, {_load()} at the start; "
          f"{Path(args.mesh).name} ({len(built.mesh.faces) - 2} faces) + ground, hdl32e over ±{args.sector:g}°, {args.repeats} interleaved rounds\n")  # fmt: skip
    times: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    cpu: dict[str, list[float]] = {name: [] for name, _, _ in cases}
    for rnd in range(args.repeats + 1):
        for name, lidar, kw in cases:
            t0, c0 = time.perf_counter(), time.process_time()
            if kw is None:
                _cast_alone(scene, lidar, sector)
            else:
                pulses = scan(scene, lidar, seed=rnd, azimuth_range_deg=sector, **kw).meta["n_rays"]
            wall, used = time.perf_counter() - t0, time.process_time() - c0
            if rnd:  # round 0 is the warm-up
                times[name].append(wall)
                cpu[name].append(used)
    ref, ref_cpu = statistics.median(times[cases[0][0]]), statistics.median(cpu[cases[0][0]])
    print(
        "| case | pulses | points | points with several returns | ms per scan (wall) | µs per pulse (wall) | × today (wall) | µs per pulse (CPU) | × today (CPU) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, lidar, kw in cases:
        s = None if kw is None else scan(scene, lidar, seed=0, azimuth_range_deg=sector, **kw)
        med, med_cpu = statistics.median(times[name]), statistics.median(cpu[name])
        points, several = ("–", "–") if s is None else (f"{len(s):,}", f"{int((s.number_of_returns > 1).sum()):,}")
        print(
            f"| {name} | {pulses:,} | {points} | {several} | {1e3 * med:.1f} | {1e6 * med / pulses:.2f} | {med / ref:.2f} | "
            f"{1e6 * med_cpu / pulses:.2f} | {med_cpu / ref_cpu:.2f} |"
        )
    print(f"\n{_load()} at the end; ratios are of medians from this run (default footprint: K = {DEFAULT_K}).")
    if args.profile:
        lidar = base.with_(footprint_rays=DEFAULT_K, **multi)
        profile = cProfile.Profile()
        profile.enable()
        for rnd in range(args.repeats):
            scan(scene, lidar, seed=rnd, azimuth_range_deg=sector)
        profile.disable()
        print(f"\n## cProfile: {args.repeats} scans, {DEFAULT_K} sub-rays, opaque ({_load()})\n")
        pstats.Stats(profile).sort_stats("cumulative").print_stats(20)


if __name__ == "__main__":
    main()
