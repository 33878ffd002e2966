"""The partial echoes' fit (sensors/fit/partial_echo_meshes.py): scans made with a known min_echo_reflectance give it back; the
classes shared by the scans and the mesh folders, and what the fit refuses, in one line."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.sensors.fit import mesh_crops as pc
from zbuf_occlude.sensors.fit import partial_echo_meshes as pe
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.real_scans.records import RealScan
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam
from zbuf_occlude.sensors.patterns.spinning import lidar_preset

#: Every crop 5.5-9 m away: all of them count (MATCHED_RANGE_M), so that few crops make a fit.
NEAR = CropPlacement.from_keywords({c: {"distance_m": (5.5, 9.0)} for c in ("car", "pole")})
GRID = (0.0, 0.1, 0.2, 0.3, 0.4)


def write_meshes(root: Path) -> Path:
    """Two car-sized boxes and two poles, one class folder each: the least experiment sim2real's mesh reader takes."""
    shapes = {"car": [trimesh.creation.box((4.0, 1.8, 1.5)), trimesh.creation.box((4.5, 1.9, 1.3))],
              "pole": [trimesh.creation.cylinder(0.1, 5.0, sections=16), trimesh.creation.cylinder(0.12, 6.0, sections=12)]}  # fmt: skip
    for name, meshes in shapes.items():
        (root / name).mkdir(parents=True, exist_ok=True)
        for i, mesh in enumerate(meshes):
            mesh.export(root / name / f"m{i}.obj")
    return root


def real_scans(root: Path, truth: float, *, crops: int, seed: int, sensor=None) -> list[RealScan]:
    """Scans of the meshes under ``root`` made with ``min_echo_reflectance`` = ``truth``, as the real scans a reader gives."""
    sensor = pe.partial_echo_sensor(sensor or lidar_preset("hdl32e"), truth)
    meshes = find_class_meshes(root)
    return [RealScan(c.points_m.astype(np.float32), c.class_name, str(root.parent / "real" / f"{c.mesh}_{c.crop}.csv"), "folder",
                     points_sensor_m=c.points_m) for c in pc.mesh_crops(meshes, sensor, crops, seed, placement=NEAR)]  # fmt: skip


def test_the_fit_recovers_the_threshold_the_scans_were_made_with(tmp_path: Path) -> None:
    root = write_meshes(tmp_path / "meshes")
    base = with_beam(lidar_preset("hdl32e"), range_noise_m=0.02, dropout=0.02)
    # the "real" scans: the crops the fit draws (the same seed, placements and sensor), made at 0.2
    scans = real_scans(root, 0.2, crops=5, seed=0, sensor=base)
    said: list[str] = []
    r = pe.fit_partial_echoes(scans, base, root, crops_per_mesh=5, seed=0, bootstrap=50, grid=GRID, placement=NEAR, say=said.append)
    e = r.fit.estimate
    # within its bootstrap spread (about 0.15 with 20 scans: the outline share moves little between thresholds), and
    # within the search's step: the scans at 0.2 are the simulated crops at 0.2
    assert abs(e.value - 0.2) <= 2.0 * e.std and e.value == pytest.approx(0.2, abs=0.0125), e
    lo, hi = pc.MATCHED_RANGE_M
    assert r.classes == ("car", "pole") and r.skipped == {} and e.n == sum(lo <= pc.centroid_range_m(s.points_sensor_m) < hi for s in scans)
    assert int(np.argmin(r.fit.objective)) == GRID.index(0.2)
    # the pole's outline moves with the threshold: the fit is not read off flat curves
    assert r.fit.simulated["pole"][-1] - r.fit.simulated["pole"][0] > 0.01
    # the sensor carries the threshold, with the beam it was fitted with, and the geometry it was given
    b = r.sensor.beam
    assert b.min_echo_reflectance == pytest.approx(e.value) and (b.footprint_rays, b.return_mode, b.max_returns) == (7, "strongest", 1)
    assert (b.range_noise_m, b.dropout, b.divergence_deg) == (0.02, 0.02, 0.16)
    assert any("threshold 0.2" in line for line in said) and "fitted min_echo_reflectance" in r.markdown()


