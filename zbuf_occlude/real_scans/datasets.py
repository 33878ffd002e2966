"""Real LiDAR object scans: readers, the paper's normalisation, and its car TP/FP/F1 protocol.

Sryamkin et al. 2023 (Table 3B, "Test 3") test classifiers trained on generated clouds
on real, segmented single-viewpoint scans of the Sydney Urban Objects data set (SUO;
De Deuge, Quadros, Hung, Douillard, "Unsupervised feature learning for classification
of outdoor 3D scans", ACRA 2013).  Two sources are read here:

``suo``
    SUO's per-object files ``objects/<class>.<instance>.<scan>.bin`` (packed binary
    records) and ``.csv`` (the same records as text, no header).  Fields, in order:
    ``t`` int64 (timestamp, µs), ``intensity`` uint8, ``id`` uint8 (laser id),
    ``x y z`` float32 (metres, sensor frame, z up), ``azimuth`` float32 (radians),
    ``range`` float32 (metres), ``pid`` int32 (point id).  A binary record is
    34 bytes, no padding (:data:`SUO_DTYPE`).  The class is the file name's first
    dot-separated field (``4wd.0.2299.bin`` → ``4wd``).
``lidarnet``
    LiDARNet v2 CSVs (``../shared/data/lidarnet_v2_partial``, SOURCE.md there): a
    header row ``origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity``;
    **y is up** and the unit is about 1/5 m.  Points are taken from ``origin_*``
    (the ``relative_*`` columns are the same minus the bounding-box centre) and turned
    to z up by the proper rotation ``(x, y, z) → (x, −z, y)``.  The class is the
    ``object`` column.  Byte-identical files are dropped (first path in sorted order kept).

Every scan is normalised like the paper's meshes (§4.1, and :func:`zbuf_occlude.mesh.load.normalize_mesh`):
bounding-box centre at the origin, maximum extent 1, z up.  No torch here.

The car protocol (Test 3, our reading of the paper; it gives no formula): the model's
predicted class is mapped to "car" or not; for each real car-type class ``c``
(SUO: 4wd, bus, car, truck, ute, van; 188 scans), ``TP_c`` = scans of ``c`` predicted
car, ``FN_c`` = scans of ``c`` predicted anything else, ``FP`` = scans of real classes
outside the car group predicted car (shared by every ``c``; zero when only car-type scans
are tested).  Accuracy_c = TP_c / n_c (the paper's per-class "accuracy on car / 4wd"),
precision = TP/(TP+FP), recall = TP/(TP+FN), F1 their harmonic mean; the paper's
"average F1" is the mean of F1_c over the car-type classes.
"""

from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.caps import MAX_REAL_SCAN_BYTES, MAX_REAL_SCAN_LINE_BYTES
from zbuf_occlude.io.file_errors import parser_failure
from zbuf_occlude.io.regular_files import open_regular_file, read_regular_file
from zbuf_occlude.real_scans.files import (
    find_scan_files,
    row_capacity,
    load_scan_folder,
    read_lines,
    scan_digest,
)
from zbuf_occlude.real_scans.records import RealScan, normalize_points

__all__ = [
    "SUO_DTYPE",
    "SUO_FIELDS",
    "SUO_CAR_CLASSES",
    "LIDARNET_UNITS_PER_METRE",
    "read_suo_bin",
    "read_suo_csv",
    "write_suo_bin",
    "write_suo_csv",
    "read_suo_object",
    "read_lidarnet_csv",
    "load_real_scans",
    "car_scores",
    "car_scores_from_labels",
]

log = logging.getLogger(__name__)

#: Field names of an SUO point record, in file order.
SUO_FIELDS = ("t", "intensity", "id", "x", "y", "z", "azimuth", "range", "pid")
#: SUO binary record: packed (34 bytes), little-endian, the field order above.
SUO_DTYPE = np.dtype({"names": list(SUO_FIELDS), "formats": ["<i8", "u1", "u1", "<f4", "<f4", "<f4", "<f4", "<f4", "<i4"]})
#: SUO's six car-type classes (the paper: "every car type counts as car", 188 scans).
SUO_CAR_CLASSES = ("4wd", "bus", "car", "truck", "ute", "van")
#: LiDARNet v2 units per metre (SOURCE.md: about 5; median pedestrian ≈ 8.3 units).
LIDARNET_UNITS_PER_METRE = 5.0
_LIDARNET_HEADER = ("origin_x", "origin_y", "origin_z")


