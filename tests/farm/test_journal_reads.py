"""The farm's journal (plan, records, tasks) read through the reading layer: inside its folder, regular files only.

A task folder given to ``farm-merge`` may be shared or crafted: a plan or a record that links to a
file elsewhere is not the run's, and one that is a FIFO would block every command on the folder.
"""

from __future__ import annotations

import json
import os

import pytest

from zbuf_occlude.dataset.layout import PLAN_FILE
from zbuf_occlude.errors import InvalidInputError, UnsafePathError
from zbuf_occlude.farm.journal import read_json, read_plan

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs os.mkfifo")


def test_a_plan_that_links_out_of_its_folder_is_refused_naming_it(tmp_path):
    (tmp_path / "task").mkdir()
    (tmp_path / "plan.json").write_text("{}")
    (tmp_path / "task" / PLAN_FILE).symlink_to(tmp_path / "plan.json")
    with pytest.raises(UnsafePathError, match=rf"{PLAN_FILE} leads outside {tmp_path / 'task'}"):
        read_plan(tmp_path / "task")


@needs_fifo
def test_a_plan_that_is_a_fifo_is_refused_at_once(tmp_path):
    os.mkfifo(tmp_path / PLAN_FILE)
    with pytest.raises(InvalidInputError, match=rf"{PLAN_FILE}: is a FIFO; only regular files are read"):
        read_plan(tmp_path)


def test_no_plan_is_none_and_a_damaged_one_is_named(tmp_path):
    assert read_plan(tmp_path) is None
    (tmp_path / PLAN_FILE).write_bytes(b"\xff{}")
    with pytest.raises(InvalidInputError, match=rf"{PLAN_FILE}: not UTF-8"):
        read_plan(tmp_path)


def test_a_record_that_links_out_of_the_run_is_no_record(tmp_path):
    (tmp_path / "out" / "records").mkdir(parents=True)
    (tmp_path / "rec.json").write_text(json.dumps({"status": "ok"}))
    (tmp_path / "out" / "records" / "000000.json").symlink_to(tmp_path / "rec.json")
    (tmp_path / "out" / "records" / "000001.json").write_text(json.dumps({"status": "ok"}))
    assert read_json(tmp_path / "out" / "records" / "000000.json", within=tmp_path / "out") is None
    assert read_json(tmp_path / "out" / "records" / "000001.json", within=tmp_path / "out") == {"status": "ok"}


@needs_fifo
def test_a_record_that_is_a_fifo_is_no_record(tmp_path):
    os.mkfifo(tmp_path / "000000.json")
    assert read_json(tmp_path / "000000.json", within=tmp_path) is None
