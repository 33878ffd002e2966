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
float32 (written with pypcd4), in PCN's frame (y up, bounding-box diagonal 1).

Names:

* ``taxonomy_id``: the ShapeNet synset id when the class is one of ShapeNet-55's, by id or name
  (:func:`~zbuf_occlude.exporters.label_sets.shapenet_synset`: ``chair`` → ``03001627``, as PCN's
  own ``PCN.json``), else the class name itself (``--label-set shapenet55`` refuses such a class
  instead).  Classes that give one id share its entry;
* ``taxonomy_name``: the class name (several, ``,``-joined, as ShapeNet's ``taxonomy.json`` joins
  synonyms); a class named by a bare synset id gets ShapeNet's first name for it;
* ``model_id``: the last ``/`` part of the object's name (``chair/train/chair_0001`` →
  ``chair_0001``; ShapeNetCore's ``SYNSET/MODEL_ID`` → ``MODEL_ID``).  Two objects of one taxonomy
  with the same model id are refused before anything is written.

The source is read one object at a time: a first pass over the shards' attributes (names, classes,
splits, checked), then one shard at a time.  Objects that ``generate`` could not make (no shard)
are left out, with a warning.
"""

from __future__ import annotations

import json
import logging
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np

from zbuf_occlude.dataset.layout import PROTOCOL_FILE
from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.exporters.label_sets import SHAPENET55, label_set, shapenet_synset
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.io.owned import OwnedFolder, remove_empty_folders
from zbuf_occlude.protocols.base import read_arrays_h5, shard_name

__all__ = ["CATEGORY_FILE", "FILE_NAMES", "PROTOCOL", "SUBSETS", "PcnModel", "PcnPlan", "plan_pcn", "write_pcn"]

log = logging.getLogger(__name__)

#: The protocol whose folders this target reads.
PROTOCOL = "pcn"
#: The category file PoinTr's ``CATEGORY_FILE_PATH`` names (``data/PCN/PCN.json``).
CATEGORY_FILE = "PCN.json"
#: The splits every entry of ``PCN.json`` has, empty or not (PoinTr reads ``dc[subset]``).
SUBSETS = ("train", "val", "test")
#: The names this target writes (regular expressions, for the owned folder).
FILE_NAMES = (re.escape(CATEGORY_FILE), r"[^/]+/partial/[^/]+/[^/]+/\d{2,}\.pcd", r"[^/]+/complete/[^/]+/[^/]+\.pcd")
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
    """

    source: Path
    models: tuple[PcnModel, ...]
    taxonomy_names: dict[str, str]

    @property
    def samples(self) -> dict[str, int]:
        """Models per split."""
        counts: dict[str, int] = {}
        for m in self.models:
            counts[m.split] = counts.get(m.split, 0) + 1
        return counts


def _shard_attrs(path: Path) -> Mapping[str, object]:
    """The attributes of one shard, without reading its arrays (the plan's pass)."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return dict(f.attrs)
    except (OSError, ValueError) as exc:
        raise DatasetFormatError(f"cannot read {path}: {exc}; run `generate --protocol {PROTOCOL}` again into that folder") from None


def _read_record(source: Path) -> list:
    """The objects ``source/protocol.json`` lists, once it is a pcn run's."""
    path = source / PROTOCOL_FILE
    if not path.is_file():
        raise InvalidInputError(
            f"{source} holds no {PROTOCOL_FILE}: export --to pcn reads a `generate --protocol {PROTOCOL}` folder; {_MAKE_SOURCE}"
        )
    record = read_json_file(path)
    protocol = record.get("protocol") if isinstance(record, dict) else None
    if protocol != PROTOCOL or not isinstance(record.get("objects"), list):
        what = f"a `generate --protocol {protocol}` run" if isinstance(protocol, str) else "no protocol run of ours"
        raise InvalidInputError(f"{path} is {what}: export --to pcn reads a `generate --protocol {PROTOCOL}` folder; {_MAKE_SOURCE}")
    return record["objects"]


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
    first_names = dict((synset, names[0]) for synset, names in SHAPENET55)
    return ",".join(sorted(first_names[c] if c == taxonomy_id and c in first_names else c for c in classes))


def plan_pcn(source: str | os.PathLike, label_set_name: str = "own") -> PcnPlan:
    """Read and check what ``source`` (a ``generate --protocol pcn`` folder) exports to, reading
    only ``protocol.json`` and the shards' attributes; nothing is written.

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
        A shard is damaged or is not the object ``protocol.json`` lists at its place.
    """
    source = Path(source)
    objects = _read_record(source)
    found, missing = [], 0
    for index, entry in enumerate(objects):
        shard = source / shard_name(PROTOCOL, index)
        if not shard.is_file():
            missing += 1  # generate could not make it (its failures are reported there)
            continue
        attrs = _shard_attrs(shard)
        name, class_name, split = (attrs.get(k) for k in ("name", "class_name", "split"))
        listed = entry[0] if isinstance(entry, list) and entry else None
        if not all(isinstance(v, str) and v for v in (name, class_name, split)) or name != listed:
            raise DatasetFormatError(
                f"{shard} is not the object {source / PROTOCOL_FILE} lists at place {index} ({listed!r}); "
                f"run `generate --protocol {PROTOCOL}` again into that folder"
            )
        if "/" in split or split in (".", ".."):
            raise DatasetFormatError(f"{shard} has the split {split!r}, which cannot name a folder; run `generate` again into that folder")
        found.append((shard, name, class_name, split))
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
    return PcnPlan(source, tuple(models), {t: _taxonomy_name(t, by_id[t]) for t in sorted(by_id)})


