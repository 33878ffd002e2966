"""Procedural trunks and shrubs: meshes of the shapes the street meshes lack, written as z-up PLY files.

    python docs/results/sensor_fit/procedural_meshes.py OUT [N]   (from the repository root; N of each, default 6)

writes OUT/pole/procedural__trunk_K.ply and OUT/bush/procedural__shrub_K.ply (K = 0 .. N-1; seed K, the same files on
every run).  The street meshes' poles are posts, lamps and signs, and their bushes are trees with a trunk under the
crown; the fit half's real trunks are bare stems (2.4-3.8 m tall, 0.10-0.64 m across the line of sight, 10th-90th
percentile) and its real bushes blobs of foliage about as wide as tall (width/height 0.97-1.48) from the ground up.

* A trunk is a tapered stem on a grid of rings (trimesh's faces from a cylinder-like vertex grid): base radius 2-9 %
  of its height (the real width/height 0.04-0.15 and a tail of thick trunks), a root flare, a slight bend, an
  elliptic cross-section, bark-scale noise, and in most of them one to three branch stubs near the top
  (`trimesh.creation.cylinder`).
* A shrub is six to ten icospheres (`trimesh.creation.icosphere`) of random radii in a blob as wide as 1-1.6 times
  its height, each displaced by noise and with 30 % of its faces removed, so that the beams that pass an outer gap
  return from the foliage behind it, as in a real bush.

Sizes do not matter: the experiment sizes every mesh to its class's range and normalises every cloud.  Both shapes are
the package's (`zbuf_occlude.mesh.families.trunk.unit_trunk`, `zbuf_occlude.mesh.families.shrub.unit_shrub`); the
package's `zbuf-occlude families` command writes them, and other families, in real size.
"""

import sys
from pathlib import Path

import numpy as np

from zbuf_occlude.mesh.families.shrub import unit_shrub as shrub
from zbuf_occlude.mesh.families.trunk import unit_trunk as trunk


def main(out: Path, n: int) -> None:
    for cls, make, stem in (("pole", trunk, "trunk"), ("bush", shrub, "shrub")):
        (out / cls).mkdir(parents=True, exist_ok=True)
        for k in range(n):
            mesh = make(np.random.default_rng([k, 0x7EE]))
            mesh.export(out / cls / f"procedural__{stem}_{k}.ply")
            print(cls, k, np.round(mesh.extents / mesh.extents[2], 2).tolist(), len(mesh.faces))


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 6)
