"""The mesh file formats: one module per format family, each giving its table entries; one dispatcher.

trimesh parses; each format's module (:mod:`.off`, :mod:`.obj`, :mod:`.ply`, :mod:`.stl`,
:mod:`.gltf`, :mod:`.collada`) makes sure the result is the whole file and that what the file
declares is checked before trimesh allocates it, and contributes :class:`~.base.Format` entries
(file type, extensions, reader, check, optional package) to :data:`FORMATS`, the one table
:func:`zbuf_occlude.mesh.load.load_mesh` dispatches on by extension.  A format is added by one
module and one line in :data:`FORMATS`.

Every file goes through the same steps, in this order (:func:`read_trimesh`):

1. the file is read once (:func:`zbuf_occlude.io.regular_files.read_regular_file`: a regular
   file, size capped), and every later step gets these bytes;
2. ``needs``: the optional package the format needs is importable (COLLADA: pycollada);
3. ``check``: what the bytes declare, before trimesh parses them (OFF: header and counts; STL:
   a binary file's length; OBJ: no vertex index 0; glTF and COLLADA: the scene's sizes,
   :mod:`zbuf_occlude.mesh.limits`);
4. ``read``: trimesh parses the bytes into one mesh, its scene flattened
   (:mod:`zbuf_occlude.mesh.flatten`); what can only be compared with the parsed mesh is
   checked there (PLY: the header's counts; OFF: faces read vs declared).

The first step that fails ends the load with a :class:`~zbuf_occlude.errors.MeshLoadError`
naming the file.  Discovery checks step 2 once per format before any file is read
(:func:`zbuf_occlude.mesh.inputs.discovery.check_readers_installed`), and reports the files of
:data:`UNREAD_FORMATS`, 3D formats that no entry reads, instead of passing over them.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import TYPE_CHECKING

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.io.caps import MAX_MESH_FILE_BYTES
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.mesh.formats import collada, gltf, obj, off, ply, stl
from zbuf_occlude.mesh.formats.base import Format

if TYPE_CHECKING:
    import trimesh

__all__ = ["EXTENSIONS_TEXT", "FORMATS", "SUPPORTED_EXTENSIONS", "UNREAD_FORMATS", "missing_package", "read_trimesh"]

#: Every format, by trimesh's file type, in the order the help lists their extensions.
FORMATS: dict[str, Format] = {fmt.file_type: fmt for module in (off, obj, ply, stl, gltf, collada) for fmt in module.FORMATS}
#: File extensions load_mesh accepts (lower case), mapped to trimesh's file type.
SUPPORTED_EXTENSIONS: dict[str, str] = {ext: fmt.file_type for fmt in FORMATS.values() for ext in fmt.extensions}
#: The extensions as the help of every command lists them (".off, .obj, ...").
EXTENSIONS_TEXT = ", ".join(SUPPORTED_EXTENSIONS)

#: 3D model and scene formats that no entry of :data:`FORMATS` reads, by lower-case extension:
#: the format's name.  Discovery reports such a file as skipped (a folder of FBX files is not
#: an empty folder); files that sit beside meshes (a glTF's ``.bin`` and textures, an OBJ's
#: ``.mtl``, notes) are no 3D format and are not listed.  Extensions that other kinds of files
#: share (``.x``, ``.abc``, ``.mesh``) are left out: a wrong report is noise on every run.
UNREAD_FORMATS: dict[str, str] = {
    ".fbx": "FBX", ".blend": "Blender", ".3ds": "3ds Max (3DS)", ".max": "3ds Max", ".ma": "Maya ASCII",
    ".mb": "Maya binary", ".c4d": "Cinema 4D", ".lwo": "LightWave", ".lxo": "Modo", ".skp": "SketchUp",
    ".usd": "USD", ".usda": "USD", ".usdc": "USD", ".usdz": "USDZ", ".x3d": "X3D", ".x3dv": "X3D",
    ".x3db": "X3D", ".wrl": "VRML", ".vrml": "VRML", ".3mf": "3MF", ".amf": "AMF", ".ifc": "IFC",
    ".step": "STEP", ".stp": "STEP", ".iges": "IGES", ".igs": "IGES", ".dxf": "DXF", ".dwg": "DWG",
    ".vtk": "VTK", ".vtp": "VTK", ".vtu": "VTK", ".ztl": "ZBrush", ".pmx": "MikuMikuDance",
    ".vrm": "VRM",
}  # fmt: skip


def missing_package(fmt: Format) -> bool:
    """Whether the optional package ``fmt`` needs (:attr:`Format.needs`) cannot be imported."""
    if fmt.needs is None:
        return False
    try:
        return importlib.util.find_spec(fmt.needs[0]) is None
    except (ImportError, ValueError):  # a parent package missing; a module without its spec
        return True


def _check_installed(fmt: Format, path: Path) -> None:
    if fmt.needs is not None and missing_package(fmt):
        module, extra = fmt.needs
        raise MeshLoadError(f"{path}: reading {fmt.file_type.upper()} needs the {module!r} package: {install_hint(extra)}")


def read_trimesh(path: Path, file_type: str) -> trimesh.Trimesh:
    """Parse ``path`` with trimesh into one Trimesh (scenes flattened with their transforms).

    The steps of the module docstring, with the entry of :data:`FORMATS` for ``file_type``.

    Parameters
    ----------
    path : Path
        The file.
    file_type : str
        A value of :data:`SUPPORTED_EXTENSIONS`.

    Returns
    -------
    mesh : trimesh.Trimesh
        As parsed (``process=False``): vertices and faces in file order.

    Raises
    ------
    MeshLoadError
        Naming the file: not an OFF file, a point cloud and no faces, fewer vertices or
        faces than declared, a vertex or face line cut short, a missing optional package,
        declared sizes past the caps of :mod:`zbuf_occlude.mesh.limits`, a file it names that
        is not a regular file in its folder.
    OSError
        The file cannot be read.
    Exception
        Whatever trimesh raises on content it cannot parse (a zoo of types);
        :func:`zbuf_occlude.mesh.load.load_mesh` reports it with the file name.
    """
    fmt = FORMATS[file_type]
    raw = read_regular_file(path, max_bytes=MAX_MESH_FILE_BYTES, error=MeshLoadError)
    _check_installed(fmt, path)
    if fmt.check is not None:
        fmt.check(raw, path)
    return fmt.read(raw, path, file_type)
