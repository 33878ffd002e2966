"""The objects of a data set: the meshes of a tree, a flat folder or a list file, numbered and labelled.

Each function plans the input kinds it is given (``kinds``, :mod:`zbuf_occlude.mesh.inputs.kinds`;
meshes unless told): ``generate`` and ``farm`` plan point-set files too, each cloud of one an
object, named, labelled and split as :mod:`zbuf_occlude.mesh.inputs.point_sets` says.
"""

from __future__ import annotations

import logging
import os
import re
import stat
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.samples import object_key
from zbuf_occlude.io.caps import MAX_LIST_BYTES
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS
from zbuf_occlude.mesh.inputs.discovery import (
    SkippedInput,
    check_readers_installed,
    collect_inputs,
    no_inputs_error,
    non_utf8_reason,
    unusable_entry_reason,
    walk_mesh_files,
)
from zbuf_occlude.mesh.inputs.kinds import MESH, POINT_SET, InputKind, kind_of, kinds_text
from zbuf_occlude.mesh.inputs.layouts import check_class_from, label_file, label_tree, layout_text
from zbuf_occlude.mesh.paths import DEFAULT_SPLIT, SPLITS, name_set, printable_path
from zbuf_occlude.mesh.inputs.point_sets import POINT_SET_LAYOUT, CloudEntry, pointnet_split

__all__ = [
    "FarmObject", "ObjectScan", "discover_objects", "scan_objects", "scan_inputs", "number_objects",
    "scan_paths", "objects_from_paths",
]  # fmt: skip

log = logging.getLogger(__name__)


# -- inputs ------------------------------------------------------------------------------
@dataclass(frozen=True)
class FarmObject:
    """One mesh of the farm's plan.

    Attributes
    ----------
    index : int
        Position in the plan (``object_index`` in the shards); shards and records are named by it.
    name : str
        Path relative to the input root (or as written in the list file), POSIX, without
        suffix; the seed key is :func:`~zbuf_occlude.geometry.samples.object_key` ``(name)``.
    source : str
        The mesh file, or the point-set file holding the cloud.
    class_name, split : str
    label : int
        Line of ``shape_names.txt``.
    cloud : int or None
        A point-set input: the cloud's row in ``source`` (0 for a ``.npy`` or ``.ply`` file);
        None for a mesh.  Its object's dense cloud is the cloud's points, and its visibility is
        decided from them (:func:`zbuf_occlude.pipeline.occlude_point_set`).
    """

    index: int
    name: str
    source: str
    class_name: str
    split: str
    label: int
    cloud: int | None = None

    @property
    def kind(self) -> InputKind:
        """Its input kind (:mod:`zbuf_occlude.mesh.inputs.kinds`): :data:`~zbuf_occlude.mesh.inputs.kinds.POINT_SET`
        for a cloud of a point-set file, else :data:`~zbuf_occlude.mesh.inputs.kinds.MESH`."""
        return MESH if self.cloud is None else POINT_SET

    @property
    def key(self) -> int:
        """Seed key of the object (:func:`~zbuf_occlude.geometry.samples.object_key` of ``name``)."""
        return object_key(self.name)


def _natural_key(text: str) -> list:
    # "chair_2" < "chair_10"; integer labels of a list file sort numerically.
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", text)]


#: A row of the plan before it is numbered: ``(name, source, class_name, split)``, and for a cloud
#: of a point-set file its row there (:attr:`FarmObject.cloud`).
Row = tuple  # (str, str, str, str) or (str, str, str, str, int)


def _scan_tree(root: Path, class_from: int | None, kinds: Sequence[InputKind]) -> tuple[list[Row], list[SkippedInput], str]:
    # Hidden folders and temporary files are left out, not reported.
    files, skipped = walk_mesh_files(root, skip_hidden=True, kinds=kinds)
    if not files:
        return [], skipped, ""
    rows, layouts = _label_files(root, files, class_from, skipped, kinds)
    return rows, skipped, layout_text(layouts)


def _clouds_or_skip(path: Path, kind: InputKind, skipped: list[SkippedInput]) -> list[CloudEntry] | None:
    """The clouds of a point-set file (``kind.objects``), or None after recording why it cannot be
    read (it is skipped like an unreadable folder: the run records it and exits 1)."""
    try:
        return kind.objects(path)
    except InvalidInputError as exc:
        reason = str(exc)
        for prefix in (f"{path}: ", f"{printable_path(path)}: "):
            reason = reason.removeprefix(prefix)
        skipped.append(SkippedInput(printable_path(path), reason))
        log.warning("skipped %s", skipped[-1])
        return None


