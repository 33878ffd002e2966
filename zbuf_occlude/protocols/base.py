"""The engine every protocol runs on: objects in, one HDF5 shard per object out, then a finish step.

A protocol is a :class:`Protocol`: a function making one object's arrays (``make``) and an
optional ``finish`` that assembles the shards into the recipe's own layout.  The engine
discovers the meshes as ``generate`` does (:func:`zbuf_occlude.farm.generate.scan_paths`:
same names, labels and splits), writes ``OUT/shards/<protocol>_<index>.h5`` through the owned
folder (:meth:`~zbuf_occlude.io.owned.OwnedFolder.write`: atomic, recorded), and resumes: a
shard that exists is not redone.  The options are recorded in ``OUT/protocol.json`` with the
meshes; a rerun with other options or meshes is refused unless ``overwrite``.
"""

from __future__ import annotations

import json
import logging
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.dataset.layout import PROTOCOL_FILE
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError, ZbufOccludeError
from zbuf_occlude.geometry.samples import PROTOCOL_STREAM, derive_rng
from zbuf_occlude.farm.journal import input_root, relative_objects, root_name
from zbuf_occlude.farm.ownership import check_inputs_outside_out
from zbuf_occlude.io.atomic import atomic_h5, temp_h5
from zbuf_occlude.io.hdf5 import declared_nbytes, open_hdf5
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.mesh.inputs.plan import FarmObject, scan_paths
from zbuf_occlude.resources import check_memory

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "Protocol", "ProtocolOptions", "ProtocolRun", "run_protocol", "write_arrays_h5", "read_arrays_h5", "open_arrays_h5",
    "SHARDS_DIR", "shard_name",
]  # fmt: skip

log = logging.getLogger(__name__)

#: Folder of the per-object shards inside ``--out``.
SHARDS_DIR = "shards"


@dataclass(frozen=True)
class ProtocolOptions:
    """Options of a protocol run (each protocol reads the ones it uses and states its defaults).

    Attributes
    ----------
    severity : int or None
        ModelNet40-C's severity, 1..5.
    seed : int
        Base seed; each object's generator is ``(seed, object_key(name))``.
    n_points : int or None
        Points per cloud (None: the protocol's own).
    views : str
        Pose schedule (:func:`zbuf_occlude.geometry.cameras.view_schedule`) of the ``depth`` protocol.
    resolution : int
        Square image size of the ``depth`` protocol, pixels.
    radius : float
        Camera distance of the ``depth`` protocol, object units.
    downsample : {"random", "fps"}
        Down-sampling of back-projected clouds (:func:`zbuf_occlude.protocols.depth.downsample`).
    normals, camera_frame : bool
        Also write per-point face normals and camera-frame coordinates.
    complete_points : int
        Points of the complete cloud written beside the partial ones (0: none).
    up : {"auto", "+z", "+y", "-y", "+x", "-x", "-z"}
        The mesh files' up axis, turned to +z on loading (:func:`~zbuf_occlude.load_mesh`'s ``up``;
        ``auto``: by path and format).
    """

    severity: int | None = None
    seed: int = 0
    n_points: int | None = None
    views: str = "grid25"
    resolution: int = 256
    radius: float = 4.0
    downsample: str = "random"
    normals: bool = False
    camera_frame: bool = False
    complete_points: int = 0
    up: str = "auto"
    extra: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Protocol:
    """One recipe.

    Attributes
    ----------
    name : str
    summary : str
        One line for ``--help``.
    make : callable ``(mesh, obj, options, rng) -> dict[str, ndarray]``
        One object's arrays (``mesh`` as :func:`zbuf_occlude.load_mesh` gives it).
    finish : callable ``(folder, objects, shards, options) -> list[Path]``, optional
        Writes the recipe's own files from the shards (in plan order), each through ``folder``
        (:class:`~zbuf_occlude.io.owned.OwnedFolder`: ``folder.write(name)``).
    outputs : tuple of str
        Regular expressions of the names ``finish`` writes in ``--out`` (the only ones it may).
    run_key : callable ``(options) -> str``, optional
        For a protocol whose runs share one folder (ModelNet40-C's corruptions and severities):
        the name of a run's record (``protocol_<key>.json``) and shards (``shards/<key>_<index>.h5``),
        so that each run owns its own files; default: one run per folder, ``protocol.json``.
    check : callable ``(options) -> None``, optional
        Raises InvalidInputError naming a bad option value.
    """

    name: str
    summary: str
    make: Callable[[trimesh.Trimesh, FarmObject, ProtocolOptions, np.random.Generator], dict[str, np.ndarray]]
    finish: Callable[[OwnedFolder, list[FarmObject], list[Path], ProtocolOptions], list[Path]] | None = None
    outputs: tuple[str, ...] = ()
    run_key: Callable[[ProtocolOptions], str] | None = None
    check: Callable[[ProtocolOptions], None] | None = None


