"""``fit-sensor --meshes``: the partial echoes' threshold fitted and written into the sensor file beside the geometry's
fit; the inputs it cannot take (LAS/LAZ scans, a sensor that is no spinning LiDAR, a bad count, a hostile meshes folder)
refused in one line, before any scan is read, with nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.sensors.fit import mesh_crops as pc
from zbuf_occlude.sensors.fit import partial_echo_meshes as pe
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.real_scans.datasets import LIDARNET_UNITS_PER_METRE
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset

HEADER = "origin_x,origin_y,origin_z,relative_x,relative_y,relative_z,object,complexity\n"


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    code = cli_main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err.strip()


@pytest.fixture(scope="module")
def folders(tmp_path_factory) -> tuple[Path, Path]:
    """A meshes folder (two car-sized boxes, two poles) and LiDARNet-style scans of its meshes 5.5-9 m away, made by an
    HDL-32E with a footprint that drops echoes of less than 0.2 apparent reflectance."""
    root = tmp_path_factory.mktemp("fit_meshes")
    shapes = {"car": [trimesh.creation.box((4.0, 1.8, 1.5)), trimesh.creation.box((4.5, 1.9, 1.3))],
              "pole": [trimesh.creation.cylinder(0.1, 5.0, sections=16), trimesh.creation.cylinder(0.12, 6.0, sections=12)]}  # fmt: skip
    for name, meshes in shapes.items():
        (root / "meshes" / name).mkdir(parents=True)
        for i, mesh in enumerate(meshes):
            mesh.export(root / "meshes" / name / f"m{i}.obj")
    truth = pe.partial_echo_sensor(with_beam(lidar_preset("hdl32e"), range_noise_m=0.02), 0.2)
    near = CropPlacement.from_keywords({c: {"distance_m": (5.5, 9.0)} for c in shapes})
    for c in pc.mesh_crops(find_class_meshes(root / "meshes"), truth, 3, 5, placement=near):
        folder = root / "scans" / c.class_name.title()
        folder.mkdir(parents=True, exist_ok=True)
        p = c.points_m
        y_up = np.stack([p[:, 0], p[:, 2], -p[:, 1]], axis=1) * LIDARNET_UNITS_PER_METRE  # the data set's axes and unit
        rows = "".join(f"{x},{y},{z},0,0,0,{c.class_name},0\n" for x, y, z in y_up)
        (folder / f"{c.mesh.replace('/', '_')}_{c.crop}.csv").write_text(HEADER + rows)
    return root / "scans", root / "meshes"


def test_the_fitted_threshold_is_written_into_the_sensor_file_with_its_table(folders, tmp_path: Path, capsys) -> None:
    scans, meshes = folders
    out = tmp_path / "fitted.json"
    code, said, err = _run(["fit-sensor", str(scans), "--sensor", "hdl32e", "--meshes", str(meshes), "--crops-per-mesh", "3",
                            "--seed", "3", "--out", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    spec = json.loads(out.read_text())
    fit = spec["fit"]["partial_echoes"]
    fitted = sensor_from_name(str(out))
    assert fitted.beam.min_echo_reflectance == fit["estimate"]["value"] > 0  # the file's beam carries the fitted threshold
    assert (fitted.beam.footprint_rays, fitted.beam.return_mode, fitted.beam.divergence_deg) == (7, "strongest", 0.16)
    assert fitted.beam.range_noise_m == pytest.approx(0.02, rel=0.2)  # the geometry's fit is kept
    assert "estimates" in spec["fit"] and fit["classes"] and set(fit["classes"]) <= {"car", "pole"}
    table = out.with_suffix(".md").read_text()
    assert "## Detection of partial echoes" in table and "| J |" in table and "range_noise_m" in table
    assert "fitted min_echo_reflectance" in said and "threshold 0.5" in said


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--sensor", "riegl-q1560"], "--meshes: fits a spinning LiDAR, and --sensor riegl-q1560 is a AirborneScanner"),
        (["--sensor", "kinect-v1"], "--meshes: fits a spinning LiDAR, and --sensor kinect-v1 is a DepthCamera"),
        (["--sensor", "hdl32e", "--crops-per-mesh", "0"], "--crops-per-mesh must be an integer >= 1"),
        (["--sensor", "hdl32e", "--crops-per-mesh", "x"], "--crops-per-mesh must be a whole number"),
        (["--sensor", "hdl32e", "--crops-per-mesh", "1000000"], "--crops-per-mesh must be at most 100,000"),
        (["--sensor", "hdl32e", "--up-map", "car/*=+w"], "--up-map: axis must be one of"),
    ],
)  # fmt: skip
def test_what_the_fit_cannot_take_is_refused_before_reading_and_writes_nothing(folders, tmp_path: Path, capsys, argv, message) -> None:
    scans, meshes = folders
    out = tmp_path / "f.json"
    code, _, err = _run(["fit-sensor", str(scans), "--meshes", str(meshes), "--out", str(out), *argv], capsys)
    assert code == 2 and message in err and len(err.splitlines()) == 1, err
    assert not out.exists() and not out.with_suffix(".md").exists()


def test_meshes_with_las_scans_or_its_options_without_meshes_are_refused(folders, tmp_path: Path, capsys) -> None:
    scans, meshes = folders
    (tmp_path / "a.laz").write_bytes(b"not a laz file")  # never read
    code, _, err = _run(["fit-sensor", str(tmp_path / "a.laz"), "--sensor", "hdl32e", "--altitude", "50", "--meshes", str(meshes),
                         "--out", str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 2 and err.endswith(
        "--meshes: fits a spinning LiDAR to object scans, and " + str(tmp_path / "a.laz") + " holds LAS/LAZ scans"
    )
    code, _, err = _run(
        ["fit-sensor", str(scans), "--sensor", "hdl32e", "--crops-per-mesh", "2", "--out", str(tmp_path / "f.json")], capsys
    )
    assert code == 2 and err.endswith("--crops-per-mesh: for the partial echoes' fit, which --meshes FOLDER asks for")
    code, _, err = _run(["fit-sensor", str(scans), "--sensor", "hdl32e", "--meshes", str(tmp_path / "nowhere"), "--out",
                         str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 2 and err.endswith("nowhere is not a folder")
    assert not (tmp_path / "f.json").exists()


def test_a_link_out_of_the_meshes_folder_is_one_line_before_any_scan_is_read(tmp_path: Path, capsys) -> None:
    (tmp_path / "meshes" / "car").mkdir(parents=True)
    (tmp_path / "secret.txt").write_text("not yours")
    (tmp_path / "meshes" / "car" / "evil.obj").symlink_to(tmp_path / "secret.txt")
    (tmp_path / "scans").mkdir()  # no scans: refused for the link before they are looked for
    code, _, err = _run(["fit-sensor", str(tmp_path / "scans"), "--sensor", "hdl32e", "--meshes", str(tmp_path / "meshes"), "--out",
                         str(tmp_path / "f.json")], capsys)  # fmt: skip
    assert code == 2 and "evil.obj" in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_a_users_file_at_out_is_refused_and_left_as_it_is_before_a_mesh_is_scanned(folders, tmp_path: Path, capsys, monkeypatch) -> None:
    scans, meshes = folders
    out = tmp_path / "fitted.json"
    out.write_bytes(b'{"mine": true}')
    monkeypatch.setattr(pc, "mesh_crops", lambda *a, **k: pytest.fail("a mesh was scanned before --out was checked"))
    code, _, err = _run(["fit-sensor", str(scans), "--sensor", "hdl32e", "--meshes", str(meshes), "--out", str(out)], capsys)
    assert code == 2 and str(out) in err and "not recorded by a run of ours" in err and len(err.splitlines()) == 1, err
    assert out.read_bytes() == b'{"mine": true}' and sorted(p.name for p in tmp_path.iterdir()) == ["fitted.json"]
