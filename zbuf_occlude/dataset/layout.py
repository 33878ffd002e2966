"""The on-disk layout of zbuf_occlude's outputs: file names, format version, schemas.

One module, no imports of the package: the writers (:mod:`zbuf_occlude.io.clouds`, the farm's
worker and journal, ``generate``) and the reader (:class:`~zbuf_occlude.dataset.reader.OccludedDataset`)
take every name from here, so they cannot drift apart.

A data set folder (``farm --out``, ``generate --out``), ``format_version`` :data:`FORMAT_VERSION`::

    DATASET/
      dataset_card.json      parameters, poses, tool version, command lines, GL renderers;
                             written last: it marks the data set finished
      dataset_card.json.sha256
                             the card's SHA-256 (``sha256sum`` format), written right after it
      shape_names.txt        one class name per line; line i is label i (PointNet)
      train_files.txt        files of the train split, one per line, paths relative to
                             DATASET (PointNet's file list): the farm's shards; generate's
                             occluded_train.h5 (h5) or sample files (npz, ply)
      test_files.txt         ... of the test split
      manifest.jsonl         one JSON record per object: source, class, split, status, error,
                             files and their SHA-256, visible-point counts per pose, seed, key
      shards/<split>_<object_index:06d>.h5
                             one shard per object (the unit a resumed run never redoes)
      records/<object_index:06d>.json, tasks/, plan.json
                             the journal (resume, parameters, sharded runs, farm-merge)
      .zbuf_occlude.lock     held while a run or merge writes (tasks/lock-I-of-N.lock for
                             a --shard I/N task); see zbuf_occlude.farm.lock

``generate`` writes the same journal, and per sample ``DATASET/<name>/<stem>_vPPP_el±EEE_
azAAA_sSS.npz|ply`` (``--format npz|ply``), or per object a shard with
:data:`PROVENANCE_COLUMNS` and, joined per split, ``DATASET/occluded_<split>.h5``
(:func:`split_file_name`; ``--format h5``, the default): a split's samples never share a
file with another split's, and each row's ``split`` column names its split.

Storage modes of a shard (``storage`` in the card):

``dense`` (farm) and ``h5`` (generate)
    PointNet's HDF5 layout, :data:`POINTNET_COLUMNS` (``data (B, n, 3) float32``,
    ``label (B,) int64``, ``elevation_deg``/``azimuth_deg (B,) float64`` degrees) plus
    :data:`INDEX_COLUMNS` ``(B,) int64``; ``h5`` adds :data:`PROVENANCE_COLUMNS`.
``compact`` (farm)
    :data:`COMPACT_DATASETS`: the object's dense cloud once, ``dense_points (M, 3)
    float32``, and per pose a visibility bitmask ``visible_bits (P, ceil(M / 8)) uint8``
    (:func:`numpy.packbits`), plus ``n_visible``, ``elevation_deg``, ``azimuth_deg (P,)``;
    the reader redraws the samples bit-identically (:func:`zbuf_occlude.geometry.samples.pose_samples`).
``dense`` of ``farm --sensor``
    The dense columns, each scan's placement, ``ring (B, n) int16`` and, when the sensor records
    several returns per pulse, :data:`POINT_COLUMNS`: a LiDAR's return fields, ``(B, n)`` each,
    one value per point of ``data``, declared by the object's manifest record (``point_columns``).

Row order inside a shard, and sample order of the reader: pose-major, then sample index.
Integrity: every file of an object has its SHA-256 in the object's record and the manifest
(``sha256``, parallel to ``shards``); resume and the reader compare them.
"""

from __future__ import annotations

from typing import NamedTuple

from zbuf_occlude.io.locks import LOCK_FILE  # the data-set lock (zbuf_occlude.farm.lock): the output layer's