@dataclass
class ProtocolRun:
    """What :func:`run_protocol` did: shards written or resumed, failures ``(source, message)``, files of ``finish``."""

    done: int = 0
    resumed: int = 0
    failures: list[tuple[str, str]] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)

    @property
    def exit_status(self) -> int:
        return 1 if self.failures else 0


def _fill_h5(f: Any, arrays: Mapping[str, Any], attrs: Mapping[str, Any] | None) -> None:
    """Write named arrays (strings as UTF-8) and attributes into the open ``h5py.File`` ``f``."""
    import h5py

    text = h5py.string_dtype("utf-8")
    for key, value in arrays.items():
        a = np.asarray(value)
        if a.dtype.kind == "U":  # h5py writes str objects as UTF-8, not numpy's fixed-width UTF-32
            a = a.astype(object)
        f.create_dataset(key, data=a, dtype=text if a.dtype.kind == "O" else None, track_times=False)
    f.attrs.update(dict(attrs or {}))


def write_arrays_h5(path: str | os.PathLike, arrays: Mapping[str, Any], attrs: Mapping[str, Any] | None = None) -> Path:
    """Write named arrays (strings as UTF-8) to one HDF5 file, atomically (:func:`zbuf_occlude.io.atomic.atomic_h5`).

    Raises
    ------
    OutputError
        ``path`` cannot be written (its folder, a full disk).
    """
    with atomic_h5(path) as f:
        _fill_h5(f, arrays, attrs)
    return Path(path)


def open_arrays_h5(path: str | os.PathLike, *, within: str | os.PathLike | None = None) -> Any:
    """``path``, a file of :func:`write_arrays_h5`, open for reading once it is checked: a regular file
    (a FIFO would block), inside the folder ``within`` when given (links resolved), then by the checked
    HDF5 opener (:func:`~zbuf_occlude.io.hdf5.open_hdf5`: no links, virtual datasets or external
    storage; every dataset stores the bytes its shape declares).  Close it (or use ``with``).

    Raises
    ------
    DatasetFormatError
        Not a regular file, not HDF5, or refused by the checks (the message names the file).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    """
    return open_hdf5(path, within=within)


def read_arrays_h5(
    path: str | os.PathLike, *, within: str | os.PathLike | None = None, names: Sequence[str] | None = None
) -> dict[str, Any]:
    """Every dataset (strings decoded) and attribute of a file of :func:`write_arrays_h5`, opened by
    :func:`open_arrays_h5`; the bytes the datasets declare are checked against the memory available
    before any is read.

    Parameters
    ----------
    path : str or PathLike
    within : str or PathLike, optional
        The folder ``path`` was found in: it must stay inside it, links resolved.
    names : sequence of str, optional
        Only these datasets (each must be there); default: every one at the file's root.

    Returns
    -------
    dict
        Each dataset's array by name, and ``"attrs"``: the file's attributes.

    Raises
    ------
    DatasetFormatError
        The file is damaged, not HDF5, refused by :func:`open_arrays_h5`, or lacks one of ``names``
        (the message names it).
    UnsafePathError
        ``within`` is given and ``path`` leads outside it.
    InsufficientMemoryError
        The datasets declare more bytes than the memory available.
    """
    import h5py

    with open_arrays_h5(path, within=within) as f:
        try:
            datasets = [k for k in f if f.get(k, getclass=True) is h5py.Dataset]
            keys = datasets if names is None else list(names)
            missing = [k for k in keys if k not in datasets]
            if missing:
                raise DatasetFormatError(f"{path} has no dataset {', '.join(map(repr, missing))}; it is not a shard of ours")
            declared = sum(declared_nbytes(f[k]) for k in keys)
            check_memory(declared, option=f"reading {path} ({declared:,} bytes declared)", hint="it is no shard a protocol run writes")
            out: dict[str, Any] = {k: (f[k].asstr()[()] if f[k].dtype.kind == "O" else f[k][()]) for k in keys}
            out["attrs"] = dict(f.attrs)
        except ZbufOccludeError:
            raise
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise DatasetFormatError(f"cannot read {path}: {exc}") from None
    return out


#: What a protocol's name may be: it becomes part of its shards' file names.
_PROTOCOL_NAME = r"[a-z0-9][a-z0-9-]*"
#: The shards of any protocol run, as the folder's ledger names them.
_SHARD_NAMES = rf"{SHARDS_DIR}/{_PROTOCOL_NAME}_\d{{6}}\.h5"


#: A run's record: ``protocol.json``, or ``protocol_<key>.json`` for a protocol whose runs share a folder.
_RECORD_NAMES = rf"protocol(_{_PROTOCOL_NAME})?\.json"


