"""Layouts of mesh collections: how each mesh's name, class and split are found.

A class label taken from the wrong folder is a silent, fatal error for a data set
(ShapeNetCore read with ModelNet's rule labels every object ``models``).  So the layout
of a folder is recognised from all of its files together, the one used is recorded in
the data-set card (``layout``), and a result that looks wrong is refused unless the user
says where the class is (``--class-from``) or gives a list file.

Layouts (``LAYOUTS``), tried in this order; a folder takes the first that every mesh file
under it fits:

``shapenetcore-v2``
    ``SYNSET/MODEL_ID/models/model_normalized.obj`` (ShapeNetCore v2);
``shapenetcore-v1``
    ``SYNSET/MODEL_ID/model.obj`` (ShapeNetCore v1); SYNSET is 8 digits.  The class is the synset's name in
    the ``taxonomy.json`` at the top of the folder given (its first comma-separated
    name: ``"airplane,aeroplane,plane"`` -> ``airplane``), else the synset id; the
    object's name is ``SYNSET/MODEL_ID`` (a model id may appear in two synsets); split
    ``train``.  ShapeNetCore's models are **+y up** (its ``taxonomy``'s alignment: up
    ``(0, 1, 0)``), so a file at such a path is turned y → z unless told otherwise
    (:func:`zbuf_occlude.mesh.scene.resolve_up`, :func:`~zbuf_occlude.mesh.paths.shapenet_path`).
``modelnet``
    ``CLASS/SPLIT/NAME.ext`` with SPLIT ``train`` or ``test`` (ModelNet10/40).
``flat``
    every file directly in the folder, ``CLASS_NNNN.ext``: the class is the name without
    its number (ModelNet's file names), split ``train``.
``class-folders``
    otherwise: the class is the folder directly below the one given, whatever lies below it
    (``CLASS/NAME.ext``, ``CLASS/train/NAME.ext``, ``CLASS/OBJECT/scene.gltf``: a mesh in a
    folder of its own, with its buffers and textures, belongs to the class above); the split
    is a ``train``/``test`` folder below the class.  A folder below a class folder that
    holds several meshes may be a class of its own or a group of the class: it is taken as
    part of its class, and a warning names it.

Refused (:class:`~zbuf_occlude.errors.InvalidInputError`, exit 2) unless
``class_from`` is given: a class named like a container (:data:`CONTAINER_NAMES`:
``models``, ``meshes``, ``train`` ...), and, for ``class-folders``, meshes directly in the
folder given beside its class folders (no folder names their class), one class for
several meshes (all in one sub-folder: the folder given is probably one level too
high) or one file name for every mesh (``ID/mesh.obj``: the folders are objects, not
classes).  ``class_from=N`` takes the class from the N-th folder above each file
(1: the folder holding it) and the split from a ``train``/``test`` folder below that
(layout ``class-from:N``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from os import PathLike
from pathlib import Path
from typing import NamedTuple

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.json_files import read_json_file
from zbuf_occlude.mesh.paths import DEFAULT_SPLIT, SPLITS, class_and_split, printable_path, shapenet_path

__all__ = [
    "LAYOUTS",
    "CONTAINER_NAMES",
    "TAXONOMY_FILE",
    "LabelledMesh",
    "read_taxonomy",
    "label_tree",
    "label_file",
    "check_class_from",
    "layout_text",
]

log = logging.getLogger(__name__)

#: The layouts this module recognises, each with the paths it expects.
LAYOUTS: dict[str, str] = {
    "shapenetcore-v2": "SYNSET/MODEL_ID/models/model_normalized.obj",
    "shapenetcore-v1": "SYNSET/MODEL_ID/model.obj",
    "modelnet": "CLASS/train|test/NAME.ext",
    "flat": "CLASS_NNNN.ext in one folder",
    "class-folders": "CLASS/NAME.ext, CLASS/.../NAME.ext",
    "files": "mesh files given one by one (class from the folders above each)",
    "list-file": "PATH LABEL [SPLIT] lines",
    "class-from:N": "--class-from N: the N-th folder above each file",
}

#: Folder names that hold meshes but name no class: a class taken from one of them means
#: the rule read the wrong level of the tree (ShapeNetCore's ``models``, a split folder).
CONTAINER_NAMES = frozenset(
    {"model", "models", "mesh", "meshes", "train", "test", "val", "valid", "validation", "data", "objects", "shapes"}
)

#: ShapeNetCore's table of synsets: a JSON list of ``{"synsetId", "name", "children", ...}``.
TAXONOMY_FILE = "taxonomy.json"


class LabelledMesh(NamedTuple):
    """One mesh file with its name (unique seed key), class and split."""

    name: str
    path: Path
    class_name: str
    split: str


def layout_text(layouts: Sequence[str]) -> str:
    """The card's ``layout`` of several inputs: one name, or the distinct names in order."""
    return ", ".join(dict.fromkeys(layouts))