# -- Sydney Urban Objects ------------------------------------------------------------------
def read_suo_bin(path: str | os.PathLike) -> NDArray[np.void]:
    """SUO binary object file → structured array of :data:`SUO_DTYPE` records.

    Raises
    ------
    InvalidInputError
        Missing file, or a size that is not a whole number of 34-byte records.
    """
    path = Path(path)
    raw = read_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)
    if len(raw) % SUO_DTYPE.itemsize:
        raise InvalidInputError(
            f"{path}: {len(raw)} bytes is not a multiple of the {SUO_DTYPE.itemsize}-byte SUO record "
            "(a Git LFS pointer or a truncated file?)"
        )
    return np.frombuffer(raw, dtype=SUO_DTYPE).copy()


def read_suo_csv(path: str | os.PathLike) -> NDArray[np.void]:
    """SUO CSV object file (9 comma-separated fields per line, no header) → structured array.

    Streamed into one :data:`SUO_DTYPE` array sized from the file's line count, checked first
    like a LiDARNet CSV's (:func:`read_lidarnet_csv`).

    Raises
    ------
    InvalidInputError
        Missing file, too large, too many lines or a line too long, or a line without 9
        numeric fields (its line number is given).
    """
    path = Path(path)
    fh, _ = open_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)
    try:
        with fh:
            # streamed into one structured array: memory is the records, not a Python tuple per line
            capacity = row_capacity(path, fh, bytes_per_point=SUO_DTYPE.itemsize)
            out, n = np.empty(capacity, dtype=SUO_DTYPE), 0
            for lineno, line in read_lines(path, fh):
                if not line.strip():
                    continue
                parts = line.strip().split(",")
                if len(parts) != len(SUO_FIELDS):
                    raise InvalidInputError(f"{path}:{lineno}: expected {len(SUO_FIELDS)} fields, got {len(parts)}")
                try:
                    out[n] = (int(parts[0]), int(parts[1]), int(parts[2]), *map(float, parts[3:8]), int(parts[8]))
                except (ValueError, OverflowError):
                    raise InvalidInputError(
                        f"{path}:{lineno}: a field is not a number (t, intensity, id, x, y, z, azimuth, range, pid)"
                    ) from None
                n += 1
    except OSError as exc:
        raise InvalidInputError(f"cannot read SUO file {path}: {parser_failure(exc)}") from None
    return out[:n].copy() if n < capacity else out


def write_suo_bin(path: str | os.PathLike, records: NDArray[np.void]) -> None:
    """Write :data:`SUO_DTYPE` records in SUO's binary format (atomically)."""
    write_bytes(path, np.asarray(records, dtype=SUO_DTYPE).tobytes())


def write_suo_csv(path: str | os.PathLike, records: NDArray[np.void]) -> None:
    """Write :data:`SUO_DTYPE` records in SUO's CSV format (floats with 9 significant digits, exact for float32)."""
    rec = np.asarray(records, dtype=SUO_DTYPE)
    lines = [
        ",".join([str(int(r["t"])), str(int(r["intensity"])), str(int(r["id"]))]
                 + [f"{float(r[k]):.9g}" for k in ("x", "y", "z", "azimuth", "range")] + [str(int(r["pid"]))])
        for r in rec
    ]  # fmt: skip
    write_bytes(path, ("\n".join(lines) + ("\n" if lines else "")).encode())


def read_suo_object(path: str | os.PathLike) -> RealScan:
    """One SUO object (``.bin`` or ``.csv``) as a normalised :class:`RealScan` (z up already)."""
    path = Path(path)
    rec = read_suo_bin(path) if path.suffix.lower() == ".bin" else read_suo_csv(path)
    if len(rec) == 0:
        raise InvalidInputError(f"{path}: no points")
    xyz = np.stack([rec["x"], rec["y"], rec["z"]], axis=1).astype(np.float64)
    return RealScan(
        points=normalize_points(xyz, what=str(path)), label=path.name.split(".")[0], source=str(path), dataset="suo",
        extent_m=xyz.max(axis=0) - xyz.min(axis=0), points_sensor_m=xyz,
    )  # fmt: skip