__all__ = [
    "FORMAT_VERSION",
    "CARD_FILE",
    "CARD_SHA256_FILE",
    "MANIFEST_FILE",
    "SHAPE_NAMES_FILE",
    "SHARD_DIR",
    "RECORD_DIR",
    "TASK_DIR",
    "PLAN_FILE",
    "PROTOCOL_FILE",
    "LOCK_FILE",
    "SPLIT_FILE_PREFIX",
    "split_file_name",
    "STORAGE_MODES",
    "SAMPLE_FILE_FORMATS",
    "GENERATE_STORAGES",
    "POINTNET_COLUMNS",
    "INDEX_COLUMNS",
    "PROVENANCE_COLUMNS",
    "COMPACT_DATASETS",
    "COLUMN_TYPES",
    "POINT_COLUMNS",
    "PointColumn",
    "MAX_RETURN_NUMBER",
    "file_list_name",
    "shard_name",
    "record_name",
    "task_lock_name",
    "sample_file_name",
]

#: Version of the layout above; readers refuse newer ones.  2: compact shards hold top-up points.
FORMAT_VERSION = 2
CARD_FILE = "dataset_card.json"
#: The card's SHA-256, ``<hex>  dataset_card.json`` (``sha256sum -c`` reads it); data sets
#: written before it existed have none and still read.
CARD_SHA256_FILE = "dataset_card.json.sha256"
MANIFEST_FILE = "manifest.jsonl"
SHAPE_NAMES_FILE = "shape_names.txt"
SHARD_DIR = "shards"
#: The journal.
RECORD_DIR, TASK_DIR, PLAN_FILE = "records", "tasks", "plan.json"
#: The options of a ``generate --protocol`` folder (zbuf_occlude.protocols), which is not a data set of this layout.
PROTOCOL_FILE = "protocol.json"
#: ``generate --format h5``'s joined files, one per split: ``occluded_<split>.h5``.
SPLIT_FILE_PREFIX = "occluded_"
#: The farm's storage modes, which :class:`~zbuf_occlude.dataset.reader.OccludedDataset` reads.
STORAGE_MODES = ("dense", "compact")
#: ``generate``'s one-file-per-sample formats.
SAMPLE_FILE_FORMATS = ("npz", "ply")
#: Every ``generate --format``: one PointNet part per object (``h5``) or a file per sample.
GENERATE_STORAGES = ("h5", *SAMPLE_FILE_FORMATS)
#: PointNet's datasets, one row per sample.
POINTNET_COLUMNS = ("data", "label", "elevation_deg", "azimuth_deg", "sample_index", "n_visible")
#: Per-row indices the farm and generate add (int64).
INDEX_COLUMNS = ("object_index", "pose_index")
#: What ``generate --format h5`` adds: ``face_index (B, n) int32``, ``radius (B,) float64``,
#: ``source``, ``class_name`` and ``split (B,)`` UTF-8.
PROVENANCE_COLUMNS = ("face_index", "radius", "source", "class_name", "split")
#: Datasets of a compact shard (format 1 shards lack the last two).
COMPACT_DATASETS = ("dense_points", "visible_bits", "n_visible", "elevation_deg", "azimuth_deg", "n_topped_up", "topup_points")
#: What each dataset of a shard holds: ``(kinds, ndim)``, kinds from ``"f"`` float, ``"i"``/``"u"``
#: integer, ``"T"`` string (:class:`zbuf_occlude.io.hdf5.Column`).  The reader and ``verify``
#: refuse a shard whose dataset differs (a string or integer ``data`` is not points).
COLUMN_TYPES = {
    "data": ("f", 3), "label": ("iu", 1), "elevation_deg": ("f", 1), "azimuth_deg": ("f", 1),
    "sample_index": ("iu", 1), "n_visible": ("iu", 1), "object_index": ("iu", 1), "pose_index": ("iu", 1),
    "face_index": ("iu", 2), "radius": ("f", 1), "source": ("T", 1), "class_name": ("T", 1), "split": ("T", 1),
    "dense_points": ("f", 2), "visible_bits": ("u", 2), "n_topped_up": ("iu", 1), "topup_points": ("f", 2),
    # farm --sensor rows (zbuf_occlude.sensors.crops.farm_datasets)
    "distance_m": ("f", 1), "sensor_height_m": ("f", 1), "object_azimuth_deg": ("f", 1), "yaw_deg": ("f", 1),
    "size_m": ("f", 1), "ring": ("iu", 2), "hidden_below_m": ("f", 1), "width_scale": ("f", 1),
    # their return fields (POINT_COLUMNS)
    "return_number": ("u", 2), "number_of_returns": ("u", 2), "intensity": ("f", 2), "pulse_id": ("i", 2),
    "gps_time": ("f", 2), "scan_angle_deg": ("f", 2),
}  # fmt: skip

