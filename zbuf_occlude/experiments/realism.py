"""How LiDAR-like are generated object clouds?  Statistics against real scans.

Each cloud's statistics are :mod:`zbuf_occlude.experiments.realism_stats`' (rings and their
spacing, range and the count exponent, nearest-neighbour spacing, vertical extent, across-sight
width, outline share; a crop's height, width and vertical profile), whose names are importable
from here too.  This module reads the sets, compares them and writes the report.

:func:`compare_sets` compares two sets of clouds in a sensor frame: the medians of those statistics,
the count exponent over the ranges both sets cover, and the generated clouds' counts against the
real clouds' fit at the same range.

Per class (:func:`compare_classes`), for any sensor and the only comparison for airborne crops
(which record no sensor position, so neither rings nor ranges): points per crop; height over width;
and how the points spread over the height (the median normalised height and the share of points in
each tenth of it).  For clouds in a sensor frame (``by_range``), also the median points per crop in
range bins (:data:`RANGE_BINS_M`), the count exponent over the class's crops and the median outline
share.  A pole simulated as a tall shaft has its points spread up the shaft (median near 0.5,
height/width 10 or more), where an aerial crop of a real pole often shows a squat top (median near 1,
height/width near 1): the table shows such a mismatch.

:func:`realism_report` writes the tables (Markdown and CSV) and a side-by-side figure.  Sets are read by
:func:`read_object_clouds` from scan NPZ files (:meth:`Scan.to_npz`; each non-ground object is one
cloud), LiDARNet v2 CSVs, or class folders of point-cloud files of any format the real-scan
reader takes (:func:`zbuf_occlude.real_scans.datasets.load_real_scans`).  A cloud's class is its
class folder (the first folder under the path given; LiDARNet's ``object`` column).
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.realism_stats import (  # noqa: F401 - every name of realism_stats.__all__ stays importable from here
    HEIGHT_BINS,
    OUTLINE_GAP_FACTOR,
    RANGE_BINS_M,
    RING_GAP_DEG,
    SAME_AZIMUTH_DEG,
    ObjectCloud,
    break_depths_m,
    class_summary,
    cloud_stats,
    fit_count_exponent,
    outline_mask,
    outline_share,
    profile_distance,
    range_bin_medians,
    ring_labels,
    ring_spacings_deg,
    scan_line_runs,
    shape_stats,
)
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.safe_paths import check_found_file
from zbuf_occlude.sensors.scan_data import read_scan_npz
from zbuf_occlude.sensors.scan_files import TRAJECTORY_SUFFIX
from zbuf_occlude.sensors.scene.objects import GROUND_ID

# The statistics (ObjectCloud, cloud_stats, ring_labels, outline_share, ...) are realism_stats' names, documented
# there; imported above, they stay importable from here too (callers import them from either module).
__all__ = [
    "read_object_clouds", "compare_sets", "compare_classes", "markdown_table", "class_table", "realism_report", "REPORT_FILES",
    "RATIO_TARGET",
]  # fmt: skip

log = logging.getLogger(__name__)

#: A count (or a shape ratio) matches when generated / real lies within this factor either way.
RATIO_TARGET = 1.5
#: The median normalised height matches within a tenth of the object's height (one height bin).
MEDIAN_HEIGHT_TARGET = 0.1
#: The vertical profiles match when at most this share of the points would have to move to another
#: tenth of the height (total variation distance of the class's mean profiles).
PROFILE_TARGET = 0.1


# -- reading ------------------------------------------------------------------------------------
def _from_npz(path: Path, ground_in_crops: bool = False, label: str | None = None) -> list[ObjectCloud]:
    """The objects of one scan file, labelled ``label`` (None: ``object<id>``)."""
    s = read_scan_npz(path)
    pts = s.points.astype(np.float64) - s.sensor_position
    if s.frame == "sensor":
        pts = pts @ np.asarray(s.sensor_to_world, dtype=np.float64)[:3, :3].T  # world axes: z up
    objects = [oid for oid in np.unique(s.object_id) if oid != GROUND_ID]
    if ground_in_crops and len(objects) == 1:  # a crop: its ground returns are part of it
        return [ObjectCloud(pts, label or f"object{objects[0]}", f"{path}#{objects[0]}")]
    return [ObjectCloud(pts[s.object_id == oid], label or f"object{oid}", f"{path}#{oid}") for oid in objects]


def read_object_clouds(path: str | os.PathLike, *, min_points: int = 1, ground_in_crops: bool = False) -> list[ObjectCloud]:
    """Object clouds under ``path`` (a file or a folder, searched recursively): scan ``.npz`` files
    and/or LiDARNet v2 ``.csv`` files (duplicates dropped); or, when it holds no ``.npz``, any
    real scans :func:`~zbuf_occlude.real_scans.datasets.load_real_scans` reads (class folders of
    point-cloud files, such as aerial crops; LiDARNet; SUO), in metres as their files give them.

    Each object of a scan file is one cloud, its ground returns (object id 0) left out; with
    ``ground_in_crops``, a file holding one object (a crop made with a ground margin:
    ``scan --crop --ground-margin``) is one cloud with its ground returns, as a real crop that
    a box segmentation cut holds them.  A scan file in a folder under ``path`` takes that
    folder's name as its class (``gen/pole/*.npz``: ``pole``), else ``object<id>``.

    Raises
    ------
    InvalidInputError
        ``path`` missing or holding no cloud, or a file that cannot be read (named).
    """
    from zbuf_occlude.real_scans.datasets import load_real_scans

    root = Path(path)
    if not root.exists():
        raise InvalidInputError(f"realism: {root} does not exist")
    if root.is_file():
        files = [root]
    else:  # a found file linking outside the folder is refused as every scan folder's (io.safe_paths.check_found_file)
        found = sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in (".npz", ".csv"))
        files = [check_found_file(p, root) for p in found]
    clouds: list[ObjectCloud] = []
    npz = [f for f in files if f.suffix.lower() == ".npz"]
    csvs = [f for f in files if f.suffix.lower() == ".csv" and f.name != "MANIFEST.csv" and not f.name.endswith(TRAJECTORY_SUFFIX)]
    if csvs or not npz and root.is_dir():
        # discovery, labels, de-duplication; beside scan files only LiDARNet's CSVs
        for real in load_real_scans(root, dataset="lidarnet" if npz else "auto"):
            clouds.append(ObjectCloud(real.points_sensor_m, real.label, real.source))
    for f in npz:
        parts = f.relative_to(root).parts if f != root else ()
        clouds.extend(_from_npz(f, ground_in_crops, parts[0] if len(parts) > 1 else None))
    clouds = [c for c in clouds if len(c.points_m) >= min_points]
    if not clouds:
        raise InvalidInputError(f"realism: no object clouds (scan .npz or LiDARNet .csv) under {root}")
    return clouds


# -- comparing ----------------------------------------------------------------------------------
def compare_classes(generated: list[ObjectCloud], real: list[ObjectCloud], *, by_range: bool = False,
                    ) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """Per class, generated against real: points per crop, height over width and the vertical distribution.

    Classes are the labels both sets have; when they share none, every cloud of each set is pooled
    as one class, ``all``.  With ``by_range`` (both sets in a sensor frame), each summary also
    holds the points per crop by range, the count exponent and the outline share
    (:func:`class_summary`).

    Returns
    -------
    rows : list of dict
        As :func:`compare_sets`'s (``metric`` starts with the class), four per class: median points
        per crop and median height / width (ratio generated / real, within :data:`RATIO_TARGET`),
        median normalised height (difference within :data:`MEDIAN_HEIGHT_TARGET`), and the distance
        between the mean height profiles (within :data:`PROFILE_TARGET`).
    table : dict
        ``{class: {"generated": summary, "real": summary}}``, each summary :func:`class_summary`'s.
    """
    shared = sorted({c.label for c in generated} & {c.label for c in real})
    groups = {k: ([c for c in generated if c.label == k], [c for c in real if c.label == k]) for k in shared} or {"all": (generated, real)}
    rows, table = [], {}
    for k, (g_clouds, r_clouds) in groups.items():
        g, r = class_summary(g_clouds, by_range=by_range), class_summary(r_clouds, by_range=by_range)
        table[k] = {"generated": g, "real": r}
        for name, key in (("median points per crop", "n_points"), ("median height / width", "height_to_width")):
            ratio = g[key] / r[key] if r[key] > 0 else math.nan
            rows.append({"metric": f"{k}: {name} (n={g['crops']}, {r['crops']})", "generated": g[key], "real": r[key],
                         "difference": ratio, "target": f"1/{RATIO_TARGET:g} <= ratio <= {RATIO_TARGET:g}",
                         "met": bool(1 / RATIO_TARGET <= ratio <= RATIO_TARGET) if math.isfinite(ratio) else ""})  # fmt: skip
        d = g["median_normalised_height"] - r["median_normalised_height"]
        rows.append({"metric": f"{k}: median height above the crop's bottom, share of its height", "generated": g["median_normalised_height"],
                     "real": r["median_normalised_height"], "difference": d, "target": f"abs(diff) <= {MEDIAN_HEIGHT_TARGET:g}",
                     "met": bool(abs(d) <= MEDIAN_HEIGHT_TARGET) if math.isfinite(d) else ""})  # fmt: skip
        tv = profile_distance(g["height_shares"], r["height_shares"])
        rows.append({"metric": f"{k}: share of points in another tenth of the height (profile distance)", "generated": "", "real": "",
                     "difference": tv, "target": f"<= {PROFILE_TARGET:g}", "met": bool(tv <= PROFILE_TARGET)})  # fmt: skip
    return rows, table


def _bin_names(bins_m: tuple[float, ...] = RANGE_BINS_M) -> list[str]:
    """``["5-10", "10-15", ...]``: the range bins' names, metres."""
    return [f"{lo:g}-{hi:g}" for lo, hi in zip(bins_m[:-1], bins_m[1:])]


