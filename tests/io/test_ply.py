"""PLY point clouds parsed from memory (io.ply): what trimesh reads, and one line naming the file otherwise."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.io.ply import parse_ply_vertices


def _ply(geometry) -> bytes:
    buffer = io.BytesIO()
    geometry.export(buffer, file_type="ply")
    return buffer.getvalue()


def test_the_vertices_of_a_point_cloud_as_stored():
    points = np.arange(12, dtype=np.float32).reshape(4, 3) / 7
    vertices = parse_ply_vertices(_ply(trimesh.PointCloud(points)), "cloud.ply")
    assert vertices.dtype == np.float64 and np.array_equal(vertices, points.astype(np.float64))


def test_a_mesh_is_refused_where_only_points_are_wanted():
    raw = _ply(trimesh.creation.box())
    assert parse_ply_vertices(raw, "box.ply").shape == (8, 3)
    with pytest.raises(DatasetFormatError, match=r"^box\.ply: a Trimesh, not a point cloud$"):
        parse_ply_vertices(raw, "box.ply", error=DatasetFormatError, points_only=True)


@pytest.mark.parametrize("raw", [bytes(range(256)) * 4, b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"])
def test_hostile_bytes_are_one_line_naming_the_file(raw):
    with pytest.raises(InvalidInputError, match=r"^bad\.ply: cannot parse as PLY \(") as info:
        np.asarray(parse_ply_vertices(raw, "bad.ply"))
    assert "\n" not in str(info.value)
