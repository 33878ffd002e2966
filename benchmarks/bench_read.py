"""Shuffled reads of a compact data set: ms per item for several ``object_cache`` settings (prints a table).

A compact data set (``--storage compact``) keeps each object's dense cloud and visibility
bitmasks; :class:`zbuf_occlude.OccludedDataset` redraws every sample from them, and keeps the
arrays of up to ``object_cache`` objects in memory.  A shuffled read whose object is not kept
reads and unpacks the object's shard first.  This benchmark builds one compact data set of the
paper's shape (objects × ``paper100`` poses, the farm's default 32,768-point dense cloud; the
real meshes repeated under distinct names as in ``bench_farm.py``), then reads it in shuffled
order with each setting: the default (sized from the data set and the memory available),
``object_cache=0`` (only the last object kept) and ``object_cache=64``.

Measured in one run, interleaved (each repeat reads the same random indices with every
setting in turn; one data set object per setting, kept across repeats, its first pass over
every object not timed: shard checksums, file handles); the table gives the median ms per
item over the repeats and their range.  The load average is printed before and after.

    python benchmarks/bench_read.py                        # 200 objects, ~2 min to build on 2 cores
    python benchmarks/bench_read.py --objects 27 --reads 500 --repeats 3   # a quick look
    python benchmarks/bench_read.py --scratch /tmp/bench_read               # keep the data set, reuse it
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from zbuf_occlude import OccludedDataset
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.farm import DEFAULT_FARM_DENSE_POINTS, DEFAULT_FARM_RESOLUTION, FarmParams, RunOptions, run_farm
from zbuf_occlude.resources import available_memory, format_bytes

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_farm import MODELNET_SUBSET, repeated_objects  # noqa: E402  (a sibling script, not a package)

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


def _load() -> str:
    if not hasattr(os, "getloadavg"):
        return "load average unknown"
    return "load average " + ", ".join(f"{x:.2f}" for x in os.getloadavg())


def _setting(text: str) -> int | None:
    return None if text == "default" else int(text)


def _read_ms(ds: OccludedDataset, indices: np.ndarray) -> float:
    t0 = time.perf_counter()
    for i in indices:
        ds[int(i)]
    return (time.perf_counter() - t0) * 1e3 / len(indices)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", type=Path, default=MODELNET_SUBSET if MODELNET_SUBSET.is_dir() else SAMPLES,
                   help="real meshes (default: ../shared/data/modelnet_subset, else data/samples)")  # fmt: skip
    p.add_argument("--objects", type=int, default=200, help="objects of the data set (default: 200, the paper's)")
    p.add_argument("--views", default="paper100")
    p.add_argument("--samples-per-view", type=int, default=1)
    p.add_argument("--points", type=int, default=2048)
    p.add_argument("--dense-points", type=int, default=DEFAULT_FARM_DENSE_POINTS)
    p.add_argument("--workers", type=int, default=2, help="farm workers that build the data set")
    p.add_argument("--caches", default="default,0,64", help="comma-separated object_cache settings ('default': not given)")
    p.add_argument("--reads", type=int, default=2000, help="shuffled reads per setting and repeat")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scratch", type=Path, help="the data set folder, reused when finished (default: a temporary one, removed)")
    args = p.parse_args(argv)

    if args.scratch is not None:
        return _measure(args, args.scratch)
    # a data set of its own, which tempfile removes when the measurement ends
    with tempfile.TemporaryDirectory(prefix="bench_read_") as scratch:
        return _measure(args, Path(scratch))


def _measure(args: argparse.Namespace, out: Path) -> int:
    """Build the compact data set in ``out`` unless it is there, then time shuffled reads."""
    if not (out / CARD_FILE).is_file():
        params = FarmParams(views=args.views, samples_per_view=args.samples_per_view, n_points=args.points,
                            dense_points=args.dense_points, resolution=DEFAULT_FARM_RESOLUTION, storage="compact")  # fmt: skip
        t0 = time.perf_counter()
        run_farm(repeated_objects(args.root, args.objects), out, params,
                 RunOptions(workers=args.workers, progress=False, command="benchmarks/bench_read.py"))  # fmt: skip
        print(f"# built {out} in {time.perf_counter() - t0:.0f} s")
    settings = args.caches.split(",")
    sets = {s: OccludedDataset(out, object_cache=_setting(s)) for s in settings}
    first = next(iter(sets.values()))
    n_objects = len({first.metadata(i)["object_index"] for i in range(len(first))})
    found = available_memory()
    print(f"# {n_objects} objects × {len(first) // max(n_objects, 1)} samples of {first.n_points} points, compact; "
          f"{args.reads} shuffled reads × {args.repeats} repeats, interleaved")  # fmt: skip
    print(f"# machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}; memory available "
          f"{format_bytes(found[0]) if found else 'unknown'}")  # fmt: skip
    print(f"# before: {_load()}", flush=True)
    for ds in sets.values():  # not timed: every object's shard checked and opened once
        for obj_first in np.unique([ds.metadata(i)["object_index"] for i in range(len(ds))], return_index=True)[1]:
            ds[int(obj_first)]
    rng = np.random.default_rng(0)
    ms: dict[str, list[float]] = {s: [] for s in settings}
    for _ in range(args.repeats):
        indices = rng.integers(0, len(first), args.reads)
        for s, ds in sets.items():
            ms[s].append(_read_ms(ds, indices))
    print(f"# after: {_load()}")
    print()
    print("| object_cache | objects it keeps at most | ms/item (median) | range |")
    print("|---|---:|---:|---:|")
    for s, ds in sets.items():
        print(f"| {s} | {ds.object_cache} | {statistics.median(ms[s]):.2f} | {min(ms[s]):.2f}–{max(ms[s]):.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
