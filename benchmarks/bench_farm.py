"""Benchmark of the render farm at the paper's data-set shape (not a test; prints a table).

Shape (Sryamkin et al. 2023, §4.3): 200 objects × 100 poses (``paper100``, Eq. 11–12) × 10
samples per pose × 2048 points = 200,000 samples.  200 distinct ModelNet meshes are not
available here, so the objects are the real meshes of ``../shared/data/modelnet_subset``
taken in turn (sorted by path) and repeated, each repeat a distinct object with its own
name and so its own seed key (``rep<k>/<path>``): the dense clouds and samples differ,
the rendering cost of a repeat is that of its mesh.

For each storage mode and worker count: wall time, views/s, samples/s, peak resident
memory per worker process (the largest ``ru_maxrss`` any worker reported), bytes on disk
and samples per MB (MB = 10^6 bytes) next to the paper's Table 2 (28.8 samples/MB).
With ``--objects N < 200`` the run is scaled down and the table also gives the time
extrapolated linearly to 200 objects (use a multiple of the mesh count, 27 here, so the
sample holds each mesh equally often).

    python benchmarks/bench_farm.py                      # full shape, 1 and 2 workers, both modes
    python benchmarks/bench_farm.py --objects 27         # one pass over the real meshes
    python benchmarks/bench_farm.py --objects 27 --workers 2 --storage compact --markdown
    python benchmarks/bench_farm.py --objects 27 --stages    # where one worker's time goes

``--stages`` renders the objects in this process with one thread per view (a worker's share of
two cores with two workers) and prints the wall time of each stage, exclusive of the stages
it calls, as a Markdown table (the stages' functions are wrapped with timers; nothing else changes).
"""

from __future__ import annotations

import argparse
import functools
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

from zbuf_occlude.farm import (
    DEFAULT_FARM_DENSE_POINTS,
    DEFAULT_FARM_RESOLUTION,
    PAPER_SAMPLES_PER_MB,
    FarmParams,
    RunOptions,
    run_farm,
)
from zbuf_occlude.mesh.inputs.plan import FarmObject, discover_objects

#: The paper's data set: 5 meshes × 40 classes (§4.3).
PAPER_OBJECTS = 200
MODELNET_SUBSET = Path(__file__).resolve().parents[2] / "shared" / "data" / "modelnet_subset"


def repeated_objects(root: Path, n_objects: int) -> list[FarmObject]:
    """``n_objects`` farm objects cycling over the real meshes under ``root``, each with its own name (key)."""
    meshes = discover_objects(root)
    objects = []
    for i in range(n_objects):
        m = meshes[i % len(meshes)]
        objects.append(FarmObject(i, f"rep{i // len(meshes):03d}/{m.name}", m.source, m.class_name, m.split, m.label))
    return objects


def _gl_renderer() -> str:
    from zbuf_occlude.render import context_info

    info = context_info()
    return f"{info['renderer']} via {info['backend']}, OpenGL {info['version']}"