# -- LiDARNet v2 ---------------------------------------------------------------------------
def read_lidarnet_csv(path: str | os.PathLike) -> RealScan:
    """One LiDARNet v2 object CSV as a normalised, z-up :class:`RealScan`.

    The rows are streamed into one ``(N, 3) float64`` array sized from the file's line count,
    which is checked first (:data:`~zbuf_occlude.real_scans.files.MAX_SCAN_POINTS` and the memory
    available), and no line may pass :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_LINE_BYTES`.

    Raises
    ------
    InvalidInputError
        Missing file, more than :data:`~zbuf_occlude.io.caps.MAX_REAL_SCAN_BYTES`, too many
        lines or a line too long, not UTF-8, a header without
        ``origin_x,origin_y,origin_z,...,object``, a bad row or a second object label (its line
        number is given), or fewer than one point.
    """
    path = Path(path)
    fh, _ = open_regular_file(path, max_bytes=MAX_REAL_SCAN_BYTES, error=InvalidInputError)
    try:
        with fh:
            # streamed into one (N, 3) float64 array, lines bounded: memory is the points, not Python rows
            capacity = row_capacity(path, fh)
            rows = ((i, next(csv.reader([line]), [])) for i, line in read_lines(path, fh, errors="strict"))
            _, first = next(rows, (1, []))
            header = [h.strip() for h in first]
            if tuple(header[:3]) != _LIDARNET_HEADER or "object" not in header:
                raise InvalidInputError(
                    f"{path}: not a LiDARNet CSV (its first line is not the header {','.join(_LIDARNET_HEADER)},...,object)"
                )
            obj = header.index("object")
            p, n, labels = np.empty((capacity, 3)), 0, set()
            for lineno, row in rows:
                if not row:
                    continue
                try:
                    p[n] = float(row[0]), float(row[1]), float(row[2])
                    labels.add(row[obj].strip())
                except (ValueError, IndexError):
                    raise InvalidInputError(f"{path}:{lineno}: expected numbers x, y, z and an object label on the line") from None
                if len(labels) > 1:  # one object per file: stop at the second label
                    raise InvalidInputError(f"{path}:{lineno}: a second object label; a LiDARNet CSV holds one object")
                n += 1
    except UnicodeDecodeError as exc:
        raise InvalidInputError(f"{path} is not UTF-8 text ({exc.reason}); is it a LiDARNet CSV?") from None
    except csv.Error:  # a field longer than csv.field_size_limit(), a NUL byte
        raise InvalidInputError(f"{path}: not a LiDARNet CSV (a field longer than the csv module reads, or a NUL byte)") from None
    except OSError as exc:
        raise InvalidInputError(f"cannot read LiDARNet file {path}: {parser_failure(exc)}") from None
    if n == 0:
        raise InvalidInputError(f"{path}: no points")
    p = p[:n]
    zup = np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1) / LIDARNET_UNITS_PER_METRE  # y up → z up, metres
    return RealScan(
        points=normalize_points(zup, what=str(path)), label=labels.pop(), source=str(path), dataset="lidarnet",
        extent_m=zup.max(axis=0) - zup.min(axis=0), points_sensor_m=zup,
    )  # fmt: skip


def _is_lidarnet_csv(path: Path) -> bool:
    """Whether a CSV's first line is LiDARNet's header (read with a bounded ``readline``)."""
    try:
        fh, _ = open_regular_file(path, error=InvalidInputError)
        with fh:
            first = fh.readline(MAX_REAL_SCAN_LINE_BYTES)
    except (OSError, InvalidInputError):  # unreadable, a FIFO: not LiDARNet's (its reader names the problem)
        return False
    return first.decode("utf-8", errors="replace").startswith(",".join(_LIDARNET_HEADER))


#: Extensions each data set's reader reads.
_READS = {"lidarnet": (".csv",), "suo": (".bin", ".csv")}


def _unreadable(files: Sequence[Path], dataset: str) -> list[Path]:
    return [f for f in files if f.suffix.lower() not in _READS[dataset]]


def _refuse_unreadable(root: Path, files: Sequence[Path], dataset: str, why: str) -> None:
    """Raise naming the files ``dataset``'s reader would skip, so that no class vanishes silently."""
    left = _unreadable(files, dataset) if not why else list(files)
    if left:
        names = ", ".join(str(f.relative_to(root) if f.is_relative_to(root) else f) for f in left[:5])
        more = f" and {len(left) - 5} more" if len(left) > 5 else ""
        raise InvalidInputError(
            f"real scans under {root}: the {dataset} reader cannot read {len(left)} file(s): {names}{more}"
            f"{why or ''}; pass dataset='folder' to read every file as a plain point cloud, or move them out"
        )


