"""How far the sim-to-real run's two occluded training sets are apart: for every training pose of
seed S (the train split of the 48 street meshes), the occluded set's mesh mask (``auto``) against
the occluded-points set's mask (point-splat, points alone) on the same 8,192 dense points.

    python docs/results/point_visibility/sim2real_masks.py 0      # prints one JSON line

It wraps ``pipeline.occlude_object`` to record each mask while the two sets are built exactly as
``experiment sim2real --occluded-points`` builds them (needs ../shared/data/street_objects).
"""

import sys
import json
import numpy as np
from zbuf_occlude import pipeline
from zbuf_occlude.experiments.sim2real.data import OCCLUDED_POINTS, SetRecipe, build_set
from zbuf_occlude.mesh.inputs.class_folders import find_class_meshes, split_whole_meshes

seed = int(sys.argv[1]) if len(sys.argv) > 1 else 0
meshes = find_class_meshes("../shared/data/street_objects", up_map={"bush/openglforest__*": "+y"})
train, _ = split_whole_meshes(meshes, 0.2, seed)
names = sorted({m.class_name for m in meshes})
calls = []
real = pipeline.occlude_object


def spy(mesh, poses, **kw):
    for i, vis, clouds in real(mesh, poses, **kw):
        calls.append((kw["method"], vis.copy(), clouds[0].n_visible if clouds else 0, clouds[0].n_topped_up if clouds else 0))
        yield i, vis, clouds


pipeline.occlude_object = spy
recipe = SetRecipe(dense_points=8192, resolution=512, elevation_deg=(-5.0, 30.0))
build_set("occluded", train, names, 100, 256, seed, recipe)
mesh_calls = list(calls)
calls.clear()
build_set(OCCLUDED_POINTS, train, names, 100, 256, seed, recipe)
assert len(calls) == len(mesh_calls)
acc, iou, fv, fh, vm, vp = [], [], [], [], [], []
for (_, a, _, _), (_, b, _, _) in zip(mesh_calls, calls):
    acc.append((a == b).mean())
    iou.append((a & b).sum() / max((a | b).sum(), 1))
    fv.append((b & ~a).mean())
    fh.append((a & ~b).mean())
    vm.append(a.mean())
    vp.append(b.mean())
print(
    json.dumps(
        {
            "seed": seed,
            "poses": len(calls),
            "accuracy_mean": float(np.mean(acc)),
            "accuracy_min": float(np.min(acc)),
            "iou_mean": float(np.mean(iou)),
            "iou_min": float(np.min(iou)),
            "false_visible": float(np.mean(fv)),
            "false_hidden": float(np.mean(fh)),
            "visible_share_mesh": float(np.mean(vm)),
            "visible_share_points": float(np.mean(vp)),
            "mesh_topped_up_poses": int(sum(t > 0 for *_, t in mesh_calls)),
            "points_poses_under_256": int(sum(n < 256 for _, _, n, _ in calls)),
        }
    )
)