def _cloud_rows(name: str, path: Path, class_name: str, split: str, clouds: Sequence[CloudEntry] | None) -> list[Row]:
    """The plan's rows of one file: a mesh's one row, or one per cloud of a point-set file (whose
    own labels, where it has them, name the class)."""
    if clouds is None:
        return [(name, str(path), class_name, split)]
    return [(name + c.suffix, str(path), c.class_name or class_name, split, c.cloud) for c in clouds]


def _split_of(rel: Path, path: Path, split: str) -> str:
    """A point-set file's split: a split folder in its path, else PointNet's file lists beside it, else ``split``."""
    if any(part in SPLITS for part in rel.parts[:-1]):
        return split
    return pointnet_split(path) or split


def _label_files(
    root: Path | None, files: Sequence[Path], class_from: int | None, skipped: list[SkippedInput], kinds: Sequence[InputKind]
) -> tuple[list[Row], list[str]]:
    """Rows and layouts of the ``files`` of ``kinds`` found under the folder ``root`` (None: one
    file given by name).

    Meshes and point-set files without labels are labelled together by their layout
    (:func:`~zbuf_occlude.mesh.inputs.layouts.label_tree`, :func:`~zbuf_occlude.mesh.inputs.layouts.label_file`);
    point-set files with labels name their clouds' classes themselves (layout
    :data:`~zbuf_occlude.mesh.inputs.point_sets.POINT_SET_LAYOUT`), so no folder check applies to them.
    Point-set files that cannot be read are added to ``skipped``.
    """
    clouds: dict[Path, list[CloudEntry]] = {}
    by_layout: list[Path] = []
    labelled: list[Path] = []
    for f in files:
        f = Path(f).absolute()
        kind = kind_of(f, kinds)
        if kind is None or kind.objects is None:  # one object per file
            by_layout.append(f)
            continue
        entries = _clouds_or_skip(f, kind, skipped)
        if entries is None:
            continue
        clouds[f] = entries
        (by_layout if entries[0].class_name is None else labelled).append(f)
    rows: list[Row] = []
    layouts: list[str] = []
    if by_layout:
        if root is None:
            layout, mesh = label_file(by_layout[0], class_from=class_from)
            meshes = [mesh]
        else:
            layout, meshes = label_tree(root, by_layout, class_from=class_from)
        layouts.append(layout)
        for m in meshes:
            rel = Path(m.path.name) if root is None else m.path.relative_to(root.absolute())
            split = _split_of(rel, m.path, m.split) if m.path in clouds else m.split
            rows += _cloud_rows(m.name, m.path, m.class_name, split, clouds.get(m.path))
    if labelled:
        layouts.append(POINT_SET_LAYOUT)
        for f in labelled:
            rel = Path(f.name) if root is None else f.relative_to(root.absolute())
            folder_split = next((part for part in rel.parts[:-1] if part in SPLITS), DEFAULT_SPLIT)
            rows += _cloud_rows(rel.with_suffix("").as_posix(), f, "", _split_of(rel, f, folder_split), clouds[f])
    return rows, layouts


def _not_regular(path: Path) -> str | None:
    """Why a list file's entry is no file to open (a FIFO, socket, device), or None.

    Missing files and broken links are left to the loader: they fail as their object.
    """
    try:
        st = os.stat(path)
    except OSError:
        return None
    return None if stat.S_ISREG(st.st_mode) else unusable_entry_reason(path) or "not a regular file; never opened"


