"""The returns of one scan, :class:`Scan`, and its files: NPZ (written and read back, checked), PLY, LAS/LAZ.

Written by :func:`zbuf_occlude.sensors.scan.scan`; read back by :func:`read_scan_npz`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.arrays import load_npz
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.caps import MAX_SCAN_NPZ_BYTES
from zbuf_occlude.io.encodings import npz_bytes

__all__ = ["FRAMES", "Scan", "read_scan_npz"]

#: Frames a scan's points can be given in.
FRAMES = ("sensor", "world")


@dataclass
class Scan:
    """One scan: the returns of one sensor sweep (or frame).

    Attributes
    ----------
    points : (N, 3) float32
        Return positions (noise included), metres, in ``frame``.
    ring : (N,) int32 or None
        LiDAR beam index (row of ``Lidar.elevations_deg``); None for cameras.
    pixel : (N, 2) int32 or None
        Camera pixel ``(u, v)`` (column, row); None for LiDARs.
    range_m : (N,) float32
        Measured distance from the sensor centre, metres (noise included).
    face_index : (N,) int64
        Row of the face hit in its object's own mesh (as loaded; the ground's quad: 0 or 1).
    object_id : (N,) int32
        Scene object hit (0: ground; objects, then occluders, from 1).
    normal : (N, 3) float32
        Unit normal of the face hit, facing the sensor, in ``frame``.
    incidence_deg : (N,) float32
        Angle between the ray and that normal, degrees in [0, 90].
    frame : {"sensor", "world"}
    sensor_position : (3,) float64
        Sensor centre in ``frame`` (zeros in the sensor frame).
    sensor_to_world : (4, 4) float64
    sensor : str
        Sensor name.
    meta : dict
        Backend, ray counts and the like (not written to files).
    return_number : (N,) uint8 or None
        LiDAR: 1..n, the point's position among its pulse's returns in range order (LAS
        "Return Number").  1 everywhere with one return per pulse (``Lidar.max_returns`` 1).
    number_of_returns : (N,) uint8 or None
        LiDAR: n, the returns its pulse recorded, the same on every point of the pulse.
    intensity : (N,) float32 or None
        LiDAR: received energy, ``ρ cos θ f / R²`` in m⁻² (:func:`~.echoes.hit_energy`, the
        units of ``Lidar.detection_threshold``), power noise included.  With the multi-return
        model, the echo's energy; with one return per pulse, the received power the detection
        test uses when ``reflectivity`` is given, and 1.0 when it is not (no radiometry).
    pulse_id : (N,) int64 or None
        LiDAR: ``ring · Lidar.n_azimuths + azimuth index``, unique per pulse of one scan; the
        returns of one pulse share it (airborne: the pulse's row among the plan's pulses; a ray
        table: the pulse's row in the table).
    gps_time : (N,) float64 or None
        LiDAR: firing time of the pulse, seconds from the revolution's first firing
        (``(azimuth index + b / n_beams) / (n_azimuths · rotation_hz)``, beam ``b`` firing
        ``b / n_beams`` of a cycle after the cycle's first: every pulse a time of its own);
        the returns of one pulse share it (airborne: the firing time along the flight line,
        :func:`~zbuf_occlude.sensors.airborne.scan_airborne`; a ray table: its row's ``time_s``,
        exactly).
    scan_angle_deg : (N,) float32 or None
        LiDAR: the beam's elevation, degrees (the spinning scanner's scan angle; a ray table: its
        row's elevation); airborne: the across-track angle from nadir, signed as ASPRS LAS 1.4
        defines it.

    The LiDAR-only arrays are None for depth cameras.
    """

    points: NDArray[np.float32]
    ring: NDArray[np.int32] | None
    pixel: NDArray[np.int32] | None
    range_m: NDArray[np.float32]
    face_index: NDArray[np.int64]
    object_id: NDArray[np.int32]
    normal: NDArray[np.float32]
    incidence_deg: NDArray[np.float32]
    frame: str = "sensor"
    sensor_position: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    sensor_to_world: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))
    sensor: str = ""
    meta: dict = field(default_factory=dict)
    return_number: NDArray[np.uint8] | None = None
    number_of_returns: NDArray[np.uint8] | None = None
    intensity: NDArray[np.float32] | None = None
    pulse_id: NDArray[np.int64] | None = None
    gps_time: NDArray[np.float64] | None = None
    scan_angle_deg: NDArray[np.float32] | None = None

    #: Per-point arrays of every scan, in file order.
    _BASE = ("points", "ring", "pixel", "range_m", "face_index", "object_id", "normal", "incidence_deg")
    #: Per-point arrays of a LiDAR's returns (None for other sensors), written after the rest.
    _RETURNS = ("return_number", "number_of_returns", "intensity", "pulse_id", "gps_time", "scan_angle_deg")
    _PER_POINT = _BASE + _RETURNS

    def __len__(self) -> int:
        return len(self.points)

    def select(self, mask: ArrayLike) -> Scan:
        """The returns where ``mask`` (bool or index array) holds."""
        changes = {k: (None if getattr(self, k) is None else getattr(self, k)[mask]) for k in self._PER_POINT}
        return replace(self, **changes, meta=dict(self.meta))

    def crop(self, object_id: int) -> Scan:
        """The returns of one scene object (occlusion by every other object included)."""
        return self.select(self.object_id == int(object_id))

    def arrays(self) -> dict[str, np.ndarray]:
        """The NPZ content: every present per-point field of the base set, ``sensor_position``,
        ``sensor_to_world``, ``frame`` and ``sensor`` (0-d strings), then the present return fields
        (``return_number`` ... ``scan_angle_deg``)."""
        out = {k: getattr(self, k) for k in self._BASE if getattr(self, k) is not None}
        out.update(sensor_position=np.asarray(self.sensor_position, np.float64), sensor_to_world=self.sensor_to_world,
                   frame=np.array(self.frame), sensor=np.array(self.sensor))  # fmt: skip
        out.update({k: getattr(self, k) for k in self._RETURNS if getattr(self, k) is not None})
        return out

    def to_npz(self, path: str | os.PathLike) -> Path:
        """Write :meth:`arrays` to ``path`` (atomic, uncompressed)."""
        return write_bytes(path, npz_bytes(self.arrays()))

    def to_ply(self, path: str | os.PathLike) -> Path:
        """Write binary little-endian PLY: x y z, nx ny nz (float32), range_m, incidence_deg
        (float32), ring or u v (int32), face_index, object_id (int32); the sensor position
        and frame in header comments.  Readable by Open3D, trimesh, CloudCompare."""
        cols = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
                ("range_m", "<f4"), ("incidence_deg", "<f4")]  # fmt: skip
        cols += [("ring", "<i4")] if self.ring is not None else [("u", "<i4"), ("v", "<i4")] if self.pixel is not None else []
        cols += [("face_index", "<i4"), ("object_id", "<i4")]
        rows = np.empty(len(self), dtype=cols)
        rows["x"], rows["y"], rows["z"] = self.points.T
        rows["nx"], rows["ny"], rows["nz"] = self.normal.T
        rows["range_m"], rows["incidence_deg"] = self.range_m, self.incidence_deg
        if self.ring is not None:
            rows["ring"] = self.ring
        elif self.pixel is not None:
            rows["u"], rows["v"] = self.pixel.T
        rows["face_index"], rows["object_id"] = self.face_index, self.object_id
        kind = {"<f4": "float", "<i4": "int"}
        header = ["ply", "format binary_little_endian 1.0", f"comment zbuf_occlude scan sensor {self.sensor or '-'} frame {self.frame}",
                  "comment sensor_position " + " ".join(f"{v:.9g}" for v in self.sensor_position), f"element vertex {len(self)}"]  # fmt: skip
        header += [f"property {kind[t]} {name}" for name, t in cols] + ["end_header"]
        return write_bytes(path, ("\n".join(header) + "\n").encode("ascii") + rows.tobytes())

    def to_las_bytes(self, compress: bool = False, *, intensity_full_scale: float = 1.0) -> bytes:
        """The scan as the bytes of a LAS 1.4 file, point format 6 (LAZ with ``compress``), in memory.

        Through :func:`zbuf_occlude.io.las.las_bytes`: coordinates in ``frame`` (the sensor's or
        the world's, as the scan holds them), metres, stored in steps of 1 mm; no coordinate
        reference system.  Per point: ``return_number``, ``number_of_returns``, ``gps_time``
        (seconds from the sweep's first firing; airborne: along the flight line), ``scan_angle_deg``
        (a spinning scanner: the beam's elevation; airborne: the across-track angle), and the
        intensity ``round(65535 · min(intensity / intensity_full_scale, 1))``.  A scan without
        these fields (a depth camera's) is written as one return per point, time 0, scan angle
        0, intensity 0.

        Parameters
        ----------
        compress : bool
            LAZ (LASzip through lazrs) instead of LAS.
        intensity_full_scale : float
            The received energy (m⁻², :attr:`intensity`) stored as 65535, > 0; 1.0 (default): a
            white Lambertian target at normal incidence, 1 m away, filling the beam.  Scans with
            one return per pulse and no ``reflectivity`` (intensity 1.0) store 65535.

        Returns
        -------
        bytes
            The whole file; write it with :meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes`
            or :func:`~zbuf_occlude.io.atomic.write_bytes`.

        Raises
        ------
        InvalidInputError
            ``intensity_full_scale`` not a finite number > 0, or points too far apart for int32
            steps of 1 mm (:func:`~zbuf_occlude.io.las.las_bytes`).
        """
        from zbuf_occlude.io.las import las_bytes
        from zbuf_occlude.sensors.checks import real

        full = real(intensity_full_scale, "intensity_full_scale", low=0.0, low_open=True)
        n = len(self)
        ones = np.ones(n, np.uint8)
        if self.intensity is None:
            intensity = np.zeros(n, np.uint16)
        else:
            share = np.clip(np.asarray(self.intensity, np.float64) / full, 0.0, 1.0)
            intensity = np.rint(share * 65535.0).astype(np.uint16)
        return las_bytes(
            np.asarray(self.points, np.float64), intensity=intensity,
            return_number=ones if self.return_number is None else self.return_number,
            number_of_returns=ones if self.number_of_returns is None else self.number_of_returns,
            gps_time=np.zeros(n) if self.gps_time is None else self.gps_time,
            scan_angle_deg=np.zeros(n) if self.scan_angle_deg is None else np.asarray(self.scan_angle_deg, np.float64),
            scale=0.001, compress=compress,
        )  # fmt: skip

    def to_las(self, path: str | os.PathLike, compress: bool = False) -> Path:
        """Write :meth:`to_las_bytes` to ``path`` (atomic); LAZ with ``compress``."""
        return write_bytes(path, self.to_las_bytes(compress))

    def to_laz(self, path: str | os.PathLike) -> Path:
        """Write :meth:`to_las_bytes` compressed (LAZ) to ``path`` (atomic)."""
        return self.to_las(path, compress=True)


#: Per-point arrays of a scan NPZ: (columns or None for (N,), dtype kinds accepted); "f" = any
#: real number (integers too), "i" = integers only.
_NPZ_PER_POINT = {"points": (3, "f"), "range_m": (None, "f"), "face_index": (None, "i"), "object_id": (None, "i"),
                  "normal": (3, "f"), "incidence_deg": (None, "f"), "ring": (None, "i"), "pixel": (2, "i"),
                  "return_number": (None, "i"), "number_of_returns": (None, "i"), "intensity": (None, "f"),
                  "pulse_id": (None, "i"), "gps_time": (None, "f"), "scan_angle_deg": (None, "f")}  # fmt: skip
_KINDS = {"f": "fiu", "i": "iu"}


def _checked_npz(path: Path, d: dict[str, np.ndarray]) -> None:
    """Shapes and dtypes of a scan NPZ's arrays, each error naming the file and the key."""
    n = None
    for key, (cols, kind) in _NPZ_PER_POINT.items():
        if key not in d:
            continue
        a = d[key]
        want = "(N,)" if cols is None else f"(N, {cols})"
        if a.dtype.kind not in _KINDS[kind] or a.ndim != (1 if cols is None else 2) or (cols is not None and a.shape[1] != cols):
            raise InvalidInputError(f"{path}: {key} must be a {want} {'number' if kind == 'f' else 'integer'} array, "
                                    f"got shape {a.shape} dtype {a.dtype}")  # fmt: skip
        if n is not None and len(a) != n:
            raise InvalidInputError(f"{path}: {key} has {len(a)} rows but points has {n}")
        n = len(a) if n is None else n
    for key, shape in (("sensor_position", (3,)), ("sensor_to_world", (4, 4))):
        a = d.get(key)
        if a is None:
            continue
        if a.dtype.kind not in "fiu" or a.shape != shape or not np.isfinite(a).all():
            raise InvalidInputError(f"{path}: {key} must be a finite {shape} number array, got shape {a.shape} dtype {a.dtype}")
    for key in ("frame", "sensor"):
        if key in d and (d[key].dtype.kind != "U" or d[key].ndim != 0):
            raise InvalidInputError(f"{path}: {key} must be a string, got shape {d[key].shape} dtype {d[key].dtype}")
    if "frame" in d and str(d["frame"]) not in FRAMES:
        raise InvalidInputError(f"{path}: frame must be one of {FRAMES}, got {str(d['frame'])!r}")
    if "points" in d and d["points"].ndim == 2:
        bad = int((~np.isfinite(d["points"].astype(np.float64, copy=False))).any(axis=1).sum())
        if bad:
            raise InvalidInputError(
                f"{path}: {bad} point{' has' if bad == 1 else 's have'} NaN or inf coordinates: the scan is damaged; "
                "write it again with `zbuf-occlude scan` or move it out of the folder"
            )


def read_scan_npz(path: str | os.PathLike) -> Scan:
    """Read a scan written by :meth:`Scan.to_npz`, checking every array before it is used.

    Raises
    ------
    InvalidInputError
        Naming the file: missing, not a regular file, inflating past
        :data:`~zbuf_occlude.io.caps.MAX_SCAN_NPZ_BYTES`, missing keys, or an array of the wrong shape or dtype
        (per-point arrays of N rows, ``points`` (N, 3) finite numbers, ``normal`` (N, 3) numbers, indices integers,
        ``sensor_position`` a finite (3,), ``sensor_to_world`` a finite (4, 4), ``frame`` one
        of :data:`FRAMES`).

    Notes
    -----
    A file written before scans had return fields reads with ``return_number`` and
    ``number_of_returns`` 1 and ``intensity`` 1.0 (one return per pulse, no radiometry), and
    ``pulse_id``, ``gps_time``, ``scan_angle_deg`` None.
    """
    path = Path(path)
    d = load_npz(path, max_bytes=MAX_SCAN_NPZ_BYTES, error=InvalidInputError)  # a regular file, sizes first
    missing = {"points", "range_m", "face_index", "object_id", "normal", "incidence_deg", "sensor_position"} - set(d)
    if missing:
        raise InvalidInputError(f"{path}: not a scan NPZ, missing keys {sorted(missing)}")
    _checked_npz(path, d)
    n = len(d["points"])
    return Scan(
        d["points"], d.get("ring"), d.get("pixel"), d["range_m"], d["face_index"], d["object_id"], d["normal"],
        d["incidence_deg"], str(d.get("frame", "sensor")), d["sensor_position"].astype(np.float64),
        d.get("sensor_to_world", np.eye(4)).astype(np.float64), str(d.get("sensor", "")),
        return_number=d["return_number"].astype(np.uint8) if "return_number" in d else np.ones(n, np.uint8),
        number_of_returns=d["number_of_returns"].astype(np.uint8) if "number_of_returns" in d else np.ones(n, np.uint8),
        intensity=d["intensity"].astype(np.float32) if "intensity" in d else np.ones(n, np.float32),
        pulse_id=d["pulse_id"].astype(np.int64) if "pulse_id" in d else None,
        gps_time=d["gps_time"].astype(np.float64) if "gps_time" in d else None,
        scan_angle_deg=d["scan_angle_deg"].astype(np.float32) if "scan_angle_deg" in d else None,
    )  # fmt: skip
