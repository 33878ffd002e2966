"""The scan command of two commits, interleaved on the same settings: what a change to the scan's front end costs.

usage: python benchmarks/bench_scan_request.py --base REV [--runs N] [--cases NAME,...]

Exports commit ``REV`` (``git archive``) to a temporary folder and runs ``zbuf-occlude scan`` from it and from this
work tree in turn, A B A B ..., each run a fresh process in a fresh output folder (``PYTHONPATH`` chooses the tree; the
environment is this one).  Prints, per case, the median wall seconds of each tree over ``--runs`` pairs and the median of
the pairwise ratios this/base (pairing keeps a ratio steady while the machine's speed drifts), as a Markdown table.
The cases: a spinning LiDAR's scan of the shipped street scene, crops of the shipped chair with a footprint's echoes
resolved (the adaptive cast), and an airborne flight over the street.  Takes about 2 minutes on 2 cores with 5 runs.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from io import BytesIO
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASES = {
    "street_hdl32e": "{repo}/data/scenes/street.json --sensor hdl32e --samples 2",
    "chair_echoes": "{repo}/data/samples/chair/train/chair_0001.off --sensor hdl32e --footprint --divergence 0.3 --max-returns 3 "
    "--range-resolution 0.3 --samples 3 --crop --distance 5:10",
    "street_airborne": "{repo}/data/scenes/street.json --sensor riegl-q1560",
}


def _export(rev: str, into: Path) -> None:
    """Commit ``rev``'s tree under ``into``."""
    data = subprocess.run(["git", "-C", str(REPO), "archive", "--format=tar", rev], check=True, capture_output=True).stdout
    with tarfile.open(fileobj=BytesIO(data)) as tar:
        tar.extractall(into, filter="data")


def _run(tree: Path, args: str, out: Path) -> float:
    """Wall seconds of one scan command from ``tree`` (run from ``out``'s folder: the work tree is not on the path)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    cmd = [sys.executable, "-m", "zbuf_occlude.cli.main", "scan", *args.format(repo=REPO).split(), "--no-progress", "--out", str(out)]
    start = time.perf_counter()
    subprocess.run(cmd, cwd=out.parent, env=env, check=True, capture_output=True)
    return time.perf_counter() - start


def _package(tree: Path, cwd: Path) -> str:
    """Where the package a run from ``tree`` imports lies (the check that ``PYTHONPATH`` chooses the tree)."""
    code = "import zbuf_occlude; print(zbuf_occlude.__file__)"
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, check=True, capture_output=True, text=True).stdout.strip()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--base", required=True, help="the commit to compare with (the scan before the change)")
    p.add_argument("--runs", type=int, default=5, help="pairs of runs per case (default: %(default)s)")
    p.add_argument("--cases", default=",".join(CASES), help=f"comma-separated, of {', '.join(CASES)}")
    a = p.parse_args(argv)
    cases = [c for c in a.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        p.error(f"--cases: unknown {', '.join(unknown)}")
    with tempfile.TemporaryDirectory() as tmp:
        base = Path(tmp) / "base"
        _export(a.base, base)
        for tree in (REPO, base):
            if not _package(tree, Path(tmp)).startswith(str(tree)):
                raise SystemExit(f"the package is not imported from {tree}: check the environment")
        print(f"load average {os.getloadavg()[0]:.2f} at the start; {a.runs} pairs per case, this tree (A) against {a.base} (B)\n")
        print("| case | A median s | B median s | A/B median of pairs |\n|---|---|---|---|")
        for name in cases:
            _run(REPO, CASES[name], Path(tmp) / "warm")  # warm the caches (numba, the OS's files) for both trees
            _run(base, CASES[name], Path(tmp) / "warm_b")
            pairs = [(_run(REPO, CASES[name], Path(tmp) / f"a{i}"), _run(base, CASES[name], Path(tmp) / f"b{i}")) for i in range(a.runs)]
            ratio = statistics.median(x / y for x, y in pairs)
            print(f"| {name} | {statistics.median(x for x, _ in pairs):.2f} | {statistics.median(y for _, y in pairs):.2f} | {ratio:.3f} |")
        print(f"\nload average {os.getloadavg()[0]:.2f} at the end")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
