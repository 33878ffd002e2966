"""Cost per pulse of the multi-return scan against the first-return scan of the same scanner (not a test; prints a Markdown table).

Three families of cases, each against its own first-return scan (its first case); ``--scene``
picks the spinning ones, ``--no-airborne`` leaves the airborne one out:

* **sector** (``--scene sector``): a vegetation mesh (``--mesh``; default
  ``../shared/data/street_objects/bush/gazebo__oak_tree.dae`` where present, else the shipped
  ``data/samples/table/test/table_0393.off``) 4 m tall, 8 m from an HDL-32E on the ground plane;
  the scanner fires only in the object's azimuth sector (±``--sector`` degrees), so most pulses
  meet the object.  The ``hdl32e`` preset as shipped (1 ray, 1 return: the reference), then the
  multi-return model (``max_returns`` 4, range resolution 0.5 m, divergence 0.3°) at
  ``footprint_rays`` K for each K of ``--ks`` (default 1, 7, 19, 37), opaque (first hits only)
  and with the reflectance table's transmittance (``scan(transmittance="table")``: foliage lets
  0.3 of each sub-ray on, so sub-rays are cast again through the crown); and, at the default
  footprint (K = 7), "directions and cast alone": the footprint's sub-ray directions and their
  first hits (Embree, exact float64 ranges), no echoes: the floor of any exact scan of that
  footprint.
* **turn** (``--scene turn``): four shipped meshes (``data/samples``: a table, a chair, a desk
  and a sofa, 1.5 m tall, 6 m from the sensor, 90° apart) on the ground plane; the ``hdl32e``
  preset over a full turn (69,440 pulses), as shipped (the reference), then
  ``with_beam(..., footprint_rays=K, max_returns=2, range_resolution_m=0.75)`` for each K of
  ``--ks`` (default 7, the default footprint, and 19).
* **airborne**: ``scan_airborne`` over the turn's four meshes with the ``riegl-q1560`` preset
  (19 sub-rays, 15 returns, the materials' optics) over the square ``±--half-size`` m around
  them, against the same scanner with one ray and one return (``footprint_rays=1,
  max_returns=1, range_resolution_m=0``: the ideal beam's geometry, the preset's noise).

``--echo-rules chain,waveform`` runs every multi-return case once per echo rule
(``Beam.echo_rule``: the chain of hits, or the peaks of the pulse's waveform; default chain alone),
the waveform's cases named so.  In the turn and airborne families each multi-return case runs twice:
with ``footprint="exact"`` (every sub-ray cast) and with the default cast, "auto", which is the
adaptive footprint there (:mod:`zbuf_occlude.sensors.beam.adaptive_cast`: sub-rays cast only where
a footprint may hold two surfaces); the table gives the share of pulses whose sub-rays were not
cast (the scan's ``footprint_uniform_share``).  The sector family casts every sub-ray (``"exact"``).

Repeats are interleaved (every case once per round, ``--repeats`` rounds after one warm-up
round that builds the Embree BVH and the caches), so load changes hit every case alike.  The
table gives the median wall and CPU (``time.process_time``) time per scan and per pulse, the
ratio of medians to the family's first-return scan from this run, the points, and the shares of
the pulses with a return that have 1, 2 and 3 or more returns (seed 0).  The load average is
printed before and after: compare ratios, not times, between runs, and only runs at a similar
load.  numpy's BLAS runs ``--blas-threads`` threads (default 1; 0: as the environment sets
them): a multithreaded OpenBLAS busy-waits on a loaded machine, which makes the scan's
``(P, 3) @ (3, 3)`` products erratic and inflates the cheap first-return scan most.

``--profile`` prints, after the table, cProfile's ``--profile-lines`` costliest calls (sorted by
``--profile-sort``: own time, or cumulative time) over ``--repeats`` scans of the first opaque
multi-return case at the default footprint (else the first multi-return case): where the time
of the multi-return path goes (Embree, the sub-ray directions, the exact ranges, the echoes).

    .venv/bin/python benchmarks/bench_returns.py                        # every family, ~2-3 min on 2 cores
    .venv/bin/python benchmarks/bench_returns.py --scene sector --no-airborne --ks 1,7,19,37
    .venv/bin/python benchmarks/bench_returns.py --scene turn --repeats 9 --ks 7,19
    .venv/bin/python benchmarks/bench_returns.py --scene turn --ks 7 --no-airborne --profile
    .venv/bin/python benchmarks/bench_returns.py --blas-threads 0      # BLAS threads as the environment sets them
    .venv/bin/python benchmarks/bench_returns.py --scene turn --echo-rules chain,waveform   # the two echo rules side by side
"""

