"""Point-set files as inputs of ``generate`` and ``farm``: one object per cloud.

A point-set file (:mod:`zbuf_occlude.io.point_sets`: PointNet-layout HDF5, ``.npy``, a ``.ply``
with no faces) holds one cloud or many; each cloud is one object of the plan, as a mesh file is.

* **Name**: the file's, as a mesh's (its path relative to the folder given, without the
  suffix), with ``_<row:04d>`` for the rows of an HDF5 file: ``ply_data_train0_0007``.
* **Class**: the file's own label of the cloud, named by the class list beside it
  (``shape_names.txt``, :func:`zbuf_occlude.io.point_sets.shape_names`); a label without a class
  list is its number as text (``"7"``), so that the file's labels are kept.  A file without
  labels takes its class as a mesh would, from the folders (:mod:`zbuf_occlude.mesh.inputs.layouts`).
* **Split**: a ``train``/``test`` folder as for meshes, or, for a file without one, PointNet's
  ``train_files.txt``/``test_files.txt`` beside it where they list its name
  (``modelnet40_ply_hdf5_2048``'s layout); else ``train``.
* **Frame** (:func:`load_cloud`): the points turned so that the up axis is +z (``up``; ``"auto"``
  reads each layout in its own frame, :func:`zbuf_occlude.io.point_sets.stored_up`: PointNet's
  HDF5 files +y up, as ModelNet's clouds are stored there, an HDF5 file's ``up`` attribute where it
  has one, ``.npy`` and ``.ply`` as stored, +z), then normalised as a mesh is
  (centre of the bounding box to the origin, largest side 1; Sryamkin et al. 2023, §4.1).  The
  cloud's points are the object's dense cloud as they are: nothing is sampled.  A cloud that
  float64 cannot normalise (:func:`cloud_frame`) is refused in one line.

The lists beside a file (the class list, the split lists) are read as a shared folder's files
are (:mod:`zbuf_occlude.io.regular_files`): regular files only, inside the file's folder once
links are resolved, of at most :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_LIST_BYTES
from zbuf_occlude.io.regular_files import read_text_file
from zbuf_occlude.mesh.paths import SPLITS, printable_path
from zbuf_occlude.resources import check_memory

__all__ = [
    "POINT_SET_LAYOUT", "BYTES_PER_PLANNED_CLOUD", "MIN_KEPT_DISTINCT", "CloudEntry", "LoadedCloud", "point_set_clouds",
    "pointnet_split", "load_cloud", "cloud_frame",
]  # fmt: skip

#: The card's ``layout`` of point-set files whose clouds are labelled by the files themselves.
POINT_SET_LAYOUT = "point-set labels"
#: Bytes one cloud of a point-set file costs the plan of discovery: its :class:`CloudEntry`, the
#: plan's row and object, and their names (589 B at the peak of ``scan_inputs`` over a file of
#: 100,000 one-point clouds, by tracemalloc; rounded up).
BYTES_PER_PLANNED_CLOUD = 640
#: The least share of a cloud's distinct points that must stay distinct once it is scaled to
#: extent 1 and rounded to float32, the dtype its samples are written in (:func:`cloud_frame`):
#: a half.  Points closer than float32's resolution of the extent (about 6e-8 of it) merge, as
#: near-duplicates may, a few at a time; a cloud that loses more than half of them is one whose
#: extent is set by points so far from the rest that the rest rounds to a few points, and every
#: sample of it would repeat them.
MIN_KEPT_DISTINCT = 0.5
_HDF5 = (".h5", ".hdf5")


@dataclass(frozen=True)
class CloudEntry:
    """One cloud of a point-set file, as discovery plans it.

    Attributes
    ----------
    cloud : int
        Its row in the file (0 for a ``.npy`` or ``.ply`` file, which hold one cloud).
    suffix : str
        What its object's name adds to the file's: ``""``, or ``"_<row:04d>"`` for HDF5 rows.
    class_name : str or None
        From the file's label (module docstring); None: the file has none.
    """

    cloud: int
    suffix: str
    class_name: str | None


@dataclass(frozen=True)
class LoadedCloud:
    """One cloud read for the farm's worker (:func:`load_cloud`).

    Attributes
    ----------
    points : (N, 3) float64
        Turned to +z up and normalised: bounding-box centre at the origin, largest side 1
        (object units, as a normalised mesh's).
    normals : (N, 3) float64 or None
        Unit normals, turned with the points; None where the file has none.
    up, up_source : str
        The up axis the cloud was read with (``+x`` … ``-z``) and why.
    """

    points: NDArray[np.float64]
    normals: NDArray[np.float64] | None
    up: str
    up_source: str


def point_set_clouds(path: str | os.PathLike) -> list[CloudEntry]:
    """The clouds of a point-set file, each with its name suffix and class, reading headers and labels only.

    Raises
    ------
    InvalidInputError
        The file is refused by :func:`zbuf_occlude.io.point_sets.point_set_labels` (naming it
        and why), its class list by :func:`zbuf_occlude.io.point_sets.shape_names` (a link out
        of its folder: :class:`~zbuf_occlude.errors.UnsafePathError`), or a label has no line
        in its class list.
    InsufficientMemoryError
        Planning its clouds (:data:`BYTES_PER_PLANNED_CLOUD` each) would need more memory than
        is available (naming the number of clouds).
    """
    from zbuf_occlude.io.point_sets import point_set_labels, shape_names

    path = Path(path)
    labels = point_set_labels(path)
    check_memory(
        len(labels) * BYTES_PER_PLANNED_CLOUD, option=f"planning the {len(labels):,} clouds of {printable_path(path)}",
        hint="split the file, or free memory",
    )  # fmt: skip
    names = shape_names(path) if any(label is not None for label in labels) else None
    if names is not None:
        beyond = [label for label in labels if label is not None and label >= len(names)]
        if beyond:
            raise InvalidInputError(
                f"{printable_path(path)}: label {max(beyond)} has no line in the class list beside it ({len(names)} "
                f"names); {len(beyond)} clouds are labelled beyond it"
            )
    many = path.suffix.lower() in _HDF5
    return [
        CloudEntry(
            row, f"_{row:04d}" if many else "",
            None if label is None else (names[label] if names is not None else str(label)),
        )
        for row, label in enumerate(labels)
    ]  # fmt: skip


def pointnet_split(path: str | os.PathLike) -> str | None:
    """The split of a point-set file listed in PointNet's ``<split>_files.txt`` beside it, or None.

    PointNet's ``modelnet40_ply_hdf5_2048`` lists its files there by a path whose last part is
    the file's name (``data/modelnet40_ply_hdf5_2048/ply_data_test0.h5``).  A missing list counts
    as absent; a file listed in two splits has none.  A list that is there is read by
    :func:`~zbuf_occlude.io.regular_files.read_text_file`'s rules (undecodable bytes replaced:
    a line that is not UTF-8 names no file here).

    Raises
    ------
    InvalidInputError
        A list that is not a regular file (a FIFO, a folder, a dangling link: refused
        unopened), cannot be read, or is larger than
        :data:`~zbuf_occlude.io.caps.MAX_LIST_BYTES` (naming it).
    UnsafePathError
        A list that leads outside the file's folder (a link to a file elsewhere).
    """
    path = Path(path)
    found = []
    for split in SPLITS:
        listing = path.parent / f"{split}_files.txt"
        if not os.path.lexists(listing):
            continue
        text = read_text_file(listing, max_bytes=MAX_LIST_BYTES, within=path.parent, errors="replace")
        if any(line.strip().replace("\\", "/").rsplit("/", 1)[-1] == path.name for line in text.splitlines()):
            found.append(split)
    return found[0] if len(found) == 1 else None


def load_cloud(path: str | os.PathLike, cloud: int, *, up: str = "auto") -> LoadedCloud:
    """Read cloud ``cloud`` of a point-set file in the pipeline's frame (module docstring).

    Parameters
    ----------
    path : str or PathLike
        The point-set file.
    cloud : int
        Its row (:attr:`CloudEntry.cloud`).
    up : str
        The file's up axis (:data:`zbuf_occlude.mesh.scene.UP_CHOICES`); ``"auto"``: its layout's
        (:func:`zbuf_occlude.io.point_sets.stored_up`: PointNet HDF5 +y, ``.npy`` and ``.ply`` +z).

    Returns
    -------
    LoadedCloud

    Raises
    ------
    InvalidInputError
        As :func:`zbuf_occlude.io.point_sets.read_point_sets` (naming the file), ``up`` unknown,
        or the cloud cannot be normalised (:func:`cloud_frame`: its points all coincide, its
        extent overflows float64, or scaling it merges most of its points).
    """
    from zbuf_occlude.io.point_sets import read_point_sets, stored_up
    from zbuf_occlude.mesh.scene import UP_CHOICES

    if up not in UP_CHOICES:
        raise InvalidInputError(f"up axis must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    path = Path(path)
    (point_set,) = read_point_sets(path, rows=[int(cloud)])
    points, normals = point_set.points, point_set.normals
    axis, why = stored_up(path) if up == "auto" else (up, "explicit")
    points, normals = cloud_frame(points, normals, axis, what=f"{printable_path(path)}: cloud {point_set.name!r}")
    return LoadedCloud(points, normals, axis, why)


def cloud_frame(
    points: NDArray[np.float64], normals: NDArray[np.float64] | None, up: str, *, what: str
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """A cloud in the frame a loaded mesh has: its ``up`` axis turned to +z, then its bounding box
    centred on 0 with maximum extent 1 (as :func:`zbuf_occlude.mesh.load.normalize_mesh`,
    Sryamkin et al. 2023, §4.1).

    The rule of a cloud that can be normalised, checked in float64, where it is done:

    * its **extent** (the largest side of its bounding box) is finite and above 0: a cloud
      from -1.5e308 to 1.5e308 has an extent of inf (the subtraction overflows), and dividing
      by it would put every point at 0; a cloud whose points all coincide has none;
    * its **scale** ``1 / extent`` is finite (an extent below 5.6e-309, subnormal, is refused);
    * scaling **keeps its points apart** where they are written: at least
      :data:`MIN_KEPT_DISTINCT` of its distinct points stay distinct once scaled and rounded to
      float32, the dtype of every sample.  One outlier at 1e200 beside a cloud of unit size sets
      an extent against which the rest spans 1e-200: scaled, the whole cloud but the outlier is
      one repeated point.  Near-duplicates (points within ~6e-8 of the extent of each other)
      may merge; they are the same point in every output.

    The centre is ``(lo + hi) / 2``, or ``lo / 2 + hi / 2`` where that sum overflows.

    Parameters
    ----------
    points : (N, 3) float64
    normals : (N, 3) float64 or None
        Turned with the points (a rotation keeps them unit).
    up : str
        ``"+x"``, ``"-y"``, ...: the cloud's up axis.
    what : str
        The cloud, for the message.

    Returns
    -------
    points : (N, 3) float64
    normals : (N, 3) float64 or None
        C-contiguous.

    Raises
    ------
    InvalidInputError
        One line naming ``what`` and the numbers: every point coincides (no extent), the
        extent overflows or its scale does, or scaling merges most distinct points (above).
    """
    if up != "+z":
        from zbuf_occlude.mesh.scene import up_rotation

        rotation = up_rotation(up)[:3, :3]
        points = points @ rotation.T
        normals = None if normals is None else normals @ rotation.T
    lo, hi = points.min(axis=0), points.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        extent = float((hi - lo).max())
        centre = (lo + hi) / 2.0
    span = f"coordinates from {float(lo.min()):.3g} to {float(hi.max()):.3g}"
    if not math.isfinite(extent):
        raise InvalidInputError(f"{what}: its extent overflows float64 ({span}); a cloud is normalised by its extent: scale it down")
    if not extent > 0.0:
        raise InvalidInputError(f"{what}: its {len(points):,} points all coincide; a cloud needs an extent to be seen from around it")
    scale = 1.0 / extent
    if not math.isfinite(scale):
        raise InvalidInputError(f"{what}: its extent {extent:.3g} is too small to scale to 1 in float64; scale it up")
    if not np.isfinite(centre).all():
        centre = lo / 2.0 + hi / 2.0
    scaled = (points - centre) * scale
    _check_kept_apart(points, scaled, what=what, span=span)
    return np.ascontiguousarray(scaled), None if normals is None else np.ascontiguousarray(normals)


def _distinct_rows(points: NDArray[np.floating]) -> int:
    """Distinct rows of ``points`` (N, 3): its values' bytes, with -0.0 made +0.0."""
    rows = np.ascontiguousarray(points + 0.0).view(np.dtype((np.void, points.dtype.itemsize * 3))).ravel()
    return len(np.unique(rows))


def _check_kept_apart(points: NDArray[np.float64], scaled: NDArray[np.float64], *, what: str, span: str) -> None:
    """Refuse a scaling that merged more than :data:`MIN_KEPT_DISTINCT` of the distinct points,
    as float32 keeps them (:func:`cloud_frame`); sorts the scaled cloud, and the cloud itself only
    when that could be so."""
    n = len(points)
    kept = _distinct_rows(scaled.astype(np.float32))
    if kept >= MIN_KEPT_DISTINCT * n:  # the cloud has at most n distinct points: no need to count them
        return
    distinct = _distinct_rows(points)
    if kept < MIN_KEPT_DISTINCT * distinct:
        raise InvalidInputError(
            f"{what}: scaled to extent 1, its {distinct:,} distinct points become {kept:,} in float32 ({span}): points far "
            "from the rest set its extent, and the rest rounds together; remove the outliers"
        )
