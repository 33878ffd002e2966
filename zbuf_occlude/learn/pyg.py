"""Occlusion on the fly as a PyTorch Geometric transform (the ``pyg`` extra: ``pip install '.[pyg]'`` from a checkout).

:class:`OccludeMesh` takes PyG's mesh ``Data(pos=(V, 3), face=(3, F), y=...)`` — what
``torch_geometric.datasets.ModelNet`` yields — and returns ``Data(pos=(n_points, 3), y=...)``:
one random occluded view (:class:`zbuf_occlude.learn.on_the_fly.RandomOcclusion`), where PyG's
own ``SamplePoints`` would give a complete cloud.  The mesh is normalised to maximum extent 1
(:func:`zbuf_occlude.mesh.load.normalize_mesh`) and sampled densely once per process.

A point cloud ``Data(pos=(N, 3), normal=(N, 3), y=...)`` (no ``face``; ``normal`` optional), what
PyG's point-cloud data sets and ``SamplePoints`` yield, is occluded from its points alone (the
point-set path of :class:`~zbuf_occlude.learn.on_the_fly.RandomOcclusion`): the result's ``pos``
(and ``normal``) are rows of the input's.

PyG gives a transform no sample index, so the view is a function of ``(seed, epoch, content)``
(the BLAKE2b key of the vertex and face bytes, or of the points and normals): deterministic
across workers and runs, new in each epoch after :meth:`OccludeMesh.set_epoch`.
"""

from __future__ import annotations

import hashlib

import numpy as np
import trimesh

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.io.point_sets import PointSet
from zbuf_occlude.learn import require_torch
from zbuf_occlude.learn.on_the_fly import (
    DEFAULT_DENSE_ON_THE_FLY,
    DEFAULT_ON_THE_FLY_METHOD,
    PoseDistribution,
    ProcessCache,
    RandomOcclusion,
)
from zbuf_occlude.mesh.load import normalize_mesh
from zbuf_occlude.mesh.scene import UP_AXES
from zbuf_occlude.pipeline import dense_cloud

__all__ = ["OccludeMesh"]

try:
    from torch_geometric.data import Data
    from torch_geometric.transforms import BaseTransform
except ImportError as exc:  # pragma: no cover - exercised where PyG is absent
    raise BackendUnavailable(f"zbuf_occlude.learn.pyg needs PyTorch Geometric: {install_hint('pyg')} ({exc})") from None

_CACHE_SIZE = 64


class OccludeMesh(BaseTransform):
    """PyG transform: mesh ``Data(pos, face, y)`` or point cloud ``Data(pos[, normal], y)`` → occluded ``Data(pos[, normal], y)``.

    Parameters
    ----------
    n_points, poses, seed, method, normalize
        As :class:`~zbuf_occlude.learn.on_the_fly.RandomOcclusion` (``method`` applies to meshes;
        point clouds use the point splats).
    dense_points : int
        Dense cloud per mesh, sampled once per process.
    up : str
        A point cloud's up axis, from which the elevation of the poses is measured (``+z``;
        ``+y`` for ShapeNet's clouds): :data:`zbuf_occlude.mesh.scene.UP_AXES`.  Meshes are
        taken z up.

    Raises
    ------
    InvalidInputError
        (on call) ``data`` has no ``pos`` (V, 3), a ``face`` that is not (3, F), or a
        ``normal`` that is not (V, 3) beside a point cloud's ``pos``; bad points or normals
        (NaN/inf, zero normals).
    """

    def __init__(self, n_points: int = 2048, *, poses: PoseDistribution = PoseDistribution(), seed: int = 0,
                 method: str = DEFAULT_ON_THE_FLY_METHOD, normalize: bool = True, dense_points: int = DEFAULT_DENSE_ON_THE_FLY,
                 up: str = "+z"):  # fmt: skip
        if up not in UP_AXES:
            raise InvalidInputError(f"up must be one of {', '.join(UP_AXES)}, got {up!r}")
        self.occlusion = RandomOcclusion(n_points, poses=poses, seed=seed, method=method, normalize=normalize)
        self.seed, self.dense_points, self.up = int(seed), int(dense_points), up
        self._meshes = ProcessCache(_CACHE_SIZE)

    def set_epoch(self, epoch: int) -> None:
        """Draw the views of ``epoch``."""
        self.occlusion.set_epoch(epoch)

    def _forward_points(self, data: Data, pos) -> Data:
        """:meth:`forward` of a point cloud ``Data(pos[, normal])``."""
        torch = require_torch()
        normal = getattr(data, "normal", None)
        if normal is not None and (normal.dim() != 2 or tuple(normal.shape) != tuple(pos.shape)):
            raise InvalidInputError(f"OccludeMesh: a point cloud's normal must be (N, 3) like its pos {tuple(pos.shape)}; got {data!r}")
        points = pos.detach().cpu().numpy().astype(np.float64)
        normals = None if normal is None else normal.detach().cpu().numpy().astype(np.float64)
        digest = hashlib.blake2b(points.tobytes() + (b"" if normals is None else normals.tobytes()), digest_size=8).digest()
        key = int.from_bytes(digest, "little")
        sample = self.occlusion(PointSet(points, normals, None, "pyg"), None, key % (2**63), key=key, up=self.up)
        out = Data(pos=torch.from_numpy(sample["points"]))
        if normals is not None:
            out.normal = torch.from_numpy(sample["normals"])
        if getattr(data, "y", None) is not None:
            out.y = data.y
        return out

    def forward(self, data: Data) -> Data:
        torch = require_torch()
        pos, face = getattr(data, "pos", None), getattr(data, "face", None)
        if pos is not None and face is None and pos.dim() == 2 and pos.shape[1] == 3:
            return self._forward_points(data, pos)
        if pos is None or face is None or pos.dim() != 2 or pos.shape[1] != 3 or face.dim() != 2 or face.shape[0] != 3:
            raise InvalidInputError(
                "OccludeMesh needs a mesh Data(pos=(V, 3), face=(3, F)) or a point cloud Data(pos=(N, 3)); got " + repr(data)
            )
        v = pos.detach().cpu().numpy().astype(np.float64)
        f = face.detach().cpu().numpy().T.astype(np.int64)
        key = int.from_bytes(hashlib.blake2b(v.tobytes() + f.tobytes(), digest_size=8).digest(), "little")

        def build():
            mesh = normalize_mesh(trimesh.Trimesh(v, f, process=False))
            return mesh, dense_cloud(mesh, key, seed=self.seed, count=self.dense_points)

        mesh, dense = self._meshes.get_or_build(key, build)
        sample = self.occlusion(mesh, dense, key % (2**63), key=key)
        out = Data(pos=torch.from_numpy(sample["points"]))
        if getattr(data, "y", None) is not None:
            out.y = data.y
        return out

    def __repr__(self) -> str:
        return f"{type(self).__name__}(n_points={self.occlusion.n_points}, method={self.occlusion.method!r})"
