"""Caps on what a file read may hold: one place per cap, each named for the file it caps.

A cap is the most bytes a read of one kind of file may hold (or a part of such a file: a line,
a header, the arrays an ``.npz`` inflates to).  A file's size is checked against its cap on the
open file (``fstat``) before a byte is read, and the error names the file, its size and the cap
(:func:`zbuf_occlude.io.regular_files.open_regular_file`).  A cap is not what a read allocates:
a read reserves the file's size, never the cap, and stops once the file grew past the cap
(:func:`zbuf_occlude.io.regular_files.read_at_most`).  Every caller names its cap at the call
(``max_bytes=MAX_LIST_BYTES``): a cap not named there is a cap not named for what it caps.

Caps on the sizes a *mesh* declares (its counts, a glTF accessor) are not caps on a read; they
stay with the mesh readers (:mod:`zbuf_occlude.mesh.limits`, :mod:`zbuf_occlude.mesh.formats.gltf`).
"""

from __future__ import annotations

from zbuf_occlude.defaults import MAX_POINTS

__all__ = [
    "MAX_CARD_CHECKSUM_BYTES", "MAX_CHECKPOINT_BYTES", "MAX_CLOUD_NPZ_BYTES", "MAX_CLOUD_NPZ_POINTS", "MAX_LAS_BYTES",
    "MAX_LAS_HEADER_BYTES", "MAX_VLR_RECORD_BYTES", "MAX_LEDGER_BYTES", "MAX_LEDGER_LINE_BYTES", "MAX_LIST_BYTES", "MAX_LOCK_BYTES",
    "MAX_MANIFEST_BYTES",
    "MAX_MESH_FILE_BYTES", "MAX_METADATA_BYTES", "MAX_NPY_HEADER_BYTES", "MAX_POINT_SET_BYTES", "MAX_POINT_SET_PLY_HEADER_BYTES",
    "MAX_PROTOCOL_FILE_BYTES", "MAX_RAY_TABLE_LINE_BYTES", "MAX_REAL_SCAN_ARRAY_BYTES", "MAX_REAL_SCAN_BYTES",
    "MAX_REAL_SCAN_LINE_BYTES", "MAX_SCAN_NPZ_BYTES", "MAX_SPEC_FILE_BYTES", "MAX_TABLE_BYTES", "MAX_TRAJECTORY_BYTES",
    "MAX_TRAJECTORY_LINE_BYTES", "MAX_TRAJECTORY_POSES",
]  # fmt: skip

# -- text and metadata ------------------------------------------------------------------------------

#: Largest text list read (``shape_names.txt``, split lists, ``--list`` files, file lists of a data
#: set): 64 MiB, some 500,000 paths of 128 bytes; ShapeNetCore's largest list is under 3 MiB.
MAX_LIST_BYTES = 64 << 20
#: Largest JSON metadata file read whole (a card, a plan, a record, a protocol record, a layout's
#: index): 256 MiB; a data-set card of 200,000 samples is a few MiB.
MAX_METADATA_BYTES = 256 << 20
#: Largest lock file read: a lock holds a pid and a host name, a few dozen bytes.
MAX_LOCK_BYTES = 512
#: Largest table read: 256 MiB, a million rows of 250 bytes; the comparison's ``results.csv`` of
#: every method, size and view of a mesh set is a few MiB.
MAX_TABLE_BYTES = 256 << 20
#: Largest scene or sensor file, bytes (16 MiB): a scene of the most objects a file may hold
#: (:data:`~zbuf_occlude.sensors.checks.MAX_SCENE_OBJECTS`) takes about 2 MB.
MAX_SPEC_FILE_BYTES = 16 << 20

# -- meshes -----------------------------------------------------------------------------------------

#: Largest mesh file, or file a mesh names (a glTF buffer, an OBJ material, a texture), read: 2 GiB.
#: glTF buffers are addressed with 32-bit byte lengths and a GLB is at most 4 GiB by its uint32
#: length field; a buffer larger than this is not an object's mesh.
MAX_MESH_FILE_BYTES = 2 << 30

# -- data sets and the files a command keeps ---------------------------------------------------------

#: Largest ``manifest.jsonl`` read: 4 GiB.  One line per object, of a few kB (a ``generate
#: --format npz`` object lists each sample file with its SHA-256: some 40 kB), so 100,000 such
#: objects or a million HDF5 ones; a larger file is not a manifest of ours.
MAX_MANIFEST_BYTES = 4 << 30
#: Largest ``card.sha256`` read: its one line is 64 hex digits, two spaces and the card's name.
MAX_CARD_CHECKSUM_BYTES = 200
#: Longest ``protocol.json`` read to name the protocol (the file is small; a large one is not ours).
MAX_PROTOCOL_FILE_BYTES = 1 << 20
#: Largest ledger read: 256 MiB, some two million files of ours (a line is about 130 bytes).
MAX_LEDGER_BYTES = 256 << 20
#: A ledger line longer than this is damaged (a path is at most a few hundred bytes).
MAX_LEDGER_LINE_BYTES = 8192
#: Largest checkpoint read: 32 GiB.  The largest model :func:`zbuf_occlude.learn.models.check_model_config`
#: lets a checkpoint build (3DmFV-Net at width 8, ``fv_grid`` 16, 1,000 classes) holds 5.6 GiB of
#: float32 weights, and a resume point (``last.pt``) holds them four times (the weights, the best
#: weights and Adam's two moments): some 23 GiB.
MAX_CHECKPOINT_BYTES = 32 << 30

