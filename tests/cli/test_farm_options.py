"""``farm``'s options: their defaults, read from the machine where they depend on it."""

from __future__ import annotations

import argparse
import os

import pytest

from zbuf_occlude.cli.farm import add_farm_parser
from zbuf_occlude.defaults import MAX_WORKERS


def _workers_default() -> tuple[int, str]:
    parser = argparse.ArgumentParser()
    farm = add_farm_parser(parser.add_subparsers())
    args = parser.parse_args(["farm", "meshes", "--out", "ds"])
    return args.workers, farm.format_help()


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity"), reason="no CPU affinity on this system")
def test_workers_default_to_the_cores_this_process_may_use(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 2, 5})  # a CPU set of 3 cores (taskset, a batch job)
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    workers, help_text = _workers_default()
    assert workers == 3
    assert "(default: 3; the CPU cores this process may use" in " ".join(help_text.split())
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(MAX_WORKERS + 100)))
    assert _workers_default()[0] == MAX_WORKERS


def test_without_an_affinity_mask_the_workers_are_every_core(monkeypatch):
    monkeypatch.delattr(os, "sched_getaffinity", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 6)
    assert _workers_default()[0] == 6
    monkeypatch.setattr(os, "cpu_count", lambda: None)  # unknown: one worker
    assert _workers_default()[0] == 1
