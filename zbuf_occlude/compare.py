"""Image space vs object space: every HSR method side by side, against the oracle.

For every mesh × number of points × camera pose × method, :func:`compare` times one call
of :func:`~zbuf_occlude.visibility.visible_mask` (wall time per view) and scores its
answer against the reference method (``"oracle"``, exact):

``accuracy``
    Fraction of points on which the method agrees with the reference.
``false_visible_rate``, ``false_hidden_rate``
    Fraction of *all* points the method calls visible that the reference hides, and the
    reverse; ``accuracy = 1 - false_visible_rate - false_hidden_rate``.
``iou``
    Intersection over union of the two visible sets (1 when both are empty).
``chamfer``
    Symmetric Chamfer distance between the two output clouds (mean nearest-neighbour
    distance each way, averaged; object units, meshes normalised to extent 1).

Optional sweeps score the image-space methods at several z-buffer resolutions and the
occupancy grid at several grid sizes.  :func:`write_results` writes ``results.csv``, a
Markdown report and PNG plots; :func:`table_1a` and :func:`table_1b` format the
reproduction of Sryamkin et al. 2023, Table 1A/1B.  :func:`run_compare` is the whole
``zbuf-occlude compare`` command; :func:`add_compare_parser` adds it to an argparse CLI.

A method that raises on a mesh is recorded in its row's ``error`` column and in the
report, and the run goes on.
"""

from __future__ import annotations

import argparse
import csv
import logging
import math
import os
import time
import tracemalloc
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .cameras import DEFAULT_RADIUS, camera_on_sphere, view_schedule
from .errors import InvalidInputError, OutputError, ZbufOccludeError
from . import io
from .mesh import find_meshes, load_mesh
from .metrics import agreement
from .sampling import sample_surface
from .visibility import available_methods, visible_mask

__all__ = [
    "chamfer_distance",
    "parse_methods",
    "parse_int_list",
    "compare",
    "write_results",
    "write_csv",
    "read_csv",
    "summarise",
    "table_1a",
    "table_1b",
    "run_compare",
    "add_compare_parser",
    "RESULT_FIELDS",
    "DEFAULT_METHODS",
    "DEFAULT_POINTS",
    "DEFAULT_VIEWS",
    "DEFAULT_REFERENCE",
    "RESOLUTION_SWEEP",
    "GRID_SWEEP",
    "IMAGE_SPACE_METHODS",
    "PAPER_TABLE_1A_REDUCTION",
    "PAPER_TABLE_1B_REDUCTION",
]

log = logging.getLogger(__name__)

#: Methods compared by default (the issue's list; open3d-* are added when asked for).
DEFAULT_METHODS = (
    "zbuffer",
    "oracle",
    "paper-vertex",
    "paper-exact",
    "paper-pruned",
    "og32",
    "og64",
    "naive-zbuffer",
)
#: Point counts of Table 1B of Sryamkin et al. 2023.
DEFAULT_POINTS = (1000, 10000, 50000, 100000)
#: Pose schedule (see :func:`zbuf_occlude.cameras.view_schedule`).
DEFAULT_VIEWS = "grid25"
#: The method every other is scored against: exact (Embree candidates, float64 decisions).
DEFAULT_REFERENCE = "oracle"
#: Z-buffer resolutions of the agreement-vs-resolution sweep, pixels.
RESOLUTION_SWEEP = (128, 256, 512, 1024, 2048)
#: Occupancy-grid sizes of the agreement-vs-grid sweep, cells per axis.
GRID_SWEEP = (16, 32, 64, 128)
#: Methods with a ``resolution`` option, swept over :data:`RESOLUTION_SWEEP`.
IMAGE_SPACE_METHODS = ("zbuffer", "zbuffer-tolerance", "naive-zbuffer")
#: Methods with a ``grid`` option (or a grid in their name), swept over :data:`GRID_SWEEP`.
GRID_METHODS = ("og",) + tuple(f"og{g}" for g in GRID_SWEEP)
#: Sryamkin et al. 2023, Table 1A: ``paper-pruned`` vs ``paper-exact`` time reduction,
#: percent (reported ≈55 %, rows from 54 to 59 %).
PAPER_TABLE_1A_REDUCTION = (54.0, 59.0)
#: Sryamkin et al. 2023, Table 1B: OG_32 / OG_64 vs exact time reduction at 50k-100k
#: points, percent.
PAPER_TABLE_1B_REDUCTION = (98.5, 99.8)
#: Bytes per mebibyte, for the ``peak_mib`` column.
_MIB = float(1 << 20)

