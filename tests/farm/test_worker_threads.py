"""Each farm worker process takes its share of the cores as the threads of its views."""

from __future__ import annotations

import pytest

from zbuf_occlude.farm.pool import worker_threads


@pytest.mark.parametrize(
    ("workers", "cpus", "threads"), [(1, 1, 1), (1, 8, 8), (2, 2, 1), (2, 8, 4), (3, 8, 2), (4, 2, 1), (16, 8, 1), (0, 4, 4)]
)
def test_each_worker_takes_its_share_of_the_cores_and_at_least_one(workers, cpus, threads):
    assert worker_threads(workers, cpus) == threads


def test_by_default_the_share_is_of_the_cores_this_process_may_use(monkeypatch):
    from zbuf_occlude.farm import pool

    monkeypatch.setattr(pool, "usable_cpus", lambda: 6)
    assert worker_threads(2) == 3
