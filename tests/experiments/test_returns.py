"""The returns experiment (experiments/returns.py, returns_comparison.py, returns_report.py) on tiny synthetic scenes: no ../shared data."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.returns import (
    AUTZEN_CELL_M,
    IGN_ALTITUDE_M,
    IGN_DIVERGENCE_DEG,
    PLOT_TREES,
    ign_scanner,
    object_pulse_shares,
    plot_scene,
    pulse_subset,
    simulate,
    simulated_classes,
)
from zbuf_occlude.experiments.canopy import canopy_height, classes_by_height, heights_above_ground
from zbuf_occlude.experiments.tree_cover import COVER_TOLERANCE, plot_cover, spacing_for_cover, tree_cover
from zbuf_occlude.experiments.returns_comparison import comparison_rows, cover_markdown, recommend_k
from zbuf_occlude.experiments.returns_report import ReturnsSettings, cover_rays_per_cell, refits_divergence, run_returns, scans_of_run
from zbuf_occlude.io.atomic import write_bytes
from zbuf_occlude.io.las import LasPoints, las_bytes, read_las
from zbuf_occlude.io.progress import PROGRESS_INTERVAL_ENV
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.io.tables import read_csv_rows
from zbuf_occlude.sensors.fit import Estimate
from zbuf_occlude.sensors.fit.return_model import GROUND_REFLECTANCE, fit_return_model
from zbuf_occlude.sensors.fit.returns import ReturnStatistics, return_statistics
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.scene.materials import reflectance
from zbuf_occlude.sensors.scene.objects import ScanScene, SceneObject

#: A footprint 1.5 m across at 1,500 m: plate edges split many pulses.
WIDE_DEG = math.degrees(1e-3)


def _plot():
    """A ground and two boxes: a 4 m tall post and a thin plate 2.5 m up (standing on a thin stem)."""
    post = trimesh.creation.box(extents=(1.2, 1.2, 4.0))
    plate = trimesh.util.concatenate([trimesh.creation.box(extents=(2.0, 2.0, 0.05)).apply_translation((0, 0, 2.5)),
                                      trimesh.creation.box(extents=(0.1, 0.1, 2.5)).apply_translation((0, 0, 1.25))])  # fmt: skip
    return plot_scene([post, plate], [4.0, 2.6], spacing_m=3.0, seed=0)


def test_the_las_round_trip_measures_what_the_scan_holds() -> None:
    scene, vegetation = _plot()
    scanner = ign_scanner(WIDE_DEG, 7)
    result = simulate(scene, scanner, vegetation, half_size_m=4.0, seeds=(0,), bootstrap=10)
    scan = result.scan
    assert result.statistics["vegetation"].estimates["returns_2"].value > 0.05  # the plates split pulses
    # the figures of the scan's own arrays, without the file: equal shares, gaps within the 1 mm steps
    full = 2.0 / scanner.altitude_m**2
    own = LasPoints(points=scan.points.astype(np.float64), intensity=np.rint(np.clip(scan.intensity / full, 0, 1) * 65535),
                    return_number=scan.return_number, number_of_returns=scan.number_of_returns, gps_time=scan.gps_time,
                    scan_angle_deg=scan.scan_angle_deg, classification=simulated_classes(scan, vegetation),
                    point_source_id=np.zeros(len(scan)), scanner_channel=np.zeros(len(scan)))  # fmt: skip
    mine, theirs = return_statistics(own, bootstrap=10).estimates, result.statistics["all"].estimates
    for name in ("returns_1", "returns_2", "returns_3", "multi_return_points", "multi_return_points_classes_3_4_5", "intensity_ratio"):
        assert mine[name].value == theirs[name].value, name
    for name in ("gap_min", "gap_median"):
        assert abs(mine[name].value - theirs[name].value) <= 2e-3, name
    assert theirs["gap_min"].value >= scanner.beam.range_resolution_m - 5 * scanner.beam.range_noise_m


def test_pooled_seeds_are_flight_lines_of_their_own() -> None:
    scene, vegetation = _plot()
    one = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0,), bootstrap=5)
    two = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0, 1), bootstrap=5)
    assert set(two.las.point_source_id.tolist()) == {0, 1}
    assert two.statistics["all"].n_pulses > one.statistics["all"].n_pulses
    assert two.pulses > one.pulses


def test_classes_follow_object_and_height() -> None:
    scene, vegetation = _plot()
    scan = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0,), bootstrap=5).scan
    classes = simulated_classes(scan, vegetation)
    assert np.all(classes[scan.object_id == 0] == 2)
    on = scan.object_id > 0
    assert np.all(classes[on][scan.points[on, 2] >= 1.5] == 5)
    assert np.all(simulated_classes(scan, ())[on] == 1)
    # low, medium and high vegetation by height above the ground (0.5 and 1.5 m)
    three = replace(scan.select(np.flatnonzero(on)[:4]), points=np.array([[0, 0, 0.2], [0, 0, 0.7], [0, 0, 1.6], [0, 0, 2.4]], np.float32))
    assert simulated_classes(three, vegetation).tolist() == [3, 4, 5, 5]
    assert simulated_classes(three, vegetation, ground_z_m=0.9).tolist() == [3, 3, 4, 5]


def _las(classes, times, numbers) -> LasPoints:
    n = len(classes)
    return LasPoints(points=np.zeros((n, 3)), intensity=np.ones(n), return_number=[1] * n, number_of_returns=numbers, gps_time=times,
                     scan_angle_deg=np.zeros(n), classification=classes, point_source_id=np.zeros(n), scanner_channel=np.zeros(n))  # fmt: skip


def test_pulse_subset_takes_whole_pulses() -> None:
    # pulse 0: vegetation then ground; pulse 1: ground only; pulse 2: building only
    las = _las([5, 2, 2, 6], [0.0, 0.0, 1.0, 2.0], [2, 2, 1, 1])
    assert pulse_subset(las, "vegetation").gps_time.tolist() == [0.0, 0.0]
    assert pulse_subset(las, "ground").gps_time.tolist() == [1.0]
    with pytest.raises(InvalidInputError, match="side"):
        pulse_subset(las, "water")
    with pytest.raises(InvalidInputError, match="no vegetation pulse"):
        pulse_subset(_las([2], [0.0], [1]), "vegetation")


def test_object_pulse_shares_count_the_objects_pulses_as_the_las_measure_does() -> None:
    scene, vegetation = _plot()
    result = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0,), bootstrap=5)
    shares, n = object_pulse_shares(result.scan, vegetation, seed=0, bootstrap=200)
    las_side = result.statistics["vegetation"]
    assert n == las_side.n_complete_pulses  # a pulse with a return on the boxes is a vegetation pulse of the file
    for k in (1, 2, 3, 4):
        value, sd = shares[f"returns_{k}"]
        assert value == pytest.approx(las_side.estimates[f"returns_{k}"].value, abs=1e-12)
        binomial = math.sqrt(value * (1 - value) / n)
        assert sd == pytest.approx(binomial, rel=0.35, abs=1e-9)  # a bootstrap over pulses of a share is binomial
    assert sum(shares[f"returns_{k}"][0] for k in (1, 2, 3, 4)) == pytest.approx(1.0)
    with pytest.raises(InvalidInputError, match="no pulse"):
        object_pulse_shares(result.scan, [99])


def _row(k: int, shares, sd: float = 0.01) -> dict:
    row = {"K": k}
    for i, share in enumerate(shares, start=1):
        row[f"returns_{i}"], row[f"returns_{i}_sd"] = share, sd
    return row


def test_recommend_k_is_the_smallest_within_the_largest_ks_uncertainty() -> None:
    rows = [_row(1, (1.0, 0.0, 0.0, 0.0)), _row(7, (0.7, 0.25, 0.05, 0.0)), _row(19, (0.62, 0.3, 0.07, 0.01)),
            _row(37, (0.61, 0.31, 0.07, 0.01)), _row(61, (0.6, 0.31, 0.08, 0.01))]  # fmt: skip
    assert recommend_k(rows) == 19
    assert recommend_k(list(reversed(rows))) == 19
    assert recommend_k([_row(k, (0.6, 0.3, 0.1, 0.0), sd=0.0) for k in (7, 19)]) == 7
    with pytest.raises(InvalidInputError):
        recommend_k([])


def _stats(values: dict[str, float]) -> ReturnStatistics:
    estimates = {name: Estimate(v, 0.01, 100, "test", "share") for name, v in values.items()}
    return ReturnStatistics(estimates, 100, 100, 100, (3, 4, 5), "m", 0, 2)


def test_comparison_verdicts_hold_the_tolerances() -> None:
    base = {"returns_1": 0.5, "returns_2": 0.4, "returns_3": 0.08, "returns_4": 0.02, "multi_return_points_classes_3_4_5": 0.6,
            "multi_return_points_class_2": 0.1, "gap_min": 0.82, "gap_median": 2.5, "intensity_ratio_classes_3_4_5": 0.5}  # fmt: skip
    real = {side: _stats(base) for side in ("all", "vegetation", "ground")}
    sim_values = base | {"returns_1": 0.59, "returns_2": 0.25, "gap_min": 0.84, "gap_median": 3.4, "intensity_ratio_classes_3_4_5": 0.3}
    sim = {side: _stats(sim_values) for side in ("all", "vegetation", "ground")}
    rows = {r["figure"]: r["verdict"] for r in comparison_rows(real, sim, real_classes=(3, 4, 5), range_resolution_m=0.82, label="t")}
    assert rows["vegetation pulses with 1 return"] == "PASS"  # +18 %
    assert rows["vegetation pulses with 2 returns"] == "FAIL"  # −37.5 %
    assert rows["smallest gap (m)"] == "PASS"  # +2.4 % of the resolution
    assert rows["median gap (m)"] == "FAIL"  # +36 %
    assert rows["intensity first-of-several / single, vegetation"] == "FAIL"


def _in_feet_unclassified(data: bytes) -> bytes:
    """A LAS file's bytes with its coordinates in international feet (a WKT saying so) and its vegetation (3–5) as class 1."""
    import io

    import laspy

    las = laspy.read(io.BytesIO(data))
    x, y, z = (np.asarray(v) / 0.3048 for v in (las.x, las.y, las.z))
    las.header.vlrs.append(laspy.vlrs.known.WktCoordinateSystemVlr('PROJCS["p",UNIT["foot",0.3048,AUTHORITY["EPSG","9002"]]]'))
    las.header.offsets = [0.0, 0.0, 0.0]
    las.x, las.y, las.z = x, y, z
    las.classification = np.where(np.isin(las.classification, (3, 4, 5)), 1, las.classification)
    buffer = io.BytesIO()
    las.write(buffer)
    return buffer.getvalue()


