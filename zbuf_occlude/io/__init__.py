"""Files we write and read: atomic writes, point-cloud formats (npz, ply, PointNet h5), safe paths.

:mod:`.atomic` (every write of the package goes through it), :mod:`.clouds` (one sample per
``.npz``/``.ply`` file, many per ``.h5``), :mod:`.safe_paths` (paths a file names stay inside
its folder), :mod:`.hdf5` (HDF5 files from anyone: only data stored inside them).
"""

from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.io.atomic import (
    TempOwner,
    atomic_h5,
    atomic_path,
    file_sha256,
    temp_is_orphan,
    temp_owner,
    write_csv,
    write_text,
)
from zbuf_occlude.io.hdf5 import check_hdf5, open_hdf5
from zbuf_occlude.io.clouds import (
    FORMATS,
    clouds_of_h5,
    concat_h5,
    read_h5,
    read_h5_clouds,
    read_npz,
    write_h5,
    write_npz,
    write_ply,
)

__all__ = [
    "OccludedCloud",
    "atomic_path",
    "atomic_h5",
    "TempOwner",
    "temp_owner",
    "temp_is_orphan",
    "file_sha256",
    "write_text",
    "write_csv",
    "write_npz",
    "read_npz",
    "write_ply",
    "write_h5",
    "concat_h5",
    "read_h5",
    "read_h5_clouds",
    "clouds_of_h5",
    "FORMATS",
    "check_hdf5",
    "open_hdf5",
]
