"""``benchmarks/bench_farm.py --stages``: where one farm worker's time goes, stage by stage.

Its numbers are not tested (speed is measured, never asserted): only that the table holds the
stages, that they add up to the total, and that the timers are taken off afterwards.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))


def test_the_stage_table_adds_up_and_the_timers_are_taken_off(tmp_path, capsys):
    import bench_farm

    from zbuf_occlude.visibility import cpu_zbuffer, embree_fast

    rasterise, threads = cpu_zbuffer._rasterise, embree_fast.DEFAULT_THREADS
    args = ["--root", str(REPO_ROOT / "data" / "samples"), "--objects", "2", "--views", "fibonacci:3", "--stages",
            "--storage", "compact", "--dense-points", "3000", "--scratch", str(tmp_path)]  # fmt: skip
    assert bench_farm.main(args) == 0
    out = capsys.readouterr().out
    rows = dict(re.findall(r"^\| (.+?) \| ([0-9.]+) \| [0-9.]+ \|$", out, flags=re.MULTILINE))
    for stage in ("mesh file read and parsed", "per view: pre-pass raster (numba)", "per view: Embree rays (float32)",
                  "per mesh: the oracle's Embree scene (BVH, face groups, adjacency)", "shard written (compressed) and hashed"):  # fmt: skip
        assert stage in rows, out
    total = float(rows.pop("total"))
    assert abs(sum(float(s) for s in rows.values()) - total) < 0.01 * len(rows) + 1e-9
    assert "load average" in out and "ms per view" in out
    assert cpu_zbuffer._rasterise is rasterise and embree_fast.DEFAULT_THREADS == threads
