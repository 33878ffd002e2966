"""Occlusion on the fly vs a stored farm data set: loader throughput and PointNet training time (prints a table).

Both sources give the same kind of sample: 2,048 points drawn from the visible part of a
32,768-point dense cloud (embree-fast, exact).  ``farm``: the samples are generated once
(``generate --format h5``, fibonacci poses) and read back per index from the HDF5 data set
(:class:`zbuf_occlude.OccludedDataset`); ``on-the-fly``:
:class:`zbuf_occlude.learn.OnTheFlyOccludedDataset` draws a new pose per index and epoch.

Measured, one run, interleaved (farm, on-the-fly, farm, on-the-fly, ...; medians):

1. loader throughput: a full pass of a ``DataLoader`` with ``--workers`` persistent workers
   (on-the-fly: :class:`~zbuf_occlude.learn.EpochSampler` sends the epoch), samples/s, and per
   worker; the first pass (dense clouds, Embree BVHs, JIT, file handles) is a warm-up, not timed;
2. PointNet training: an epoch of optimiser steps (batch ``--batch``, ``--threads`` torch
   threads), data from each source through the same ``DataLoader``; the slow-down of
   on-the-fly is its epoch time over the farm's, minus 1.  The loader's workers run beside
   the training process, so on-the-fly costs nothing while a worker makes a batch faster
   than a step consumes it.  ``bound if not overlapped``: the loader's time per epoch over the
   farm's training epoch, what on-the-fly would add if its worker made nothing during steps
   (the steadier figure on a busy machine, where the wall-time ratio is noisy).

``--point-sets`` measures instead what occlusion on the fly costs per item on point sets (clouds
without a mesh: PointNet's 2,048-point clouds): each shipped mesh sampled once at ``--points``
(``zo.sample_surface``, seed 0, no normals), one random view per item through
:class:`zbuf_occlude.learn.RandomOcclusion`, interleaved item by item: ``fresh`` prepares the
cloud for every item (a cache that never hits), ``cached`` finds the preparation in its
per-process cache (an epoch after the first), and Open3D's ``hidden_point_removal`` (radius 100
x the bounding-box diagonal, the cloud built inside the timing as a user's call builds it) on
the same points and pose, when ``import open3d`` works.  Median ms per item over
``--repeats`` x ``--views`` items per cloud.

    python benchmarks/bench_on_the_fly.py                       # shipped meshes, full-width PointNet
    python benchmarks/bench_on_the_fly.py --views 4 --width 0.25 --repeats 1   # a quick look
    python benchmarks/bench_on_the_fly.py --point-sets          # ms per item from 2,048-point clouds
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from zbuf_occlude import OccludedDataset
from zbuf_occlude.farm import FarmParams
from zbuf_occlude.farm.generate import generate
from zbuf_occlude.learn import EpochSampler, OnTheFlyOccludedDataset
from zbuf_occlude.learn.data import normalize_batch
from zbuf_occlude.learn.models import PointNet

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"


class FarmSamples(torch.utils.data.Dataset):
    """A farm data set read per index (what a training loop over stored samples does)."""

    def __init__(self, root: Path):
        self.ds = OccludedDataset(root)

    def __len__(self) -> int:
        return len(self.ds)

    def __getitem__(self, i: int):
        points, label, _ = self.ds[i]
        return torch.from_numpy(normalize_batch(points[None])[0]), label


def _load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def _loader(ds, args) -> tuple[torch.utils.data.DataLoader, EpochSampler | None]:
    # persistent workers for both sources: their caches (file handles; dense clouds, BVHs) stay warm
    sampler = EpochSampler(ds) if isinstance(ds, OnTheFlyOccludedDataset) else None
    loader = torch.utils.data.DataLoader(ds, batch_size=args.batch, sampler=sampler, num_workers=args.workers,
                                         persistent_workers=args.workers > 0)  # fmt: skip
    return loader, sampler


def _pass(loader, sampler, epoch: int) -> float:
    if sampler is not None:
        sampler.set_epoch(epoch)
    t0 = time.perf_counter()
    for _ in loader:
        pass
    return time.perf_counter() - t0


def _train_epoch(loader, sampler, model, opt, epoch: int) -> tuple[float, float, int]:
    if sampler is not None:
        sampler.set_epoch(epoch)
    steps = 0
    t0, c0 = time.perf_counter(), time.process_time()
    for x, y in loader:
        loss = F.cross_entropy(model(x), y) + model.regularizer
        opt.zero_grad()
        loss.backward()
        opt.step()
        steps += 1
    return time.perf_counter() - t0, time.process_time() - c0, steps


def _hpr_ms(points: np.ndarray, eye: np.ndarray) -> float:
    import open3d as o3d

    start = time.perf_counter()
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    cloud.hidden_point_removal(eye, diameter * 100.0)
    return 1e3 * (time.perf_counter() - start)


def point_sets(args) -> int:
    """ms per item of occlusion on the fly from point sets: fresh preparation, cached, Open3D's HPR."""
    import zbuf_occlude as zo
    from zbuf_occlude.geometry.cameras import camera_on_sphere
    from zbuf_occlude.learn import RandomOcclusion
    from zbuf_occlude.mesh.inputs.point_sets import cloud_frame

    try:
        import open3d  # noqa: F401
    except ImportError:
        with_hpr = False
    else:
        with_hpr = True
    meshes = (
        sorted(Path(args.meshes[0]).glob("*/*/*.off"))
        if len(args.meshes) == 1 and Path(args.meshes[0]).is_dir()
        else [Path(m) for m in args.meshes]
    )
    clouds = [np.asarray(zo.sample_surface(zo.load_mesh(m), args.points, seed=0)[0], dtype=np.float64) for m in meshes]
    cached = RandomOcclusion(args.points, seed=0)
    RandomOcclusion(args.points, seed=1)(clouds[0], index=0, epoch=0)  # numba's compilation is not an item
    for i, cloud in enumerate(clouds):  # the first epoch fills the cache
        cached(cloud, index=i, epoch=0)
    times: dict[str, list[float]] = {"fresh": [], "cached": [], "hpr": []}
    print(f"# {_load()}")
    for epoch in range(1, 1 + args.repeats * args.views):
        for i, cloud in enumerate(clouds):
            runs = [("fresh", RandomOcclusion(args.points, seed=0)), ("cached", cached)]
            for name, occlusion in runs if (epoch + i) % 2 else runs[::-1]:
                start = time.perf_counter()
                sample = occlusion(cloud, index=i, epoch=epoch)
                times[name].append(1e3 * (time.perf_counter() - start))
            if with_hpr:  # the same pose, in the frame RandomOcclusion views the cloud in
                frame, _ = cloud_frame(cloud, None, "+z", what="cloud")
                eye = camera_on_sphere(sample["elevation_deg"], sample["azimuth_deg"]).eye
                times["hpr"].append(_hpr_ms(frame, eye))
    print(f"# {_load()}")
    print(
        f"# {len(clouds)} clouds of {args.points:,} points (shipped meshes, no normals), {args.repeats * args.views} items each, interleaved"
    )
    print()
    print("| per item | ms (median) | / Open3D HPR |")
    print("|---|---:|---:|")
    hpr = statistics.median(times["hpr"]) if times["hpr"] else None
    for name, label in (
        ("fresh", "on the fly, preparation every item"),
        ("cached", "on the fly, preparation cached"),
        ("hpr", "Open3D HPR"),
    ):
        if times[name]:
            ms = statistics.median(times[name])
            print(f"| {label} | {ms:.2f} | {'n/a' if hpr is None else f'{ms / hpr:.2f}×'} |")
    return 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("meshes", nargs="*", default=[str(SAMPLES)])
    p.add_argument("--views", type=int, default=16, help="samples per object and epoch (farm: fibonacci poses)")
    p.add_argument("--points", type=int, default=2048)
    p.add_argument("--dense", type=int, default=32768)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--workers", type=int, default=1, help="DataLoader workers")
    p.add_argument("--threads", type=int, default=1, help="torch threads of the training process")
    p.add_argument("--width", type=float, default=1.0, help="PointNet channel multiplier")
    p.add_argument("--repeats", type=int, default=2)
    p.add_argument("--point-sets", action="store_true", help="ms per item from point sets against Open3D's HPR (no training)")
    args = p.parse_args()
    if args.point_sets:
        return point_sets(args)
    torch.set_num_threads(args.threads)
    print(f"# {_load()}")
    print(f"# python {sys.version.split()[0]}, torch {torch.__version__}, {os.cpu_count()} CPUs, workers={args.workers}, "
          f"threads={args.threads}, batch={args.batch}, points={args.points}, dense={args.dense}, PointNet width={args.width}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        params = FarmParams(views=f"fibonacci:{args.views}", samples_per_view=1, n_points=args.points, dense_points=args.dense,
                            storage="h5", method="embree-fast", resolution=512)  # fmt: skip
        summary, _ = generate(args.meshes, tmp, params=params, progress=False)
        print(f"# farm data set: {summary.samples} samples generated in {time.perf_counter() - t0:.1f} s")
        sources = {"farm": FarmSamples(Path(tmp)),
                   "on-the-fly": OnTheFlyOccludedDataset(args.meshes, n_points=args.points, dense_points=args.dense,
                                                         views_per_object=args.views)}  # fmt: skip
        n = {k: len(v) for k, v in sources.items()}
        loaders = {k: _loader(ds, args) for k, ds in sources.items()}
        for loader, sampler in loaders.values():  # warm-up (not timed): dense clouds, BVHs, JIT, file handles
            _pass(loader, sampler, 0)
        loader_s: dict[str, list[float]] = {k: [] for k in sources}
        train_s: dict[str, list[float]] = {k: [] for k in sources}
        train_cpu: dict[str, list[float]] = {k: [] for k in sources}
        steps = {}
        models = {}
        for r in range(args.repeats):
            for name, (loader, sampler) in loaders.items():
                loader_s[name].append(_pass(loader, sampler, r + 1))
        for name in sources:  # one model per source, same initial weights
            torch.manual_seed(0)
            models[name] = PointNet(n_classes=40, width=args.width)
        opts = {k: torch.optim.Adam(m.parameters(), lr=1e-3) for k, m in models.items()}
        for r in range(args.repeats):
            for name, (loader, sampler) in loaders.items():
                sec, cpu, steps[name] = _train_epoch(loader, sampler, models[name], opts[name], r + 1)
                train_s[name].append(sec)
                train_cpu[name].append(cpu)
    print(f"# {_load()}")
    print()
    print("| source | samples/epoch | loader samples/s | per worker | loader s/epoch | train epoch s (wall) | train CPU s "
          "(main process) | s/step | slow-down (wall) | bound if not overlapped |")  # fmt: skip
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    base = statistics.median(train_s["farm"])
    for name in sources:
        ls, ts, tc = statistics.median(loader_s[name]), statistics.median(train_s[name]), statistics.median(train_cpu[name])
        rate = n[name] / ls
        # the most on-the-fly could add if no batch were made while a step runs: its loader time per epoch
        print(f"| {name} | {n[name]} | {rate:.1f} | {rate / max(args.workers, 1):.1f} | {ls:.2f} | {ts:.2f} | {tc:.2f} | "
              f"{ts / steps[name]:.3f} | {(ts / base - 1) * 100:+.1f} % | {ls / base * 100:.1f} % |")  # fmt: skip
    print()
    print("medians of", args.repeats, "interleaved runs; raw wall seconds:", {k: [round(v, 2) for v in vs] for k, vs in train_s.items()})
    return 0


if __name__ == "__main__":
    np.seterr(all="ignore")
    sys.exit(main())