def _read_list_file(list_file: Path, kinds: Sequence[InputKind]) -> tuple[list[Row], list[SkippedInput]]:
    found, skipped = [], []
    base = list_file.parent
    # a regular file (a FIFO would block) of at most MAX_LIST_BYTES; named on the command line, so no folder holds it
    data = read_regular_file(list_file, max_bytes=MAX_LIST_BYTES, error=InvalidInputError)
    for lineno, raw_bytes in enumerate(data.splitlines(), start=1):
        try:
            raw = raw_bytes.decode("utf-8")
        except UnicodeDecodeError:
            skipped.append(SkippedInput(f"{printable_path(list_file)}:{lineno}", "line is not valid UTF-8; re-save the list as UTF-8"))
            log.warning("skipped %s", skipped[-1])
            continue
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        tokens = line.rsplit(maxsplit=2)
        if len(tokens) == 3 and tokens[2] in SPLITS:
            path_text, label, split = tokens
        else:
            tokens = line.rsplit(maxsplit=1)
            if len(tokens) != 2:
                raise InvalidInputError(f"{list_file}:{lineno}: expected 'PATH LABEL [train|test]', a path and a label")
            (path_text, label), split = tokens, DEFAULT_SPLIT
        path = Path(path_text)
        name = path.with_suffix("").as_posix()
        source = path if path.is_absolute() else base / path
        # the names are written into the shards; a FIFO or device would block or mislead the loader
        problem = non_utf8_reason(source) or _not_regular(source)
        if problem:
            skipped.append(SkippedInput(printable_path(source), problem))
            log.warning("skipped %s", skipped[-1])
            continue
        kind = kind_of(source, kinds)
        if kind is not None and kind.objects is not None:
            clouds = _clouds_or_skip(source, kind, skipped)
            if clouds is not None:
                found += _cloud_rows(name, source, label, split, clouds)
            continue
        found.append((name, str(source), label, split))
    return found, skipped


class ObjectScan(NamedTuple):
    """What :func:`scan_objects` found."""

    #: The farm's plan, as :func:`discover_objects` returns it.
    objects: list[FarmObject]
    #: Unreadable folders, broken links, FIFOs, files with non-UTF-8 names, files of 3D
    #: formats not read, undecodable list lines: not in the plan.  A run that must not lose inputs silently exits
    #: non-zero when not empty.
    skipped: list[SkippedInput]
    #: How names, classes and splits were found (:data:`~zbuf_occlude.mesh.inputs.layouts.LAYOUTS`).
    layout: str = ""


def discover_objects(
    source: str | os.PathLike,
    *,
    classes: Sequence[str] | str | None = None,
    per_class: int | None = None,
    splits: Sequence[str] | str = SPLITS,
    class_from: int | None = None,
) -> list[FarmObject]:
    """The farm's plan: :func:`scan_objects` without the list of skipped inputs (they are
    logged as warnings)."""
    return scan_objects(source, classes=classes, per_class=per_class, splits=splits, class_from=class_from).objects