# -- point clouds -----------------------------------------------------------------------------------

#: Points one cloud ``.npz`` may hold (:func:`zbuf_occlude.io.clouds.read_npz`): the most
#: ``--points`` takes (:data:`zbuf_occlude.defaults.MAX_POINTS`).
MAX_CLOUD_NPZ_POINTS = MAX_POINTS
#: Bytes a cloud ``.npz``'s arrays may inflate to: :data:`MAX_CLOUD_NPZ_POINTS` points of float64
#: coordinates (24 bytes) and an int64 ``face_index`` (8 bytes), and 1 MiB for the scalars (the
#: class name and the source path are text of any length).
MAX_CLOUD_NPZ_BYTES = MAX_CLOUD_NPZ_POINTS * (3 * 8 + 8) + (1 << 20)
#: Bytes one read of a point-set file may take, as float64 coordinates and normals, and the largest
#: ``.ply`` point cloud read: 2 GiB (``modelnet40_ply_hdf5_2048``'s largest file is 100 MB so read).
MAX_POINT_SET_BYTES = 2 << 30
#: Bytes of a point-set PLY header read to find its elements (a header is a few hundred bytes).
MAX_POINT_SET_PLY_HEADER_BYTES = 1 << 16
#: Longest ``.npy`` header read: numpy's own ``max_header_size`` default (``numpy.lib.format``),
#: past which numpy refuses to parse a header as unsafe; an (N, 3) array's header is 128 bytes.
MAX_NPY_HEADER_BYTES = 10_000
#: Largest LAS/LAZ file read: 16 GiB, :data:`~zbuf_occlude.defaults.MAX_POINTS` (10⁸) points of
#: the largest standard record (67 bytes, format 10) and some extra bytes per point.  A 1 km² tile
#: of a national survey holds 10 to 50 million points.
MAX_LAS_BYTES = 16 << 30
#: Most bytes of a LAS/LAZ file before the first point (header, VLRs and any gap), which laspy
#: reads into memory: :data:`zbuf_occlude.io.las_layout.MAX_VLRS` records of at most 65,589 bytes
#: (a 54-byte header and a uint16 length) are 33.6 MB.
MAX_LAS_HEADER_BYTES = 64 << 20
#: Most bytes a VLR's record holds, written or read: its record length is a uint16 (ASPRS LAS 1.4 R15 §2.5).
MAX_VLR_RECORD_BYTES = 65535

# -- scans ------------------------------------------------------------------------------------------

#: Largest scan ``.npz`` read (:func:`zbuf_occlude.sensors.scan_data.read_scan_npz`), inflated: 4 GiB (a
#: 128-beam sweep of a street is ~2.6 M returns, ~0.1 GB in this layout); checked from the zip
#: directory and the array headers before reading.
MAX_SCAN_NPZ_BYTES = 4 << 30
#: Longest line of a CSV ray table, line end included: a row written to round trip takes at most
#: 76 bytes (:data:`zbuf_occlude.io.ray_tables.CSV_BYTES_PER_ROW`); a kilobyte leaves room for
#: spaces and padding.
MAX_RAY_TABLE_LINE_BYTES = 1024
#: Largest real scan file read (a scan of one object is kilobytes to megabytes): 1 GiB.
MAX_REAL_SCAN_BYTES = 1 << 30
#: Bytes a real scan's ``.npy``/``.npz`` may declare once inflated: the same 1 GiB as a file.  A zip
#: member compresses 1000:1 (zeros), so the cap is checked against the sizes the zip directory and
#: the ``.npy`` header declare, before anything is read.
MAX_REAL_SCAN_ARRAY_BYTES = MAX_REAL_SCAN_BYTES
#: Longest line of a real text scan: 4 KiB.  A row is a few numbers (x y z, intensity, a label);
#: a longer line is not a row, and splitting a 1 GB line takes ~50x its size in Python strings.
MAX_REAL_SCAN_LINE_BYTES = 4096
#: Largest trajectory CSV read (:func:`zbuf_occlude.sensors.platform.load_trajectory`), read whole:
#: 128 MiB, :data:`MAX_TRAJECTORY_POSES` rows of ~130 bytes (a ROS odometry row printed in full: a
#: 10-digit time to the nanosecond, three positions, a quaternion of 17 digits); 6 decimals take ~70.
MAX_TRAJECTORY_BYTES = 128 << 20
#: Most poses (rows) one trajectory holds: a million, three hours of odometry at 100 Hz.  Checked on
#: the file's line count before a row is parsed, so a file of short lines is refused unsplit.
MAX_TRAJECTORY_POSES = 1_000_000
#: Longest line of a trajectory CSV, line end included: a row of eight numbers written to round
#: trip (``%.17g``: at most 24 characters each) takes under 200 bytes; a kilobyte leaves room for spaces.
MAX_TRAJECTORY_LINE_BYTES = 1024
