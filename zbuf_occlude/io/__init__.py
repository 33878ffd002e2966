"""Files we write and read: atomic writes, point-cloud formats (npz, ply, PointNet h5), safe paths.

:mod:`.atomic` (every write of the package goes through it), :mod:`.clouds` (one sample per
``.npz``/``.ply`` file, many per ``.h5``), :mod:`.safe_paths` (paths a file names stay inside
its folder), :mod:`.hdf5` (HDF5 files from anyone: only data stored inside them), :mod:`.arrays`
(``.npy``/``.npz`` files from anyone: shapes and sizes read from their headers before inflating),
:mod:`.regular_files` (a file a user or another file names: regular files only, opened without
blocking, sizes checked before reading), :mod:`.caps` (every cap on what a file read may hold,
named for what it caps),
:mod:`.las` (LAS/LAZ point clouds from anyone, with their per-return fields; LAS/LAZ bytes written),
:mod:`.las_layout` (a LAS/LAZ file's header, records and LAZ chunks, checked before laspy reads them),
:mod:`.las_crs` (a LAS file's coordinate unit, from its CRS records), :mod:`.owned` (the one way a
command writes into a user's folder) and :mod:`.deletes` (what it may delete or replace),
:mod:`.file_errors` (errors that name a file, never quote it).
"""

from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.io import atomic, clouds
from zbuf_occlude.io.atomic import *  # noqa: F403  (each module's __all__, re-exported whole)
from zbuf_occlude.io.clouds import *  # noqa: F403
from zbuf_occlude.io.hdf5 import check_hdf5, open_hdf5
from zbuf_occlude.io.las import LasPoints, las_bytes, read_las

__all__ = ["OccludedCloud", *atomic.__all__, *clouds.__all__, "check_hdf5", "open_hdf5", "LasPoints", "las_bytes", "read_las"]
