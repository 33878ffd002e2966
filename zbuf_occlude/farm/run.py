"""Executors (in-process, process pool, Dask) and the farm itself: run_farm, merge_farm."""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import shutil
import sys
import time
from collections.abc import Iterator, Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from zbuf_occlude._version import install_hint
from zbuf_occlude.dataset.layout import (
    MANIFEST_FILE,
    PLAN_FILE,
    TASK_DIR,
)
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError, OutputError
from zbuf_occlude.farm.checks import (
    check_before_work,
    check_out_outside_inputs,
    check_point_set_options,
    object_size,
    prepare_out,
    storage_of,
)
from zbuf_occlude.farm.config import (
    MANIFEST_INTERVAL_S,
    FarmParams,
    RunOptions,
    record_path,
)
from zbuf_occlude.farm.options import OPTION_NAMES
from zbuf_occlude.farm.journal import (
    FarmSummary,
    check_out_layout,
    finalize,
    finished_record,
    input_root,
    manifest_lines,
    objects_of,
    plan_doc,
    portable_command,
    read_json,
    read_plan,
    relative_objects,
    remove_stale_temps,
    root_name,
    root_relative,
    skipped_inputs_doc,
    skipped_inputs_of,
)
from zbuf_occlude.farm.lifecycle import sigterm_as_interrupt
from zbuf_occlude.farm.lock import farm_lock
from zbuf_occlude.farm.ownership import check_inputs_outside_out, check_no_foreign_files, wipe_earlier_run
from zbuf_occlude.farm.pool import run_in_workers
from zbuf_occlude.farm.shards import select_shard
from zbuf_occlude.farm.worker import package_version, process_object, write_json
from zbuf_occlude.io.atomic import write_text
from zbuf_occlude.io.copies import copy_regular_file
from zbuf_occlude.io.safe_paths import path_inside
from zbuf_occlude.mesh.inputs.kinds import INPUT_KINDS
from zbuf_occlude.mesh.inputs.plan import FarmObject, scan_objects

log = logging.getLogger(__name__)


# -- executors -----------------------------------------------------------------------------
def _serial(todo: Sequence[FarmObject], params: FarmParams, out: Path, root: Path) -> Iterator[dict[str, Any]]:
    for obj in todo:
        yield process_object(obj, params, out, root)


def _dask(
    todo: Sequence[FarmObject], params: FarmParams, out: Path, root: Path, scheduler: str | None, dask_local: int | None
) -> Iterator[dict[str, Any]]:
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise BackendUnavailable(f"the Dask executor needs dask.distributed: {install_hint('dask')}") from exc
    with contextlib.ExitStack() as stack:
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler))
            except (OSError, TimeoutError) as exc:
                raise BackendUnavailable(f"cannot reach the Dask scheduler {scheduler}: {exc}") from exc
        else:
            # one thread per worker process: each process owns one GL context
            cluster = stack.enter_context(LocalCluster(n_workers=dask_local, threads_per_worker=1, processes=True, dashboard_address=None))
            client = stack.enter_context(Client(cluster))
        # a fresh token per run: a long-lived scheduler may still know the keys of an earlier run
        token = f"{params.digest()}-{os.getpid()}-{time.time_ns()}"
        futures = [
            client.submit(process_object, obj, params, str(out), str(root), key=f"zbuf-farm-{token}-{obj.index}", pure=False)
            for obj in todo
        ]
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel(futures)


# -- the farm ----------------------------------------------------------------------------------
def _check_compatible(out: Path, plan: dict[str, Any]) -> None:
    old = read_json(out / PLAN_FILE, within=out)
    if old is None:
        if (out / PLAN_FILE).exists():
            raise OutputError(f"{out / PLAN_FILE} is unreadable; use --overwrite to start over")
        return
    if old.get("params_digest") != plan["params_digest"]:
        diff = ", ".join(
            f"{OPTION_NAMES.get(k, k)} {old['params'].get(k)!r} -> {v!r}" for k, v in plan["params"].items() if old["params"].get(k) != v
        )
        raise InvalidInputError(
            f"{out} holds a run made with other parameters ({diff}; earlier -> now); use --overwrite to start over, or another --out"
        )
    if old.get("plan_digest") != plan["plan_digest"]:
        raise InvalidInputError(
            f"{out} holds a farm run over other objects ({len(old['objects'])} vs {len(plan['objects'])}: --classes, "
            "--per-class, --splits or the input changed); use --overwrite or another --out"
        )


def _estimate_bytes(params: FarmParams) -> int:
    """Bytes one object's files take, as its storage kind estimates them."""
    return storage_of(params).disk_bytes(object_size(params))


