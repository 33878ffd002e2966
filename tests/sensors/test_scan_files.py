"""A scan run by the library from a request and a placement (``run_scan``): what it writes, and what it refuses
before it holds the folder, in the caller's words."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.placement import CropDistributions, ObjectPlacement
from zbuf_occlude.sensors.request import ScanRequest
from zbuf_occlude.sensors.scan_data import read_scan_npz
from zbuf_occlude.sensors.scan_files import run_scan

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "data" / "scenes" / "street.json"
CAR = CropDistributions(distance_m=10.0, height_m=1.8, size_m=4.5, azimuth_deg=0.0, yaw_deg=0.0)


def test_a_request_by_name_scans_a_primitive_into_its_own_folder(tmp_path: Path) -> None:
    request = ScanRequest("vlp16", samples=2, formats=("npz",))
    written = list(run_scan(request, "box", tmp_path / "o", ObjectPlacement(CAR), seed=3, crop=True))
    assert [w.files[0].name for w in written] == ["box_vlp16_s000.npz", "box_vlp16_s001.npz"]
    assert all(w.object_returns > 0 and w.distance_m == pytest.approx(10.0) for w in written)
    s = read_scan_npz(written[0].files[0])
    assert len(s) == written[0].object_returns and np.all(s.object_id != 0)  # the crop: the object's returns only
    again = list(run_scan(request, "box", tmp_path / "p", ObjectPlacement(CAR), seed=3, crop=True))
    assert again[1].files[0].read_bytes() == written[1].files[0].read_bytes()


def test_nothing_is_read_or_written_before_the_first_scan_is_asked_for(tmp_path: Path) -> None:
    scans = run_scan(ScanRequest("vlp16"), "box", tmp_path / "o", ObjectPlacement(CAR))
    assert not (tmp_path / "o").exists()
    next(scans)
    assert (tmp_path / "o" / "box_vlp16_s000.npz").is_file()


@pytest.mark.parametrize(
    ("source", "request_fields", "kwargs", "words"),
    [
        ("box", {"trajectory": "DRIVE"}, {}, r"^--trajectory moves the sensor through a scene file's frame"),
        (SCENE, {}, {"crop": True}, r"^--crop keeps one mesh's returns; street.json is a scene file"),
        ("box", {"sensor": "kinect-v1"}, {}, r"places a LiDAR; use a scene file for a depth camera"),
    ],
)  # fmt: skip
def test_what_a_run_refuses_names_the_callers_option(tmp_path: Path, source, request_fields: dict, kwargs: dict, words: str) -> None:
    drive = tmp_path / "drive.csv"  # a trajectory by its file, read with the request
    drive.write_text("time_s,x_m,y_m,z_m,roll_deg,pitch_deg,yaw_deg\n0,0,0,1.8,0,0,0\n1,2,0,1.8,0,0,0\n")
    fields = {"sensor": "vlp16", **{k: drive if v == "DRIVE" else v for k, v in request_fields.items()}}
    request = ScanRequest(fields.pop("sensor"), names={"trajectory": "--trajectory", "crop": "--crop"}, **fields)
    with pytest.raises(InvalidInputError, match=words):
        list(run_scan(request, source, tmp_path / "o", ObjectPlacement(CAR), **kwargs))
    assert not any((tmp_path / "o").glob("*.npz"))


def test_a_primitive_has_no_length_or_height_of_its_own(tmp_path: Path) -> None:
    placement = ObjectPlacement(CAR, size_of="height", names={"size_of": "--size-of", "size_m": "--size"})
    with pytest.raises(InvalidInputError, match=r"^--size-of height measures a mesh file; a primitive takes --size"):
        list(run_scan(ScanRequest("vlp16"), "cylinder", tmp_path / "o", placement))


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"size_of": "width"}, r"^size_of must be one of length, height, max"),
        ({"size_of": "height", "distributions": CropDistributions(extents_m=(1, 1, 2))}, r"^size_of height says what size_m measures"),
        ({"across_sight_width_m": (0.0, 0.0)}, r"^across_sight_width_m must have HI > 0 metres"),
        ({"width_profile": ("1", "x")}, r"^width_profile must be 2 or more numbers > 0, V,V,\.\.\., bottom to top, got '1,x'"),
        ({"width_profile": (1.0,)}, r"^width_profile must be 2 or more numbers > 0"),
        ({"occlude": True}, r"^occlude meets across_sight_width_m with a side occluder: it needs across_sight_width_m"),
    ],
)  # fmt: skip
def test_a_placement_checks_its_fields_on_construction(fields: dict, words: str) -> None:
    with pytest.raises(InvalidInputError, match=words):
        ObjectPlacement(**fields)
    assert ObjectPlacement(across_sight_width_m=0.5, width_profile=("1", "2")).width_profile == (1.0, 2.0)


def test_a_request_without_las_keywords_writes_las_at_the_default_gps_start(tmp_path: Path) -> None:
    laspy = pytest.importorskip("laspy")
    (written,) = run_scan(ScanRequest("vlp16", formats=("las",)), "box", tmp_path / "o", ObjectPlacement(CAR))
    las = laspy.read(written.files[0])
    assert len(las.points) > 0 and float(np.min(las.gps_time)) >= 0
