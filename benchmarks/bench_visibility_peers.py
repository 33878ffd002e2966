"""The peer table of issue 11: our visibility methods beside the tools a user would pick instead.

One process, one mesh (default ModelNet10 ``sofa_0001``), for each point count (100k, 1M):
the methods run side by side on each pose (interleaved, so that a shared machine's load hits
them alike), after one warm-up pose.  Per method: set-up cost (building the per-point-set
scene), median wall ms per view, process CPU ms per view, agreement with the oracle pooled
over the poses, false-visible rate, and the fraction of points decided on the CPU.  Set-up
is timed with the mesh's own caches (Embree BVH, face planes, GPU buffers) already built,
as for the second point set of a mesh.

Methods: ``auto`` (the default; says which method it chose), ``zbuffer-exact``,
``embree-fast``, ``zbuffer`` (issue 3) and its GPU-only variant, trimesh + Embree
``intersects_any`` (rays from the point, offset 1e-5 towards the camera), mesh_to_sdf's rule
(``naive-zbuffer``: a strict depth test), the project's ``oracle``, and Open3D's
``RaycastingScene`` and ``hidden_point_removal`` when Open3D is installed.

Usage::

    .venv/bin/python benchmarks/bench_visibility.py --peers            # the same as:
    .venv/bin/python benchmarks/bench_visibility_peers.py --points 100000,1000000
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MESH = REPO_ROOT.parent / "shared" / "data" / "modelnet_subset" / "ModelNet10" / "sofa" / "train" / "sofa_0001.off"
DEFAULT_POSES = "-80:0,-40:72,0:144,40:216,80:288"
WARMUP_POSE = (-40.0, 0.0)


def _methods(mesh, points, fi, resolution):
    """name -> (setup() -> state, view(state, camera) -> (visible, cpu_fraction))."""
    import trimesh

    import zbuf_occlude as zo
    from zbuf_occlude.visibility import visible_mask
    from zbuf_occlude.visibility.auto import choose_method, make_scene
    from zbuf_occlude.visibility.embree_fast import FastScene
    from zbuf_occlude.visibility.gpu_exact import ExactScene
    from zbuf_occlude.visibility.zbuffer import Scene

    def frac(scene):
        return getattr(scene, "last_cpu_fraction", float("nan"))

    def trimesh_setup():
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        inter = RayMeshIntersector(mesh)
        inter.intersects_any(np.zeros((1, 3)), np.array([[1.0, 0.0, 0.0]]))  # builds the BVH
        return inter

    def trimesh_view(inter, cam):
        d = cam.eye - points
        u = d / np.linalg.norm(d, axis=1)[:, None]
        inside = cam.in_frustum(points)
        return inside & ~inter.intersects_any(points + 1e-5 * u, u), 0.0

    out = {
        f"auto (= {choose_method()})": (lambda: make_scene(mesh, points, fi), lambda s, c: (s.visible(c), frac(s))),
        f"zbuffer-exact {resolution}²": (
            lambda: ExactScene(mesh, points, fi),
            lambda s, c: (s.visible(c, resolution=resolution), frac(s)),
        ),
        "embree-fast": (lambda: FastScene(mesh, points, fi), lambda s, c: (s.visible(c), frac(s))),
        f"zbuffer (issue 3) {resolution}²": (
            lambda: Scene(mesh, points, fi),
            lambda s, c: (s.visible(c, resolution=resolution), float("nan")),
        ),
        f"zbuffer GPU-only {resolution}²": (
            lambda: Scene(mesh, points, fi),
            lambda s, c: (s.visible(c, resolution=resolution, resolve="none"), 0.0),
        ),
        "trimesh + Embree intersects_any": (trimesh_setup, trimesh_view),
        "mesh_to_sdf rule (strict depth test)": (
            lambda: None,
            lambda s, c: (visible_mask(mesh, points, c, "naive-zbuffer", face_index=fi, resolution=resolution), 0.0),
        ),
    }
    try:
        import open3d  # noqa: F401

        out["Open3D RaycastingScene"] = (
            lambda: None,
            lambda s, c: (visible_mask(mesh, points, c, "open3d-raycast", face_index=fi), 0.0),
        )
        out["Open3D hidden_point_removal"] = (
            lambda: None,
            lambda s, c: (visible_mask(mesh, points, c, "open3d-hpr", face_index=fi), 0.0),
        )
    except Exception:  # noqa: BLE001 - not installed (or its wheel lacks a system library)
        pass
    del trimesh, zo
    return out


def run(mesh_path: Path, n_points: int, poses, resolution: int) -> tuple[list[dict], str]:
    import zbuf_occlude as zo
    from zbuf_occlude.visibility import visible_mask

    mesh = zo.load_mesh(mesh_path)
    points, fi = zo.sample_surface(mesh, n_points, seed=0)
    methods = _methods(mesh, points, fi, resolution)
    warm = zo.camera_on_sphere(*WARMUP_POSE, resolution=resolution)
    visible_mask(mesh, points[:1000], warm, "oracle", face_index=fi[:1000])  # oracle's BVH
    state, rows = {}, {}
    for name, (setup, _) in methods.items():  # per-mesh caches (BVH, planes, GPU buffers)
        scene = setup()
        if hasattr(scene, "release"):
            scene.release()
    for name, (setup, view) in methods.items():
        t = time.perf_counter()
        state[name] = setup()
        setup_s = time.perf_counter() - t
        view(state[name], warm)  # warm-up: JIT, shaders, BVH, targets
        rows[name] = {"method": name, "setup_ms": 1e3 * setup_s, "wall": [], "cpu": [], "agree": 0, "fv": 0, "n": 0, "cpu_frac": []}
    oracle = {"wall": [], "cpu": []}
    for el, az in poses:
        cam = zo.camera_on_sphere(el, az, resolution=resolution)
        t, c = time.perf_counter(), time.process_time()
        truth = visible_mask(mesh, points, cam, "oracle", face_index=fi)
        oracle["wall"].append(time.perf_counter() - t)
        oracle["cpu"].append(time.process_time() - c)
        for name, (_, view) in methods.items():
            t, c = time.perf_counter(), time.process_time()
            got, frac = view(state[name], cam)
            r = rows[name]
            r["wall"].append(time.perf_counter() - t)
            r["cpu"].append(time.process_time() - c)
            r["agree"] += int((got == truth).sum())
            r["fv"] += int((got & ~truth).sum())
            r["n"] += len(points)
            r["cpu_frac"].append(frac)
    out = []
    for r in rows.values():
        out.append({
            "method": r["method"], "setup_ms": r["setup_ms"],
            "ms": 1e3 * statistics.median(r["wall"]), "cpu_ms": 1e3 * statistics.median(r["cpu"]),
            "agreement": r["agree"] / r["n"], "false_visible": r["fv"] / r["n"],
            "cpu_fraction": float(np.nanmean(r["cpu_frac"])) if not all(np.isnan(r["cpu_frac"])) else None,
            "walls": r["wall"],
        })
    out.append({"method": "project oracle (truth)", "setup_ms": None, "ms": 1e3 * statistics.median(oracle["wall"]),
                "cpu_ms": 1e3 * statistics.median(oracle["cpu"]), "agreement": 1.0, "false_visible": 0.0, "cpu_fraction": 1.0,
                "walls": oracle["wall"]})
    return out, f"{len(mesh.faces):,} faces"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, default=DEFAULT_MESH)
    ap.add_argument("--points", default="100000,1000000")
    ap.add_argument("--poses", default=DEFAULT_POSES)
    ap.add_argument("--resolution", type=int, default=1024)
    args = ap.parse_args(argv)
    import zbuf_occlude as zo
    from zbuf_occlude.render.context import shared_context

    poses = zo.view_schedule(args.poses)
    try:
        renderer = shared_context().info["GL_RENDERER"]
    except Exception as exc:  # noqa: BLE001
        renderer = f"none ({exc})"
    print(f"# Visibility peers: {args.mesh.name}, {len(poses)} poses ({args.poses}), one run\n")
    print(f"Machine: {platform.node()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at start; "
          f"OpenGL renderer: {renderer}. Wall times on a shared machine are noisy: compare within a row group "
          "(the methods ran interleaved, pose by pose); CPU ms is the process's CPU time (all threads).\n")
    for n in (int(x) for x in args.points.split(",")):
        rows, desc = run(args.mesh, n, poses, args.resolution)
        auto = next(r for r in rows if r["method"].startswith("auto"))
        peer = next(r for r in rows if r["method"].startswith("trimesh"))
        ratios = [p / a for p, a in zip(peer["walls"], auto["walls"])]
        print(f"## {n:,} points, {desc}\n")
        print("| method | set-up ms | ms / view | CPU ms / view | agreement | false-visible | CPU-settled |")
        print("|---|---:|---:|---:|---:|---:|---:|")
        for r in rows:
            setup = "—" if r["setup_ms"] is None else f"{r['setup_ms']:.0f}"
            cpu = "—" if r["cpu_fraction"] is None or np.isnan(r["cpu_fraction"]) else f"{r['cpu_fraction']:.3%}"
            print(f"| {r['method']} | {setup} | {r['ms']:.0f} | {r['cpu_ms']:.0f} | {r['agreement']:.4%} | {r['false_visible']:.4%} | {cpu} |")
        print(f"\nauto vs trimesh intersects_any: {peer['ms'] / auto['ms']:.2f}× faster (median wall), per-pose ratios "
              f"{', '.join(f'{x:.2f}' for x in ratios)}; CPU time {peer['cpu_ms'] / auto['cpu_ms']:.2f}×.\n", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
