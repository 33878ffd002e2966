#!/usr/bin/env python
"""Hand-written mutants of the GLSL shaders in ``zbuf_occlude/render/shaders/`` (mutmut cannot mutate GLSL).

Each mutant is one textual change to one shader.  For each, the package (its shaders
included) is copied to a temporary directory, the change is applied to the copy, and the
relevant tests run against the copy (``PYTHONPATH`` points at it, so
:func:`zbuf_occlude.render.shaders.shader_dir` is the copy's mutated folder; the
checkout is never modified).  A mutant is *killed* when a test fails, *survived* when all
pass, *error* when pytest could not run (e.g. collection failed) and *n/a* when the text
it changes is no longer in the shader (the shader was edited: update the mutant).

Usage (from anywhere; takes minutes per mutant on a loaded two-core machine)::

    python scripts/shader_mutants.py                 # every mutant, default tests
    python scripts/shader_mutants.py --list          # the mutants, not run
    python scripts/shader_mutants.py --only vert-depth-sign frag-raw-primitive-id
    python scripts/shader_mutants.py --tests tests/visibility/test_zbuffer.py -k "not real_modelnet"

Exit status: 0 if every applicable mutant was killed or is marked equivalent, 1 otherwise.
Outside CI (too slow); scores are recorded in docs/development/testing.md.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: The shaders' folder, relative to the repository root and to a copy's root.
SHADERS = Path("zbuf_occlude", "render", "shaders")
DEFAULT_TESTS = ["tests/visibility/test_zbuffer.py", "tests/render/test_moderngl_backend.py"]
# the real-mesh sweep needs ../shared and minutes; the wheel build needs no shader edits
DEFAULT_K = "not real_modelnet and not wheel"


@dataclass(frozen=True)
class Mutant:
    id: str
    shader: str
    old: str
    new: str
    why: str
    #: Why the mutant cannot change any result the project relies on (None: it can).
    equivalent: str | None = None


MUTANTS = [
    # -- common.glsl: reprojection, depth, the exact segment test, the bit masks ----------
    Mutant(
        "common-behind-camera",
        "common.glsl",
        "if (clip.w <= 0.0) return false;",
        "if (clip.w < -1.0) return false;",
        "points behind the camera pass the w test",
        equivalent="cameras stay outside the bounding sphere: no surface point has w <= 0",
    ),
    Mutant(
        "common-frustum-loose",
        "common.glsl",
        "greaterThanEqual(ndc, vec3(1.0))",
        "greaterThanEqual(ndc, vec3(1.5))",
        "the frustum's far/right/top clip planes widened",
    ),
    Mutant(
        "common-window-offset",
        "common.glsl",
        "(ndc.xy * 0.5 + 0.5)",
        "(ndc.xy * 0.5 + 0.25)",
        "projection to pixels shifted by a quarter image",
    ),
    Mutant(
        "common-linear-depth-w",
        "common.glsl",
        "dot(depth_row, vec4(p, 1.0))",
        "dot(depth_row, vec4(p, 0.0))",
        "linear depth loses the translation part",
    ),
    Mutant("common-tvec-sign", "common.glsl", "vec3 tvec = -a;", "vec3 tvec = a;", "Moller-Trumbore origin vector with the wrong sign"),
    Mutant(
        "common-u-bound",
        "common.glsl",
        "if (u < -edge_epsilon || u > 1.0 + edge_epsilon) return false;",
        "if (u < -edge_epsilon || u > 0.5) return false;",
        "barycentric u bound halved",
    ),
    Mutant(
        "common-uv-sum", "common.glsl", "u + v > 1.0 + edge_epsilon", "v > 1.0 + edge_epsilon", "the third edge (u + v <= 1) not tested"
    ),
    Mutant(
        "common-no-edge-widening",
        "common.glsl",
        "if (v < -edge_epsilon ||",
        "if (v < edge_epsilon ||",
        "barycentric v bound narrowed instead of widened (shared edges leak)",
    ),
    Mutant(
        "common-t-not-distance",
        "common.glsl",
        "return t * length(d) > tolerance && t <= 1.0;",
        "return t > tolerance && t <= 1.0;",
        "self-hit tolerance compared with t instead of the distance",
    ),
    Mutant(
        "common-no-tolerance",
        "common.glsl",
        "return t * length(d) > tolerance && t <= 1.0;",
        "return t > 0.0 && t <= 1.0;",
        "no self-hit tolerance: a point's own surface may hide it",
    ),
    Mutant(
        "common-beyond-eye",
        "common.glsl",
        "return t * length(d) > tolerance && t <= 1.0;",
        "return t * length(d) > tolerance;",
        "faces beyond the eye occlude",
        equivalent="cameras stay outside the bounding sphere: no face lies beyond the eye on a sight line",
    ),
    Mutant(
        "common-visible-bit",
        "common.glsl",
        "atomicOr(visible_bits[i >> 5], 1u << (i & 31u));",
        "atomicOr(visible_bits[i >> 5], 1u << (i & 15u));",
        "visible bit written to the wrong position",
    ),
    Mutant(
        "common-uncertain-offset",
        "common.glsl",
        "visible_bits[((n_points + 31u) >> 5) + (i >> 5)]",
        "visible_bits[(n_points >> 5) + (i >> 5)]",
        "uncertain words overlap the visible words",
    ),
    # -- mesh.vert / mesh.frag: the depth and face-index image ------------------------------
    Mutant("vert-depth-sign", "mesh.vert", "v_depth = -eye_position.z;", "v_depth = eye_position.z;", "linear depth with the wrong sign"),
    Mutant("vert-depth-scale", "mesh.vert", "v_depth = -eye_position.z;", "v_depth = -0.99 * eye_position.z;", "linear depth 1 % short"),
    Mutant(
        "frag-raw-primitive-id",
        "mesh.frag",
        "float(draw_face[gl_PrimitiveID])",
        "float(gl_PrimitiveID)",
        "face index of the draw order instead of the mesh's face row",
    ),
    Mutant(
        "frag-face-off-by-one",
        "mesh.frag",
        "float(draw_face[gl_PrimitiveID])",
        "float(draw_face[gl_PrimitiveID] + 1)",
        "face index off by one",
    ),
    # -- visibility_candidates.comp: the default "zbuffer" method ---------------------------
    Mutant(
        "cand-no-centre-test",
        "visibility_candidates.comp",
        "if (centre >= 0 && centre != own && segment_hits_face(p, centre, tolerance, edge_epsilon)) return;",
        "",
        "the centre pixel's face is never tested (it is marked tested)",
    ),
    Mutant(
        "cand-own-face-tested",
        "visibility_candidates.comp",
        "if (face < 0 || face == own) continue;",
        "if (face < 0) continue;",
        "the point's own face is tested as an occluder",
        equivalent="the tolerance rejects the own face (t * |d| ~ 0), so results do not change; only speed",
    ),
    Mutant(
        "cand-window-asymmetric",
        "visibility_candidates.comp",
        "for (int dy = -NEIGHBORHOOD; dy <= NEIGHBORHOOD; ++dy)",
        "for (int dy = -NEIGHBORHOOD; dy < NEIGHBORHOOD; ++dy)",
        "the window's last row is skipped",
    ),
    Mutant(
        "cand-no-window",
        "visibility_candidates.comp",
        "for (int dy = -NEIGHBORHOOD; dy <= NEIGHBORHOOD; ++dy)",
        "for (int dy = 1; dy <= 0; ++dy)",
        "only the centre pixel's face is tested",
    ),
    Mutant(
        "cand-no-uncertain",
        "visibility_candidates.comp",
        "if (own >= 0 && centre != own) mark_uncertain(i);",
        "",
        "points without evidence are never sent to the CPU",
    ),
    Mutant(
        "cand-uncertain-inverted",
        "visibility_candidates.comp",
        "if (own >= 0 && centre != own) mark_uncertain(i);",
        "if (own >= 0 && centre == own) mark_uncertain(i);",
        "the wrong points are sent to the CPU",
    ),
    # -- visibility_tolerance.comp: "zbuffer-tolerance" and "naive-zbuffer" ------------------
    Mutant(
        "tol-silhouette-hidden",
        "visibility_tolerance.comp",
        "if (texel.g < 0.0) { mark_visible(i); return; }",
        "if (texel.g < 0.0) { return; }",
        "points on the silhouette (background pixel) hidden",
    ),
    Mutant(
        "tol-no-allowance",
        "visibility_tolerance.comp",
        "if (point_depth <= texel.r + allowed) mark_visible(i);",
        "if (point_depth <= texel.r) mark_visible(i);",
        "no depth tolerance at all",
    ),
    Mutant(
        "tol-no-slope",
        "visibility_tolerance.comp",
        "slope_scale * (point_depth / focal_px) * slope",
        "slope_scale * (point_depth / focal_px)",
        "slope-scaled term ignores the slope",
    ),
    Mutant(
        "tol-back-faces",
        "visibility_tolerance.comp",
        "float c = abs(dot(n, normalize(eye - p)));",
        "float c = dot(n, normalize(eye - p));",
        "|cos| lost: back-facing normals give negative slopes",
    ),
]


def apply(mutant: Mutant, shader_dir: Path) -> bool:
    """Apply ``mutant`` to ``shader_dir``; False if its text is not (exactly once) there."""
    path = shader_dir / mutant.shader
    if not path.is_file():
        return False
    text = path.read_text(encoding="utf-8")
    if text.count(mutant.old) != 1:
        return False
    path.write_text(text.replace(mutant.old, mutant.new), encoding="utf-8")
    return True


def run_tests(copy: Path, tests: list[str], k: str | None, timeout: float) -> tuple[int, str]:
    env = {**os.environ, "PYTHONPATH": str(copy)}
    # Run from the copy (python -m puts the working directory first on sys.path), on the
    # checkout's tests by absolute path (they find data/samples beside themselves).
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "--rootdir", str(REPO)]
    cmd += [str(REPO / t) for t in tests] + (["-k", k] if k else [])
    try:
        out = subprocess.run(cmd, cwd=copy, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return 124, "timeout"
    lines = (out.stdout + out.stderr).strip().splitlines()
    return out.returncode, lines[-1] if lines else ""


def fresh_copy(root: Path) -> Path:
    if root.exists():
        shutil.rmtree(root)
    root.mkdir(parents=True)
    shutil.copytree(REPO / "zbuf_occlude", root / "zbuf_occlude", ignore=shutil.ignore_patterns("__pycache__"))
    (root / "pyproject.toml").write_text("")  # keeps pytest from taking the copy for a project root
    return root


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tests", nargs="+", default=DEFAULT_TESTS, help="test files (default: %(default)s)")
    parser.add_argument("-k", default=DEFAULT_K, help="pytest -k expression (default: %(default)r)")
    parser.add_argument("--only", nargs="+", metavar="ID", help="run only these mutants")
    parser.add_argument("--list", action="store_true", help="list the mutants and exit")
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per mutant's test run")
    args = parser.parse_args(argv)

    mutants = [m for m in MUTANTS if not args.only or m.id in args.only]
    if args.only and len(mutants) != len(set(args.only)):
        parser.error(f"unknown mutant ids: {sorted(set(args.only) - {m.id for m in MUTANTS})}")
    if args.list:
        for m in mutants:
            print(f"{m.id:26s} {m.shader:28s} {m.why}" + (f"  [equivalent: {m.equivalent}]" if m.equivalent else ""))
        return 0

    with tempfile.TemporaryDirectory(prefix="zbuf_shader_mutants_") as tmp:
        copy = Path(tmp) / "tree"
        fresh_copy(copy)
        probe = subprocess.run(
            [sys.executable, "-c", "from zbuf_occlude.render.shaders import shader_dir; print(shader_dir())"],
            env={**os.environ, "PYTHONPATH": str(copy)}, cwd=copy, capture_output=True, text=True,
        )  # fmt: skip
        if Path(probe.stdout.strip()) != copy / SHADERS:
            print(f"the copy's shaders are not the ones loaded: {probe.stdout.strip()!r} {probe.stderr[-500:]}", file=sys.stderr)
            return 2
        t0 = time.perf_counter()
        rc, tail = run_tests(copy, args.tests, args.k, args.timeout)
        print(f"{'baseline':26s} {'passed' if rc == 0 else 'FAILED':9s} {time.perf_counter() - t0:6.0f} s  {tail}", flush=True)
        if rc != 0:
            print("the unmutated shaders fail the tests: fix that first", file=sys.stderr)
            return 2
        results = {}
        for m in mutants:
            fresh_copy(copy)
            if not apply(m, copy / SHADERS):
                results[m.id] = "n/a"
                print(f"{m.id:26s} {'n/a':9s}        text not found once in {m.shader}", flush=True)
                continue
            t0 = time.perf_counter()
            rc, tail = run_tests(copy, args.tests, args.k, args.timeout)
            status = {0: "survived", 1: "killed", 124: "timeout"}.get(rc, "error")
            results[m.id] = status
            note = f"  [equivalent: {m.equivalent}]" if status == "survived" and m.equivalent else ""
            print(f"{m.id:26s} {status:9s} {time.perf_counter() - t0:6.0f} s  {tail}{note}", flush=True)

    applicable = [m for m in mutants if results[m.id] != "n/a"]
    killed = [m for m in applicable if results[m.id] in ("killed", "timeout", "error")]
    equivalent = [m for m in applicable if results[m.id] == "survived" and m.equivalent]
    survived = [m for m in applicable if results[m.id] == "survived" and not m.equivalent]
    scored = len(applicable) - len(equivalent)
    print(
        f"\nshader mutants: {len(killed)}/{len(applicable)} killed, {len(equivalent)} equivalent survivors, "
        f"{len(survived)} other survivors; score {100.0 * len(killed) / max(1, scored):.1f} % of non-equivalent"
    )
    for m in survived:
        print(f"  SURVIVED {m.id}: {m.shader}: {m.why}")
    return 0 if not survived else 1


if __name__ == "__main__":
    sys.exit(main())
