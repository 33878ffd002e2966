"""The returns of one scan, :class:`Scan`, and its files: NPZ (written and read back, checked), PLY, LAS/LAZ.

Written by :func:`zbuf_occlude.sensors.scan.scan`; read back by :func:`read_scan_npz`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.arrays import load_npz
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.caps import MAX_SCAN_NPZ_BYTES
from zbuf_occlude.io.encodings import npz_bytes
from zbuf_occlude.sensors.beam.fields import INTENSITY_UNITS, device_quantity, intensity_counts
from zbuf_occlude.sensors.checks import MAX_SCENE_OBJECTS, namer, reals

__all__ = ["FRAMES", "GPS_START_S", "GPS_TIME_RESOLUTION_S", "MAX_LAS_ORIGIN_M", "UNIT_INTENSITY_SCALE", "Scan", "check_gps_start",
           "las_origin", "read_scan_npz"]  # fmt: skip

#: Frames a scan's points can be given in.
FRAMES = ("sensor", "world")
#: The adjusted standard GPS time (GPS seconds − 10⁹, ASPRS LAS 1.4 R15 global encoding bit 0) of
#: 2026-01-01T00:00:00 UTC, seconds: the time 0 of a scan written as LAS.  GPS time counts from
#: 1980-01-06T00:00:00 UTC without leap seconds: 16,797 days to 2026-01-01 (date(2026, 1, 1) −
#: date(1980, 1, 6)) · 86,400 s = 1,451,260,800 s of UTC, plus the 18 leap seconds UTC took since
#: (GPS − UTC = 18 s since 2017-01-01, IERS Bulletin C) = 1,451,260,818 s; minus 10⁹.  Every scan's times,
#: an airborne plan's included (its lines flown one after another from 0 on), are ≥ 0.
GPS_START_S = 451_260_818.0
#: The coarsest step between the float64 GPS times of a scan's LAS file, seconds: 1 µs.  LAS stores
#: GPS time as float64 seconds (R15, "GPS Time"), whose step doubles with every power of 2 of the
#: time: 60 ns at :data:`GPS_START_S`, 1 µs or finer below 2³³ s (8.6e9 s of adjusted standard time,
#: the year 2283).  Scanners stamp pulses to the microsecond (Velodyne's packets: µs past the hour)
#: and the fastest preset fires every 1.25 µs (riegl-q1560, 800 kHz), so at this step its pulses keep
#: distinct times in firing order.  A finer rule (0.1 µs) would refuse real adjusted standard times
#: from 2028 on (2²⁹ s), which are as LAS writes them.
GPS_TIME_RESOLUTION_S = 1e-6
#: Largest |coordinate| of a LAS file's origin (``to_las_bytes(origin_m=)``), metres: every projected CRS's false
#: eastings and northings (UTM's 10,000 km, Lambert-93's 7,000 km) lie well within it, and float64 keeps nm steps there.
MAX_LAS_ORIGIN_M = 1e8
#: The intensity scale of a scan whose beam gives none, counts·m²: received energy 1 m⁻² (a white
#: Lambertian target at normal incidence 1 m away, filling the beam) and above store 65535.
UNIT_INTENSITY_SCALE = 65535.0


def check_las_frame(frame: str, *, moving: bool, crs=None, origin_m=None, names: Mapping[str, str | None] | None = None) -> None:
    """The one statement of the frames a LAS file takes: a moving sensor's points in the sensor frame lie each in its own
    pulse's frame, which no one height above the ground classifies; a CRS labels world coordinates, and an origin places
    them.  ``names`` maps ``frame``, ``crs`` and ``origin_m`` to the caller's words
    (:func:`~zbuf_occlude.sensors.beam.fields.check_returns`'s rule).

    Raises
    ------
    InvalidInputError
        Any of them in the sensor frame.
    """
    n = namer(names)
    if frame != "world" and moving:
        raise InvalidInputError(f"a moving sensor's points in the {frame} frame lie each in its own pulse's frame, which LAS cannot "
                                f"classify by height: give {n('frame')} world")  # fmt: skip
    if crs is not None and frame != "world":
        raise InvalidInputError(
            f"{n('crs')} {crs} labels world coordinates: it needs {n('frame')} world (the points are in the {frame} frame)"
        )
    if origin_m is not None and frame != "world":
        raise InvalidInputError(f"{n('origin_m')} places the world frame's origin: it needs {n('frame')} world (the points are in "
                                f"the {frame} frame)")  # fmt: skip


def las_origin(origin_m, name: str = "origin_m") -> NDArray[np.float64]:
    """(3,) float64: ``origin_m``, the world frame's origin in the coordinates a LAS file is written in (a CRS's easting,
    northing and height, metres): 2 or 3 finite numbers within ±:data:`MAX_LAS_ORIGIN_M` (a height of 0 where 2 are given).

    Raises
    ------
    InvalidInputError
        Another count, or a number not finite or beyond the bound, naming ``name``.
    """
    values = reals(origin_m, name, lengths=(2, 3), low=-MAX_LAS_ORIGIN_M, high=MAX_LAS_ORIGIN_M)
    return np.array([*values, 0.0][:3], dtype=np.float64)


def check_gps_start(gps_start_s: float, times_s: ArrayLike | None = None, *, name: str = "gps_start_s") -> float:
    """``gps_start_s`` checked as the adjusted standard GPS time of a scan's time 0 in a LAS file.

    Every time written, ``gps_start_s + times_s``, must be >= 0 (adjusted standard GPS time, ASPRS
    LAS 1.4 R15), and float64 times at the last of them must be at most
    :data:`GPS_TIME_RESOLUTION_S` apart (``numpy.spacing``): at 1e17 s they are 16 s apart and
    every point of a scan would get one time.

    Parameters
    ----------
    gps_start_s : float
        Adjusted standard GPS time (GPS seconds − 10⁹) of the scan's time 0, seconds.
    times_s : (N,) float, optional
        The scan's times, seconds from its first firing (:attr:`Scan.gps_time`; airborne: a few
        minutes negative at most); None or empty: the start alone.
    name : str
        What messages call ``gps_start_s`` (a caller names its own option).

    Returns
    -------
    float
        ``gps_start_s``.

    Raises
    ------
    InvalidInputError
        ``gps_start_s`` not a finite number, a time below 0, or a last time at which float64
        steps are coarser than :data:`GPS_TIME_RESOLUTION_S` (the message gives the step there
        and the latest start that keeps the resolution).
    """
    from zbuf_occlude.sensors.checks import real

    start = real(gps_start_s, name)
    relative = np.zeros(1) if times_s is None else np.asarray(times_s, np.float64).ravel()
    relative = relative if relative.size else np.zeros(1)
    first, last = start + relative.min(), start + relative.max()
    if not first >= 0.0:
        raise InvalidInputError(f"{name} {start:.9g} puts the scan's first time at {first:.9g} s: adjusted standard GPS times must "
                                "be >= 0; give a later start")  # fmt: skip
    step = math.ulp(last)  # numpy.spacing, without its overflow warning at the largest floats
    if step > GPS_TIME_RESOLUTION_S:
        # float64 steps are 2**(e - 53) in [2**(e - 1), 2**e); frexp gives GPS_TIME_RESOLUTION_S's binade, exactly
        below = math.ldexp(1.0, math.frexp(GPS_TIME_RESOLUTION_S)[1] + 52) - float(relative.max())
        given = next(d for d in range(1, 18) if float(_short(start, d)) == start)  # as typed: 1e17, 8.6e9, 8589934591.99
        digits = next((d for d in range(2, 18) if _short(below, d) != _short(start, d)), 17)  # 8.59e9 below 8.6e9, not 8.6e9
        raise InvalidInputError(
            f"{name} {_short(start, given)}: at {_short(last, 2)} s float64 GPS times are {_short(step, 2)} s apart; a start below "
            f"about {_short(below, digits)} s keeps the {GPS_TIME_RESOLUTION_S * 1e6:g} µs that LAS GPS times need"
        )
    return start


def _short(x: float, digits: int) -> str:
    """``x`` in ``digits`` significant digits, exponent unpadded: ``1e17``, ``8.6e9``, ``16``, ``0.5``."""
    mantissa, _, exponent = f"{x:.{digits}g}".partition("e")
    return mantissa + (f"e{int(exponent)}" if exponent else "")


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
        "Return Number").  1 everywhere with one return per pulse (the beam's ``max_returns`` 1,
        :class:`~zbuf_occlude.sensors.beam.fields.Beam`).
    number_of_returns : (N,) uint8 or None
        LiDAR: n, the returns its pulse recorded, the same on every point of the pulse.
    intensity : (N,) float32 or None
        LiDAR: received energy, ``ρ |cos θ| f / R²`` in m⁻² (:func:`~zbuf_occlude.sensors.beam.echoes.hit_energy`, the
        units of the beam's ``detection_threshold``), power noise included; ρ = 1 where no
        ``reflectivity`` is given.  A beam that resolves echoes records each echo's energy; so
        does every beam with an ``intensity_scale`` (every preset's).  1.0 only for a beam
        without ``intensity_scale`` (the ``ideal`` one), one return per pulse and no
        reflectivities (no radiometry).
    pulse_id : (N,) int64 or None
        LiDAR: ``ring · Lidar.n_azimuths + azimuth index``, unique per pulse of one scan; the
        returns of one pulse share it (airborne: the pulse's row among the plan's pulses; a ray
        table: the pulse's row in the table).
    gps_time : (N,) float64 or None
        LiDAR: firing time of the pulse, seconds from the revolution's first firing
        (``(azimuth index + b / n_beams) / (n_azimuths · rotation_hz)``, beam ``b`` firing
        ``b / n_beams`` of a cycle after the cycle's first: every pulse a time of its own);
        the returns of one pulse share it (airborne: the firing time on the flight plan's clock, its
        lines flown one after another from 0 on, :func:`~zbuf_occlude.sensors.scan.scan_airborne`; a ray table: its row's ``time_s``,
        exactly).  On a :class:`~zbuf_occlude.sensors.platform.Trajectory`, the time on the
        trajectory's clock (its ``start_s`` plus the time into the sweep).
    scan_angle_deg : (N,) float32 or None
        LiDAR: the beam's elevation, degrees (the spinning scanner's scan angle; a ray table: its
        row's elevation); airborne: the across-track angle from nadir, signed as ASPRS LAS 1.4
        defines it.
    intensity_scale : float or None
        Counts per unit of received energy (counts·m², :attr:`intensity` is m⁻²): the scanner's
        beam's, which :meth:`to_las_bytes` stores intensities through; None: the beam gives none.
    max_intensity : int or None
        The largest count the scanner stores, 1 to 65535 (an 8-bit reflectivity's 255): the
        beam's; None: 65535.
    intensity_unit : {"energy", "reflectivity"}
        What the scanner writes of :attr:`intensity`: its counts, or counts of the calibrated reflectivity
        ``intensity · range_m²`` (:data:`~zbuf_occlude.sensors.beam.fields.INTENSITY_UNITS`, the beam's).
    object_classes : tuple of str or None
        Class name by object id (index 0: ``"ground"``, the objects, then the occluders, as the
        scene numbers them); None: not known.  :meth:`to_las_bytes` classifies points by it.

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
    intensity_scale: float | None = None
    object_classes: tuple[str, ...] | None = None
    max_intensity: int | None = None
    intensity_unit: str = "energy"

    #: Per-point arrays of every scan, in file order.
    _BASE = ("points", "ring", "pixel", "range_m", "face_index", "object_id", "normal", "incidence_deg")
    #: Per-point arrays of a LiDAR's returns (None for other sensors), written after the rest.
    _RETURNS = ("return_number", "number_of_returns", "intensity", "pulse_id", "gps_time", "scan_angle_deg")
    _PER_POINT = _BASE + _RETURNS

    def __len__(self) -> int:
        return len(self.points)

    def select(self, mask: ArrayLike) -> Scan:
        """The returns where ``mask`` (bool or index array) holds; ``meta``'s per-point arrays (one row a return: an
        airborne scan's ``line_id`` and ``scan_angle_deg``) selected with them."""
        changes = {k: (None if getattr(self, k) is None else getattr(self, k)[mask]) for k in self._PER_POINT}
        n = len(self)
        meta = {k: (v[mask] if isinstance(v, np.ndarray) and v.ndim >= 1 and len(v) == n else v) for k, v in self.meta.items()}
        return replace(self, **changes, meta=meta)

    def crop(self, object_id: int) -> Scan:
        """The returns of one scene object (occlusion by every other object included)."""
        return self.select(self.object_id == int(object_id))

    def arrays(self) -> dict[str, np.ndarray]:
        """The NPZ content: every present per-point field of the base set, ``sensor_position``,
        ``sensor_to_world``, ``frame`` and ``sensor`` (0-d strings), then the present return fields
        (``return_number`` ... ``scan_angle_deg``), then, when known, ``intensity_scale`` (0-d
        float64), ``object_classes`` (``(K,)`` strings), ``max_intensity`` (0-d int64) and, where it is not
        ``"energy"``, ``intensity_unit`` (0-d string)."""
        out = {k: getattr(self, k) for k in self._BASE if getattr(self, k) is not None}
        out.update(sensor_position=np.asarray(self.sensor_position, np.float64), sensor_to_world=self.sensor_to_world,
                   frame=np.array(self.frame), sensor=np.array(self.sensor))  # fmt: skip
        out.update({k: getattr(self, k) for k in self._RETURNS if getattr(self, k) is not None})
        if self.intensity_scale is not None:
            out["intensity_scale"] = np.array(float(self.intensity_scale))
        if self.object_classes is not None:
            out["object_classes"] = np.array(list(self.object_classes), dtype=str).reshape(len(self.object_classes))
        if self.max_intensity is not None:
            out["max_intensity"] = np.array(int(self.max_intensity), np.int64)
        if self.intensity_unit != "energy":
            out["intensity_unit"] = np.array(self.intensity_unit)
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

    def to_las_bytes(
        self,
        compress: bool = False,
        *,
        intensity_scale: float | None = None,
        class_map: Mapping[str, int] | None = None,
        ground_z_m: float = 0.0,
        scan_number: int = 0,
        gps_start_s: float = GPS_START_S,
        crs: int | str | None = None,
        origin_m=None,
    ) -> bytes:
        """The scan as the bytes of a LAS 1.4 file, point format 6 (LAZ with ``compress``), as a survey writes it.

        Through :func:`zbuf_occlude.io.las.las_bytes`: coordinates in ``frame`` (the sensor's or
        the world's, as the scan holds them), metres, stored in steps of 1 mm.  Per point
        (docs/guide/las_fields.md lists them):

        * ``return_number``, ``number_of_returns``, ``scan_angle_deg`` (a spinning scanner: the
          beam's elevation; airborne: the across-track angle) as the scan holds them;
        * ``intensity``: ``rint(clip(q · scale, 0, top))`` counts, ``q`` the :attr:`intensity` (or, where the
          scanner writes a calibrated reflectivity, :attr:`intensity_unit`, ``intensity · range_m²``), ``scale`` the
          ``intensity_scale`` given, else the scan's :attr:`intensity_scale` (its beam's), else
          65535 (:data:`UNIT_INTENSITY_SCALE`: a received energy of 1 m⁻² or more stores 65535);
          ``top`` the scan's :attr:`max_intensity` (its beam's), else 65535;
        * ``gps_time``: adjusted standard GPS time (global encoding bit 0 set), ``gps_start_s``
          plus the scan's :attr:`gps_time` (seconds from its first firing; airborne: from the
          start of the plan's first line, its lines one after another);
        * ``classification``: the ASPRS class of the object hit
          (:func:`~zbuf_occlude.sensors.scene.las_classes.asprs_classification`: ground 2, vegetation
          3/4/5 by height above ``ground_z_m`` in the world frame, building 6, others 1; a
          ``class_map`` overrides it by class name);
        * ``point_source_id``: the airborne flight line (``meta["line_id"]``, when it holds one
          value per point), else ``scan_number``;
        * extra bytes ``object_id`` (int32) and ``class_index`` (uint16), an index into the class
          names VLR (:data:`~zbuf_occlude.io.las.CLASS_NAMES_USER_ID`, a JSON array): the distinct
          :attr:`object_classes` in object order (objects of no known class: ``""``).

        A scan without return fields (a depth camera's) is written as one return per point,
        time ``gps_start_s``, scan angle 0, intensity 0.

        Parameters
        ----------
        compress : bool
            LAZ (LASzip through lazrs) instead of LAS.
        intensity_scale : float, optional
            Counts per unit of received energy (counts·m²), finite and > 0.
        class_map : mapping of str to int, optional
            Class name → ASPRS code (:func:`~zbuf_occlude.sensors.scene.las_classes.load_class_map` reads one).
        ground_z_m : float
            The ground plane's height in the world frame, metres (a scene's ``ground_z_m``).
        scan_number : int
            The point source id of a scan without flight lines, 0 to 65535.
        gps_start_s : float
            The adjusted standard GPS time of the scan's time 0, seconds (default
            :data:`GPS_START_S`, 2026-01-01T00:00:00 UTC); every time written must be >= 0 and
            keep float64 steps of :data:`GPS_TIME_RESOLUTION_S` at most (:func:`check_gps_start`:
            a start below about 8.6e9 s).
        crs : int or str, optional
            The EPSG code of a projected CRS in metres (``"EPSG:2154"``), or of one compound with
            a vertical CRS in metres (``"EPSG:2154+5720"``;
            :func:`~zbuf_occlude.io.las_crs.epsg_crs`), written as a WKT VLR; needs pyproj (the
            ``crs`` extra) and a scan in the world frame.
        origin_m : (2,) or (3,) float, optional
            Where the world frame's origin lies in the file's coordinates (a CRS's easting, northing and height, metres;
            :func:`las_origin`): every point is written at its world position plus it, so that a scene made about the
            origin lands where the CRS says.  Needs a scan in the world frame.

        Returns
        -------
        bytes
            The whole file; write it with :meth:`~zbuf_occlude.io.owned.OwnedFolder.write_bytes`
            or :func:`~zbuf_occlude.io.atomic.write_bytes`.

        Raises
        ------
        InvalidInputError
            ``intensity_scale``, ``ground_z_m`` or ``gps_start_s`` not finite (scale > 0), a bad ``origin_m``, a
            :attr:`max_intensity` outside 1 to 65535, a time that would be negative or whose
            float64 steps are coarser than :data:`GPS_TIME_RESOLUTION_S`, ``scan_number`` out of
            range, an object id beyond :attr:`object_classes`, a bad class map, ``crs`` on a scan
            in the sensor frame or not the EPSG code of a projected CRS in metres, or points too
            far apart for int32 steps of 1 mm
            (:func:`~zbuf_occlude.io.las.las_bytes`).
        BackendUnavailable
            ``crs`` without pyproj.
        """
        from zbuf_occlude.io.las import SurveyFields, las_bytes
        from zbuf_occlude.sensors.checks import count, real
        from zbuf_occlude.sensors.scene.las_classes import asprs_classification

        given = self.intensity_scale if intensity_scale is None else intensity_scale
        scale = UNIT_INTENSITY_SCALE if given is None else real(given, "intensity_scale", low=0.0, low_open=True)
        ground = real(ground_z_m, "ground_z_m")
        source = count(scan_number, "scan_number", low=0, high=65535)
        top = 65535 if self.max_intensity is None else count(self.max_intensity, "max_intensity", low=1, high=65535)
        check_las_frame(self.frame, moving=bool(self.meta.get("moving")), crs=crs, origin_m=origin_m)
        origin = np.zeros(3) if origin_m is None else las_origin(origin_m)
        n = len(self)
        ones = np.ones(n, np.uint8)
        intensity = np.zeros(n, np.uint16)
        if self.intensity is not None:
            intensity = intensity_counts(device_quantity(self.intensity, self.range_m, self.intensity_unit), scale, top)
        relative = np.zeros(n) if self.gps_time is None else np.asarray(self.gps_time, np.float64)
        times = check_gps_start(gps_start_s, relative) + relative
        points = np.asarray(self.points, np.float64)
        ids = np.asarray(self.object_id, np.int64)
        classes = self._classes(ids)
        m = np.asarray(self.sensor_to_world, np.float64)
        world_z = points[:, 2] if self.frame == "world" else points @ m[2, :3] + m[2, 3]
        classification = asprs_classification(ids, classes, world_z - ground, class_map)  # checks the ids against the classes
        position = {name: k for k, name in enumerate(dict.fromkeys(classes))}
        index_of = np.array([position[c] for c in classes], np.int64)
        line = self.meta.get("line_id")
        flight_lines = line is not None and np.shape(line) == (n,)
        return las_bytes(
            points + origin, intensity=intensity,
            return_number=ones if self.return_number is None else self.return_number,
            number_of_returns=ones if self.number_of_returns is None else self.number_of_returns,
            gps_time=times,
            scan_angle_deg=np.zeros(n) if self.scan_angle_deg is None else np.asarray(self.scan_angle_deg, np.float64),
            classification=classification,
            point_source_id=np.asarray(line) if flight_lines else np.full(n, source, np.int64),
            survey=SurveyFields(object_id=ids, class_index=index_of[ids], class_names=list(position), adjusted_standard_gps_time=True, crs=crs),
            compress=compress,
        )  # fmt: skip

    def _classes(self, ids: NDArray[np.int64]) -> tuple[str, ...]:
        """:attr:`object_classes`, or, when None, ``"ground"`` then ``""`` (no known class) up to the largest id."""
        if self.object_classes is not None:
            return tuple(self.object_classes)
        return ("ground",) + ("",) * (int(ids.max()) if len(ids) else 0)

    def to_las(self, path: str | os.PathLike, compress: bool = False, **las_options) -> Path:
        """Write :meth:`to_las_bytes` to ``path`` (atomic); LAZ with ``compress``; ``las_options`` are its keywords."""
        return write_bytes(path, self.to_las_bytes(compress, **las_options))

    def to_laz(self, path: str | os.PathLike, **las_options) -> Path:
        """Write :meth:`to_las_bytes` compressed (LAZ) to ``path`` (atomic)."""
        return self.to_las(path, compress=True, **las_options)


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
    for key in ("frame", "sensor", "intensity_unit"):
        if key in d and (d[key].dtype.kind != "U" or d[key].ndim != 0):
            raise InvalidInputError(f"{path}: {key} must be a string, got shape {d[key].shape} dtype {d[key].dtype}")
    if "intensity_scale" in d:
        a = d["intensity_scale"]
        if a.dtype.kind not in "fiu" or a.ndim != 0 or not (np.isfinite(a) and a > 0):
            raise InvalidInputError(f"{path}: intensity_scale must be one finite number > 0, got shape {a.shape} dtype {a.dtype}")
    if "max_intensity" in d:
        a = d["max_intensity"]
        if a.dtype.kind not in "iu" or a.ndim != 0 or not 1 <= int(a) <= 65535:
            raise InvalidInputError(f"{path}: max_intensity must be one integer 1 to 65535, got shape {a.shape} dtype {a.dtype}")
    if "object_classes" in d:
        a = d["object_classes"]
        if a.dtype.kind != "U" or a.ndim != 1 or len(a) > MAX_SCENE_OBJECTS + 1:
            raise InvalidInputError(f"{path}: object_classes must be at most {MAX_SCENE_OBJECTS + 1:,} strings (N,), got shape {a.shape} "
                                    f"dtype {a.dtype}")  # fmt: skip
    for key, choices in (("frame", FRAMES), ("intensity_unit", INTENSITY_UNITS)):
        if key in d and str(d[key]) not in choices:
            raise InvalidInputError(f"{path}: {key} must be one of {choices}, got another string")
    for key in ("return_number", "number_of_returns"):  # LAS 1.4's 1..15, before uint8 would wrap 257 to 1
        a = d.get(key)
        if a is not None and len(a) and not (int(a.min()) >= 1 and int(a.max()) <= 15):
            raise InvalidInputError(f"{path}: {key} must be 1 to 15 (LAS 1.4's return numbers), got {int(a.min())} to {int(a.max())}")
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
        of :data:`FRAMES`, ``intensity_scale`` one finite number > 0, ``object_classes`` (K,) strings, ``max_intensity`` one integer 1 to 65535).

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
        intensity_scale=float(d["intensity_scale"]) if "intensity_scale" in d else None,
        object_classes=tuple(str(c) for c in d["object_classes"]) if "object_classes" in d else None,
        max_intensity=int(d["max_intensity"]) if "max_intensity" in d else None,
        intensity_unit=str(d["intensity_unit"]) if "intensity_unit" in d else "energy",
    )  # fmt: skip
