"""Load meshes from disk, drop degenerate faces and normalise them to the unit box.

trimesh does the parsing; this module adds what the pipeline needs on top:
errors that name the file and the cause, removal of degenerate faces (ModelNet has
them), and the normalisation of Sryamkin et al. 2023, §4.1 (centre the axis-aligned
bounding box on the origin, scale uniformly to a maximum extent of 1).

Provenance is stored on every mesh this module returns, in
``mesh.metadata["zbuf_occlude"]``:

``source`` : str or None
    The file the mesh was loaded from.
``n_degenerate_faces_dropped`` : int
    Faces removed because they repeat a vertex index or have (numerically) zero area.
``n_unreferenced_vertices_dropped`` : int
    Vertices removed because no kept face uses them.
``center`` : list of 3 float, ``scale`` : float
    The normalisation that was applied, in the source file's units:
    ``normalised = (original - center) * scale``.  Identity (``[0, 0, 0]``, ``1.0``)
    when the mesh was not normalised.
``up``, ``up_source`` : str
    The file's up axis, rotated to +z before anything else, and the rule that chose it
    (:mod:`zbuf_occlude.mesh.scene`); ``center`` is in the rotated frame.
``extent`` : list of 3 float; ``units_m`` : float or None; ``extent_m`` : list of 3 float or None
    The z-up bounding box size before normalisation in file units, the metres per file
    unit the format declares (glTF, COLLADA), and that size in metres.

Files cut short are errors, not partial meshes (:mod:`zbuf_occlude.mesh.formats`).
The discovery of mesh files lives in :mod:`zbuf_occlude.mesh.inputs.discovery`; its names are
re-exported here (``find_meshes``, ``scan_meshes``, ``class_and_split``, ...).

ModelNet quirks handled (all verified on real files with trimesh 5.2): the malformed
header ``OFF3514 3546 0`` (counts on the ``OFF`` line), CRLF line endings, triangle
soup with duplicated vertices (kept as is: meshes need not be watertight or
manifold), polygons with more than three vertices (fan-triangulated by trimesh) and
zero-area faces.
"""

from __future__ import annotations

import logging
import re
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError, MeshLoadError, ZbufOccludeError
from zbuf_occlude.io.file_errors import parser_failure
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS, read_trimesh
from zbuf_occlude.mesh.scene import FACE_MATERIALS, UP_CHOICES, declared_units_m, face_materials_of, resolve_up, up_rotation

__all__ = [
    "DEGENERATE_AREA_RTOL",
    "MAX_ABS_COORDINATE",
    "METADATA_KEY",
    "load_mesh",
    "normalize_mesh",
    "clean_mesh",
    "degenerate_faces",
]

log = logging.getLogger(__name__)

#: A face whose area is at most this times the squared maximum extent of the mesh is
#: degenerate.  1e-14 is about 50 float64 epsilons: it catches faces that are exactly
#: flat but whose cross product rounding left at ~1e-16 (ModelNet has such faces at
#: 4e-21), while a triangle 1e-7 of the object on a side is still kept.
DEGENERATE_AREA_RTOL = 1e-14

#: Largest vertex coordinate magnitude accepted: float32's maximum (~3.4e38).  The GPU
#: methods work in float32, and beyond it areas and squared extents overflow float64 too
#: (1e200 squared); such files are corrupt or in absurd units.
MAX_ABS_COORDINATE = float(np.finfo(np.float32).max)

#: The package that installs a module trimesh may import while parsing, where the names differ
#: (named in the message when it is missing).
_PACKAGE_OF_MODULE = {"PIL": "pillow", "charset_normalizer": "charset-normalizer"}

#: Key of this package's provenance dictionary in ``trimesh.Trimesh.metadata``.
METADATA_KEY = "zbuf_occlude"