#: Columns of ``results.csv``, in order.
RESULT_FIELDS = (
    "mesh",
    "n_faces",
    "n_points",
    "view",
    "elevation_deg",
    "azimuth_deg",
    "method",
    "sweep",
    "param",
    "time_s",
    "peak_mib",
    "n_visible",
    "n_reference_visible",
    "accuracy",
    "false_visible_rate",
    "false_hidden_rate",
    "iou",
    "chamfer",
    "error",
)


# =========================================================================================
# Metrics
# =========================================================================================
def chamfer_distance(a: NDArray[np.floating], b: NDArray[np.floating]) -> float:
    """Symmetric Chamfer distance: ``(mean_a d(a, B) + mean_b d(b, A)) / 2``.

    Parameters
    ----------
    a : (N, 3) float
    b : (M, 3) float

    Returns
    -------
    float
        Object units; 0.0 when both are empty, NaN when exactly one is.
    """
    from scipy.spatial import cKDTree  # deferred: scipy is only needed here

    a = np.asarray(a, dtype=np.float64).reshape(-1, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 3)
    if len(a) == 0 and len(b) == 0:
        return 0.0
    if len(a) == 0 or len(b) == 0:
        return math.nan
    d_ab, _ = cKDTree(b).query(a)
    d_ba, _ = cKDTree(a).query(b)
    return float((d_ab.mean() + d_ba.mean()) / 2.0)


# =========================================================================================
# Argument parsing helpers
# =========================================================================================
def parse_methods(spec: str | Sequence[str]) -> list[str]:
    """Method names from ``"a,b,c"`` or a sequence; :class:`InvalidInputError` on unknown ones."""
    names = [m.strip() for m in spec.split(",")] if isinstance(spec, str) else [str(m).strip() for m in spec]
    names = [m for m in names if m]
    if not names:
        raise InvalidInputError("no visibility method given; e.g. --methods zbuffer,oracle,paper-exact")
    known = set(available_methods())
    unknown = [m for m in names if m not in known]
    if unknown:
        raise InvalidInputError(f"unknown visibility method(s) {', '.join(unknown)}; available: {', '.join(sorted(known))}")
    return list(dict.fromkeys(names))


def parse_int_list(spec: str | Iterable[int], what: str = "values") -> list[int]:
    """Positive integers from ``"1000,10000"`` (``k`` suffix allowed: ``"50k"``) or an iterable."""
    items = spec.split(",") if isinstance(spec, str) else list(spec)
    out = []
    for item in items:
        text = str(item).strip().lower()
        if not text:
            continue
        scale = 1000 if text.endswith("k") else 1
        try:
            value = int(float(text.rstrip("k")) * scale)
        except ValueError:
            raise InvalidInputError(f"bad {what} {spec!r}: {item!r} is not an integer") from None
        if value < 1:
            raise InvalidInputError(f"bad {what} {spec!r}: {value} < 1")
        out.append(value)
    return out


# =========================================================================================
# The run
# =========================================================================================
def _run_once(
    mesh: Any, points: NDArray[np.float64], face_index: NDArray[np.int64], camera: Any, method: str, options: dict
) -> tuple[NDArray[np.bool_], float]:
    start = time.perf_counter()
    mask = visible_mask(mesh, points, camera, method, face_index=face_index, **options)
    return np.asarray(mask, dtype=bool), time.perf_counter() - start


def _peak_mib(
    mesh: Any, points: NDArray[np.float64], face_index: NDArray[np.int64], camera: Any, method: str, options: dict
) -> float:
    # tracemalloc sees numpy's and Python's allocations (not Embree's, OpenGL's or numba's
    # thread stacks); run untimed, after the timed call, so tracing never slows a timing.
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        visible_mask(mesh, points, camera, method, face_index=face_index, **options)
        return tracemalloc.get_traced_memory()[1] / _MIB
    finally:
        tracemalloc.stop()


def _row(**fields: Any) -> dict[str, Any]:
    row = dict.fromkeys(RESULT_FIELDS, "")
    row.update(fields)
    return row


def _score(row: dict[str, Any], mask: NDArray[np.bool_], ref: NDArray[np.bool_], points: NDArray[np.float64]) -> None:
    a = agreement(mask, ref)
    row.update(
        n_visible=int(mask.sum()),
        n_reference_visible=int(ref.sum()),
        accuracy=a["accuracy"],
        false_visible_rate=a["false_visible"],
        false_hidden_rate=a["false_hidden"],
        iou=a["iou"],
        chamfer=chamfer_distance(points[mask], points[ref]),
    )


