"""Cost per pulse of the multi-return scan against the first-return scan of the same scanner (not a test; prints Markdown tables).

Scene: four shipped meshes (``data/samples``: a table, a chair, a desk and a sofa, 1.5 m
tall, 6 m from the sensor, 90° apart) on the scene's ground plane.  Two families of cases,
each against its own first-return scan:

* **spinning**: the ``hdl32e`` preset over a full turn (69,440 pulses), as shipped (1 ray, 1
  return: the reference), then ``with_beam(..., footprint_rays=K, max_returns=2,
  range_resolution_m=0.75)`` for each K of ``--ks`` (default 7, the default footprint, and 19);
* **airborne**: ``scan_airborne`` with the ``riegl-q1560`` preset (19 sub-rays, 15 returns,
  the materials' optics) over the square ``±--half-size`` m around the objects, against the same
  scanner with one ray and one return (``footprint_rays=1, max_returns=1,
  range_resolution_m=0``: the ideal beam's geometry, the preset's noise).

Where ``scan`` takes ``footprint="adaptive"`` (:mod:`zbuf_occlude.sensors.adaptive_footprint`:
sub-rays cast only where a footprint may hold two surfaces), each multi-return case is run that
way too, and the table gives the share of pulses whose sub-rays were not cast.

Repeats are interleaved (every case once per round, ``--repeats`` rounds after one warm-up
round that builds the Embree BVH and the caches), so load changes hit every case alike.  The
table gives the median wall and CPU (``time.process_time``) time per scan and per pulse, and
the ratio of medians to the family's first-return scan from this run; the points, and the
shares of pulses with a return that have 1, 2 and 3 or more returns (seed 0).  The load
average is printed before and after: compare ratios, not times, between runs, and only runs
at a similar load.  numpy's BLAS runs ``--blas-threads`` threads (default 1; 0: as the
environment sets them): a multithreaded OpenBLAS busy-waits on a loaded machine, which makes
the scan's ``(P, 3) @ (3, 3)`` products erratic and inflates the cheap first-return scan most.

``--profile`` prints, after the tables, cProfile's ``--profile-lines`` costliest calls (own
time) over ``--repeats`` scans of the first multi-return spinning case: where the time of the
multi-return path goes (Embree, the sub-ray directions, the exact ranges, the echoes).

    .venv/bin/python benchmarks/returns_cost.py                       # ~1 min on 2 cores
    .venv/bin/python benchmarks/returns_cost.py --repeats 9 --ks 7,19
    .venv/bin/python benchmarks/returns_cost.py --ks 7 --no-airborne --profile
    .venv/bin/python benchmarks/returns_cost.py --blas-threads 0     # BLAS threads as the environment sets them
"""

from __future__ import annotations

import argparse
import cProfile
import inspect
import os
import platform
import pstats
import statistics
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from zbuf_occlude.sensors import Lidar, ScanScene, scan, with_beam
from zbuf_occlude.sensors.airborne_presets import airborne_preset
from zbuf_occlude.sensors.scan import scan_airborne

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"
#: (file under data/samples, class): the objects of the scene, placed 90° apart.
OBJECTS = (
    ("table/test/table_0393.off", "table"),
    ("chair/train/chair_0001.off", "chair"),
    ("desk/test/desk_0201.off", "desk"),
    ("sofa/test/sofa_0681.off", "sofa"),
)
#: Distance of the objects from the sensor (and from the airborne square's centre), metres, and their height.
DISTANCE_M, SIZE_M = 6.0, 1.5
#: The spinning multi-return beam's fields besides the footprint (a 5 ns pulse: c·τ/2 = 0.75 m).
MULTI = {"max_returns": 2, "range_resolution_m": 0.75}
#: Whether this version's scans take ``footprint="adaptive"``.
ADAPTIVE = "footprint" in inspect.signature(scan).parameters


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min)"


def _scene() -> ScanScene:
    scene = ScanScene()
    for i, (path, name) in enumerate(OBJECTS):
        a = np.radians(90.0 * i + 20.0)
        scene.add(str(SAMPLES / path), class_name=name, position_m=(DISTANCE_M * np.cos(a), DISTANCE_M * np.sin(a)), size_m=SIZE_M)
    return scene


