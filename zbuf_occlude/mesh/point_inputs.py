"""Point-set files as inputs of ``generate`` and ``farm``: one object per cloud.

A point-set file (:mod:`zbuf_occlude.io.point_sets`: PointNet-layout HDF5, ``.npy``, a ``.ply``
with no faces) holds one cloud or many; each cloud is one object of the plan, as a mesh file is.

* **Name**: the file's, as a mesh's (its path relative to the folder given, without the
  suffix), with ``_<row:04d>`` for the rows of an HDF5 file: ``ply_data_train0_0007``.
* **Class**: the file's own label of the cloud, named by the class list beside it
  (``shape_names.txt``, :func:`zbuf_occlude.io.point_sets.shape_names`); a label without a class
  list is its number as text (``"7"``), so that the file's labels are kept.  A file without
  labels takes its class as a mesh would, from the folders (:mod:`zbuf_occlude.mesh.layouts`).
* **Split**: a ``train``/``test`` folder as for meshes, or, for a file without one, PointNet's
  ``train_files.txt``/``test_files.txt`` beside it where they list its name
  (``modelnet40_ply_hdf5_2048``'s layout); else ``train``.
* **Frame** (:func:`load_cloud`): the points turned so that the up axis is +z (``up``; ``"auto"``
  reads a point set as stored, +z, since no point-set format declares its up axis: PointNet's
  HDF5 files hold ModelNet +y up, so pass ``up="+y"`` there), then normalised as a mesh is
  (centre of the bounding box to the origin, largest side 1; Sryamkin et al. 2023, §4.1).  The
  cloud's points are the object's dense cloud as they are: nothing is sampled.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.discovery import SPLITS, printable_path

__all__ = ["POINT_SET_LAYOUT", "CloudEntry", "LoadedCloud", "point_set_clouds", "pointnet_split", "load_cloud", "cloud_frame"]

#: The card's ``layout`` of point-set files whose clouds are labelled by the files themselves.
POINT_SET_LAYOUT = "point-set labels"
#: Largest ``train_files.txt``/``test_files.txt`` read (PointNet's are a few hundred bytes).
_FILE_LIST_BYTES = 1 << 20
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
        and why), or a label has no line in its class list.
    """
    from zbuf_occlude.io.point_sets import point_set_labels, shape_names

    path = Path(path)
    labels = point_set_labels(path)
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
    the file's name (``data/modelnet40_ply_hdf5_2048/ply_data_test0.h5``).  A list that is
    missing, larger than 1 MiB or unreadable counts as absent; a file listed in two splits has none.
    """
    path = Path(path)
    found = []
    for split in SPLITS:
        listing = path.parent / f"{split}_files.txt"
        try:
            if not listing.is_file() or listing.stat().st_size > _FILE_LIST_BYTES:
                continue
            text = listing.read_bytes().decode("utf-8", "replace")
        except OSError:
            continue
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
        The file's up axis (:data:`zbuf_occlude.mesh.scene.UP_CHOICES`); ``"auto"``: as stored, +z.

    Returns
    -------
    LoadedCloud

    Raises
    ------
    InvalidInputError
        As :func:`zbuf_occlude.io.point_sets.read_point_sets` (naming the file), ``up`` unknown,
        or the cloud's points all coincide (it has no extent to normalise).
    """
    from zbuf_occlude.io.point_sets import read_point_sets
    from zbuf_occlude.mesh.scene import UP_CHOICES

    if up not in UP_CHOICES:
        raise InvalidInputError(f"up axis must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    path = Path(path)
    (point_set,) = read_point_sets(path, rows=[int(cloud)])
    points, normals = point_set.points, point_set.normals
    axis, why = ("+z", "as stored (+z)") if up == "auto" else (up, "explicit")
    points, normals = cloud_frame(points, normals, axis, what=f"{printable_path(path)}: cloud {point_set.name!r}")
    return LoadedCloud(points, normals, axis, why)


def cloud_frame(
    points: NDArray[np.float64], normals: NDArray[np.float64] | None, up: str, *, what: str
) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """A cloud in the frame a loaded mesh has: its ``up`` axis turned to +z, then its bounding box
    centred on 0 with maximum extent 1 (as :func:`zbuf_occlude.mesh.load.normalize_mesh`,
    Sryamkin et al. 2023, §4.1).

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
        Every point coincides (no extent to normalise).
    """
    if up != "+z":
        from zbuf_occlude.mesh.scene import up_rotation

        rotation = up_rotation(up)[:3, :3]
        points = points @ rotation.T
        normals = None if normals is None else normals @ rotation.T
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = float((hi - lo).max())
    if not extent > 0.0:
        raise InvalidInputError(f"{what}: its {len(points):,} points all coincide; a cloud needs an extent to be seen from around it")
    points = (points - (lo + hi) / 2.0) * (1.0 / extent)
    return np.ascontiguousarray(points), None if normals is None else np.ascontiguousarray(normals)
