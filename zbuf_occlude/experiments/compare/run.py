"""The comparison run: every method timed on every mesh × point count × pose and scored against the reference.

See :mod:`zbuf_occlude.experiments.compare` for the metrics.
"""

from __future__ import annotations

import logging
import math
import os
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import ZbufOccludeError
from zbuf_occlude.experiments.compare.config import CompareConfig
from zbuf_occlude.experiments.compare.results import RESULT_FIELDS
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.mesh.inputs.discovery import find_meshes
from zbuf_occlude.visibility import available_methods, visible_mask
from zbuf_occlude.visibility.metrics import agreement
from zbuf_occlude.visibility.registry import method_info

__all__ = ["chamfer_distance", "compare", "RESOLUTION_SWEEP", "GRID_SWEEP", "IMAGE_SPACE_METHODS", "GRID_METHODS"]  # noqa: F822 (module __getattr__)

log = logging.getLogger(__name__)

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


class _View(NamedTuple):
    """The inputs of one timed call but the method: the mesh, its samples and their faces, a camera."""

    mesh: Any
    points: NDArray[np.float64]
    face_index: NDArray[np.int64]
    camera: Any


def _run_once(view: _View, method: str, options: dict) -> tuple[NDArray[np.bool_], float]:
    start = time.perf_counter()
    mask = visible_mask(view.mesh, view.points, view.camera, method, face_index=view.face_index, **options)
    return np.asarray(mask, dtype=bool), time.perf_counter() - start


def _peak_mib(view: _View, method: str, options: dict) -> float:
    # tracemalloc sees numpy's and Python's allocations (not Embree's, OpenGL's or numba's
    # thread stacks); run untimed, after the timed call, so tracing never slows a timing.
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        visible_mask(view.mesh, view.points, view.camera, method, face_index=view.face_index, **options)
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


#: One call of a comparison but the reference: method, sweep (``""``, ``"resolution"`` or ``"grid"``),
#: the swept value (``""`` when none) and the keywords it adds.
_Job = tuple[str, str, Any, dict]


def _sweep_jobs(methods: Sequence[str], resolution_sweep: Sequence[int], grid_sweep: Sequence[int]) -> list[_Job]:
    jobs = []
    for m in methods:
        if method_info(m).takes_resolution:
            jobs += [(m, "resolution", r, {"resolution": r}) for r in resolution_sweep]
    # A name that fixes the grid (og32) sweeps the method whose grid it fixes (og).
    grid_methods = [m if method_info(m).takes_grid else method_info(m).grid_of for m in methods]
    for m in dict.fromkeys(g for g in grid_methods if g):
        jobs += [(m, "grid", g, {"grid": g}) for g in grid_sweep]
    return jobs


@dataclass(frozen=True)
class _Plan:
    """What runs on every mesh: the point counts (the sweeps' count added when it is not asked
    for), the count the sweeps run at, and the calls at each count."""

    config: CompareConfig
    counts: list[int]
    sweep_n: int
    sweeps: list[_Job]

    @classmethod
    def of(cls, config: CompareConfig) -> _Plan:
        counts = list(config.points)
        sweep_n = config.sweep_points if config.sweep_points is not None else min(counts)
        if sweep_n not in counts:
            counts = sorted(set(counts) | {sweep_n})
        return cls(config, counts, sweep_n, _sweep_jobs(config.methods, config.resolution_sweep, config.grid_sweep))

    def jobs(self, n: int) -> list[_Job]:
        """The calls at ``n`` points but the reference's (only the sweeps at a count added for them)."""
        if n not in self.config.points:
            return self.sweeps
        return [(m, "", "", {}) for m in self.config.methods] + (self.sweeps if n == self.sweep_n else [])

    def calls_per_mesh(self) -> int:
        per_view = len(self.config.methods) + 1
        return sum(len(self.config.poses) * (per_view + (len(self.sweeps) if n == self.sweep_n else 0)) for n in self.counts)


@dataclass
class _MeshState:
    """What the run on one mesh remembers: the methods over budget (and why), the calls warmed up,
    the methods whose memory was measured at the current point count."""

    over_budget: dict[str, str] = field(default_factory=dict)
    warmed: set[tuple[str, str, Any]] = field(default_factory=set)
    measured_memory: set[str] = field(default_factory=set)


