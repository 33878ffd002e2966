"""The benchmark commands run (their numbers are not tested: speed is measured, never asserted).

* ``bash benchmarks/gpu.sh OUT --smoke`` writes its report (the CPU half of the GPU benchmark);
* without ``--smoke`` or ``--allow-software`` it refuses a software OpenGL renderer (exit 3);
* ``benchmarks/bench_visibility_peers.py`` refuses a machine loaded above its CPU count unless
  ``--force`` (exit 3), and a bad ``--points`` (exit 2);
* ``benchmarks/bench_returns.py`` at its smallest sizes prints every family's cases: the sector's
  first-return, opaque, transmittance and cast-alone rows, the turn's and the airborne
  scanner's exact and default (adaptive) rows (with the share of sub-rays not cast), each family's first
  row its reference (ratio 1.00), and the profile.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / "benchmarks"))


def _gpu_sh(out: Path, *flags: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHON": sys.executable}
    env.pop("ZBUF_OCCLUDE_AUTO", None)
    return subprocess.run(
        ["bash", str(REPO_ROOT / "benchmarks" / "gpu.sh"), str(out), *flags], env=env, capture_output=True, text=True, timeout=600
    )


@pytest.mark.slow
def test_gpu_benchmark_smoke_writes_its_report(tmp_path):
    res = _gpu_sh(tmp_path / "out", "--smoke")
    assert res.returncode == 0, res.stderr[-3000:]
    report = (tmp_path / "out" / "gpu.md").read_text()
    assert "OpenGL renderer (EGL)" in report and "GPU (nvidia-smi" in report
    assert "`zo.visible_mask` one-shot" in report and "`zbuffer-exact` kept scene" in report
    assert "| dense | 1 | 2 |" in report  # the farm's row: 2 objects, 1 worker
    assert "Load average (1, 5, 15 min) after" in report
    assert "## zbuffer-exact, stage by stage" in report and "| bin count ms |" in report
    assert "## Occlusion on the fly" in report and "| on-the-fly |" in report
    assert "## Point-splat visibility: GPU against CPU" in report and "### A GPU view's parts" in report


@pytest.mark.slow
def test_gpu_benchmark_refuses_a_software_renderer(tmp_path):
    from zbuf_occlude.render.context import SOFTWARE_RENDERERS, shared_context

    renderer = str(shared_context().info["GL_RENDERER"]).lower()
    if not any(s in renderer for s in SOFTWARE_RENDERERS):
        pytest.skip(f"a hardware renderer here ({renderer}): nothing to refuse")
    res = _gpu_sh(tmp_path / "out")
    assert res.returncode == 3, res.stderr[-2000:]
    assert "software rasteriser" in res.stderr
    assert not (tmp_path / "out" / "gpu.md").exists()


def test_peer_benchmark_refuses_a_loaded_machine_and_bad_points(monkeypatch, capsys):
    import bench_visibility_peers as bench

    monkeypatch.setattr(os, "getloadavg", lambda: (bench.cores() + 1.0, 0.0, 0.0))
    assert bench.main(["--points", "500", "--poses", "fibonacci:1"]) == 3
    assert "exceeds" in capsys.readouterr().err
    assert bench.main(["--points", "10,abc"]) == 2
    assert "'10,abc'" in capsys.readouterr().err


def test_peer_benchmark_sets_each_of_ours_beside_the_fastest_peer_call():
    import bench_visibility_peers as bench

    def row(name, walls):
        return {"method": name, "setup_ms": 0.0, "wall": walls, "cpu": walls, "agree": 0, "fv": 0, "fh": 0, "n": 0}

    rows = [
        row("`zo.visible_mask` one-shot", [0.010, 0.012]),
        row("Open3D `RaycastingScene.test_occlusions`", [0.030, 0.030]),
        row("Open3D `RaycastingScene.cast_rays`", [0.020, 0.024]),
    ]
    text = "\n".join(bench.against_fastest_peer(rows))
    assert "fastest peer call, Open3D `RaycastingScene.cast_rays` (22.0 ms per view)" in text
    assert "| `zo.visible_mask` one-shot | 11.0 | 22.0 | **2.00×** | 2.00× (2.00–2.00) |" in text
    assert "test_occlusions` 1.36×" in text


def test_returns_benchmark_prints_every_family(capsys):
    import bench_returns as bench

    bench.main(["--repeats", "1", "--ks", "7", "--sector", "5", "--half-size", "5", "--mesh", str(bench.FALLBACK), "--profile",
                "--profile-lines", "3", "--echo-rules", "chain,waveform"])  # fmt: skip
    out = capsys.readouterr().out
    rows = {tuple(cell.strip() for cell in line.split("|")[1:3]): line.split("|") for line in out.splitlines() if line.startswith("| ")}
    for family, name in [
        ("sector", "hdl32e: 1 ray, 1 return"),
        ("sector", "hdl32e: 7 sub-rays, 4 returns, opaque"),
        ("sector", "hdl32e: 7 sub-rays, 4 returns, transmittance"),
        ("sector", "hdl32e: 7 sub-rays: directions and cast alone"),
        ("turn", "hdl32e: 1 ray, 1 return"),
        ("turn", "hdl32e: 7 sub-rays, 2 returns, exact"),
        ("turn", "hdl32e: 7 sub-rays, 2 returns, default (adaptive)"),
        ("airborne", "riegl-q1560: 1 ray, 1 return"),
        ("airborne", "riegl-q1560: 19 sub-rays, 15 returns, exact"),
        ("airborne", "riegl-q1560: 19 sub-rays, 15 returns, default (adaptive)"),
        ("sector", "hdl32e: 7 sub-rays, 4 returns, waveform, opaque"),
        ("turn", "hdl32e: 7 sub-rays, 2 returns, waveform, exact"),
        ("turn", "hdl32e: 7 sub-rays, 2 returns, waveform, default (adaptive)"),
        ("airborne", "riegl-q1560: 19 sub-rays, 15 returns, waveform, exact"),
    ]:
        assert (family, name) in rows, (family, name, out)
    for family in ("sector", "turn", "airborne"):  # the reference: its own ratio
        assert rows[family, next(n for f, n in rows if f == family)][9].strip() == "1.00"
    assert rows["turn", "hdl32e: 1 ray, 1 return"][3].strip() == "69,440"
    assert float(rows["turn", "hdl32e: 7 sub-rays, 2 returns, default (adaptive)"][6]) > 0.0  # sub-rays not cast, %
    assert rows["turn", "hdl32e: 7 sub-rays, 2 returns, exact"][6].strip() == "–"
    assert rows["sector", "hdl32e: 7 sub-rays: directions and cast alone"][4].strip() == "–"  # no points: no scan
    assert "## cProfile: 1 scans of sector: hdl32e: 7 sub-rays, 4 returns, opaque" in out