def shard_name(key: str, index: int) -> str:
    """The shard of object ``index`` of run ``key`` (the protocol's name, or its ``run_key``), relative to ``--out``."""
    return f"{SHARDS_DIR}/{key}_{index:06d}.h5"


def _run_shards(key: str) -> str:
    """The names (a regular expression, relative to ``--out``) of run ``key``'s shards (:func:`shard_name`)."""
    return rf"{SHARDS_DIR}/{re.escape(key)}_\d{{6}}\.h5"


def _run_key(protocol: Protocol, options: ProtocolOptions) -> str:
    """What names a run's record and shards: the protocol's name, or its ``run_key`` (several runs, one folder)."""
    return protocol.name if protocol.run_key is None else protocol.run_key(options)


def _record_name(protocol: Protocol, key: str) -> str:
    return PROTOCOL_FILE if key == protocol.name else f"protocol_{key}.json"


def _owned(out: Path, protocol: Protocol) -> OwnedFolder:
    """``out`` as a protocol run owns it: the runs' records, the shards, and the files ``finish`` writes."""
    return OwnedFolder(
        out, names=[_RECORD_NAMES, _SHARD_NAMES, *protocol.outputs], subfolders=[SHARDS_DIR], what=f"the {protocol.name} run",
    )  # fmt: skip


def _read_record(path: Path) -> dict[str, Any]:
    """A run's record, checked to be ours.

    Raises
    ------
    InvalidInputError
        It is not JSON, or not a record of ours (its protocol name could not name a shard).
    """
    try:
        old = read_json_file(path, within=path.parent)
    except InvalidInputError as exc:
        old = exc
    if (
        not isinstance(old, dict) or not isinstance(old.get("protocol"), str) or not isinstance(old.get("objects"), list)
        or not re.fullmatch(_PROTOCOL_NAME, old["protocol"])
    ):  # fmt: skip
        raise InvalidInputError(f"{path} was not written by zbuf_occlude; move it away, or choose another --out")
    return old


def _earlier_options(folder: OwnedFolder, protocol: Protocol, key: str) -> dict[str, Any] | None:
    """The options an earlier run of ``key`` recorded in the folder (``None`` when there is none).

    A run of an earlier version kept no ledger: its ``protocol.json``, its shards (by the names
    its own record gives, checked against the shard pattern) and the files of ``finish`` are
    recorded as they are.

    Raises
    ------
    InvalidInputError
        A record exists but is not ours, or ``shards/`` holds files and no record says they are
        ours: a run would replace or delete them.
    """
    out = folder.root
    legacy, shards = out / PROTOCOL_FILE, out / SHARDS_DIR
    if os.path.lexists(legacy) and not os.path.lexists(folder.ledger_path):
        old = _read_record(legacy)
        earlier = [shard_name(old["protocol"], i) for i in range(len(old["objects"]))]
        outputs = [p.name for p in out.iterdir() if any(re.fullmatch(rx, p.name) for rx in protocol.outputs)]
        folder.adopt([PROTOCOL_FILE, *earlier, *outputs])
    path = out / _record_name(protocol, key)
    if os.path.lexists(path):
        return _read_record(path)
    if os.path.lexists(shards) and not shards.is_dir():
        raise InvalidInputError(f"{shards} is not a folder; a run writes its shards there: move it away, or choose another --out")
    ours = re.compile(_run_shards(key))
    recorded = set(folder.written())
    # a shard of this run's name that nothing records, or anything in shards/ of a folder that holds no run of ours
    foreign = [
        p for p in (sorted(shards.iterdir()) if shards.is_dir() else [])
        if (rel := f"{SHARDS_DIR}/{p.name}") not in recorded and (ours.fullmatch(rel) or not recorded)
    ]  # fmt: skip
    if foreign:
        raise InvalidInputError(
            f"{foreign[0]} was not written by zbuf_occlude ({out} holds no record of it: no {path.name}), and a run "
            "would replace or delete it: move it away, or choose an empty --out"
        )
    return None


