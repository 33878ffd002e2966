"""The farm's journal, manifest, file lists and data-set card, and the run summary."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from zbuf_occlude.dataset.layout import (
    CARD_FILE,
    CARD_SHA256_FILE,
    FORMAT_VERSION,
    LOCK_FILE,
    MANIFEST_FILE,
    PLAN_FILE,
    RECORD_DIR,
    SHAPE_NAMES_FILE,
    SHARD_DIR,
    TASK_DIR,
    file_list_name,
    split_file_name,
)
from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.farm.config import BYTES_PER_MB, FarmParams, plan_digest, record_path, shard_path
from zbuf_occlude.farm.worker import base_record, package_version, write_json
from zbuf_occlude.geometry.samples import count_padded
from zbuf_occlude.io.atomic import file_sha256, size_mismatch, write_text
from zbuf_occlude.io.json_files import loads_json, read_json_file
from zbuf_occlude.io.deletes import delete_own_files, remove_dead_temps
from zbuf_occlude.io.owned import check_layout
from zbuf_occlude.io.caps import MAX_METADATA_BYTES
from zbuf_occlude.io.regular_files import read_text_file
from zbuf_occlude.io.safe_paths import check_line_text, check_relative_name, path_inside
from zbuf_occlude.mesh.paths import SPLITS, printable_path
from zbuf_occlude.mesh.inputs.plan import FarmObject

log = logging.getLogger(__name__)


# -- journal, manifest, card -------------------------------------------------------------------
def check_out_layout(out: Path) -> None:
    """Check that every folder and file the farm writes or deletes directly under ``out`` stays inside it.

    The one check behind every write and delete of a run, ``generate``, ``--overwrite``
    (:func:`~zbuf_occlude.farm.ownership.wipe_earlier_run`) and ``farm-merge``: ``shards/``, ``records/``,
    ``tasks/`` (locks included), the plan, card, manifest, class names, file lists, joined
    files and the lock, once symlinks are resolved (:func:`~zbuf_occlude.io.owned.check_layout`).
    Files named by records (generate's ``npz``/``ply`` samples) are checked where they are
    written or deleted.  A symlink to elsewhere is refused, not followed: ``OUT/shards`` linked
    to another folder would have the run overwrite, or ``--overwrite`` delete, the files there.

    Raises
    ------
    UnsafePathError
        One of them leads outside ``out`` (the message names it and where it leads).
    """
    names = (SHARD_DIR, RECORD_DIR, TASK_DIR, PLAN_FILE, CARD_FILE, CARD_SHA256_FILE, MANIFEST_FILE, SHAPE_NAMES_FILE, LOCK_FILE)
    check_layout(out, (*names, *map(file_list_name, SPLITS), *map(split_file_name, SPLITS)))


def read_json(path: Path, *, within: Path) -> dict[str, Any] | None:
    """A JSON object of the journal (plan, record, task, card) in the folder ``within``; ``None`` if
    missing, damaged, not an object, not a regular file (a FIFO), larger than
    :data:`~zbuf_occlude.io.caps.MAX_METADATA_BYTES` or a link out of ``within``."""
    try:
        doc = read_json_file(path, within=within)
    except (OSError, InvalidInputError):  # nested too deep, not JSON, a FIFO, a link out: damaged, as far as the journal goes
        return None
    return doc if isinstance(doc, dict) else None


def read_plan(folder: Path) -> dict[str, Any] | None:
    """``folder/plan.json`` checked against :class:`~zbuf_occlude.dataset.schema.Plan`; ``None`` if there is none.

    Raises
    ------
    InvalidInputError
        The plan is not a regular file (a FIFO), is larger than
        :data:`~zbuf_occlude.io.caps.MAX_METADATA_BYTES`, is not UTF-8 JSON, a field is
        missing or mistyped, or its parameters are not a farm's.
    UnsafePathError
        The plan is a link that leads outside ``folder``.
    """
    from pydantic import ValidationError

    from zbuf_occlude.dataset.schema import Plan, describe_validation_error

    path = folder / PLAN_FILE
    if not path.exists():
        return None
    text = read_text_file(path, within=folder, max_bytes=MAX_METADATA_BYTES)
    try:
        Plan.model_validate_json(text)
    except ValidationError as exc:
        raise InvalidInputError(f"{path} is not a farm plan: {describe_validation_error(exc)}") from None
    plan = loads_json(text, what=str(path))
    try:
        FarmParams.from_dict(plan["params"])
    except TypeError as exc:
        raise InvalidInputError(f"{path}: field 'params' is not a farm's parameters ({exc})") from None
    return plan


def finished_record(out: Path, obj: FarmObject, digest: str) -> dict[str, Any] | None:
    """The record of ``obj`` if it finished (ok, same parameters, shard present and whole).

    Raises
    ------
    UnsafePathError
        The record names a file outside ``out`` (absolute, ``..``, through a symlink).
    """
    where = record_path(out, obj.index)
    rec = read_json(where, within=out)
    if not isinstance(rec, dict) or rec.get("params_digest") != digest or rec.get("name") != obj.name:
        return None
    if rec.get("status") != "ok" or not isinstance(rec.get("shards"), list) or not isinstance(rec.get("bytes"), int):
        return None
    files = [path_inside(out, rel, what=f"{where} field 'shards'") for rel in rec["shards"]]
    if size_mismatch(files, rec["bytes"]) is not None:  # before a byte is read
        return None
    # a shard rewritten in place keeps its size: compare the bytes (records of older
    # versions carry no digest and are trusted on their size)
    for rel, digest in zip(rec["shards"], rec.get("sha256") or ()):
        if file_sha256(out / rel) != digest:
            log.warning("%s does not match its SHA-256 in %s: redoing %s", out / rel, record_path(out, obj.index), obj.name)
            return None
    return rec


def remove_stale_temps(out: Path, objects: Sequence[FarmObject], everything: bool) -> int:
    """Remove the temporary files that dead writers left in ``out``; return how many.

    :func:`~zbuf_occlude.io.atomic.atomic_path` leaves ``.<name>.<pid>-<host>-<random>.tmp`` behind
    when a run is SIGKILLed mid-write.  Only temps of dead processes on this host go
    (:func:`~zbuf_occlude.io.deletes.remove_dead_temps`), in every folder a run writes into
    (``shards/``, ``records/``, ``tasks/``, ``--out`` and ``generate``'s per-mesh folders), and a
    sharded task (``everything=False``) touches only those of its own objects: other tasks may
    be writing theirs right now.  Call it while holding the lock
    (:func:`~zbuf_occlude.farm.lock.farm_lock`).
    """
    names = None if everything else {Path(shard_path(o)).name for o in objects} | {f"{o.index:06d}.json" for o in objects}
    removed = sum(remove_dead_temps(out / folder, names) for folder in (SHARD_DIR, RECORD_DIR))
    # --out itself may hold the user's files: only temporaries that name their (dead) writer
    removed += remove_dead_temps(out, names, ours=lambda name: True)
    if everything:
        removed += remove_dead_temps(out / TASK_DIR)
    for o in objects:  # generate --format npz|ply: an object's sample files are all its own
        try:  # a name that cannot be a folder inside out ("..") is refused where its object is made
            check_relative_name(o.name, what="a mesh's name")
            if (out / o.name).is_dir():  # one stat an object; only generate's sample files make these folders
                removed += remove_dead_temps(path_inside(out, o.name, what=f"the folder of object {o.index}"))
        except UnsafePathError:
            continue
    return removed


def input_root(inputs: Iterable[str | os.PathLike], objects: Sequence[FarmObject]) -> Path:
    """The input root: the folder a data set names its meshes relative to.

    The deepest folder holding every input given (a folder: itself; a mesh or list file: the
    folder holding it) and every object's mesh.  A folder given alone is the root, however
    deep its meshes lie; a list file's root is its folder, or the folder above both it and
    meshes it names elsewhere; several inputs: the deepest folder holding them all; a ready
    plan given without its inputs: the deepest folder holding its meshes.  Paths are made
    absolute and ``..`` removed, symlinks are not resolved.

    Returns
    -------
    Path
        Absolute (the working folder when there is neither an input nor an object).
    """
    folders = [os.path.abspath(p) if os.path.isdir(p) else os.path.dirname(os.path.abspath(p)) for p in inputs]
    folders += [os.path.dirname(os.path.abspath(o.source)) for o in objects]
    return Path(os.path.commonpath(folders)) if folders else Path.cwd()


def root_relative(path: str | os.PathLike, root: Path) -> str:
    """``path`` relative to ``root`` (:func:`input_root`), POSIX and printable: how a data set names
    a file it was given, so that it holds no absolute path of its author's.

    Parameters
    ----------
    path : str or PathLike
        A mesh, folder or list-file line; relative paths are taken from the working folder.
        Bytes that are not UTF-8 may be raw or already printable (``\\xNN``,
        :func:`~zbuf_occlude.mesh.inputs.discovery.printable_path`): both give the same text.
    root : Path
        The input root, absolute.

    Returns
    -------
    str
        E.g. ``"chair/train/chair_0001.off"``; ``"."`` for the root itself, ``"../x"`` for a path
        outside it (a list file may name inputs anywhere).
    """
    return Path(os.path.relpath(printable_path(os.path.abspath(path)), printable_path(root))).as_posix()


def relative_objects(objects: Sequence[FarmObject], root: Path) -> list[FarmObject]:
    """``objects`` with each ``source`` relative to ``root`` (:func:`root_relative`): what the plan,
    the records and the shards write."""
    return [dataclasses.replace(o, source=root_relative(o.source, root)) for o in objects]


def root_name(root: Path) -> str:
    """What the plan and the card call the input root (their ``source``): its name, never its path."""
    return root.name or root.anchor  # the file system's root has no name


def portable_command(argv: str | Sequence[str], *, out: Path, root: Path | None = None) -> str:
    """A command line as a data set records it (the card's ``commands``): each argument that
    names a path is written without the author's folders, so the record reveals nothing of the
    machine and is the same wherever the data set was built.

    An argument names a path when it is absolute or names something that exists (relative to
    the working folder); ``--option=value`` is read as its value.  Such a path is written as
    ``out``'s name (and the path below it) when it lies in ``out``, else as ``root``'s name
    (:func:`root_name`) and the path below it when it lies in the input root, else as its file
    name alone (a sensor file, a program).  Other arguments are kept as typed.

    Parameters
    ----------
    argv : str or sequence of str
        The command line, the program first (``["zbuf-occlude", "farm", ...]``); a text is split
        as a shell would (one that cannot be, such as one with an unclosed quote, at white space).
    out : Path
        The data set's folder.
    root : Path, optional
        The input root (:func:`input_root`); None for a merge, which has none.

    Returns
    -------
    str
        The command, shell-quoted (:func:`shlex.join`).
    """
    import shlex

    if isinstance(argv, str):
        try:
            argv = shlex.split(argv)
        except ValueError:  # an unclosed quote: its words, so that each path is still rewritten
            argv = argv.split()
    bases = [Path(os.path.abspath(base)) for base in (out, root) if base is not None]

    def portable(arg: str) -> str:
        if not arg or not (os.path.isabs(arg) or os.path.lexists(arg)):
            return arg
        for base in bases:
            rel = root_relative(arg, base)
            if rel != ".." and not rel.startswith("../"):
                return printable_path(Path(root_name(base), rel).as_posix())
        path = Path(os.path.abspath(arg))
        return printable_path(path.name or path.anchor)

    words = []
    for arg in argv:
        option, eq, value = arg.partition("=")
        words.append(f"{option}={portable(value)}" if eq and option.startswith("-") else portable(arg))
    return shlex.join(words)


def plan_doc(objects: Sequence[FarmObject], params: FarmParams, source: str, layout: str | None = None) -> dict[str, Any]:
    """The plan of a run (``plan.json``); class names that would break ``shape_names.txt`` are refused here, before any work.

    ``layout`` says how classes and splits were found (zbuf_occlude.mesh.inputs.layouts), for the card.
    """
    shape_names_of(objects)
    return {
        "format_version": FORMAT_VERSION,
        "params": params.to_dict(),
        "params_digest": params.digest(),
        "plan_digest": plan_digest(objects),
        "source": source,
        "layout": layout,
        "objects": [plan_object(o) for o in objects],
    }


def plan_object(obj: FarmObject) -> dict[str, Any]:
    """One object as the plan records it: its fields, ``cloud`` only for a point-set input (a
    mesh's entry is the same as before point sets were taken)."""
    doc = dataclasses.asdict(obj)
    if doc.get("cloud") is None:
        doc.pop("cloud", None)
    return doc


def objects_of(plan: dict[str, Any]) -> list[FarmObject]:
    """The objects of a plan (``plan.json``); a damaged plan raises InvalidInputError."""
    try:
        objects = [FarmObject(**o) for o in plan["objects"]]
    except (KeyError, TypeError) as exc:
        raise InvalidInputError(f"{PLAN_FILE} is damaged ({type(exc).__name__}: {exc}); rerun the farm command") from None
    if not all(isinstance(o.index, int) and isinstance(o.split, str) for o in objects):
        raise InvalidInputError(f"{PLAN_FILE} is damaged (an object's index is not an integer or its split not a string)")
    return objects


def shape_names_of(objects: Sequence[FarmObject]) -> list[str]:
    """Class names by label (line i of ``shape_names.txt`` is label i).

    Raises
    ------
    InvalidInputError
        A label with two names, or a class name with a control character (``\n``,
        ``\x85``, ...), which would break the one-name-per-line file.
    """
    names: dict[int, str] = {}
    for o in objects:
        check_line_text(o.class_name, what=f"{o.source!r}: class name")
        if names.setdefault(o.label, o.class_name) != o.class_name:
            raise InvalidInputError(f"label {o.label} is used by classes {names[o.label]!r} and {o.class_name!r}")
    return [names.get(i, f"unused_{i}") for i in range(max(names) + 1)] if names else []


def manifest_lines(objects: Sequence[FarmObject], params: FarmParams, records: dict[int, dict[str, Any]]) -> str:
    return "".join(json.dumps(records.get(o.index) or base_record(o, params), sort_keys=True) + "\n" for o in objects)


def padded_samples(records: Sequence[dict[str, Any]], params: FarmParams) -> int:
    """Samples of the finished ``records`` padded with repeated points (fewer visible than ``--points``)."""
    per_pose = 1 if params.sensor else params.samples_per_view  # --sensor: one sample per scan
    return sum(count_padded(r["n_visible"], params.n_points, per_pose) for r in records if r["status"] == "ok")


def up_axes(records: Sequence[dict[str, Any]]) -> dict[str, int]:
    """``{"+y (ShapeNetCore layout (+Y up))": n, ...}`` over ``records`` that say their up axis."""
    counts: dict[str, int] = {}
    for r in records:
        if r.get("up"):
            key = f"{r['up']} ({r.get('up_source', '?')})"
            counts[key] = counts.get(key, 0) + 1
    return dict(sorted(counts.items()))


def folder_bytes(out: Path) -> int:
    return sum(p.stat().st_size for p in out.rglob("*") if p.is_file())


def finalize(
    out: Path,
    plan: dict[str, Any],
    records: dict[int, dict[str, Any]],
    commands: list[str],
    skipped: Sequence[tuple[str, str]] = (),
) -> None:
    """Write manifest, shape names, file lists and (last: it marks the data set finished) the card.

    ``skipped``: ``(path, reason)`` of inputs discovery could not take (unreadable folders,
    names that are not UTF-8), each path relative to the input root (:func:`root_relative`),
    recorded in the card as ``skipped_inputs`` (:func:`skipped_inputs_doc`).
    """
    from zbuf_occlude.dataset.schema import CHECKSUM_ALGORITHM

    objects = objects_of(plan)
    params = FarmParams.from_dict(plan["params"])
    write_text(out / MANIFEST_FILE, manifest_lines(objects, params, records))
    shape_names = shape_names_of(objects)
    write_text(out / SHAPE_NAMES_FILE, "".join(f"{n}\n" for n in shape_names))
    splits = sorted({o.split for o in objects}, key=lambda s: (s not in SPLITS, s))
    for split in splits:
        ok_in_split = [o for o in objects if o.split == split and records[o.index]["status"] == "ok"]
        shards = [s for o in ok_in_split for s in records[o.index]["shards"]]
        # the split comes from the plan (a task folder's, for farm-merge): the list must stay inside out
        write_text(path_inside(out, file_list_name(split), what=f"{PLAN_FILE} split"), "".join(f"{s}\n" for s in shards))
    ok = [r for r in records.values() if r["status"] == "ok"]
    every_file_hashed = all(len(r.get("sha256") or ()) == len(r["shards"]) for r in ok)
    n_samples = int(sum(r["n_samples"] for r in ok))
    n_padded = padded_samples(ok, params)
    if n_padded:
        # a sensor's scan has the points its beams return; a pose already took the top-up (geometry.samples.top_up)
        remedy = "move the sensor closer or lower --points" if params.sensor else "lower --points: topped up, still too few"
        shares = sorted({o.kind.visible_share for o in objects if not o.kind.topped_up and o.kind.visible_share})
        if shares:  # a cloud has no faces to top up on: a pose sees the measured share of it
            remedy = (f"lower --points: a point-set file's cloud is not topped up, and a pose sees about "
                      f"{round(100 * shares[0])} % of it (of a 2,048-point cloud, about {round(2048 * shares[0])} points)")  # fmt: skip
        log.warning(
            "%d of %d samples hold repeated points: fewer than --points %d points were visible from their poses "
            "(each sample's n_visible says how many; %s); recorded as n_padded_samples in %s",
            n_padded, n_samples, params.n_points, remedy, out / CARD_FILE,
        )  # fmt: skip
    card = {
        "format_version": FORMAT_VERSION,
        "tool": "zbuf_occlude",
        "version": package_version(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "commands": commands,
        "source": plan["source"],
        "layout": plan.get("layout"),
        "storage": params.storage,
        "params": params.to_dict(),
        "params_digest": plan["params_digest"],
        "plan_digest": plan["plan_digest"],
        "poses": [list(p) for p in params.poses],
        "splits": splits,
        "shape_names": shape_names,
        "n_objects": len(objects),
        "n_objects_ok": len(ok),
        "n_objects_failed": len(objects) - len(ok),
        "skipped_inputs": skipped_inputs_doc(skipped),
        "up": params.up,
        # how many objects were read with each up axis, and why (ShapeNetCore layout, glTF, as stored...)
        "up_axes": up_axes(ok),
        "n_samples": n_samples,
        "n_padded_samples": n_padded,
        "shard_bytes": int(sum(r["bytes"] for r in ok)),
        # point-set inputs: where visibility came from and how their objects were made (absent for meshes only)
        **point_set_card(objects, ok),
        # the reader refuses a manifest without them (unless verify=False): removing them cannot hide a change
        "checksums": CHECKSUM_ALGORITHM if every_file_hashed else None,
        "renderers": sorted({r["renderer"] for r in ok if r.get("renderer")}),
        "seed_derivation": "numpy SeedSequence([seed, blake2b64(name), stream, pose_index, sample_index]), "
        "zbuf_occlude.geometry.samples.derive_rng; stream 0 = dense cloud, 1 = sample draws, "
        "3 = top-up candidates (pose_index, round)",
        "reference": "Sryamkin, Msallam, Klestov 2023, A method to create real-like point clouds for 3D object classification",
    }
    write_card(out, card)


def point_set_card(objects: Sequence[FarmObject], ok: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """The card's ``visibility_from`` and ``point_sets`` (:class:`~zbuf_occlude.dataset.schema.PointSetCard`)
    of a plan that holds clouds of point-set files; ``{}`` for a plan of meshes only.

    ``visibility_from`` is ``"points"`` when every object is a cloud, ``"points and meshes"``
    when some are; ``point_sets`` counts them and those of them (finished) whose file gave normals,
    and states the method, its settings, the dense cloud and ``face_index``.  Each object's record
    says the same of it (``visibility``, ``visibility_from``, ``normals``).
    """
    from zbuf_occlude.defaults import DEFAULT_POINT_NEIGHBOURS, DEFAULT_SPLAT_SCALE, DEFAULT_SPLAT_TOLERANCE
    from zbuf_occlude.mesh.inputs.kinds import POINT_SET
    from zbuf_occlude.pipeline import NO_FACE

    n_clouds = sum(o.kind is POINT_SET for o in objects)
    if not n_clouds:
        return {}
    return {
        "visibility_from": "points" if n_clouds == len(objects) else "points and meshes",
        "point_sets": {
            "n_objects": n_clouds,
            "n_with_normals": sum(bool(r.get("normals")) for r in ok if r.get("visibility_from") == "points"),
            "visibility": POINT_SET.method,
            "settings": {"neighbours": DEFAULT_POINT_NEIGHBOURS, "splat_scale": DEFAULT_SPLAT_SCALE, "tolerance": DEFAULT_SPLAT_TOLERANCE},
            "dense_cloud": "the cloud's own points, normalised as a mesh (bounding-box centre at 0, largest side 1); "
            "nothing sampled, nothing topped up; normals from the file where it has them, else estimated",
            "face_index": NO_FACE,
        },
    }


def skipped_inputs_doc(skipped: Iterable[tuple[str, str]]) -> list[dict[str, str]]:
    """``skipped`` (``(path, reason)`` pairs) as the card and a task's file record them:
    ``[{"path": ..., "reason": ...}, ...]``."""
    return [{"path": p, "reason": r} for p, r in skipped]


def skipped_inputs_of(doc: dict[str, Any]) -> list[tuple[str, str]]:
    """The ``(path, reason)`` pairs of a task file's ``skipped_inputs`` (:func:`skipped_inputs_doc`);
    entries that are not two strings (a damaged or older file) are left out."""
    items = doc.get("skipped_inputs")
    return [
        (i["path"], i["reason"]) for i in items if isinstance(i, dict) and isinstance(i.get("path"), str) and isinstance(i.get("reason"), str)
    ] if isinstance(items, list) else []  # fmt: skip


def write_card(out: Path, card: dict[str, Any]) -> None:
    """Write the card, then its SHA-256 file (:data:`~zbuf_occlude.dataset.layout.CARD_SHA256_FILE`).

    The old SHA-256 file goes first: a run stopped in between leaves a card without one
    (read like an older data set), never one with a stale checksum.
    """
    from zbuf_occlude.dataset.schema import card_sha256_line

    delete_own_files(out, [CARD_SHA256_FILE], what="the card's checksum")
    write_json(out / CARD_FILE, card)
    write_text(out / CARD_SHA256_FILE, card_sha256_line(file_sha256(out / CARD_FILE)))


# -- summary -------------------------------------------------------------------------------------
@dataclass
class FarmSummary:
    """What a farm run (or merge) did; :meth:`format` is the one-screen report the CLI prints."""

    out: str
    objects: int
    done: int
    failed: int
    resumed: int
    samples: int
    bytes: int
    wall_s: float
    views: int
    storage: str
    finished: bool
    workers: str = "1 process"
    peak_rss_mb: float = 0.0
    failures: list[tuple[str, str]] = field(default_factory=list)
    #: ``(path, reason)`` of inputs that could not even be planned (unreadable folder, non-UTF-8 name):
    #: paths as given to a run, relative to the input root in a merge (as its tasks recorded them).
    skipped: list[tuple[str, str]] = field(default_factory=list)
    #: Samples holding repeated points because fewer than ``n_points`` were visible (the card's ``n_padded_samples``).
    padded: int = 0

    @classmethod
    def of_records(
        cls,
        out: Path,
        records: dict[int, dict[str, Any]],
        params: FarmParams,
        *,
        objects: int,
        resumed: int,
        finished: bool,
        wall_s: float,
        views: int = 0,
        workers: str = "1 process",
        peak_rss_mb: float = 0.0,
        skipped: Sequence[tuple[str, str]] = (),
    ) -> FarmSummary:
        """The summary of ``records`` (object index → record), the one place a run and a merge
        count samples, padded samples, failures and bytes (a finished data set: its folder;
        a task's part: its records' bytes)."""
        ok = [r for r in records.values() if r["status"] == "ok"]
        return cls(
            out=str(out),
            objects=objects,
            done=len(ok),
            failed=len(records) - len(ok),
            resumed=resumed,
            samples=int(sum(r["n_samples"] for r in ok)),
            padded=padded_samples(ok, params),
            bytes=folder_bytes(out) if finished else int(sum(r["bytes"] for r in ok)),
            wall_s=wall_s,
            views=views,
            storage=params.storage,
            finished=finished,
            workers=workers,
            peak_rss_mb=peak_rss_mb,
            failures=[(r["name"], r["error"]) for r in records.values() if r["status"] != "ok"],
            skipped=list(skipped),
        )

    @property
    def exit_status(self) -> int:
        """0 if every input was done, 1 if some failed or were skipped (the CLI's status)."""
        return 1 if self.failed or self.skipped else 0

    @property
    def samples_per_mb(self) -> float:
        return self.samples / (self.bytes / BYTES_PER_MB) if self.bytes else 0.0

    @property
    def views_per_s(self) -> float:
        return self.views / self.wall_s if self.wall_s > 0 else 0.0

    def format(self) -> str:
        """Multi-line human summary."""
        lines = [
            f"zbuf-occlude farm: {self.out}  ({'finished' if self.finished else 'this task done; run farm-merge when all tasks are'})",
            f"  objects   {self.done} done ({self.resumed} from an earlier run), {self.failed} failed, {self.objects} planned",
            f"  samples   {self.samples:,}  ({self.storage} storage)"
            + (f", {self.padded:,} padded with repeated points" if self.padded else ""),
            f"  bytes     {self.bytes:,} ({self.bytes / BYTES_PER_MB:.1f} MB)  ->  {self.samples_per_mb:,.1f} samples/MB",
            f"  wall      {self.wall_s:.1f} s, {self.views} views rendered, {self.views_per_s:.1f} views/s, "
            f"{self.workers}, peak RSS per worker {self.peak_rss_mb:.0f} MB",
        ]
        for name, error in self.failures[:10]:
            lines.append(f"  FAILED    {name}: {error}")
        for path, reason in self.skipped[:10]:
            lines.append(f"  SKIPPED   {path}: {reason}")
        if len(self.failures) > 10:
            lines.append(f"  ... and {len(self.failures) - 10} more failures (see {MANIFEST_FILE})")
        return "\n".join(lines)