@pytest.mark.parametrize("detection", [True, False])
def test_run_returns_writes_its_outputs(tmp_path, detection, capsys, monkeypatch) -> None:
    meshes = tmp_path / "bush"
    meshes.mkdir()
    for i, tree in enumerate(PLOT_TREES):
        box = trimesh.creation.box(extents=(1.0 + 0.2 * i, 1.0, 2.0))
        write_bytes(meshes / (tree.file.rsplit(".", 1)[0] + ".obj"), box.export(file_type="obj").encode())
    trees = [type(t)(t.file.rsplit(".", 1)[0] + ".obj", "+z", 3.0) for t in PLOT_TREES]
    # a "real" file: the same kind of plot simulated at a wide beam, written with its classes
    scene, vegetation = _plot()
    real = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0,), bootstrap=5).las
    data = las_bytes(real.points, intensity=real.intensity, return_number=real.return_number, number_of_returns=real.number_of_returns,
                     gps_time=real.gps_time, scan_angle_deg=real.scan_angle_deg, classification=real.classification)  # fmt: skip
    real_path = write_bytes(tmp_path / "real.las", data)
    # without detection, an Autzen-like file too: the same scan in international feet, its vegetation unclassified (class 1)
    autzen_path = None if detection else write_bytes(tmp_path / "autzen.las", _in_feet_unclassified(data))
    import zbuf_occlude.experiments.returns_report as report

    # the crowns filled with leaves in one of the two runs (their build is most of a run's time)
    settings_ = ReturnsSettings(divergence_factors=(1.0, 8.0), sweep_rays=(7,), k_values=(1, 7), seeds=(0,), repeats=1, copies=1,
                                spacing_m=4.0, bootstrap=5, detection=detection, leaf_area_density=1.0 if detection else 0.0)  # fmt: skip
    original = report.PLOT_TREES
    report.PLOT_TREES = tuple(trees)
    try:
        monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")  # a line per scan in a log
        capsys.readouterr()
        summary = run_returns(tmp_path / "out", meshes, real_path, autzen_path=autzen_path, settings=settings_, progress=detection)
        scene, vegetation, centre, half = report.ign_plot(meshes, settings_)
    finally:
        report.PLOT_TREES = original
    out = tmp_path / "out"
    # the progress of the scans on stderr, one line each (stderr is not a terminal), up to the total; none with progress=False
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("returns: ")]
    total = scans_of_run(settings_)
    assert total == 2 * 1 * 1 + 2 * 1 + 0 + 2 * 1
    if detection:
        assert [int(line.split()[1].split("/")[0]) for line in lines] == list(range(1, total + 1)), lines
        assert all(f"/{total} scan" in line for line in lines)
    else:
        assert lines == []
    assert summary["recommended_k"] in (1, 7)
    assert summary["verdicts"]["PASS"] + summary["verdicts"]["FAIL"] + summary["verdicts"]["not measured"] == (2 if detection else 3) * 13
    assert read_regular_file(out / "returns.png", max_bytes=1 << 24)[:8] == b"\x89PNG\r\n\x1a\n"
    sweep = read_csv_rows(out / "divergence_sweep.csv")
    assert [float(r["divergence_deg"]) for r in sweep] == pytest.approx(
        [IGN_DIVERGENCE_DEG, 8 * IGN_DIVERGENCE_DEG] * (1 if detection else 2), rel=1e-5
    )
    k_rows = read_csv_rows(out / "k_sweep.csv")
    assert [int(r["K"]) for r in k_rows] == [1, 7]
    # K = 1 is one ray a pulse, opaque surfaces: one return each (the fit gives a one-ray beam a footprint; the sweep keeps K)
    assert float(k_rows[0]["multi_return_share"]) == 0.0 < float(k_rows[1]["multi_return_share"])
    assert len(read_csv_rows(out / "comparison.csv")) == (26 if detection else 39)
    if not detection:  # Autzen's plot: the IGN plot's meshes scaled to its canopy height, measured in metres on its class 1 by height
        autzen = read_las(autzen_path)
        assert autzen.linear_unit_m == pytest.approx(0.3048)
        classed = classes_by_height(autzen, heights_above_ground(autzen))
        canopy = summary["autzen_fit"]["canopy"]
        assert canopy["tile_m"] == pytest.approx(canopy_height(classed, cell_m=AUTZEN_CELL_M), rel=1e-12)
        assert canopy["tile_m"] == pytest.approx(canopy_height(read_las(real_path), cell_m=AUTZEN_CELL_M), abs=0.01)  # the feet undone
        assert canopy["height_scale"] == pytest.approx(canopy["tile_m"] / canopy["ign_plot_m"], rel=1e-12)
        assert canopy["tile_cover"]["value"] == tree_cover(classed, cell_m=AUTZEN_CELL_M, bootstrap=5).value
        assert "## Autzen (class 1 classed by height)" in read_regular_file(out / "real.md", max_bytes=1 << 20).decode()
    fitted = fit_return_model(read_las(real_path), altitude_m=IGN_ALTITUDE_M, bootstrap=5).estimates
    model = summary["model"]
    assert model["range_resolution_m"] == fitted["range_resolution_m"].value
    if detection:  # the scanner as the fit sets it, the ground at the fit's reflectance, the boxes ("vegetation") foliage's at 1064 nm
        assert model["detection_threshold"] == fitted["detection_threshold"].value > 0
        assert model["reflectivity"] == [GROUND_REFLECTANCE] + [reflectance("foliage", 1064.0)] * len(PLOT_TREES)
    else:
        assert "detection_threshold" not in model and model["detection"] is False
    assert "low_deg" not in summary["divergence_fits"][0]  # the fit's own ± sd only
    covers = summary["tree_cover"]  # the tile's measured by tree_cover, the scans' the same way, the spacing as given
    assert covers["tile"]["value"] == tree_cover(read_las(real_path), bootstrap=5).value
    assert covers["spacing_m"] == pytest.approx(4.0) and 0.0 <= covers["plot_vertical_rays"] <= 1.0
    assert set(covers["scans"]) == {"IGN, fitted divergence", "IGN, data-sheet divergence"}
    assert "Tree cover" in summary["table"] and "the real tile" in read_regular_file(out / "real.md", max_bytes=1 << 20).decode()
    # the sweep's first row is the fitted scanner over the plot with the model's reflectivity
    scanner = fit_return_model(read_las(real_path), altitude_m=IGN_ALTITUDE_M, bootstrap=5).apply(ign_scanner(IGN_DIVERGENCE_DEG, 7))
    assert model["echo_rule"] == "waveform"  # the experiment's receiver: echoes told apart on the waveform
    scanner = with_beam(scanner, echo_rule="waveform")
    if not detection:
        scanner = with_beam(scanner, detection_threshold=0.0)
    again = simulate(scene, scanner, vegetation, center_xy=centre, half_size_m=half, seeds=(0,), bootstrap=5,
                     reflectivity=model.get("reflectivity")).statistics["all"].estimates["multi_return_points_classes_3_4_5"]  # fmt: skip
    assert float(sweep[0]["multi_return_share"]) == pytest.approx(again.value, rel=1e-5)


