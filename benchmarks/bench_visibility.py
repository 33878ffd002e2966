"""Per-view cost of z-buffer hidden surface removal against the exact oracles (issue 3, item 11).

For each mesh (small, medium, large) and point count, one subprocess loads the mesh, samples
the points, builds a :class:`zbuf_occlude.visibility.zbuffer.ResidentPoints` once and then, for each pose, runs side by side:

* ``zbuffer``: ``scene.visible(camera, resolution=R)``, the pipeline a user of many views runs
  (rasterise depth + face id, compute-shader candidate tests, Embree for the uncertain points);
* ``GPU only``: the same with ``resolve="none"`` (no CPU pass; a few % of points mis-called);
* ``render``: ``scene.renderer.render(camera)``, rasterisation plus read-back of depth and face
  id to numpy (not part of ``zbuffer``, which reads back one bit per point; shown for scale);
* ``Embree oracle``: ``visible_mask(..., method="oracle", face_index=...)``;
* ``numpy oracle``: ``visible_mask(..., method="oracle-numpy", ...)``, only on as many poses as
  fit in ``--numpy-max-s`` seconds per configuration, by an estimate from two small probes;
  skipped, with the estimate, where not even one does.

Times are per view, the median over the poses; one warm-up pose per mesh is excluded (shader
JIT, render-target allocation, Embree BVH build).  Wall time is what a user waits for; CPU time
(all threads of the process: llvmpipe's rasteriser threads and Embree's single thread) is
also given, because on a shared machine wall times swing with other people's load while CPU
time does not.  Agreement is with the Embree oracle, pooled over the poses.  Peak memory is the
process's peak resident set size during each method's calls (the peak is reset before every
call through ``/proc/self/clear_refs``), including everything it holds (mesh, points, GL
buffers); each configuration runs in its own process, so peaks do not leak across rows.

A second measurement gives the throughput, views per second, of ``scene.visible`` at a lower
resolution over the ``grid25`` poses.

Usage::

    .venv/bin/python benchmarks/bench_visibility.py                  # the full run, ~10 min
    .venv/bin/python benchmarks/bench_visibility.py --sizes small --points 10000 --poses 2
    .venv/bin/python benchmarks/bench_visibility.py --peers          # issue 11's peer table

The report (Markdown) goes to stdout, progress to stderr.
"""

from __future__ import annotations

import argparse
import datetime
import json
import logging
import os
import platform
import resource
import shlex
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
MODELNET_SUBSET = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset"

#: Default meshes.  small: shipped with the repository (2,234 faces); medium: a real ModelNet10
#: sofa (27,288 faces after cleaning); large: the medium mesh, 1-to-4 midpoint subdivided
#: ``--large-subdivisions`` times (twice: 436,608 faces).
DEFAULT_SMALL = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
DEFAULT_MEDIUM = MODELNET_SUBSET / "ModelNet10" / "sofa" / "train" / "sofa_0001.off"
DEFAULT_LARGE_SUBDIVISIONS = 2
DEFAULT_POINTS = (10_000, 100_000, 1_000_000)
DEFAULT_RESOLUTION = 1024
#: Measured poses: the diagonal of grid25, so every elevation and every azimuth occurs once.
DEFAULT_POSES = "-80:0,-40:72,0:144,40:216,80:288"
#: Warm-up pose, not in the measured set.
WARMUP_POSE = (-40.0, 0.0)
#: Points given to the Embree oracle in the warm-up call: enough to build and touch the BVH,
#: few enough not to cost a full 1M-point view.
WARMUP_ORACLE_POINTS = 1_000
#: Point counts the numpy oracle is timed on to estimate a whole view (fixed + per-point cost).
NUMPY_PROBE_POINTS = (300, 1500)
#: Time the numpy oracle may take per configuration (estimated): it runs on as many poses,
#: up to ``--numpy-poses``, as fit, and is skipped where not even one does.
DEFAULT_NUMPY_MAX_S = 30.0
DEFAULT_NUMPY_POSES = 3
DEFAULT_SEED = 0
#: Throughput measurement: the issue's target is >= 80 views/s at 512² with 100k points.
DEFAULT_THROUGHPUT_RESOLUTION = 512
DEFAULT_THROUGHPUT_POINTS = 100_000
DEFAULT_THROUGHPUT_VIEWS = 25
#: Files whose git blob ids the report lists, so a run can be matched to the code it measured.
MEASURED_SOURCES = (
    "zbuf_occlude/visibility/zbuffer.py",
    "zbuf_occlude/visibility/oracle.py",
    "zbuf_occlude/render/moderngl_backend.py",
    "zbuf_occlude/render/shaders/visibility_candidates.comp",
    "zbuf_occlude/render/shaders/common.glsl",
)
#: numpy's BLAS threads in the workers.  (N, 3) @ (3, 3) products (``Camera.project``, used by
#: the oracles' frustum test) under a multithreaded OpenBLAS cost ~6x more on a busy 2-core
#: machine (its threads busy-wait); that would flatter the z-buffer's ratios, so pin it to 1.
DEFAULT_BLAS_THREADS = 1
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Per-configuration subprocess limit, seconds.
DEFAULT_CONFIG_TIMEOUT_S = 900.0
#: The issue's targets (on this machine).
TARGET_RATIO_100K = 5.0
TARGET_RATIO_1M = 20.0
TARGET_VIEWS_PER_S = 80.0
TARGET_PEAK_MB = 2048.0