def _views(arrays: Mapping[str, np.ndarray], shard: Path) -> tuple[list[np.ndarray], np.ndarray]:
    """The partial views and the complete cloud of one shard, checked."""
    try:
        partial, offsets, complete = (np.asarray(arrays[k]) for k in ("partial", "partial_offsets", "complete"))
    except KeyError as exc:
        raise DatasetFormatError(f"{shard} has no array {exc}; run `generate --protocol {PROTOCOL}` again into that folder") from None
    ok = (
        partial.ndim == 2 and partial.shape[1] == 3 and complete.ndim == 2 and complete.shape[1] == 3 and offsets.ndim == 1
        and len(offsets) >= 2 and offsets[0] == 0 and offsets[-1] == len(partial) and np.all(np.diff(offsets) >= 0)
    )  # fmt: skip
    if not ok:
        raise DatasetFormatError(
            f"{shard}: partial {partial.shape}, partial_offsets {offsets.shape}, complete {complete.shape} are not "
            f"a pcn shard's; run `generate --protocol {PROTOCOL}` again into that folder"
        )
    return [partial[a:b] for a, b in zip(offsets[:-1], offsets[1:])], complete


def _write_pcd(folder: OwnedFolder, rel: str, points: np.ndarray) -> None:
    """One binary (uncompressed) PCD of ``points`` as float32 ``x y z``."""
    from pypcd4 import Encoding, PointCloud

    cloud = PointCloud.from_xyz_points(np.ascontiguousarray(points, dtype=np.float32))
    with folder.write(rel) as tmp:
        cloud.save(tmp, encoding=Encoding.BINARY)


def write_pcn(folder: OwnedFolder, plan: PcnPlan) -> list[Path]:
    """Write ``plan``'s models in PCN's layout (module docstring), one shard read at a time; then
    remove the ``.pcd`` files an earlier export into ``folder`` wrote that this one does not.

    Parameters
    ----------
    folder : OwnedFolder
        The export's folder, held (names :data:`FILE_NAMES`).
    plan : PcnPlan
        From :func:`plan_pcn`.

    Returns
    -------
    list of Path
        ``PCN.json`` (the point clouds are in the folder's ledger).

    Raises
    ------
    DatasetFormatError, OutputError
        A shard is damaged (:func:`~zbuf_occlude.protocols.base.read_arrays_h5`, or arrays that are not a pcn shard's).
    UnsafePathError, OutputError
        As :meth:`~zbuf_occlude.io.owned.OwnedFolder.write`.
    """
    folder.check_writable([CATEGORY_FILE])  # a foreign PCN.json (a clone of PoinTr ships one) is refused before any file is written
    splits = list(SUBSETS) + sorted({m.split for m in plan.models} - set(SUBSETS))
    lists = {t: {s: [] for s in splits} for t in plan.taxonomy_names}
    written, empty = set(), 0
    for model in plan.models:
        views, complete = _views(read_arrays_h5(model.shard), model.shard)
        for v, points in enumerate(views):
            rel = f"{model.split}/partial/{model.taxonomy_id}/{model.model_id}/{v:02d}.pcd"
            _write_pcd(folder, rel, points)
            written.add(rel)
            empty += not len(points)
        rel = f"{model.split}/complete/{model.taxonomy_id}/{model.model_id}.pcd"
        _write_pcd(folder, rel, complete)
        written.add(rel)
        lists[model.taxonomy_id][model.split].append(model.model_id)
    if empty:
        log.warning("%d partial views saw nothing and are empty clouds (PoinTr's PCN pads a view to 2,048 points with zeros)", empty)
    entries = [{"taxonomy_id": t, "taxonomy_name": name, **lists[t]} for t, name in plan.taxonomy_names.items()]
    files = [folder.write_text(CATEGORY_FILE, json.dumps(entries, indent=1) + "\n")]
    clouds = re.compile("|".join(f"(?:{n})" for n in FILE_NAMES[1:]))
    stale = [rel for rel in folder.written() if clouds.fullmatch(rel) and rel not in written]
    folder.delete(stale)  # an earlier export's models: checked as ours and unchanged first
    for rel in stale:
        remove_empty_folders(folder.root, PurePosixPath(rel).parent.as_posix())
    return files