from __future__ import annotations

import argparse
import cProfile
import os
import platform
import pstats
import statistics
import time
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable

import numpy as np
from threadpoolctl import threadpool_limits

from zbuf_occlude.sensors import Lidar, ScanScene, scan, with_beam
from zbuf_occlude.sensors.patterns.airborne_presets import airborne_preset
from zbuf_occlude.sensors.raycast.embree import cast_embree
from zbuf_occlude.sensors.scan import scan_airborne

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "data" / "samples"
#: The sector scene's object: a shared bush mesh where present, else a shipped one.
BUSH = ROOT.parent / "shared" / "data" / "street_objects" / "bush" / "gazebo__oak_tree.dae"
FALLBACK = SAMPLES / "table" / "test" / "table_0393.off"
#: The default footprint: scan --footprint's 7 sub-rays.
DEFAULT_K = 7
#: The sector scene's multi-return beam fields besides the footprint.
SECTOR_MULTI = {"max_returns": 4, "range_resolution_m": 0.5, "divergence_deg": 0.3}
#: The sector scene's object: distance from the sensor and height, metres.
SECTOR_DISTANCE_M, SECTOR_SIZE_M = 8.0, 4.0
#: (file under data/samples, class): the turn and airborne scenes' objects, placed 90° apart.
OBJECTS = (
    ("table/test/table_0393.off", "table"),
    ("chair/train/chair_0001.off", "chair"),
    ("desk/test/desk_0201.off", "desk"),
    ("sofa/test/sofa_0681.off", "sofa"),
)
#: Distance of the turn's objects from the sensor (and from the airborne square's centre), metres, and their height.
DISTANCE_M, SIZE_M = 6.0, 1.5
#: The turn's multi-return beam fields besides the footprint (a 5 ns pulse: c·τ/2 = 0.75 m).
TURN_MULTI = {"max_returns": 2, "range_resolution_m": 0.75}
#: The spinning scenes' default footprint sub-ray counts.
DEFAULT_KS = {"sector": "1,7,19,37", "turn": "7,19"}


@dataclass(frozen=True)
class Case:
    """One timed case: ``run(seed)`` scans and returns the Scan, or (the cast-alone floor) the number of pulses."""

    family: str
    name: str
    run: Callable[[int], object]
    #: Footprint sub-rays of a multi-return case; None for a first-return reference.
    k: int | None = None
    #: Whether the case is an opaque, exact multi-return scan (what --profile looks for).
    plain: bool = False


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min)"


def _cast_alone(scene: ScanScene, lidar: Lidar, sector: tuple[float, float]) -> int:
    """The sub-rays of ``lidar``'s footprint and their first hits (Embree, then the exact float64
    range on the hit face), nothing else: what any scan of that footprint pays before its echoes.
    Returns the number of pulses."""
    pose = scene.default_sensor_pose()
    d_sensor, _, _ = lidar.rays(sector)
    cast_embree(scene.build().mesh, pose[:3, 3], lidar.beam.footprint_directions(d_sensor @ pose[:3, :3].T).reshape(-1, 3))
    return len(d_sensor)


def _rule_name(rule: str) -> str:
    """What a case's name says of its echo rule: nothing for the chain rule (the default)."""
    return "" if rule == "chain" else f", {rule}"


def _sector_cases(args, ks: list[int], rules: list[str]) -> list[Case]:
    scene = ScanScene().add(args.mesh, class_name="bush", position_m=(SECTOR_DISTANCE_M, 0.0), size_m=SECTOR_SIZE_M)
    hdl = Lidar.preset("hdl32e")
    sector = (-args.sector, args.sector)
    cases = [Case("sector", "hdl32e: 1 ray, 1 return", lambda seed: scan(scene, hdl, seed=seed, azimuth_range_deg=sector))]
    for k, rule in ((k, rule) for k in ks for rule in rules if k > 1 or rule == "chain"):
        lidar = with_beam(hdl, footprint_rays=k, echo_rule=rule, **SECTOR_MULTI)
        head = f"hdl32e: {k} sub-rays, {SECTOR_MULTI['max_returns']} returns{_rule_name(rule)}"
        run = lambda seed, s=lidar: scan(scene, s, seed=seed, azimuth_range_deg=sector, footprint="exact")  # noqa: E731
        cases.append(Case("sector", f"{head}, opaque", run, k, True))
        run = lambda seed, s=lidar: scan(scene, s, seed=seed, azimuth_range_deg=sector, transmittance="table", footprint="exact")  # noqa: E731
        cases.append(Case("sector", f"{head}, transmittance", run, k))
        if k == DEFAULT_K and rule == rules[0]:  # the floor: the sub-rays cast, no echoes
            cases.append(
                Case("sector", f"hdl32e: {k} sub-rays: directions and cast alone", lambda seed, s=lidar: _cast_alone(scene, s, sector), k)
            )
    return cases


