"""``zbuf-occlude generate`` on the farm's engine: one worker, small defaults, npz/ply/h5 writers.

``generate`` and :func:`~zbuf_occlude.farm.run_farm` share everything but their defaults and
writers: the objects' identity keys (the path relative to the folder given, without suffix),
the recorded parameters (``plan.json``; other parameters are refused unless ``overwrite``),
the lock on ``--out``, the per-object records with SHA-256 of every file, resume, the
manifest and card, and the failure records.  Per object the worker writes

* ``npz`` / ``ply``: one file per sample, ``OUT/<name>/<stem>_vPPP_el±EEE_azAAA_sSS.<fmt>``;
* ``h5`` (the default): one PointNet-layout part per object, ``OUT/shards/<split>_<index>.h5``
  (with ``face_index``, ``radius``, ``source``, ``class_name``, ``split``), joined at the end
  into one file per split, ``OUT/occluded_train.h5`` and ``OUT/occluded_test.h5``, which
  ``train_files.txt`` and ``test_files.txt`` list (PointNet's layout).  The parts stay: they
  are what a rerun resumes from.

:class:`~zbuf_occlude.dataset.reader.OccludedDataset` reads the folder in every format.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

from zbuf_occlude.dataset.layout import CARD_FILE, file_list_name, split_file_name
from zbuf_occlude.dataset.storage import storages
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm.checks import check_out_outside_inputs, storage_of
from zbuf_occlude.farm.config import GENERATE_DEFAULTS, FarmParams, RunOptions, record_path
from zbuf_occlude.farm.journal import FarmSummary, read_json, shape_names_of, write_card
from zbuf_occlude.farm.run import run_farm
from zbuf_occlude.io.atomic import file_sha256, write_text
from zbuf_occlude.io.clouds import concat_h5
from zbuf_occlude.io.deletes import delete_own_files
from zbuf_occlude.io.safe_paths import path_inside
from zbuf_occlude.mesh.paths import SPLITS
from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS
from zbuf_occlude.mesh.inputs.plan import FarmObject, scan_inputs

__all__ = ["generate"]

log = logging.getLogger(__name__)


def _merge_h5(out: Path, objects: Sequence[FarmObject]) -> list[Path]:
    """Join the per-object parts of the finished objects into one file per split,
    ``OUT/occluded_<split>.h5``, and list it in ``OUT/<split>_files.txt`` (PointNet's layout).

    Rows keep the objects' order (the plan's), then pose-major, then sample index, as the
    reader serves them.  A split with no finished object gets an empty list and no file (one
    left by an earlier run is removed, so no stale split survives ``--overwrite``; with no
    ``objects``, as for ``--format npz|ply``, every split's file is).  Each joined file and file
    list goes into the card's ``joined_files`` with its SHA-256, which ``verify`` checks.
    """
    parts: dict[str, list[Path]] = {}
    for o in objects:
        rec = read_json(record_path(out, o.index), within=out)
        if rec and rec.get("status") == "ok":
            parts.setdefault(o.split, []).extend(
                path_inside(out, rel, what=f"{record_path(out, o.index)} field 'shards'") for rel in rec["shards"]
            )
    shape_names = shape_names_of(objects)
    written = []
    for split in sorted({*SPLITS, *(o.split for o in objects)}):
        target = out / split_file_name(split)
        if not parts.get(split):
            delete_own_files(out, [split_file_name(split)], what="an earlier run's joined file")
            if any(o.split == split for o in objects):
                write_text(out / file_list_name(split), "")
            continue
        # streamed: a split's file may be larger than the memory (one part at a time is read);
        # parts of older versions have no split column: their split is the one they are listed under
        written.append(concat_h5(target, parts[split], fill={"split": split}, attrs={"shape_names": shape_names}))
        write_text(out / file_list_name(split), f"{split_file_name(split)}\n")
    if objects:
        card = read_json(out / CARD_FILE, within=out)
        card["joined_files"] = [
            {"path": name, "sha256": file_sha256(out / name), "split": split}
            for split in sorted({o.split for o in objects})
            for name in ((split_file_name(split),) if parts.get(split) else ()) + (file_list_name(split),)
        ]
        write_card(out, card)
    return written


def generate(
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    *,
    params: FarmParams = GENERATE_DEFAULTS,
    overwrite: bool = False,
    progress: bool = True,
    command: str | None = None,
    class_from: int | None = None,
    isolate: bool = False,
    set_params: frozenset[str] | None = None,
) -> tuple[FarmSummary, list[FarmObject]]:
    """Occluded samples of a few meshes into ``out`` (``zbuf-occlude generate``).

    Parameters
    ----------
    paths : sequence of str or PathLike
        Mesh files, point-set files and folders (:func:`~zbuf_occlude.mesh.inputs.scan_inputs`;
        each cloud of a point-set file is one object, seen from its points alone); unreadable
        folders, names that are not UTF-8 and point-set files that cannot be read are skipped,
        recorded in the card and ``summary.skipped`` (exit 1).
    out : str or PathLike
        Output folder.
    params : FarmParams
        ``params.storage`` is the format: ``"h5"`` (default: one file per split,
        ``occluded_train.h5``/``occluded_test.h5``), ``"npz"`` or ``"ply"`` (one file per sample).
    overwrite : bool
        Start over instead of resuming (needed when ``out`` holds other parameters).
    progress : bool
        Progress on stderr (:func:`zbuf_occlude.io.progress.progress`): a bar on a terminal, a line
        every few seconds in a log.
    class_from : int, optional
        Take each mesh's class from this folder level above it (``--class-from``).
    isolate : bool
        Render in a worker process that a SIGTERM stops at once (:func:`~.run.run_farm`).
    set_params : frozenset of str, optional
        The ``params`` fields the user set (:attr:`~zbuf_occlude.farm.config.RunOptions.set_params`):
        point-set inputs refuse ``dense_points``, ``density`` and ``resolution`` set, and take
        their own ``n_points`` where it is not; None: the fields that differ from :data:`GENERATE_DEFAULTS`.

    Returns
    -------
    summary : FarmSummary
        ``summary.padded``: samples holding repeated points (fewer visible than
        ``params.n_points``), also in the card (``n_padded_samples``) and warned about once.
    objects : list of FarmObject
        The plan (names, sources), to report failures by file.

    Raises
    ------
    InvalidInputError
        Bad paths, clashing names, or ``out`` holds a run with other parameters.
    OutputError, BackendUnavailable
        As :func:`~zbuf_occlude.farm.run_farm` (the lock held by another run included).
    """
    kind = storage_of(params)
    if kind.written_by != "generate":
        raise InvalidInputError(f"generate writes one of {storages('generate')}, not {params.storage!r}")
    check_out_outside_inputs(out, paths)
    scan = scan_inputs(paths, class_from=class_from, kinds=INPUT_KINDS)
    objects, skipped = scan.objects, scan.skipped
    out = Path(out)
    options = RunOptions(
        workers=1, overwrite=overwrite, progress=progress, command=command,
        inputs=tuple(paths),
        on_finished=lambda folder: _merge_h5(folder, objects if kind.joins_splits else []),
        skipped=tuple((s.path, s.reason) for s in skipped), layout=scan.layout, isolate=isolate,
        progress_label="generate", defaults=GENERATE_DEFAULTS, set_params=set_params,
    )  # fmt: skip
    summary = run_farm(objects, out, params, options)
    return summary, objects
