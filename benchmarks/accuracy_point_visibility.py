"""Visibility from points alone against the exact mesh oracle (prints tables; not a test).

For every mesh: sample N points with the paper's area-weighted sampling (seed 0), take the exact
oracle's visibility of those points from each pose (``method="oracle"``, with the mesh), and run
the point-only methods on the points alone:

* ``point-splat``: :func:`zbuf_occlude.visible_mask_points` without normals;
* ``point-splat +n``: with the sampled faces' normals, of either sign;
* ``point-splat +o``: with those normals taken as oriented (``oriented=True``);
* ``HPR best``: Open3D's hidden point removal (Katz et al. 2007) at the radius factor that is best
  for this mesh and N (searched with the oracle: a flattering baseline no user could choose);
* ``HPR ×F``: at each radius factor F of the search (one row each in the CSV); the summary shows
  the factor that is best on average over the tuning meshes (``--hpr-factor``, chosen there), the
  fair baseline, beside Open3D's example factor 100 (the ``open3d-hpr`` method's default).

Also printed: the **boundary share**, the fraction of points with one of their 4 nearest neighbours
on the other side of the oracle's visible/hidden boundary: what no method that reads only point
positions at this density can be sure of.  Time per view is the median wall time of one camera
(``PointSurfels.visible``; the neighbour search, done once per cloud, is reported apart).

    python benchmarks/accuracy_point_visibility.py                       # shipped meshes + ../shared street meshes
    python benchmarks/accuracy_point_visibility.py --sets tune --points 2048 10000   # the meshes the defaults were chosen on (16 ModelNet, 6 made in code)
    python benchmarks/accuracy_point_visibility.py --csv docs/results/point_visibility/per_mesh.csv
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import trimesh
from scipy.spatial import cKDTree

import zbuf_occlude as zo
from zbuf_occlude.visibility.metrics import agreement

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
MESH_SUFFIXES = (".off", ".obj", ".glb", ".gltf", ".dae")
HPR_FACTORS = (2.0, 10.0, 100.0, 1000.0, 10000.0)
OURS = ("point-splat", "point-splat +n", "point-splat +o")


class Procedural(NamedTuple):
    """A tuning mesh made in code (its ``name`` stands where a file's name would)."""

    name: str
    mesh: trimesh.Trimesh


def procedural_meshes() -> list[Procedural]:
    """Tuning meshes of the kinds point-only visibility finds hardest, made from trimesh's
    primitives and scaled as loaded meshes are (centred, largest extent 1): thin plates seen
    nearly edge-on from the ``fibonacci:16`` poses (elevations within ±11° of their planes), a
    closed shell with another object inside, and parts thinner than the normals' neighbourhood
    (a stool's legs, rods)."""
    rotation, move = trimesh.transformations.rotation_matrix, trimesh.transformations.translation_matrix
    box, cylinder = trimesh.creation.box, trimesh.creation.cylinder
    plate = box(extents=(1.0, 0.8, 0.01), transform=rotation(np.radians(4.0), [1, 0, 0]))
    pair = [box(extents=(1.0, 0.6, 0.012), transform=move([0, y, z]) @ rotation(np.radians(a), [0, 1, 0]))
            for y, z, a in ((-0.25, 0.0, -7.0), (0.25, 0.15, 9.0))]  # fmt: skip
    legs = [
        cylinder(radius=0.012, height=0.8, transform=move([x, y, 0.0]))
        for x, y in ((0.25, 0.25), (-0.25, 0.25), (0.25, -0.25), (-0.25, -0.25))
    ]
    rods = [cylinder(radius=0.01 + 0.004 * k, height=1.0, transform=move([0.15 * (k - 2.5), 0, 0]) @ rotation(np.radians(20 * k), [1, 0, 0]))
            for k in range(6)]  # fmt: skip
    made = {
        "proc_thin_plate": plate,
        "proc_plate_pair": trimesh.util.concatenate(pair),
        "proc_shell_box": trimesh.util.concatenate([trimesh.creation.icosphere(subdivisions=4, radius=0.5), box(extents=(0.4, 0.4, 0.4))]),
        "proc_box_ball": trimesh.util.concatenate([box(extents=(1.0, 0.8, 0.6)), trimesh.creation.icosphere(subdivisions=3, radius=0.25)]),
        "proc_stool": trimesh.util.concatenate([cylinder(radius=0.4, height=0.03, transform=move([0, 0, 0.4])), *legs]),
        "proc_rods": trimesh.util.concatenate(rods),
    }
    for mesh in made.values():
        mesh.apply_translation(-mesh.bounds.mean(axis=0))
        mesh.apply_scale(1.0 / mesh.extents.max())
    return [Procedural(name, mesh) for name, mesh in made.items()]


def mesh_sets() -> dict[str, list]:
    """The shipped meshes, the 48 street meshes and the tuning meshes (ModelNet meshes of
    ../shared that are not shipped, and :func:`procedural_meshes`; the defaults were chosen on
    these and nowhere else)."""
    shipped = sorted((ROOT / "data" / "samples").rglob("*.off"))
    names = {p.name for p in shipped}
    street = sorted(p for p in (SHARED / "street_objects").rglob("*") if p.suffix.lower() in MESH_SUFFIXES)
    tune: dict[str, Path] = {}  # ModelNet10 and ModelNet40 hold copies of some meshes: each once
    for p in sorted((SHARED / "modelnet_subset").rglob("*.off")):
        if p.name not in names:
            tune.setdefault(p.name, p)
    return {"samples": shipped, "street": street, "tune": [*sorted(tune.values()), *procedural_meshes()]}


def hpr(mesh, points: np.ndarray, camera: zo.Camera, factor: float) -> np.ndarray:
    """Open3D's hidden point removal through the registered ``open3d-hpr`` method (the mesh unused)."""
    return zo.visible_mask(mesh, points, camera, method="open3d-hpr", hpr_radius_factor=factor)


def timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def boundary_share(points: np.ndarray, truth: np.ndarray) -> float:
    """Mean over poses of the fraction of points with a differently labelled 4-neighbour."""
    _, idx = cKDTree(points).query(points, k=5)
    return float(np.mean([(t[idx[:, 1:]] != t[:, None]).any(axis=1).mean() for t in truth]))


def measure(path: Path | Procedural, n: int, cameras: list[zo.Camera], factors: tuple[float, ...] = HPR_FACTORS) -> list[dict]:
    mesh = path.mesh if isinstance(path, Procedural) else zo.load_mesh(path)
    points, face_index = zo.sample_surface(mesh, n, seed=0)
    normals = mesh.face_normals[face_index]
    truth = np.array([zo.visible_mask(mesh, points, c, method="oracle", face_index=face_index) for c in cameras])
    rows = []
    for name, nrm, oriented in (("point-splat", None, False), ("point-splat +n", normals, False), ("point-splat +o", normals, True)):
        surfels, prep_s = timed(zo.point_surfels, points, nrm, oriented=oriented)
        masks, times = zip(*(timed(surfels.visible, c) for c in cameras))
        rows.append(_row(path, n, name, masks, truth, times, prep_s))
    hpr_masks = {f: [timed(hpr, mesh, points, c, f) for c in cameras] for f in factors}
    best = max(factors, key=lambda f: np.mean([(m == t).mean() for (m, _), t in zip(hpr_masks[f], truth)]))
    for name, factor in (("HPR best", best), *((f"HPR ×{f:g}", f) for f in factors)):
        masks, times = zip(*hpr_masks[factor])
        rows.append(_row(path, n, name, masks, truth, times, 0.0, factor=factor))
    share = boundary_share(points, truth)
    for r in rows:
        r["boundary_share"] = share
    return rows


def _row(path, n, method, masks, truth, times, prep_s, factor=None) -> dict:
    scores = [agreement(m, t) for m, t in zip(masks, truth)]
    row = {"mesh": path.name, "n": n, "method": method, "hpr_factor": factor,
           "ms_per_view": 1e3 * float(np.median(times)), "prepare_ms": 1e3 * prep_s}  # fmt: skip
    for key in ("accuracy", "iou", "false_visible", "false_hidden"):
        row[key] = float(np.mean([s[key] for s in scores]))
    row["worst_view_accuracy"] = float(min(s["accuracy"] for s in scores))
    return row


def summary(rows: list[dict], n: int, hpr_factor: float) -> None:
    print(f"\n### N = {n:,} points ({len({r['mesh'] for r in rows if r['n'] == n})} meshes, mean over meshes and poses)\n")
    print("| method | accuracy | visible IoU | false visible | false hidden | worst view | ms / view | prepare ms |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for method in dict.fromkeys((*OURS, "HPR best", f"HPR ×{hpr_factor:g}", "HPR ×100")):
        sel = [r for r in rows if r["n"] == n and r["method"] == method]
        if not sel:
            continue
        mean = {k: np.mean([r[k] for r in sel]) for k in ("accuracy", "iou", "false_visible", "false_hidden", "prepare_ms")}
        print(f"| {method} | {mean['accuracy']:.3f} | {mean['iou']:.3f} | {mean['false_visible']:.3f} | "
              f"{mean['false_hidden']:.3f} | {min(r['worst_view_accuracy'] for r in sel):.3f} | "
              f"{np.median([r['ms_per_view'] for r in sel]):.1f} | {mean['prepare_ms']:.0f} |")  # fmt: skip
    share = np.mean([r["boundary_share"] for r in rows if r["n"] == n and r["method"] == OURS[0]])
    print(f"\nboundary share (points with a 4-neighbour on the other side of the visible/hidden boundary): {share:.3f}")
    by_mesh: dict[str, dict[str, float]] = {}
    for r in rows:
        if r["n"] == n:
            by_mesh.setdefault(r["mesh"], {})[r["method"]] = r["accuracy"]
    for ours in OURS:
        for hpr_name in ("HPR best", f"HPR ×{hpr_factor:g}"):
            below = sorted(m for m, acc in by_mesh.items() if acc.get(ours, 1.0) < acc.get(hpr_name, 0.0))
            print(f"{ours} below {hpr_name} on {len(below)} of {len(by_mesh)} meshes" + (f": {', '.join(below)}" if below else ""))
    means = {f: np.mean(acc) for f in HPR_FACTORS if (acc := [r["accuracy"] for r in rows if r["n"] == n and r["method"] == f"HPR ×{f:g}"])}
    print("HPR mean accuracy per radius factor: " + ", ".join(f"×{f:g} {a:.3f}" for f, a in means.items()))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("--sets", nargs="+", default=["samples", "street"], choices=["samples", "street", "tune"])
    p.add_argument("--points", nargs="+", type=int, default=[2048, 10000, 100000])
    p.add_argument("--views", default="fibonacci:16")
    p.add_argument("--hpr-factors", type=float, nargs="+", default=list(HPR_FACTORS), help="the radius factors HPR is searched over")
    p.add_argument("--hpr-factor", type=float, default=100.0, help="the fixed HPR radius factor shown (choose it on --sets tune)")
    p.add_argument("--csv", type=Path, help="write one row per mesh, N and method")
    args = p.parse_args()
    sets = mesh_sets()
    paths = [path for s in args.sets for path in sets[s]]
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule(args.views)]
    print("#", subprocess.run(["uptime"], check=False, capture_output=True, text=True).stdout.strip())
    print(f"# {len(paths)} meshes ({', '.join(args.sets)}), {len(cameras)} poses ({args.views}), seed 0")
    rows: list[dict] = []
    for n in args.points:
        for path in paths:
            rows.extend(measure(path, n, cameras, tuple(args.hpr_factors)))
        summary(rows, n, args.hpr_factor)
    print("#", subprocess.run(["uptime"], check=False, capture_output=True, text=True).stdout.strip())
    if args.csv:
        args.csv.parent.mkdir(parents=True, exist_ok=True)
        with open(args.csv, "w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