def _objects_scene() -> ScanScene:
    scene = ScanScene()
    for i, (path, name) in enumerate(OBJECTS):
        a = np.radians(90.0 * i + 20.0)
        scene.add(str(SAMPLES / path), class_name=name, position_m=(DISTANCE_M * np.cos(a), DISTANCE_M * np.sin(a)), size_m=SIZE_M)
    return scene


def _turn_cases(ks: list[int], rules: list[str]) -> list[Case]:
    scene = _objects_scene()
    hdl = Lidar.preset("hdl32e")
    cases = [Case("turn", "hdl32e: 1 ray, 1 return", lambda seed: scan(scene, hdl, seed=seed))]
    for k, rule in ((k, rule) for k in ks for rule in rules):
        lidar = with_beam(hdl, footprint_rays=k, echo_rule=rule, **TURN_MULTI)
        for kw in ({"footprint": "exact"}, {}):
            cast = ", exact" if kw else ", default (adaptive)"
            name = f"hdl32e: {k} sub-rays, {TURN_MULTI['max_returns']} returns{_rule_name(rule)}{cast}"
            cases.append(Case("turn", name, lambda seed, s=lidar, kw=kw: scan(scene, s, seed=seed, **kw), k, bool(kw)))
    return cases


def _airborne_cases(half_size_m: float, rules: list[str]) -> list[Case]:
    scene = _objects_scene()
    q1560 = airborne_preset("riegl-q1560")
    one = with_beam(q1560, footprint_rays=1, max_returns=1, range_resolution_m=0.0)
    cases = [Case("airborne", "riegl-q1560: 1 ray, 1 return", lambda seed: scan_airborne(scene, one, half_size_m=half_size_m, seed=seed))]
    k = q1560.beam.footprint_rays
    for rule, kw in ((rule, kw) for rule in rules for kw in ({"footprint": "exact"}, {})):
        scanner = with_beam(q1560, echo_rule=rule)
        cast = ", exact" if kw else ", default (adaptive)"
        name = f"riegl-q1560: {k} sub-rays, {q1560.beam.max_returns} returns{_rule_name(rule)}{cast}"
        run = lambda seed, kw=kw, s=scanner: scan_airborne(scene, s, half_size_m=half_size_m, seed=seed, **kw)  # noqa: E731
        cases.append(Case("airborne", name, run, k, bool(kw)))
    return cases


def _cases(args) -> list[Case]:
    """Every case of the run, family by family; a family's first case is its first-return reference."""
    scenes = ("sector", "turn") if args.scene == "all" else (args.scene,)
    rules = [v for v in args.echo_rules.split(",") if v]
    cases: list[Case] = []
    for family in scenes:
        ks = [int(v) for v in (args.ks or DEFAULT_KS[family]).split(",") if v]
        cases += _sector_cases(args, ks, rules) if family == "sector" else _turn_cases(ks, rules)
    if args.airborne:
        cases += _airborne_cases(args.half_size, rules)
    return cases


def _shares(s) -> str:
    """Shares of the pulses with a return that have 1, 2 and 3+ returns, percent."""
    n = s.number_of_returns[s.return_number == 1].astype(np.int64)
    if not len(n):
        return "–"
    return " / ".join(f"{100.0 * v:.1f}" for v in (np.mean(n == 1), np.mean(n == 2), np.mean(n >= 3)))


