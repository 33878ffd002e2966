"""Compile the sensors' numba kernels ahead of use, into numba's on-disk cache: the adaptive footprint's loops.

The twin of :mod:`zbuf_occlude.visibility.warmup` (its rules of numba's cache, its reports and
its command line) for :mod:`zbuf_occlude.sensors`: :func:`warm_up` (``python -m
zbuf_occlude.sensors.warmup``, which ``scripts/install.sh`` runs) scans a small scene once with a
spinning LiDAR and once with an airborne preset, each with ``footprint="adaptive"``, so that the
kernels of :mod:`zbuf_occlude.sensors.beam.adaptive_kernel` compile with the argument types of real scans.
"""

from __future__ import annotations

import sys

from zbuf_occlude.visibility.warmup import KernelReport, kernel_reports
from zbuf_occlude.visibility.warmup import kernels as package_kernels
from zbuf_occlude.visibility.warmup import main as warm_up_main

__all__ = ["kernels", "warm_up", "main"]


def kernels() -> dict:
    """Every numba kernel of :mod:`zbuf_occlude.sensors` compiled on its own, by ``module.function``
    (:func:`zbuf_occlude.visibility.warmup.kernels` over this package)."""
    import zbuf_occlude.sensors as package

    return package_kernels(package)


def _exercise() -> None:
    """An adaptive scan of a box on the ground (a spinning LiDAR's sector, an airborne preset's square), then
    :func:`~zbuf_occlude.sensors.beam.footprint.plane_subrays` and :func:`~zbuf_occlude.sensors.beam.adaptive_cast.plane_echoes` on two beams."""
    import numpy as np
    import trimesh

    from zbuf_occlude.sensors import Lidar, ScanScene, airborne_preset, scan, scan_airborne, with_beam

    scene = ScanScene().add(trimesh.creation.box(extents=(2.0, 2.0, 1.5)), class_name="box", position_m=(8.0, 0.0))
    lidar = with_beam(Lidar.preset("vlp16"), footprint_rays=7, max_returns=2, range_resolution_m=0.5)
    scan(scene, lidar, seed=0, azimuth_range_deg=(-20.0, 20.0), footprint="adaptive")
    scan_airborne(scene, airborne_preset("riegl-q1560"), (8.0, 0.0), 3.0, seed=0, footprint="adaptive")
    # the array forms of the same loops (public, not called by a scan)
    from zbuf_occlude.sensors.beam.adaptive_cast import plane_echoes
    from zbuf_occlude.sensors.beam.footprint import footprint_offsets, plane_subrays

    offsets, weights = footprint_offsets(7, 0.2)
    ranges, cosines = plane_subrays(np.full(2, 10.0), np.tile([0.0, 0.0, -1.0], (2, 1)), np.tile([0.0, 0.0, 1.0], (2, 1)), offsets)
    plane_echoes(ranges, cosines, weights)


def warm_up() -> list[KernelReport]:
    """Compile (or load from numba's cache) every kernel of :func:`kernels` in this process.

    Returns
    -------
    list of KernelReport
        One per kernel, as :func:`zbuf_occlude.visibility.warmup.warm_up` gives them.

    Raises
    ------
    BackendUnavailable
        Embree (``embreex``) cannot be imported.
    """
    _exercise()
    return kernel_reports(kernels())


def main(argv: list[str] | None = None) -> int:
    """``python -m zbuf_occlude.sensors.warmup [-q]``: :func:`warm_up`, one line per kernel on stderr (0; 2 for an unknown option)."""
    return warm_up_main(argv, command="python -m zbuf_occlude.sensors.warmup", run=warm_up)


if __name__ == "__main__":
    sys.exit(main())