def test_the_command_honours_no_progress(tmp_path, monkeypatch) -> None:
    import zbuf_occlude.experiments.returns_report as report
    from zbuf_occlude.cli.main import main

    calls = []

    def fake(*args, **kwargs):
        calls.append(kwargs["progress"])
        return {"table": "", "divergence_fits": [], "recommended_k": 7, "seconds": 0.0}

    monkeypatch.setattr(report, "run_returns", fake)
    for extra in ([], ["--no-progress"]):
        assert main(["experiment", "returns", str(tmp_path), "--real", "x.laz", "--out", str(tmp_path / "out"), *extra]) == 0
    assert calls == [True, False]


def test_the_command_refuses_bad_options_in_one_line(tmp_path, capsys) -> None:
    from zbuf_occlude.cli.main import main

    def run(*extra: str) -> int:
        try:
            return main(["experiment", "returns", str(tmp_path), "--out", str(tmp_path / "out"), *extra])
        except SystemExit as exc:
            return int(exc.code)

    assert run("--real", "x.laz", "--bootstrap", "1") == 2
    assert "--bootstrap must be an integer >= 2 (a spread needs two resamples), got 1" in capsys.readouterr().err
    assert run("--real", "x.laz", "--bootstrap", "10001") == 2  # fit-sensor's cap, before the scans are read
    assert "--bootstrap must be at most 10,000 (MAX_BOOTSTRAP), got 10001" in capsys.readouterr().err
    assert run("--real", "x.laz", "--leaf-area-density", "-1") == 2
    assert "--leaf-area-density must be a number >= 0 m²/m³, got -1" in capsys.readouterr().err
    assert run("--real", "x.laz", "--leaf-area-density", "nan") == 2
    assert "--leaf-area-density must be a finite number of m²/m³, got nan" in capsys.readouterr().err
    assert run("--real", str(tmp_path / "missing.laz"), "--bootstrap", "2") != 0
    err = capsys.readouterr().err
    assert "missing.laz" in err and "Traceback" not in err