def _referenced_extent(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(3,) min and max corner of the vertices used by ``faces``."""
    used = vertices[np.unique(faces)]
    return used.min(axis=0), used.max(axis=0)


def _face_areas(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    v0 = vertices[faces[:, 0]]
    cross = np.cross(vertices[faces[:, 1]] - v0, vertices[faces[:, 2]] - v0)
    return 0.5 * np.sqrt(np.einsum("ij,ij->i", cross, cross))


def _degenerate_mask(vertices: NDArray[np.float64], faces: NDArray[np.int64], max_extent: float, area_rtol: float) -> NDArray[np.bool_]:
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    return repeated | (_face_areas(vertices, faces) <= area_rtol * max_extent**2)


def _check_coordinates(vertices: NDArray[np.float64], *, what: str, error: type[ZbufOccludeError]) -> None:
    """Raise ``error`` on NaN/inf vertices or coordinates beyond :data:`MAX_ABS_COORDINATE`."""
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise error(
            f"{what}: {int(bad.sum())} of {len(vertices)} vertices are NaN or inf "
            f"(first at index {int(np.argmax(bad))}); fix or re-export the mesh"
        )
    if len(vertices):
        magnitude = np.abs(vertices).max(axis=1)
        if magnitude.max() > MAX_ABS_COORDINATE:
            first = int(np.argmax(magnitude > MAX_ABS_COORDINATE))
            raise error(
                f"{what}: vertex coordinates reach {magnitude.max():.3g} (first at index {first}), beyond the "
                f"float32 range (+-{MAX_ABS_COORDINATE:.3g}) the renderer works in; the file is corrupt or in "
                "absurd units: rescale it"
            )


def _check(
    vertices: NDArray[np.float64],
    faces: NDArray[np.int64],
    *,
    what: str,
    error: type[ZbufOccludeError],
    area_rtol: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.bool_]]:
    """Validate a mesh; return its referenced bounds and degenerate-face mask.

    Raises ``error`` with a message starting with ``what`` (the file or "mesh").
    """
    if len(vertices) == 0 and len(faces) == 0:
        raise error(f"{what}: empty mesh (no vertices, no faces)")
    if len(faces) == 0:
        raise error(f"{what}: mesh has {len(vertices)} vertices but no faces; a point cloud is not a mesh")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise error(f"{what}: faces must be (F, 3) triangles, got shape {faces.shape}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise error(f"{what}: face indices span [{faces.min()}, {faces.max()}] but there are only {len(vertices)} vertices")
    _check_coordinates(vertices, what=what, error=error)
    lo, hi = _referenced_extent(vertices, faces)
    max_extent = float((hi - lo).max())
    if max_extent == 0.0:
        raise error(f"{what}: all vertices coincide at {lo.tolist()} (zero extent); nothing to normalise or sample")
    degenerate = _degenerate_mask(vertices, faces, max_extent, area_rtol)
    if degenerate.all():
        raise error(f"{what}: all {len(faces)} faces are degenerate (repeated vertex index or zero area); the mesh has no surface")
    return lo, hi, degenerate


#: Provenance keys that describe the file (load_mesh), carried through clean/normalise unchanged.
_FILE_KEYS = ("up", "up_source", "extent", "units_m", "extent_m")


def _provenance(mesh: trimesh.Trimesh) -> dict[str, Any]:
    """A fresh copy of the mesh's provenance dictionary, with defaults for missing keys."""
    old = dict(mesh.metadata.get(METADATA_KEY, {}))
    return {
        "source": old.get("source"),
        "n_degenerate_faces_dropped": int(old.get("n_degenerate_faces_dropped", 0)),
        "n_unreferenced_vertices_dropped": int(old.get("n_unreferenced_vertices_dropped", 0)),
        "center": list(old.get("center", [0.0, 0.0, 0.0])),
        "scale": float(old.get("scale", 1.0)),
        **{k: old[k] for k in _FILE_KEYS if k in old},
    }


def _drop_faces(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], keep: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], NDArray[np.int64], int]:
    """Keep ``faces[keep]`` in their order and only the vertices they use, in their order."""
    faces = faces[keep]
    used = np.zeros(len(vertices), dtype=bool)
    used[faces.ravel()] = True
    remap = np.cumsum(used) - 1
    return vertices[used], remap[faces].astype(np.int64), int(len(vertices) - used.sum())


