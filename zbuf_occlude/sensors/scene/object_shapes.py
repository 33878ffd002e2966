"""The shapes of a scene's objects: primitive meshes and the width-profile warp.

A scene object (:class:`~zbuf_occlude.sensors.scene.objects.SceneObject`) is a mesh file, a given mesh or
a primitive, ``{"box_m": [x, y, z]}`` or ``{"cylinder": {"radius_m": r, "height_m": h}}`` (sizes
in metres; :func:`primitive_args` checks one before trimesh allocates anything).  Its shape may be
warped by a width profile: ``K >= 2`` horizontal stretch factors over the mesh's relative height
(:func:`width_profile_factors`, :func:`warp_to_width_profile`), applied in the mesh's own z-up
frame, metres or the units it was loaded in.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import MAX_COORDINATE_M, count, mapping, real, reals, value_kind

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "FACE_ROWS",
    "MAX_CYLINDER_SECTIONS",
    "PRIMITIVE_KEYS",
    "CYLINDER_KEYS",
    "check_width_profile",
    "width_profile_factors",
    "split_tall_faces",
    "warp_to_width_profile",
    "primitive_args",
    "primitive_mesh",
    "is_trimesh",
]

#: Key of a warped object's local mesh ``metadata``: ``(F,) int64``, each face's row in the mesh as loaded.
FACE_ROWS = "face_rows_as_loaded"
#: Most sections of a scene cylinder.  At 4096 a facet spans 0.09°, finer than any preset's
#: angular step (0.1–0.4°), so more sections change no scan; the limit is checked before
#: trimesh allocates (1e8 sections would need tens of GB).
MAX_CYLINDER_SECTIONS = 4096
#: Keys of a primitive mesh spec and of its cylinder.
PRIMITIVE_KEYS = ("box_m", "cylinder")
CYLINDER_KEYS = ("radius_m", "height_m", "sections")


def check_width_profile(profile) -> tuple[float, ...]:
    """``profile`` as a tuple of floats, checked: at least 2 finite factors > 0
    (:class:`~zbuf_occlude.sensors.scene.objects.SceneObject` ``width_profile``).

    Raises
    ------
    InvalidInputError
        Anything else, naming the value.
    """
    try:
        out = tuple(float(v) for v in profile)
    except (TypeError, ValueError):
        out = ()
    if len(out) < 2 or not all(math.isfinite(v) and v > 0 for v in out):
        raise InvalidInputError(f"width_profile must be 2 or more factors > 0, one per relative-height bin, got {value_kind(profile)}")
    return out


def width_profile_factors(z: NDArray[np.floating], profile: tuple[float, ...]) -> NDArray[np.float64]:
    """The horizontal stretch of each height ``z (N,)`` under a width profile: ``(N,) float64``.

    ``profile`` holds ``K`` factors at the centres ``(k + 0.5) / K`` of ``K`` equal bins of the
    relative height ``(z − min z) / (max z − min z)``; the factor is linear between centres and
    constant beyond the outer ones (all ``profile[0]`` when ``z`` has no extent).
    """
    z = np.asarray(z, dtype=np.float64)
    extent = float(np.ptp(z)) if len(z) else 0.0
    if extent <= 0:
        return np.full(len(z), profile[0])
    k = len(profile)
    return np.interp((z - z.min()) / extent, (np.arange(k) + 0.5) / k, np.asarray(profile, dtype=np.float64))


def split_tall_faces(v: NDArray[np.float64], faces: NDArray[np.int64], bins: int):
    """Bisect every edge that spans more than half a profile bin in height (``ptp(z) / (2 · bins)``),
    so that a warp by :func:`width_profile_factors` bends long walls too: a post's sides have
    vertices only at its ends.  Edges are measured with x and y squashed 1000x, so that only
    their height counts (a midpoint stays a midpoint under the squash).  Returns the new
    vertices ``(V', 3) float64``, faces ``(F', 3) int64`` and each new face's row in ``faces``."""
    import trimesh.remesh

    extent = float(np.ptp(v[:, 2]))
    if extent <= 0:
        return v.copy(), faces, np.arange(len(faces))
    squash = np.array([1e-3, 1e-3, 1.0])
    sv, sf, rows = trimesh.remesh.subdivide_to_size(v * squash, faces, extent / (2 * bins), max_iter=12, return_index=True)
    return sv / squash, np.asarray(sf, dtype=np.int64), np.asarray(rows, dtype=np.int64)