#: The stages of ``--stages``: (module, attribute, stage), wrapped in this order (the outer last).
_STAGES = [
    ("zbuf_occlude.mesh.load", "read_trimesh", "mesh file read and parsed"),
    ("zbuf_occlude.mesh.load", "load_mesh", "mesh cleaned and normalised"),
    ("zbuf_occlude.farm.worker", "dense_cloud", "dense cloud sampled"),
    ("zbuf_occlude.visibility.oracle_embree", "_EmbreeScene.__init__", "per mesh: the oracle's Embree scene (BVH, face groups, adjacency)"),
    ("zbuf_occlude.visibility.embree_fast", "_Scene.__init__", "per mesh: embree-fast's scene (face data; before, its own BVH)"),
    ("zbuf_occlude.visibility.cpu_zbuffer", "_MeshData.__init__", "per mesh: the pre-pass's face data"),
    ("zbuf_occlude.visibility.embree_fast", "FastScene.__init__", "per mesh: the session (points in Morton order)"),
    ("zbuf_occlude.pipeline", "CameraSphere.camera", "per view: camera"),
    ("zbuf_occlude.visibility.cpu_zbuffer", "zbuffer_tasks", "per view: pre-pass set-up (projection, bands)"),
    ("zbuf_occlude.visibility.cpu_zbuffer", "_rasterise", "per view: pre-pass raster (numba)"),
    ("zbuf_occlude.visibility.cpu_zbuffer", "_classify", "per view: pre-pass classification (numba)"),
    ("zbuf_occlude.visibility.embree_fast", "FastScene._chunk", "per view: Embree rays (float32)"),
    ("zbuf_occlude.visibility.embree_fast", "occluded_embree", "per view: float64 re-checks (near-ties, creases)"),
    ("zbuf_occlude.visibility.embree_fast", "_crease", "per view: float64 re-checks (near-ties, creases)"),
    ("zbuf_occlude.visibility.embree_fast", "FastScene.visible", "per view: the rest of a view (Python, masks)"),
    ("zbuf_occlude.pipeline", "top_up", "per view: top-up of the poses that see < n points"),
    ("zbuf_occlude.dataset.storage", "write_datasets", "shard written (compressed) and hashed"),
    ("zbuf_occlude.farm.worker", "file_sha256", "shard written (compressed) and hashed"),
    ("zbuf_occlude.farm.worker", "process_object", "the rest (samples, records, masks packed)"),
]


def stage_times(objects: list[FarmObject], params: FarmParams, out: Path) -> tuple[dict[str, float], float]:
    """Seconds per stage of :data:`_STAGES` (exclusive of the stages it calls) over ``objects``,
    rendered in this process with one thread per view after one object of warm-up; and the wall time."""
    import importlib

    from zbuf_occlude.visibility.embree_fast import set_default_threads

    totals: dict[str, float] = {}
    inner: list[float] = []  # per open stage: the time of the stages it called

    def timed(stage, fn):
        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            inner.append(0.0)
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - t0
                totals[stage] = totals.get(stage, 0.0) + elapsed - inner.pop()
                if inner:
                    inner[-1] += elapsed

        return wrapper

    from zbuf_occlude.visibility import embree_fast

    originals = []
    for module, attr, stage in _STAGES:
        owner = importlib.import_module(module)
        *path, name = attr.split(".")
        for part in path:
            owner = getattr(owner, part)
        originals.append((owner, name, getattr(owner, name)))
        setattr(owner, name, timed(stage, getattr(owner, name)))
    threads = embree_fast.DEFAULT_THREADS
    set_default_threads(1)
    try:
        worker = importlib.import_module("zbuf_occlude.farm.worker")
        worker.process_object(objects[-1], params, out)  # warm-up: imports, compiled kernels, GL context
        totals.clear()
        t0 = time.perf_counter()
        for obj in objects:
            worker.process_object(obj, params, out)
        return totals, time.perf_counter() - t0
    finally:
        for owner, name, original in reversed(originals):
            setattr(owner, name, original)
        set_default_threads(threads)