def _normalised(
    vertices: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    # Sryamkin et al. 2023, §4.1: centre of the axis-aligned bounding box to the origin,
    # then one uniform scale so that the largest side is 1 (aspect ratio preserved).
    center = (lo + hi) / 2.0
    scale = 1.0 / float((hi - lo).max())
    return (vertices - center) * scale, center, scale


def _as_arrays(mesh: trimesh.Trimesh) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    if not isinstance(mesh, trimesh.Trimesh):
        raise InvalidInputError(f"expected a trimesh.Trimesh, got {type(mesh).__name__}")
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if faces.size == 0:
        faces = faces.reshape(0, 3)
    return vertices, faces


def _make(vertices: NDArray[np.float64], faces: NDArray[np.int64], metadata: dict[str, Any], provenance: dict[str, Any]) -> trimesh.Trimesh:
    # process=False: merging duplicated vertices would change ModelNet's triangle soup,
    # and faces must stay in file order so that face_index means the same everywhere.
    out = trimesh.Trimesh(vertices=vertices, faces=faces, process=False, validate=False)
    out.metadata.update({k: v for k, v in metadata.items() if k != METADATA_KEY})
    out.metadata[METADATA_KEY] = provenance
    return out


def _check_rtol(area_rtol: float) -> None:
    if not (np.isfinite(area_rtol) and area_rtol >= 0.0):
        raise InvalidInputError(f"area_rtol must be finite and >= 0, got {area_rtol}")


def degenerate_faces(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> NDArray[np.bool_]:
    """Which faces are degenerate.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        A face with area ``<= area_rtol * max_extent**2`` is degenerate, where
        ``max_extent`` is the largest side of the bounding box of the referenced
        vertices (default :data:`DEGENERATE_AREA_RTOL`, scale invariant).

    Returns
    -------
    degenerate : (F,) bool
        True for faces that repeat a vertex index or have (numerically) zero area.
        All True when every vertex coincides (zero extent); empty for a mesh without faces.

    Raises
    ------
    InvalidInputError
        If ``mesh`` is not a Trimesh, has face indices out of range or NaN/inf
        vertices, or ``area_rtol`` is negative or not finite.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    if len(faces) == 0:
        return np.zeros(0, dtype=bool)
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InvalidInputError(f"mesh face indices span [{faces.min()}, {faces.max()}] for {len(vertices)} vertices")
    _check_coordinates(vertices, what="mesh", error=InvalidInputError)
    lo, hi = _referenced_extent(vertices, faces)
    return _degenerate_mask(vertices, faces, float((hi - lo).max()), area_rtol)


def clean_mesh(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> trimesh.Trimesh:
    """A copy of ``mesh`` without degenerate faces and unreferenced vertices.

    The kept faces and vertices stay in their order; duplicated vertices are *not*
    merged and the mesh need not be watertight.  The numbers of dropped faces and
    vertices are added to ``metadata["zbuf_occlude"]`` (see the module docstring).

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        See :func:`degenerate_faces`.

    Returns
    -------
    mesh : trimesh.Trimesh
        New mesh; vertices (V', 3) float64, faces (F', 3) int64.

    Raises
    ------
    InvalidInputError
        If the mesh is empty, has no faces, has NaN/inf vertices, face indices out of
        range, zero extent, or only degenerate faces; or ``area_rtol`` is negative
        or not finite.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    _, _, degenerate = _check(vertices, faces, what="mesh", error=InvalidInputError, area_rtol=area_rtol)
    vertices, faces, n_unref = _drop_faces(vertices, faces, ~degenerate)
    prov = _provenance(mesh)
    prov["n_degenerate_faces_dropped"] += int(degenerate.sum())
    prov["n_unreferenced_vertices_dropped"] += n_unref
    return _make(vertices, faces, mesh.metadata, prov)


def normalize_mesh(mesh: trimesh.Trimesh, *, area_rtol: float = DEGENERATE_AREA_RTOL) -> trimesh.Trimesh:
    """A copy of ``mesh`` centred and scaled to the unit box (Sryamkin et al. 2023, §4.1).

    The centre of the axis-aligned bounding box of the referenced vertices moves to the
    origin and one uniform scale makes the largest side 1.  Faces and vertices are
    kept as they are (use :func:`clean_mesh` to drop degenerate faces); unreferenced
    vertices are transformed too but do not count for the bounding box.

    ``metadata["zbuf_occlude"]["center"]`` and ``["scale"]`` are composed with any
    earlier normalisation, so they always map back to the source file's units:
    ``normalised = (original - center) * scale``.

    Parameters
    ----------
    mesh : trimesh.Trimesh
    area_rtol : float
        Only used for the check that not every face is degenerate; see
        :func:`degenerate_faces`.

    Returns
    -------
    mesh : trimesh.Trimesh
        New mesh; vertices (V, 3) float64 with bounding box centre 0 and max extent 1.

    Raises
    ------
    InvalidInputError
        Same checks as :func:`clean_mesh`.
    """
    _check_rtol(area_rtol)
    vertices, faces = _as_arrays(mesh)
    lo, hi, _ = _check(vertices, faces, what="mesh", error=InvalidInputError, area_rtol=area_rtol)
    new_vertices, center, scale = _normalised(vertices, lo, hi)
    prov = _provenance(mesh)
    # Compose with the earlier map x1 = (x0 - c0) * s0:  x2 = (x1 - c1) * s1
    # = (x0 - (c0 + c1 / s0)) * (s0 * s1).
    old_center, old_scale = np.asarray(prov["center"], dtype=np.float64), prov["scale"]
    prov["center"] = (old_center + center / old_scale).tolist()
    prov["scale"] = old_scale * scale
    return _make(new_vertices, faces, mesh.metadata, prov)


def load_mesh(
    path: str | PathLike[str],
    *,
    normalize: bool = True,
    area_rtol: float = DEGENERATE_AREA_RTOL,
    up: str = "auto",
) -> trimesh.Trimesh:
    """Load a triangle mesh from OFF, OBJ, PLY, STL, glTF (GLB, .gltf) or COLLADA, cleaned, z up, normalised.

    Steps: parse with trimesh (polygons are fan-triangulated, scenes flattened with
    their node transforms; ``.gltf`` reads its external or embedded buffers, COLLADA
    needs pycollada, the ``collada`` extra), rotate the file's up axis to +z, check,
    drop degenerate faces and unreferenced vertices (:func:`clean_mesh`), then, if
    ``normalize``, centre and scale to the unit box as in Sryamkin et al. 2023, §4.1
    (:func:`normalize_mesh`).  Duplicated vertices are kept and the mesh need not be
    watertight or manifold.

    Parameters
    ----------
    path : str or PathLike
        Mesh file; the format comes from the extension (case-insensitive), see
        :data:`SUPPORTED_EXTENSIONS`.
    normalize : bool
        Centre the bounding box on the origin and scale the max extent to 1.
    area_rtol : float
        Relative area below which a face is degenerate; see :func:`degenerate_faces`.
    up : {"auto", "+z", "+y", "-y", "+x", "-x", "-z"}
        The file's up axis, rotated to +z.  ``auto``: +y for a file at a ShapeNetCore path,
        else the format's convention (glTF +y unless trimesh wrote it, COLLADA its declared
        ``<up_axis>``, OBJ by its exporter, others as stored);
        :mod:`zbuf_occlude.mesh.scene` gives the rules.

    Returns
    -------
    mesh : trimesh.Trimesh
        vertices (V, 3) float64, faces (F, 3) int64, in file order minus dropped ones, z up.
        ``mesh.metadata["zbuf_occlude"]`` holds the provenance (module docstring) and
        ``up``, ``up_source`` (the rule applied), ``extent`` (3 floats: the bounding box
        of the z-up mesh before normalisation, file units), ``units_m`` (metres per file
        unit when the format declares it, else None) and ``extent_m`` (``extent`` in
        metres, or None).

    Raises
    ------
    MeshLoadError
        With the file name and cause: missing file, a directory, unsupported
        extension, unreadable or unparsable content, no vertices or no faces,
        NaN/inf vertices, face indices out of range, zero extent (all vertices
        coincide) or only degenerate faces; declared sizes past the caps of
        :mod:`zbuf_occlude.mesh.limits` or of the file's format (:mod:`zbuf_occlude.mesh.formats`)
        or more than the memory there is; a file it names that is not a regular file in its
        folder (a FIFO); a Python module the parser needs that is not installed (named, with
        the package to install); never a ``MemoryError``.
    InvalidInputError
        If ``area_rtol`` is negative or not finite, or ``up`` is not an axis.
    """
    _check_rtol(area_rtol)
    if up not in UP_CHOICES:
        raise InvalidInputError(f"up axis must be one of {', '.join(UP_CHOICES)}, got {up!r}")
    path = Path(path)
    if not path.exists():
        raise MeshLoadError(f"{path}: no such file")
    if path.is_dir():
        raise MeshLoadError(f"{path}: is a directory, expected a mesh file")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_EXTENSIONS:
        raise MeshLoadError(f"{path}: unsupported extension {path.suffix!r}; use one of {', '.join(SUPPORTED_EXTENSIONS)}")
    file_type = SUPPORTED_EXTENSIONS[suffix]
    try:
        loaded = read_trimesh(path, file_type)
        axis, up_source = resolve_up(path, file_type, up)
        units_m = declared_units_m(path, file_type)
    except OSError as exc:
        raise MeshLoadError(f"{path}: cannot read file ({exc.strerror or exc})") from exc
    except MemoryError:
        # A size the file declares that passed the caps of its format's check but not this machine.
        raise MeshLoadError(f"{path}: not enough memory to load it; the file declares more than this machine can hold") from None
    except MeshLoadError:
        raise
    except ImportError as exc:  # a module trimesh imports for this file (Pillow: an OBJ's textures) is missing: not the file's fault
        # trimesh re-raises a failed optional import later, from its message alone (no exc.name)
        named = re.search(r"No module named '([^'.]+)", str(exc))
        module = (exc.name or (named.group(1) if named else str(exc))).partition(".")[0]
        raise MeshLoadError(
            f"{path}: reading this {file_type.upper()} file needs the Python module {module!r}, which is not installed; "
            f"install zbuf-occlude's dependencies again (pip install {_PACKAGE_OF_MODULE.get(module, module)})"
        ) from exc
    except Exception as exc:  # trimesh raises a zoo of types (ValueError, IndexError, NameError, KeyError, ...)
        raise MeshLoadError(f"{path}: cannot parse as {file_type.upper()} ({parser_failure(exc)})") from exc

    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshLoadError(f"{path}: trimesh returned a {type(loaded).__name__}, not a triangle mesh")
    vertices, faces = _as_arrays(loaded)
    if axis != "+z":
        vertices = vertices @ up_rotation(axis)[:3, :3].T
    _, _, degenerate = _check(vertices, faces, what=str(path), error=MeshLoadError, area_rtol=area_rtol)
    n_degenerate = int(degenerate.sum())
    if n_degenerate:
        log.debug("%s: dropping %d degenerate faces of %d", path, n_degenerate, len(faces))
    materials = face_materials_of(loaded)
    vertices, faces, n_unref = _drop_faces(vertices, faces, ~degenerate)
    if materials is not None and n_degenerate:  # the faces kept keep their materials
        loaded.metadata[FACE_MATERIALS] = materials.select(~degenerate)
    prov = {
        "source": str(path),
        "n_degenerate_faces_dropped": n_degenerate,
        "n_unreferenced_vertices_dropped": n_unref,
        "center": [0.0, 0.0, 0.0],
        "scale": 1.0,
    }
    extent = (vertices.max(axis=0) - vertices.min(axis=0)).tolist()
    prov.update(up=axis, up_source=up_source, extent=extent, units_m=units_m,
                extent_m=None if units_m is None else [e * units_m for e in extent])  # fmt: skip
    if normalize:
        # Dropping degenerate faces never empties the mesh (checked above), so the
        # bounds of the kept vertices are finite and, being a superset of a
        # non-degenerate face, of positive extent.
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        vertices, center, scale = _normalised(vertices, lo, hi)
        prov["center"], prov["scale"] = center.tolist(), scale
    return _make(vertices, faces, loaded.metadata, prov)
