"""ASPRS classes by the rule (class name and height above the ground) and by a user's class map, and hostile class map files."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.scene.las_classes import (
    MAX_CLASS_MAP_KEYS,
    RESERVED_CODES,
    VEGETATION_HEIGHTS_M,
    asprs_classification,
    check_class_map,
    load_class_map,
    rule_code,
)

RULE_CODES = {1, 2, 3, 4, 5, 6}


@pytest.mark.parametrize(
    ("name", "code"),
    [("tree", 3), ("oak_tree", 3), ("Trees", 3), ("hedge-row", 3), ("bushes", 3), ("plant", 3), ("building", 6),
     ("office building", 6), ("houses", 6), ("car", 1), ("treehouse", 1), ("wall", 1), ("", 1), ("street_lamp", 1)],
)  # fmt: skip
def test_the_rule_reads_the_words_of_a_class_name(name: str, code: int) -> None:
    assert rule_code(name) == code


def test_vegetation_splits_at_ign_heights_and_the_ground_is_2() -> None:
    low, medium = VEGETATION_HEIGHTS_M
    assert (low, medium) == (0.5, 1.5)
    heights = np.array([0.0, 0.2, 0.499, 0.5, 1.0, 1.499, 1.5, 12.0, 7.0, 0.1, 30.0])
    ids = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0, 2, 3])
    got = asprs_classification(ids, ("ground", "tree", "house", "car"), heights)
    assert got.dtype == np.uint8
    assert got.tolist() == [3, 3, 3, 4, 4, 4, 5, 5, 2, 6, 1]


def test_a_class_map_overrides_the_rule_by_exact_name() -> None:
    ids = np.array([0, 1, 2, 3, 3])
    heights = np.array([0.0, 3.0, 3.0, 0.1, 2.0])
    classes = ("ground", "car", "oak_tree", "tree")
    got = asprs_classification(ids, classes, heights, {"car": 64, "oak_tree": 5, "ground": 20, "unused": 9})
    assert got.tolist() == [20, 64, 5, 3, 5]  # "tree" is not "oak_tree": the rule keeps it


def test_object_ids_beyond_the_classes_are_refused() -> None:
    with pytest.raises(InvalidInputError, match="object_classes names 2 objects"):
        asprs_classification(np.array([0, 2]), ("ground", "car"), np.zeros(2))
    with pytest.raises(InvalidInputError, match="NaN"):
        asprs_classification(np.array([1]), ("ground", "tree"), np.array([np.nan]))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.text(alphabet="abtreuildngshoup_ -", max_size=12), min_size=1, max_size=6),
    st.data(),
)
def test_codes_are_always_the_rules_and_the_ground_always_2(names: list[str], data) -> None:
    classes = ("ground", *names)
    n = data.draw(st.integers(0, 40))
    ids = np.array(data.draw(st.lists(st.integers(0, len(names)), min_size=n, max_size=n)), dtype=np.int64)
    heights = np.array(data.draw(st.lists(st.floats(-5, 50, allow_nan=False), min_size=n, max_size=n)), dtype=np.float64)
    got = asprs_classification(ids, classes, heights)
    assert set(got.tolist()) <= RULE_CODES
    assert (got[ids == 0] == 2).all()
    assert (got[ids != 0] != 2).all()
    # vegetation's class never falls as its points rise
    plants = np.isin(ids, [k for k, name in enumerate(classes) if k and rule_code(name) == 3])
    order = np.argsort(heights[plants], kind="stable")
    assert (np.diff(got[plants][order].astype(int)) >= 0).all()


@settings(max_examples=100, deadline=None)
@given(st.dictionaries(st.text(min_size=1, max_size=8), st.sampled_from(sorted(set(range(256)) - RESERVED_CODES)), max_size=5))
def test_mapped_names_get_their_code(class_map: dict[str, int]) -> None:
    names = ["ground", *class_map, "tree"]
    ids = np.arange(len(names))
    got = asprs_classification(ids, names, np.ones(len(names)), class_map)
    for k, name in enumerate(names):
        if name in class_map:
            assert got[k] == class_map[name]


def _write(tmp_path: Path, text: str, name: str = "map.json") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_a_class_map_file_reads(tmp_path: Path) -> None:
    assert load_class_map(_write(tmp_path, '{"car": 1, "oak_tree": 5, "kiosk": 64}')) == {"car": 1, "oak_tree": 5, "kiosk": 64}


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('["car", 1]', "must be a JSON object"),
        ('{"car": 1.0}', "'car': the ASPRS code must be a whole number"),
        ('{"car": "1"}', "'car': the ASPRS code must be a whole number"),
        ('{"car": true}', "'car': the ASPRS code must be a whole number"),
        ('{"car": null}', "'car'"),
        ('{"car": [1]}', "'car'"),
        ('{"car": {"code": 1}}', "'car'"),
        ('{"car": NaN}', "'car'"),
        ('{"car": 256}', "'car'.*0 to 255"),
        ('{"car": -1}', "'car'.*0 to 255"),
        ('{"car": 1' + "0" * 5000 + "}", "car|digits|JSON"),
        ('{"car": 8}', "'car': the ASPRS code is one LAS 1.4 reserves"),
        ('{"car": 12}', "code is one LAS 1.4 reserves"),
        ('{"car": 40}', "code is one LAS 1.4 reserves"),
        ('{"": 1}', "a class name must be 1 to 256 characters, got an empty one"),
        ("[" * 5000 + "]" * 5000, "deeper than"),
        ("{not json", "not valid JSON"),
    ],
)
def test_hostile_class_maps_are_one_line_naming_the_file(tmp_path: Path, text: str, match: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(InvalidInputError, match=match) as info:
        load_class_map(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_too_many_keys_are_refused(tmp_path: Path) -> None:
    path = _write(tmp_path, json.dumps({f"c{k}": 1 for k in range(MAX_CLASS_MAP_KEYS + 1)}))
    with pytest.raises(InvalidInputError, match=f"{MAX_CLASS_MAP_KEYS + 1:,} class names"):
        load_class_map(path)
    assert len(check_class_map({f"c{k}": 1 for k in range(MAX_CLASS_MAP_KEYS)})) == MAX_CLASS_MAP_KEYS


def test_a_directory_a_fifo_and_another_suffix_are_refused(tmp_path: Path) -> None:
    folder = tmp_path / "dir.json"
    folder.mkdir()
    with pytest.raises(InvalidInputError, match="dir.json"):
        load_class_map(folder)
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    with pytest.raises(InvalidInputError, match="fifo.json"):
        load_class_map(fifo)  # refused without blocking on the open
    with pytest.raises(InvalidInputError, match="unknown class map format '.yaml'"):
        load_class_map(_write(tmp_path, "car: 1", "map.yaml"))
    with pytest.raises(InvalidInputError, match="missing.json"):
        load_class_map(tmp_path / "missing.json")
