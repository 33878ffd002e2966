"""The GPU backend's masks against the CPU's for every kind of normals, several tolerances and the
splats alone: the shipped meshes, 2,048 and 10,000 points, 8 poses (prints the point-views compared
and those equal; run from the repository root).

    python docs/results/point_visibility/gpu_h200/normal_kinds.py
"""

from pathlib import Path

import numpy as np

import zbuf_occlude as zo
from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

meshes = sorted(p for p in Path("data/samples").rglob("*") if p.suffix.lower() in SUPPORTED_EXTENSIONS)
cameras = [zo.camera_on_sphere(el, az) for el, az in zo.view_schedule("fibonacci:8")]
total = equal = sided = 0
for path in meshes:
    mesh = zo.load_mesh(path)
    for n in (2048, 10000):
        points, face_index = zo.sample_surface(mesh, n, seed=0)
        kinds = {
            "estimated": zo.point_surfels(points),
            "given": zo.point_surfels(points, mesh.face_normals[face_index]),
            "oriented": zo.point_surfels(points, mesh.face_normals[face_index], oriented=True),
        }
        for name, surfels in kinds.items():
            sided += int(np.count_nonzero(surfels.sided))
            for camera in cameras:
                for tolerance in (0.25, 0.0, 1.0):
                    gpu = surfels.visible(camera, backend="gpu", tolerance=tolerance, hull_test=False)
                    cpu = surfels.visible(camera, tolerance=tolerance, hull_test=False)
                    total += n
                    equal += int(np.count_nonzero(gpu == cpu))
                    if not np.array_equal(gpu, cpu):
                        print("differs:", path.name, n, name, tolerance, np.flatnonzero(gpu != cpu)[:5])
print(total, equal, equal / total, "sided points seen", sided)
