"""The checks of the public API's arguments: one per kind (mesh, camera, points, face index, a count, a number >= 0, a flag).

A wrong kind of argument (a file name where a mesh goes, ``(30, 45)`` where a camera goes, text
where points go) is an :class:`~zbuf_occlude.errors.ArgumentTypeError` (a ``TypeError``) saying
what was expected, what was given and how to make the right thing; a right kind with wrong
values (a shape, NaN) is an :class:`~zbuf_occlude.errors.InvalidInputError`.  Every public
function that takes these arguments calls these checks first.
"""

from __future__ import annotations

import math
import numbers
import os
from typing import Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import ArgumentTypeError, InvalidInputError
from zbuf_occlude.geometry.cameras import Camera

__all__ = ["check_camera", "check_count", "check_face_index", "check_mesh", "check_flag", "check_nonnegative", "check_points", "described"]

#: Characters of a value quoted in a message.
_SHOWN = 60


def described(value: Any) -> str:
    """``str 'x.off'``, ``tuple (30, 45)``: the type and the start of the value, for a message."""
    text = repr(value) if isinstance(value, (str, bytes, os.PathLike, tuple, int, float)) else ""
    text = text if len(text) <= _SHOWN else text[: _SHOWN - 3] + "..."
    return f"{type(value).__name__} {text}".rstrip()


def check_mesh(mesh: Any, name: str = "mesh") -> Any:
    """``mesh`` if it is a mesh (a ``trimesh.Trimesh``, or anything with ``vertices`` and ``faces``).

    Raises
    ------
    ArgumentTypeError
        A path or anything else (the message says to load a file with ``zo.load_mesh``).
    """
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        return mesh
    hint = " (load a mesh file with zo.load_mesh(path) first)" if isinstance(mesh, (str, bytes, os.PathLike)) else ""
    raise ArgumentTypeError(f"{name} must be a trimesh.Trimesh{hint}, got {described(mesh)}")


def check_camera(camera: Any, name: str = "camera") -> Camera:
    """``camera`` if it is a :class:`~zbuf_occlude.geometry.cameras.Camera`.

    Raises
    ------
    ArgumentTypeError
        Anything else; a pair of numbers is told about ``zo.camera_on_sphere``.
    """
    if isinstance(camera, Camera):
        return camera
    hint = ""
    if isinstance(camera, (tuple, list)) and len(camera) == 2:
        hint = " (make one from elevation and azimuth with zo.camera_on_sphere(elevation_deg, azimuth_deg))"
    raise ArgumentTypeError(f"{name} must be a zbuf_occlude.Camera{hint}, got {described(camera)}")


def _numeric(value: Any, name: str, kinds: str) -> np.ndarray:
    if isinstance(value, (str, bytes, os.PathLike, dict)):
        raise ArgumentTypeError(f"{name} must be a numeric array, got {described(value)}")
    try:
        array = np.asarray(value)
    except (ValueError, TypeError) as exc:  # ragged nested lists
        raise InvalidInputError(f"{name} must be a numeric array: {exc}") from None
    if array.dtype == object:
        try:
            array = array.astype(np.float64)
        except (ValueError, TypeError):
            raise ArgumentTypeError(f"{name} must be a numeric array, got an array of objects that are not all numbers") from None
    if array.dtype.kind not in kinds:
        raise ArgumentTypeError(f"{name} must be a numeric array, got dtype {array.dtype}")
    return array


def check_points(points: Any, name: str = "points") -> NDArray[np.float64]:
    """``points (N, 3)`` as C-contiguous float64, every coordinate finite.

    Raises
    ------
    ArgumentTypeError
        Not a numeric array (text, a path, complex or boolean values).
    InvalidInputError
        Another shape than ``(N, 3)``, or NaN/inf (the message counts the rows).
    """
    pts = np.ascontiguousarray(_numeric(points, name, "fiu"), dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise InvalidInputError(f"{name} must have shape (N, 3), got {pts.shape}")
    # (a sum of finite values is finite unless it overflows: the full test only then)
    with np.errstate(over="ignore", invalid="ignore"):
        finite = bool(np.isfinite(pts.sum())) or bool(np.all(np.isfinite(pts)))
    if not finite:
        raise InvalidInputError(f"{name} contain {int((~np.isfinite(pts)).any(axis=1).sum())} rows with NaN/inf")
    return pts


def check_face_index(face_index: Any, n_points: int, n_faces: int) -> NDArray[np.int64] | None:
    """``face_index (N,)`` as int64 in ``[0, n_faces)``; ``None`` passes through.

    Raises
    ------
    ArgumentTypeError
        Not an integer array.
    InvalidInputError
        Another shape than ``(n_points,)``, or an index out of range.
    """
    if face_index is None:
        return None
    fi = np.ascontiguousarray(_numeric(face_index, "face_index", "iu"), dtype=np.int64)
    if fi.shape != (n_points,):
        raise InvalidInputError(f"face_index must have shape ({n_points},), got {fi.shape}")
    if n_points and (fi.min() < 0 or fi.max() >= n_faces):
        raise InvalidInputError(f"face_index out of range [0, {n_faces})")
    return fi


def _shown(value: object) -> str:
    """``repr(value)`` for a message; an integer too long for ``repr`` (over 4,300 digits) by its size."""
    if isinstance(value, numbers.Integral) and abs(int(value)).bit_length() > 1024:
        return f"an integer of about {int(abs(int(value)).bit_length() * math.log10(2)) + 1:,} digits"
    return repr(value)


def _number(value: object, name: str) -> float:
    """``value`` as a float when it is a real number (not a bool, not text): else ArgumentTypeError."""
    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} must be a number, got {described(value)}")
    try:
        return float(value)
    except OverflowError:  # an int too large for a float
        return math.inf


def check_nonnegative(value: object, name: str, high: float = math.inf) -> float:
    """``value`` as a float, a real number (else ArgumentTypeError), finite and in ``[0, high]`` (else InvalidInputError)."""
    v = _number(value, name)
    if not math.isfinite(v) or not 0 <= v <= high:
        raise InvalidInputError(f"{name} must be finite and >= 0{f' and <= {high:g}' if high < math.inf else ''}, got {_shown(value)}")
    return v


def check_count(value: object, name: str) -> int:
    """``value`` as an int, a real number (else ArgumentTypeError), whole and at least 1 (else InvalidInputError)."""
    if not isinstance(value, numbers.Real) or isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} must be an integer, got {described(value)}")
    if not isinstance(value, numbers.Integral) or int(value) < 1:
        raise InvalidInputError(f"{name} must be an integer >= 1, got {_shown(value)}")
    return int(value)


def check_flag(value: object, name: str) -> bool:
    """``value`` as a bool: ``True`` or ``False`` (numpy's too), else ArgumentTypeError (``1`` and ``"yes"`` are no flags)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ArgumentTypeError(f"{name} must be True or False, got {described(value)}")
    return bool(value)