def test_surfaces_that_transmit_give_hits_behind_them() -> None:
    scene, vegetation = _plot()
    kwargs = {"half_size_m": 4.0, "seeds": (0,), "bootstrap": 5}
    one_ray = ign_scanner(IGN_DIVERGENCE_DEG, 1)  # one ray a pulse: one return, unless it goes on through
    opaque = simulate(scene, one_ray, vegetation, **kwargs).statistics["vegetation"].estimates
    through = simulate(scene, one_ray, vegetation, reflectivity=[0.3, 0.5, 0.5], transmittance=[0.0, 0.5, 0.5],
                       **kwargs).statistics["vegetation"].estimates  # fmt: skip
    assert opaque["returns_1"].value == 1.0
    assert through["returns_2"].value > 0.5  # the boxes' pulses reach the ground below them too


def _cells_las(tops, *, pulses: int = 6, cell_m: float = 1.0, under=None) -> LasPoints:
    """A scan of one row of cells: per cell ``pulses`` first returns on the ground at z 0 and one more
    return of class ``tops[i]`` at z 5 (None: none), and ``under`` (class, z) returns below it."""
    points, classes, numbers = [], [], []
    for i, top in enumerate(tops):
        x = (i + 0.5) * cell_m
        for j in range(pulses):
            points.append((x + 0.01 * j, 0.5, 0.0))
            classes.append(2)
            numbers.append(1)
        for cls, z in ([(top, 5.0)] if top is not None else []) + list(under or []):
            points.append((x, 0.4, z))
            classes.append(cls)
            numbers.append(2)
    n = len(points)
    return LasPoints(points=np.array(points), intensity=np.ones(n), return_number=numbers, number_of_returns=[2] * n,
                     gps_time=np.arange(n, dtype=np.float64), scan_angle_deg=np.zeros(n), classification=classes,
                     point_source_id=np.zeros(n), scanner_channel=np.zeros(n))  # fmt: skip