def _record_options(
    folder: OwnedFolder, protocol: Protocol, options: ProtocolOptions, objects: Sequence[FarmObject], root: Path, overwrite: bool
) -> list[FarmObject]:
    """Write the run's record (``protocol.json``, or ``protocol_<run>.json``: :func:`_record_name`): the options and the meshes, each named relative to the input root
    ``root`` (which is named by its name only); refuse an earlier run's other options or meshes.
    Returns ``objects`` as the outputs name them (:func:`~zbuf_occlude.farm.journal.relative_objects`)."""
    out = folder.root
    key = _run_key(protocol, options)
    record = _record_name(protocol, key)
    named = relative_objects(objects, root)
    recorded = {"protocol": protocol.name, **asdict(options)}
    recorded["extra"] = dict(options.extra)
    # shards are named by plan index: another set of meshes must not resume from them
    recorded["objects"] = [[o.name, o.source] for o in named]
    recorded["source"] = root_name(root)
    old = _earlier_options(folder, protocol, key)
    if old is not None and not overwrite and old != json.loads(json.dumps(recorded)) and old != _as_written_before(recorded, objects):
        raise InvalidInputError(f"{out} holds a run with other options or meshes ({out / record}); use --overwrite or another --out")
    if old is not None and overwrite:  # this run's shards as the ledger records them, checked; nothing else
        folder.delete(folder.written(_run_shards(key)))
    for path in sorted(out.iterdir()):  # before any work: finish would refuse to replace them at the end
        if any(re.fullmatch(rx, path.name) for rx in protocol.outputs) and not folder.check_unchanged(path.name):
            raise InvalidInputError(
                f"{path} was not written by a run of ours (or was changed since), and this run would replace it: "
                "move it away, or choose another --out"
            )
    folder.write_text(record, json.dumps(recorded, indent=1, sort_keys=True) + "\n")
    return named


def _as_written_before(recorded: dict[str, Any], objects: Sequence[FarmObject]) -> dict[str, Any]:
    """``recorded`` as earlier versions wrote it (each mesh by the path it was found at, no
    ``source``): their runs resume rather than being refused."""
    before = {k: v for k, v in recorded.items() if k != "source"}
    before["objects"] = [[o.name, o.source] for o in objects]
    return json.loads(json.dumps(before))


def run_protocol(
    protocol: Protocol,
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike,
    options: ProtocolOptions = ProtocolOptions(),
    *,
    overwrite: bool = False,
    progress: bool = True,
) -> ProtocolRun:
    """Run ``protocol`` over the meshes under ``paths`` into ``out``.

    Per object: :func:`~zbuf_occlude.load_mesh` (``options.up``), the generator ``(seed, object_key(name), 2)``
    (:func:`~zbuf_occlude.geometry.samples.derive_rng`), ``protocol.make``, one shard.  A mesh that fails
    (unreadable, nothing in view) is recorded and skipped (exit status 1); then ``finish``.

    Raises
    ------
    InvalidInputError
        A bad option (``protocol.check``), bad paths, or ``out`` holds other options or meshes.
    OutputError
        ``out`` cannot be written.
    """
    if protocol.check is not None:
        protocol.check(options)
    objects, skipped = scan_paths(paths)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InvalidInputError(f"--out {out} exists and is not a folder")
    check_inputs_outside_out(out, (*paths, *(o.source for o in objects)))  # before anything in out is touched
    with _owned(out, protocol) as folder:
        return _run_owned(protocol, folder, objects, skipped, paths, options, overwrite=overwrite, progress=progress)


def _run_owned(
    protocol: Protocol,
    folder: OwnedFolder,
    objects: list[FarmObject],
    skipped: Sequence[Any],
    paths: Sequence[str | os.PathLike],
    options: ProtocolOptions,
    *,
    overwrite: bool,
    progress: bool,
) -> ProtocolRun:
    """:func:`run_protocol` once ``--out`` is held."""
    out = folder.root
    # what the outputs write: each mesh relative to the input root, no absolute path of the author's
    named = _record_options(folder, protocol, options, objects, input_root(paths, objects), overwrite)
    run = ProtocolRun(failures=[(s.path, s.reason) for s in skipped])
    shards: list[Path] = []
    key = _run_key(protocol, options)
    from zbuf_occlude.io.progress import progress as progress_bar

    for found, obj in progress_bar(list(zip(objects, named)), desc=protocol.name, unit="obj", enabled=progress):
        rel = shard_name(key, obj.index)
        shard = out / rel
        if folder.holds(rel):
            run.resumed += 1
            shards.append(shard)
            continue
        try:
            from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a protocol runs

            mesh = load_mesh(found.source, up=options.up)
            rng = derive_rng(options.seed, obj.key, PROTOCOL_STREAM)
            arrays = protocol.make(mesh, obj, options, rng)
        except ZbufOccludeError as exc:
            run.failures.append((found.source, str(exc)))
            log.warning("%s: %s", found.source, exc)
            continue
        attrs = {"protocol": protocol.name, "name": obj.name, "source": obj.source, "class_name": obj.class_name,
                 "split": obj.split, "label": obj.label, "object_index": obj.index}  # fmt: skip
        with folder.write(rel) as tmp, temp_h5(tmp) as f:
            _fill_h5(f, arrays, attrs)
        run.done += 1
        shards.append(shard)
    if protocol.finish is not None and shards:
        done = {int(p.stem.rsplit("_", 1)[1]) for p in shards}
        run.files = protocol.finish(folder, [o for o in named if o.index in done], shards, options)
    return run