def class_table(table: dict[str, dict[str, dict]]) -> str:
    """:func:`compare_classes`' table as Markdown: one row per class and set, the height profile in percent, bottom to top;
    with summaries by range (:func:`class_summary`), the median points per crop in each range bin (crops in it),
    the count exponent, the median outline share and the median width per eighth of the height over the crop's
    width, bottom to top, after it."""
    by_range = any("n_points_by_range" in st for sets in table.values() for st in sets.values())
    head = ["class", "set", "crops", "median points", "median height, m", "median width, m", "median height / width",
            "median plan elongation", "median normalised height", "% of points per tenth of the height, bottom to top"]  # fmt: skip
    if by_range:
        widths = "median width per eighth of the height / the crop's, bottom to top"
        head += [f"median points at {b} m (crops)" for b in _bin_names()] + ["count exponent", "median outline share", widths]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for k, sets in table.items():
        for name, st in sets.items():
            profile = " ".join(f"{100 * v:.0f}" for v in st["height_shares"])
            cells = [k, name, str(st["crops"]), *(_fmt(st[key]) for key in ("n_points", "height_m", "width_m", "height_to_width",
                                                                           "plan_elongation", "median_normalised_height")), profile]  # fmt: skip
            if by_range:
                cells += [f"{_fmt(m)} ({c})" for m, c in zip(st["n_points_by_range"], st["crops_by_range"])]
                cells += [_fmt(st["count_exponent"]), _fmt(st["outline_share"]), " ".join(f"{v:.2f}" for v in st["width_profile"])]
            lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _class_rows(table: dict[str, dict[str, dict]]) -> list[dict]:
    """:func:`compare_classes`' table as CSV rows: class, set, the medians, one column per tenth of the height and,
    by range, per range bin and per eighth of the height (``relative_width_0_0.125``, ...: the width profile)."""
    by_range = ("n_points_by_range", "crops_by_range")
    arrays = ("height_shares", *by_range, "width_profile")
    return [{"class": k, "set": name, **{key: v for key, v in st.items() if key not in arrays},
             **_fraction_columns("share", st["height_shares"]),
             **{f"{key}_{b}_m": v.item() for key in by_range if key in st for b, v in zip(_bin_names(), st[key])},
             **_fraction_columns("relative_width", st.get("width_profile", ()))}
            for k, sets in table.items() for name, st in sets.items()]  # fmt: skip


