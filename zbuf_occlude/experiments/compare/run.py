"""The comparison run: every method timed on every mesh × point count × pose and scored against the reference.

See :mod:`zbuf_occlude.experiments.compare` for the metrics.
"""

from __future__ import annotations

import logging
import math
import os
import time
import tracemalloc
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_RESOLUTION, DEFAULT_VIEWS
from zbuf_occlude.errors import InvalidInputError, ZbufOccludeError
from zbuf_occlude.experiments.compare.results import RESULT_FIELDS
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, camera_on_sphere, view_schedule
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.mesh.discovery import find_meshes
from zbuf_occlude.visibility import available_methods, visible_mask
from zbuf_occlude.visibility.metrics import agreement
from zbuf_occlude.visibility.registry import method_info

__all__ = [
    "chamfer_distance",
    "parse_methods",
    "parse_int_list",
    "compare",
    "DEFAULT_METHODS",
    "DEFAULT_POINTS",
    "DEFAULT_REFERENCE",
    "RESOLUTION_SWEEP",
    "GRID_SWEEP",
    "IMAGE_SPACE_METHODS",
    "GRID_METHODS",
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
#: Pose schedule (see :func:`zbuf_occlude.geometry.cameras.view_schedule`).
#: The method every other is scored against: exact (Embree candidates, float64 decisions).
DEFAULT_REFERENCE = "oracle"
#: Z-buffer resolutions of the agreement-vs-resolution sweep, pixels.
RESOLUTION_SWEEP = (128, 256, 512, 1024, 2048)
#: Occupancy-grid sizes of the agreement-vs-grid sweep, cells per axis.
GRID_SWEEP = (16, 32, 64, 128)
#: ``IMAGE_SPACE_METHODS``: methods with a ``resolution`` option, swept over
#: :data:`RESOLUTION_SWEEP` (the registered methods declaring ``takes_resolution``; the run asks
#: :func:`method_info`, so methods registered later are swept too).  ``GRID_METHODS``: methods
#: with a ``grid`` option (or a grid in their name), swept over :data:`GRID_SWEEP`.  Both are
#: read from the registry when first used (:func:`__getattr__`): asking it imports every built-in
#: method, with numba and moderngl, which ``zbuf-occlude --help`` must not pay for.
_METHOD_GROUPS = {
    "IMAGE_SPACE_METHODS": lambda info: info.takes_resolution,
    "GRID_METHODS": lambda info: info.takes_grid or bool(info.grid_of),
}


def __getattr__(name: str):
    if name in _METHOD_GROUPS:
        return tuple(m for m in available_methods() if _METHOD_GROUPS[name](method_info(m)))
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
#: Bytes per mebibyte, for the ``peak_mib`` column.
_MIB = float(1 << 20)


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
        if method_info(m).takes_resolution:
            jobs += [(m, "resolution", r, {"resolution": r}) for r in resolution_sweep]
    # A name that fixes the grid (og32) sweeps the method whose grid it fixes (og).
    grid_methods = [m if method_info(m).takes_grid else method_info(m).grid_of for m in methods]
    for m in dict.fromkeys(g for g in grid_methods if g):
        jobs += [(m, "grid", g, {"grid": g}) for g in grid_sweep]
    return jobs


def compare(
    paths: Sequence[str | os.PathLike],
    methods: Sequence[str] = DEFAULT_METHODS,
    points: Sequence[int] = DEFAULT_POINTS,
    views: str | Sequence[tuple[float, float]] = DEFAULT_VIEWS,
    resolution: int = DEFAULT_RESOLUTION,
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
        Progress on stderr (:func:`zbuf_occlude.io.progress.progress`).

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
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a comparison runs

    options = method_options or {}
    rows: list[dict[str, Any]] = []
    per_view = len(methods) + 1
    # folders are searched recursively, as by `generate` and `validate`; a file that does
    # not load is reported in the table like any other failure
    paths = [f for p in paths for f in ([m for m, _ in find_meshes([p])] if Path(p).is_dir() else [p])]
    total = len(paths) * sum(len(poses) * (per_view + (len(sweeps) if n == sweep_n else 0)) for n in counts)
    from zbuf_occlude.io.progress import progress as progress_bar

    bar = progress_bar(total=total, desc="compare", unit="call", enabled=progress)
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
