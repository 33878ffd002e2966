"""Benchmark of ``export`` (``pointnet-h5``, ``modelnet-txt``) against reading the data set once (not a test; prints a table).

The source is a compact farm data set of the paper's shape (Sryamkin et al. 2023, §4.3: 200
objects × ``paper100`` × 10 samples × 2048 points = 200,000 samples), built here from the real
meshes of ``../shared/data/modelnet_subset`` taken in turn (``bench_farm.repeated_objects``), or
a data set you name with ``--dataset``.  Each measurement runs in a process of its own, so that
its peak resident memory (``ru_maxrss``) is its own; the read and the exports (``--to``, each
target in turn) are interleaved, ``--repeats`` times each, and the table gives each one's median
wall time, its ratio to the read and to ``pointnet-h5``, its CPU time (all its threads; less
dependent on the machine's load than the wall time, which a CPU-bound export loses more of to
other work) and the peak memory.  ``--baseline SRC``
adds the exports of another checkout's package (``SRC/zbuf_occlude``: the code before a change),
interleaved too.  Run it at two sizes (``--objects 27`` and ``--objects 54``): memory that does not
grow with the set stays the same.  The load average is printed before and after.

    python benchmarks/bench_export.py                   # the paper's shape (builds it: a few minutes)
    python benchmarks/bench_export.py --objects 27 --repeats 3
    python benchmarks/bench_export.py --objects 2 --samples-per-view 5 --to pointnet-h5 modelnet-txt --baseline /tmp/old
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
for _, block in OccludedDataset(sys.argv[1]).iter_arrays():
    n += len(block)
print(json.dumps({"wall_s": time.perf_counter() - t0, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "samples": n}))
"""
_EXPORT = """
import inspect, json, os, resource, sys, time
from zbuf_occlude.exporters import export
quiet = {"progress": False} if "progress" in inspect.signature(export).parameters else {}
t0, c0 = time.perf_counter(), time.process_time()
export(sys.argv[1], sys.argv[3], sys.argv[2], **quiet)
wall, cpu = time.perf_counter() - t0, time.process_time() - c0
files = sum(len(f) for _, _, f in os.walk(sys.argv[2]))
print(json.dumps({"wall_s": wall, "cpu_s": cpu, "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "files": files}))
"""


def _measure(code: str, *args: str, package_root: str | None = None) -> dict:
    env = dict(os.environ)
    if package_root is not None:  # another checkout's package first on the path
        env["PYTHONPATH"] = os.pathsep.join([package_root, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, env=env, cwd=package_root, check=False)
    if done.returncode:
        raise SystemExit(f"a measurement failed ({args}):\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _build(objects: int, out: Path, samples_per_view: int = 10) -> Path:
    """Build the source in a process of its own: the peak memory (``ru_maxrss``) a process starts with
    is its parent's at the fork, so this one stays small and each measurement's figure is its own."""
    code = f"""
import sys
sys.path.insert(0, {str(Path(__file__).resolve().parent)!r})
from pathlib import Path
from bench_farm import MODELNET_SUBSET, repeated_objects
from zbuf_occlude.farm import DEFAULT_FARM_DENSE_POINTS, DEFAULT_FARM_RESOLUTION, FarmParams, RunOptions, run_farm
params = FarmParams(views="paper100", samples_per_view={samples_per_view}, n_points=2048, dense_points=DEFAULT_FARM_DENSE_POINTS,
                    resolution=DEFAULT_FARM_RESOLUTION, storage="compact")
run_farm(repeated_objects(MODELNET_SUBSET, {objects}), Path({str(out)!r}), params=params, options=RunOptions(workers=2, progress=False))
"""
    subprocess.run([sys.executable, "-c", code], check=True)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--objects", type=int, default=200, help="objects of the built data set (default: the paper's 200)")
    ap.add_argument("--samples-per-view", type=int, default=10, help="samples per view of the built data set (default: %(default)s)")
    ap.add_argument("--dataset", help="export this data set instead of building one")
    ap.add_argument("--to", nargs="+", default=["pointnet-h5"], help="the targets, interleaved (default: %(default)s)")
    ap.add_argument("--baseline", help="a checkout whose zbuf_occlude package exports too, interleaved (the code before a change)")
    ap.add_argument("--repeats", type=int, default=3, help="reads and exports, interleaved (default: %(default)s)")
    args = ap.parse_args(argv)
    runs = [(to, None) for to in args.to] + ([(to, args.baseline) for to in args.to] if args.baseline else [])
    with tempfile.TemporaryDirectory(prefix="bench_export_") as tmp:
        source = Path(args.dataset) if args.dataset else _build(args.objects, Path(tmp) / "dataset", args.samples_per_view)
        source = source.resolve()
        print(f"# source {source}; load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        reads, exports = [], {run: [] for run in runs}
        for _ in range(args.repeats):
            reads.append(_measure(_READ, str(source)))
            for to, root in runs:
                with tempfile.TemporaryDirectory(prefix="export_", dir=tmp) as target:  # each export into a new folder
                    exports[to, root].append(_measure(_EXPORT, str(source), str(Path(target) / "out"), to, package_root=root))
        read_s = statistics.median(r["wall_s"] for r in reads)
        first = statistics.median(e["wall_s"] for e in exports[runs[0]])
        print(f"# load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
        print(
            f"# {reads[0]['samples']:,} samples; read once: {read_s:.2f} s (median of {args.repeats}), peak {max(r['peak_mb'] for r in reads):.0f} MB"
        )
        first_cpu = statistics.median(e.get("cpu_s", float("nan")) for e in exports[runs[0]])
        print(f"| export | code | files | median s | / read | / {runs[0][0]} | CPU s | CPU / {runs[0][0]} | peak MB |")
        print("|---|---|---|---|---|---|---|---|---|")
        for (to, root), done in exports.items():
            wall = statistics.median(e["wall_s"] for e in done)
            cpu = statistics.median(e.get("cpu_s", float("nan")) for e in done)
            print(f"| {to} | {root or 'this checkout'} | {done[0]['files']:,} | {wall:.2f} | {wall / read_s:.2f} | "
                  f"{wall / first:.1f} | {cpu:.2f} | {cpu / first_cpu:.1f} | {max(e['peak_mb'] for e in done):.0f} |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
