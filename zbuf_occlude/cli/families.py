"""``zbuf-occlude families``: the argparse face of :func:`~zbuf_occlude.mesh.families.write_family`."""

from __future__ import annotations

import argparse
from typing import Any

from zbuf_occlude.cli.options import Checked, count, out_folder, seed
from zbuf_occlude.defaults import DEFAULT_SEED

__all__ = ["add_families_parser"]

#: Objects written when ``--count`` is not given.
DEFAULT_COUNT = 10


def _cli_families(args: argparse.Namespace) -> int:
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.mesh.families import write_family

    width_scale = None
    if args.fit is not None:
        from zbuf_occlude.mesh.families.fitted import read_families_fit

        fit = read_families_fit(args.fit)
        try:
            width_scale = fit.width_scale(args.family)
        except InvalidInputError as exc:
            raise InvalidInputError(f"--fit {args.fit}: {exc}") from None
    run = write_family(args.family, args.out, count=args.count, seed=args.seed, width_scale=width_scale)
    print(f"{len(run.files)} {args.family} meshes -> {run.files[0].parent} (parameters: {run.manifest})")
    return 0


def add_families_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``families`` subcommand to an argparse ``subparsers``; ``func`` returns an exit code."""
    from zbuf_occlude.mesh.families.registry import FAMILIES

    rows = "; ".join(f"{name} (class {f.class_name})" for name, f in FAMILIES.items())
    p = subparsers.add_parser(
        "families",
        help="write procedural trunks, shrubs, hedges, trees, utility poles, street lights, sign posts or pedestrians as meshes",
        description=(
            "Write --count seeded objects of one procedural family into --out/CLASS/FAMILY_K.ply (z up, metres, standing "
            "on z = 0) with CLASS/FAMILY.manifest.json listing each file's drawn parameters and the seed. The folder is "
            f"a mesh folder for farm, generate and experiment sim2real. Families: {rows}."
        ),
    )
    p.add_argument("family", metavar="FAMILY", choices=list(FAMILIES), help=f"one of: {', '.join(FAMILIES)}")
    p.add_argument(
        "--count", action=Checked, check=count("MAX_FAMILY_MESHES"), default=DEFAULT_COUNT, help="objects to write (default: %(default)s)"
    )
    p.add_argument(
        "--seed", action=Checked, check=seed, default=DEFAULT_SEED, help="object K draws from (seed, K, family) (default: %(default)s)"
    )
    p.add_argument(
        "--fit",
        metavar="FILE",
        help="a families fit (fitted_families.json, written by experiment sim2real --fit-families): draw FAMILY as the fit "
        "chose, each object stretched horizontally by a factor in the fit's width_scale range (default: the family's own widths)",
    )
    p.add_argument("--out", action=Checked, check=out_folder, required=True, help="the folder; its CLASS subfolder holds the files")
    p.set_defaults(func=_cli_families)
    return p