log = logging.getLogger("bench_visibility")


# =========================================================================================
# Measurement helpers (run inside the worker process)
# =========================================================================================
def _reset_peak_rss() -> bool:
    """Reset the process's peak RSS to its current RSS; False where the kernel does not allow it."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _peak_rss_mb() -> float:
    """Peak resident set size of this process, MiB (``ru_maxrss`` is KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


class _Timer:
    """Collects per-call wall time, process CPU time and peak RSS of one method."""

    def __init__(self) -> None:
        self.wall: list[float] = []
        self.cpu: list[float] = []
        self.peak_mb = 0.0
        self.peak_resettable = True

    def __call__(self, fn: Callable[[], Any]) -> Any:
        self.peak_resettable &= _reset_peak_rss()
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        w1, c1 = time.perf_counter(), time.process_time()
        self.wall.append(w1 - w0)
        self.cpu.append(c1 - c0)
        self.peak_mb = max(self.peak_mb, _peak_rss_mb())
        return out

    def summary(self) -> dict[str, Any]:
        if not self.wall:
            return {}
        return {
            "wall_ms": 1e3 * statistics.median(self.wall),
            "cpu_ms": 1e3 * statistics.median(self.cpu),
            "wall_ms_all": [1e3 * t for t in self.wall],
            "n_views": len(self.wall),
            "peak_mb": self.peak_mb,
            "peak_resettable": self.peak_resettable,
        }


def _agreement_counts(predicted: np.ndarray, truth: np.ndarray) -> dict[str, int]:
    return {
        "n": int(len(truth)),
        "false_visible": int(np.count_nonzero(predicted & ~truth)),
        "false_hidden": int(np.count_nonzero(~predicted & truth)),
        "truth_visible": int(np.count_nonzero(truth)),
    }


def _pool(counts: list[dict[str, int]]) -> dict[str, float]:
    """Agreement pooled over poses, plus the worst pose's accuracy."""
    n = sum(c["n"] for c in counts)
    fv = sum(c["false_visible"] for c in counts)
    fh = sum(c["false_hidden"] for c in counts)
    worst = min(1.0 - (c["false_visible"] + c["false_hidden"]) / c["n"] for c in counts)
    return {
        "accuracy": 1.0 - (fv + fh) / n,
        "false_visible": fv / n,
        "false_hidden": fh / n,
        "worst_accuracy": worst,
        "visible_fraction": sum(c["truth_visible"] for c in counts) / n,
    }


def _load(spec: dict[str, Any]):
    import zbuf_occlude as zo

    mesh = zo.load_mesh(spec["path"])
    for _ in range(spec.get("subdivisions", 0)):
        # 1-to-4 midpoint subdivision: same surface, 4x the faces (loaded mesh is normalised).
        mesh = mesh.subdivide()
    return mesh


def _parse_poses(text: str) -> list[tuple[float, float]]:
    """``--poses``: a count N (the first N of :data:`DEFAULT_POSES`) or a view schedule."""
    from zbuf_occlude import view_schedule

    if text.strip().isdigit():
        return view_schedule(DEFAULT_POSES)[: int(text)]
    return view_schedule(text)


def run_config(job: dict[str, Any]) -> dict[str, Any]:
    """One (mesh, point count) row: every method over every pose.  Runs in a fresh process."""
    import zbuf_occlude as zo
    from zbuf_occlude.visibility.zbuffer import ResidentPoints

    out: dict[str, Any] = {"job": job, "gl": zo.context_info()}
    t0 = time.perf_counter()
    _reset_peak_rss()
    mesh = _load(job["mesh"])
    points, face_index = zo.sample_surface(mesh, count=job["points"], seed=job["seed"])
    out["load_sample_s"] = time.perf_counter() - t0
    out["n_faces"] = len(mesh.faces)
    res = job["resolution"]
    cameras = [zo.camera_on_sphere(el, az, resolution=res) for el, az in _parse_poses(job["poses"])]
    warm = zo.camera_on_sphere(*WARMUP_POSE, resolution=res)

    t0 = time.perf_counter()
    scene = ResidentPoints(mesh, points, face_index)
    out["scene_build_s"] = time.perf_counter() - t0
    out["setup_peak_mb"] = _peak_rss_mb()

    # Warm-up: shader JIT on first dispatch, render targets, Embree BVH (built once per mesh).
    t0 = time.perf_counter()
    scene.visible(warm, resolution=res)
    scene.visible(warm, resolution=res, resolve="none")
    scene.renderer.render(warm)
    out["zbuffer_warmup_s"] = time.perf_counter() - t0
    sub = slice(0, WARMUP_ORACLE_POINTS)
    t0 = time.perf_counter()
    zo.visible_mask(mesh, points[sub], warm, method="oracle", face_index=face_index[sub])
    out["oracle_warmup_s"] = time.perf_counter() - t0

    timers = {k: _Timer() for k in ("zbuffer", "gpu_only", "render", "oracle", "numpy")}
    agree: dict[str, list[dict[str, int]]] = {"zbuffer": [], "gpu_only": [], "numpy": []}
    uncertain: list[float] = []

    # Numpy oracle: its cost is a fixed part (planes, projection and sort of all faces) plus a
    # part that grows with the points in the frustum; fit both from two probes and extrapolate.
    inside = np.flatnonzero(cameras[0].in_frustum(points))
    probe_times = []
    probe_sizes = [min(n, len(inside)) for n in NUMPY_PROBE_POINTS]
    for n in probe_sizes:
        probe = inside[:: max(1, len(inside) // max(n, 1))][:n]
        w0 = time.perf_counter()
        zo.visible_mask(mesh, points[probe], cameras[0], method="oracle-numpy", face_index=face_index[probe])
        probe_times.append(time.perf_counter() - w0)
    per_point = max(probe_times[1] - probe_times[0], 0.0) / max(probe_sizes[1] - probe_sizes[0], 1)
    fixed = max(probe_times[0] - per_point * probe_sizes[0], 0.0)
    numpy_est_s = fixed + per_point * len(inside)
    out["numpy_est_view_s"] = numpy_est_s
    numpy_poses = min(job["numpy_poses"], int(job["numpy_max_s"] // max(numpy_est_s, 1e-9)))

    for k, cam in enumerate(cameras):
        log.info("  pose %d/%d (el %g, az %g)", k + 1, len(cameras), cam.elevation_deg, cam.azimuth_deg)
        z = timers["zbuffer"](lambda cam=cam: scene.visible(cam, resolution=res))
        g = timers["gpu_only"](lambda cam=cam: scene.visible(cam, resolution=res, resolve="none"))
        timers["render"](lambda cam=cam: scene.renderer.render(cam))
        o = timers["oracle"](lambda cam=cam: zo.visible_mask(mesh, points, cam, method="oracle", face_index=face_index))
        # Share of points the compute shader leaves to Embree (untimed; the private buffer is
        # the ResidentPoints' own upload, so this repeats exactly what scene.visible just did).
        uncertain.append(float(scene.renderer.visible(cam, scene._buffer)[1].mean()))
        agree["zbuffer"].append(_agreement_counts(z, o))
        agree["gpu_only"].append(_agreement_counts(g, o))
        if k < numpy_poses:
            n = timers["numpy"](lambda cam=cam: zo.visible_mask(mesh, points, cam, method="oracle-numpy", face_index=face_index))
            agree["numpy"].append(_agreement_counts(n, o))

    scene.release()
    out["timings"] = {k: t.summary() for k, t in timers.items()}
    out["agreement"] = {k: _pool(v) for k, v in agree.items() if v}
    out["uncertain_fraction"] = {"mean": float(np.mean(uncertain)), "max": float(np.max(uncertain))}
    out["process_peak_mb"] = _peak_rss_mb()
    return out


def run_throughput(job: dict[str, Any]) -> dict[str, Any]:
    """Views per second of ``scene.visible`` over the grid25 poses, one process, one ResidentPoints."""
    import zbuf_occlude as zo
    from zbuf_occlude.visibility.zbuffer import ResidentPoints

    mesh = _load(job["mesh"])
    points, face_index = zo.sample_surface(mesh, count=job["points"], seed=job["seed"])
    res = job["resolution"]
    grid = zo.view_schedule("grid25")
    cameras = [zo.camera_on_sphere(*grid[k % len(grid)], resolution=res) for k in range(job["views"])]
    out: dict[str, Any] = {"job": job, "n_faces": len(mesh.faces)}
    with ResidentPoints(mesh, points, face_index) as scene:
        for resolve in ("embree", "none"):
            scene.visible(zo.camera_on_sphere(*WARMUP_POSE, resolution=res), resolve=resolve)
            w0, c0 = time.perf_counter(), time.process_time()
            for cam in cameras:
                scene.visible(cam, resolution=res, resolve=resolve)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            out[resolve] = {"views_per_s": len(cameras) / wall, "cpu_ms_per_view": 1e3 * cpu / len(cameras)}
    return out


# =========================================================================================
# Driver (parent process)
# =========================================================================================
def _spawn(kind: str, job: dict[str, Any], timeout_s: float, blas_threads: int) -> dict[str, Any]:
    """Run one job in a fresh interpreter; its peak memory is then its own."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", kind, json.dumps(job)]
    env = os.environ.copy()
    if blas_threads > 0:
        env.update(dict.fromkeys(BLAS_THREAD_VARIABLES, str(blas_threads)))
    try:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=None, text=True, timeout=timeout_s, env=env)
    except subprocess.TimeoutExpired:
        return {"job": job, "error": f"timed out after {timeout_s:.0f} s"}
    if proc.returncode != 0:
        return {"job": job, "error": f"worker exited with {proc.returncode}"}
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _fmt_ms(ms: float | None) -> str:
    if ms is None:
        return "–"
    return f"{ms:,.0f}" if ms >= 100 else f"{ms:.1f}"


def _fmt_pct(x: float | None, digits: int = 2) -> str:
    return "–" if x is None else f"{100 * x:.{digits}f}"


def _machine() -> dict[str, str]:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    def git(*args: str) -> str:
        try:
            return subprocess.run(["git", *args], cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout.strip()
        except (OSError, subprocess.CalledProcessError):
            return "unknown"

    dirty = git("status", "--porcelain", "--untracked-files=no")
    # Blob ids of the measured sources: the tree may hold uncommitted work of others.
    sources = " ".join(f"{Path(f).name} {git('hash-object', f)[:8]}" for f in MEASURED_SOURCES)
    return {
        "sources": sources,
        "cpu": f"{os.cpu_count()}-core {platform.machine()} ({cpu})",
        "commit": git("rev-parse", "--short", "HEAD") + (" + uncommitted changes" if dirty else ""),
        "python": platform.python_version(),
        "numpy": np.__version__,
    }


def _row_label(result: dict[str, Any]) -> str:
    job = result["job"]
    faces = f"{result['n_faces']:,}" if "n_faces" in result else "?"
    return f"{job['mesh']['label']} | {faces} | {job['points']:,}"


def report(results: list[dict[str, Any]], throughput: dict[str, Any] | None, args, started: dict) -> str:
    """The Markdown report: header, timing table, agreement/memory table, targets."""
    lines: list[str] = []
    machine = _machine()
    gl = next((r["gl"] for r in results if "gl" in r), {})
    lines += [
        "## z-buffer HSR vs the exact oracles: per-view cost",
        "",
        f"- command: `{started['command']}`",
        f"- date: {started['date']}; commit {machine['commit']}; measured sources (git blob ids): {machine['sources']}",
        f"- machine: {machine['cpu']}; OpenGL: {gl.get('renderer', '?')}, {gl.get('version', '?')} "
        f"via {gl.get('backend', '?').upper()}, vendor {gl.get('vendor', '?')}; Python {machine['python']}, "
        f"numpy {machine['numpy']}",
        f"- load average (1 min) at start / end: {started['load_start']:.1f} / {os.getloadavg()[0]:.1f} "
        "(other processes share the CPU: wall times are noisy, CPU times less so)",
        f"- numpy BLAS threads: {args.blas_threads or 'as in the environment'}; llvmpipe threads: "
        f"{os.environ.get('LP_NUM_THREADS', 'default (one per core)')}\n"
        f"- resolution {args.resolution}², poses (el:az) "
        f"{','.join(f'{el:g}:{az:g}' for el, az in _parse_poses(args.poses))} (median over them; warm-up pose "
        f"{WARMUP_POSE[0]:g}:{WARMUP_POSE[1]:g} excluded), seed {args.seed}",
        "",
        "### Time per view, ms (median over poses)",
        "",
        "`zbuffer` = `scene.visible(camera, resolution=R)` (render + compute shader + Embree for "
        'uncertain points); `GPU only` = `resolve="none"`; `render` = `scene.renderer.render` '
        "(rasterise + read back depth and face id, for scale); ratios = oracle time / `zbuffer` "
        "time, wall (CPU).",
        "",
        "| mesh | faces | points | zbuffer wall (CPU) | GPU only wall (CPU) | render + read-back | "
        "Embree oracle wall (CPU) | numpy oracle wall | Embree / zbuffer | numpy / zbuffer |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        if "error" in r:
            lines.append(f"| {_row_label(r)} | error: {r['error']} |||||||")
            continue
        t = r["timings"]
        z, g, rd, o, n = (t[k] for k in ("zbuffer", "gpu_only", "render", "oracle", "numpy"))
        if n:
            numpy_cell = _fmt_ms(n["wall_ms"])
            if n["n_views"] < z["n_views"]:
                numpy_cell += f" ({n['n_views']} pose{'s' if n['n_views'] > 1 else ''})"
            numpy_ratio = f"{n['wall_ms'] / z['wall_ms']:.0f}×"
        else:
            numpy_cell = f"skipped (est. {r['numpy_est_view_s']:,.0f} s)"
            numpy_ratio = f"(est. {1e3 * r['numpy_est_view_s'] / z['wall_ms']:,.0f}×)"
        lines.append(
            f"| {_row_label(r)} | {_fmt_ms(z['wall_ms'])} ({_fmt_ms(z['cpu_ms'])}) | "
            f"{_fmt_ms(g['wall_ms'])} ({_fmt_ms(g['cpu_ms'])}) | {_fmt_ms(rd['wall_ms'])} | "
            f"{_fmt_ms(o['wall_ms'])} ({_fmt_ms(o['cpu_ms'])}) | {numpy_cell} | "
            f"{o['wall_ms'] / z['wall_ms']:.1f}× ({o['cpu_ms'] / z['cpu_ms']:.1f}×) | {numpy_ratio} |"
        )
    lines += [
        "",
        "### Agreement with the Embree oracle (pooled over poses, % of all points) and peak memory",
        "",
        "`sent to Embree`: points the compute shader flags uncertain (the centre pixel does not show "
        "their own face: sub-pixel faces, cracks), decided by Embree in `zbuffer`, called visible in `GPU only`. "
        "Peak RSS, MiB: the process's peak resident set during that method's calls (mesh, points and "
        "GL buffers included); `setup` = load + sample + `ResidentPoints` build.",
        "",
        "| mesh | faces | points | visible | zbuffer acc. (worst pose) | false-vis. | false-hid. | "
        "GPU only acc. | sent to Embree, mean (max) | numpy == Embree | peak RSS setup / zbuffer / Embree | "
        "one-off: ResidentPoints build, BVH build |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        if "error" in r:
            continue
        a, t = r["agreement"], r["timings"]
        za, ga = a["zbuffer"], a["gpu_only"]
        na = a.get("numpy")
        numpy_cell = "–" if na is None else f"{_fmt_pct(na['accuracy'], 3)} %"
        lines.append(
            f"| {_row_label(r)} | {_fmt_pct(za['visible_fraction'], 1)} % | {_fmt_pct(za['accuracy'], 3)} % "
            f"({_fmt_pct(za['worst_accuracy'], 3)}) | {_fmt_pct(za['false_visible'], 3)} | "
            f"{_fmt_pct(za['false_hidden'], 3)} | {_fmt_pct(ga['accuracy'], 2)} % | "
            f"{_fmt_pct(r['uncertain_fraction']['mean'], 1)} % ({_fmt_pct(r['uncertain_fraction']['max'], 1)}) | "
            f"{numpy_cell} | "
            f"{r['setup_peak_mb']:,.0f} / {t['zbuffer']['peak_mb']:,.0f} / {t['oracle']['peak_mb']:,.0f} | "
            f"{r['scene_build_s']:.2f} s, {r['oracle_warmup_s']:.2f} s |"
        )
    if throughput is not None and "error" not in throughput:
        job = throughput["job"]
        lines += [
            "",
            f"### Throughput: `scene.visible` over {job['views']} grid25 poses, {job['resolution']}², "
            f"{job['points']:,} points, {job['mesh']['label']} ({throughput['n_faces']:,} faces), one process",
            "",
            "| resolve | views/s (wall) | CPU ms per view |",
            "|---|---:|---:|",
        ]
        for resolve in ("embree", "none"):
            tp = throughput[resolve]
            lines.append(f"| `{resolve}` | {tp['views_per_s']:.1f} | {tp['cpu_ms_per_view']:.1f} |")
    lines += ["", "### Targets (issue 3)", ""] + _targets(results, throughput, args)
    return "\n".join(lines) + "\n"


def _targets(results: list[dict[str, Any]], throughput: dict[str, Any] | None, args) -> list[str]:
    def find(label: str, n: int) -> dict[str, Any] | None:
        for r in results:
            if r["job"]["mesh"]["label"] == label and r["job"]["points"] == n and "error" not in r:
                return r
        return None

    def verdict(ok: bool) -> str:
        return "**met**" if ok else "**missed**"

    out = []
    for n, target in ((100_000, TARGET_RATIO_100K), (1_000_000, TARGET_RATIO_1M)):
        r = find("medium", n)
        if r is None:
            out.append(f"- medium mesh, {n:,} points: not measured in this run")
            continue
        z, o = r["timings"]["zbuffer"], r["timings"]["oracle"]
        wall, cpu = o["wall_ms"] / z["wall_ms"], o["cpu_ms"] / z["cpu_ms"]
        out.append(
            f"- medium mesh, {args.resolution}², {n:,} points, zbuffer ≥ {target:g}× faster than the Embree "
            f"oracle: {wall:.1f}× wall ({cpu:.1f}× CPU time) → {verdict(wall >= target)}"
        )
    if throughput is not None and "error" not in throughput:
        vps = throughput["embree"]["views_per_s"]
        job = throughput["job"]
        out.append(
            f"- ≥ {TARGET_VIEWS_PER_S:g} views/s at {job['resolution']}² with {job['points']:,} points: "
            f"{vps:.1f} views/s ({throughput['none']['views_per_s']:.1f} GPU only) → "
            f"{verdict(vps >= TARGET_VIEWS_PER_S)}"
        )
    large = [r for r in results if r["job"]["mesh"]["label"] == "large" and "error" not in r]
    if large:
        r = max(large, key=lambda r: r["job"]["points"])
        peak = max(r["setup_peak_mb"], r["timings"]["zbuffer"]["peak_mb"])
        out.append(
            f"- peak memory, large mesh ({r['n_faces']:,} faces), {r['job']['points']:,} points, z-buffer "
            f"pipeline < {TARGET_PEAK_MB:,.0f} MiB: {peak:,.0f} MiB → {verdict(peak < TARGET_PEAK_MB)}"
        )
    return out


def _python_name() -> str:
    """The interpreter as typed from the repository root (``.venv/bin/python``), else ``python``."""
    exe = Path(sys.executable)
    try:
        return exe.relative_to(REPO_ROOT).as_posix()
    except ValueError:
        return "python"


def main(argv: list[str] | None = None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    if "--peers" in argv:  # issue 11's peer table (benchmarks/bench_visibility_peers.py)
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench_visibility_peers import main as peers_main

        return peers_main([a for a in argv if a != "--peers"])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter)
    parser.add_argument("--small", type=Path, default=DEFAULT_SMALL, help="small mesh (~2k faces)")
    parser.add_argument("--medium", type=Path, default=DEFAULT_MEDIUM, help="medium mesh (~20-30k faces)")
    parser.add_argument("--large", type=Path, default=None, help="mesh to subdivide for 'large' (default: --medium)")
    parser.add_argument(
        "--large-subdivisions", type=int, default=DEFAULT_LARGE_SUBDIVISIONS, help="1-to-4 subdivisions of --large (default %(default)s)"
    )
    parser.add_argument("--sizes", default="small,medium,large", help="which meshes (default %(default)s)")
    parser.add_argument(
        "--points", default=",".join(str(n) for n in DEFAULT_POINTS), help="point counts, comma separated (default %(default)s)"
    )
    parser.add_argument("--resolution", type=int, default=DEFAULT_RESOLUTION, help="image size (default %(default)s)")
    parser.add_argument(
        "--poses",
        default=DEFAULT_POSES,
        help="measured poses: EL:AZ,..., a schedule name, or a count N (the first N of the default, %(default)s)",
    )
    parser.add_argument(
        "--numpy-max-s",
        type=float,
        default=DEFAULT_NUMPY_MAX_S,
        help="estimated seconds the numpy oracle may take per mesh and point count; it runs on as many poses as fit (default %(default)s)",
    )
    parser.add_argument(
        "--numpy-poses", type=int, default=DEFAULT_NUMPY_POSES, help="poses the numpy oracle runs on, at most (default %(default)s)"
    )
    parser.add_argument("--throughput-resolution", type=int, default=DEFAULT_THROUGHPUT_RESOLUTION)
    parser.add_argument("--throughput-points", type=int, default=DEFAULT_THROUGHPUT_POINTS)
    parser.add_argument(
        "--throughput-views", type=int, default=DEFAULT_THROUGHPUT_VIEWS, help="views timed for views/s; 0 skips the throughput measurement"
    )
    parser.add_argument("--seed", type=int, default=DEFAULT_SEED)
    parser.add_argument(
        "--blas-threads",
        type=int,
        default=DEFAULT_BLAS_THREADS,
        help="numpy BLAS threads in the measuring processes; 0 leaves the environment as it is (default %(default)s)",
    )
    parser.add_argument("--timeout", type=float, default=DEFAULT_CONFIG_TIMEOUT_S, help="seconds per configuration")
    parser.add_argument("--worker", nargs=2, metavar=("KIND", "JOB"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(message)s", datefmt="%H:%M:%S", stream=sys.stderr)

    if args.worker:
        kind, job = args.worker[0], json.loads(args.worker[1])
        result = {"config": run_config, "throughput": run_throughput}[kind](job)
        print(json.dumps(result))
        return 0

    started = {
        "command": shlex.join([_python_name(), "benchmarks/bench_visibility.py", *(sys.argv[1:] if argv is None else argv)]),
        "date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "load_start": os.getloadavg()[0],
    }
    large_src = args.large or args.medium
    meshes = {
        "small": {"label": "small", "path": str(args.small)},
        "medium": {"label": "medium", "path": str(args.medium)},
        "large": {"label": "large", "path": str(large_src), "subdivisions": args.large_subdivisions},
    }
    sizes = [s.strip() for s in args.sizes.split(",") if s.strip()]
    for s in sizes:
        if s not in meshes:
            parser.error(f"unknown size {s!r}; use small, medium, large")
        if not Path(meshes[s]["path"]).is_file():
            parser.error(f"{s} mesh not found: {meshes[s]['path']} (pass --{s} PATH)")
    counts = [int(n) for n in args.points.split(",") if n.strip()]
    if args.throughput_views > 0 and not Path(meshes["medium"]["path"]).is_file():
        parser.error(f"medium mesh not found for the throughput run: {args.medium} (pass --medium PATH)")

    results = []
    t_start = time.perf_counter()
    for s in sizes:
        for n in counts:
            log.info("%s mesh, %d points", s, n)
            job = {
                "mesh": meshes[s],
                "points": n,
                "resolution": args.resolution,
                "poses": args.poses,
                "seed": args.seed,
                "numpy_max_s": args.numpy_max_s,
                "numpy_poses": args.numpy_poses,
            }
            results.append(_spawn("config", job, args.timeout, args.blas_threads))
    throughput = None
    if args.throughput_views > 0:
        log.info("throughput: medium mesh, %d points, %d²", args.throughput_points, args.throughput_resolution)
        job = {
            "mesh": meshes["medium"],
            "points": args.throughput_points,
            "resolution": args.throughput_resolution,
            "views": args.throughput_views,
            "seed": args.seed,
        }
        throughput = _spawn("throughput", job, args.timeout, args.blas_threads)
    log.info("done in %.0f s", time.perf_counter() - t_start)
    sys.stdout.write(report(results, throughput, args, started))
    return 0


if __name__ == "__main__":
    sys.exit(main())