def scan_objects(
    source: str | os.PathLike,
    *,
    classes: Sequence[str] | str | None = None,
    per_class: int | None = None,
    splits: Sequence[str] | str = SPLITS,
    class_from: int | None = None,
    kinds: Sequence[InputKind] = (MESH,),
) -> ObjectScan:
    """The farm's plan: meshes under ``source``, filtered, labelled and numbered, and the
    inputs that had to be skipped.

    Parameters
    ----------
    source : str or PathLike
        A folder in one of the layouts of :mod:`zbuf_occlude.mesh.inputs.layouts` (ModelNet
        ``ROOT/<class>/<split>/<name>.off``, ShapeNetCore v1/v2 with ``taxonomy.json``,
        class folders ``ROOT/<class>/<name>.off``, a flat folder ``ROOT/<class>_<NNNN>.off``),
        or a list file with one ``PATH LABEL [SPLIT]`` per line (paths relative to the list
        file; ``#`` starts a comment; ``LABEL`` is a class name; FIFOs and devices are
        skipped, never opened).  Any extension of
        :data:`zbuf_occlude.mesh.load.SUPPORTED_EXTENSIONS`.  Objects without a split are in
        ``train``.
    classes : sequence of str or comma-separated str, optional
        Keep these classes only.
    per_class : int, optional
        Keep the first K objects (by name, natural order) of each class and split.
    splits : sequence of str or comma-separated str
        Keep these splits.
    class_from : int, optional
        A folder: take each mesh's class from this folder level above it (1: the folder
        holding it) instead of the detected layout (``--class-from``).
    kinds : sequence of InputKind
        The kinds of input planned (:mod:`zbuf_occlude.mesh.inputs.kinds`; meshes unless told).
        :data:`~zbuf_occlude.mesh.inputs.kinds.INPUT_KINDS` plans point-set files too (``.npy``,
        PointNet-layout HDF5, ``.ply`` without faces; :mod:`zbuf_occlude.mesh.inputs.point_sets`):
        one object per cloud, whose ``cloud`` is its row.  A point-set file that cannot be read is
        skipped (``skipped``), as an unreadable folder is.

    Returns
    -------
    ObjectScan
        ``objects``: sorted by name; ``index`` is the position, ``label`` the position of
        the class in the sorted (natural order) list of kept classes.  ``skipped``:
        folders that could not be read, files whose path is not UTF-8 and list lines
        that are not UTF-8 (:class:`~zbuf_occlude.mesh.inputs.discovery.SkippedInput`, each logged as a
        warning), whatever the class filter.  ``layout``: the layout used.

    Raises
    ------
    InvalidInputError
        ``source`` missing, nothing found, labels refused by the layout checks
        (:mod:`zbuf_occlude.mesh.inputs.layouts`), ``class_from`` with a list file, a list file larger
        than :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES`, an unknown class, or
        ``per_class < 1``.
    BackendUnavailable
        A format of the meshes kept needs an optional package that is not installed
        (:func:`~zbuf_occlude.mesh.inputs.discovery.check_readers_installed`).
    """
    source = Path(source).absolute()  # the manifest's source paths must not depend on the working folder
    if source.is_dir():
        found, skipped, layout = _scan_tree(source, class_from, kinds)
    elif source.is_file():
        kind = kind_of(source, kinds)
        if kind is not None and kind.objects is not None:
            raise InvalidInputError(
                f"{printable_path(source)} is a point-set file; farm takes a folder or a list file: give the folder "
                f"holding it ({printable_path(source.parent)}), or run: zbuf-occlude generate {printable_path(source)}"
            )
        if source.suffix.lower() in SUPPORTED_EXTENSIONS:
            raise InvalidInputError(
                f"{printable_path(source)} is a mesh file; farm takes a folder of meshes or a list file "
                f"('PATH LABEL [train|test]' per line); for one mesh run: zbuf-occlude generate {printable_path(source)}"
            )
        if class_from is not None:
            raise InvalidInputError(f"--class-from applies to folders; the list file {printable_path(source)} names each class")
        (found, skipped), layout = _read_list_file(source, kinds), "list-file"
    else:
        raise InvalidInputError(f"no such mesh folder or list file: {printable_path(source)}")
    if not found:
        missed = f"; skipped {len(skipped)}: " + "; ".join(map(str, skipped[:3])) if skipped else ""
        raise InvalidInputError(f"no {kinds_text(kinds)} under {printable_path(source)}{missed}")
    if classes is not None:
        wanted = name_set(classes)
        unknown = wanted - {f[2] for f in found}
        if unknown:
            have = sorted({f[2] for f in found}, key=_natural_key)
            raise InvalidInputError(f"classes {sorted(unknown)} not found under {source}; it has {have}")
        found = [f for f in found if f[2] in wanted]
    split_set = name_set(splits)
    found = [f for f in found if f[3] in split_set]
    found.sort(key=lambda f: _natural_key(f[0]))
    if per_class is not None:
        if per_class < 1:
            raise InvalidInputError(f"--per-class must be >= 1, got {per_class}")
        taken: dict[tuple[str, str], int] = {}
        kept = []
        for f in found:
            n = taken.get((f[2], f[3]), 0)
            if n < per_class:
                kept.append(f)
                taken[(f[2], f[3])] = n + 1
        found = kept
    if not found:
        raise InvalidInputError(f"no meshes left under {source} after the class/split selection")
    check_readers_installed(f[1] for f in found)  # the meshes kept only: a class left out needs nothing
    return ObjectScan(number_objects(found), skipped, layout)


