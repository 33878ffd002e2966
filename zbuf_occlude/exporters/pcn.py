"""``export --to pcn``: the layout of PCN's completion data set (Yuan et al., "PCN: Point Completion
Network", 3DV 2018), as PCN, PoinTr (``datasets/PCNDataset.py``), SnowflakeNet and SeedFormer read it.

The source is a ``zbuf-occlude generate MESHES --protocol pcn --out DIR`` folder
(:mod:`zbuf_occlude.protocols.pcn`): ``protocol.json`` and one shard per object holding its partial
views (``partial``, ``partial_offsets``) and its complete cloud (``complete``).  A farm or generate
data set holds no complete cloud, so it is no source of this target.  The export writes:

* ``PCN.json``: a JSON list, one entry per taxonomy, ``{"taxonomy_id", "taxonomy_name", "train",
  "val", "test"}``, each split a list of model ids (``val`` is empty unless objects have the split
  ``val``; a split of another name gets a key of its own);
* ``<split>/partial/<taxonomy_id>/<model_id>/NN.pcd``: each partial view the shard holds
  (``00``, ``01``, ...; PoinTr reads 8 for ``train`` and ``00`` for ``val`` and ``test``), in
  the order PCN's ``render_depth.py`` rendered them; a view that saw nothing is an empty cloud;
* ``<split>/complete/<taxonomy_id>/<model_id>.pcd``: the complete cloud, 16,384 points unless
  ``generate --complete-points`` said otherwise (PoinTr asserts its config's ``N_POINTS``).

Each ``.pcd`` is binary, uncompressed (PoinTr's reader takes no compression), fields ``x y z``
float32 (written with pypcd4), in PCN's frame (+y up, bounding-box diagonal 1; ``up`` turns it to
another up axis).

Names:

* ``taxonomy_id``: the ShapeNet synset id when the class is one of ShapeNet-55's, by id or name
  (:func:`~zbuf_occlude.exporters.label_sets.shapenet_synset`: ``chair`` → ``03001627``, as PCN's
  own ``PCN.json``), else the class name itself (``label_set_name="shapenet55"`` refuses such a class
  instead).  Classes that give one id share its entry;
* ``taxonomy_name``: the class name (several, ``,``-joined, as ShapeNet's ``taxonomy.json`` joins
  synonyms); a class named by a bare synset id gets ShapeNet's first name for it;
* ``model_id``: the last ``/`` part of the object's name (``chair/train/chair_0001`` →
  ``chair_0001``; ShapeNetCore's ``SYNSET/MODEL_ID`` → ``MODEL_ID``).  Two objects of one taxonomy
  with the same model id are refused before anything is written.

The source is checked whole before anything is written (:func:`plan_pcn`): ``protocol.json``
read capped and inside the folder, each shard inside the folder (links resolved), a regular
file, opened by the checked HDF5 opener (no links, virtual datasets or external storage; each
dataset stores the bytes it declares), its attributes and the shapes its arrays declare those
of a pcn shard (the complete cloud as many points as the run recorded), its view offsets read
and checked, and the largest shard checked against the memory available.  Then the shards are
read one at a time.  Objects that ``generate`` could not make (no shard) are left out, with a
warning.
"""

from __future__ import annotations

import io
import itertools
import json
import logging
import os
import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from zbuf_occlude.dataset.layout import PROTOCOL_FILE
from zbuf_occlude.defaults import MAX_POINTS
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.exporters.base import ExportOptions, Target, Written, turn_up
from zbuf_occlude.exporters.label_sets import SHAPENET55, label_set, shapenet_synset
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.progress import progress
from zbuf_occlude.io.safe_paths import path_inside
from zbuf_occlude.protocols.base import open_arrays_h5, shard_name
from zbuf_occlude.protocols.pcn import COMPLETE_POINTS, HEIGHT, N_VIEWS, WIDTH
from zbuf_occlude.resources import check_memory