def test_tree_cover_is_the_share_of_cells_whose_highest_return_is_vegetation() -> None:
    # 10 cells: 3 topped by high vegetation, 1 by low vegetation, 1 by a building (not counted), 5 by the ground
    las = _cells_las([5, 5, 5, 3, 6, None, None, None, None, None])
    cover = tree_cover(las, bootstrap=20)
    assert cover.value == pytest.approx(4 / 9) and cover.n == 9 and cover.unit == "share"
    assert tree_cover(las, classes=(5,), bootstrap=20).value == pytest.approx(3 / 8)  # low vegetation is then neither
    # vegetation below a higher ground return does not cover the cell
    low = _cells_las([None, None], under=[(5, -1.0)])
    assert tree_cover(low, bootstrap=20).value == 0.0
    # cells with too few pulses are left out
    assert tree_cover(_cells_las([5, None], pulses=3), min_pulses=3, bootstrap=20).value == 0.5
    with pytest.raises(InvalidInputError, match="no cell of 1 m holds 5 pulses"):
        tree_cover(_cells_las([5, None], pulses=3), bootstrap=20)


def test_tree_cover_resamples_blocks_of_cells() -> None:
    covered = tree_cover(_cells_las([5] * 30), bootstrap=20)
    assert covered.value == 1.0 and covered.std == 0.0
    # 30 cells in three 10 m blocks, all covered, half covered and bare: the blocks are the draws
    las = _cells_las([5] * 10 + [5, None] * 5 + [None] * 10)
    blocks = tree_cover(las, bootstrap=400, seed=1)
    assert blocks.value == pytest.approx(0.5)
    assert blocks.std == pytest.approx(0.5 / math.sqrt(3), rel=0.3)  # the sd of a mean of 3 blocks (1, 0.5, 0), not of 30 cells
    assert tree_cover(las, bootstrap=400, seed=1, block_m=1.0).std == pytest.approx(math.sqrt(0.25 / 30), rel=0.3)


