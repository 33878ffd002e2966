"""Occlusion on the fly as a PyTorch Geometric transform (the ``pyg`` extra: ``pip install '.[pyg]'`` from a checkout).

:class:`OccludeMesh` takes PyG's mesh ``Data(pos=(V, 3), face=(3, F), y=...)`` — what
``torch_geometric.datasets.ModelNet`` yields — and returns ``Data(pos=(n_points, 3), y=...)``:
one random occluded view (:class:`zbuf_occlude.learn.on_the_fly.RandomOcclusion`), where PyG's
own ``SamplePoints`` would give a complete cloud.  The mesh is normalised to maximum extent 1
(:func:`zbuf_occlude.mesh.load.normalize_mesh`) and sampled densely once per process.

PyG gives a transform no sample index, so the view is a function of ``(seed, epoch, mesh
content)`` (the BLAKE2b key of the vertex and face bytes): deterministic across workers and
runs, new in each epoch after :meth:`OccludeMesh.set_epoch`.
"""

from __future__ import annotations

import hashlib

import numpy as np
import trimesh

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.learn import require_torch
from zbuf_occlude.learn.on_the_fly import (
    DEFAULT_DENSE_ON_THE_FLY,
    DEFAULT_ON_THE_FLY_METHOD,
    PoseDistribution,
    ProcessCache,
    RandomOcclusion,
)
from zbuf_occlude.mesh.load import normalize_mesh
from zbuf_occlude.pipeline import dense_cloud

__all__ = ["OccludeMesh"]

try:
    from torch_geometric.data import Data
    from torch_geometric.transforms import BaseTransform
except ImportError as exc:  # pragma: no cover - exercised where PyG is absent
    raise BackendUnavailable(f"zbuf_occlude.learn.pyg needs PyTorch Geometric: {install_hint('pyg')} ({exc})") from None

_CACHE_SIZE = 64


class OccludeMesh(BaseTransform):
    """PyG transform: mesh ``Data(pos, face, y)`` → occluded ``Data(pos, y)``.

    Parameters
    ----------
    n_points, poses, seed, method, normalize
        As :class:`~zbuf_occlude.learn.on_the_fly.RandomOcclusion`.
    dense_points : int
        Dense cloud per mesh, sampled once per process.

    Raises
    ------
    InvalidInputError
        (on call) ``data`` has no ``pos`` (V, 3) or no ``face`` (3, F).
    """

    def __init__(self, n_points: int = 2048, *, poses: PoseDistribution = PoseDistribution(), seed: int = 0,
                 method: str = DEFAULT_ON_THE_FLY_METHOD, normalize: bool = True, dense_points: int = DEFAULT_DENSE_ON_THE_FLY):  # fmt: skip
        self.occlusion = RandomOcclusion(n_points, poses=poses, seed=seed, method=method, normalize=normalize)
        self.seed, self.dense_points = int(seed), int(dense_points)
        self._meshes = ProcessCache(_CACHE_SIZE)

    def set_epoch(self, epoch: int) -> None:
        """Draw the views of ``epoch``."""
        self.occlusion.set_epoch(epoch)

    def forward(self, data: Data) -> Data:
        torch = require_torch()
        pos, face = getattr(data, "pos", None), getattr(data, "face", None)
        if pos is None or face is None or pos.dim() != 2 or pos.shape[1] != 3 or face.dim() != 2 or face.shape[0] != 3:
            raise InvalidInputError("OccludeMesh needs a mesh Data(pos=(V, 3), face=(3, F)); got " + repr(data))
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