def read_taxonomy(folder: str | PathLike[str]) -> dict[str, str]:
    """``{synset id: class name}`` from ``folder/taxonomy.json`` (ShapeNetCore), or ``{}``.

    The class name is the first of the entry's comma-separated names (``"chair"``,
    ``"airplane,aeroplane,plane"`` -> ``airplane``).

    Raises
    ------
    InvalidInputError
        The file is not JSON, not a list of objects, or an entry's ``synsetId`` or
        ``name`` is not printable text (the message names the file and the entry).
    """
    path = Path(folder) / TAXONOMY_FILE
    if not path.is_file():
        return {}
    try:
        entries = read_json_file(path)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{path}: not a readable JSON file ({exc})") from None
    if not isinstance(entries, list):
        raise InvalidInputError(f"{path}: expected a list of {{'synsetId', 'name'}} objects, got {type(entries).__name__}")
    table: dict[str, str] = {}
    for i, entry in enumerate(entries):
        sid = entry.get("synsetId") if isinstance(entry, dict) else None
        name = entry.get("name") if isinstance(entry, dict) else None
        if not (isinstance(sid, str) and isinstance(name, str)):
            raise InvalidInputError(f"{path}: entry {i} needs text fields 'synsetId' and 'name'")
        first = name.split(",", 1)[0].strip()
        if not (sid.isprintable() and first and first.isprintable()):
            raise InvalidInputError(f"{path}: entry {i}: its 'synsetId' or the first name of its 'name' is empty or not printable text")
        table[sid] = first
    return table


def _synset_names(synsets: set[str], taxonomy: dict[str, str]) -> dict[str, str]:
    """Class name per synset: the taxonomy's, or the id when absent or shared by two synsets."""
    names = {s: taxonomy.get(s, s) for s in synsets}
    counts: dict[str, int] = {}
    for n in names.values():
        counts[n] = counts.get(n, 0) + 1
    for s, n in names.items():
        if counts[n] > 1 and n != s:
            log.warning("synsets share the name %r in %s; using the synset id %s as the class", n, TAXONOMY_FILE, s)
            names[s] = s
    return names


def _class_from_level(path: Path, level: int) -> tuple[str, str]:
    """Class: the ``level``-th folder above ``path`` (1: its folder); split: a split folder below it."""
    parents = path.parents
    if level > len(parents) - 1 or not parents[level - 1].name:
        raise InvalidInputError(f"--class-from {level}: {printable_path(path)} has no folder {level} levels up")
    below = [p.name for p in list(parents)[: level - 1]]
    split = next((n for n in below if n in SPLITS), DEFAULT_SPLIT)
    return parents[level - 1].name, split


def check_class_from(class_from: int | None) -> None:
    """Refuse a ``class_from`` that is no folder level (an integer >= 1): :class:`~zbuf_occlude.errors.InvalidInputError`."""
    if class_from is not None and (isinstance(class_from, bool) or not isinstance(class_from, int) or class_from < 1):
        raise InvalidInputError(f"--class-from must be an integer >= 1 (1: the folder holding each file), got {class_from!r}")


def _refuse(where: str, layout: str, why: str) -> None:
    raise InvalidInputError(
        f"{where}: {why} (layout {layout}: {LAYOUTS[layout]}); the class labels would be wrong. "
        "Say which folder above each file names its class with --class-from N (1: the folder holding it), "
        "or give a list file of 'PATH LABEL [SPLIT]' lines"
    )


#: How many files or folders a message names (the count is given in full).
_NAMED = 3


def _some(names: Sequence[str]) -> str:
    return ", ".join(names[:_NAMED]) + (", ..." if len(names) > _NAMED else "")


def _label_class_folders(root: Path, paths: Sequence[Path]) -> list[LabelledMesh]:
    """Layout ``class-folders``: the class is the first folder below ``root`` (module docstring).

    Raises
    ------
    InvalidInputError
        A mesh lies in ``root`` itself, beside the class folders.
    """
    loose = [p.name for p in paths if p.parent == root]
    if loose:
        _refuse(
            printable_path(root), "class-folders",
            f"{len(loose)} of its {len(paths)} meshes ({_some(loose)}) {'lies' if len(loose) == 1 else 'lie'} in the "
            "folder itself, beside its sub-folders, in no class folder: move each into the folder of its class",
        )  # fmt: skip
    meshes: list[LabelledMesh] = []
    per_folder: dict[str, int] = {}  # meshes in each folder below a class folder (split folders aside)
    for p in paths:
        rel = p.relative_to(root)
        between = rel.parts[1:-1]
        split = next((d for d in between if d in SPLITS), DEFAULT_SPLIT)
        meshes.append(LabelledMesh(rel.with_suffix("").as_posix(), p, rel.parts[0], split))
        if any(d not in SPLITS for d in between):
            folder = rel.parent.as_posix()
            per_folder[folder] = per_folder.get(folder, 0) + 1
    # one mesh in a folder of its own (a glTF with its buffers) is an object; several may be a sub-class
    crowded = [f"{folder} ({n})" for folder, n in per_folder.items() if n > 1]
    if crowded:
        log.warning(
            "%s: %d folders below a class folder hold several meshes each (%s): each is taken as part of the class "
            "above it, the folder directly below %s; if they are classes, say which folder names the class with "
            "--class-from N (1: the folder holding each file) or give a list file",
            printable_path(root), len(crowded), _some(crowded), printable_path(root),
        )  # fmt: skip
    return meshes