def _cases(args) -> list[tuple[str, str, object]]:
    """``(family, name, run)``: ``run(seed)`` scans and returns the Scan; a family's first case is its reference."""
    scene = _scene()
    hdl = Lidar.preset("hdl32e")
    modes = [{}] + ([{"footprint": "adaptive"}] if ADAPTIVE else [])
    cases = [("spinning", "hdl32e: 1 ray, 1 return", lambda seed, s=hdl: scan(scene, s, seed=seed))]
    for k in (int(v) for v in args.ks.split(",") if v):
        lidar = with_beam(hdl, footprint_rays=k, **MULTI)
        for kw in modes:
            name = f"hdl32e: {k} sub-rays, 2 returns{', adaptive' if kw else ''}"
            cases.append(("spinning", name, lambda seed, s=lidar, kw=kw: scan(scene, s, seed=seed, **kw)))
    if args.airborne:
        q1560 = airborne_preset("riegl-q1560")
        one = with_beam(q1560, footprint_rays=1, max_returns=1, range_resolution_m=0.0)
        run = lambda seed, s=one: scan_airborne(scene, s, half_size_m=args.half_size, seed=seed)  # noqa: E731
        cases.append(("airborne", "riegl-q1560: 1 ray, 1 return", run))
        for kw in modes:
            name = f"riegl-q1560: {q1560.beam.footprint_rays} sub-rays, {q1560.beam.max_returns} returns{', adaptive' if kw else ''}"
            run = lambda seed, s=q1560, kw=kw: scan_airborne(scene, s, half_size_m=args.half_size, seed=seed, **kw)  # noqa: E731
            cases.append(("airborne", name, run))
    return cases


def _shares(s) -> str:
    """Shares of the pulses with a return that have 1, 2 and 3+ returns, percent."""
    n = s.number_of_returns[s.return_number == 1].astype(np.int64)
    if not len(n):
        return "–"
    return " / ".join(f"{100.0 * v:.1f}" for v in (np.mean(n == 1), np.mean(n == 2), np.mean(n >= 3)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ks", default="7,19", help="footprint sub-ray counts of the spinning multi-return cases")
    ap.add_argument("--repeats", type=int, default=7, help="interleaved rounds after the warm-up")
    ap.add_argument("--half-size", type=float, default=25.0, help="airborne: half-size of the square scanned, metres")
    ap.add_argument("--no-airborne", dest="airborne", action="store_false", help="leave the airborne cases out")
    ap.add_argument("--profile", action="store_true", help="then profile the first multi-return spinning case (cProfile)")
    ap.add_argument("--profile-lines", type=int, default=25, help="calls --profile prints")
    ap.add_argument("--blas-threads", type=int, default=1, help="numpy's BLAS threads (0: as the environment sets them)")
    args = ap.parse_args()
    if args.blas_threads > 0:
        threadpool_limits(args.blas_threads, user_api="blas")
    cases = _cases(args)
    blas = args.blas_threads or "as in the environment"
    print(f"# returns_cost: {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"{_load()} at the start; BLAS threads: {blas}; {args.repeats} interleaved rounds after a warm-up"
          f"{'' if ADAPTIVE else '; this version has no adaptive footprints'}\n")  # fmt: skip
    wall: dict[str, list[float]] = {name: [] for _, name, _ in cases}
    cpu: dict[str, list[float]] = {name: [] for _, name, _ in cases}
    for rnd in range(args.repeats + 1):
        for _, name, run in cases:
            t0, c0 = time.perf_counter(), time.process_time()
            run(rnd)
            if rnd:  # round 0 is the warm-up
                wall[name].append(time.perf_counter() - t0)
                cpu[name].append(time.process_time() - c0)
    print("| family | case | pulses | points | pulses with 1 / 2 / 3+ returns, % | sub-rays not cast, % | ms per scan (wall) "
          "| µs per pulse (wall) | × first return (wall) | µs per pulse (CPU) | × first return (CPU) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ref: dict[str, tuple[float, float]] = {}
    for family, name, run in cases:
        s = run(0)
        pulses = int(s.meta["n_rays"])
        w, c = statistics.median(wall[name]), statistics.median(cpu[name])
        ref.setdefault(family, (w, c))
        skipped = s.meta.get("footprint_uniform_share")
        skipped = "–" if skipped is None else f"{100.0 * skipped:.1f}"
        print(f"| {family} | {name} | {pulses:,} | {len(s):,} | {_shares(s)} | {skipped} | {1e3 * w:.1f} | {1e6 * w / pulses:.2f} | "
              f"{w / ref[family][0]:.2f} | {1e6 * c / pulses:.2f} | {c / ref[family][1]:.2f} |")  # fmt: skip
    print(f"\n{_load()} at the end; ratios are of medians from this run, each to its family's first case.")
    if args.profile:
        family, name, run = next(c for c in cases if c[0] == "spinning" and "sub-rays" in c[1])
        profile = cProfile.Profile()
        profile.enable()
        for rnd in range(args.repeats):
            run(rnd)
        profile.disable()
        print(f"\n## cProfile: {args.repeats} scans of {name} ({_load()})\n")
        pstats.Stats(profile).sort_stats("tottime").print_stats(args.profile_lines)


if __name__ == "__main__":
    main()