def run_farm(
    source: str | os.PathLike | Sequence[FarmObject],
    out: str | os.PathLike,
    params: FarmParams | None = None,
    options: RunOptions | None = None,
) -> FarmSummary:
    """Build (or resume) an occluded data set from many meshes.

    Parameters
    ----------
    source : str, PathLike or sequence of FarmObject
        Mesh tree, flat folder or list file (:func:`scan_objects`; point-set files among the
        meshes too, one object per cloud, seen from its points alone), or a ready plan.  The data
        set names each mesh by its path relative to the input root
        (:func:`~zbuf_occlude.farm.journal.input_root`: the folder given; for a list file, the
        deepest folder holding it and its meshes), and the root by its name (the card's
        ``source``), never by absolute paths; so are the inputs that had to be skipped (the
        card's ``skipped_inputs``; the summary keeps them as given, for the person running it).
    out : str or PathLike
        Data set folder (layout: :mod:`zbuf_occlude.dataset.reader`).
    params : FarmParams, optional
        What to render; default :class:`FarmParams` ``()`` (paper100, 10 samples of 2048
        points per pose, 32768 dense points, 512² z-buffer, seed 0, dense storage).
    options : RunOptions, optional
        How to run it (default :class:`RunOptions` ``()``: one process, the whole data set,
        a progress bar); its fields are described there.

    Returns
    -------
    FarmSummary

    Raises
    ------
    InvalidInputError
        Bad parameters or selection; ``out`` holds a run with other parameters; ``--method``
        or ``--sensor`` with point-set inputs, or an option their kind does not use (``--dense-points``,
        ``--density``, ``--resolution``: :func:`~zbuf_occlude.farm.checks.check_point_set_options`).
    OutputError
        ``out`` cannot be created or written, or the disk is full (finished objects are kept).
    BackendUnavailable
        No OpenGL 4.3 context, or Dask requested but not installed or unreachable.
    """
    t0 = time.perf_counter()
    params = params or FarmParams()
    o = options or RunOptions()
    workers, scheduler, dask_local, shard, skipped = o.workers, o.scheduler, o.dask_local, o.shard, o.skipped
    source_text, layout = o.source_text, o.layout
    if workers < 1:
        raise InvalidInputError(f"--workers must be >= 1, got {workers}")
    if scheduler and dask_local:
        raise InvalidInputError("give either --scheduler or --dask-local, not both")
    if dask_local is not None and dask_local < 1:
        raise InvalidInputError(f"--dask-local must be >= 1, got {dask_local}")
    task, n_tasks = shard
    if isinstance(source, (str, os.PathLike)):
        check_out_outside_inputs(out, [source])
        check_inputs_outside_out(out, [source])
    # before any mesh is found or loaded; the GL is checked here only when we render here, and
    # the memory only for processes of this machine (not those of a --scheduler's cluster)
    check_before_work(params, out, gl=not (scheduler or dask_local), workers=None if scheduler else dask_local or workers)
    if isinstance(source, (str, os.PathLike)):
        scan = scan_objects(
            source, classes=o.classes, per_class=o.per_class, splits=o.splits, class_from=o.class_from, kinds=INPUT_KINDS
        )  # fmt: skip
        objects, skipped = scan.objects, [*skipped, *((s.path, s.reason) for s in scan.skipped)]
        layout, inputs = scan.layout, [source]
    else:
        objects, inputs = list(source), o.inputs
        if [o.index for o in objects] != list(range(len(objects))):
            raise InvalidInputError("a ready plan must number its objects 0, 1, 2, ... in order")
    params = check_point_set_options(objects, params, o.defaults, o.set_params)  # a plan of clouds: their method, their --points
    check_inputs_outside_out(out, (o.source for o in objects))  # before anything in out is touched
    root = input_root(inputs, objects)
    objects, source_text = relative_objects(objects, root), source_text or root_name(root)
    mine = select_shard(objects, task, n_tasks)
    out = Path(out)
    check_out_layout(out)  # every write and delete below stays inside out
    with sigterm_as_interrupt(), farm_lock(out, shard):
        run = dataclasses.replace(o, source_text=source_text, layout=layout, skipped=tuple((str(p), str(r)) for p, r in skipped))
        return _run_locked(out, objects, mine, params, run, t0, root)