@pytest.mark.parametrize(("field", "value", "message"), [("cell_m", 0.0, "cell_m"), ("cell_m", math.nan, "cell_m"),
                                                         ("block_m", -1.0, "block_m"), ("min_pulses", 0, "min_pulses")])  # fmt: skip
def test_tree_cover_refuses_bad_settings(field, value, message) -> None:
    with pytest.raises(InvalidInputError, match=message):
        tree_cover(_cells_las([5, None]), **{field: value}, bootstrap=20)


def test_tree_cover_refuses_a_scan_too_wide_for_its_grid() -> None:
    las = _cells_las([5, None])
    far = replace(las, points=np.vstack([las.points[:-1], [[1e300, 0.0, 0.0]]]))
    with pytest.raises(InvalidInputError, match="cells of 1 m across"):
        tree_cover(far, bootstrap=20)


def _box_scene(extent_m: float, positions) -> tuple[ScanScene, tuple[int, ...]]:
    objects = [
        SceneObject(trimesh.creation.box(extents=(extent_m, extent_m, 2.0)), class_name="vegetation", position_m=xy) for xy in positions
    ]
    return ScanScene(objects=objects, ground=True, ground_half_extent_m=50.0), tuple(range(1, len(objects) + 1))


def test_plot_cover_counts_cells_whose_highest_hit_is_vegetation() -> None:
    # a 4 m box on cell boundaries in a 20 m square: 16 of 400 cells
    scene, vegetation = _box_scene(4.0, [(0.0, 0.0)])
    assert plot_cover(scene, (0.0, 0.0), 10.0, vegetation, rays_per_cell=8) == pytest.approx(16 / 400)
    two, _ = _box_scene(4.0, [(-4.0, -4.0), (4.0, 4.0)])
    assert plot_cover(two, (0.0, 0.0), 10.0, (1,), rays_per_cell=8) == pytest.approx(16 / 384)  # the other box is neither
    # a 5 m box: 25 m² of ground, but 36 cells hold some of it: with many rays a cell each sees its edge
    scene, vegetation = _box_scene(5.0, [(0.0, 0.0)])
    assert plot_cover(scene, (0.0, 0.0), 10.0, vegetation, rays_per_cell=200) == pytest.approx(36 / 400)
    one = plot_cover(scene, (0.0, 0.0), 10.0, vegetation, rays_per_cell=1, seed=3)
    assert 16 / 400 <= one <= 36 / 400
    with pytest.raises(InvalidInputError, match="rays"):
        plot_cover(scene, (0.0, 0.0), 10_000.0, vegetation, rays_per_cell=10)


def test_spacing_for_cover_gives_the_plot_that_cover() -> None:
    boxes = [trimesh.creation.box(extents=(2.0, 2.0, 1.0)) for _ in range(4)]
    sizes = [2.0] * 4
    for cover in (0.1, 0.3):
        spacing = spacing_for_cover(boxes, sizes, cover, rays_per_cell=4)
        scene, vegetation = plot_scene(boxes, sizes, spacing_m=spacing, seed=0)
        # a few hundred cells: the cover moves in steps of about 1/200 as the spacing grows
        assert plot_cover(scene, (0.0, 0.0), spacing, vegetation, rays_per_cell=4) == pytest.approx(cover, abs=0.006)
        # 4 crowns of 4 m² (turned, they touch a few more cells) in a square 2 spacings wide
        assert math.sqrt(16.0 / (4 * cover)) * 0.9 <= spacing <= math.sqrt(16.0 / (4 * cover)) * 1.35
    with pytest.raises(InvalidInputError, match="cover"):
        spacing_for_cover(boxes, sizes, 1.0, rays_per_cell=4)
    # a cover so small that the plot outgrows the rays plot_cover casts: refused in one line, not cast
    with pytest.raises(InvalidInputError, match="rays is more than"):
        spacing_for_cover(boxes[:1], sizes[:1], 1e-9, rays_per_cell=1000)


def test_cover_markdown_names_every_cover() -> None:
    est = {"value": 0.371, "std": 0.057, "n": 1146}
    covers = {"cell_m": 1.0, "min_pulses": 5, "block_m": 10.0, "tile": est, "spacing_m": 8.49, "rays_per_cell": 20,
              "plot_vertical_rays": 0.3711, "scans": {"IGN, fitted divergence": {"value": 0.4, "std": 0.01, "n": 900}}}  # fmt: skip
    text = cover_markdown(covers)
    assert "the real tile: 37.1 % ± 5.7 % (1,146 cells)" in text
    assert "20 vertical rays a cell: 37.1 % (trees 8.49 m apart)" in text
    assert "IGN, fitted divergence: 40.0 % ± 1.0 % (900 cells)" in text
    assert "vertical" not in cover_markdown(covers, tile_only=True)


