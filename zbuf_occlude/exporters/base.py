"""What every export target gives the table: a :class:`Target`; and what the targets share.

A target is one module (:mod:`.pointnet_h5`, :mod:`.modelnet_txt`, :mod:`.pcn`) holding its
writer and one :class:`Target`, an entry of :data:`zbuf_occlude.exporters.TARGETS`.  A target says
what it reads, which parameters of :func:`~zbuf_occlude.exporters.export` it takes, and the frame
its network family trains in (:attr:`Target.up`): PointNet's ``modelnet40_ply_hdf5_2048``, the
ModelNet text files of Pointnet_Pointnet2_pytorch and PCN's data are **+y up**, and their
augmentation turns about y (PointNet's ``provider.rotate_point_cloud``, "along up direction").

Errors raised here and by the targets name :func:`~zbuf_occlude.exporters.export`'s parameters
as a call would (``label_set_name='modelnet10'``); the CLI names its flags instead
(:mod:`zbuf_occlude.cli.export`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.exporters.label_sets import LABEL_SETS

__all__ = ["DATASET", "OPTIONS", "UP_AXES", "ExportOptions", "Target", "Written", "check_up", "frame_of", "turn_up"]

#: What a target reads: a farm or generate data set (``None``), or a ``generate --protocol NAME`` folder (``NAME``).
DATASET = None
#: The up axes an export may be written in.
UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
#: The parameters of :func:`~zbuf_occlude.exporters.export` a target may take besides ``to``, ``out``,
#: ``label_set_name`` and ``up`` (each refused by a target that does not take it).
OPTIONS = ("seed", "list_prefix")


@dataclass(frozen=True)
class ExportOptions:
    """What :func:`~zbuf_occlude.exporters.export` hands a target's writer besides the folder and the source.

    Attributes
    ----------
    seed : int or None
        ``pointnet-h5``'s shuffle (``None`` for a target that does not take it).
    list_prefix : str or None
        ``pointnet-h5``'s file lists' prefix, checked.
    up : str
        The export's up axis, one of :data:`UP_AXES`.
    progress : bool
        A progress bar (or line) on stderr while the samples are written.
    """

    seed: int | None
    list_prefix: str | None
    up: str
    progress: bool = True


@dataclass(frozen=True)
class Written:
    """What a target's writer wrote.

    Attributes
    ----------
    files : list of Path
        The files a user opens first (class list, file lists).
    samples : dict of str to int
        Samples (or models) per split.
    """

    files: list[Path]
    samples: dict[str, int]


@dataclass(frozen=True)
class Target:
    """One ``to`` of :func:`~zbuf_occlude.exporters.export`: what it reads, writes and takes.

    Attributes
    ----------
    name : str
        The target's name (``"pointnet-h5"``).
    summary : str
        One line: the layout and the networks that read it.
    file_names : tuple of str
        Regular expressions of the names it writes (for the owned folder).
    read : callable
        ``read(source, label_set_name) -> opened``: the whole source read and checked before
        anything is made (a refusal makes nothing).
    write : callable
        ``write(folder, opened, options: ExportOptions) -> Written``.
    up : str
        The up axis its network family trains in (the default of ``up``), one of :data:`UP_AXES`.
    frame : str
        Whose frame that is, in words (what export prints and records).
    protocol : str or None
        :data:`DATASET`, or the ``generate --protocol`` whose folders it reads.
    options : tuple of str
        Which of :data:`OPTIONS` it takes.
    label_sets : tuple of str
        The label sets it takes.
    unit : str
        What one of :attr:`Written.samples` is (``"sample"``, or ``"model"`` for ``pcn``).
    """

    name: str
    summary: str
    file_names: tuple[str, ...]
    read: Callable[[Path, str], Any]
    write: Callable[[Any, Any, ExportOptions], Written]
    up: str
    frame: str
    protocol: str | None = DATASET
    options: tuple[str, ...] = ()
    label_sets: tuple[str, ...] = LABEL_SETS
    unit: str = "sample"


#: (column, sign) of each up axis: the object's up (+z in our frame) becomes that axis.
_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


def _to_z_up(axis: str) -> NDArray[np.float64]:
    """(3, 3) signed permutation ``R`` with ``p @ R`` sending an ``axis``-up row vector ``p`` to +z up.

    The inverse of :func:`_from_z_up`; for +y, ``(x, y, z) → (x, −z, y)`` as the readers turn a
    +y-up file (:func:`zbuf_occlude.mesh.scene.up_rotation`).
    """
    return _from_z_up(axis).T


def _from_z_up(axis: str) -> NDArray[np.float64]:
    """(3, 3) signed permutation ``R`` with ``p @ R`` sending a +z-up row vector ``p`` to ``axis`` up.

    A quarter turn about x for ±y (+y: ``(x, y, z) → (x, z, −y)``, PCN's own turn), about y for
    ±x, a half turn about x for −z; proper rotations all (determinant 1).
    """
    column, sign = _AXES[axis]
    rotation = np.zeros((3, 3))
    if column == 2:
        rotation[0, 0], rotation[1, 1], rotation[2, 2] = 1.0, sign, sign
    elif column == 1:  # z -> ±y, y -> ∓z, x kept
        rotation[0, 0], rotation[2, 1], rotation[1, 2] = 1.0, sign, -sign
    else:  # z -> ±x, x -> ∓z, y kept
        rotation[1, 1], rotation[2, 0], rotation[0, 2] = 1.0, sign, -sign
    return rotation


def check_up(up: object) -> str:
    """``up``, once it is one of :data:`UP_AXES`.

    Raises
    ------
    InvalidInputError
        Another value.
    """
    if not isinstance(up, str) or up not in UP_AXES:
        raise InvalidInputError(f"up={up!r}: give one of {', '.join(UP_AXES)} (the axis that is up in the export) or None")
    return up


def turn_up(points: NDArray[np.floating], source_up: str, up: str) -> NDArray[np.floating]:
    """``points (..., 3)`` turned from ``source_up`` up to ``up`` up, dtype kept.

    A proper rotation by a signed permutation: each value is moved and maybe negated, never
    rounded, so that turning back gives the same bytes.  The same frame returns ``points`` itself.
    """
    if source_up == up:
        return points
    rotation = _to_z_up(source_up) @ _from_z_up(up)
    column = np.argmax(np.abs(rotation), axis=0)  # output column j is input column[j] times its sign
    sign = rotation[column, np.arange(3)]
    out = points[..., column]
    return np.where(sign < 0, -out, out).astype(points.dtype, copy=False)


def frame_of(target: Target, up: str) -> dict[str, str]:
    """What an export records of its frame (``export.json``'s ``frame``): the up axis and whose frame it is."""
    if up == target.up:
        said = f"{up} up, {target.frame}"
    else:
        said = f"{up} up (asked for; {target.name}'s networks train {target.up} up, {target.frame})"
    return {"up": up, "frame": said}