def _fraction_columns(name: str, values) -> dict[str, float]:
    """``{f"{name}_{lo}_{hi}": value}``, one column per equal fraction of the height, bottom to top (``share_0_0.1``)."""
    n = len(values)
    return {f"{name}_{b / n:g}_{(b + 1) / n:g}": float(v) for b, v in enumerate(values)}


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
        "median_outline_share": float(np.nanmedian([s["outline_share"] for s in stats])),
        "_spacing": spacing, "_range": r, "_count": n, "_nn": np.array([s["nn_spacing_m"] for s in stats]),
    }  # fmt: skip


def compare_sets(
    generated: list[ObjectCloud], real: list[ObjectCloud], *, ring_gap_deg: float = RING_GAP_DEG
) -> tuple[list[dict], dict, dict]:
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
        {"metric": f"count / real fit at matched range (n={g['count_ratio_n']})", "generated": ratio, "real": 1.0, "difference": "", "target": f"1/{RATIO_TARGET:g} <= ratio <= {RATIO_TARGET:g}", "met": (1 / RATIO_TARGET <= ratio <= RATIO_TARGET) if math.isfinite(ratio) else ""},
        {"metric": "median points per cloud", "generated": g["median_points"], "real": r["median_points"], "difference": "", "target": "", "met": ""},
        {"metric": "median nearest-neighbour spacing, m", "generated": g["median_nn_spacing_m"], "real": r["median_nn_spacing_m"], "difference": g["median_nn_spacing_m"] - r["median_nn_spacing_m"], "target": "", "met": ""},
        {"metric": "median vertical extent, m", "generated": g["median_vertical_extent_m"], "real": r["median_vertical_extent_m"], "difference": g["median_vertical_extent_m"] - r["median_vertical_extent_m"], "target": "", "met": ""},
        {"metric": "median across-sight width, m", "generated": g["median_across_sight_width_m"], "real": r["median_across_sight_width_m"], "difference": g["median_across_sight_width_m"] - r["median_across_sight_width_m"], "target": "", "met": ""},
        {"metric": "median outline share (points ending a run of their ring)", "generated": g["median_outline_share"], "real": r["median_outline_share"], "difference": g["median_outline_share"] - r["median_outline_share"], "target": "", "met": ""},
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