def scan_inputs(paths: Sequence[str | os.PathLike], *, class_from: int | None = None, kinds: Sequence[InputKind] = (MESH,)) -> ObjectScan:
    """The plan of ``generate``: the files of ``kinds`` given and under the folders given
    (searched recursively), labelled by their layout (:mod:`~zbuf_occlude.mesh.inputs.layouts`: a
    folder by :func:`~zbuf_occlude.mesh.inputs.layouts.label_tree`, a file by
    :func:`~zbuf_occlude.mesh.inputs.layouts.label_file`) and numbered (:func:`number_objects`),
    and the inputs that had to be skipped.

    With :data:`~zbuf_occlude.mesh.inputs.kinds.INPUT_KINDS`, point-set files too: one object per
    cloud (as :func:`scan_objects`; a file that cannot be read is skipped).

    Raises
    ------
    InvalidInputError
        ``class_from`` is no folder level, a path is missing or of none of ``kinds``, nothing was
        found, labels are refused by the layout checks, or two files have one name.
    BackendUnavailable
        A format found needs an optional package that is not installed.
    """
    check_class_from(class_from)
    inputs, skipped = collect_inputs(paths, kinds=kinds)
    rows: list[Row] = []
    layouts: list[str] = []
    for path, files in inputs:
        if files is None or files:
            found_rows, found_layouts = _label_files(None if files is None else path, files or [path], class_from, skipped, kinds)
            rows += found_rows
            layouts += found_layouts
    if not rows:
        raise no_inputs_error(paths, skipped, kinds)
    check_readers_installed(r[1] for r in rows)
    return ObjectScan(number_objects(rows), skipped, layout_text(layouts))


def number_objects(found: Sequence[Row]) -> list[FarmObject]:
    """The plan: ``(name, source, class_name, split)`` rows numbered in the order given (a fifth
    entry: the row of a point-set file's cloud, :attr:`FarmObject.cloud`).

    Labels number the class names in natural order (``chair_2`` before ``chair_10``), the
    lines of ``shape_names.txt``.  Used by :func:`scan_objects` and ``generate``.

    Raises
    ------
    InvalidInputError
        Two rows have one name (``chair_0001.off`` and ``chair_0001.obj``): the name seeds
        the samples and names the outputs, so one would overwrite the other.
    """
    by_name: dict[str, list[str]] = {}
    for name, src, *_ in found:
        by_name.setdefault(name, []).append(src)
    clashes = {n: p for n, p in by_name.items() if len(p) > 1}
    if clashes:
        text = "; ".join(f"{' and '.join(p)} are both {n!r}" for n, p in sorted(clashes.items())[:5])
        raise InvalidInputError(
            f"mesh names must be unique (the name seeds the samples and names the output files): {text}; rename or move one of each"
        )
    labels = {c: i for i, c in enumerate(sorted({f[2] for f in found}, key=_natural_key))}
    objects = [FarmObject(i, name, src, cls, split, labels[cls], *cloud) for i, (name, src, cls, split, *cloud) in enumerate(found)]
    keys: dict[int, str] = {}
    for o in objects:
        if o.key in keys:
            log.warning(
                "objects %s and %s share the seed key %d (hash collision): their draws are correlated",
                keys[o.key], o.name, o.key,
            )  # fmt: skip
        keys[o.key] = o.name
    return objects


def scan_paths(paths: Sequence[str | os.PathLike], *, class_from: int | None = None) -> tuple[list[FarmObject], list[SkippedInput]]:
    """The plan of ``generate``: mesh files and folders (searched recursively), numbered,
    and the inputs that had to be skipped (:func:`~zbuf_occlude.mesh.inputs.scan_inputs`).

    Each object's name is its path relative to the folder given (a file given alone: its
    stem; ShapeNetCore: ``SYNSET/MODEL_ID``), without the suffix; class and split come
    from the folder's layout (:mod:`zbuf_occlude.mesh.inputs.layouts`, ``class_from``: the
    folder level that names the class); labels number the class names
    (:func:`~zbuf_occlude.mesh.inputs.number_objects`, as the farm does).

    Returns
    -------
    objects : list of FarmObject
    skipped : list of SkippedInput
        Unreadable folders, broken links, files whose names are not UTF-8 and files of 3D
        formats not read (:func:`~zbuf_occlude.mesh.inputs.discovery.walk_mesh_files`); the run
        records them and exits 1.

    Raises
    ------
    InvalidInputError
        A path is missing or no mesh file, nothing was found, the layout's labels are
        refused, or two files have one name (``chair_0001.off`` and ``chair_0001.obj``):
        the name seeds the samples and names the outputs, so one would overwrite the other.
    """
    scan = scan_inputs(paths, class_from=class_from)
    return scan.objects, scan.skipped


def objects_from_paths(paths: Sequence[str | os.PathLike]) -> list[FarmObject]:
    """:func:`scan_paths` without the skipped inputs (each was logged as a warning)."""
    return scan_paths(paths)[0]