def test_the_plot_is_spaced_for_the_tiles_cover(tmp_path) -> None:
    import zbuf_occlude.experiments.returns_report as report

    meshes = tmp_path / "bush"
    meshes.mkdir()
    for i, tree in enumerate(PLOT_TREES):
        write_bytes(
            meshes / (tree.file.rsplit(".", 1)[0] + ".obj"),
            trimesh.creation.box(extents=(1.0 + 0.2 * i, 1.0, 2.0)).export(file_type="obj").encode(),
        )
    trees = tuple(type(t)(t.file.rsplit(".", 1)[0] + ".obj", "+z", 3.0) for t in PLOT_TREES)
    settings_ = ReturnsSettings(seeds=(0,), copies=1, leaf_area_density=0.0)  # boxes as they are: the spacing is under test, not leaves
    original, report.PLOT_TREES = report.PLOT_TREES, trees
    try:
        scene, vegetation, centre, half = report.ign_plot(meshes, settings_, tree_cover=0.25)
        fixed = report.ign_plot(meshes, replace(settings_, spacing_m=5.0), tree_cover=0.25)
        tall = report.ign_plot(meshes, replace(settings_, spacing_m=5.0), height_scale=2.5)
        with pytest.raises(InvalidInputError, match="height_scale"):
            report.ign_plot(meshes, replace(settings_, spacing_m=5.0), height_scale=0.0)
        with pytest.raises(InvalidInputError, match="tree cover"):
            report.ign_plot(meshes, settings_)
    finally:
        report.PLOT_TREES = original
    assert cover_rays_per_cell(settings_) == 10
    assert plot_cover(scene, centre, half, vegetation, rays_per_cell=10) == pytest.approx(0.25, abs=COVER_TOLERANCE)
    assert fixed[3] == 3 * 5.0 / 2  # a spacing given is kept
    assert [o.size_m for o in tall[0].objects] == pytest.approx([2.5 * o.size_m for o in fixed[0].objects])  # every mesh scaled


def test_the_divergence_is_fitted_again_with_the_k_it_is_compared_at(tmp_path, capsys, monkeypatch) -> None:
    settings_ = ReturnsSettings(sweep_rays=(7,), k_values=(1, 19), seeds=(0,), repeats=1, copies=1, spacing_m=4.0, bootstrap=5,
                                leaf_area_density=0.0)  # fmt: skip
    assert refits_divergence(19, settings_) and not refits_divergence(7, settings_) and not refits_divergence(1, settings_)
    meshes = tmp_path / "bush"
    meshes.mkdir()
    for i, tree in enumerate(PLOT_TREES):
        box = trimesh.creation.box(extents=(1.0 + 0.2 * i, 1.0, 2.0))
        write_bytes(meshes / (tree.file.rsplit(".", 1)[0] + ".obj"), box.export(file_type="obj").encode())
    trees = tuple(type(t)(t.file.rsplit(".", 1)[0] + ".obj", "+z", 3.0) for t in PLOT_TREES)
    scene, vegetation = _plot()
    real = simulate(scene, ign_scanner(WIDE_DEG, 7), vegetation, half_size_m=4.0, seeds=(0,), bootstrap=5).las
    data = las_bytes(real.points, intensity=real.intensity, return_number=real.return_number, number_of_returns=real.number_of_returns,
                     gps_time=real.gps_time, scan_angle_deg=real.scan_angle_deg, classification=real.classification)  # fmt: skip
    real_path = write_bytes(tmp_path / "real.las", data)
    import zbuf_occlude.experiments.returns_report as report

    monkeypatch.setattr(report, "PLOT_TREES", trees)
    monkeypatch.setenv(PROGRESS_INTERVAL_ENV, "0")
    monkeypatch.setattr(report, "recommend_k", lambda rows: 19)  # the K compared, whatever the sweep says
    capsys.readouterr()
    summary = run_returns(tmp_path / "out", meshes, real_path, settings=settings_)
    fits = summary["divergence_fits"]
    assert [f["K"] for f in fits] == [7, 19] and summary["recommended_k"] == 19
    if math.isfinite(fits[-1]["divergence_deg"]):
        assert summary["compared_divergence_deg"] == fits[-1]["divergence_deg"]
    sweep = read_csv_rows(tmp_path / "out" / "divergence_sweep.csv")
    assert [int(r["K"]) for r in sweep] == [7, 7, 7, 7, 7, 7, 7, 7, 19, 19, 19, 19, 19, 19, 19, 19]
    # the progress bar's total grows by the sweep at K 19 once that K is known, and the count reaches it
    total = scans_of_run(settings_, refit=True)
    assert total == scans_of_run(settings_) + len(settings_.divergence_factors)
    counts = [int(line.split()[1].split("/")[0]) for line in capsys.readouterr().err.splitlines() if line.startswith("returns: ")]
    assert counts == list(range(1, total + 1))