def test_classes_are_the_labels_with_a_mesh_folder_and_the_others_are_named(tmp_path: Path) -> None:
    root = write_meshes(tmp_path / "meshes")
    scans = real_scans(root, 0.1, crops=2, seed=1)
    tree = scans[0].__class__(scans[0].points, "tree", "real/tree_0.csv", "folder", points_sensor_m=scans[0].points_sensor_m)
    (root / "bench").mkdir()
    trimesh.creation.box((1.5, 0.5, 0.8)).export(root / "bench" / "b.obj")
    r = pe.fit_partial_echoes([*scans, tree], lidar_preset("hdl32e"), root, crops_per_mesh=2, bootstrap=5, grid=(0.0, 0.3), placement=NEAR)
    assert r.classes == ("car", "pole") and r.skipped == {"tree": "no meshes", "bench": "no real scans"}
    assert "tree (no meshes)" in r.markdown() and r.to_json()["skipped"] == r.skipped


def test_no_shared_class_is_refused_naming_both_folders(tmp_path: Path) -> None:
    root = write_meshes(tmp_path / "meshes")
    scans = [RealScan(np.zeros((3, 3), np.float32), "chair", str(tmp_path / "real" / "Chair" / "a.csv"), "folder",
                      points_sensor_m=np.ones((3, 3)))]  # fmt: skip
    with pytest.raises(InvalidInputError, match=r"^meshes .*meshes and .*real.Chair share no class: meshes of \['car', 'pole'\], "
                                                r"real scans of \['chair'\]"):  # fmt: skip
        pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root)


def test_crops_out_of_range_or_none_near_enough_are_refused(tmp_path: Path) -> None:
    root = write_meshes(tmp_path / "meshes")
    scans = real_scans(root, 0.1, crops=1, seed=0)
    for bad in (0, -1, 2.5, True, 10**9):
        with pytest.raises(InvalidInputError, match="crops_per_mesh must be an integer from 1 to"):
            pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root, crops_per_mesh=bad)
    far = CropPlacement.from_keywords({c: {"distance_m": (15.0, 20.0)} for c in ("car", "pole")})
    with pytest.raises(InvalidInputError, match=r"no class to fit the partial echoes on: car: no crop of its meshes 5-10 m away"):
        pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root, crops_per_mesh=1, grid=(0.0, 0.3), placement=far)
    moved = [RealScan(s.points, s.label, s.source, s.dataset, points_sensor_m=s.points_sensor_m * 3.0) for s in scans]  # 16-27 m away
    with pytest.raises(InvalidInputError, match=r"car: no real scan 5-10 m away; pole: no real scan 5-10 m away"):
        pe.fit_partial_echoes(moved, lidar_preset("hdl32e"), root, crops_per_mesh=1, grid=(0.0, 0.3), placement=NEAR)


def test_a_beam_without_divergence_or_a_sensor_of_another_kind_is_refused_before_a_mesh_is_read(tmp_path: Path) -> None:
    (tmp_path / "car").mkdir()
    (tmp_path / "car" / "bad.obj").write_text("not a mesh")  # never read
    with pytest.raises(InvalidInputError, match=r"^meshes samples the beam's divergence cone, and hdl64e's beam .* divergence_deg"):
        pe.fit_partial_echoes([], lidar_preset("hdl64e"), tmp_path)
    with pytest.raises(InvalidInputError, match="^meshes: the partial echoes are fitted for a spinning LiDAR, not a AirborneScanner"):
        pe.fit_partial_echoes([], sensor_from_name("riegl-q1560"), tmp_path)
    with pytest.raises(InvalidInputError, match=r"^meshes .*nowhere is not a folder$"):
        pe.fit_partial_echoes([], lidar_preset("hdl32e"), tmp_path / "nowhere")