def _method_row(view: _View, job: _Job, ref: NDArray[np.bool_], base: dict[str, Any], config: CompareConfig, state: _MeshState
                ) -> dict[str, Any]:  # fmt: skip
    """The row of one method (or sweep value) on one view, scored against the reference's mask ``ref``."""
    method, sweep, param, extra = job
    row = _row(**base, method=method, sweep=sweep, param=param)
    if method in state.over_budget and not sweep:
        row["error"] = state.over_budget[method]
        return row
    opts = {**config.method_options.get(method, {}), **extra}
    try:
        if config.warmup and (method, sweep, param) not in state.warmed:
            # Untimed first call per mesh: JIT compilation (numba), the
            # Embree BVH and the GL upload of the mesh are one-off costs.
            _run_once(view, method, opts)
            state.warmed.add((method, sweep, param))
        mask, dt = _run_once(view, method, opts)
        row["time_s"] = dt
        _score(row, mask, ref, view.points)
        if config.memory and not sweep and method not in state.measured_memory:
            row["peak_mib"] = _peak_mib(view, method, opts)
            state.measured_memory.add(method)
        if config.method_budget_s is not None and not sweep and dt > config.method_budget_s:
            state.over_budget[method] = (
                f"skipped: {dt:.1f} s per view at {base['n_points']} points exceeded the budget of {config.method_budget_s:g} s"
            )
    except Exception as exc:  # noqa: BLE001 - reported in the table, not fatal
        log.warning("compare: %s failed on %s (%d points): %s", method, base["mesh"], base["n_points"], exc)
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _compare_mesh(mesh: Any, name: str, plan: _Plan, bar: Any) -> list[dict[str, Any]]:
    """Every row of one loaded mesh: per point count and view, the reference's, then each job's."""
    config, reference = plan.config, plan.config.reference
    ref_options = config.method_options.get(reference, {})
    rows: list[dict[str, Any]] = []
    state = _MeshState()
    for n in sorted(plan.counts):
        pts, fi = sample_surface(mesh, count=n, seed=config.seed)
        jobs = plan.jobs(n)
        state.measured_memory = set()
        for v, (el, az) in enumerate(config.poses):
            view = _View(mesh, pts, fi, camera_on_sphere(el, az, config.radius, resolution=config.resolution))
            base = dict(mesh=name, n_faces=len(mesh.faces), n_points=n, view=v, elevation_deg=el, azimuth_deg=az)
            try:
                if config.warmup and v == 0 and n == min(plan.counts):
                    _run_once(view, reference, ref_options)
                ref, ref_time = _run_once(view, reference, ref_options)
            except Exception as exc:  # noqa: BLE001 - reported in the table, not fatal
                log.warning("compare: reference %s failed on %s: %s", reference, name, exc)
                rows.append(_row(**base, method=reference, error=f"reference failed: {exc}"))
                bar.update(1 + len(jobs))
                continue
            row = _row(**base, method=reference, time_s=ref_time)
            _score(row, ref, ref, pts)
            rows.append(row)
            bar.update(1)
            for job in jobs:
                if job[0] != reference or job[1]:  # the reference itself is its row above
                    rows.append(_method_row(view, job, ref, base, config, state))
                bar.update(1)
    return rows


def compare(paths: Sequence[str | os.PathLike], config: CompareConfig | None = None, *, progress: bool = True) -> list[dict[str, Any]]:
    """Time every method and score it against the reference, mesh × points × view.

    Parameters
    ----------
    paths : sequence of path
        Mesh files (normalised by :func:`zbuf_occlude.load_mesh`), or folders, searched
        recursively; a file that does not load is reported in the rows (``method="*"``).
    config : CompareConfig, optional
        The methods, point counts, poses, reference, sweeps and options
        (:class:`~zbuf_occlude.experiments.compare.config.CompareConfig`, checked when made);
        default: its defaults.
    progress : bool
        Progress on stderr (:func:`zbuf_occlude.io.progress.progress`).

    Returns
    -------
    rows : list of dict
        One per (mesh, points, view, method[, sweep value]) with the keys of
        :data:`RESULT_FIELDS`; metrics are floats (``time_s``: wall seconds per view; ``chamfer``:
        object units), ``error`` is empty on success.  A method that raises is recorded in its
        row's ``error`` and the run goes on.

    Raises
    ------
    InvalidInputError
        From the default :class:`CompareConfig` only (a config is checked when it is made).
    """
    from zbuf_occlude.io.progress import progress as progress_bar
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a comparison runs

    plan = _Plan.of(config if config is not None else CompareConfig())
    # folders are searched recursively, as by `generate` and `validate`; a file that does
    # not load is reported in the table like any other failure
    paths = [f for p in paths for f in ([m for m, _ in find_meshes([p])] if Path(p).is_dir() else [p])]
    bar = progress_bar(total=len(paths) * plan.calls_per_mesh(), desc="compare", unit="call", enabled=progress)
    rows: list[dict[str, Any]] = []
    for path in paths:
        name = Path(path).stem
        try:
            mesh = load_mesh(path)
        except ZbufOccludeError as exc:
            log.warning("compare: %s", exc)
            rows.append(_row(mesh=name, method="*", error=str(exc)))
            bar.update(plan.calls_per_mesh())
            continue
        rows += _compare_mesh(mesh, name, plan, bar)
    bar.close()
    return rows