def _check_labels(where: str, layout: str, meshes: Sequence[LabelledMesh]) -> None:
    """Refuse labels that a known mistake produces (module docstring)."""
    classes = {m.class_name for m in meshes}
    containers = sorted(c for c in classes if c.lower() in CONTAINER_NAMES)
    if containers:
        _refuse(where, layout, f"classes {containers} are folder names that hold meshes, not classes")
    if layout != "class-folders" or len(meshes) < 2:
        return
    if len(classes) == 1:
        _refuse(where, layout, f"every mesh would get the one class {next(iter(classes))!r}")
    stems = {m.path.name for m in meshes}
    if len(stems) == 1:
        _refuse(where, layout, f"every mesh file is named {next(iter(stems))!r}: the folders above are objects, not classes")


def label_tree(root: str | PathLike[str], files: Sequence[Path], *, class_from: int | None = None) -> tuple[str, list[LabelledMesh]]:
    """Names, classes and splits of the mesh ``files`` found under the folder ``root``.

    Parameters
    ----------
    root : str or PathLike
        The folder given (names are relative to it, POSIX, without suffix).
    files : sequence of Path
        Mesh files under ``root`` (:func:`~zbuf_occlude.mesh.inputs.discovery.walk_mesh_files`).
    class_from : int, optional
        Take the class from this folder level above each file (1: the folder holding it).

    Returns
    -------
    layout : str
        One of :data:`LAYOUTS` (``class-from:N`` with ``class_from``).
    meshes : list of LabelledMesh
        In the order of ``files``.

    Raises
    ------
    InvalidInputError
        ``class_from`` below 1 or above the file system's root; labels refused by the
        checks of the module docstring; ``taxonomy.json`` unreadable.
    """
    check_class_from(class_from)
    root = Path(root).absolute()
    paths = [Path(f).absolute() for f in files]

    def name_of(p: Path) -> str:
        return p.relative_to(root).with_suffix("").as_posix()

    if class_from is not None:
        return f"class-from:{class_from}", [LabelledMesh(name_of(p), p, *_class_from_level(p, class_from)) for p in paths]
    shapenet = [shapenet_path(p) for p in paths]
    for layout in ("shapenetcore-v2", "shapenetcore-v1"):
        if paths and all(m is not None and m[0] == layout for m in shapenet):
            names = _synset_names({m[1] for m in shapenet}, read_taxonomy(root))
            meshes = [LabelledMesh(f"{s}/{mid}", p, names[s], DEFAULT_SPLIT) for p, (_, s, mid) in zip(paths, shapenet)]
            _check_labels(printable_path(root), layout, meshes)
            return layout, meshes
    if paths and all(p.parent.name in SPLITS for p in paths):
        layout = "modelnet"
        meshes = [LabelledMesh(name_of(p), p, *class_and_split(p)) for p in paths]
    elif paths and all(p.parent == root for p in paths):
        layout = "flat"
        meshes = [LabelledMesh(name_of(p), p, *class_and_split(p.name)) for p in paths]
    else:
        layout = "class-folders"
        meshes = _label_class_folders(root, paths)
    _check_labels(printable_path(root), layout, meshes)
    return layout, meshes


def label_file(path: str | PathLike[str], *, class_from: int | None = None) -> tuple[str, LabelledMesh]:
    """Name (the stem), class and split of one mesh file given by name (layout ``files``).

    The class comes from the folders above it: ShapeNetCore's synset id for its file
    names, else :func:`~zbuf_occlude.mesh.inputs.discovery.class_and_split`; or from ``class_from``.

    Raises
    ------
    InvalidInputError
        The class would be a container name (``models``...) and no ``class_from`` is given.
    """
    check_class_from(class_from)
    p = Path(path).absolute()
    if class_from is not None:
        return f"class-from:{class_from}", LabelledMesh(p.stem, p, *_class_from_level(p, class_from))
    shapenet = shapenet_path(p)
    if shapenet is not None:
        mesh = LabelledMesh(f"{shapenet[1]}/{shapenet[2]}", p, shapenet[1], DEFAULT_SPLIT)
    else:
        mesh = LabelledMesh(p.stem, p, *class_and_split(p))
    _check_labels(printable_path(p), "files", [mesh])
    return "files", mesh