def _detect(root: Path, files: Sequence[Path]) -> str:
    """``lidarnet`` (every file a CSV with its header), ``suo`` (every file ``class.instance.scan.bin|csv``), else ``folder``.

    Raises
    ------
    InvalidInputError
        Some CSVs carry LiDARNet's header and other files do not: its reader would drop
        them (a whole class in another format), so the files are named instead.
    """
    lidarnet = [f for f in files if f.suffix.lower() == ".csv" and _is_lidarnet_csv(f)]
    if lidarnet:
        chosen = set(lidarnet)
        _refuse_unreadable(root, [f for f in files if f not in chosen], "lidarnet", " (no LiDARNet header)")
        return "lidarnet"
    if files and all(f.suffix.lower() in (".bin", ".csv") and f.name.count(".") == 3 for f in files):
        return "suo"
    return "folder"


def load_real_scans(
    path: str | os.PathLike,
    *,
    dataset: str = "auto",
    classes: Iterable[str] | None = None,
    min_points: int = 1,
    dedupe: bool = True,
    label_map: Mapping[str, str] | None = None,
    up: str = "+z",
    units: str | float = "m",
) -> list[RealScan]:
    """Every object scan under ``path`` (a file or a folder searched recursively).

    Parameters
    ----------
    path : path
        SUO ``objects/`` folder (``.bin`` preferred; ``.csv`` read where no ``.bin`` of the
        same name exists) or a LiDARNet v2 folder (``*.csv`` except ``MANIFEST.csv``).
    dataset : {"auto", "suo", "lidarnet", "folder"}
        ``folder``: any folder with one sub-folder per class of point-cloud files
        (:func:`zbuf_occlude.real_scans.files.load_scan_folder`, which ``label_map``, ``up`` and
        ``units`` apply to).  ``auto``: LiDARNet when a CSV has its header, SUO when every
        file is named ``class.instance.scan.bin|csv``, else ``folder``.
    classes : iterable of str, optional
        Keep these labels only.
    min_points : int
        Drop scans with fewer points.
    dedupe : bool
        Drop files byte-identical to an earlier one (sorted path order; LiDARNet has 37).

    Returns
    -------
    list of RealScan
        Sorted by source path.

    Raises
    ------
    InvalidInputError
        ``path`` missing, an unknown ``dataset``, or no scan found.
    UnsafePathError
        A file under the folder ``path`` is a link leading outside it to a file of another
        extension (:func:`~zbuf_occlude.real_scans.files.find_scan_files`), refused before any
        file is read; a subclass of InvalidInputError.
    """
    root = Path(path)
    if not root.exists():
        raise InvalidInputError(f"real scans: {root} does not exist")
    if dataset not in ("auto", "suo", "lidarnet", "folder"):
        raise InvalidInputError(f"dataset must be auto, suo, lidarnet or folder, got {dataset!r}")
    if dataset != "folder":  # the files found, and each CSV's first line read, once
        files = [root] if root.is_file() else find_scan_files(root)
        if dataset == "auto":
            dataset = _detect(root, files)
            if dataset == "folder" and not root.is_dir():
                raise InvalidInputError(f"{root}: neither a LiDARNet CSV nor an SUO object; give the folder of class folders")
    if dataset == "folder":
        scans = load_scan_folder(root, label_map=label_map, up=up, units=units, min_points=min_points, dedupe=dedupe)
        return [s for s in scans if classes is None or s.label in set(classes)]
    _refuse_unreadable(root, files, dataset, "")
    if dataset == "suo":
        stems_with_bin = {p.with_suffix("") for p in files if p.suffix.lower() == ".bin"}
        files = [p for p in files if p.suffix.lower() == ".bin" or p.with_suffix("") not in stems_with_bin]
    wanted = set(classes) if classes is not None else None
    seen: set[str] = set()
    scans: list[RealScan] = []
    n_dupes = 0
    for f in files:
        if dedupe:
            digest = scan_digest(f)
            if digest in seen:
                n_dupes += 1
                continue
            seen.add(digest)
        scan = read_suo_object(f) if dataset == "suo" else read_lidarnet_csv(f)
        if (wanted is None or scan.label in wanted) and len(scan.points) >= min_points:
            scans.append(scan)
    if n_dupes:
        log.info("real scans: dropped %d byte-identical duplicate files under %s", n_dupes, root)
    if not scans:
        raise InvalidInputError(f"no {dataset} scans found under {root}")
    return scans


