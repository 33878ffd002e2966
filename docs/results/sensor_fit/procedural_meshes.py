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

Sizes do not matter: the experiment sizes every mesh to its class's range and normalises every cloud.
"""

import sys
from pathlib import Path

import numpy as np
import trimesh


def trunk(rng: np.random.Generator) -> trimesh.Trimesh:
    """A stem of height 1 standing on z = 0."""
    n_z, n_a = 24, 18
    z = np.linspace(0.0, 1.0, n_z)
    a = np.linspace(0.0, 2 * np.pi, n_a, endpoint=False)
    r0 = rng.uniform(0.02, 0.09)
    flare, taper, ellipse = rng.uniform(0.2, 0.8), rng.uniform(0.6, 0.9), rng.uniform(0.75, 1.0)
    bend = rng.uniform(-0.06, 0.06, 2)

    def axis(t):  # the stem's centre (x, y) and its radius without the flare at height t
        return bend[0] * t**2, bend[1] * t**2, r0 * (1 - (1 - taper) * t)

    cx, cy, r = axis(z[:, None])
    radius = r * (1 + flare * np.exp(-z[:, None] / 0.06))
    noise = 1 + 0.04 * rng.standard_normal((n_z, n_a))
    x = (radius * noise * np.cos(a)[None]) + cx
    y = (radius * noise * ellipse * np.sin(a)[None]) + cy
    verts = np.stack([x, y, np.broadcast_to(z[:, None], x.shape)], axis=-1).reshape(-1, 3)
    faces = []
    for i in range(n_z - 1):
        for j in range(n_a):
            p, q = i * n_a + j, i * n_a + (j + 1) % n_a
            faces += [(p, q, q + n_a), (p, q + n_a, p + n_a)]
    top = len(verts)
    verts = np.vstack([verts, [[*axis(1.0)[:2], 1.0]]])
    faces += [((n_z - 1) * n_a + j, (n_z - 1) * n_a + (j + 1) % n_a, top) for j in range(n_a)]
    parts = [trimesh.Trimesh(verts, np.asarray(faces), process=False)]
    for _ in range(rng.choice([0, 1, 2, 3], p=[0.25, 0.3, 0.3, 0.15])):
        h = rng.uniform(0.75, 0.97)
        tilt, heading = np.radians(rng.uniform(30.0, 65.0)), rng.uniform(0.0, 2 * np.pi)
        length = rng.uniform(0.08, 0.3)
        *centre, r_here = axis(h)
        start = np.array([*centre, h])
        end = start + length * np.array([np.sin(tilt) * np.cos(heading), np.sin(tilt) * np.sin(heading), np.cos(tilt)])
        parts.append(trimesh.creation.cylinder(radius=r_here * rng.uniform(0.35, 0.7), segment=[start, end], sections=10))
    return trimesh.util.concatenate(parts)


def shrub(rng: np.random.Generator) -> trimesh.Trimesh:
    """A blob of foliage standing on z = 0, about as wide as 1-1.6 times its height."""
    aspect = rng.uniform(1.0, 1.6)  # horizontal extent over height
    parts = []
    for _ in range(rng.integers(6, 11)):
        r = rng.uniform(0.25, 0.4)
        centre = np.array([*rng.uniform(-1, 1, 2) * (0.5 * aspect - r), rng.uniform(r, 1 - r)])
        s = trimesh.creation.icosphere(subdivisions=2, radius=r)
        v = s.vertices * rng.uniform(0.85, 1.15, (len(s.vertices), 1)) + centre
        keep = rng.random(len(s.faces)) >= 0.3
        parts.append(trimesh.Trimesh(v, s.faces[keep], process=False))
    m = trimesh.util.concatenate(parts)
    m.apply_translation([0.0, 0.0, -m.bounds[0, 2]])
    return m


def main(out: Path, n: int) -> None:
    for cls, make, stem in (("pole", trunk, "trunk"), ("bush", shrub, "shrub")):
        (out / cls).mkdir(parents=True, exist_ok=True)
        for k in range(n):
            mesh = make(np.random.default_rng([k, 0x7EE]))
            mesh.export(out / cls / f"procedural__{stem}_{k}.ply")
            print(cls, k, np.round(mesh.extents / mesh.extents[2], 2).tolist(), len(mesh.faces))


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 6)
