"""How LiDAR-like are generated object clouds?  Statistics against real scans.

For each object cloud, in a frame centred on the sensor with z up (metres):

* ring spacing: point elevations ``asin(z / |p|)`` are grouped into rings (a gap larger than
  ``ring_gap_deg`` starts a new ring); the spacing is the difference of consecutive ring
  elevations (median elevation per ring), degrees;
* range: distance from the sensor to the cloud's centroid, metres; the point count against it
  gives the exponent ``b`` of ``count ∝ range^b`` (least squares in log–log over the clouds);
* nearest-neighbour spacing: median distance of a point to its nearest other point, metres;
* vertical extent: ``max z − min z``, metres;
* across-sight width: how wide the cloud shows across the line of sight, metres
  (:func:`zbuf_occlude.sensors.fit.across_sight_width`).

Two sets are compared by :func:`compare_sets`; :func:`realism_report` writes the table (Markdown
and CSV) and a side-by-side figure.  Sets are read by :func:`read_object_clouds` from scan NPZ
files (:meth:`Scan.to_npz`; each non-ground object is one cloud) or LiDARNet v2 CSVs.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.atomic import atomic_path, write_csv, write_text
from zbuf_occlude.sensors.fit import across_sight_width
from zbuf_occlude.sensors.scan import read_scan_npz
from zbuf_occlude.sensors.scene import GROUND_ID

__all__ = [
    "ObjectCloud", "read_object_clouds", "cloud_stats", "ring_spacings_deg", "fit_count_exponent",
    "compare_sets", "markdown_table", "realism_report", "RING_GAP_DEG",
]  # fmt: skip

log = logging.getLogger(__name__)

#: Elevation gap that separates two rings, degrees: a third of the HDL-32E's 1.33° spacing,
#: far above the elevation jitter of one ring (noise is along the beam).
RING_GAP_DEG = 0.4


@dataclass
class ObjectCloud:
    """One object's returns.

    Attributes
    ----------
    points_m : (N, 3) float64
        Sensor at the origin, world axes (z up), metres.
    label : str
    source : str
    """

    points_m: NDArray[np.float64]
    label: str
    source: str


# -- reading ------------------------------------------------------------------------------------
def _from_npz(path: Path, ground_in_crops: bool = False) -> list[ObjectCloud]:
    s = read_scan_npz(path)
    pts = s.points.astype(np.float64) - s.sensor_position
    if s.frame == "sensor":
        pts = pts @ np.asarray(s.sensor_to_world, dtype=np.float64)[:3, :3].T  # world axes: z up
    objects = [oid for oid in np.unique(s.object_id) if oid != GROUND_ID]
    if ground_in_crops and len(objects) == 1:  # a crop: its ground returns are part of it
        return [ObjectCloud(pts, f"object{objects[0]}", f"{path}#{objects[0]}")]
    return [ObjectCloud(pts[s.object_id == oid], f"object{oid}", f"{path}#{oid}") for oid in objects]


def read_object_clouds(path: str | os.PathLike, *, min_points: int = 1, ground_in_crops: bool = False) -> list[ObjectCloud]:
    """Object clouds under ``path``: scan ``.npz`` files and/or LiDARNet v2 ``.csv`` files
    (a file or a folder, searched recursively; LiDARNet duplicates dropped).

    Each object of a scan file is one cloud, its ground returns (object id 0) left out; with
    ``ground_in_crops``, a file holding one object (a crop made with a ground margin:
    ``scan --crop --ground-margin``) is one cloud with its ground returns, as a real crop that
    a box segmentation cut holds them.

    Raises
    ------
    InvalidInputError
        ``path`` missing or holding no cloud, or a ``.csv`` that is not UTF-8 (named).
    """
    root = Path(path)
    if not root.exists():
        raise InvalidInputError(f"realism: {root} does not exist")
    files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in (".npz", ".csv"))
    clouds: list[ObjectCloud] = []
    csvs = [f for f in files if f.suffix.lower() == ".csv" and f.name != "MANIFEST.csv"]
    if csvs:
        from zbuf_occlude.real_scans.datasets import load_real_scans

        for real in load_real_scans(root, dataset="lidarnet"):  # discovery, labels, de-duplication
            clouds.append(ObjectCloud(real.points_sensor_m, real.label, real.source))
    for f in files:
        if f.suffix.lower() == ".npz":
            clouds.extend(_from_npz(f, ground_in_crops))
    clouds = [c for c in clouds if len(c.points_m) >= min_points]
    if not clouds:
        raise InvalidInputError(f"realism: no object clouds (scan .npz or LiDARNet .csv) under {root}")
    return clouds


# -- statistics ---------------------------------------------------------------------------------
def ring_spacings_deg(points_m: NDArray[np.floating], *, ring_gap_deg: float = RING_GAP_DEG) -> NDArray[np.float64]:
    """(R − 1,) float64: elevation differences of consecutive rings, degrees (module docstring)."""
    p = np.asarray(points_m, dtype=np.float64)
    if len(p) < 2:
        return np.zeros(0)
    elev = np.sort(np.degrees(np.arcsin(np.clip(p[:, 2] / np.linalg.norm(p, axis=1), -1, 1))))
    cuts = np.flatnonzero(np.diff(elev) > ring_gap_deg) + 1
    centres = np.array([np.median(g) for g in np.split(elev, cuts)])
    return np.diff(centres)


def cloud_stats(cloud: ObjectCloud, *, ring_gap_deg: float = RING_GAP_DEG) -> dict:
    """Per-cloud statistics: ``n_points, range_m, n_rings, ring_spacings_deg, nn_spacing_m, vertical_extent_m, across_sight_width_m``."""
    from scipy.spatial import cKDTree

    p = cloud.points_m
    spacing = ring_spacings_deg(p, ring_gap_deg=ring_gap_deg)
    nn = float(np.median(cKDTree(p).query(p, k=2)[0][:, 1])) if len(p) > 1 else float("nan")
    return {
        "n_points": len(p),
        "range_m": float(np.linalg.norm(p.mean(axis=0))),
        "n_rings": len(spacing) + 1,
        "ring_spacings_deg": spacing,
        "nn_spacing_m": nn,
        "vertical_extent_m": float(np.ptp(p[:, 2])) if len(p) else 0.0,
        "across_sight_width_m": across_sight_width(p),
    }


def fit_count_exponent(range_m, count) -> tuple[float, float, float]:
    """Least-squares fit ``log count = a + b log range``: ``(b, standard error of b, a)``."""
    x, y = np.log(np.asarray(range_m, float)), np.log(np.asarray(count, float))
    if len(x) < 3 or np.ptp(x) == 0:
        return float("nan"), float("nan"), float("nan")
    A = np.column_stack([np.ones_like(x), x])
    coef, res, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ coef
    se = math.sqrt(resid @ resid / (len(x) - 2) / ((x - x.mean()) @ (x - x.mean())))
    return float(coef[1]), se, float(coef[0])


def _summary(stats: list[dict]) -> dict:
    spacing = np.concatenate([s["ring_spacings_deg"] for s in stats]) if stats else np.zeros(0)
    r = np.array([s["range_m"] for s in stats])
    n = np.array([s["n_points"] for s in stats])
    b, se, a = fit_count_exponent(r, n)
    return {
        "clouds": len(stats),
        "median_ring_spacing_deg": float(np.median(spacing)) if len(spacing) else float("nan"),
        "count_exponent": b, "count_exponent_se": se, "count_log_intercept": a,
        "median_points": float(np.median(n)), "median_range_m": float(np.median(r)),
        "range_m_p5_p95": (float(np.percentile(r, 5)), float(np.percentile(r, 95))),
        "median_nn_spacing_m": float(np.nanmedian([s["nn_spacing_m"] for s in stats])),
        "median_vertical_extent_m": float(np.median([s["vertical_extent_m"] for s in stats])),
        "median_across_sight_width_m": float(np.median([s["across_sight_width_m"] for s in stats])),
        "_spacing": spacing, "_range": r, "_count": n, "_nn": np.array([s["nn_spacing_m"] for s in stats]),
    }  # fmt: skip


def compare_sets(generated: list[ObjectCloud], real: list[ObjectCloud], *, ring_gap_deg: float = RING_GAP_DEG) -> tuple[list[dict], dict, dict]:
    """Statistics of both sets and the table rows.

    The count ratio at matched range is ``count / (real fit at that range)`` per generated cloud
    inside the real clouds' 5–95 % range, median over them.

    Returns
    -------
    rows : list of dict
        ``metric, generated, real, difference, target, met``.
    gen, real : dict
        :func:`_summary` of each set (arrays under keys starting with ``_``).
    """
    g = _summary([cloud_stats(c, ring_gap_deg=ring_gap_deg) for c in generated])
    r = _summary([cloud_stats(c, ring_gap_deg=ring_gap_deg) for c in real])
    lo, hi = r["range_m_p5_p95"]
    inside = (g["_range"] >= lo) & (g["_range"] <= hi)
    predicted = np.exp(r["count_log_intercept"]) * g["_range"][inside] ** r["count_exponent"]
    ratio = float(np.median(g["_count"][inside] / predicted)) if inside.any() else float("nan")
    g["count_ratio_at_matched_range"] = ratio
    g["count_ratio_n"] = int(inside.sum())
    # The exponent over the ranges both sets cover: a cloud nearer than any real one (an
    # extended object seen from a few metres, whose angular size saturates) would bend the fit.
    c_lo = max(g["_range"].min(), r["_range"].min())
    c_hi = min(g["_range"].max(), r["_range"].max())
    common = {}
    for name, st in (("g", g), ("r", r)):
        m = (st["_range"] >= c_lo) & (st["_range"] <= c_hi)
        common[name] = fit_count_exponent(st["_range"][m], st["_count"][m])[:2] + (int(m.sum()),)
    g["count_exponent_common"], r["count_exponent_common"] = common["g"][0], common["r"][0]
    ds = g["median_ring_spacing_deg"] - r["median_ring_spacing_deg"]
    db = common["g"][0] - common["r"][0]
    db_all = g["count_exponent"] - r["count_exponent"]
    rows = [
        {"metric": "clouds", "generated": g["clouds"], "real": r["clouds"], "difference": "", "target": "", "met": ""},
        {"metric": "median range, m", "generated": g["median_range_m"], "real": r["median_range_m"], "difference": g["median_range_m"] - r["median_range_m"], "target": "", "met": ""},
        {"metric": "median ring spacing, deg", "generated": g["median_ring_spacing_deg"], "real": r["median_ring_spacing_deg"], "difference": ds, "target": "abs(diff) <= 0.05", "met": abs(ds) <= 0.05},
        {"metric": f"count-vs-range exponent b (count ∝ r^b), common range {c_lo:.1f}-{c_hi:.1f} m (n={common['g'][2]}, {common['r'][2]})", "generated": common["g"][0], "real": common["r"][0], "difference": db, "target": "abs(diff) <= 0.2", "met": abs(db) <= 0.2},
        {"metric": "its standard error", "generated": common["g"][1], "real": common["r"][1], "difference": "", "target": "", "met": ""},
        {"metric": "exponent b over all clouds", "generated": g["count_exponent"], "real": r["count_exponent"], "difference": db_all, "target": "", "met": ""},
        {"metric": f"count / real fit at matched range (n={g['count_ratio_n']})", "generated": ratio, "real": 1.0, "difference": "", "target": "1/1.5 <= ratio <= 1.5", "met": (1 / 1.5 <= ratio <= 1.5) if math.isfinite(ratio) else ""},
        {"metric": "median points per cloud", "generated": g["median_points"], "real": r["median_points"], "difference": "", "target": "", "met": ""},
        {"metric": "median nearest-neighbour spacing, m", "generated": g["median_nn_spacing_m"], "real": r["median_nn_spacing_m"], "difference": g["median_nn_spacing_m"] - r["median_nn_spacing_m"], "target": "", "met": ""},
        {"metric": "median vertical extent, m", "generated": g["median_vertical_extent_m"], "real": r["median_vertical_extent_m"], "difference": g["median_vertical_extent_m"] - r["median_vertical_extent_m"], "target": "", "met": ""},
        {"metric": "median across-sight width, m", "generated": g["median_across_sight_width_m"], "real": r["median_across_sight_width_m"], "difference": g["median_across_sight_width_m"] - r["median_across_sight_width_m"], "target": "", "met": ""},
    ]  # fmt: skip
    return rows, g, r


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "yes" if v else "**no**"
    if isinstance(v, (float, np.floating)):
        return f"{v:.3f}" if math.isfinite(v) else "n/a"
    return str(v)


def markdown_table(rows: list[dict]) -> str:
    """The rows as a Markdown table."""
    keys = ["metric", "generated", "real", "difference", "target", "met"]
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(_fmt(row[k]) for k in keys) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _figure(g: dict, r: dict, path: Path, labels: tuple[str, str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
    bins = np.arange(0.0, 4.01, 0.05)
    for s, name, colour in ((g, labels[0], "tab:blue"), (r, labels[1], "tab:orange")):
        ax[0].hist(s["_spacing"], bins=bins, alpha=0.6, density=True, label=name, color=colour)
        ax[1].loglog(s["_range"], s["_count"], ".", alpha=0.5, color=colour, label=f"{name}: b = {s['count_exponent']:.2f}")
        xs = np.geomspace(max(s["_range"].min(), 1e-3), s["_range"].max(), 20)
        ax[1].loglog(xs, np.exp(s["count_log_intercept"]) * xs ** s["count_exponent"], "-", color=colour)
        ax[2].loglog(s["_range"], s["_nn"], ".", alpha=0.5, color=colour, label=name)
    ax[0].set(xlabel="ring spacing, deg", ylabel="density", title="elevation ring spacing")
    ax[1].set(xlabel="range, m", ylabel="points", title="point count vs range (all clouds)")
    ax[2].set(xlabel="range, m", ylabel="median nearest-neighbour spacing, m", title="point spacing vs range")
    for a in ax:
        a.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.tight_layout()
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)


def realism_report(generated: str | os.PathLike, real: str | os.PathLike, out_dir: str | os.PathLike, *, ring_gap_deg: float = RING_GAP_DEG, min_points: int = 1, figure: bool = True,
                   ground_in_crops: bool = False) -> list[dict]:  # fmt: skip
    """Compare two sets of object clouds; write ``realism.md``, ``realism.csv`` and ``realism.png``
    under ``out_dir``.  ``ground_in_crops``: the generated crops' ground returns count
    (:func:`read_object_clouds`).

    Raises
    ------
    InvalidInputError
        A set is missing or empty.
    OutputError
        ``out_dir`` cannot be written.
    """
    gen_clouds = read_object_clouds(generated, min_points=min_points, ground_in_crops=ground_in_crops)
    real_clouds = read_object_clouds(real, min_points=min_points)
    rows, g, r = compare_sets(gen_clouds, real_clouds, ring_gap_deg=ring_gap_deg)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    header = f"Generated: {generated} ({len(gen_clouds)} clouds); real: {real} ({len(real_clouds)} clouds)\n\n"
    write_text(out / "realism.md", header + markdown_table(rows))
    write_csv(out / "realism.csv", rows)
    if figure:
        _figure(g, r, out / "realism.png", ("generated", "real"))
    return rows
