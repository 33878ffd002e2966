"""Visibility peers: zbuf_occlude's call beside the tools a user would pick instead.

One process, one mesh (default ModelNet10 ``sofa_0001``), for each point count: every method
tests the same points from the same cameras, interleaved pose by pose (A B C, B C A, ...: the
order rotates each pose, so that a shared machine's load hits all methods alike), after one
warm-up pose; ``--repeats`` goes over the poses again.  Per method: set-up (what is built once per
mesh or point set), median wall and CPU ms per view (CPU: the process's time, all threads), and
agreement with the exact oracle pooled over the poses (false-visible, false-hidden).

Every speed figure of ours is then given against the *fastest peer call* of the same run (the
peer row of the smallest median wall time; Open3D's ``cast_rays`` on the machines measured so
far), side by side: both medians, their ratio, and the median and range of the per-view ratios
(each view's two calls ran back to back, so these hold up on a shared machine).

Rows:

* ``zo.visible_mask(mesh, points, camera, face_index=fi)``: the one-shot call (method
  ``auto``); per-mesh state (Embree scene, face data) is kept across calls by the library;
* ``zo.VisibilitySession(...)`` once, then ``session.visible(camera)``: a kept session;
* ``embree-fast``, rays only: the one-shot call without the z-buffer pre-pass;
* Open3D ``RaycastingScene`` (``test_occlusions`` and ``cast_rays``), NVIDIA Warp
  ``mesh_query_ray`` (CPU; CUDA when present), trimesh ``RayMeshIntersector.intersects_any``
  (Embree): the peers.  Each gets its mesh structure built once (set-up) and, per view, the
  rays a user would build: from each point in the frustum towards the eye, starting
  ``--offset`` object units off the point (meshes are normalised to extent 1), occluded iff
  anything is hit before the eye;
* with ``--gpu-methods``: ``zbuffer-exact`` and ``zbuffer`` kept scenes (OpenGL).

The load averages (``uptime``) are printed before and after; a run that starts with more load
than CPUs is refused (exit 3) unless ``--force``, and then flagged in the output.

Usage::

    .venv/bin/python benchmarks/bench_visibility_peers.py                 # 100k and 1M, 15 poses
    .venv/bin/python benchmarks/bench_visibility_peers.py --points 100000 --only one-shot,Open3D --repeats 4
    .venv/bin/python benchmarks/bench_visibility_peers.py --smoke         # a few seconds
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sofa_mesh import default_mesh  # noqa: E402

REPO_ROOT = Path(__file__).resolve().parents[1]
WARMUP_POSE = (-40.0, 10.0)

try:  # NVIDIA Warp: the kernel is defined at import (Warp compiles module-level kernels)
    with contextlib.redirect_stdout(io.StringIO()):
        import warp as wp

        wp.config.quiet = True
        wp.init()  # prints its banner here, not in the middle of a table

    @wp.kernel
    def _warp_occluded(
        mesh: wp.uint64, points: wp.array(dtype=wp.vec3), eye: wp.vec3, offset: float, out: wp.array(dtype=wp.int32)
    ):  # pragma: no cover - compiled by Warp
        i = wp.tid()
        p = points[i]
        d = eye - p
        dist = wp.length(d)
        dn = d / dist
        q = wp.mesh_query_ray(mesh, p + dn * offset, dn, dist - offset)
        out[i] = wp.where(q.result, 1, 0)
except Exception:  # noqa: BLE001 - not installed, or no usable device
    wp = None


def cores() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def _rays_towards_eye(points, cam, offset):
    """Per frustum point: origin ``offset`` off the point towards the eye, unit direction,
    length to the eye (float64)."""
    d = cam.eye - points
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    u = d / dist[:, None]
    return points + offset * u, u, dist - offset


def methods(mesh, points, fi, args) -> dict:
    """name -> (setup() -> state, view(state, camera) -> visible (N,) bool)."""
    import zbuf_occlude as zo
    from zbuf_occlude.visibility.auto import choose_method
    from zbuf_occlude.visibility.embree_fast import FastScene

    off = args.offset
    out = {
        f"`zo.visible_mask` one-shot (auto = {choose_method(one_shot=True)})": (
            lambda: None,
            lambda s, c: zo.visible_mask(mesh, points, c, face_index=fi),
        ),
        f"`VisibilitySession` once (auto = {choose_method()}), `session.visible` per view": (
            lambda: zo.VisibilitySession(mesh, points, fi),
            lambda s, c: s.visible(c),
        ),
        "embree-fast one-shot, rays only (no z-buffer pre-pass)": (
            lambda: None,
            lambda s, c: FastScene(mesh, points, fi, sort=False, prepass=False).visible(c),
        ),
    }
    if args.gpu_methods:
        from zbuf_occlude.visibility.gpu_exact import ExactScene

        out["`zbuffer-exact` kept scene (OpenGL)"] = (lambda: ExactScene(mesh, points, fi), lambda s, c: s.visible(c))
        out["`zbuffer` kept scene (OpenGL)"] = (lambda: zo.VisibilitySession(mesh, points, fi, method="zbuffer"), lambda s, c: s.visible(c))
    try:
        from zbuf_occlude.visibility.peers import import_open3d

        o3d = import_open3d()

        def o3d_setup():
            scene = o3d.t.geometry.RaycastingScene()
            scene.add_triangles(
                o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)), o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32))
            )
            return scene

        def o3d_occlusions(scene, cam):
            inside = cam.in_frustum(points)
            org, u, length = _rays_towards_eye(points[inside], cam, off)
            rays = np.hstack([org, u * length[:, None]]).astype(np.float32)  # t in [0, 1]: to the eye
            inside[inside] = ~scene.test_occlusions(o3d.core.Tensor(rays), tnear=0.0, tfar=1.0).numpy().astype(bool)
            return inside

        def o3d_cast(scene, cam):
            inside = cam.in_frustum(points)
            org, u, length = _rays_towards_eye(points[inside], cam, off)
            hit = scene.cast_rays(o3d.core.Tensor(np.hstack([org, u]).astype(np.float32)))["t_hit"].numpy()
            inside[inside] = ~(hit < length)
            return inside

        out["Open3D `RaycastingScene.test_occlusions`"] = (o3d_setup, o3d_occlusions)
        out["Open3D `RaycastingScene.cast_rays`"] = (o3d_setup, o3d_cast)
    except Exception as exc:  # noqa: BLE001
        print(f"(Open3D not measured: {exc})", file=sys.stderr)
    if wp is not None:
        # (Warp's CPU path runs one thread: skipped above --warp-cpu-max-points)
        devices = (["cpu"] if len(points) <= args.warp_cpu_max_points else []) + (["cuda:0"] if wp.is_cuda_available() else [])
        for device in devices:

            def warp_setup(device=device):
                with contextlib.redirect_stdout(io.StringIO()):
                    m = wp.Mesh(
                        points=wp.array(np.asarray(mesh.vertices, dtype=np.float32), dtype=wp.vec3, device=device),
                        indices=wp.array(np.asarray(mesh.faces, dtype=np.int32).ravel(), dtype=wp.int32, device=device),
                    )
                return m

            def warp_view(m, cam, device=device):
                inside = cam.in_frustum(points)
                pts = wp.array(points[inside].astype(np.float32), dtype=wp.vec3, device=device)
                hit = wp.zeros(len(pts), dtype=wp.int32, device=device)
                with contextlib.redirect_stdout(io.StringIO()):
                    wp.launch(
                        _warp_occluded, dim=len(pts), inputs=[m.id, pts, wp.vec3(*cam.eye.astype(np.float32)), off, hit], device=device
                    )
                inside[inside] = hit.numpy() == 0
                return inside

            out[f"Warp `mesh_query_ray` ({device})"] = (warp_setup, warp_view)
    try:
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        def trimesh_setup():
            inter = RayMeshIntersector(mesh)
            inter.intersects_any(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]))  # builds the BVH
            return inter

        def trimesh_view(inter, cam):
            inside = cam.in_frustum(points)
            org, u, _ = _rays_towards_eye(points[inside], cam, off)
            inside[inside] = ~inter.intersects_any(org, u)  # the eye is outside the mesh: nothing beyond it
            return inside

        out["trimesh `RayMeshIntersector.intersects_any`"] = (trimesh_setup, trimesh_view)
    except Exception as exc:  # noqa: BLE001
        print(f"(trimesh + Embree not measured: {exc})", file=sys.stderr)
    if args.only:
        keep = [w.strip().lower() for w in args.only.split(",") if w.strip()]
        out = {name: m for name, m in out.items() if any(w in name.lower() for w in keep)}
    return out


def run(mesh, n_points: int, poses, args) -> list[dict]:
    import zbuf_occlude as zo

    points, fi = zo.sample_surface(mesh, n_points, seed=0)
    table = methods(mesh, points, fi, args)
    warm = zo.camera_on_sphere(*WARMUP_POSE)
    zo.visible_mask(mesh, points[:1000], warm, "oracle", face_index=fi[:1000])  # per-mesh caches
    rows, state = {}, {}
    for name, (setup, view) in table.items():
        t, c = time.perf_counter(), time.process_time()
        state[name] = setup()
        rows[name] = {
            "method": name,
            "setup_ms": 1e3 * (time.perf_counter() - t),
            "setup_cpu_ms": 1e3 * (time.process_time() - c),
            "wall": [],
            "cpu": [],
            "agree": 0,
            "fv": 0,
            "fh": 0,
            "n": 0,
        }
        view(state[name], warm)  # JIT, kernels, first-touch
    oracle = {"wall": [], "cpu": []}
    names = list(table)
    with_truth = n_points <= args.oracle_max_points
    for k, (el, az) in enumerate(list(poses) * args.repeats):
        cam = zo.camera_on_sphere(el, az)
        truth = None
        if with_truth:
            t, c = time.perf_counter(), time.process_time()
            truth = zo.visible_mask(mesh, points, cam, "oracle", face_index=fi)
            oracle["wall"].append(time.perf_counter() - t)
            oracle["cpu"].append(time.process_time() - c)
        for name in names[k % len(names) :] + names[: k % len(names)]:  # rotate the order
            t, c = time.perf_counter(), time.process_time()
            got = table[name][1](state[name], cam)
            r = rows[name]
            r["wall"].append(time.perf_counter() - t)
            r["cpu"].append(time.process_time() - c)
            if truth is not None:
                r["agree"] += int((got == truth).sum())
                r["fv"] += int((got & ~truth).sum())
                r["fh"] += int((~got & truth).sum())
                r["n"] += len(points)
    for s in state.values():
        if hasattr(s, "release"):
            s.release()
    out = list(rows.values())
    if with_truth:
        out.append(
            {
                "method": "the project's exact `oracle` (truth)",
                "setup_ms": None,
                "wall": oracle["wall"],
                "cpu": oracle["cpu"],
                "agree": 1,
                "fv": 0,
                "fh": 0,
                "n": 1,
            }
        )
    return out


def _fmt_rate(r, key):
    return "—" if not r["n"] else f"{r[key] / r['n']:.4%}"


PEERS = ("Open3D", "Warp", "trimesh")


def _is_peer(row: dict) -> bool:
    return any(p in row["method"] for p in PEERS)


def report(rows, n_points, desc) -> list[str]:
    lines = [
        f"### {n_points:,} points, {desc}",
        "",
        "| method | set-up ms | wall ms / view | CPU ms / view | agreement | false-visible | false-hidden |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        setup = "—" if r["setup_ms"] is None else f"{r['setup_ms']:.0f}"
        lines.append(
            f"| {r['method']} | {setup} | {1e3 * statistics.median(r['wall']):.1f} | {1e3 * statistics.median(r['cpu']):.1f} "
            f"| {_fmt_rate(r, 'agree')} | {_fmt_rate(r, 'fv')} | {_fmt_rate(r, 'fh')} |"
        )
    return lines + [""] + against_fastest_peer(rows)


def against_fastest_peer(rows) -> list[str]:
    """Each of our rows beside the fastest peer call of the same run: medians, their ratio and the
    per-view ratios (peer / ours: above 1, ours is faster)."""
    peers = [r for r in rows if _is_peer(r)]
    ours = [r for r in rows if not _is_peer(r) and r["setup_ms"] is not None]
    if not peers or not ours:
        return []
    fastest = min(peers, key=lambda r: statistics.median(r["wall"]))
    peer_ms = 1e3 * statistics.median(fastest["wall"])
    lines = [
        f"Against the fastest peer call, {fastest['method']} ({peer_ms:.1f} ms per view), same run, "
        "interleaved view by view (speed-up = its time / ours):",
        "",
        "| ours | ours, ms / view | fastest peer, ms / view | speed-up (medians) | per-view speed-up: median (range) |",
        "|---|---:|---:|---:|---:|",
    ]
    for o in ours:
        per = [p / q for p, q in zip(fastest["wall"], o["wall"])]
        ours_ms = 1e3 * statistics.median(o["wall"])
        lines.append(
            f"| {o['method']} | {ours_ms:.1f} | {peer_ms:.1f} | **{peer_ms / ours_ms:.2f}×** "
            f"| {statistics.median(per):.2f}× ({min(per):.2f}–{max(per):.2f}) |"
        )
    others = sorted((r for r in peers if r is not fastest), key=lambda r: statistics.median(r["wall"]))
    if others:
        lines += [
            "",
            "Other peer calls, time per view relative to the fastest: "
            + "; ".join(f"{r['method']} {statistics.median(r['wall']) / statistics.median(fastest['wall']):.2f}×" for r in others)
            + ".",
        ]
    return lines + [""]


def _uptime() -> str:
    """``uptime``'s line (the time, and the load averages over 1, 5 and 15 min), or "no uptime"."""
    try:
        line = subprocess.run(["uptime"], capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        line = ""
    return line or "no uptime"


def _versions() -> str:
    out = []
    for mod in ("numpy", "numba", "embreex", "trimesh", "open3d"):
        try:
            out.append(f"{mod} {__import__(mod).__version__}")
        except Exception:  # noqa: BLE001
            pass
    if wp is not None:
        out.append(f"warp {wp.__version__}")
    try:
        commit = subprocess.run(
            ["git", "-C", str(REPO_ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
    except Exception:  # noqa: BLE001
        commit = ""
    return ", ".join(out) + (f"; commit {commit}" if commit else "")


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, default=None, help="default: sofa_0001 of ../shared, else a shipped sofa")
    ap.add_argument("--points", default="100000,1000000", help="comma-separated point counts")
    ap.add_argument("--poses", default="fibonacci:15", help="a view schedule (zbuf_occlude.view_schedule)")
    ap.add_argument("--offset", type=float, default=1e-4, help="the peers' ray start offset, object units")
    ap.add_argument("--gpu-methods", action="store_true", help="also zbuffer-exact and zbuffer (OpenGL)")
    ap.add_argument("--oracle-max-points", type=int, default=2_000_000, help="no agreement above this")
    ap.add_argument("--warp-cpu-max-points", type=int, default=2_000_000, help="no Warp CPU row above this")
    ap.add_argument("--repeats", type=int, default=1, help="times over the poses (each view interleaved)")
    ap.add_argument("--only", default="", help="comma-separated parts of the row names to time (e.g. one-shot,Open3D)")
    ap.add_argument("--force", action="store_true", help="run (flagged) even when the load average exceeds the CPUs")
    ap.add_argument("--smoke", action="store_true", help="tiny sizes (2,000 points, 3 poses), any load")
    args = ap.parse_args(argv)
    if args.smoke:
        args.points, args.poses, args.force = "2000", "fibonacci:3", True
    try:
        counts = [int(x) for x in args.points.split(",")]
        if min(counts) < 1:
            raise ValueError
    except ValueError:
        print(f"bench_visibility_peers: error: --points {args.points!r}: use positive integers, e.g. 100000,1000000", file=sys.stderr)
        return 2
    if args.repeats < 1:
        print(f"bench_visibility_peers: error: --repeats {args.repeats}: use a positive integer", file=sys.stderr)
        return 2
    import zbuf_occlude as zo

    poses = zo.view_schedule(args.poses)
    path = args.mesh or default_mesh()
    mesh = zo.load_mesh(path)
    load_before, n_cpu = os.getloadavg(), cores()
    loaded = load_before[0] > n_cpu
    if loaded and not args.force:
        print(
            f"bench_visibility_peers: load average {load_before[0]:.2f} exceeds the {n_cpu} CPUs: timings would be "
            "noise. Wait for a quiet machine, or pass --force (the output is then flagged).",
            file=sys.stderr,
        )
        return 3
    lines = [
        f"## Visibility peers: {path.name}, {len(poses)} poses ({args.poses}) × {args.repeats}, one run"
        + (" — ⚠ LOADED MACHINE, timings unreliable" if loaded else ""),
        "",
        f"Machine: {_cpu_model()}, {n_cpu} CPUs, {platform.node()}; {_versions()}.",
        f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`",
        "",
        f"Load average (1, 5, 15 min) before: {', '.join(f'{x:.2f}' for x in load_before)} (`{_uptime()}`).",
        "",
    ]
    print("\n".join(lines), flush=True)
    for n in counts:
        rows = run(mesh, n, poses, args)
        print("\n".join(report(rows, n, f"{len(mesh.faces):,} faces, median of {len(poses) * args.repeats} views")), flush=True)
    load_after = os.getloadavg()
    flag = (
        " ⚠ load above the CPU count: absolute timings unreliable (the per-view ratios less so)"
        if max(load_before[0], load_after[0]) > n_cpu
        else ""
    )
    print(f"Load average (1, 5, 15 min) after: {', '.join(f'{x:.2f}' for x in load_after)} (`{_uptime()}`).{flag}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
