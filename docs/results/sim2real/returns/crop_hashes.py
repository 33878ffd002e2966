"""Are the lidar set's training clouds the same on two machines?  sha256 of the crops of a few meshes.

    python docs/results/sim2real/returns/crop_hashes.py MESHES > hashes.txt

``MESHES``: class folders of meshes (``bush``, ``car``, ``pedestrian``, ``pole``; two meshes a class at
least, as ``experiment sim2real`` asks).  For the ``hdl32e`` preset (one ray) and the sensor file of
the runs with Velodyne's strongest echo (``docs/results/returns_realism/fit/hdl32e_footprint.json``),
seeds 0 and 1: each mesh's 6 crops as ``experiment sim2real``'s ``lidar`` set draws them
(:func:`~zbuf_occlude.sensors.crops.lidar_object_samples` with the class's placement and real size),
their returns and the sha256 of their points (float64 bytes), then one hash over all meshes.  Run
from the repository root.
"""

import hashlib
import platform
import sys

import numpy as np

from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M
from zbuf_occlude.sensors.crops import lidar_object_samples
from zbuf_occlude.sensors.kinds import sensor_from_name

SENSORS = (("preset", "hdl32e"), ("echo", "docs/results/returns_realism/fit/hdl32e_footprint.json"))


def main() -> None:
    print(platform.machine(), "numpy", np.__version__)
    meshes = find_class_meshes(sys.argv[1], up_map={}, classes=["bush", "car", "pedestrian", "pole"])
    for label, name in SENSORS:
        sensor = sensor_from_name(name)
        for seed in (0, 1):
            whole = hashlib.sha256()
            for entry in meshes:
                dist, _ = CropPlacement().crop_distributions(entry, CLASS_SIZES_M[entry.class_name])
                clouds = lidar_object_samples(entry.mesh, sensor, name=entry.name, n_samples=6, n_points=256, seed=seed,
                                              distributions=dist, class_name=entry.class_name)  # fmt: skip
                digest = hashlib.sha256()
                for cloud in clouds:
                    digest.update(np.ascontiguousarray(cloud.points, np.float64).tobytes())
                whole.update(digest.digest())
                print(f"{label} seed {seed} {entry.name}: {sum(c.n_visible for c in clouds)} returns, {digest.hexdigest()[:16]}")
            print(f"{label} seed {seed} ALL {whole.hexdigest()[:16]}")


if __name__ == "__main__":
    main()