def print_stages(objects: list[FarmObject], params: FarmParams, out: Path) -> None:
    """``--stages``: the Markdown table of :func:`stage_times`, with the load average."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    totals, wall = stage_times(objects, params, out)
    after = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    views = len(objects) * len(params.poses)
    print(
        f"# {len(objects)} objects, {wall:.1f} s ({wall / views * 1e3:.2f} ms per view), one thread; load average {load:.2f} before, {after:.2f} after"
    )
    total = sum(totals.values())
    print("| stage | s | % |\n|---|---:|---:|")
    for stage, seconds in sorted(totals.items(), key=lambda kv: -kv[1]):
        print(f"| {stage} | {seconds:.2f} | {100 * seconds / total:.1f} |")
    print(f"| total | {total:.2f} | 100 |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--root", type=Path, default=MODELNET_SUBSET, help="real meshes (ModelNet-style tree)")
    p.add_argument("--objects", type=int, default=PAPER_OBJECTS, help="objects to render (default: 200, the paper's)")
    p.add_argument("--views", default="paper100")
    p.add_argument("--samples-per-view", type=int, default=10)
    p.add_argument("--points", type=int, default=2048)
    p.add_argument("--dense-points", type=int, default=DEFAULT_FARM_DENSE_POINTS)
    p.add_argument("--resolution", type=int, default=DEFAULT_FARM_RESOLUTION)
    p.add_argument("--workers", default="1,2", help="comma-separated worker counts (default: 1,2)")
    p.add_argument("--storage", default="dense,compact", help="comma-separated storage modes")
    p.add_argument("--scratch", type=Path, help="where the data sets go (default: a temporary folder, removed)")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--stages", action="store_true", help="where one worker's time goes, stage by stage (in this process)")
    args = p.parse_args(argv)

    if not args.root.is_dir():
        print(f"no meshes at {args.root}", file=sys.stderr)
        return 2
    objects = repeated_objects(args.root, args.objects)
    n_meshes = len(discover_objects(args.root))
    scratch = args.scratch or Path(tempfile.mkdtemp(prefix="bench_farm_"))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"# {args.objects} objects ({n_meshes} real meshes repeated with distinct keys) × {args.views} × "
        f"{args.samples_per_view} samples × {args.points} points; dense cloud {args.dense_points}, {args.resolution}² z-buffer"
    )
    print(
        f"# machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"GL: {_gl_renderer()}; load average before: {load:.2f}"
    )
    if args.stages:
        params = FarmParams(
            views=args.views, samples_per_view=args.samples_per_view, n_points=args.points,
            dense_points=args.dense_points, resolution=args.resolution, storage=args.storage.split(",")[-1],
        )  # fmt: skip
        print_stages(objects, params, scratch)
        if args.scratch is None:
            shutil.rmtree(scratch, ignore_errors=True)
        return 0
    rows = []
    for storage in args.storage.split(","):
        for workers in (int(w) for w in args.workers.split(",")):
            out = scratch / f"{storage}_w{workers}"
            shutil.rmtree(out, ignore_errors=True)
            params = FarmParams(
                views=args.views, samples_per_view=args.samples_per_view, n_points=args.points,
                dense_points=args.dense_points, resolution=args.resolution, storage=storage,
            )  # fmt: skip
            t0 = time.perf_counter()
            s = run_farm(objects, out, params, RunOptions(workers=workers, command="benchmarks/bench_farm.py"))
            wall = time.perf_counter() - t0
            load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
            rows.append({
                "storage": storage, "workers": workers, "objects": len(objects), "wall_s": wall, "views_s": s.views / wall,
                "samples_s": s.samples / wall, "peak_mb": s.peak_rss_mb, "bytes": s.bytes, "samples": s.samples,
                "samples_mb": s.samples_per_mb, "wall_200_s": wall * PAPER_OBJECTS / len(objects), "load": load,
                "failed": s.failed,
            })  # fmt: skip
            print(f"# done {storage} × {workers} workers: {wall:.1f} s (load average after: {load:.2f})", flush=True)
            if args.scratch is None:
                shutil.rmtree(out, ignore_errors=True)
    if args.scratch is None:
        shutil.rmtree(scratch, ignore_errors=True)

    head = ["storage", "workers", "objects", "wall s", "views/s", "samples/s", "peak MB/worker", "MB on disk",
            "samples/MB", "wall s @200 objects", "failed"]  # fmt: skip
    cells = [
        [r["storage"], r["workers"], r["objects"], f"{r['wall_s']:.0f}", f"{r['views_s']:.1f}", f"{r['samples_s']:.0f}",
         f"{r['peak_mb']:.0f}", f"{r['bytes'] / 1e6:.1f}", f"{r['samples_mb']:.0f}", f"{r['wall_200_s']:.0f}", r["failed"]]
        for r in rows
    ]  # fmt: skip
    if args.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
        for c in cells:
            print("| " + " | ".join(map(str, c)) + " |")
    else:
        widths = [max(len(str(x)) for x in col) for col in zip(head, *cells)]
        for line in [head, *cells]:
            print("  ".join(str(x).rjust(w) for x, w in zip(line, widths)))
    print(f"# paper, Table 2: {PAPER_SAMPLES_PER_MB} samples/MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