#: Most returns of one pulse: LAS 1.4 point formats 6-10 keep the return number and the number of
#: returns in 4 bits each (ASPRS LAS 1.4 R15, Table 15), so 1 <= return_number <= number_of_returns <= 15.
MAX_RETURN_NUMBER = 15


class PointColumn(NamedTuple):
    """One per-point column a shard may keep beside ``data``: ``(B, n)`` of ``dtype``, each value
    in ``[low, high]`` (finite), in ``unit``."""

    dtype: str
    low: float
    high: float
    unit: str


#: The per-point columns a ``farm --sensor`` shard keeps when its sensor records several returns per
#: pulse: the return fields of :class:`zbuf_occlude.sensors.scan_data.Scan` (LAS 1.4's Return Number,
#: Number of Returns, Intensity, GPS Time and Scan Angle, and the pulse each return came from), in
#: this order, stored as the scan holds them.  ``return_number`` is also at most its point's
#: ``number_of_returns``; ``scan_angle_deg`` spans LAS 1.4's ±180°.
POINT_COLUMNS = {
    "return_number": PointColumn("uint8", 1, MAX_RETURN_NUMBER, "position among its pulse's returns, range order"),
    "number_of_returns": PointColumn("uint8", 1, MAX_RETURN_NUMBER, "returns its pulse recorded"),
    "intensity": PointColumn("float32", 0.0, float("inf"), "received energy, m^-2"),
    "pulse_id": PointColumn("int64", 0, 2**63 - 1, "the pulse, unique within its scan"),
    "gps_time": PointColumn("float64", float("-inf"), float("inf"), "firing time of its pulse, seconds"),
    "scan_angle_deg": PointColumn("float32", -180.0, 180.0, "scan angle, degrees"),
}


def file_list_name(split: str) -> str:
    """PointNet's name of a split's shard list, e.g. ``train_files.txt``."""
    return f"{split}_files.txt"


def split_file_name(split: str) -> str:
    """``generate --format h5``'s file of one split relative to the data set folder, e.g.
    ``occluded_train.h5`` (listed in ``train_files.txt``)."""
    return f"{SPLIT_FILE_PREFIX}{split}.h5"


def shard_name(split: str, object_index: int) -> str:
    """An object's shard relative to the data set folder, ``shards/<split>_<index:06d>.h5``."""
    return f"{SHARD_DIR}/{split}_{object_index:06d}.h5"


def record_name(object_index: int) -> str:
    """An object's record relative to the data set folder, ``records/<index:06d>.json``."""
    return f"{RECORD_DIR}/{object_index:06d}.json"


def task_lock_name(task: int, n_tasks: int) -> str:
    """The lock of ``--shard I/N`` task ``I`` relative to the data set folder."""
    return f"{TASK_DIR}/lock-{task}-of-{n_tasks}.lock"


def sample_file_name(name: str, pose_index: int, elevation_deg: float, azimuth_deg: float, sample_index: int, fmt: str) -> str:
    """``generate``'s file of one sample relative to ``--out``, e.g.
    ``chair/train/chair_0001/chair_0001_v007_el+030_az045_s03.npz``: the pose index keeps
    names unique, the angles (whole degrees) keep them readable."""
    stem = name.rsplit("/", 1)[-1]
    return f"{name}/{stem}_v{pose_index:03d}_el{elevation_deg:+04.0f}_az{azimuth_deg:03.0f}_s{sample_index:02d}.{fmt}"
