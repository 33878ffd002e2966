"""Contact sheets: one picture of what a data set or a folder of scans holds.

:func:`contact_sheet` draws a grid with a row per sample (a few objects per class, a few poses
per object) and three panels per row:

1. **fixed view**: the sample from one camera shared by every row
   (:data:`FIXED_ELEVATION_DEG`, :data:`FIXED_AZIMUTH_DEG`), so shapes compare and the hidden
   side shows as missing;
2. **camera view**: the sample as the camera that made it saw it: the pose's pinhole camera of
   the data set (:func:`~zbuf_occlude.geometry.cameras.camera_on_sphere` with the card's radius
   and resolution, pixels), or, for sensor scans, the directions of the returns seen from the
   sensor (azimuth and elevation, degrees: a spinning LiDAR's range-image axes; a depth camera's
   own pixels);
3. **complete cloud**: the dense cloud the sample was drawn from, from the fixed camera, when
   the data set keeps it (``compact`` storage), else the panel says it is not stored.

It reads the data sets that ``farm`` and ``generate`` write (every storage, ``farm --sensor``
included, through :class:`~zbuf_occlude.dataset.reader.OccludedDataset`) and the folders of
``.npz`` scans that ``zbuf-occlude scan`` writes (:func:`~zbuf_occlude.sensors.scan_data.read_scan_npz`).
The drawing is :mod:`.sheet_drawing`'s (matplotlib's Agg canvas: no display, no pyplot state).
"""

from __future__ import annotations

import logging
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, Camera, camera_on_sphere
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.experiments.sheet_drawing import PANEL_INCHES, draw_sheet, image_bounds, write_png

if TYPE_CHECKING:  # matplotlib is imported when a sheet is drawn
    from matplotlib.figure import Figure

    from zbuf_occlude.dataset.reader import OccludedDataset

__all__ = [
    "contact_sheet",
    "ContactSheet",
    "SheetRow",
    "FIXED_ELEVATION_DEG",
    "FIXED_AZIMUTH_DEG",
    "DEFAULT_PER_CLASS",
    "DEFAULT_POSES",
    "DEFAULT_DPI",
    "MAX_SHEET_ROWS",
    "MAX_SHEET_PIXELS",
    "MAX_DPI",
]

log = logging.getLogger(__name__)

#: The shared viewpoint: above the horizon, so tops and fronts both show ...
FIXED_ELEVATION_DEG = 20.0
#: ... and between two sides of an axis-aligned object, so no side is seen edge-on.
FIXED_AZIMUTH_DEG = -60.0
#: Image size of the fixed camera, pixels: only the panel's axes are in pixels, nothing is rendered.
FIXED_RESOLUTION = 256
#: Objects drawn per class (scan folders: scans per mesh, times ``poses``).
DEFAULT_PER_CLASS = 2
#: Poses drawn per object (one sample of each).
DEFAULT_POSES = 2
#: Dots per inch of the PNG: a panel of :data:`~zbuf_occlude.experiments.sheet_drawing.PANEL_INCHES` is then 158 pixels wide.
DEFAULT_DPI = 72
#: Dots per inch at most: a print needs 300; past this the panels only cost memory.
MAX_DPI = 600
#: Rows at most: a longer sheet is no longer read; ask for fewer per class (or poses) on data
#: sets of many classes.
MAX_SHEET_ROWS = 200
#: Pixels of the PNG at most, ``rows * 3 * (PANEL_INCHES * dpi) ** 2``: under PIL's
#: ``Image.MAX_IMAGE_PIXELS`` (89.5 M; the PNG is read back to make its palette, and PIL refuses
#: twice that as a decompression bomb), a 256 MB RGBA canvas; with :data:`MAX_SHEET_ROWS` it also
#: keeps a sheet under Agg's 2**16 pixels a side (at most ``sqrt(200 * 64 M / 3)`` = 65,320 tall).
MAX_SHEET_PIXELS = 64_000_000
#: Degrees added around the returns of a sensor view, so the outermost ones are not on the frame.
ANGLE_MARGIN_DEG = 1.0
#: The scan files of ``zbuf-occlude scan``: ``<mesh>_<sensor>_s<k>.npz``; the part before ``_s<k>`` groups them.
SCAN_NAME = re.compile(r"^(?P<group>.+)_s(?P<sample>\d+)$")


