"""Contact sheets of data sets and scan folders: the rows chosen, the camera column, the complete cloud, the PNG."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import SAMPLE_MESHES, tiny_dataset

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.contact_sheet import (
    DEFAULT_DPI,
    MAX_DPI,
    MAX_SHEET_PIXELS,
    MAX_SHEET_ROWS,
    contact_sheet,
)
from zbuf_occlude.experiments.sheet_drawing import PANEL_INCHES
from zbuf_occlude.geometry.cameras import camera_on_sphere
from zbuf_occlude.sensors.patterns.spinning import LIDAR_PRESETS
from zbuf_occlude.sensors.scan_data import read_scan_npz

pytestmark = pytest.mark.slow  # each fixture renders a small data set or scans a mesh

CHAIR = SAMPLE_MESHES / "chair" / "train" / "chair_0001.off"
DPI = 40  # small PNGs: the tests look at sizes and pixels, not at details


@pytest.fixture(scope="module")
def compact(tmp_path_factory) -> Path:
    """A chair (train) and a desk (test), poses 0:0 and 30:90, 64-point samples of a 1,024-point dense cloud."""
    return tiny_dataset(tmp_path_factory.mktemp("compact") / "ds", "compact")


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> Path:
    """Three VLP-16 crops of the chair, written by ``zbuf-occlude scan`` (npz and ply)."""
    out = tmp_path_factory.mktemp("scans") / "scans"
    args = ["scan", str(CHAIR), "--out", str(out), "--samples", "3", "--crop", "--sensor", "vlp16", "--format", "both",
            "--azimuth=-30:30", "--distance", "8:12"]  # fmt: skip
    assert main(args) == 0
    return out


def _png(path: Path) -> np.ndarray:
    import matplotlib.image

    return matplotlib.image.imread(path)


def _panel_px() -> int:
    return round(PANEL_INCHES * DPI)


def test_a_data_set_sheet_has_every_class_and_pose(compact: Path, tmp_path: Path) -> None:
    sheet = contact_sheet(compact, tmp_path / "sheet.png", per_class=1, poses=2, seed=3, dpi=DPI)
    assert sheet.source == "dataset"
    assert [r.class_name for r in sheet.rows] == ["chair", "chair", "desk", "desk"]
    assert sorted({(r.name, r.elevation_deg, r.azimuth_deg) for r in sheet.rows}) == [
        (name, el, az) for name in ("chair/train/chair_0001", "desk/test/desk_0201") for el, az in ((0.0, 0.0), (30.0, 90.0))
    ]
    assert sheet.shape == (4, 3) and len(sheet.figure.axes) == 12
    for row in sheet.rows:  # titles name the class, the mesh, the pose and the point count
        assert row.titles[0].startswith(f"{row.class_name}: {row.name}\n")
        assert f"el {row.elevation_deg:.0f}°, az {row.azimuth_deg:.0f}°, 64 points" in row.titles[0]
    image = _png(sheet.path)
    assert image.shape[:2] == (4 * _panel_px(), 3 * _panel_px())
    assert image[..., :3].mean(axis=2).std() > 0.05  # not blank
    assert not list(tmp_path.glob(".*.tmp"))  # written through a temporary file, renamed


def test_the_camera_column_is_the_pose_that_made_the_sample(compact: Path, tmp_path: Path) -> None:
    from zbuf_occlude.mesh.load import load_mesh
    from zbuf_occlude.visibility.registry import visible_mask

    resolution = OccludedDataset(compact).card["params"]["resolution"]
    sheet = contact_sheet(compact, tmp_path / "sheet.png", per_class=1, poses=2, dpi=DPI)
    seen, seen_from_behind = [], []
    for row in sheet.rows:
        assert row.camera_units == "pixels" and row.camera.resolution == (resolution, resolution)
        # inside the image the card's resolution gives (pixel centres at integers: edges at -1/2, W - 1/2)
        assert row.camera_bounds == ((-0.5, resolution - 0.5), (-0.5, resolution - 0.5))
        assert np.all((row.camera_view >= -0.5) & (row.camera_view < resolution - 0.5))
        assert np.allclose(row.camera_view, row.camera.project(row.points)[0])
        # the sample's points are the ones this camera sees (the exact oracle on the mesh), not
        # the ones the camera on the other side sees
        mesh = load_mesh(SAMPLE_MESHES / f"{row.name}.off")
        behind = camera_on_sphere(-row.elevation_deg, row.azimuth_deg + 180.0, row.camera.radius, resolution=resolution)
        seen.append(visible_mask(mesh, row.points, row.camera, "oracle").mean())
        seen_from_behind.append(visible_mask(mesh, row.points, behind, "oracle").mean())
    assert min(seen) >= 0.9 and all(a > b for a, b in zip(seen, seen_from_behind, strict=True))
    assert np.mean(seen_from_behind) < 0.75


def test_the_complete_column_is_the_cloud_the_sample_was_drawn_from(compact: Path, tmp_path: Path) -> None:
    sheet = contact_sheet(compact, tmp_path / "sheet.png", per_class=1, poses=1, dpi=DPI)
    for row in sheet.rows:
        assert row.complete.shape == (1024, 3) and row.titles[2] == "complete: 1024 points"
        # compact storage redraws each sample from the dense cloud (no point topped up here)
        assert np.isin(row.points.view("f8,f8,f8"), row.complete.view("f8,f8,f8")).all()
        # the fixed view is one camera for every row: the same projection of the sample and of the cloud
        assert np.allclose(row.fixed_view, sheet.fixed_camera.project(row.points)[0])
        assert np.allclose(row.complete_view, sheet.fixed_camera.project(row.complete)[0])


def test_a_data_set_without_its_complete_cloud_says_so(tmp_path: Path) -> None:
    ds = tiny_dataset(tmp_path / "ds", "dense")
    sheet = contact_sheet(ds, tmp_path / "sheet.png", per_class=1, poses=1, dpi=DPI)
    assert len(sheet.rows) == 2
    assert all(r.complete is None and r.titles[2] == "complete: not stored" for r in sheet.rows)
    assert not sheet.figure.axes[2].axison  # an empty panel with its title


def test_a_scan_folder_sheet_shows_the_sensors_rings(scans: Path, tmp_path: Path) -> None:
    sheet = contact_sheet(scans, tmp_path / "sheet.png", per_class=1, poses=2, seed=1, dpi=DPI)
    assert sheet.source == "scans" and sheet.shape == (2, 3)
    elevations = np.asarray(LIDAR_PRESETS["vlp16"].elevations_deg)
    for row in sheet.rows:
        assert row.class_name == "chair_0001_vlp16" and row.name.endswith(".npz")
        scan = read_scan_npz(scans / row.name)
        assert len(row.points) == len(scan) and f"{len(scan)} returns" in row.titles[0]
        # the sensor column: every return on its beam's elevation, seen from the sensor (not from the ground)
        assert row.camera_units == "degrees"
        assert np.allclose(row.camera_view[:, 1], elevations[scan.ring], atol=0.01)
        assert row.camera_bounds[1] == (elevations.min() - 1.0, elevations.max() + 1.0)
        assert row.complete is None and row.titles[2] == "complete: not stored"
        # a sensor 1.8 m high, 8-12 m from an object 4.5 m long: seen from near the horizon
        assert abs(row.elevation_deg) < 20.0
    image = _png(sheet.path)
    assert image.shape[:2] == (2 * _panel_px(), 3 * _panel_px())
    assert image[..., :3].mean(axis=2).std() > 0.05


def test_a_depth_camera_scan_is_drawn_at_its_pixels(tmp_path: Path) -> None:
    from zbuf_occlude.sensors.patterns.depth_camera import DEPTH_CAMERA_PRESETS

    scene = SAMPLE_MESHES.parent / "scenes" / "street.json"
    assert main(["scan", str(scene), "--sensor", "kinect-v1", "--out", str(tmp_path / "scans")]) == 0
    sheet = contact_sheet(tmp_path / "scans", tmp_path / "sheet.png", dpi=DPI)
    (row,) = sheet.rows
    camera = DEPTH_CAMERA_PRESETS["kinect-v1"]
    scan = read_scan_npz(tmp_path / "scans" / row.name)
    assert row.camera_units == "pixels" and row.camera_bounds == ((-0.5, camera.width - 0.5), (-0.5, camera.height - 0.5))
    keep = scan.object_id > 0 if np.any(scan.object_id > 0) else slice(None)
    assert np.array_equal(row.camera_view, scan.pixel[keep])


def test_titles_are_readable_and_a_long_name_fits_its_panel(scans: Path, compact: Path, tmp_path: Path) -> None:
    import shutil

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    folder = tmp_path / "long"
    folder.mkdir()
    long_stem = "a_mesh_named_as_a_catalogue_names_it_street_furniture_bench_with_backrest_model_42"
    shutil.copy(next(scans.glob("*_s000.npz")), folder / f"{long_stem}_vlp16_s000.npz")
    sheet = contact_sheet(folder, tmp_path / "sheet.png", dpi=DEFAULT_DPI)
    assert long_stem in sheet.rows[0].titles[0]  # the row keeps the whole name; the panel shows what fits
    for figure in (sheet.figure, contact_sheet(compact, tmp_path / "ds.png", per_class=1, poses=1, dpi=DEFAULT_DPI).figure):
        canvas = FigureCanvasAgg(figure)
        canvas.draw()
        renderer = canvas.get_renderer()
        column = figure.bbox.width / 3
        for k, ax in enumerate(figure.axes):
            title = ax.title
            # capitals at least 9 pixels tall at the default dpi: the font's size in pixels, and an "H" as Agg draws it
            assert title.get_fontsize() * DEFAULT_DPI / 72 >= 12.0
            _, height, descent = renderer.get_text_width_height_descent("H", title.get_fontproperties(), ismath=False)
            assert height - descent >= 8.5
            box = title.get_window_extent(renderer)
            assert (k % 3) * column <= box.x0 and box.x1 <= (k % 3 + 1) * column, (title.get_text(), box)
            assert "…" not in title.get_text().split("\n", 1)[-1]  # counts are wrapped, never cut
    shown = sheet.figure.axes[0].title.get_text()
    assert "…" in shown and shown.startswith("a_mesh") and "s000.npz" in shown  # its start and its end


def test_the_same_seed_draws_the_same_sheet(scans: Path, tmp_path: Path) -> None:
    names = [[r.name for r in contact_sheet(scans, tmp_path / f"{k}.png", per_class=1, poses=2, seed=7, dpi=DPI).rows] for k in range(2)]
    assert names[0] == names[1]
    seeds = {tuple(r.name for r in contact_sheet(scans, tmp_path / "s.png", per_class=1, poses=1, seed=s, dpi=DPI).rows) for s in range(8)}
    assert len(seeds) > 1  # the seed chooses among the three scans


def test_bad_inputs_are_refused_by_name(compact: Path, tmp_path: Path, capsys) -> None:
    with pytest.raises(InvalidInputError, match="is neither a data set"):
        contact_sheet(SAMPLE_MESHES, tmp_path / "a.png")
    with pytest.raises(InvalidInputError, match="per_class must be an integer >= 1, got 0"):
        contact_sheet(compact, tmp_path / "a.png", per_class=0)
    with pytest.raises(InvalidInputError, match="MAX_SHEET_ROWS"):
        contact_sheet(compact, tmp_path / "a.png", per_class=MAX_SHEET_ROWS)
    with pytest.raises(InvalidInputError, match=r"ending in \.png"):
        contact_sheet(compact, tmp_path / "a.jpg")
    not_a_scan = tmp_path / "folder"
    not_a_scan.mkdir()
    (not_a_scan / "x_s000.npz").write_bytes(b"not a zip")
    with pytest.raises(InvalidInputError, match="x_s000.npz"):
        contact_sheet(not_a_scan, tmp_path / "a.png")
    assert not list(tmp_path.glob("*.png"))

    for args, named in (([str(SAMPLE_MESHES)], str(SAMPLE_MESHES)), ([str(compact), "--per-class", "0"], "--per-class")):
        assert main(["contact-sheet", *args, "--out", str(tmp_path / "out" / "a.png")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and named in err and "Traceback" not in err
    assert not (tmp_path / "out").exists()  # a refused run leaves no folder behind
    assert main(["contact-sheet", str(compact), "--out", str(tmp_path / "a.png"), "--dpi", "601"]) == 2
    assert "--dpi must be at most 600 (MAX_DPI), got 601" in capsys.readouterr().err


def test_the_command_writes_the_png(compact: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "sheets" / "sheet.png"
    assert main(["contact-sheet", str(compact), "--out", str(out), "--per-class", "1", "--poses", "1", "--dpi", str(DPI)]) == 0
    assert capsys.readouterr().out == f"2 rows (dataset) -> {out}\n"
    assert _png(out).shape[:2] == (2 * _panel_px(), 3 * _panel_px())


def test_a_scan_with_a_non_finite_point_is_refused_naming_the_file(scans: Path, tmp_path: Path, capsys) -> None:
    folder = tmp_path / "damaged"
    folder.mkdir()
    name = sorted(p.name for p in scans.glob("*.npz"))[0]
    with np.load(scans / name) as z:
        arrays = {k: z[k] for k in z.files}
    for bad in (np.nan, np.inf):
        arrays["points"][3, 1] = bad
        np.savez(folder / name, **arrays)
        with pytest.raises(InvalidInputError, match=rf"{name}: 1 point has NaN or inf coordinates"):
            contact_sheet(folder, tmp_path / "a.png", dpi=DPI)
        assert main(["contact-sheet", str(folder), "--out", str(tmp_path / "a.png"), "--dpi", str(DPI)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and str(folder / name) in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.png"))


def _unread_scans(folder: Path, meshes: int) -> Path:
    """A folder of ``meshes`` one-scan groups that are not scans at all: a sheet's size is checked before a file is read."""
    folder.mkdir()
    for k in range(meshes):
        (folder / f"mesh_{k:04d}_vlp16_s000.npz").write_bytes(b"not read")
    return folder


