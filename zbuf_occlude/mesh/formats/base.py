"""What every format module gives the table: a :class:`Format`; and what its readers share.

A format is one reader and, optionally, one check of the raw bytes that runs before the reader
(declared sizes, structure trimesh would not notice).  Both raise
:class:`~zbuf_occlude.errors.MeshLoadError` naming the file (:func:`malformed` for a structure
that contradicts itself).  The dispatcher,
:func:`zbuf_occlude.mesh.formats.read_trimesh`, reads the file once and hands the same bytes to
both, so what was checked is what is parsed.
"""

from __future__ import annotations

import io
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.mesh.flatten import flatten_scene
from zbuf_occlude.mesh.named_files import folder_resolver
from zbuf_occlude.mesh.scene import FACE_MATERIALS, face_materials

if TYPE_CHECKING:  # trimesh (and scipy with it) is imported by the readers, when a file is read
    import trimesh

__all__ = ["Format", "malformed", "parse", "read_with_named_files"]


def malformed(path: Path, file_type: str, problem: object) -> MeshLoadError:
    """The error for a file whose structure contradicts itself (counts declared vs found, cut lines).

    Returns
    -------
    MeshLoadError
        ``PATH: cannot parse as TYPE: PROBLEM``, to be raised.
    """
    return MeshLoadError(f"{path}: cannot parse as {file_type.upper()}: {problem}")


@dataclass(frozen=True)
class Format:
    """One file type of the table: its extensions, the reader and the check that runs first.

    Attributes
    ----------
    file_type : str
        trimesh's name of the file type (``"off"``, ``"glb"``, ...).
    extensions : tuple of str
        Lower-case suffixes with the dot (``(".off",)``).
    read : callable
        ``read(raw, path, file_type) -> trimesh.Trimesh``: the file's bytes parsed into one
        mesh (``process=False``: vertices and faces in file order), with whatever the format
        checks against what was parsed.  Raises :class:`~zbuf_occlude.errors.MeshLoadError`
        naming ``path``, or whatever trimesh raises.
    check : callable or None
        ``check(raw, path) -> None``, run on the same bytes before ``read``: what the file
        declares, checked before trimesh allocates it.  Raises
        :class:`~zbuf_occlude.errors.MeshLoadError` naming ``path``.
    needs : (module, extra) or None
        The optional package the reader needs beyond trimesh and the extra that installs it;
        checked once per format when the files are found, and again after each file is read
        and before ``check``.
    name : str
        The format's name in messages (``"COLLADA"``); empty: ``file_type`` in capitals.
    """

    file_type: str
    extensions: tuple[str, ...]
    read: Callable[[bytes, Path, str], trimesh.Trimesh]
    check: Callable[[bytes, Path], None] | None = None
    needs: tuple[str, str] | None = None
    name: str = ""

    @property
    def title(self) -> str:
        """The format's name in messages: :attr:`name`, else ``file_type`` in capitals."""
        return self.name or self.file_type.upper()


def parse(raw: bytes, path: Path, file_type: str, **kwargs: Any) -> trimesh.Trimesh:
    """``raw``, the bytes of ``path``, parsed by trimesh (``process=False``) into one Trimesh, its scene flattened.

    ``kwargs`` go to :func:`trimesh.load_scene` (a ``resolver``).

    Raises
    ------
    MeshLoadError
        Naming ``path``: the file holds a point cloud and no faces.
    """
    import trimesh

    scene = trimesh.load_scene(io.BytesIO(raw), file_type=file_type, process=False, **kwargs)
    # flatten_scene concatenates every Trimesh of a scene (GLB) with its node transform
    # baked in, and drops points and paths: Scene.to_mesh() in time linear in the nodes.
    # process=False at load keeps vertex and face order as in the file (no merging of
    # ModelNet's duplicated vertices).
    mesh = flatten_scene(scene)
    materials = face_materials(scene)
    if any(materials.names):  # the name of each face's material, for reflectance; none in OFF, STL, plain PLY
        mesh.metadata[FACE_MATERIALS] = materials
    if len(mesh.faces) == 0:
        n_points = sum(len(g.vertices) for g in scene.geometry.values() if isinstance(g, trimesh.PointCloud))
        if n_points:
            raise MeshLoadError(f"{path}: holds a point cloud of {n_points} points and no faces; a point cloud is not a mesh")
    return mesh


def read_with_named_files(raw: bytes, path: Path, file_type: str) -> trimesh.Trimesh:
    """The reader of formats that name other files (OBJ materials, glTF buffers and images, STL none).

    Every file ``raw`` names is read inside ``path``'s folder, regular files only, size capped
    (:func:`zbuf_occlude.mesh.named_files.folder_resolver`).
    """
    return parse(raw, path, file_type, resolver=folder_resolver(path))
