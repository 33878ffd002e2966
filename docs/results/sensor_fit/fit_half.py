"""What the sensor_fit scripts share: LiDARNet v2's fit half and the sensor, crop placement and heights that
`experiment sim2real --fit-sensor --sensor hdl32e` fits to it, with the street meshes it sees (bush trees glTF, +y up).
Imported by the scripts beside it (run from the repository root, ../shared beside it)."""

from types import SimpleNamespace

from zbuf_occlude.experiments import sim2real as S
from zbuf_occlude.experiments.sim2real_data import check_lidar_meshes, find_class_meshes, real_clouds, real_scan_rows
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors.presets import sensor_from_name


def load_fit_half(data: str) -> SimpleNamespace:
    """``scans``, ``kept`` (scan row per cloud), ``names``, ``real_y``, ``fit_half`` (cloud rows), ``fitted`` (the sensor),
    ``placement`` and ``sizes`` (per class) and ``meshes`` (those the fitted sensor sees), for the data folder ``data``."""
    scans = load_real_scans(f"{data}/lidarnet_v2_partial")
    meshes = find_class_meshes(f"{data}/street_objects", up_map={"bush/openglforest__*": "+y"})
    names = sorted({m.class_name for m in meshes})
    _, real_y, _ = real_clouds(scans, names, {}, 256, 0)
    half, _ = S._stratified_half(real_y)
    kept = real_scan_rows(scans, names, {})
    fitted, placement, sizes, _ = S._fit_sensor([scans[kept[i]] for i in half], sensor_from_name("hdl32e"), real_y[half], names)
    meshes, _ = check_lidar_meshes(meshes, fitted, sizes, 256, placement=placement)
    return SimpleNamespace(scans=scans, kept=kept, names=names, real_y=real_y, fit_half=half, fitted=fitted, placement=placement,
                           sizes=sizes, meshes=meshes)  # fmt: skip
