"""Rules tried on top of the splats' view without normals, and dropped (prints Markdown tables; not a test).

Each rule is measured as ``benchmarks/accuracy_point_visibility.py`` measures the method: N points sampled from each
mesh (seed 0), 16 poses (``fibonacci:16``), accuracy against the exact mesh oracle, the mean over meshes of the mean
over poses.  The rules:

* **Where the normals fail** (a bound, not a method): the faces' normals put in place of the estimated ones where
  the two differ by more than 10°, 30° or 60°; and where those points lie: the share of points a third or more of whose 8
  nearest neighbours were sampled on faces turned more than 25° from the point's own (edges, parts thinner than the
  spacing), and the share of estimates more than 30° off there and elsewhere.
* **A splat radius from the neighbourhood's flatness**: the radius times 0.5-0.8 where the 12-neighbourhood's
  surface variation (smallest eigenvalue over the trace) exceeds 0.02-0.1.
* **Rods turned to the camera**: where the 12-neighbourhood is a line (linearity above 0.6, 0.75 or 0.9), the normal
  of each view the direction to the eye without its part along the line.
* **A vote of the neighbours**: each point takes the majority answer of its k nearest points, itself among them (k 5, 9
  and 15: odd, so no vote ties).
* **A learned fusion**: logistic regression (scikit-learn) on the splats' answer with and without the hull test,
  HPR's (:func:`~zbuf_occlude.visibility.point_hull.on_flipped_hull` of the whole cloud at 100 farthest distances), and
  the share of the 11 nearest neighbours that each of the splats and HPR sees; fitted on the tuning meshes' point-views,
  scored on the reported meshes.

    python docs/results/point_visibility/tried_rules.py --points 2048 10000    # needs ../shared/data (the tuning and street meshes)
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import zbuf_occlude as zo
from zbuf_occlude.visibility.point_hull import on_flipped_hull

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "benchmarks"))
from accuracy_point_visibility import Procedural, mesh_sets  # noqa: E402

HPR_FACTOR = 100.0
NEIGHBOURS = 12
VOTES = (5, 9, 15)


def covariance_shape(points: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface variation, linearity and the line's direction of each point's neighbourhood ``idx``."""
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    return values[:, 0] / values.sum(axis=1), (values[:, 2] - values[:, 1]) / values[:, 2], vectors[:, :, 2]


def accuracy(masks, truth) -> float:
    return float(np.mean([(m == t).mean() for m, t in zip(masks, truth)]))


def measure(path, n: int, cameras: list[zo.Camera]) -> dict:
    """Every rule's accuracy on one mesh, and the fusion's features and labels."""
    mesh = path.mesh if isinstance(path, Procedural) else zo.load_mesh(path)
    points, face_index = zo.sample_surface(mesh, n, seed=0)
    faces = mesh.face_normals[face_index]
    truth = [zo.visible_mask(mesh, points, c, method="oracle", face_index=face_index) for c in cameras]
    surfels = zo.point_surfels(points)
    _, nearest = cKDTree(points).query(points, k=max(NEIGHBOURS, *VOTES))  # each point first
    idx = nearest[:, :NEIGHBOURS]
    variation, linearity, line = covariance_shape(points, idx)
    splat = [surfels.visible(c) for c in cameras]
    row = {"splats": accuracy(splat, truth)}
    error = np.degrees(np.arccos(np.clip(np.abs(np.einsum("ij,ij->i", surfels.normals, faces)), 0.0, 1.0)))
    mixed = (np.abs(np.einsum("nkj,nj->nk", faces[idx[:, 1:9]], faces)) > np.cos(np.radians(25))).mean(axis=1) < 2 / 3
    where = {
        "mixed": mixed.mean(),
        "off_mixed": (error[mixed] > 30).mean() if mixed.any() else np.nan,
        "off_rest": (error[~mixed] > 30).mean(),
    }
    for degrees in (10, 30, 60):
        given = zo.point_surfels(points, np.where((error > degrees)[:, None], faces, surfels.normals))
        row[f"faces' normals where off by > {degrees}°"] = accuracy([given.visible(c) for c in cameras], truth)
    for rough, factor in ((0.02, 0.8), (0.05, 0.7), (0.05, 0.5), (0.1, 0.7)):
        shrunk = dataclasses.replace(surfels, radius=np.where(variation > rough, factor * surfels.radius, surfels.radius))
        row[f"radius × {factor} where variation > {rough}"] = accuracy([shrunk.visible(c) for c in cameras], truth)
    for straight in (0.6, 0.75, 0.9):
        masks = []
        for c in cameras:
            across = c.eye - points
            across -= np.einsum("ij,ij->i", across, line)[:, None] * line
            facing = across / np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-300)
            turned = dataclasses.replace(surfels, normals=np.where((linearity > straight)[:, None], facing, surfels.normals))
            masks.append(turned.visible(c))
        row[f"rods turned to the camera, linearity > {straight}"] = accuracy(masks, truth)
    for k in VOTES:
        row[f"vote of {k} neighbours"] = accuracy([m[nearest[:, :k]].mean(axis=1) > 0.5 for m in splat], truth)
    bare = [surfels.visible(c, hull_test=False) for c in cameras]
    hpr = [on_flipped_hull(points, c.eye, HPR_FACTOR) for c in cameras]
    features = [np.column_stack([s, b, h, s[idx[:, 1:]].mean(axis=1), h[idx[:, 1:]].mean(axis=1)]) for s, b, h in zip(splat, bare, hpr)]
    return {"row": row, "features": features, "truth": truth, "where": where}


def main() -> int:
    from sklearn.linear_model import LogisticRegression

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("--points", type=int, nargs="+", default=[2048, 10000])
    args = p.parse_args()
    sets = mesh_sets()
    cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule("fibonacci:16")]
    for n in args.points:
        runs = {name: [measure(path, n, cameras) for path in sets[name]] for name in ("tune", "samples", "street")}
        reported = runs["samples"] + runs["street"]
        print(f"\n### {n:,} points: mean accuracy (22 tuning meshes, {len(reported)} reported)\n")
        print("| rule | tuning | reported |\n|---|---:|---:|")
        for key in runs["tune"][0]["row"]:
            print(f"| {key} | {np.mean([r['row'][key] for r in runs['tune']]):.4f} | {np.mean([r['row'][key] for r in reported]):.4f} |")
        x = np.vstack([f for r in runs["tune"] for f in r["features"]])
        y = np.concatenate([t for r in runs["tune"] for t in r["truth"]])
        fusion = LogisticRegression(max_iter=2000).fit(x, y)
        scores = {name: np.mean([accuracy([fusion.predict(f) for f in r["features"]], r["truth"]) for r in rs])
                  for name, rs in (("tune", runs["tune"]), ("reported", reported))}  # fmt: skip
        print(f"| learned fusion (fitted on the tuning meshes) | {scores['tune']:.4f} | {scores['reported']:.4f} |")
        for name, rs in (("tuning", runs["tune"]), ("reported", reported)):
            share = {k: np.nanmean([r["where"][k] for r in rs]) for k in rs[0]["where"]}
            print(f"\n{name}: {share['mixed']:.3f} of the points have mixed neighbours; estimates more than 30° off: "
                  f"{share['off_mixed']:.3f} of those, {share['off_rest']:.3f} of the rest")  # fmt: skip
        print("\nthe fusion's weights (splats, splats without the hull, HPR, neighbours' splats, neighbours' HPR; intercept): "
              + ", ".join(f"{w:.2f}" for w in (*fusion.coef_[0], fusion.intercept_[0])))  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