def _run_locked(
    out: Path, objects: list[FarmObject], mine: list[FarmObject], params: FarmParams, run: RunOptions, t0: float, root: Path
) -> FarmSummary:
    """:func:`run_farm` once the lock of ``out`` (or of this task) is held; ``root``: the input
    root the objects' sources are relative to."""
    task, n_tasks = run.shard
    workers, scheduler, dask_local, skipped = run.workers, run.scheduler, run.dask_local, run.skipped
    plan = plan_doc(objects, params, run.source_text, layout=run.layout)
    check_no_foreign_files(out, objects, params.storage)
    if run.overwrite:
        wipe_earlier_run(out, None if n_tasks == 1 else mine)
    else:
        _check_compatible(out, plan)
    if n_tasks == 1 or read_json(out / PLAN_FILE, within=out) != plan:
        # tasks of one array share plan.json; it is written once, the same for all (checked above)
        write_json(out / PLAN_FILE, plan)
    command = portable_command(run.command or sys.argv, out=out, root=root)
    recorded_skips = [(root_relative(p, root), r) for p, r in skipped]  # the data set's, relative as its sources
    write_json(
        out / TASK_DIR / f"task-{task}-of-{n_tasks}.json",
        {"shard": [task, n_tasks], "command": command, "version": package_version(),
         "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), "objects": [o.index for o in mine],
         "skipped_inputs": skipped_inputs_doc(recorded_skips)},
    )  # fmt: skip
    remove_stale_temps(out, mine, everything=n_tasks == 1)

    digest = params.digest()
    records: dict[int, dict[str, Any]] = {}
    for o in mine:
        rec = finished_record(out, o, digest)
        if rec is not None:
            records[o.index] = rec
    resumed = len(records)
    todo = [o for o in mine if o.index not in records]
    if todo:
        need, free = _estimate_bytes(params) * len(todo), shutil.disk_usage(out).free
        if need > free:
            log.warning("about %.0f MB still to write to %s but only %.0f MB free", need / 1e6, out, free / 1e6)
    log.info("%d objects in this task, %d finished earlier, %d to render", len(mine), resumed, len(todo))

    out = out.resolve()  # workers (Dask: possibly on other machines) may not share our working folder
    if scheduler or dask_local:
        records_iter = _dask(todo, params, out, root, scheduler, dask_local)
        workers_text = f"dask {scheduler or f'LocalCluster({dask_local})'}"
    elif (workers > 1 and len(todo) > 1) or (run.isolate and todo):
        records_iter = run_in_workers(todo, params, out, min(workers, len(todo)), root)
        workers_text = f"{min(workers, len(todo))} processes" if workers > 1 else "1 worker process"
    else:
        records_iter = _serial(todo, params, out, root)
        workers_text = "1 process"

    manifest = out / (MANIFEST_FILE if n_tasks == 1 else f"{TASK_DIR}/manifest-{task}-of-{n_tasks}.jsonl")
    views = 0
    peak = 0.0
    last_manifest = time.monotonic()
    from zbuf_occlude.io.progress import progress

    bar = progress(total=len(mine), initial=resumed, unit="obj", desc=run.progress_label, enabled=run.progress)
    t_render = time.perf_counter()
    try:
        for rec in records_iter:
            records[rec["object_index"]] = rec
            peak = max(peak, rec.get("peak_rss_mb", 0.0))
            if rec["status"] == "ok":
                views += len(rec["n_visible"])
            n_failed = sum(r["status"] != "ok" for r in records.values())
            rate = views / max(time.perf_counter() - t_render, 1e-9)
            bar.set_postfix(views_s=f"{rate:.1f}", failed=n_failed, refresh=False)
            bar.update(1)  # after the postfix: a line written now shows this object's
            if time.monotonic() - last_manifest > MANIFEST_INTERVAL_S:
                write_text(manifest, manifest_lines(mine, params, records))
                last_manifest = time.monotonic()
    finally:
        bar.close()
        records_iter.close()  # an interrupt in this loop stops the pool's workers now, not at garbage collection
        with contextlib.suppress(OutputError):  # a full disk must not hide the original error
            write_text(manifest, manifest_lines(mine, params, records))

    finished = False
    if n_tasks == 1:
        finalize(out, plan, records, [command], recorded_skips)
        finished = True
        if run.on_finished is not None:
            run.on_finished(out)
    else:
        log.info("task %d/%d done; run `zbuf-occlude farm-merge %s` when all %d tasks are", task, n_tasks, out, n_tasks)
    return FarmSummary.of_records(
        out, records, params, objects=len(mine), resumed=resumed, finished=finished, wall_s=time.perf_counter() - t0,
        views=views, workers=workers_text, peak_rss_mb=peak, skipped=skipped or (),
    )  # fmt: skip


