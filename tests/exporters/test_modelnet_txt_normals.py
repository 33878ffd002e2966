"""The normals ``export --to modelnet-txt`` writes (exporters.modelnet_txt.estimate_normals, numba
kernels) against the numpy statement of the method (geometry.normals.estimate_normals): the same
text to the last digit but for rounding, on the shipped meshes seen from a few poses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import zbuf_occlude as zo
from zbuf_occlude.exporters.modelnet_txt import estimate_normals
from zbuf_occlude.exporters.text_table import fixed_point_table_bytes
from zbuf_occlude.geometry import normals as reference
from zbuf_occlude.sensors.patterns.spinning import beam_directions

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"
MESHES = sorted(SAMPLES.glob("*/*/*.off"))
#: Poses (elevation, azimuth in degrees) at radius 4; elevation 0 puts the eye in the plane z = 0.
POSES = ((30.0, 45.0), (0.0, 0.0), (-60.0, 200.0))


def _digits(normal: np.ndarray) -> np.ndarray:
    """Each component's ``%.6f`` text as an integer of millionths, ``-0.000000`` read as ``0``."""
    text = fixed_point_table_bytes(np.ascontiguousarray(normal, dtype=np.float32)).decode()
    return np.array([round(float(v) * 1e6) for v in text.replace("\n", ",").rstrip(",").split(",")]).reshape(-1, 3)


@pytest.mark.parametrize("mesh_path", MESHES, ids=[p.stem for p in MESHES])
def test_the_exported_normals_are_the_reference_normals_but_for_rounding(mesh_path):
    mesh = zo.load_mesh(mesh_path)
    points, _ = zo.sample_surface(mesh, 2_048, seed=0)
    points = np.asarray(points, dtype=np.float32)
    for elevation, azimuth in POSES:
        eye = beam_directions(elevation, azimuth) * 4.0
        fast, slow = estimate_normals(points, eye), reference.estimate_normals(points, eye)
        assert fast.dtype == np.float32 and fast.shape == points.shape
        # the side: the same wherever the plane does not pass (to rounding) through the eye
        towards = eye - points.astype(np.float64)
        edge_on = np.abs(np.einsum("ni,ni->n", slow, towards)) <= 1e-6 * np.linalg.norm(towards, axis=1)
        flipped = np.einsum("ni,ni->n", fast, slow) < 0
        assert not np.any(flipped & ~edge_on), (elevation, azimuth, np.flatnonzero(flipped & ~edge_on)[:5])
        # the text: at most one millionth apart (a last digit at a rounding tie), zero's sign aside
        fast[flipped] *= -1.0
        apart = np.abs(_digits(fast) - _digits(slow))
        assert apart.max() <= 1, (elevation, azimuth, apart.max())
        assert np.count_nonzero(apart) <= 1e-3 * apart.size  # measured: a handful per mesh, most none


@pytest.mark.parametrize("n", [0, 1, 2, 3, 5, 16, 17])
def test_tiny_samples_get_the_reference_normals(n):
    points = np.random.default_rng(n).normal(size=(n, 3)).astype(np.float32)
    eye = np.array([0.0, 0.0, 4.0])
    fast, slow = estimate_normals(points, eye), reference.estimate_normals(points, eye)
    assert fast.shape == (n, 3) and fast.dtype == np.float32
    np.testing.assert_allclose(fast, slow, atol=1e-6)  # a blob: well separated eigenvalues, the same side