@dataclass
class SheetRow:
    """One row of a contact sheet: a sample and its three panels.

    Attributes
    ----------
    class_name : str
        The sample's class (scan folders: the scanned mesh and sensor, ``chair_0001_vlp16``).
    name : str
        The mesh's name relative to the data set (``chair/train/chair_0001``), or the scan file's name.
    elevation_deg, azimuth_deg : float
        The camera (or sensor) seen from the object, degrees (the data set's convention: z up,
        azimuth from +x towards +y; sensors: from the object's bounding-box centre).
    points : (N, 3) float64
        The sample drawn: object frame for data sets; world frame, metres, for scans (the
        object's returns when the scan marks them, ``object_id > 0``).
    complete : (M, 3) float64 or None
        The complete cloud in the frame of ``points``; None when the data set does not keep it.
    fixed_view : (N, 2) float64
        ``points`` in pixels of :attr:`ContactSheet.fixed_camera` (``u`` right, ``v`` down); scans
        are first centred on their bounding box and scaled to a largest side of 1.
    fixed_depth : (N,) float64
        Linear depth along the fixed camera's axis (colours the fixed view; object units).
    camera_view : (N, 2) float64
        ``points`` as their camera saw them: pixels (``u``, ``v``) of ``camera`` or of the depth
        camera; or, for a LiDAR, (azimuth, elevation) of each return seen from the sensor,
        degrees, azimuth from the line of sight to the object's centre, positive to the left.
    camera_depth : (N,) float64
        What colours the camera panel: linear depth along ``camera``'s optical axis (object
        units), or the range from the sensor (the frame's units: metres for scans).
    camera_units : {"pixels", "degrees"}
    camera_bounds : ((2,), (2,)) tuple of float
        The camera panel's x and y limits: the image's outer pixel edges ``[-0.5, W - 0.5]``,
        or the returns' azimuths and the sensor's elevation span (degrees).
    camera : Camera or None
        The data set pose's pinhole camera; None for sensor rows.
    titles : tuple of 3 str
        The panels' titles.
    complete_view : (M, 2) float64 or None
        ``complete`` in pixels of the fixed camera.
    """

    class_name: str
    name: str
    elevation_deg: float
    azimuth_deg: float
    points: NDArray[np.float64]
    complete: NDArray[np.float64] | None
    fixed_view: NDArray[np.float64]
    fixed_depth: NDArray[np.float64]
    camera_view: NDArray[np.float64]
    camera_depth: NDArray[np.float64]
    camera_units: str
    camera_bounds: tuple[tuple[float, float], tuple[float, float]]
    camera: Camera | None = None
    titles: tuple[str, str, str] = ("", "", "")
    complete_view: NDArray[np.float64] | None = field(default=None, repr=False)


@dataclass
class ContactSheet:
    """What :func:`contact_sheet` drew.

    Attributes
    ----------
    path : Path
        The PNG written.
    source : {"dataset", "scans"}
    rows : list of SheetRow
        One per row of the grid, class after class.
    fixed_camera : Camera
        The camera of the first and third columns.
    figure : matplotlib.figure.Figure
        The drawn figure (``len(rows)`` × 3 axes).
    """

    path: Path
    source: str
    rows: list[SheetRow]
    fixed_camera: Camera
    figure: Figure

    @property
    def shape(self) -> tuple[int, int]:
        """``(rows, 3)``: the grid's panels."""
        return len(self.rows), 3


