"""Example clouds of docs/results/sim2real.md: a real HDL-32E scan beside one cloud of each training set.

Needs the research-only data next to the repository (../shared/data); run from the repository root:

    python docs/results/sim2real/make_figure.py [../shared/data]

Same class per row; the synthetic clouds come from one mesh of that class, made exactly as the
experiment makes them (quick scale: 256 points, seed 0); the real scan is the first of its class.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np

from zbuf_occlude.experiments.sim2real.data import TRAINING_SETS, SetRecipe, build_sets
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes
from zbuf_occlude.experiments.sim2real.real import real_clouds
from zbuf_occlude.experiments.sim2real.report import plot_examples
from zbuf_occlude.real_scans.datasets import load_real_scans
from zbuf_occlude.sensors import lidar_preset

logging.getLogger("trimesh").setLevel(logging.ERROR)
SHARED = Path(sys.argv[1] if len(sys.argv) > 1 else "../shared/data")
MESHES = {"car": "car/pgdrive__beetle_scene", "pedestrian": "pedestrian/hw3dmodels__man", "pole": "pole/gazebo__lamp_post",
          "bush": "bush/gazebo__pine_tree"}  # fmt: skip

meshes = [m for m in find_class_meshes(SHARED / "street_objects", up_map={"bush/openglforest__*": "+y"}) if m.name in MESHES.values()]
names = sorted(MESHES)
sets = build_sets(meshes, names, 1, 256, 0, SetRecipe(sensor=lidar_preset("hdl32e")))
real_pts, real_y, _ = real_clouds(load_real_scans(SHARED / "lidarnet_v2_partial"), names, {}, 256, 0)
rows = {}
for i, cls in enumerate(names):
    row = {"real (LiDARNet)": real_pts[np.flatnonzero(real_y == i)[0]]}
    for kind in TRAINING_SETS[:3]:
        row[kind] = sets[kind].points[np.flatnonzero(sets[kind].labels == i)[0]]
    rows[cls] = row
out = plot_examples(Path(__file__).with_name("examples.png"), rows, "real scan vs one cloud of each training set (normalised, 256 points)")
print(out)