def test_a_link_out_of_the_meshes_folder_is_refused_and_a_fifo_named_like_a_mesh_skipped(tmp_path: Path) -> None:
    root = write_meshes(tmp_path / "meshes")
    scans = real_scans(root, 0.1, crops=1, seed=0)
    (tmp_path / "secret.txt").write_text("not yours")
    (root / "car" / "evil.obj").symlink_to(tmp_path / "secret.txt")
    with pytest.raises(UnsafePathError, match=r"evil\.obj") as caught:
        pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root, crops_per_mesh=1)
    assert "\n" not in str(caught.value)
    (root / "car" / "evil.obj").unlink()
    os.mkfifo(root / "car" / "pipe.obj")  # opening it would block: it must be passed over, not read
    r = pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root, crops_per_mesh=1, bootstrap=5, grid=(0.0, 0.3), placement=NEAR)
    assert r.classes == ("car", "pole")


def test_a_crop_lost_at_one_threshold_leaves_every_thresholds_row(tmp_path: Path, monkeypatch) -> None:
    root = write_meshes(tmp_path / "meshes")
    scans = real_scans(root, 0.1, crops=2, seed=0)
    drawn = pc.mesh_crops

    def losing_the_first(meshes, sensor, *args, **options):  # at 0.3, the first crop has too few returns
        crops = drawn(meshes, sensor, *args, **options)
        return crops[1:] if sensor.beam.min_echo_reflectance == 0.3 else crops

    monkeypatch.setattr(pc, "mesh_crops", losing_the_first)
    r = pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), root, crops_per_mesh=2, bootstrap=5, grid=(0.0, 0.3, 0.4), placement=NEAR)
    first = drawn(find_class_meshes(root), pe.partial_echo_sensor(lidar_preset("hdl32e"), 0.0), 2, 0, placement=NEAR)
    near = [c for c in first if pc.MATCHED_RANGE_M[0] <= c.range_m < pc.MATCHED_RANGE_M[1]]
    assert (first[0].mesh, first[0].crop) == (near[0].mesh, near[0].crop)  # the crop lost is one compared
    assert (
        sum(r.crops.values()) == len(near) - 1
        and r.crops[first[0].class_name] == sum(c.class_name == first[0].class_name for c in near) - 1
    )


def test_a_class_without_a_real_size_is_refused_naming_sizes_before_a_mesh_is_read(tmp_path: Path) -> None:
    (tmp_path / "chair").mkdir()
    (tmp_path / "chair" / "bad.obj").write_text("not a mesh")  # never read
    scans = [RealScan(np.zeros((3, 3), np.float32), "chair", "real/chair/a.csv", "folder", points_sensor_m=np.ones((3, 3)))]
    with pytest.raises(InvalidInputError, match=r"^meshes: classes \['chair'\] have no real size .*give sizes CLASS=DIMENSION"):
        pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), tmp_path)
    # a caller's names for them, as fit-sensor gives its options
    with pytest.raises(InvalidInputError, match=r"^--meshes: classes \['chair'\] have no real size .*give --sizes CLASS=DIMENSION"):
        pe.fit_partial_echoes(scans, lidar_preset("hdl32e"), tmp_path, names={"meshes": "--meshes", "sizes": "--sizes"})


def test_a_mesh_folder_reads_its_files_with_their_up_axes(tmp_path: Path) -> None:
    from zbuf_occlude.mesh.inputs.class_folders import MeshFolder

    root = write_meshes(tmp_path / "meshes")
    upright = {m.name: m.mesh.extents for m in MeshFolder(root, "+z").find()}
    turned = {m.name: m.mesh.extents for m in MeshFolder(root, "+z", {"pole/*": "+y"}).find(classes=["car", "pole"])}
    assert sorted(turned) == ["car/m0", "car/m1", "pole/m0", "pole/m1"]
    assert all(np.array_equal(turned[n], upright[n]) for n in ("car/m0", "car/m1"))  # the map names the poles only
    for name in ("pole/m0", "pole/m1"):
        extents = turned[name]  # a pole read with +y up lies along the ground: its height is its width
        assert extents[2] < extents[:2].max() and upright[name][2] > upright[name][:2].max()