__all__ = [
    "ARRAYS", "CATEGORY_FILE", "FILE_NAMES", "PROTOCOL", "SUBSETS", "TARGET", "PcnModel", "PcnPlan", "pcd_bytes", "plan_pcn", "write_pcn",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The protocol whose folders this target reads.
PROTOCOL = "pcn"
#: The category file PoinTr's ``CATEGORY_FILE_PATH`` names (``data/PCN/PCN.json``).
CATEGORY_FILE = "PCN.json"
#: The splits every entry of ``PCN.json`` has, empty or not (PoinTr reads ``dc[subset]``).
SUBSETS = ("train", "val", "test")
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (re.escape(CATEGORY_FILE), r"[^/]+/partial/[^/]+/[^/]+/\d{2,}\.pcd", r"[^/]+/complete/[^/]+/[^/]+\.pcd")
#: The arrays of a shard the export reads.
ARRAYS = ("partial", "partial_offsets", "complete")
#: Most partial points a shard may declare: every pixel of every view.
MAX_PARTIAL_POINTS = N_VIEWS * WIDTH * HEIGHT
#: Bytes in memory per point of a shard while it is exported: the array as read (float64 at
#: most), its float32 copy, pypcd4's record array, the PCD's bytes and their copy.
BYTES_PER_EXPORTED_POINT = 3 * 8 + 4 * 12
#: How the command that makes a source is named in refusals.
_MAKE_SOURCE = f"run `zbuf-occlude generate MESHES --protocol {PROTOCOL} --out DIR` and export DIR"


@dataclass(frozen=True)
class PcnModel:
    """One object of the source, as the export names it.

    Attributes
    ----------
    shard : Path
        Its shard (``shards/pcn_NNNNNN.h5``).
    name : str
        Its name in the source (``chair/train/chair_0001``).
    split : str
        Its split (the folder of ``<split>/partial`` and the key of ``PCN.json``).
    taxonomy_id : str
    model_id : str
    """

    shard: Path
    name: str
    split: str
    taxonomy_id: str
    model_id: str


@dataclass(frozen=True)
class PcnPlan:
    """What :func:`write_pcn` writes, checked: the models in the source's order and each taxonomy's name.

    Attributes
    ----------
    source : Path
        The ``generate --protocol pcn`` folder.
    models : tuple of PcnModel
    taxonomy_names : dict of str to str
        ``taxonomy_name`` of each ``taxonomy_id``, in ``PCN.json``'s order (sorted by id).
    complete_points : int or None
        Points of every complete cloud, as the run recorded them (``None``: it recorded none).
    """

    source: Path
    models: tuple[PcnModel, ...]
    taxonomy_names: dict[str, str]
    complete_points: int | None = None

    @property
    def samples(self) -> dict[str, int]:
        """Models per split."""
        counts: dict[str, int] = {}
        for m in self.models:
            counts[m.split] = counts.get(m.split, 0) + 1
        return counts


def _redo(source: Path) -> str:
    return f"run `generate --protocol {PROTOCOL}` again into {source}"


def _attr(f: Any, key: str, shard: Path) -> object:
    """The scalar attribute ``key`` of an open shard (``None`` when it has none)."""
    if key not in f.attrs:
        return None
    if f.attrs.get_id(key).shape != ():  # read only once it is one value, whatever it declares
        raise DatasetFormatError(f"{shard}: the attribute {key!r} is not one value; it is not a pcn shard")
    return f.attrs[key]


def _check_declared(f: Any, shard: Path, complete_points: int | None) -> int:
    """Check the shapes and kinds the shard's arrays declare (nothing is read); return their points.

    Raises
    ------
    DatasetFormatError
        An array is missing or is not what a pcn shard holds (the message names it and its shape).
    """
    import h5py

    shapes = {}
    for key in ARRAYS:
        if f.get(key, getclass=True) is not h5py.Dataset:
            raise DatasetFormatError(f"{shard} has no array {key!r}; it is not a pcn shard")
        ds = f[key]
        kind = "iu" if key == "partial_offsets" else "f"
        if ds.dtype.kind not in kind or ds.dtype.itemsize > 8 or ds.shape is None:
            raise DatasetFormatError(f"{shard}: {key!r} holds {ds.dtype} values; it is not a pcn shard")
        shapes[key] = ds.shape
    partial, offsets, complete = (shapes[k] for k in ARRAYS)
    why = None
    if len(partial) != 2 or partial[1] != 3 or partial[0] > MAX_PARTIAL_POINTS:
        why = f"'partial' declares {partial}, where a pcn shard holds (M, 3), M <= {MAX_PARTIAL_POINTS:,} ({N_VIEWS} views of {WIDTH} x {HEIGHT})"
    elif len(offsets) != 1 or not 2 <= offsets[0] <= N_VIEWS + 1:
        why = f"'partial_offsets' declares {offsets}, where a pcn shard holds (V + 1,), V <= {N_VIEWS} views"
    elif len(complete) != 2 or complete[1] != 3 or complete[0] > MAX_POINTS:
        why = f"'complete' declares {complete}, where a pcn shard holds (C, 3), C <= {MAX_POINTS:,}"
    elif complete_points is not None and complete[0] != complete_points:
        why = f"'complete' declares {complete}, where the run recorded {complete_points:,} points"
    if why is not None:
        raise DatasetFormatError(f"{shard}: {why}; it is not a pcn shard")
    return int(partial[0]) + int(complete[0])


def _check_offsets(offsets: np.ndarray, n_partial: int, shard: Path) -> None:
    """Refuse view offsets that do not cut ``partial`` into views in order."""
    if not (offsets[0] == 0 and offsets[-1] == n_partial and np.all(np.diff(offsets) >= 0)):
        raise DatasetFormatError(
            f"{shard}: partial_offsets {offsets.tolist()} do not cut its {n_partial:,} partial points into views; it is not a pcn shard"
        )


def _check_shard(shard: Path, source: Path, complete_points: int | None) -> tuple[dict[str, object], int]:
    """One shard's attributes and points, checked (module docstring); nothing but its offsets is read."""
    with open_arrays_h5(shard, within=source) as f:
        attrs = {key: _attr(f, key, shard) for key in ("name", "class_name", "split")}
        points = _check_declared(f, shard, complete_points)
        try:
            offsets = np.asarray(f["partial_offsets"][()])
        except (OSError, ValueError) as exc:
            raise DatasetFormatError(f"cannot read {shard}: {exc}") from None
        _check_offsets(offsets, f["partial"].shape[0], shard)
    return attrs, points


def _read_record(source: Path) -> dict:
    """``source/protocol.json`` (read capped, inside ``source``), once it is a pcn run's."""
    path = source / PROTOCOL_FILE
    if not os.path.lexists(path):
        raise InvalidInputError(
            f"{source} holds no {PROTOCOL_FILE}: to='pcn' reads a `generate --protocol {PROTOCOL}` folder; {_MAKE_SOURCE}"
        )
    record = read_json_file(path, within=source)
    protocol = record.get("protocol") if isinstance(record, dict) else None
    if protocol != PROTOCOL or not isinstance(record.get("objects"), list):
        what = f"a `generate --protocol {protocol}` run" if isinstance(protocol, str) else "no protocol run of ours"
        raise InvalidInputError(f"{path} is {what}: to='pcn' reads a `generate --protocol {PROTOCOL}` folder; {_MAKE_SOURCE}")
    return record


def _complete_points(record: dict) -> int | None:
    """The complete cloud's points the run recorded (``--complete-points``, 0: the default); ``None`` if it recorded none."""
    value = record.get("complete_points")
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        return None
    return value or COMPLETE_POINTS


def _taxonomy(classes: list[str], label_set_name: str) -> dict[str, str]:
    """``taxonomy_id`` of each class (module docstring).

    Raises
    ------
    InvalidInputError
        ``label_set_name`` is ``shapenet55`` and a class is none of ShapeNet-55's, or a class name
        cannot be a folder name.
    """
    if label_set_name == "shapenet55":
        label_set("shapenet55", classes).labels(classes)  # refuses, naming them, classes ShapeNet lacks
    synsets = {c: shapenet_synset(c) for c in classes}
    ids = {c: synsets[c] or c for c in classes}
    for c, taxonomy_id in ids.items():
        if "/" in taxonomy_id or taxonomy_id in ("", ".", ".."):
            raise InvalidInputError(f"the class {c!r} cannot name a folder of PCN's layout; rename it in the mesh folder or list file")
    if other := sorted(c for c in classes if synsets[c] is None):
        log.warning(
            "classes %s are not ShapeNet's: their taxonomy_id is the class name; PoinTr's runner looks each taxonomy_id up "
            "in its data/shapenet_synset_dict.json (a KeyError at validation): add these ids there", other,
        )  # fmt: skip
    return ids


def _taxonomy_name(taxonomy_id: str, classes: list[str]) -> str:
    first_names = {synset: names[0] for synset, names in SHAPENET55}
    return ",".join(sorted(first_names[c] if c == taxonomy_id and c in first_names else c for c in classes))


def plan_pcn(source: str | os.PathLike, label_set_name: str = "own") -> PcnPlan:
    """Read and check what ``source`` (a ``generate --protocol pcn`` folder) exports to, reading
    only ``protocol.json``, the shards' attributes and their view offsets (the module docstring
    lists the checks); nothing is written.

    Parameters
    ----------
    source : str or PathLike
        The folder (``protocol.json``, ``shards/pcn_NNNNNN.h5``; :mod:`zbuf_occlude.protocols.base`).
    label_set_name : {"own", "shapenet55"}
        ``own``: a class that is not ShapeNet's keeps its name as its ``taxonomy_id``;
        ``shapenet55``: such a class is refused.

    Returns
    -------
    PcnPlan

    Raises
    ------
    InvalidInputError
        ``source`` is no pcn run (no ``protocol.json``, or another protocol's), two objects of
        one taxonomy share a model id, or a class is refused (``shapenet55``).
    DatasetFormatError
        A shard is damaged, not a regular file (a FIFO), refused by the checked HDF5 opener
        (links, virtual datasets, external storage, data it does not store), declares arrays
        that are not a pcn shard's, or is not the object ``protocol.json`` lists at its place.
    UnsafePathError
        ``protocol.json``, ``shards/`` or a shard leads outside ``source`` (a link).
    InsufficientMemoryError
        The largest shard would not fit in memory while it is exported.
    """
    source = Path(source)
    record = _read_record(source)
    objects, complete_points = record["objects"], _complete_points(record)
    found, missing, largest, largest_shard = [], 0, 0, None
    for index, entry in enumerate(objects):
        shard = path_inside(source, shard_name(PROTOCOL, index), what=f"the shard of object {index} of {source / PROTOCOL_FILE}")
        if not os.path.lexists(shard):
            missing += 1  # generate could not make it (its failures are reported there)
            continue
        attrs, points = _check_shard(shard, source, complete_points)
        if points > largest:
            largest, largest_shard = points, shard
        name, class_name, split = (attrs[k] for k in ("name", "class_name", "split"))
        listed = entry[0] if isinstance(entry, list) and entry else None
        if not all(isinstance(v, str) and v for v in (name, class_name, split)) or name != listed:
            raise DatasetFormatError(
                f"{shard} is not the object {source / PROTOCOL_FILE} lists at place {index} ({listed!r}); {_redo(source)}"
            )
        if "/" in split or split in (".", ".."):
            raise DatasetFormatError(f"{shard} has the split {split!r}, which cannot name a folder; {_redo(source)}")
        found.append((shard, name, class_name, split))
    check_memory(
        largest * BYTES_PER_EXPORTED_POINT, option=f"exporting the shard {largest_shard} ({largest:,} points)",
        hint="free memory, or run `generate --protocol pcn` with fewer --complete-points",
    )  # fmt: skip
    if missing:
        log.warning("%s: %d of %d objects have no shard (generate could not make them); they are left out", source, missing, len(objects))
    if not found:
        raise InvalidInputError(f"{source} holds no shard of {PROTOCOL_FILE}'s objects: nothing to export; {_MAKE_SOURCE}")
    ids = _taxonomy(sorted({f[2] for f in found}), label_set_name)
    models, owner = [], {}
    for shard, name, class_name, split in found:
        model = PcnModel(shard, name, split, ids[class_name], PurePosixPath(name).name)
        other = owner.setdefault((model.taxonomy_id, model.model_id), name)
        if other != name:
            raise InvalidInputError(
                f"{other!r} and {name!r} would both be model {model.model_id!r} of taxonomy {model.taxonomy_id!r} in PCN's "
                f"layout, which names a model by its file name: rename one of the meshes and run `generate --protocol {PROTOCOL}` again"
            )
        models.append(model)
    by_id: dict[str, list[str]] = {}
    for c, t in ids.items():
        by_id.setdefault(t, []).append(c)
    return PcnPlan(source, tuple(models), {t: _taxonomy_name(t, by_id[t]) for t in sorted(by_id)}, complete_points)


def _views(model: PcnModel, plan: PcnPlan) -> tuple[list[np.ndarray], np.ndarray]:
    """The partial views and the complete cloud of one shard, checked again as :func:`plan_pcn` checked
    it (the file may have changed since), then read."""
    with open_arrays_h5(model.shard, within=plan.source) as f:
        _check_declared(f, model.shard, plan.complete_points)
        try:
            partial, offsets, complete = (np.asarray(f[k][()]) for k in ARRAYS)
        except (OSError, ValueError) as exc:
            raise DatasetFormatError(f"cannot read {model.shard}: {exc}") from None
    _check_offsets(offsets, len(partial), model.shard)
    return [partial[a:b] for a, b in itertools.pairwise(offsets)], complete


def pcd_bytes(points: np.ndarray) -> bytes:
    """``points (N, 3)`` as the bytes of a binary (uncompressed) PCD file of float32 ``x y z`` (pypcd4)."""
    from pypcd4 import Encoding, PointCloud

    buffer = io.BytesIO()
    PointCloud.from_xyz_points(np.ascontiguousarray(points, dtype=np.float32)).save(buffer, encoding=Encoding.BINARY)
    return buffer.getvalue()


def write_pcn(folder: OwnedFolder, plan: PcnPlan, *, up: str = "+y", show_progress: bool = False) -> list[Path]:
    """Write ``plan``'s models in PCN's layout (module docstring), one shard read at a time.

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held (names :data:`FILE_NAMES`).
    plan : PcnPlan
        From :func:`plan_pcn`.
    up : str
        The export's up axis (:data:`~zbuf_occlude.exporters.base.UP_AXES`); the source is PCN's +y up.
    show_progress : bool
        A progress bar of the models written, on stderr.

    Returns
    -------
    list of Path
        ``PCN.json`` (the point clouds are in the folder's ledger).

    Raises
    ------
    DatasetFormatError
        A shard was changed since :func:`plan_pcn` checked it, and fails its checks now.
    UnsafePathError, OutputError
        As :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`.
    """
    folder.check_writable([CATEGORY_FILE])  # a foreign PCN.json (a clone of PoinTr ships one) is refused before any file is written
    splits = list(SUBSETS) + sorted({m.split for m in plan.models} - set(SUBSETS))
    lists = {t: {s: [] for s in splits} for t in plan.taxonomy_names}
    empty = 0
    for model in progress(plan.models, desc="export pcn", unit="model", enabled=show_progress):
        views, complete = _views(model, plan)
        for v, points in enumerate(views):
            folder.write_bytes(
                f"{model.split}/partial/{model.taxonomy_id}/{model.model_id}/{v:02d}.pcd", pcd_bytes(turn_up(points, "+y", up))
            )
            empty += not len(points)
        folder.write_bytes(f"{model.split}/complete/{model.taxonomy_id}/{model.model_id}.pcd", pcd_bytes(turn_up(complete, "+y", up)))
        lists[model.taxonomy_id][model.split].append(model.model_id)
    if empty:
        log.warning("%d partial views saw nothing and are empty clouds (PoinTr's PCN pads a view to 2,048 points with zeros)", empty)
    entries = [{"taxonomy_id": t, "taxonomy_name": name, **lists[t]} for t, name in plan.taxonomy_names.items()]
    return [folder.write_text(CATEGORY_FILE, json.dumps(entries, indent=1) + "\n")]


def _write(folder: OwnedFolder, plan: PcnPlan, options: ExportOptions) -> Written:
    return Written(write_pcn(folder, plan, up=options.up, show_progress=options.progress), plan.samples)


#: ``to="pcn"``.
TARGET = Target(
    "pcn", "PCN's completion layout, PCN.json and .pcd (PCN, PoinTr, SnowflakeNet, SeedFormer)", FILE_NAMES, plan_pcn, _write,
    up="+y", frame="PCN's (ShapeNet's alignment, bounding-box diagonal 1)", protocol=PROTOCOL,
    label_sets=("own", "shapenet55"), unit="model",
)  # fmt: skip