# -- the car protocol ----------------------------------------------------------------------
def car_scores(
    confusion: NDArray[np.integer],
    true_names: Sequence[str],
    pred_names: Sequence[str],
    *,
    car_classes: Sequence[str] = SUO_CAR_CLASSES,
    predicted_car: str | Sequence[str] = "car",
) -> dict:
    """The paper's car TP/FP/F1 (module docstring) from a real-class × model-class confusion matrix.

    Parameters
    ----------
    confusion : (R, M) int
        ``confusion[i, j]`` = scans of real class ``true_names[i]`` predicted as model
        class ``pred_names[j]``.
    true_names, pred_names : sequence of str
    car_classes : sequence of str
        Real classes that count as car (those present in ``true_names`` are scored).
    predicted_car : str or sequence of str
        Model class(es) that mean "car".

    Returns
    -------
    dict
        ``per_class``: list of dicts (``class, n, tp, fn, fp, accuracy, precision,
        recall, f1``), ``mean_f1`` (over the scored car-type classes, NaN if none),
        ``fp`` (non-car scans predicted car), ``n_scans``.

    Raises
    ------
    InvalidInputError
        Shapes disagree with the name lists, negative counts, or no model class is "car".
    """
    cm = np.asarray(confusion)
    if cm.shape != (len(true_names), len(pred_names)):
        raise InvalidInputError(f"confusion shape {cm.shape} != ({len(true_names)}, {len(pred_names)})")
    if (cm < 0).any():
        raise InvalidInputError("confusion matrix has negative counts")
    cars = {predicted_car} if isinstance(predicted_car, str) else set(predicted_car)
    car_cols = [j for j, n in enumerate(pred_names) if n in cars]
    if not car_cols:
        raise InvalidInputError(f"no model class among {sorted(cars)} in {list(pred_names)}")
    predicted_as_car = cm[:, car_cols].sum(axis=1)
    is_car = np.array([n in set(car_classes) for n in true_names])
    fp = int(predicted_as_car[~is_car].sum())
    rows = []
    for i in np.flatnonzero(is_car):
        n, tp = int(cm[i].sum()), int(predicted_as_car[i])
        fn = n - tp
        precision = tp / (tp + fp) if tp + fp else float("nan")
        recall = tp / n if n else float("nan")
        f1 = 2 * tp / (2 * tp + fp + fn) if (2 * tp + fp + fn) else float("nan")
        rows.append({"class": true_names[i], "n": n, "tp": tp, "fn": fn, "fp": fp, "accuracy": recall,
                     "precision": precision, "recall": recall, "f1": f1})  # fmt: skip
    f1s = [r["f1"] for r in rows if np.isfinite(r["f1"])]
    return {"per_class": rows, "mean_f1": float(np.mean(f1s)) if f1s else float("nan"), "fp": fp,
            "n_scans": int(cm.sum())}  # fmt: skip


def car_scores_from_labels(
    true_labels: Sequence[str],
    predicted: Sequence[str],
    *,
    model_classes: Sequence[str],
    label_map: Mapping[str, str] | None = None,
    car_classes: Sequence[str] = SUO_CAR_CLASSES,
    predicted_car: str | Sequence[str] = "car",
) -> dict:
    """:func:`car_scores` from per-scan real labels and predicted model class names.

    ``label_map`` renames real labels first (e.g. ``{"Car": "car"}``); ``car_classes``
    applies to the renamed labels.  Also returns ``confusion`` and ``true_names``.
    """
    if len(true_labels) != len(predicted):
        raise InvalidInputError(f"{len(true_labels)} labels but {len(predicted)} predictions")
    label_map = dict(label_map or {})
    real = [label_map.get(t, t) for t in true_labels]
    true_names = sorted(set(real))
    pred_names = list(model_classes)
    unknown = set(predicted) - set(pred_names)
    if unknown:
        raise InvalidInputError(f"predictions {sorted(unknown)} are not model classes {pred_names}")
    cm = np.zeros((len(true_names), len(pred_names)), dtype=np.int64)
    ti = {n: i for i, n in enumerate(true_names)}
    pj = {n: j for j, n in enumerate(pred_names)}
    for t, p in zip(real, predicted):
        cm[ti[t], pj[p]] += 1
    out = car_scores(cm, true_names, pred_names, car_classes=car_classes, predicted_car=predicted_car)
    out["confusion"], out["true_names"] = cm, true_names
    return out
