"""zbuf_occlude.learn.data: class-balanced epochs; meshes read for their content key through zbuf_occlude.io."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import MeshLoadError
from zbuf_occlude.learn.data import balanced_epoch_rows
from zbuf_occlude.mesh.inputs.duplicates import dedupe_meshes, mesh_content_key


@settings(max_examples=60, deadline=None)
@given(sizes=st.lists(st.integers(1, 40), min_size=1, max_size=5), seed=st.integers(0, 2**32 - 1))
def test_balanced_epoch_has_every_class_equally_often(sizes: list[int], seed: int) -> None:
    labels = np.repeat(np.arange(len(sizes)) * 3, sizes)  # class indices need not be 0..K-1
    np.random.default_rng(seed).shuffle(labels)
    rows = balanced_epoch_rows(labels, np.random.default_rng(seed))
    per_class = len(labels) // len(sizes)
    assert rows.dtype == np.int64 and len(rows) == per_class * len(sizes)
    assert rows.min() >= 0 and rows.max() < len(labels)
    counts = {int(c): int((labels[rows] == c).sum()) for c in np.unique(labels)}
    assert set(counts.values()) == {per_class}
    for c in np.unique(labels):  # a class's rows are used evenly: none twice before every one once
        uses = np.bincount(rows[labels[rows] == c], minlength=len(labels))[labels == c]
        assert uses.max() - uses.min() <= 1


def test_balanced_epoch_is_seeded_and_shuffled() -> None:
    labels = np.array([0] * 90 + [1] * 10)
    a = balanced_epoch_rows(labels, np.random.default_rng(1))
    assert np.array_equal(a, balanced_epoch_rows(labels, np.random.default_rng(1)))
    assert not np.array_equal(a, balanced_epoch_rows(labels, np.random.default_rng(2)))
    assert 0 < (labels[a[:50]] == 1).mean() < 1  # the classes are mixed, not one block after the other
    assert len(balanced_epoch_rows(np.zeros(0, np.int64), np.random.default_rng(0))) == 0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")
def test_a_mesh_that_is_a_fifo_is_refused_at_once_not_read(tmp_path: Path) -> None:
    (tmp_path / "a.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    os.mkfifo(tmp_path / "b.off")
    with pytest.raises(MeshLoadError, match=r"b\.off: is a FIFO; only regular files are read"):
        dedupe_meshes([tmp_path / "a.off", tmp_path / "b.off"])


def test_a_missing_mesh_is_one_line_naming_it(tmp_path: Path) -> None:
    with pytest.raises(MeshLoadError, match=r"gone\.off: cannot read file"):
        mesh_content_key(tmp_path / "gone.off")
