"""A scan's LAS/LAZ file as a survey's, read back with laspy alone: classes, extra bytes and class names, flight
lines, intensity counts, adjusted standard GPS time, CRS; and the NPZ keeps the scan's classes and scale."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import BackendUnavailable, InvalidInputError
from zbuf_occlude.io.las import CLASS_NAMES_RECORD_ID, CLASS_NAMES_USER_ID, SurveyFields, las_bytes, read_las
from zbuf_occlude.sensors.scan_data import GPS_START_S, Scan, read_scan_npz

laspy = pytest.importorskip("laspy")
pytest.importorskip("lazrs")

CLASSES = ("ground", "oak_tree", "house", "car")


def _scan(frame: str = "world", **fields) -> Scan:
    """Eight returns: ground, a tree at 0.2/1.0/3.0 m, a house, a car (world z = height; the sensor 1.8 m up)."""
    z = np.array([0.0, 0.2, 1.0, 3.0, 4.0, 0.7, 0.0, 2.0], np.float64)
    world = np.column_stack([np.arange(8.0), np.linspace(-3, 3, 8), z])
    pose = np.eye(4)
    pose[:3, 3] = (1.0, 2.0, 1.8)
    points = world if frame == "world" else world - pose[:3, 3]
    n = len(z)
    base = dict(
        frame=frame, sensor_to_world=pose, object_classes=CLASSES, intensity=np.array([1e-4, 0.5, 1.0, 2.0, 0.25, 0.0, 1e-3, 0.1], np.float32),
        gps_time=np.array([-120.0, -120.0, -0.5, 0.0, 0.25, 1.0, 1.0, 60.0]), return_number=np.array([1, 1, 2, 1, 1, 1, 1, 1], np.uint8),
        number_of_returns=np.array([1, 2, 2, 1, 1, 1, 1, 1], np.uint8), scan_angle_deg=np.linspace(-10, 10, n).astype(np.float32),
    )  # fmt: skip
    base.update(fields)
    return Scan(points.astype(np.float32), None, None, np.ones(n, np.float32), np.zeros(n, np.int64),
                np.array([0, 1, 1, 1, 2, 3, 0, 1], np.int32), np.zeros((n, 3), np.float32), np.zeros(n, np.float32), **base)  # fmt: skip


def _read(scan: Scan, compress: bool = False, **options):
    data = scan.to_las_bytes(compress, **options)
    return laspy.read(io.BytesIO(data)), data


@pytest.mark.parametrize("compress", [False, True])
def test_every_survey_field_reads_back_with_laspy(compress: bool) -> None:
    s = _scan(intensity_scale=20000.0)
    s.meta["line_id"] = np.array([0, 0, 1, 1, 2, 2, 3, 3], np.int32)
    las, _ = _read(s, compress)
    assert (las.header.version.major, las.header.version.minor, las.header.point_format.id) == (1, 4, 6)
    assert las.classification.tolist() == [2, 3, 4, 5, 6, 1, 2, 5]
    assert list(las.point_format.extra_dimension_names) == ["object_id", "class_index"]
    assert np.asarray(las.object_id).dtype == np.int32 and las.object_id.tolist() == s.object_id.tolist()
    assert np.asarray(las.class_index).dtype == np.uint16
    (vlr,) = las.header.vlrs.get_by_id(CLASS_NAMES_USER_ID, [CLASS_NAMES_RECORD_ID])
    names = json.loads(vlr.record_data.decode("utf-8"))
    assert names == list(CLASSES) and vlr.description == "names of class_index (JSON)"  # whole, within the field's 32 bytes
    assert [names[k] for k in las.class_index] == [CLASSES[k] for k in s.object_id]
    assert las.point_source_id.tolist() == [0, 0, 1, 1, 2, 2, 3, 3]
    assert las.intensity.tolist() == [2, 10000, 20000, 40000, 5000, 0, 20, 2000]
    assert las.header.global_encoding.value & 1 == 1  # adjusted standard GPS time
    assert np.asarray(las.gps_time).tobytes() == (GPS_START_S + s.gps_time).tobytes()
    assert (np.asarray(las.gps_time) > 0).all() and (np.diff(las.gps_time) >= 0).all()
    assert las.header.global_encoding.wkt and not las.header.vlrs.get("WktCoordinateSystemVlr")  # no crs given: none written
    descriptions = {d.name: d.description for d in las.point_format.extra_dimensions}
    assert descriptions["object_id"].startswith("scene object id") and "class names" in descriptions["class_index"]


def test_our_reader_reads_the_file(tmp_path: Path) -> None:
    path = tmp_path / "s.laz"
    path.write_bytes(_scan().to_las_bytes(True))
    got = read_las(path)
    assert got.classification.tolist() == [2, 3, 4, 5, 6, 1, 2, 5]
    assert got.gps_time.min() > 4e8


def test_height_above_ground_is_in_the_world_frame() -> None:
    """The same returns in the sensor frame (the sensor 1.8 m up) get the same classes; the ground may lie elsewhere."""
    world, _ = _read(_scan("world"))
    sensor, _ = _read(_scan("sensor"))
    assert sensor.classification.tolist() == world.classification.tolist()
    lower, _ = _read(_scan("world"), ground_z_m=-1.0)  # every point 1 m higher above the ground
    assert lower.classification.tolist() == [2, 4, 5, 5, 6, 1, 2, 5]


def test_intensity_counts_through_the_scale() -> None:
    legacy, _ = _read(_scan())  # no scale anywhere: 65535 per m⁻², as the files were
    assert legacy.intensity.tolist() == [7, 32768, 65535, 65535, 16384, 0, 66, 6554]
    given, _ = _read(_scan(intensity_scale=20000.0), intensity_scale=100.0)  # the call's wins
    assert given.intensity.tolist() == [0, 50, 100, 200, 25, 0, 0, 10]
    eight_bits, _ = _read(_scan(intensity_scale=20000.0, max_intensity=255))  # an 8-bit scanner's counts stop at 255
    assert eight_bits.intensity.tolist() == [2, 255, 255, 255, 255, 0, 20, 255]
    no_returns, _ = _read(_scan(intensity=None))
    assert no_returns.intensity.tolist() == [0] * 8
    with pytest.raises(InvalidInputError, match="intensity_scale"):
        _scan().to_las_bytes(intensity_scale=0.0)


def test_gps_start_and_scan_number() -> None:
    las, _ = _read(_scan(), gps_start_s=1000.0, scan_number=7)
    assert np.asarray(las.gps_time).tolist() == (1000.0 + _scan().gps_time).tolist()
    assert las.point_source_id.tolist() == [7] * 8
    with pytest.raises(InvalidInputError, match="gps_start_s 100 puts the scan's first time at -20"):
        _scan().to_las_bytes(gps_start_s=100.0)
    with pytest.raises(InvalidInputError, match="scan_number"):
        _scan().to_las_bytes(scan_number=65536)
    stale = _scan()
    stale.meta["line_id"] = np.zeros(3, np.int32)  # not one per point (a selection's): the scan number
    assert _read(stale, scan_number=2)[0].point_source_id.tolist() == [2] * 8


def test_a_scan_without_classes_has_the_ground_and_unknown_objects() -> None:
    las, _ = _read(_scan(object_classes=None))
    assert las.classification.tolist() == [2, 1, 1, 1, 1, 1, 2, 1]
    (vlr,) = las.header.vlrs.get_by_id(CLASS_NAMES_USER_ID, [CLASS_NAMES_RECORD_ID])
    assert json.loads(vlr.record_data) == ["ground", ""]
    with pytest.raises(InvalidInputError, match="object_classes names 2 objects"):
        _scan(object_classes=("ground", "tree")).to_las_bytes()


def test_a_class_map_changes_the_classes() -> None:
    las, _ = _read(_scan(), class_map={"car": 64, "house": 1})
    assert las.classification.tolist() == [2, 3, 4, 5, 1, 64, 2, 5]


def test_crs_is_a_wkt_vlr() -> None:
    pytest.importorskip("pyproj", reason="the crs extra")
    for crs in ("EPSG:2154", 2154, "epsg:2154"):
        las, _ = _read(_scan(), crs=crs)
        assert las.header.global_encoding.wkt
        assert las.header.parse_crs().to_epsg() == 2154
        assert las.header.vlrs.get("WktCoordinateSystemVlr")
    for compress in (False, True):
        assert _read(_scan(), compress, crs=2154)[0].header.parse_crs().to_epsg() == 2154
    with pytest.raises(InvalidInputError, match=r"crs EPSG:4326 \(WGS 84\) has axes in degree"):
        _scan().to_las_bytes(crs="EPSG:4326")
    with pytest.raises(InvalidInputError, match="EPSG:999999 is not"):
        _scan().to_las_bytes(crs=999999)


@pytest.mark.parametrize("crs", ["2154", "EPSG:", "EPSG:-5", "EPSG:21 54", "WGS84", "EPSG:" + "9" * 40])
def test_a_crs_that_is_no_epsg_code_is_refused(crs: str) -> None:
    with pytest.raises(InvalidInputError, match="crs must be an EPSG code"):
        _scan().to_las_bytes(crs=crs)


def test_crs_on_a_sensor_frame_scan_is_refused() -> None:
    with pytest.raises(InvalidInputError, match=r"labels world coordinates: it needs frame world \(the points are in the sensor frame\)"):
        _scan("sensor").to_las_bytes(crs="EPSG:2154")


def test_crs_without_pyproj_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "pyproj", None)  # import pyproj raises ImportError
    with pytest.raises(BackendUnavailable, match=r"needs pyproj: .*crs"):
        _scan().to_las_bytes(crs="EPSG:2154")


def test_las_bytes_refuses_class_indices_without_their_names() -> None:
    f = dict(intensity=[0, 0], return_number=[1, 1], number_of_returns=[1, 1], gps_time=[0.0, 1.0], scan_angle_deg=[0.0, 0.0])
    points = np.zeros((2, 3))
    with pytest.raises(InvalidInputError, match="give both or neither"):
        las_bytes(points, **f, survey=SurveyFields(class_index=[0, 0]))
    with pytest.raises(InvalidInputError, match="class_index must be finite and within"):
        las_bytes(points, **f, survey=SurveyFields(class_index=[0, 2], class_names=["a", "b"]))
    with pytest.raises(InvalidInputError, match="a VLR holds at most 65,535"):
        las_bytes(points, **f, survey=SurveyFields(class_index=[0, 0], class_names=["x" * 70_000]))
    with pytest.raises(InvalidInputError, match="object_id must be finite and within"):
        las_bytes(points, **f, survey=SurveyFields(object_id=[0, 2**40]))


def test_the_npz_keeps_the_classes_and_the_scale(tmp_path: Path) -> None:
    s = _scan(intensity_scale=1234.5, max_intensity=4095)
    back = read_scan_npz(s.to_npz(tmp_path / "s.npz"))
    assert back.object_classes == CLASSES and back.intensity_scale == 1234.5 and back.max_intensity == 4095
    mine, theirs = _read(back)[0], _read(s)[0]
    assert mine.classification.tolist() == theirs.classification.tolist() and mine.intensity.tolist() == theirs.intensity.tolist()
    plain = read_scan_npz(_scan(object_classes=None).to_npz(tmp_path / "p.npz"))
    assert plain.object_classes is None and plain.intensity_scale is None and plain.max_intensity is None


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [("object_classes", np.array([1, 2]), "object_classes must be"), ("object_classes", np.array([["a"]]), "object_classes must be"),
     ("intensity_scale", np.array([1.0, 2.0]), "intensity_scale must be"), ("intensity_scale", np.array(np.nan), "intensity_scale must be"),
     ("intensity_scale", np.array(-1.0), "intensity_scale must be"), ("intensity_scale", np.array("x"), "intensity_scale must be"),
     ("max_intensity", np.array(0), "max_intensity must be"), ("max_intensity", np.array(70000), "max_intensity must be"),
     ("max_intensity", np.array(255.0), "max_intensity must be")],
)  # fmt: skip
def test_a_damaged_npz_is_refused_naming_the_key(tmp_path: Path, key: str, value: np.ndarray, match: str) -> None:
    arrays = _scan().arrays()
    arrays[key] = value
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(InvalidInputError, match=match) as info:
        read_scan_npz(path)
    assert str(path) in str(info.value)
