"""Benchmark of ``export --to pointnet-h5`` against reading the data set once (not a test; prints a table).

The source is a compact farm data set of the paper's shape (Sryamkin et al. 2023, §4.3: 200
objects × ``paper100`` × 10 samples × 2048 points = 200,000 samples), built here from the real
meshes of ``../shared/data/modelnet_subset`` taken in turn (``bench_farm.repeated_objects``), or
a data set you name with ``--dataset``.  Each measurement runs in a process of its own, so that
its peak resident memory (``ru_maxrss``) is its own; reads and exports are interleaved,
``--repeats`` times each, and the table gives each one's median wall time, the ratio export / read
and the peak memory.  Run it at two sizes (``--objects 27`` and ``--objects 54``): memory that does
not grow with the set stays the same.

    python benchmarks/bench_export.py                   # the paper's shape (builds it: a few minutes)
    python benchmarks/bench_export.py --objects 27 --repeats 3
    python benchmarks/bench_export.py --dataset runs/dataset
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

#: What one measurement runs, in a process of its own: prints {"wall_s": ..., "peak_mb": ...}.
_READ = """
import json, resource, sys, time
from zbuf_occlude.dataset.reader import OccludedDataset
t0 = time.perf_counter(); n = 0
for split in ("train", "test"):
    for _, block in OccludedDataset(sys.argv[1], split=split).iter_arrays():
        n += len(block)
print(json.dumps({"wall_s": time.perf_counter() - t0, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "samples": n}))
"""
_EXPORT = """
import json, resource, sys, time
from zbuf_occlude.exporters import export
t0 = time.perf_counter()
export(sys.argv[1], "pointnet-h5", sys.argv[2])
print(json.dumps({"wall_s": time.perf_counter() - t0, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def _measure(code: str, *args: str) -> dict:
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def _build(objects: int, out: Path) -> Path:
    from bench_farm import MODELNET_SUBSET, repeated_objects

    from zbuf_occlude.farm import DEFAULT_FARM_DENSE_POINTS, DEFAULT_FARM_RESOLUTION, FarmParams, RunOptions, run_farm

    params = FarmParams(views="paper100", samples_per_view=10, n_points=2048, dense_points=DEFAULT_FARM_DENSE_POINTS,
                        resolution=DEFAULT_FARM_RESOLUTION, storage="compact")  # fmt: skip
    run_farm(repeated_objects(MODELNET_SUBSET, objects), out, params=params, options=RunOptions(workers=2, progress=False))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", type=int, default=200, help="objects of the built data set (default: the paper's 200)")
    ap.add_argument("--dataset", help="export this data set instead of building one")
    ap.add_argument("--repeats", type=int, default=3, help="reads and exports, interleaved (default: %(default)s)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_export_") as tmp:
        source = Path(args.dataset) if args.dataset else _build(args.objects, Path(tmp) / "dataset")
        print(f"# source {source}; load average before: {os.getloadavg()[0]:.2f}", flush=True)
        reads, exports = [], []
        for _ in range(args.repeats):
            reads.append(_measure(_READ, str(source)))
            with tempfile.TemporaryDirectory(prefix="export_", dir=tmp) as target:  # each export into a new folder
                exports.append(_measure(_EXPORT, str(source), str(Path(target) / "out")))
        read_s = statistics.median(r["wall_s"] for r in reads)
        export_s = statistics.median(e["wall_s"] for e in exports)
        print(f"# load average after: {os.getloadavg()[0]:.2f}")
        print("| samples | read once, s | export, s | export / read | peak MB read | peak MB export |")
        print("|---|---|---|---|---|---|")
        print(f"| {reads[0]['samples']:,} | {read_s:.1f} | {export_s:.1f} | {export_s / read_s:.2f} | "
              f"{max(r['peak_mb'] for r in reads):.0f} | {max(e['peak_mb'] for e in exports):.0f} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
