"""``zbuf-occlude generate`` on the farm's engine: one worker, small defaults, npz/ply/h5 writers.

``generate`` and :func:`~zbuf_occlude.farm.run_farm` share everything but their defaults and
writers: the objects' identity keys (the path relative to the folder given, without suffix),
the recorded parameters (``plan.json``; other parameters are refused unless ``overwrite``),
the lock on ``--out``, the per-object records with SHA-256 of every file, resume, the
manifest and card, and the failure records.  Per object the worker writes

* ``npz`` / ``ply``: one file per sample, ``OUT/<name>/<stem>_vPPP_el±EEE_azAAA_sSS.<fmt>``;
* ``h5``: one PointNet-layout part per object, ``OUT/shards/<split>_<index>.h5`` (with
  ``face_index``, ``radius``, ``source``, ``class_name``), joined at the end into
  ``OUT/occluded.h5``.  The parts stay: they are what a rerun resumes from (and
  :class:`~zbuf_occlude.dataset.OccludedDataset` reads the folder like a farm data set).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..defaults import DEFAULT_DENSE_POINTS, DEFAULT_N_POINTS, DEFAULT_RESOLUTION, DEFAULT_SAMPLES_PER_VIEW, DEFAULT_VIEWS
from ..discovery import SkippedInput, class_and_split, scan_meshes
from ..errors import InvalidInputError
from ..io import clouds_of_h5, read_h5, write_h5
from ..layout import GENERATE_STORAGES, MERGED_H5_FILE
from ..occlude import OccludedCloud
from .config import FarmParams, record_path
from .inputs import FarmObject, number_objects
from .journal import FarmSummary, read_json, shape_names_of
from .run import run_farm

__all__ = ["generate", "scan_paths", "objects_from_paths", "MERGED_H5_FILE", "GENERATE_DEFAULTS"]

log = logging.getLogger(__name__)

#: ``generate``'s defaults, smaller poses and larger images than the farm's (one machine, a few meshes):
#: the 5×5 grid of poses, 2048-point samples, 10 per pose, 100,000 dense points, a 1024² z-buffer.
GENERATE_DEFAULTS = FarmParams(
    views=DEFAULT_VIEWS, samples_per_view=DEFAULT_SAMPLES_PER_VIEW, n_points=DEFAULT_N_POINTS,
    dense_points=DEFAULT_DENSE_POINTS, resolution=DEFAULT_RESOLUTION, storage="npz",
)  # fmt: skip


def scan_paths(paths: Sequence[str | os.PathLike]) -> tuple[list[FarmObject], list[SkippedInput]]:
    """The plan of ``generate``: mesh files and folders (searched recursively), numbered,
    and the inputs that had to be skipped.

    Each object's name is its path relative to the folder given (a file given alone: its
    stem), without the suffix; class and split come from the path
    (:func:`~zbuf_occlude.mesh.class_and_split`); labels number the class names
    (:func:`~zbuf_occlude.farm.inputs.number_objects`, as the farm does).

    Returns
    -------
    objects : list of FarmObject
    skipped : list of SkippedInput
        Unreadable folders and files whose names are not UTF-8
        (:func:`~zbuf_occlude.discovery.scan_meshes`); the run records them and exits 1.

    Raises
    ------
    InvalidInputError
        A path is missing, nothing was found, or two files have one name
        (``chair_0001.off`` and ``chair_0001.obj``): the name seeds the samples and names the
        outputs, so one would overwrite the other.
    """
    found, skipped = scan_meshes(paths)
    objects = number_objects([(name, str(path), *class_and_split(path)) for path, name in found])
    return objects, skipped


def objects_from_paths(paths: Sequence[str | os.PathLike]) -> list[FarmObject]:
    """:func:`scan_paths` without the skipped inputs (each was logged as a warning)."""
    return scan_paths(paths)[0]


def _merge_h5(out: Path, objects: Sequence[FarmObject]) -> Path | None:
    """Join the per-object parts of the finished objects into ``OUT/occluded.h5``."""
    parts = []
    for o in objects:
        rec = read_json(record_path(out, o.index))
        if rec and rec.get("status") == "ok":
            parts.extend(out / rel for rel in rec["shards"])
    if not parts:
        return None
    clouds: list[OccludedCloud] = []
    columns: dict[str, list[np.ndarray]] = {"object_index": [], "pose_index": []}
    n_points = 0
    for part in parts:
        d = read_h5(part)
        n_points = d["data"].shape[1]
        for key in columns:
            columns[key].append(d[key])
        clouds.extend(clouds_of_h5(d))
    return write_h5(
        out / MERGED_H5_FILE, clouds, shape_names=shape_names_of(objects), n_points=n_points,
        columns={k: np.concatenate(v) for k, v in columns.items()},
    )  # fmt: skip


def generate(
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    params: FarmParams = GENERATE_DEFAULTS,
    overwrite: bool = False,
    progress: bool = True,
    command: str | None = None,
    isolate: bool = False,
) -> tuple[FarmSummary, list[FarmObject]]:
    """Occluded samples of a few meshes into ``out`` (``zbuf-occlude generate``).

    Parameters
    ----------
    paths : sequence of str or PathLike
        Mesh files and folders (:func:`scan_paths`); unreadable folders and names that
        are not UTF-8 are skipped, recorded in the card and ``summary.skipped`` (exit 1).
    out : str or PathLike
        Output folder.
    params : FarmParams
        ``params.storage`` is the format: ``"npz"``, ``"ply"`` or ``"h5"``.
    overwrite : bool
        Start over instead of resuming (needed when ``out`` holds other parameters).
    progress : bool
        tqdm bar on stderr.
    isolate : bool
        Render in a worker process that a SIGTERM stops at once (:func:`~.run.run_farm`).

    Returns
    -------
    summary : FarmSummary
    objects : list of FarmObject
        The plan (names, sources), to report failures by file.

    Raises
    ------
    InvalidInputError
        Bad paths, clashing names, or ``out`` holds a run with other parameters.
    OutputError, BackendUnavailable
        As :func:`~zbuf_occlude.farm.run_farm` (the lock held by another run included).
    """
    if params.storage not in GENERATE_STORAGES:
        raise InvalidInputError(f"generate writes one of {GENERATE_STORAGES}, not {params.storage!r}")
    objects, skipped = scan_paths(paths)
    out = Path(out)
    summary = run_farm(
        objects, out, params=params, workers=1, overwrite=overwrite, progress=progress, command=command,
        source_text=", ".join(str(Path(p).resolve()) for p in paths),
        on_finished=(lambda folder: _merge_h5(folder, objects)) if params.storage == "h5" else None,
        skipped=[(s.path, s.reason) for s in skipped], isolate=isolate,
    )  # fmt: skip
    return summary, objects
