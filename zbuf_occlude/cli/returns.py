"""``zbuf-occlude experiment returns``: the argparse face of :func:`~zbuf_occlude.experiments.returns_report.run_returns`."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from zbuf_occlude.cli.options import Checked, count, out_folder, real, resamples

__all__ = ["add_returns_parser"]


def _run(args: argparse.Namespace) -> int:
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.experiments.returns_report import ReturnsSettings, run_returns

    if (args.meshes is None) != (args.plot == "families"):
        raise InvalidInputError(
            "--plot families draws its own trees: give no MESHES" if args.meshes else "give MESHES (or --plot families)"
        )
    if args.plot == "families" and args.leaf_area_density is not None:
        raise InvalidInputError("--leaf-area-density fills the street meshes' crowns; the families' crowns are leaf clusters already")
    detection = not args.without_threshold
    given = {"plot": args.plot}
    if args.echo_rule is not None:
        given["echo_rule"] = args.echo_rule
    if args.leaf_area_density is not None:
        given["leaf_area_density"] = args.leaf_area_density
    settings = ReturnsSettings(bootstrap=args.bootstrap, seeds=tuple(range(args.seeds)), detection=detection, **given)
    if args.quick:
        settings = ReturnsSettings(divergence_factors=(0.5, 1.0, 2.0, 4.0, 8.0), sweep_rays=(7,), k_values=(1, 7, 19), seeds=(0,), repeats=1,
                                   copies=1, bootstrap=args.bootstrap, detection=detection, **given)  # fmt: skip
    summary = run_returns(args.out, args.meshes, args.real, autzen_path=args.autzen, settings=settings, progress=not args.no_progress)
    fits = ", ".join(f"K {f['K']}: {f['divergence_mrad']:.3g} mrad" for f in summary["divergence_fits"])
    sys.stdout.write(f"{summary['table']}\nfitted divergence {fits}; recommended K {summary['recommended_k']}; "
                     f"{summary['seconds']:.0f} s -> {args.out}\n")  # fmt: skip
    return 0


def add_returns_parser(sub: Any) -> argparse.ArgumentParser:
    """Add ``returns`` to ``experiment``'s argparse subparsers."""
    from zbuf_occlude.sensors.beam.echoes import ECHO_RULES

    p = sub.add_parser(
        "returns", help="simulate an airborne scanner over tree meshes and measure its returns per pulse as a real LAS/LAZ file's",
        description="Scan a plot of tree and bush meshes with the IGN LiDAR HD scanner's settings and several returns per pulse, "
        "write it as LAS, read it back and measure it with the function that measures --real; fit the beam divergence by "
        "simulation, choose the sub-ray count, and write the comparison with PASS/FAIL per target, the sweeps and a figure.",
    )  # fmt: skip
    p.add_argument("meshes", nargs="?", help="folder of the tree and bush meshes (street_objects/bush: the files of PLOT_TREES); "
                   "none with --plot families")  # fmt: skip
    p.add_argument("--plot", choices=("street", "families"), default="street",
                   help="the plot's vegetation: street (the meshes of MESHES, crowns filled with leaves) or families (six procedural "
                   "trees and two shrubs, zbuf-occlude families tree and shrub with seed 0, at their drawn sizes) (default: %(default)s)")  # fmt: skip
    p.add_argument("--real", required=True, help="the real LAS/LAZ file with vegetation classes 3-5 (the IGN LiDAR HD sample)")
    p.add_argument("--autzen", help="a second real LAS/LAZ file for the cross-check (its class 1 classed by height above its ground)")
    p.add_argument("--out", required=True, action=Checked, check=out_folder,
                   help="output folder (real.md, divergence_sweep.csv, k_sweep.csv, comparison.csv/.md, returns.png, run.json)")  # fmt: skip
    p.add_argument("--bootstrap", action=Checked, check=resamples, default=200, help="bootstrap resamples (default: %(default)s)")
    p.add_argument("--seeds", action=Checked, check=count(None), default=2, help="scans pooled per setting (default: %(default)s)")
    p.add_argument("--without-threshold", action="store_true",
                   help="no detection threshold and every surface alike (every echo returns), instead of the threshold fitted to --real "
                   "with the ground at the fit's reflectance and the meshes at their material's at 1064 nm")  # fmt: skip
    p.add_argument("--echo-rule", choices=ECHO_RULES, default=None,
                   help="how the simulated receiver merges a pulse's sub-ray hits into echoes: chain (a new echo at a gap of the range "
                   "resolution) or waveform (one echo per peak of the pulse's waveform) (default: the experiment's, waveform)")  # fmt: skip
    p.add_argument("--leaf-area-density", action=Checked, check=real(0.0, unit="m²/m³"), default=None,
                   help="leaves filling the crowns of the plot's trees, one-sided m² per m³ of crown; 0: the meshes as they are "
                   "(default: the experiment's, 1)")  # fmt: skip
    p.add_argument(
        "--quick",
        action="store_true",
        help="a small sweep (39 and 42 s with the IGN tile on 2 cores at load 1.3 to 1.7; longer on a busy machine, and on a "
        "first run while numba compiles): a check that the command runs, not the page's numbers",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar (or, when stderr is a file, no progress lines)")
    p.set_defaults(func=_run)
    return p
