"""Classifiers trained on generated clouds: the evidence of Sryamkin et al. 2023, Table 3.

An optional part of zbuf_occlude (the ``learn`` extra: ``pip install '.[learn]'`` from a checkout; PyTorch); the core
package never imports it.  Modules:

``models``       PointNet, VoxNet, 3DmFV-Net (torch)
``data``         clouds from a farm data set or from meshes, augmentation (numpy)
``training``     one deterministic, resumable training loop with early stopping (torch)
``metrics``      overall / mean class / per-class accuracy, confusion, per elevation (numpy)
``stats``        mean ± std over seeds, the exact permutation test (numpy)
``experiments``  (:mod:`zbuf_occlude.experiments`) the Table 3A and 3B protocols (``table3``) and
                 training on clouds from meshes, tested on real scans (``sim2real``)
``cli``          ``zbuf-occlude experiment elevation|augmentation|sim2real``
``on_the_fly``   occlusion as a training-time transform: ``RandomOcclusion`` (of a ``DenseCloud``:
                 :class:`zbuf_occlude.pipeline.DenseCloud`, re-exported here), ``OnTheFlyOccludedDataset``
``pyg``          the same as a PyTorch Geometric transform (``pip install '.[pyg]'``)
"""

from __future__ import annotations

__all__ = ["require_torch", "RandomOcclusion", "OnTheFlyOccludedDataset", "PoseDistribution", "EpochSampler", "DenseCloud"]

#: Where each lazily imported public name lives.
_LAZY = {
    **{
        name: "zbuf_occlude.learn.on_the_fly" for name in ("RandomOcclusion", "OnTheFlyOccludedDataset", "PoseDistribution", "EpochSampler")
    },
    "DenseCloud": "zbuf_occlude.pipeline",  # what RandomOcclusion takes; needs no torch
}


def __getattr__(name: str):
    # imported on first use: ``import zbuf_occlude.learn`` (the CLI does) must not import torch
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def require_torch():
    """Import torch or raise :class:`~zbuf_occlude.errors.BackendUnavailable` saying how to install it."""
    from zbuf_occlude._version import install_hint
    from zbuf_occlude.errors import BackendUnavailable

    try:
        import torch
    except ImportError:
        raise BackendUnavailable(
            f"zbuf_occlude.learn needs PyTorch: {install_hint('learn')} "
            "(CPU build; for CUDA: pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cu126)"
        ) from None
    return torch
