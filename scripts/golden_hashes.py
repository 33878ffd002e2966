"""SHA-256 of outputs that no refactor may change; ``tests/test_golden_outputs.py`` checks them.

(a) the data set of ``zbuf-occlude generate data/samples --out G --views grid25 --points 512
--samples-per-view 2 --dense-points 8192 --seed 7``, every sample read back with
``OccludedDataset`` (points, label, class, pose, sample index); (b) the masks of ``oracle``,
``embree-fast``, ``zbuffer-exact`` and ``paper-exact`` for 3,000 points and three poses on every
shipped mesh.  Usage: ``python scripts/golden_hashes.py [--write]`` (``--write`` rewrites
``tests/data/golden_hashes.json``: only for a change meant to alter outputs, said in its commit).
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
HASHES = ROOT / "tests" / "data" / "golden_hashes.json"
GENERATE = ["--views", "grid25", "--points", "512", "--samples-per-view", "2", "--dense-points", "8192", "--seed", "7"]
METHODS = ("oracle", "embree-fast", "zbuffer-exact", "paper-exact")
POSES = ((0.0, 0.0), (35.0, 100.0), (-60.0, 250.0))


def dataset_hash() -> str:
    import zbuf_occlude as zo

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "G"
        subprocess.run([sys.executable, "-m", "zbuf_occlude", "generate", str(ROOT / "data" / "samples"), "--out", str(out), *GENERATE],
                       check=True, capture_output=True, cwd=tmp)  # fmt: skip
        h = hashlib.sha256()
        for split in ("train", "test"):
            ds = zo.OccludedDataset(out, split=split)
            for i in range(len(ds)):
                points, label, meta = ds[i]
                h.update(np.ascontiguousarray(points).tobytes())
                h.update(json.dumps([int(label), meta["class_name"], meta["name"], meta["pose_index"], meta["elevation_deg"], meta["azimuth_deg"],
                                     meta["sample_index"]]).encode())  # fmt: skip
        return h.hexdigest()


def mask_hashes() -> dict[str, str]:
    import zbuf_occlude as zo

    out = {}
    for path in sorted((ROOT / "data" / "samples").rglob("*.off")):
        mesh = zo.load_mesh(path)
        points, face_index = zo.sample_surface(mesh, 3000, seed=11)
        for method in METHODS:
            h = hashlib.sha256()
            for el, az in POSES:
                camera = zo.camera_on_sphere(el, az)
                h.update(np.packbits(zo.visible_mask(mesh, points, camera, method, face_index=face_index)).tobytes())
            out[f"{path.stem}/{method}"] = h.hexdigest()
    return out


def compute() -> dict:
    return {"dataset": dataset_hash(), "masks": mask_hashes()}


if __name__ == "__main__":
    got = compute()
    if "--write" in sys.argv[1:]:
        HASHES.write_text(json.dumps(got, indent=1, sort_keys=True) + "\n")
    print(json.dumps(got, indent=1, sort_keys=True))
