"""The whole ``zbuf-occlude compare`` run as one call: :func:`run_compare`."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.experiments.compare.config import CompareConfig
from zbuf_occlude.experiments.compare.report import compare_folder, compare_writes, write_results_into
from zbuf_occlude.experiments.compare.run import compare

__all__ = ["run_compare"]


def run_compare(
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike = "compare_out",
    config: CompareConfig | None = None,
    *,
    progress: bool = True,
    command: str | None = None,
) -> Path:
    """``zbuf-occlude compare``: run :func:`compare` and write its results into ``out``; return the report path.

    ``out`` is held for the run (:func:`~zbuf_occlude.experiments.compare.report.compare_folder`) and
    every file it writes is checked before any work (:data:`~zbuf_occlude.experiments.compare.report.COMPARE_OUTPUTS`).

    Parameters
    ----------
    paths : sequence of path
        Mesh files, or folders searched recursively.
    out : path
        Output folder: ``results.csv``, ``report.md``, the plots (``*.png``; a sweep's only with that sweep).
    config : CompareConfig, optional
        What is compared (:class:`~zbuf_occlude.experiments.compare.config.CompareConfig`: methods,
        point counts, poses, resolution, seed, reference, sweeps, memory, budget); default: its defaults.
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
        From the default :class:`CompareConfig` only (a config is checked when it is made).
    OutputError
        ``out`` not writable.
    UnsafePathError
        A file of a name it writes is in ``out`` and was not written by a run of ours, or was
        changed since (checked before any work; nothing is written).
    DatasetBusy
        Another live process holds ``out``.
    """
    config = config if config is not None else CompareConfig()
    with compare_folder(out) as folder:
        folder.check_writable(compare_writes(sweeps=config.sweeps))  # every file before any work: a refusal writes nothing
        rows = compare(paths, config, progress=progress)
        return write_results_into(folder, rows, command=command)