def contact_sheet(
    path: str | os.PathLike,
    out: str | os.PathLike,
    *,
    per_class: int = DEFAULT_PER_CLASS,
    poses: int = DEFAULT_POSES,
    seed: int = DEFAULT_SEED,
    dpi: int = DEFAULT_DPI,
) -> ContactSheet:
    """Draw a contact sheet of a data set or of a folder of scans into the PNG ``out``.

    Parameters
    ----------
    path : str or PathLike
        A data set folder (``farm``, ``generate``: it holds ``dataset_card.json``) or the
        ``--out`` folder of ``zbuf-occlude scan`` (its ``.npz`` scans; ``--format npz`` or ``both``).
    out : str or PathLike
        The PNG to write (atomically: a temporary file beside it, then renamed).
    per_class : int
        Data sets: objects per class.  Scan folders: ``per_class * poses`` scans per mesh.
    poses : int
        Data sets: poses per object, one sample each (an object with fewer poses gives fewer rows).
    seed : int or numpy.random.Generator
        Chooses the objects, poses and scans (and the points drawn when a panel has more than
        :data:`~zbuf_occlude.experiments.sheet_drawing.MAX_DRAWN_POINTS`); the same seed draws the same sheet.
    dpi : int
        Pixels per inch; a panel is :data:`~zbuf_occlude.experiments.sheet_drawing.PANEL_INCHES` wide, so the PNG is
        ``3 * PANEL_INCHES * dpi`` by ``rows * PANEL_INCHES * dpi`` pixels, at most
        :data:`MAX_SHEET_PIXELS` in all (12 rows at :data:`MAX_DPI`; at the default
        :data:`MAX_SHEET_ROWS` is reached first).

    Returns
    -------
    ContactSheet
        The rows (their points, panel coordinates and titles) and the figure.

    Raises
    ------
    InvalidInputError
        ``path`` is neither a data set nor a folder of scans; ``per_class``, ``poses`` or
        ``dpi`` below 1; ``dpi`` above :data:`MAX_DPI`; a negative ``seed``; more rows than
        :data:`MAX_SHEET_ROWS`, or rows and ``dpi`` that make more pixels than
        :data:`MAX_SHEET_PIXELS` (both checked before any sample is read); ``out`` not a ``.png``
        file; a data set whose card lacks a usable ``params.radius`` or ``params.resolution``
        (unless it is a ``farm --sensor`` data set, whose samples hold their own radius); a scan
        with a NaN or infinite point; or any error of the reader
        (:class:`~zbuf_occlude.dataset.reader.OccludedDataset`) or of
        :func:`~zbuf_occlude.sensors.scan_data.read_scan_npz`, naming the file.
    BackendUnavailable
        matplotlib is missing (``pip install '.[plot]'``).
    OutputError
        ``out``'s folder cannot be made, or ``out`` cannot be written.
    UnsafePathError
        A file ``out`` exists that a run of ours did not write, or that was changed since; it is
        left as it is (:class:`~zbuf_occlude.io.owned.OwnedFolder`).
    DatasetBusy
        Another live process holds ``out``'s folder.
    """
    for name, value in (("per_class", per_class), ("poses", poses), ("dpi", dpi)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InvalidInputError(f"{name} must be an integer >= 1, got {value!r}")
    if dpi > MAX_DPI:
        raise InvalidInputError(f"dpi must be at most {MAX_DPI} (MAX_DPI), got {dpi}")
    check_seed(seed)
    root, out = Path(path), Path(out)
    if out.suffix.lower() != ".png":
        raise InvalidInputError(f"the contact sheet is a PNG: give an output path ending in .png, got {out}")
    if out.is_dir():
        raise InvalidInputError(f"{out} is a folder: give the PNG's file name")
    try:
        import matplotlib  # noqa: F401  (checked before any file is read)
    except ImportError:
        raise BackendUnavailable(f"contact-sheet needs matplotlib: {install_hint('plot')}") from None
    rng = np.random.default_rng(seed)
    fixed = camera_on_sphere(FIXED_ELEVATION_DEG, FIXED_AZIMUTH_DEG, DEFAULT_RADIUS, resolution=FIXED_RESOLUTION)
    if (root / CARD_FILE).is_file():
        source, rows = "dataset", _dataset_rows(root, int(per_class), int(poses), int(dpi), rng, fixed)
    elif root.is_dir() and any(p.suffix.lower() == ".npz" for p in root.iterdir()):
        source, rows = "scans", _scan_rows(root, int(per_class) * int(poses), int(dpi), rng, fixed)
    else:
        raise InvalidInputError(
            f"{root} is neither a data set (no {CARD_FILE}) nor a folder of scans (no .npz files of "
            "`zbuf-occlude scan --format npz`): give the --out folder of farm, generate or scan"
        )
    figure = draw_sheet(rows, fixed, int(dpi), rng)
    write_png(figure, out)
    return ContactSheet(path=out, source=source, rows=rows, fixed_camera=fixed, figure=figure)


def _check_size(n_rows: int, dpi: int, what: str) -> None:
    """Refuse a sheet of more than :data:`MAX_SHEET_ROWS` rows or :data:`MAX_SHEET_PIXELS` pixels, before it is drawn."""
    if n_rows > MAX_SHEET_ROWS:
        raise InvalidInputError(
            f"a contact sheet of {what} would have up to {n_rows} rows, more than {MAX_SHEET_ROWS} (MAX_SHEET_ROWS): "
            "ask for fewer per class or fewer poses"
        )
    panel = PANEL_INCHES * dpi  # pixels a side
    pixels = n_rows * 3 * panel**2
    if pixels > MAX_SHEET_PIXELS:
        most_dpi = math.floor(math.sqrt(MAX_SHEET_PIXELS / (n_rows * 3)) / PANEL_INCHES)
        raise InvalidInputError(
            f"a contact sheet of {what} would be up to {n_rows} rows at {dpi} dpi, {pixels / 1e6:.0f} M pixels "
            f"({3 * panel:.0f} x {n_rows * panel:.0f}), more than {MAX_SHEET_PIXELS / 1e6:.0f} M (MAX_SHEET_PIXELS): "
            f"lower dpi to {most_dpi} or less, or ask for fewer per class or fewer poses"
        )


# -- data sets ----------------------------------------------------------------------------------------
def _card_number(ds: OccludedDataset, key: str) -> float:
    """A number of the card's ``params`` (the card is data: a missing one, a string or a bool is refused by name)."""
    params = ds.card.get("params", {})
    if key not in params:  # no default: a camera guessed for a data set made with another one would mislead
        raise InvalidInputError(
            f"{ds.root / CARD_FILE} field 'params.{key}' is missing: the sheet's camera view needs the data set's "
            "camera; give the folder that `zbuf-occlude farm` or `generate` wrote, with its card"
        )
    value = params[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise InvalidInputError(f"{ds.root / CARD_FILE} field 'params.{key}' must be a positive number, got {value!r}")
    return float(value)


def _choose_samples(ds: OccludedDataset, per_class: int, poses: int, rng: np.random.Generator) -> list[int]:
    """Sample indices: per class, ``per_class`` objects and ``poses`` distinct poses of each, chosen by ``rng``."""
    labels = ds.labels
    chosen: list[int] = []
    for label in np.unique(labels):
        picked: dict[int, list[tuple[int, int]]] = {}  # object → (pose, sample index)
        for i in rng.permutation(np.flatnonzero(labels == label)).tolist():
            meta = ds.metadata(i)  # samples are walked in the seed's order until the class is full
            obj, pose = meta["object_index"], meta["pose_index"]
            rows = picked.get(obj)
            if rows is None:
                if len(picked) == per_class:
                    continue
                rows = picked[obj] = []
            if len(rows) < poses and all(p != pose for p, _ in rows):
                rows.append((pose, i))
            if len(picked) == per_class and all(len(r) == poses for r in picked.values()):
                break
        chosen += [i for obj in sorted(picked) for _, i in sorted(picked[obj])]
    return chosen


def _dataset_rows(root: Path, per_class: int, poses: int, dpi: int, rng: np.random.Generator, fixed: Camera) -> list[SheetRow]:
    from zbuf_occlude.dataset.reader import OccludedDataset

    ds = OccludedDataset(root)
    _check_size(len(np.unique(ds.labels)) * per_class * poses, dpi, str(root))
    sensor = ds.sensor
    if sensor is None:  # a sensor's samples each hold their own radius (meta["radius"]), the card's is not used
        radius, resolution = _card_number(ds, "radius"), _card_number(ds, "resolution")
    rows = []
    for i in _choose_samples(ds, per_class, poses, rng):
        points, _, meta = ds[i]
        points = np.asarray(points, dtype=np.float64)
        dense = ds.dense_points(i)
        complete = None if dense is None else np.asarray(dense, dtype=np.float64)
        el, az = float(meta["elevation_deg"]), float(meta["azimuth_deg"])
        fixed_view, fixed_depth = fixed.project(points)
        count = f"{len(points)} points, {meta['n_visible']} {'returns' if sensor else 'visible'}"
        if sensor is None:
            camera = camera_on_sphere(el, az, radius, resolution=int(resolution))
            view, depth = camera.project(points)
            bounds = image_bounds(camera.width, camera.height)
            camera_title = f"camera el {el:.0f}°, az {az:.0f}°, r {radius:g}"
            units = "pixels"
        else:
            from zbuf_occlude.sensors.patterns.spinning import beam_directions

            camera = None
            # farm --sensor: the sensor at `radius` (mesh units) from the object's centre, in the mesh frame
            sensor_at = beam_directions(el, az) * float(meta["radius"])
            view, depth = _directions_from(points, sensor_at)
            bounds = _angle_bounds(view, _preset_elevations(sensor))
            distance = meta.get("distance_m")
            camera_title = f"{sensor} view" + (f", {distance:.1f} m" if distance is not None else "")
            units = "degrees"
        rows.append(
            SheetRow(
                class_name=meta["class_name"], name=meta["name"], elevation_deg=el, azimuth_deg=az, points=points,
                complete=complete, fixed_view=fixed_view, fixed_depth=fixed_depth, camera_view=view, camera_depth=depth, camera_units=units,
                camera_bounds=bounds, camera=camera,
                titles=(f"{meta['class_name']}: {meta['name']}\nel {el:.0f}°, az {az:.0f}°, {count}", camera_title,
                        "complete: not stored" if complete is None else f"complete: {len(complete)} points"),
                complete_view=None if complete is None else fixed.project(complete)[0],
            )
        )  # fmt: skip
    return rows


# -- scan folders -------------------------------------------------------------------------------------
def _scan_rows(root: Path, per_group: int, dpi: int, rng: np.random.Generator, fixed: Camera) -> list[SheetRow]:
    from zbuf_occlude.sensors.scan_data import read_scan_npz

    groups: dict[str, list[Path]] = {}
    for p in sorted(root.iterdir()):
        if p.suffix.lower() == ".npz":
            m = SCAN_NAME.match(p.stem)
            groups.setdefault(m["group"] if m else p.stem, []).append(p)
    _check_size(sum(min(len(files), per_group) for files in groups.values()), dpi, str(root))
    rows = []
    for group, files in groups.items():
        for p in sorted(files[k] for k in rng.permutation(len(files))[:per_group]):
            rows.append(_scan_row(read_scan_npz(p), group, p.name, fixed))
    return rows


def _scan_row(s: Any, group: str, name: str, fixed: Camera) -> SheetRow:
    """One scan's row (``s``: a :class:`~zbuf_occlude.sensors.scan_data.Scan`)."""
    keep = s.object_id > 0 if np.any(s.object_id > 0) else np.ones(len(s), dtype=bool)  # the object, not the ground
    pose = np.asarray(s.sensor_to_world, dtype=np.float64)
    rotation, origin = pose[:3, :3], pose[:3, 3]
    local = np.asarray(s.points, dtype=np.float64)[keep]
    if s.frame == "world":
        world, local = local, (local - origin) @ rotation  # world → sensor
    else:
        world = local @ rotation.T + origin
    if len(world) == 0:
        raise InvalidInputError(f"{name}: the scan has no returns to draw")
    lo, hi = world.min(axis=0), world.max(axis=0)
    centre, side = (lo + hi) / 2.0, float(np.max(hi - lo))
    unit = (world - centre) / (side if side > 0 else 1.0)
    fixed_view, fixed_depth = fixed.project(unit)
    seen = origin - centre  # the sensor seen from the object's bounding-box centre, world frame
    r = float(np.linalg.norm(seen))
    el = math.degrees(math.asin(seen[2] / r)) if r > 0 else 0.0
    az = math.degrees(math.atan2(seen[1], seen[0])) % 360.0
    preset = _preset(s.sensor)
    if s.pixel is not None:
        view, depth = s.pixel[keep].astype(np.float64), local[:, 2]  # OpenCV camera frame: z is the depth
        width, height = (preset.width, preset.height) if preset is not None and hasattr(preset, "width") else (view.max(axis=0) + 1)
        bounds, units = image_bounds(int(width), int(height)), "pixels"
    else:
        view, depth = _directions_from(local, np.zeros(3))
        bounds, units = _angle_bounds(view, getattr(preset, "elevations_deg", None)), "degrees"
    return SheetRow(
        class_name=group, name=name, elevation_deg=el, azimuth_deg=az, points=world, complete=None,
        fixed_view=fixed_view, fixed_depth=fixed_depth, camera_view=view, camera_depth=depth, camera_units=units, camera_bounds=bounds,
        titles=(f"{group}: {name}\nel {el:.0f}°, az {az:.0f}°, {len(world)} returns", f"{s.sensor or 'sensor'} view, {r:.1f} m",
                "complete: not stored"),
    )  # fmt: skip


def _preset(name: str) -> Any:
    """The sensor preset a scan names, or None (a name read from a file is never opened as a path)."""
    from zbuf_occlude.sensors.patterns.depth_camera import DEPTH_CAMERA_PRESETS
    from zbuf_occlude.sensors.patterns.spinning import LIDAR_PRESETS

    key = str(name).lower()
    return LIDAR_PRESETS.get(key) or DEPTH_CAMERA_PRESETS.get(key)


def _preset_elevations(name: str | None) -> Any:
    return getattr(_preset(name or ""), "elevations_deg", None)


# -- views ----------------------------------------------------------------------------------------------
def _directions_from(points: NDArray[np.float64], sensor_at: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(N, 2)`` (azimuth, elevation) of ``points`` seen from ``sensor_at`` (z up), degrees, the
    azimuth from the line of sight to their centroid (positive to the left); and ``(N,)`` ranges."""
    d = points - sensor_at
    rng = np.linalg.norm(d, axis=1)
    elevation = np.degrees(np.arcsin(np.clip(d[:, 2] / np.maximum(rng, 1e-300), -1.0, 1.0)))
    centre = d.mean(axis=0)
    azimuth = np.degrees(np.arctan2(d[:, 1], d[:, 0]) - math.atan2(centre[1], centre[0]))
    azimuth = (azimuth + 180.0) % 360.0 - 180.0
    return np.column_stack([azimuth, elevation]), rng


def _angle_bounds(view: NDArray[np.float64], elevations_deg: Any) -> tuple[tuple[float, float], tuple[float, float]]:
    """Azimuths of the returns and the sensor's elevation span (the returns' when the sensor is unknown), degrees."""
    az_lo, az_hi = (float(view[:, 0].min()), float(view[:, 0].max())) if len(view) else (0.0, 0.0)
    if elevations_deg is not None and len(elevations_deg):
        el_lo, el_hi = float(np.min(elevations_deg)), float(np.max(elevations_deg))
    else:
        el_lo, el_hi = (float(view[:, 1].min()), float(view[:, 1].max())) if len(view) else (0.0, 0.0)
    m = ANGLE_MARGIN_DEG
    return (az_lo - m, az_hi + m), (el_lo - m, el_hi + m)
