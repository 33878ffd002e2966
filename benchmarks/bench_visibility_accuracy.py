"""Agreement of ``embree-fast`` with the exact oracle, with and without its z-buffer pre-pass.

For every shipped mesh (``data/samples``), every mesh of ``../shared/data/modelnet_subset``
when present, and the constructed meshes of ``accuracy_visibility.py`` (thin sheets, a noisy
sphere, a range-scan height field, STL soup with float32 cracks): ``--points`` points from
the ``--poses`` poses, each tested by

* ``embree-fast`` as shipped: the CPU z-buffer pre-pass settles what it can prove, rays decide
  the rest;
* ``embree-fast`` with rays only (``prepass=False``: every point cast as a ray);

with and without ``face_index``, against the oracle with ``face_index``.  Markdown on stdout:
per configuration, agreement (mean over meshes and worst mesh), false-visible and
false-hidden (pooled), and the fraction of points cast as rays.

Usage::

    .venv/bin/python benchmarks/bench_visibility_accuracy.py                 # ~5-10 min on 2 cores
    .venv/bin/python benchmarks/bench_visibility_accuracy.py --points 2000 --poses fibonacci:4 --no-shared
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))


def meshes(modelnet: Path | None) -> dict:
    from accuracy_visibility import constructed_meshes

    import zbuf_occlude as zo

    out = {f"samples/{p.stem}": zo.load_mesh(p) for p in sorted((REPO_ROOT / "data" / "samples").rglob("*.off"))}
    if modelnet is not None and modelnet.is_dir():
        out.update({p.stem: zo.load_mesh(p) for p in sorted(modelnet.rglob("*.off"))})
    out.update(constructed_meshes())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=10_000)
    ap.add_argument("--poses", default="grid25")
    ap.add_argument("--modelnet", type=Path, default=None, help="a ModelNet tree (default: ../shared/data/modelnet_subset)")
    ap.add_argument("--no-shared", action="store_true", help="only the shipped and constructed meshes")
    args = ap.parse_args(argv)
    from accuracy_visibility import MODELNET_SUBSET

    import zbuf_occlude as zo
    from zbuf_occlude.visibility.embree_fast import FastScene

    poses = zo.view_schedule(args.poses)
    configs = [
        (f"embree-fast{'' if pre else ', rays only (prepass=False)'}, {'with' if fi else 'without'} face_index", pre, fi)
        for pre in (True, False)
        for fi in (True, False)
    ]
    stats = {c[0]: {"agree": [], "fv": 0, "fh": 0, "n": 0, "rays": []} for c in configs}
    worst = {c[0]: ("", 2.0) for c in configs}
    load = os.getloadavg()
    all_meshes = meshes(None if args.no_shared else (args.modelnet or MODELNET_SUBSET))
    for name, mesh in all_meshes.items():
        points, fi = zo.sample_surface(mesh, args.points, seed=0)
        cams = [zo.camera_on_sphere(el, az) for el, az in poses]
        truth = [zo.visible_mask(mesh, points, c, "oracle", face_index=fi) for c in cams]
        for label, pre, use_fi in configs:
            scene = FastScene(mesh, points, fi if use_fi else None, sort=False, prepass=pre)
            agree = 0
            s = stats[label]
            for cam, want in zip(cams, truth):
                got = scene.visible(cam)
                agree += int((got == want).sum())
                s["fv"] += int((got & ~want).sum())
                s["fh"] += int((~got & want).sum())
                s["n"] += len(points)
                s["rays"].append(scene.last_ray_fraction)
            rate = agree / (len(points) * len(cams))
            s["agree"].append(rate)
            if rate < worst[label][1]:
                worst[label] = (name, rate)
        print(f"  {name}: done", file=sys.stderr, flush=True)
    print(
        f"Agreement with the oracle (with face_index): {len(all_meshes)} meshes, {args.points:,} points × "
        f"{len(poses)} poses ({args.poses}) each; load average before {load[0]:.2f}, after {os.getloadavg()[0]:.2f}.\n"
    )
    print("| configuration | mean agreement | worst mesh | false-visible | false-hidden | cast as rays (mean) |")
    print("|---|---:|---|---:|---:|---:|")
    for label, _, _ in configs:
        s = stats[label]
        print(
            f"| {label} | {np.mean(s['agree']):.5%} | {worst[label][0]} {worst[label][1]:.4%} | {s['fv'] / s['n']:.5%} "
            f"| {s['fh'] / s['n']:.5%} | {np.mean(s['rays']):.1%} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