def merge_farm(inputs: Sequence[str | os.PathLike], out: str | os.PathLike | None = None, *, progress: bool = True) -> FarmSummary:
    """Join the outputs of ``--shard I/N`` tasks into one finished data set.

    Parameters
    ----------
    inputs : sequence of str or PathLike
        Task output folders (the same folder for tasks that shared one ``--out``).
    out : str or PathLike, optional
        The data set folder (default: the first input).  Shards of other inputs are
        copied in (atomically); a merge can be rerun.  The card's ``skipped_inputs`` are those
        the tasks recorded (each once), and the summary's ``skipped`` too.
    progress : bool
        Progress on stderr (:func:`zbuf_occlude.io.progress.progress`): the objects read and copied.

    Raises
    ------
    InvalidInputError
        An input is not a farm output, inputs disagree on parameters or plan, or objects
        have no result yet (the message names them: rerun their tasks).
    OutputError
        ``out`` cannot be written.
    """
    t0 = time.perf_counter()
    if not inputs:
        raise InvalidInputError("farm-merge needs at least one task output folder")
    folders = [Path(p) for p in inputs]
    out = Path(out) if out is not None else folders[0]
    plans = []
    for folder in folders:
        plan = read_plan(folder)  # checked against its schema: a task folder may be crafted
        if plan is None:
            raise InvalidInputError(f"{folder} is not a farm output (no readable {PLAN_FILE})")
        plans.append(plan)
    for folder, plan in zip(folders[1:], plans[1:]):
        if (plan["params_digest"], plan["plan_digest"]) != (plans[0]["params_digest"], plans[0]["plan_digest"]):
            raise InvalidInputError(f"{folder} was made with other parameters or objects than {folders[0]}; cannot merge")
    plan = plans[0]
    prepare_out(out)
    check_out_layout(out)
    with farm_lock(out):
        return _merge_locked(folders, out, plan, progress=progress, t0=t0)


def _merge_locked(folders: list[Path], out: Path, plan: dict[str, Any], *, progress: bool, t0: float) -> FarmSummary:
    """:func:`merge_farm` once the data-set lock of ``out`` is held.

    Every input is read before anything is written: a merge that cannot finish (objects without
    a result, a damaged record) leaves ``out`` as it was.
    """
    objects = objects_of(plan)
    if out.resolve() not in {f.resolve() for f in folders}:
        check_no_foreign_files(out, objects, plan["params"].get("storage"))
        _check_compatible(out, plan)
    digest = plan["params_digest"]
    found: dict[int, tuple[Path, dict[str, Any]]] = {}
    failed: dict[int, dict[str, Any]] = {}
    commands: list[str] = []
    skipped: list[tuple[str, str]] = []  # every task scanned the same inputs: each skip once
    task_docs: list[tuple[str, dict[str, Any]]] = []
    from zbuf_occlude.io.progress import progress as progress_bar

    for folder in folders:
        for task_file in sorted((folder / TASK_DIR).glob("task-*.json")):
            doc = read_json(task_file, within=folder)
            if doc and isinstance(doc.get("command"), str) and doc["command"] not in commands:
                commands.append(doc["command"])
            skipped += [s for s in skipped_inputs_of(doc or {}) if s not in skipped]
            if doc and folder.resolve() != out.resolve():
                task_docs.append((task_file.name, doc))
        for o in progress_bar(objects, desc=f"farm-merge: read {folder.name}", unit="obj", enabled=progress, leave=False):
            if o.index in found:
                continue
            rec = finished_record(folder, o, digest)  # its files checked inside folder
            if rec is not None:
                found[o.index] = (folder, rec)
                continue
            other = read_json(record_path(folder, o.index), within=folder)
            if other and other.get("params_digest") == digest and other.get("status") == "failed":
                failed.setdefault(o.index, other)
    missing = [o for o in objects if o.index not in found and o.index not in failed]
    if missing:
        names = ", ".join(f"{o.index}:{o.name}" for o in missing[:5])
        raise InvalidInputError(
            f"{len(missing)} of {len(objects)} objects have no result yet ({names}{', ...' if len(missing) > 5 else ''}); "
            "rerun the tasks that own them (object i belongs to task i mod N), then merge again"
        )

    write_json(out / PLAN_FILE, plan)
    remove_stale_temps(out, objects, everything=True)  # dead writers' temporaries, as a run does
    for name, doc in task_docs:
        write_json(out / TASK_DIR / name, doc)
    records: dict[int, dict[str, Any]] = {}
    for index, (folder, rec) in progress_bar(sorted(found.items()), desc="farm-merge", unit="obj", enabled=progress):
        if folder.resolve() != out.resolve():
            for rel in rec["shards"]:  # the copy stays inside out
                target = path_inside(out, rel, what=f"{record_path(folder, index)} field 'shards'")
                copy_regular_file(folder / rel, target, within=folder)  # a regular file, inside its task folder
            write_json(record_path(out, index), rec)
        records[index] = rec
    for index, rec in failed.items():
        if index not in records:
            records[index] = rec
            write_json(record_path(out, index), rec)
    commands.append(portable_command(sys.argv, out=out))
    finalize(out, plan, records, commands, skipped)
    n_ok = sum(r["status"] == "ok" for r in records.values())
    return FarmSummary.of_records(
        out, records, FarmParams.from_dict(plan["params"]), objects=len(objects), resumed=n_ok, finished=True,
        wall_s=time.perf_counter() - t0, workers="merge", skipped=skipped,
    )  # fmt: skip
