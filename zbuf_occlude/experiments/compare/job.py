"""The whole ``zbuf-occlude compare`` run as one call: :func:`run_compare`."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.defaults import DEFAULT_RESOLUTION, DEFAULT_VIEWS
from zbuf_occlude.experiments.compare.report import compare_folder, compare_writes, write_results_into
from zbuf_occlude.experiments.compare.run import (
    DEFAULT_METHODS,
    DEFAULT_POINTS,
    DEFAULT_REFERENCE,
    compare,
    parse_int_list,
    parse_methods,
)

__all__ = ["run_compare"]


def run_compare(
    paths: Sequence[str | os.PathLike],
    methods: str | Sequence[str] = DEFAULT_METHODS,
    points: str | Sequence[int] = DEFAULT_POINTS,
    views: str = DEFAULT_VIEWS,
    resolution: int = DEFAULT_RESOLUTION,
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
    """``zbuf-occlude compare``: run :func:`compare` and write its results into ``out``; return the report path.

    ``out`` is held for the run (:func:`~zbuf_occlude.experiments.compare.report.compare_folder`) and
    every file it writes is checked before any work (:data:`~zbuf_occlude.experiments.compare.report.COMPARE_OUTPUTS`).

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
        Output folder: ``results.csv``, ``report.md``, the plots (``*.png``).
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
    UnsafePathError
        A file of a name it writes is in ``out`` and was not written by a run of ours, or was
        changed since (checked before any work; nothing is written).
    DatasetBusy
        Another live process holds ``out``.
    """
    method_list = parse_methods(methods)
    counts = parse_int_list(points, "point counts")
    resolutions, grids = parse_int_list(resolution_sweep, "resolutions"), parse_int_list(grid_sweep, "grid sizes")
    with compare_folder(out) as folder:
        sweeps = [sweep for sweep, values in (("resolution", resolutions), ("grid", grids)) if values]
        folder.check_writable(compare_writes(sweeps=sweeps))  # every file before any work: a refusal writes nothing
        rows = compare(
            paths,
            method_list,
            counts,
            views,
            int(resolution),
            int(seed),
            reference=reference,
            resolution_sweep=resolutions,
            grid_sweep=grids,
            sweep_points=sweep_points,
            memory=memory,
            method_budget_s=method_budget_s,
            progress=progress,
        )
        return write_results_into(folder, rows, command=command)