def warp_to_width_profile(
    v: NDArray[np.float64], faces: NDArray[np.int64], profile: tuple[float, ...]
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.int64]]:
    """A z-up mesh ``v (V, 3) float64``, ``faces (F, 3) int64`` warped by a width profile.

    Its faces are cut where they span more than half a bin in height (:func:`split_tall_faces`),
    then each vertex's x and y move away from (or towards) the footprint centre (the middle of
    the x-y bounding box) by its factor (:func:`width_profile_factors`); z is kept.  Returns the
    vertices ``(V', 3) float64``, faces ``(F', 3) int64`` and each face's row in ``faces``
    ``(F',) int64``.
    """
    v, faces, rows = split_tall_faces(v, faces, len(profile))
    factors = width_profile_factors(v[:, 2], profile)
    centre_xy = (v[:, :2].min(axis=0) + v[:, :2].max(axis=0)) / 2
    v[:, :2] = centre_xy + (v[:, :2] - centre_xy) * factors[:, None]
    return v, faces, rows


def primitive_args(spec: Mapping) -> tuple[str, dict[str, Any]]:
    """The checked arguments of a primitive's trimesh constructor (before anything is allocated).

    Raises
    ------
    InvalidInputError
        Naming the field (``mesh.cylinder.radius_m``): not exactly one of ``box_m`` and
        ``cylinder``, an unknown key, sizes not in (0, :data:`~zbuf_occlude.sensors.checks.MAX_COORDINATE_M`]
        metres, sections not an integer from 3 to :data:`MAX_CYLINDER_SECTIONS`.
    """
    spec = mapping(spec, "mesh", PRIMITIVE_KEYS)
    if len(spec) != 1:
        raise InvalidInputError(
            f"mesh must be a primitive {{'box_m': [x, y, z]}} or {{'cylinder': {{'radius_m': r, 'height_m': h}}}}, got {value_kind(spec)}"
        )
    size = {"low": 0.0, "low_open": True, "high": MAX_COORDINATE_M}
    if "box_m" in spec:
        extents = reals(spec["box_m"], "mesh.box_m", lengths=(3,), expected="3 sizes in metres", **size)
        return "box", {"extents": np.array(extents)}
    c = mapping(spec["cylinder"], "mesh.cylinder", CYLINDER_KEYS, required=("radius_m", "height_m"))
    r, h = real(c["radius_m"], "mesh.cylinder.radius_m", **size), real(c["height_m"], "mesh.cylinder.height_m", **size)
    sections = count(c.get("sections", 48), "mesh.cylinder.sections", low=3, high=MAX_CYLINDER_SECTIONS)
    return "cylinder", {"radius": r, "height": h, "sections": sections}


def primitive_mesh(spec: Mapping) -> trimesh.Trimesh:
    """The primitive's mesh in metres (trimesh's box or cylinder, centred on the origin, z up).

    Raises
    ------
    InvalidInputError
        A bad spec (:func:`primitive_args`).
    """
    import trimesh

    kind, kwargs = primitive_args(spec)
    return getattr(trimesh.creation, kind)(**kwargs)


def is_trimesh(mesh: object) -> bool:
    """Whether ``mesh`` is a ``trimesh.Trimesh`` (trimesh is imported only if it could be one)."""
    if not type(mesh).__module__.startswith("trimesh"):
        return False
    import trimesh

    return isinstance(mesh, trimesh.Trimesh)
