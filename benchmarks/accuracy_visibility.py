"""Agreement of the exact methods with the oracle, per mesh (issue 11, item 5).

For every ModelNet mesh of ``../shared/data/modelnet_subset`` (27) and a few constructed
meshes from outside ModelNet (thin sheets, STL triangle soup with float32 cracks, noisy
scan-like surfaces), ``--points`` points are sampled and tested from the ``grid25`` poses by

* ``zbuffer-exact`` at each ``--resolutions`` (the tile grid), with and without ``face_index``;
* ``embree-fast`` (``auto`` on a machine without a hardware GPU), with and without ``face_index``;
* the ``zbuffer`` method of issue 3 at 1024², with ``face_index``, for comparison;

against the oracle with ``face_index`` (the definition's ground truth).  Per mesh: agreement,
false-visible rate and the fraction of points decided on the CPU.  Markdown on stdout.

Usage::

    .venv/bin/python benchmarks/accuracy_visibility.py               # ~15 min on 2 busy cores
    .venv/bin/python benchmarks/accuracy_visibility.py --meshes 3 --points 5000
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import trimesh

REPO_ROOT = Path(__file__).resolve().parents[1]
MODELNET_SUBSET = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset"


def constructed_meshes(seed: int = 0) -> dict[str, trimesh.Trimesh]:
    """Meshes from outside ModelNet, normalised to a unit box around the origin."""
    rng = np.random.default_rng(seed)
    out: dict[str, trimesh.Trimesh] = {}
    # Thin sheets: three parallel sheets 1e-3 apart, each a 60x60 grid with a fold.
    sheets = []
    for k in range(3):
        g = trimesh.creation.box([1.0, 1.0, 1e-6])
        g = g.subdivide().subdivide().subdivide()
        g.vertices[:, 2] = 1e-3 * k + 0.1 * np.sin(3.0 * g.vertices[:, 0])
        sheets.append(g)
    out["thin-sheets"] = trimesh.util.concatenate(sheets)
    # Scan-like: a sphere with radial noise (rough), and a noisy height field (range image).
    s = trimesh.creation.icosphere(subdivisions=5)
    s.vertices *= (1.0 + 0.02 * rng.standard_normal(len(s.vertices)))[:, None]
    out["noisy-sphere"] = s
    n = 150
    x, y = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n))
    z = 0.15 * np.sin(6 * x) * np.cos(5 * y) + 0.01 * rng.standard_normal(x.shape)
    verts = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    out["range-scan"] = trimesh.Trimesh(verts, np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)]), process=False)
    # STL soup: a ModelNet-like CAD part (box with a hole) as unshared triangles, vertices
    # rounded to float32 independently per triangle (cracks of ~1e-8).
    part = trimesh.creation.box([1.0, 0.6, 0.3]).subdivide().subdivide()
    tri = part.triangles.copy()
    tri += rng.uniform(-3e-8, 3e-8, size=tri.shape)
    out["stl-soup"] = trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), process=False)
    for m in out.values():
        m.apply_translation(-m.bounds.mean(axis=0))
        m.apply_scale(1.0 / m.extents.max())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--points", type=int, default=20_000)
    ap.add_argument("--resolutions", default="1024,512")
    ap.add_argument("--poses", default="grid25")
    ap.add_argument("--meshes", type=int, default=None, help="first N ModelNet meshes only")
    ap.add_argument("--no-legacy", action="store_true", help="skip the issue-3 zbuffer row")
    args = ap.parse_args(argv)

    import zbuf_occlude as zo
    from zbuf_occlude.visibility import visible_mask
    from zbuf_occlude.visibility.embree_fast import FastScene
    from zbuf_occlude.visibility.gpu_exact import ExactScene
    from zbuf_occlude.visibility.zbuffer import ResidentPoints

    meshes: dict[str, trimesh.Trimesh] = {}
    files = sorted(MODELNET_SUBSET.rglob("*.off")) if MODELNET_SUBSET.is_dir() else []
    for path in files[: args.meshes]:
        meshes[path.stem] = zo.load_mesh(path)
    meshes.update(constructed_meshes())
    resolutions = [int(r) for r in args.resolutions.split(",")]
    poses = zo.view_schedule(args.poses)

    rows = []
    for name, mesh in meshes.items():
        t0 = time.perf_counter()
        points, fi = zo.sample_surface(mesh, args.points, seed=0)
        truth = [visible_mask(mesh, points, zo.camera_on_sphere(el, az), "oracle", face_index=fi) for el, az in poses]
        configs = []
        for res in resolutions:
            for use_fi in (True, False):
                configs.append((f"zbuffer-exact {res}² {'fi' if use_fi else 'no fi'}", "exact", res, use_fi))
        configs += [("embree-fast fi", "fast", None, True), ("embree-fast no fi", "fast", None, False)]
        if not args.no_legacy:
            configs.append(("zbuffer (issue 3) 1024² fi", "legacy", 1024, True))
        for label, kind, res, use_fi in configs:
            f = fi if use_fi else None
            scene = {"exact": ExactScene, "fast": FastScene, "legacy": ResidentPoints}[kind](mesh, points, f)
            agree = fv = cpu = total = 0
            for (el, az), want in zip(poses, truth):
                cam = zo.camera_on_sphere(el, az, resolution=res or 1024)
                got = scene.visible(cam)
                agree += int((got == want).sum())
                fv += int((got & ~want).sum())
                cpu += getattr(scene, "last_cpu_fraction", float("nan")) * len(points)
                total += len(points)
            if hasattr(scene, "release"):
                scene.release()
            rows.append((name, len(mesh.faces), label, agree / total, fv / total, cpu / total))
            print(
                f"  {name} | {label} | agreement {agree / total:.4%} | false-visible {fv / total:.4%} | CPU-settled {cpu / total:.3%}",
                file=sys.stderr,
                flush=True,
            )
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    labels = list(dict.fromkeys(r[2] for r in rows))
    print(f"Agreement with the oracle (with face_index), {args.points} points × {len(poses)} poses ({args.poses}) per mesh.\n")
    print("| method | worst mesh | mean | false-visible (mean) | worst false-visible | CPU-settled (mean / max) |")
    print("|---|---|---:|---:|---:|---:|")
    for label in labels:
        rs = [r for r in rows if r[2] == label]
        worst = min(rs, key=lambda r: r[3])
        fvw = max(rs, key=lambda r: r[4])
        cpus = [r[5] for r in rs]
        print(
            f"| {label} | {worst[0]} {worst[3]:.4%} | {np.mean([r[3] for r in rs]):.4%} | {np.mean([r[4] for r in rs]):.4%} "
            f"| {fvw[0]} {fvw[4]:.4%} | {np.nanmean(cpus):.4%} / {np.nanmax(cpus):.4%} |"
        )
    print("\nPer mesh (agreement / CPU-settled fraction):\n")
    print("| mesh | faces | " + " | ".join(labels) + " |")
    print("|---|---:|" + "---:|" * len(labels))
    for name in meshes:
        rs = {r[2]: r for r in rows if r[0] == name}
        cells = [f"{rs[lab][3]:.4%} / {rs[lab][5]:.3%}" for lab in labels]
        print(f"| {name} | {rs[labels[0]][1]} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