def _profile(cases: list[Case], args) -> None:
    multi = [c for c in cases if c.k is not None]
    if not multi:
        print("\n## cProfile: no multi-return case in this run")
        return
    case = next((c for c in multi if c.plain and c.k == DEFAULT_K), multi[0])
    order = "own" if args.profile_sort == "tottime" else "cumulative"
    profile = cProfile.Profile()
    profile.enable()
    for rnd in range(args.repeats):
        case.run(rnd)
    profile.disable()
    print(f"\n## cProfile: {args.repeats} scans of {case.family}: {case.name}, by {order} time ({_load()})\n")
    pstats.Stats(profile).sort_stats(args.profile_sort).print_stats(args.profile_lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", choices=("sector", "turn", "all"), default="all", help="the spinning families run (default: both)")
    ap.add_argument("--no-airborne", dest="airborne", action="store_false", help="leave the airborne family out")
    ap.add_argument(
        "--ks",
        default=None,
        help="footprint sub-ray counts of the spinning multi-return cases (default: 1,7,19,37 in the sector, 7,19 over the turn)",
    )
    ap.add_argument("--repeats", type=int, default=7, help="interleaved rounds after the warm-up")
    ap.add_argument(
        "--mesh",
        default=str(BUSH if BUSH.exists() else FALLBACK),
        help="the sector's object (default: a shared bush mesh, else a shipped one)",
    )
    ap.add_argument("--sector", type=float, default=20.0, help="sector: half-width of the fired azimuth sector, degrees")
    ap.add_argument("--half-size", type=float, default=25.0, help="airborne: half-size of the square scanned, metres")
    ap.add_argument("--echo-rules", default="chain", help="echo rules of the multi-return cases, chain and/or waveform (default: chain)")
    ap.add_argument("--blas-threads", type=int, default=1, help="numpy's BLAS threads (0: as the environment sets them)")
    ap.add_argument("--profile", action="store_true", help="then profile the default footprint's opaque scan (cProfile)")
    ap.add_argument("--profile-lines", type=int, default=25, help="calls --profile prints")
    ap.add_argument(
        "--profile-sort", choices=("tottime", "cumulative"), default="tottime", help="--profile's order: own or cumulative time"
    )
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats must be at least 1 (got {args.repeats}): the warm-up round is not timed")
    if args.blas_threads > 0:
        threadpool_limits(args.blas_threads, user_api="blas")
    cases = _cases(args)
    blas = args.blas_threads or "as in the environment"
    where = f"sector: {Path(args.mesh).name} over ±{args.sector:g}°; " if args.scene in ("sector", "all") else ""
    print(f"# bench_returns: {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"{_load()} at the start; {where}BLAS threads: {blas}; {args.repeats} interleaved rounds after a warm-up\n")  # fmt: skip
    wall: dict[tuple[str, str], list[float]] = {(c.family, c.name): [] for c in cases}
    cpu: dict[tuple[str, str], list[float]] = {(c.family, c.name): [] for c in cases}
    for rnd in range(args.repeats + 1):
        for c in cases:
            t0, c0 = time.perf_counter(), time.process_time()
            c.run(rnd)
            if rnd:  # round 0 is the warm-up
                wall[c.family, c.name].append(time.perf_counter() - t0)
                cpu[c.family, c.name].append(time.process_time() - c0)
    print("| family | case | pulses | points | pulses with 1 / 2 / 3+ returns, % | sub-rays not cast, % | ms per scan (wall) "
          "| µs per pulse (wall) | × first return (wall) | µs per pulse (CPU) | × first return (CPU) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    ref: dict[str, tuple[float, float]] = {}
    for c in cases:
        s = c.run(0)
        if isinstance(s, int):  # the cast-alone floor: no scan, no points
            pulses, points, shares, skipped = s, "–", "–", None
        else:
            pulses, points, shares = int(s.meta["n_rays"]), f"{len(s):,}", _shares(s)
            skipped = s.meta.get("footprint_uniform_share")
        skipped = "–" if skipped is None else f"{100.0 * skipped:.1f}"
        w, t = statistics.median(wall[c.family, c.name]), statistics.median(cpu[c.family, c.name])
        ref.setdefault(c.family, (w, t))
        print(f"| {c.family} | {c.name} | {pulses:,} | {points} | {shares} | {skipped} | {1e3 * w:.1f} | {1e6 * w / pulses:.2f} | "
              f"{w / ref[c.family][0]:.2f} | {1e6 * t / pulses:.2f} | {t / ref[c.family][1]:.2f} |")  # fmt: skip
    print(
        f"\n{_load()} at the end; ratios are of medians from this run, each to its family's first case "
        f"(default footprint: K = {DEFAULT_K})."
    )
    if args.profile:
        _profile(cases, args)


if __name__ == "__main__":
    main()