def test_the_plots_crowns_are_filled_with_leaves(tmp_path) -> None:
    import zbuf_occlude.experiments.returns_report as report

    meshes = tmp_path / "bush"
    meshes.mkdir()
    for tree in PLOT_TREES:
        write_bytes(
            meshes / (tree.file.rsplit(".", 1)[0] + ".obj"), trimesh.creation.box(extents=(2.0, 2.0, 3.0)).export(file_type="obj").encode()
        )
    trees = tuple(type(t)(t.file.rsplit(".", 1)[0] + ".obj", "+z", 3.0, t.foliage) for t in PLOT_TREES)
    assert [t.foliage for t in PLOT_TREES].count(False) == 2  # the two plants modelled leaf by leaf
    original, report.PLOT_TREES = report.PLOT_TREES, trees
    try:
        bare = report.ign_plot(meshes, ReturnsSettings(copies=1, spacing_m=6.0, leaf_area_density=0.0))[0]
        leafy = report.ign_plot(meshes, ReturnsSettings(copies=1, spacing_m=6.0))[0]
    finally:
        report.PLOT_TREES = original
    for tree, a, b in zip(trees, bare.objects, leafy.objects):
        assert len(a.mesh.faces) == 12
        if tree.foliage:  # a 2 x 2 x 3 m box, every point within 1 m of its surface: 12 m³ of crown at 1 m²/m³ of 0.1 m leaves
            assert (len(b.mesh.faces) - 12) / 2 == pytest.approx(1200, rel=0.03)
            assert 3.0 <= b.size_m <= 3.0 + 0.1 * math.sqrt(2)  # leaves at the hull's two ends reach out by half a diagonal each at most
        else:
            assert len(b.mesh.faces) == 12 and b.size_m == 3.0


@pytest.mark.parametrize(("field", "value", "message"), [
    ("leaf_area_density", -0.5, "leaf_area_density must be a finite number >= 0, got a number outside that range"),
    ("leaf_area_density", math.inf, "leaf_area_density must be a finite number >= 0, got an infinite number"),
    ("echo_rule", "peak", "echo_rule must be one of"),
    ("plot", "forest", "plot must be one of"),
])  # fmt: skip
def test_settings_refuse_bad_values(field, value, message) -> None:
    with pytest.raises(InvalidInputError, match=message):
        ReturnsSettings(**{field: value})


def test_the_families_plot_stands_the_procedural_trees_and_shrubs_at_their_drawn_sizes() -> None:
    from zbuf_occlude.experiments import returns_report as report
    from zbuf_occlude.mesh.families import FAMILIES, family_rng

    scene, vegetation, _, _ = report.ign_plot(None, ReturnsSettings(copies=2, spacing_m=12.0, plot="families"), height_scale=1.5)
    drawn = [(name, k) for name, n in report.FAMILY_PLOT for k in range(n)]
    assert len(vegetation) == len(scene.objects) == 2 * len(drawn) == 16
    for (name, k), obj in zip([d for d in drawn for _ in range(2)], scene.objects):
        mesh, _ = FAMILIES[name].make(family_rng(name, report.FAMILY_PLOT_SEED, k))  # the object families --seed 0 writes
        assert np.array_equal(obj.mesh.vertices, mesh.vertices)  # as drawn: no leaves added to a crown of leaf clusters
        assert obj.size_m == pytest.approx(1.5 * mesh.extents.max())


@pytest.mark.parametrize(("argv", "says"), [
    (["MESHES", "--plot", "families"], "give no MESHES"),
    ([], "give MESHES"),
    (["--plot", "families", "--leaf-area-density", "1"], "--leaf-area-density"),
])  # fmt: skip
def test_the_plot_option_and_the_mesh_folder_go_together(tmp_path, capsys, argv, says) -> None:
    from zbuf_occlude.cli.main import main

    argv = [str(tmp_path) if a == "MESHES" else a for a in argv]
    status = main(["experiment", "returns", *argv, "--real", str(tmp_path / "r.laz"), "--out", str(tmp_path / "o")])
    assert status == 2 and says in capsys.readouterr().err and not (tmp_path / "o").exists()
    with pytest.raises(InvalidInputError, match="takes no mesh folder"):
        run_returns(tmp_path / "o", tmp_path, tmp_path / "r.laz", settings=ReturnsSettings(plot="families"))
    with pytest.raises(InvalidInputError, match="takes a mesh folder"):
        run_returns(tmp_path / "o", None, tmp_path / "r.laz")