def test_the_sheet_s_pixels_are_capped_before_any_scan_is_read(tmp_path: Path, capsys) -> None:
    # 60 rows at 600 dpi: 60 x 3 panels of 1,320 pixels a side, 314 M pixels; refused up front, naming the values
    folder = _unread_scans(tmp_path / "many", 60)
    with pytest.raises(InvalidInputError, match=r"60 rows at 600 dpi.*MAX_SHEET_PIXELS.*lower dpi to 271 or less"):
        contact_sheet(folder, tmp_path / "a.png", dpi=MAX_DPI)
    assert main(["contact-sheet", str(folder), "--out", str(tmp_path / "a.png"), "--dpi", str(MAX_DPI)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "MAX_SHEET_PIXELS" in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.png"))


def test_the_largest_sheet_the_cap_allows_is_under_pils_bomb_limits(tmp_path: Path) -> None:
    from PIL import Image

    # the PNG is read back by PIL to make its palette: under PIL's own limit (a
    # DecompressionBombWarning past it, an error at twice), whatever the rows; and under Agg's
    # 2**16 pixels a side at MAX_SHEET_ROWS (a 12-row sheet at MAX_DPI, 63 M pixels, was drawn
    # once with the warning as an error: 13 s, too slow to repeat here)
    assert MAX_SHEET_PIXELS < Image.MAX_IMAGE_PIXELS
    assert math.sqrt(MAX_SHEET_ROWS * MAX_SHEET_PIXELS / 3) < 2**16
    rows = int(MAX_SHEET_PIXELS // (3 * (PANEL_INCHES * MAX_DPI) ** 2))  # the most rows at MAX_DPI
    assert rows == 12 and int(3 * PANEL_INCHES * MAX_DPI) * int(rows * PANEL_INCHES * MAX_DPI) <= MAX_SHEET_PIXELS
    with pytest.raises(InvalidInputError, match=r"13 rows at 600 dpi.*lower dpi to 582 or less"):
        contact_sheet(_unread_scans(tmp_path / "more", rows + 1), tmp_path / "a.png", per_class=1, poses=1, dpi=MAX_DPI)


def test_a_card_without_a_radius_is_refused_naming_it(tmp_path: Path, capsys) -> None:
    import json

    from zbuf_occlude.dataset.schema import card_sha256_line
    from zbuf_occlude.io.atomic import file_sha256

    ds = tiny_dataset(tmp_path / "ds", "dense")
    card_file = ds / "dataset_card.json"
    card = json.loads(card_file.read_text())
    assert card["params"]["radius"] == 4.0  # every farm and generate card has it
    del card["params"]["radius"]
    card_file.write_text(json.dumps(card))
    (ds / "dataset_card.json.sha256").write_text(card_sha256_line(file_sha256(card_file)))
    with pytest.raises(InvalidInputError, match=r"dataset_card.json field 'params.radius' is missing"):
        contact_sheet(ds, tmp_path / "a.png", per_class=1, poses=1, dpi=DPI)
    assert main(["contact-sheet", str(ds), "--out", str(tmp_path / "a.png"), "--dpi", str(DPI)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(card_file) in err and "params.radius" in err
    assert not list(tmp_path.glob("*.png"))
