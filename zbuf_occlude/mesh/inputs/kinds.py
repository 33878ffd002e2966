"""The kinds of input ``generate`` and ``farm`` take, each with its own answers (as storage kinds and mesh formats are).

* **mesh** (:data:`MESH`): found by its extension (:data:`~zbuf_occlude.mesh.formats.SUPPORTED_EXTENSIONS`),
  read and normalised by :func:`~zbuf_occlude.mesh.load.load_mesh` (``up="auto"``: per layout and
  format, :mod:`zbuf_occlude.mesh.scene`); its visibility by the run's ``method``; topped up.
* **point set** (:data:`POINT_SET`): ``.npy``, PointNet-layout HDF5 and ``.ply`` without faces
  (:func:`is_point_set_input`), one object per cloud (:func:`~zbuf_occlude.mesh.inputs.point_sets.point_set_clouds`),
  read and normalised by :func:`~zbuf_occlude.mesh.inputs.point_sets.load_cloud` (``up="auto"``: per layout,
  :func:`~zbuf_occlude.io.point_sets.stored_up`: PointNet's HDF5 +y); its visibility from the
  points alone (:data:`POINT_SET_METHOD`, which the card records); ``dense_points``, ``density``
  and ``resolution`` change nothing for it and are refused; never topped up (no faces).

Discovery (:mod:`zbuf_occlude.mesh.inputs.discovery`) takes the kinds a caller asks for
(``kinds=(MESH,)``, or :data:`INPUT_KINDS` for both) and asks each file's kind of them
(:func:`kind_of`).  A plan's object says its kind (:attr:`~zbuf_occlude.mesh.inputs.plan.FarmObject.kind`);
the farm asks the kind, never tests for one by name.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from zbuf_occlude.io.point_sets import POINT_SET_SUFFIXES, is_point_set_file
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

__all__ = [
    "InputKind", "MESH", "POINT_SET", "INPUT_KINDS", "POINT_SET_METHOD", "DEFAULT_POINT_SET_POINTS", "POINT_SET_VISIBLE_SHARE",
    "POINT_SET_VISIBLE_SHARE_P5", "kind_of", "kinds_text", "is_point_set_input", "plan_kind", "plan_nouns",
]  # fmt: skip

#: The visibility method of point-set inputs: the z-buffer test over surfel splats
#: (:mod:`zbuf_occlude.visibility.point_splats`).
POINT_SET_METHOD = "point-splat"


def _read_mesh(path: str | os.PathLike, cloud: int | None, *, up: str) -> Any:
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported by the work, not by modules that only plan

    return load_mesh(path, up=up)


def _read_cloud(path: str | os.PathLike, cloud: int | None, *, up: str) -> Any:
    from zbuf_occlude.mesh.inputs.point_sets import load_cloud

    return load_cloud(path, int(cloud or 0), up=up)


def _clouds(path: str | os.PathLike) -> list:
    from zbuf_occlude.mesh.inputs.point_sets import point_set_clouds  # numpy and the memory checks: when a file is planned

    return point_set_clouds(path)


def _is_mesh_file(path: str | os.PathLike) -> bool:
    return Path(path).suffix.lower() in SUPPORTED_EXTENSIONS


def is_point_set_input(path: str | os.PathLike) -> bool:
    """Whether ``generate`` and ``farm`` take the regular file ``path`` as a point-set file.

    ``.npy``; HDF5 (``.h5``, ``.hdf5``) with a PointNet-layout ``data`` dataset; ``.ply`` with
    vertices and no faces (:func:`zbuf_occlude.io.point_sets.is_point_set_file`; a PLY with
    faces is a mesh).  Only the head of a file is read.
    """
    if Path(path).suffix.lower() not in POINT_SET_SUFFIXES or not Path(path).is_file():  # a regular file (or a link to one)
        return False
    return bool(is_point_set_file(path))


@dataclass(frozen=True)
class InputKind:
    """One kind of input, and its answers.

    Attributes
    ----------
    name : str
        ``"mesh"`` or ``"point set"``.
    noun, plural : str
        What one object of the kind is called in a run's report (``"cloud"``, ``"clouds"``).
    method : str or None
        The visibility method every object of the kind takes; None: the run's ``method``.
    unused_params : tuple of str
        :class:`~zbuf_occlude.farm.FarmParams` fields that change nothing for the kind: a
        run whose objects are all of it refuses them set (naming the option), and records
        none.
    renders : bool
        Its visibility needs the OpenGL renderer (the record names it).
    topped_up : bool
        A pose that sees fewer than ``n_points`` is topped up from the faces it sees
        (:func:`~zbuf_occlude.geometry.samples.top_up`); a point set has no faces.
    default_points : int or None
        Points per sample where the user sets none; None: the command's default.
    visible_share : float or None
        The share of an object of the kind that one pose sees (the run's warning about padded
        samples names it); None: not measured (a mesh is topped up instead).
    finds : callable
        ``finds(path) -> bool``: a file of the kind (discovery).
    read : callable
        ``read(path, cloud, *, up) -> object``: the file (or its cloud ``cloud``) read and
        normalised (largest side 1, bounding-box centre at 0, +z up): a ``trimesh.Trimesh``
        or a :class:`~zbuf_occlude.mesh.inputs.point_sets.LoadedCloud`.
    """

    name: str
    noun: str
    plural: str
    method: str | None
    unused_params: tuple[str, ...]
    renders: bool
    topped_up: bool
    default_points: int | None
    visible_share: float | None
    suffixes: tuple[str, ...]
    files: str
    finds: Callable[[str | os.PathLike], bool]
    refusal: str
    read: Callable[..., Any]
    objects: Callable[[str | os.PathLike], list] | None


#: The share of a point set's points that one pose of ``grid25`` sees by
#: :data:`POINT_SET_METHOD`: its 5th percentile, over 2,048-point clouds drawn uniformly on 27
#: ModelNet meshes as PointNet's are (``benchmarks/point_set_visible.py``; the lowest of the 675
#: poses sees 12.7 %, 260 points).
POINT_SET_VISIBLE_SHARE_P5 = 0.218
#: Its median (the run's warning names it).
POINT_SET_VISIBLE_SHARE = 0.356
#: Points per sample of a point set where the user sets none: the power of two below the fewest
#: points a pose saw of PointNet's 2,048 (above), so that its samples hold distinct points, none
#: repeated (512 pads 11 % of the poses, 1024 84 %).
DEFAULT_POINT_SET_POINTS = 256

MESH = InputKind(
    "mesh", "mesh", "meshes", None, (), True, True, None, None, tuple(SUPPORTED_EXTENSIONS),
    f"mesh files ({', '.join(SUPPORTED_EXTENSIONS)})", _is_mesh_file, "", _read_mesh, None,
)  # fmt: skip
POINT_SET = InputKind(
    "point set", "cloud", "clouds", POINT_SET_METHOD, ("dense_points", "density", "resolution"), False, False,
    DEFAULT_POINT_SET_POINTS, POINT_SET_VISIBLE_SHARE, POINT_SET_SUFFIXES,
    f"point-set files ({', '.join(POINT_SET_SUFFIXES)})", is_point_set_input,
    "is not a point-set file: an HDF5 point-set file holds a dataset 'data' of shape (clouds, points, 3), PointNet's layout",
    _read_cloud, _clouds,
)  # fmt: skip
#: Every input kind: ``kinds=INPUT_KINDS`` asks discovery for all of them.
INPUT_KINDS = (MESH, POINT_SET)
#: The order a file is asked its kind (:func:`kind_of`): a ``.ply`` is named by both, and is a
#: point set where it has no faces, else a mesh.
_ASKED = (POINT_SET, MESH)


def kind_of(path: str | os.PathLike, kinds: Sequence[InputKind] = (MESH,)) -> InputKind | None:
    """The kind of ``path`` among ``kinds``: the first, point set before mesh, whose ``suffixes``
    hold its extension and that ``finds`` it (reading its head at most); None: none."""
    suffix = Path(path).suffix.lower()
    return next((k for k in _ASKED if k in kinds and suffix in k.suffixes and k.finds(path)), None)


def kinds_text(kinds: Sequence[InputKind] = (MESH,)) -> str:
    """``"mesh files (.off, ...) or point-set files (.h5, ...)"``: the files of ``kinds``, for messages."""
    return " or ".join(k.files for k in kinds)


def plan_kind(objects: Iterable[Any]) -> InputKind | None:
    """The one kind of every object of a plan (each with a ``kind``), or None for a plan of several kinds (or none)."""
    kinds = {o.kind for o in objects}
    return next(iter(kinds)) if len(kinds) == 1 else None


def plan_nouns(objects: Sequence[Any]) -> tuple[str, str]:
    """``(noun, plural)`` for a plan's objects in a run's report: its kind's (``"cloud"``, ``"clouds"``), or ``("object", "objects")``."""
    kind = plan_kind(objects)
    return (kind.noun, kind.plural) if kind is not None else ("object", "objects")