def _sweep_jobs(
    methods: Sequence[str], resolution_sweep: Sequence[int], grid_sweep: Sequence[int]
) -> list[tuple[str, str, int, dict]]:
    jobs = []
    for m in methods:
        if m in IMAGE_SPACE_METHODS:
            jobs += [(m, "resolution", r, {"resolution": r}) for r in resolution_sweep]
    if any(m in GRID_METHODS for m in methods):
        jobs += [("og", "grid", g, {"grid": g}) for g in grid_sweep]
    return jobs


def compare(
    paths: Sequence[str | os.PathLike],
    methods: Sequence[str] = DEFAULT_METHODS,
    points: Sequence[int] = DEFAULT_POINTS,
    views: str | Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    resolution: int = 1024,
    seed: int = 0,
    *,
    reference: str = DEFAULT_REFERENCE,
    resolution_sweep: Sequence[int] = (),
    grid_sweep: Sequence[int] = (),
    sweep_points: int | None = None,
    radius: float = DEFAULT_RADIUS,
    method_options: dict[str, dict[str, Any]] | None = None,
    memory: bool = False,
    method_budget_s: float | None = None,
    warmup: bool = True,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Time every method and score it against the reference, mesh × points × view.

    Parameters
    ----------
    paths : sequence of path
        Mesh files (normalised by :func:`zbuf_occlude.load_mesh`).
    methods : sequence of str
        Registered method names (see :func:`zbuf_occlude.available_methods`).
    points : sequence of int
        Sample counts; the same ``seed`` gives the same samples for every method.
    views : str or sequence of (elevation_deg, azimuth_deg)
        A :func:`zbuf_occlude.view_schedule` spec (``"grid25"``, ``"paper100"``,
        ``"fibonacci:N"``, ``"EL:AZ,..."``) or explicit poses.
    resolution : int
        Image size of the cameras, pixels (the z-buffer methods' resolution).
    seed : int
        Sampling seed.
    reference : str
        Method that defines the truth (default ``"oracle"``).  Its time is recorded too.
    resolution_sweep, grid_sweep : sequence of int
        Extra rows (``sweep="resolution"``/``"grid"``) for the image-space methods among
        ``methods`` at each resolution, and for ``og`` at each grid size, at
        ``sweep_points`` points.
    sweep_points : int, optional
        Point count of the sweeps (default: the smallest of ``points``).
    radius : float
        Camera distance, object units (default 4, the paper's §4.1).
    method_options : dict, optional
        Per-method keyword options, e.g. ``{"paper-vertex": {"max_edge": 0.05}}``.
    memory : bool
        Also record each method's peak traced memory (``peak_mib``, MiB) from one extra,
        untimed call per mesh × point count (first view).
    method_budget_s : float, optional
        A method whose call took longer than this is skipped for the larger point counts
        of that mesh (rows say so in ``error``), so one slow O(N·F) method cannot stall a
        run.
    warmup : bool
        Call every method once, untimed, on the first view of each mesh before timing it,
        so that one-off costs (numba compilation, Embree's BVH, uploading the mesh to the
        GPU) are not charged to a view.
    progress : bool
        Show a tqdm progress bar.

    Returns
    -------
    rows : list of dict
        One per (mesh, points, view, method[, sweep value]) with the keys of
        :data:`RESULT_FIELDS`; metrics are floats, ``error`` is empty on success.

    Raises
    ------
    InvalidInputError
        Unknown method names, bad point counts or a bad view schedule.
    """
    from tqdm.auto import tqdm  # deferred: only the run needs it

    methods = parse_methods(methods)
    parse_methods([reference])
    counts = parse_int_list(points, "point counts")
    if not counts:
        raise InvalidInputError("no point count given; e.g. --points 1000,10000")
    poses = view_schedule(views) if isinstance(views, str) else [(float(e), float(a)) for e, a in views]
    sweep_n = int(sweep_points) if sweep_points is not None else min(counts)
    requested = set(counts)
    if sweep_n not in counts:
        counts = sorted(set(counts) | {sweep_n})
    sweeps = _sweep_jobs(methods, resolution_sweep, grid_sweep)
    options = method_options or {}
    rows: list[dict[str, Any]] = []
    per_view = len(methods) + 1
    # folders are searched recursively, as by `generate` and `validate`; a file that does
    # not load is reported in the table like any other failure
    paths = [f for p in paths for f in ([m for m, _ in find_meshes([p])] if Path(p).is_dir() else [p])]
    total = len(paths) * sum(len(poses) * (per_view + (len(sweeps) if n == sweep_n else 0)) for n in counts)
    bar = tqdm(total=total, desc="compare", unit="call", disable=not progress)
    for path in paths:
        name = Path(path).stem
        try:
            mesh = load_mesh(path)
        except ZbufOccludeError as exc:
            log.warning("compare: %s", exc)
            rows.append(_row(mesh=name, method="*", error=str(exc)))
            bar.update(sum(len(poses) * (per_view + (len(sweeps) if n == sweep_n else 0)) for n in counts))
            continue
        over_budget: dict[str, str] = {}
        warmed: set[tuple[str, str, Any]] = set()
        for n in sorted(counts):
            pts, fi = sample_surface(mesh, count=n, seed=seed)
            jobs = [(m, "", "", {}) for m in methods] + (sweeps if n == sweep_n else [])
            if n not in requested:
                jobs = sweeps  # the sweep count was added only for the sweeps
            measured_memory: set[str] = set()
            for v, (el, az) in enumerate(poses):
                camera = camera_on_sphere(el, az, radius, resolution=resolution)
                base = dict(
                    mesh=name, n_faces=len(mesh.faces), n_points=n, view=v, elevation_deg=el, azimuth_deg=az
                )
                try:
                    if warmup and v == 0 and n == min(counts):
                        _run_once(mesh, pts, fi, camera, reference, options.get(reference, {}))
                    ref, ref_time = _run_once(mesh, pts, fi, camera, reference, options.get(reference, {}))
                except Exception as exc:  # noqa: BLE001 - reported in the table, not fatal
                    log.warning("compare: reference %s failed on %s: %s", reference, name, exc)
                    rows.append(_row(**base, method=reference, error=f"reference failed: {exc}"))
                    bar.update(1 + len(jobs))
                    continue
                row = _row(**base, method=reference, time_s=ref_time)
                _score(row, ref, ref, pts)
                rows.append(row)
                bar.update(1)
                for method, sweep, param, extra in jobs:
                    if method == reference and not sweep:
                        bar.update(1)
                        continue
                    row = _row(**base, method=method, sweep=sweep, param=param)
                    if method in over_budget and not sweep:
                        row["error"] = over_budget[method]
                        rows.append(row)
                        bar.update(1)
                        continue
                    opts = {**options.get(method, {}), **extra}
                    try:
                        if warmup and (method, sweep, param) not in warmed:
                            # Untimed first call per mesh: JIT compilation (numba), the
                            # Embree BVH and the GL upload of the mesh are one-off costs.
                            _run_once(mesh, pts, fi, camera, method, opts)
                            warmed.add((method, sweep, param))
                        mask, dt = _run_once(mesh, pts, fi, camera, method, opts)
                        row["time_s"] = dt
                        _score(row, mask, ref, pts)
                        if memory and not sweep and method not in measured_memory:
                            row["peak_mib"] = _peak_mib(mesh, pts, fi, camera, method, opts)
                            measured_memory.add(method)
                        if method_budget_s is not None and not sweep and dt > method_budget_s:
                            over_budget[method] = (
                                f"skipped: {dt:.1f} s per view at {n} points exceeded the budget of "
                                f"{method_budget_s:g} s"
                            )
                    except Exception as exc:  # noqa: BLE001 - reported in the table, not fatal
                        log.warning("compare: %s failed on %s (%d points): %s", method, name, n, exc)
                        row["error"] = f"{type(exc).__name__}: {exc}"
                    rows.append(row)
                    bar.update(1)
    bar.close()
    return rows


# =========================================================================================
# Writing
# =========================================================================================
def write_csv(rows: Sequence[dict[str, Any]], path: str | os.PathLike) -> Path:
    """Write rows with the columns of :data:`RESULT_FIELDS` (atomically) and return the path."""
    return io.write_csv(path, [{k: _fmt_csv(row.get(k, "")) for k in RESULT_FIELDS} for row in rows], RESULT_FIELDS)


def _fmt_csv(value: Any) -> Any:
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return value


_NUMERIC = {
    "n_faces": int, "n_points": int, "view": int, "n_visible": int, "n_reference_visible": int,
    "elevation_deg": float, "azimuth_deg": float, "time_s": float, "peak_mib": float, "accuracy": float,
    "false_visible_rate": float, "false_hidden_rate": float, "iou": float, "chamfer": float,
}  # fmt: skip


def read_csv(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Rows of a ``results.csv`` written by :func:`write_csv`, numbers parsed back."""
    rows = []
    with open(path, newline="") as fh:
        for raw in csv.DictReader(fh):
            row: dict[str, Any] = dict(raw)
            for key, typ in _NUMERIC.items():
                if row.get(key, "") != "":
                    row[key] = typ(float(row[key])) if typ is int else typ(row[key])
            if row.get("param", "") != "":
                row["param"] = int(row["param"])
            rows.append(row)
    return rows


def _ok(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    return [r for r in rows if not r.get("error") and r.get("time_s", "") != ""]


def summarise(
    rows: Sequence[dict[str, Any]], by: Sequence[str] = ("method", "n_points"), sweep: str = ""
) -> dict[tuple, dict[str, float]]:
    """Mean of every metric over the rows (without errors) sharing the ``by`` keys.

    Returns
    -------
    dict
        ``key tuple -> {"time_s", "accuracy", ..., "views"}`` (``views`` = number of rows).
    """
    groups: dict[tuple, list[dict[str, Any]]] = defaultdict(list)
    for r in _ok(rows):
        if r.get("sweep", "") == sweep:
            groups[tuple(r[k] for k in by)].append(r)
    out = {}
    for key, group in groups.items():
        stats = {}
        for metric in ("time_s", "accuracy", "false_visible_rate", "false_hidden_rate", "iou", "chamfer", "peak_mib"):
            values = [float(r[metric]) for r in group if r.get(metric, "") != "" and not math.isnan(float(r[metric]))]
            stats[metric] = float(np.mean(values)) if values else math.nan
        stats["views"] = len(group)
        out[key] = stats
    return out


def _f(value: float, spec: str) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else format(value, spec)


def _method_order(rows: Sequence[dict[str, Any]]) -> list[str]:
    return list(dict.fromkeys(r["method"] for r in rows if r.get("method") not in ("", "*")))


def _markdown_report(rows: Sequence[dict[str, Any]], plots: dict[str, str], title: str, command: str | None) -> str:
    methods = _method_order([r for r in rows if not r.get("sweep")])
    counts = sorted({int(r["n_points"]) for r in rows if r.get("n_points", "") != "" and not r.get("sweep")})
    meshes = list(dict.fromkeys(f"{r['mesh']} ({r['n_faces']} faces)" for r in rows if r.get("n_faces", "") != ""))
    main = summarise(rows)
    lines = [f"# {title}", ""]
    if command:
        lines += ["Produced by:", "", "```", command, "```", ""]
    n_views = len({(r["mesh"], r["view"]) for r in rows if r.get("view", "") != ""})
    lines += [
        f"Meshes: {', '.join(meshes) or '–'}; {n_views} mesh × view combinations.  Reference: exact oracle.",
        "Times are wall seconds per view (one `visible_mask` call) on this machine; agreement is the mean",
        "over meshes and views.  Rates are fractions of all points (accuracy = 1 − FV − FH).",
        "",
        "## Time per view (s)",
        "",
        "| method | " + " | ".join(f"{n:,} pts" for n in counts) + " |",
        "|---|" + "---:|" * len(counts),
    ]
    for m in methods:
        lines.append(f"| {m} | " + " | ".join(_f(main.get((m, n), {}).get("time_s", math.nan), ".4g") for n in counts) + " |")
    lines += [
        "",
        "## Agreement with the oracle",
        "",
        "| method | points | accuracy | false visible | false hidden | IoU | Chamfer | views |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for m in methods:
        for n in counts:
            s = main.get((m, n))
            if s:
                lines.append(
                    f"| {m} | {n:,} | {_f(s['accuracy'], '.4f')} | {_f(s['false_visible_rate'], '.4f')} | "
                    f"{_f(s['false_hidden_rate'], '.4f')} | {_f(s['iou'], '.4f')} | {_f(s['chamfer'], '.2e')} | {s['views']} |"
                )
    if any(r.get("peak_mib", "") != "" for r in rows):
        lines += ["", "## Peak traced memory (MiB, numpy/Python heap, first view)", "", "| method | points | peak MiB |", "|---|---:|---:|"]
        for (m, n), s in sorted(main.items(), key=lambda kv: (methods.index(kv[0][0]) if kv[0][0] in methods else 99, kv[0][1])):
            if not math.isnan(s["peak_mib"]):
                lines.append(f"| {m} | {n:,} | {s['peak_mib']:.1f} |")
    for sweep, label in (("resolution", "z-buffer resolution (px)"), ("grid", "occupancy-grid size (cells per axis)")):
        sw = summarise(rows, by=("method", "param"), sweep=sweep)
        if not sw:
            continue
        lines += ["", f"## Agreement vs {label}", "", f"| method | {sweep} | time (s) | accuracy | false visible | false hidden | IoU |", "|---|---:|---:|---:|---:|---:|---:|"]
        for (m, p), s in sorted(sw.items()):
            lines.append(
                f"| {m} | {p} | {_f(s['time_s'], '.4g')} | {_f(s['accuracy'], '.4f')} | {_f(s['false_visible_rate'], '.4f')} | "
                f"{_f(s['false_hidden_rate'], '.4f')} | {_f(s['iou'], '.4f')} |"
            )
    errors = [r for r in rows if r.get("error")]
    if errors:
        lines += ["", "## Failures and skips", "", "| mesh | points | view | method | error |", "|---|---:|---:|---|---|"]
        seen = set()
        for r in errors:
            key = (r["mesh"], r.get("n_points"), r["method"], r["error"])
            if key in seen:
                continue
            seen.add(key)
            lines.append(f"| {r['mesh']} | {r.get('n_points', '')} | {r.get('view', '')} | {r['method']} | {r['error']} |")
    if plots:
        lines += ["", "## Plots", ""]
        lines += [f"![{k}]({v})" for k, v in plots.items()]
    return "\n".join(lines) + "\n"


def _plots(rows: Sequence[dict[str, Any]], out: Path) -> dict[str, str]:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        log.warning("matplotlib is not installed (pip install 'zbuf-occlude[plot]'): no PNG plots written")
        return {}
    written: dict[str, str] = {}
    main = summarise(rows)
    methods = _method_order([r for r in rows if not r.get("sweep")])
    fig, ax = plt.subplots(figsize=(7, 5))
    for m in methods:
        pts = sorted((n, s["time_s"]) for (mm, n), s in main.items() if mm == m and not math.isnan(s["time_s"]))
        if pts:
            ax.plot(*zip(*pts), marker="o", label=m)
    ax.set(xscale="log", yscale="log", xlabel="points", ylabel="wall time per view (s)", title="Time per view vs number of points")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "time_vs_points.png", dpi=120)
    plt.close(fig)
    written["time per view vs points"] = "time_vs_points.png"
    for sweep, xlabel, fname in (
        ("resolution", "z-buffer resolution (px)", "agreement_vs_resolution.png"),
        ("grid", "occupancy grid size (cells per axis)", "agreement_vs_grid.png"),
    ):
        sw = summarise(rows, by=("method", "param"), sweep=sweep)
        if not sw:
            continue
        fig, ax = plt.subplots(figsize=(7, 5))
        for m in dict.fromkeys(k[0] for k in sw):
            series = sorted((p, s) for (mm, p), s in sw.items() if mm == m)
            x = [p for p, _ in series]
            line = ax.plot(x, [s["accuracy"] for _, s in series], marker="o", label=f"{m} accuracy")[0]
            ax.plot(x, [s["false_visible_rate"] for _, s in series], ls="--", color=line.get_color(), label=f"{m} false visible")
            ax.plot(x, [s["false_hidden_rate"] for _, s in series], ls=":", color=line.get_color(), label=f"{m} false hidden")
        ax.set(xscale="log", xlabel=xlabel, ylabel="fraction of points", title=f"Agreement with the oracle vs {sweep}")
        ax.set_xticks(sorted({k[1] for k in sw}))
        ax.get_xaxis().set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / fname, dpi=120)
        plt.close(fig)
        written[f"agreement vs {sweep}"] = fname
    return written


def write_results(
    rows: Sequence[dict[str, Any]],
    out: str | os.PathLike,
    *,
    title: str = "HSR methods compared with the exact oracle",
    command: str | None = None,
    report_name: str = "report.md",
) -> Path:
    """Write ``results.csv``, the Markdown report and the PNG plots into ``out``.

    Returns
    -------
    Path
        The report's path.

    Raises
    ------
    OutputError
        When ``out`` cannot be created or written.
    """
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create output folder {out}: {exc}") from None
    write_csv(rows, out / "results.csv")
    plots = _plots(rows, out)
    return io.write_text(out / report_name, _markdown_report(rows, plots, title, command))


# =========================================================================================
# Table 1A / 1B of the paper
# =========================================================================================
def _reduction(t_new: float, t_old: float) -> float:
    return 100.0 * (1.0 - t_new / t_old) if t_old > 0 else math.nan


def table_1a(rows: Sequence[dict[str, Any]], exact: str = "paper-exact", pruned: str = "paper-pruned") -> str:
    """Markdown: Table 1A of Sryamkin et al. 2023 reproduced, per mesh and point count.

    ``paper-exact`` vs ``paper-pruned`` mean time per view and the reduction, beside the
    paper's reported reduction, plus each method's agreement with the oracle.
    """
    s = summarise(rows, by=("mesh", "n_faces", "n_points", "method"))
    keys = sorted({k[:3] for k in s}, key=lambda k: (-int(k[1]), k[2]))
    lo, hi = PAPER_TABLE_1A_REDUCTION
    lines = [
        f"| mesh (faces) | points | views | {exact} (s) | {pruned} (s) | reduction (ours) | reduction (paper) | "
        f"{pruned} accuracy | {pruned} false hidden |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for mesh, faces, n in keys:
        e, p = s.get((mesh, faces, n, exact)), s.get((mesh, faces, n, pruned))
        if not e or not p:
            continue
        lines.append(
            f"| {mesh} ({faces}) | {n:,} | {e['views']} | {e['time_s']:.3g} | {p['time_s']:.3g} | "
            f"{_reduction(p['time_s'], e['time_s']):.1f} % | ≈55 % ({lo:g}–{hi:g} %) | {p['accuracy']:.4f} | "
            f"{p['false_hidden_rate']:.4f} |"
        )
    return "\n".join(lines) + "\n"


def table_1b(
    rows: Sequence[dict[str, Any]],
    exact: str = "paper-exact",
    methods: Sequence[str] = ("og32", "og64", "zbuffer", "oracle"),
) -> str:
    """Markdown: Table 1B of Sryamkin et al. 2023 reproduced, with the z-buffer and agreement added.

    Per mesh and point count: mean time per view of ``exact`` and of each of ``methods``,
    the reduction relative to ``exact``, and each method's accuracy against the oracle
    (which the paper did not report).
    """
    s = summarise(rows, by=("mesh", "n_faces", "n_points", "method"))
    keys = sorted({k[:3] for k in s}, key=lambda k: (-int(k[1]), k[2]))
    lo, hi = PAPER_TABLE_1B_REDUCTION
    head = f"| mesh (faces) | points | views | {exact} (s) | " + " | ".join(
        f"{m} (s) / reduction / accuracy" for m in methods
    )
    lines = [head + " | paper: OG_32/OG_64 reduction |", "|---|---:|---:|---:|" + "---:|" * len(methods) + "---:|"]
    for mesh, faces, n in keys:
        e = s.get((mesh, faces, n, exact))
        if not e:
            continue
        cells = []
        for m in methods:
            x = s.get((mesh, faces, n, m))
            cells.append(
                "–" if not x else f"{x['time_s']:.3g} / {_reduction(x['time_s'], e['time_s']):.1f} % / {x['accuracy']:.4f}"
            )
        paper = f"{lo:g}–{hi:g} %" if n >= 50_000 else "–"
        lines.append(f"| {mesh} ({faces}) | {n:,} | {e['views']} | {e['time_s']:.3g} | " + " | ".join(cells) + f" | {paper} |")
    return "\n".join(lines) + "\n"


# =========================================================================================
# The CLI face
# =========================================================================================
def run_compare(
    paths: Sequence[str | os.PathLike],
    methods: str | Sequence[str] = DEFAULT_METHODS,
    points: str | Sequence[int] = DEFAULT_POINTS,
    views: str = DEFAULT_VIEWS,
    resolution: int = 1024,
    out: str | os.PathLike = "compare_out",
    seed: int = 0,
    *,
    reference: str = DEFAULT_REFERENCE,
    resolution_sweep: str | Sequence[int] = (),
    grid_sweep: str | Sequence[int] = (),
    sweep_points: int | None = None,
    memory: bool = False,
    method_budget_s: float | None = None,
    progress: bool = True,
    command: str | None = None,
) -> Path:
    """``zbuf-occlude compare``: run :func:`compare` and :func:`write_results`; return the report path.

    Parameters
    ----------
    paths : sequence of path
        Mesh files.
    methods : str or sequence of str
        Comma-separated method names (default: :data:`DEFAULT_METHODS`).
    points : str or sequence of int
        Point counts, e.g. ``"1000,10000,50k"``.
    views : str
        Pose schedule: ``grid25`` (default), ``paper100``, ``fibonacci:N`` or ``EL:AZ,...``.
    resolution : int
        Z-buffer image size, pixels.
    out : path
        Output folder: ``results.csv``, ``report.md``, ``*.png``.
    seed : int
        Sampling seed.
    reference : str
        Method defining the truth (default ``oracle``).
    resolution_sweep, grid_sweep : str or sequence of int
        E.g. ``"128,256,512,1024,2048"`` and ``"16,32,64,128"``; empty: no sweep.
    sweep_points : int, optional
        Point count of the sweeps (default: the smallest of ``points``).
    memory : bool
        Record peak traced memory per method.
    method_budget_s : float, optional
        Skip a method at larger point counts once one view took longer than this.
    progress : bool
        Progress bar.
    command : str, optional
        The command line, quoted in the report.

    Returns
    -------
    Path
        ``out/report.md``.

    Raises
    ------
    InvalidInputError
        Bad methods, counts or views.
    OutputError
        ``out`` not writable.
    """
    rows = compare(
        paths,
        parse_methods(methods),
        parse_int_list(points, "point counts"),
        views,
        int(resolution),
        int(seed),
        reference=reference,
        resolution_sweep=parse_int_list(resolution_sweep, "resolutions"),
        grid_sweep=parse_int_list(grid_sweep, "grid sizes"),
        sweep_points=sweep_points,
        memory=memory,
        method_budget_s=method_budget_s,
        progress=progress,
    )
    return write_results(rows, out, command=command)


def _cli_compare(args: argparse.Namespace) -> int:
    import shlex
    import sys

    report = run_compare(
        args.paths,
        args.methods,
        args.points,
        args.views,
        args.resolution,
        args.out,
        args.seed,
        reference=args.reference,
        resolution_sweep=args.resolution_sweep,
        grid_sweep=args.grid_sweep,
        sweep_points=args.sweep_points,
        memory=args.memory,
        method_budget_s=args.method_budget,
        progress=not args.no_progress,
        command="zbuf-occlude " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
    )
    sys.stdout.write(f"{report}\n")  # the command's output: where the report went
    return 0


def add_compare_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``compare`` subcommand to an argparse ``subparsers``; ``func`` returns an exit code."""
    p = subparsers.add_parser(
        "compare",
        help="time every HSR method and score it against the exact oracle",
        description=(
            "For every mesh x point count x camera pose x method: wall time per view and agreement with "
            "the oracle (accuracy, false-visible and false-hidden rates, IoU, Chamfer distance). Writes "
            "results.csv, report.md and PNG plots into --out."
        ),
    )
    p.add_argument("paths", nargs="+", help="mesh files (.off, .obj, .ply, .stl, .glb) or folders (searched recursively)")
    p.add_argument("--methods", default=",".join(DEFAULT_METHODS), help="comma-separated methods (default: %(default)s)")
    p.add_argument("--points", default=",".join(str(n) for n in DEFAULT_POINTS), help="point counts (default: %(default)s)")
    p.add_argument("--views", default=DEFAULT_VIEWS, help="pose schedule: grid25, paper100, fibonacci:N or EL:AZ,... (default: %(default)s)")
    p.add_argument("--resolution", type=int, default=1024, help="z-buffer resolution in pixels (default: %(default)s)")
    p.add_argument("--out", default="compare_out", help="output folder (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="sampling seed (default: %(default)s)")
    p.add_argument("--reference", default=DEFAULT_REFERENCE, help="method that defines the truth (default: %(default)s)")
    p.add_argument("--resolution-sweep", default="", help="e.g. 128,256,512,1024,2048: agreement vs resolution")
    p.add_argument("--grid-sweep", default="", help="e.g. 16,32,64,128: agreement vs occupancy-grid size")
    p.add_argument("--sweep-points", type=int, default=None, help="point count of the sweeps (default: smallest --points)")
    p.add_argument("--memory", action="store_true", help="also record peak traced memory per method")
    p.add_argument("--method-budget", type=float, default=None, help="seconds per view after which a method is skipped at larger point counts")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=_cli_compare)
    return p
