"""A data set's files read through the reading layer: links out of the folder and FIFOs refused in one line.

The card, the manifest, ``shape_names.txt``, the file lists and ``protocol.json`` are read by
:func:`zbuf_occlude.io.regular_files.read_text_file` / :func:`~zbuf_occlude.io.json_files.read_json_file`
held inside the data set's folder; a sample file of ``generate --format npz|ply`` by
:func:`zbuf_occlude.io.arrays.load_npz` or :func:`zbuf_occlude.io.ply.parse_ply_vertices`, capped by
the points the card declares.  A shared data set whose metadata is a symlink to another file
would otherwise hand that file's lines to the reader (class names, paths) or block it (a FIFO).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from zbuf_occlude.cli.main import main
from zbuf_occlude.dataset.layout import CARD_FILE, MANIFEST_FILE, PROTOCOL_FILE, SHAPE_NAMES_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.dataset.sample_files import read_sample_points, sample_file_max_bytes
from zbuf_occlude.dataset.verify import protocol_of, verify_dataset
from zbuf_occlude.errors import DatasetFormatError, UnsafePathError

CHAIR = Path(__file__).resolve().parents[2] / "data" / "samples" / "chair"
TINY = ["--views", "0:0", "--dense-points", "512", "--points", "32", "--resolution", "64", "--samples-per-view", "1"]
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("gen") / "o"
    assert main(["generate", str(CHAIR / "train" / "chair_0001.off"), *TINY, "--out", str(out)]) == 0
    return out


@pytest.fixture
def ds(generated: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(generated, tmp_path / "ds"))


def _link_out(ds: Path, name: str) -> Path:
    """``ds/name`` moved outside the data set (same bytes) and a symlink left in its place."""
    outside = ds.parent / "elsewhere" / name
    outside.parent.mkdir(exist_ok=True)
    shutil.move(ds / name, outside)
    (ds / name).symlink_to(outside)
    return outside


@pytest.mark.parametrize("name", [CARD_FILE, MANIFEST_FILE, SHAPE_NAMES_FILE])
def test_metadata_that_links_out_of_the_data_set_is_refused_by_reader_and_verify(ds, name):
    _link_out(ds, name)  # the same bytes: only where they live is wrong
    with pytest.raises(UnsafePathError, match=rf"{name} leads outside {ds}") as info:
        OccludedDataset(ds)
    assert "\n" not in str(info.value)
    problems = verify_dataset(ds).problems
    assert any(name in p and "leads outside" in p for p in problems), problems


def test_a_file_list_that_links_out_of_the_data_set_is_a_problem_of_verify(ds):
    _link_out(ds, "train_files.txt")  # same bytes, same SHA-256: only the link tells
    problems = verify_dataset(ds).problems
    assert any("train_files.txt leads outside" in p for p in problems), problems


@needs_fifo
@pytest.mark.parametrize("name", [MANIFEST_FILE, SHAPE_NAMES_FILE])
def test_metadata_that_is_a_fifo_is_refused_at_once(ds, name):
    (ds / name).unlink()
    os.mkfifo(ds / name)
    with pytest.raises(DatasetFormatError, match=rf"{name}: is a FIFO; only regular files are read"):
        OccludedDataset(ds)


def test_a_protocol_record_that_links_out_of_the_folder_names_no_protocol(tmp_path):
    (tmp_path / "folder").mkdir()
    (tmp_path / PROTOCOL_FILE).write_text(json.dumps({"protocol": "pcn"}))
    (tmp_path / "folder" / PROTOCOL_FILE).symlink_to(tmp_path / PROTOCOL_FILE)
    assert protocol_of(tmp_path / "folder") is None
    (tmp_path / "folder" / PROTOCOL_FILE).unlink()
    (tmp_path / "folder" / PROTOCOL_FILE).write_text(json.dumps({"protocol": "pcn"}))
    assert protocol_of(tmp_path / "folder") == "pcn"


# -- sample files (generate --format npz|ply) ----------------------------------------------------
def test_a_ply_sample_file_larger_than_its_points_allow_is_refused_before_parsing(tmp_path):
    path = tmp_path / "sample.ply"
    trimesh.PointCloud(np.zeros((100_000, 3), np.float32)).export(path)  # > 1 MiB; the card says 4 points
    assert path.stat().st_size > sample_file_max_bytes(4)
    with pytest.raises(DatasetFormatError, match=rf"sample\.ply: .*more than the {sample_file_max_bytes(4):,}"):
        read_sample_points(path, "ply", 4)


def test_sample_files_are_read_as_written(tmp_path):
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    trimesh.PointCloud(points).export(tmp_path / "s.ply")
    np.savez(tmp_path / "s.npz", points=points)
    for fmt in ("ply", "npz"):
        assert np.array_equal(read_sample_points(tmp_path / f"s.{fmt}", fmt, 4, within=tmp_path), points)


@pytest.mark.parametrize("fmt", ["npz", "ply"])
def test_a_sample_file_that_links_out_of_the_data_set_is_refused(tmp_path, fmt):
    (tmp_path / "ds").mkdir()
    np.savez(tmp_path / "s.npz", points=np.zeros((4, 3), np.float32))
    trimesh.PointCloud(np.zeros((4, 3), np.float32)).export(tmp_path / "s.ply")
    (tmp_path / "ds" / f"s.{fmt}").symlink_to(tmp_path / f"s.{fmt}")
    with pytest.raises(UnsafePathError, match=rf"s\.{fmt} leads outside"):
        read_sample_points(tmp_path / "ds" / f"s.{fmt}", fmt, 4, within=tmp_path / "ds")


@needs_fifo
@pytest.mark.parametrize("fmt", ["npz", "ply"])
def test_a_sample_file_that_is_a_fifo_is_refused_at_once(tmp_path, fmt):
    os.mkfifo(tmp_path / f"s.{fmt}")
    with pytest.raises(DatasetFormatError, match=rf"s\.{fmt}: is a FIFO; only regular files are read; rerun the generate"):
        read_sample_points(tmp_path / f"s.{fmt}", fmt, 4)