def _figure(g: dict, r: dict, labels: tuple[str, str]):
    """Ring spacing, count against range and spacing against range, generated beside real."""
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
    return fig


def _save(fig, folder: OwnedFolder, name: str) -> None:
    """Write ``fig`` as the PNG ``name`` in ``folder`` (:meth:`OwnedFolder.write_bytes`) and close it."""
    import matplotlib.pyplot as plt

    try:
        fig.tight_layout()
        folder.write_bytes(name, png_bytes(fig, dpi=110))
    finally:
        plt.close(fig)


def _profile_figure(table: dict[str, dict[str, dict]]):
    """Per class, the share of points in each tenth of the height, generated beside real."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(table), figsize=(3.2 * len(table), 3.8), squeeze=False)
    centres = (np.arange(HEIGHT_BINS) + 0.5) / HEIGHT_BINS
    for ax, (k, sets) in zip(axes[0], table.items(), strict=True):
        for (name, st), colour in zip(sets.items(), ("tab:blue", "tab:orange"), strict=True):
            ax.plot(st["height_shares"], centres, "o-", color=colour, label=f"{name} ({st['crops']})")
        ax.set(xlabel="share of points", ylabel="height above the bottom / height", title=k, ylim=(0, 1))
        ax.legend(fontsize=8)
    return fig


#: The files :func:`realism_report` writes in its folder (the figure unless ``figure=False``).
REPORT_FILES = ("realism.md", "realism.csv", "realism_classes.csv", "realism.png")


def realism_report(generated: str | os.PathLike, real: str | os.PathLike, out_dir: str | os.PathLike, *, ring_gap_deg: float = RING_GAP_DEG, min_points: int = 1, figure: bool = True,
                   ground_in_crops: bool = False, airborne: bool = False) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """Compare two sets of object clouds; write ``realism.md``, ``realism.csv``,
    ``realism_classes.csv`` and ``realism.png`` under ``out_dir``.

    Parameters
    ----------
    generated, real : path
        :func:`read_object_clouds`; ``ground_in_crops`` applies to ``generated``.
    airborne : bool
        The clouds are aerial crops (no sensor position): only the per-class comparison
        (:func:`compare_classes`), whose height profiles the figure then shows; without it, the
        ring, range and spacing rows (:func:`compare_sets`) come first.

    Returns
    -------
    rows : list of dict
        What ``realism.csv`` holds: :func:`compare_sets`' rows (but its first, the cloud counts,
        alone with ``airborne``), then :func:`compare_classes`'.
    table : dict
        :func:`compare_classes`' table, as ``realism_classes.csv`` holds it.

    Raises
    ------
    InvalidInputError
        A set is missing or empty.
    OutputError
        ``out_dir`` cannot be made or written.
    UnsafePathError
        A file of a name it writes is in ``out_dir`` and was not written by a run of ours, or
        was changed since (checked before any cloud is read; nothing is written).
    DatasetBusy
        Another live process holds ``out_dir``.
    """
    files = REPORT_FILES if figure else REPORT_FILES[:-1]
    with OwnedFolder(out_dir, files=REPORT_FILES, what="the realism report") as folder:
        folder.check_writable(files)  # every file before any work: a refusal writes nothing
        return _report_into(folder, generated, real, ring_gap_deg=ring_gap_deg, min_points=min_points, figure=figure,
                            ground_in_crops=ground_in_crops, airborne=airborne)  # fmt: skip


def _report_into(folder: OwnedFolder, generated: str | os.PathLike, real: str | os.PathLike, *, ring_gap_deg: float, min_points: int, figure: bool,
                 ground_in_crops: bool, airborne: bool) -> tuple[list[dict], dict[str, dict[str, dict]]]:  # fmt: skip
    """:func:`realism_report` once its folder is held."""
    gen_clouds = read_object_clouds(generated, min_points=min_points, ground_in_crops=ground_in_crops)
    real_clouds = read_object_clouds(real, min_points=min_points)
    if airborne:
        rows = [{"metric": "clouds", "generated": len(gen_clouds), "real": len(real_clouds), "difference": "", "target": "", "met": ""}]
    else:
        rows, g, r = compare_sets(gen_clouds, real_clouds, ring_gap_deg=ring_gap_deg)
    class_rows, table = compare_classes(gen_clouds, real_clouds, by_range=not airborne)
    rows += class_rows
    header = f"Generated: {generated} ({len(gen_clouds)} clouds); real: {real} ({len(real_clouds)} clouds)\n\n"
    folder.write_text("realism.md", header + markdown_table(rows) + "\n" + class_table(table))
    folder.write_csv("realism.csv", rows)
    folder.write_csv("realism_classes.csv", _class_rows(table))
    if figure:
        _save(_profile_figure(table) if airborne else _figure(g, r, ("generated", "real")), folder, "realism.png")
    return rows, table
