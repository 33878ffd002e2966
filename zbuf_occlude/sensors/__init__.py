"""Sensor scans of mesh scenes: a beam fired along a scan pattern from a platform.

Spinning LiDARs, ray tables (a Livox's Risley rosette), airborne scanners and depth cameras
(:mod:`.kinds`); a LiDAR fitted to real scans (:mod:`.fit`).

>>> import zbuf_occlude as zo
>>> scene = zo.ScanScene().add("car.off", class_name="car", position_m=(10, 0), size_m=4.5)
>>> s = zo.scan(scene, zo.Lidar.preset("hdl32e"), seed=0)     # sensor 1.8 m above the origin
>>> car = s.crop(1)                                             # the car's returns, occluded
"""

from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.patterns.airborne_presets import AIRBORNE_PRESETS, airborne_preset
from zbuf_occlude.sensors.beam.fields import IDEAL_BEAM, RETURN_MODES, Beam
from zbuf_occlude.sensors.patterns.depth_camera import DEPTH_CAMERA_PRESETS, DepthCamera, depth_camera_preset, nguyen_axial_sigma_m
from zbuf_occlude.sensors.fit import LidarFit, fit_lidar
from zbuf_occlude.sensors.kinds import SENSOR_KINDS, kind_of, sensor_from_name, with_beam
from zbuf_occlude.sensors.patterns.spinning import LIDAR_PRESETS, Lidar, beam_directions, lidar_preset
from zbuf_occlude.sensors.platform import Trajectory, load_trajectory
from zbuf_occlude.sensors.patterns.ray_table import RAY_TABLE_PRESETS, RayTable, load_ray_table, rosette_table
from zbuf_occlude.sensors.platform import look_at_pose
from zbuf_occlude.sensors.raycast.zbuffer import ZBufferView
from zbuf_occlude.sensors.scan import scan, scan_airborne
from zbuf_occlude.sensors.scan_data import FRAMES, Scan, read_scan_npz
from zbuf_occlude.sensors.scene.objects import GROUND_ID, ScanScene, SceneObject, sensor_pose
from zbuf_occlude.sensors.scene.files import load_scene

__all__ = [
    "Beam", "IDEAL_BEAM", "RETURN_MODES", "SENSOR_KINDS", "kind_of", "sensor_from_name", "with_beam", "Trajectory", "load_trajectory",
    "Lidar", "LIDAR_PRESETS", "lidar_preset", "beam_directions", "RayTable", "RAY_TABLE_PRESETS", "load_ray_table", "rosette_table",
    "AirborneScanner", "AIRBORNE_PRESETS", "airborne_preset", "scan_airborne",
    "DepthCamera", "DEPTH_CAMERA_PRESETS", "depth_camera_preset", "nguyen_axial_sigma_m",
    "ScanScene", "SceneObject", "load_scene", "sensor_pose", "GROUND_ID",
    "Scan", "scan", "ZBufferView", "look_at_pose", "read_scan_npz", "FRAMES", "LidarFit", "fit_lidar",
]  # fmt: skip
