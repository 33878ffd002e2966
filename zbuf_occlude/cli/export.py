"""``zbuf-occlude export DATASET --to TARGET --out DIR``: the argparse face of :func:`zbuf_occlude.exporters.export`.

The library's errors name its parameters as a call would (``label_set_name='modelnet10'``);
:func:`as_flags` names the flags instead (``--label-set modelnet10``).
"""

from __future__ import annotations

import argparse
import ast
import re

from zbuf_occlude.cli.options import Checked, counted, out_folder, seed
from zbuf_occlude.defaults import DEFAULT_SEED
from zbuf_occlude.errors import ZbufOccludeError

__all__ = ["FLAGS", "add_export_parser", "as_flags"]

#: The targets, label sets and up axes, named here so that ``--help`` needs no import of the writers.
TARGET_NAMES = ("pointnet-h5", "modelnet-txt", "pcn")
LABEL_SET_NAMES = ("own", "modelnet40", "modelnet10", "shapenet55")
UP_NAMES = ("+y", "+z", "-y", "+x", "-x", "-z")
#: ``export()``'s parameters and the flags (or the argument) that give them.
FLAGS = {"dataset": "DATASET", "to": "--to", "out": "--out", "label_set_name": "--label-set", "seed": "--seed",
         "list_prefix": "--list-prefix", "up": "--up"}  # fmt: skip

#: ``name=value`` in a message (value: a Python repr of a str, or a token).
_NAMED = re.compile(rf"(?<![\w./-])({'|'.join(FLAGS)})=('(?:[^'\\]|\\.)*'|\"(?:[^\"\\]|\\.)*\"|[^\s,;:()]+)")
#: A parameter named bare, where its name is no English word.
_BARE = re.compile(r"(?<![\w./-])(label_set_name|list_prefix)(?![\w=])")
#: A value that needs no quotes on a command line.
_PLAIN = re.compile(r"[\w.+/:@%-]+")


def as_flags(message: str) -> str:
    """``message`` with the library's parameters named as this command's flags.

    ``label_set_name='modelnet10'`` becomes ``--label-set modelnet10`` (a value that a shell would
    need quoted keeps its quotes), and a bare ``list_prefix`` becomes ``--list-prefix``.
    """

    def named(match: re.Match) -> str:
        value = match[2]
        if value[0] in "'\"":
            text = ast.literal_eval(value)
            value = text if _PLAIN.fullmatch(text) else value
        return f"{FLAGS[match[1]]} {value}"

    return _BARE.sub(lambda m: FLAGS[m[1]], _NAMED.sub(named, message))


def cmd_export(args: argparse.Namespace) -> int:
    """Export, then print the samples per split, the frame and the files a user opens first."""
    from zbuf_occlude.exporters import export
    from zbuf_occlude.io.owned import LEDGER_FILE

    try:
        result = export(args.dataset, args.to, args.out, label_set_name=args.label_set, seed=args.seed,
                        list_prefix=args.list_prefix, up=args.up, progress=not args.no_progress)  # fmt: skip
    except ZbufOccludeError as exc:
        raise type(exc)(as_flags(str(exc))) from None
    per_split = ", ".join(f"{split} {counted(n, result.unit)}" for split, n in sorted(result.samples.items()))
    print(f"{result.target}: {per_split} -> {result.out}")
    print(f"  frame: {result.frame}")
    for path in result.files:
        print(f"  {path}")
    print(f"  and {counted(result.data_files, 'data file')} (listed with their SHA-256 in {result.out / LEDGER_FILE})")
    return 0


def add_export_parser(sub: argparse._SubParsersAction) -> None:
    """``zbuf-occlude export``."""
    p = sub.add_parser(
        "export",
        help="write a data set in the layout a family of networks reads unchanged (PointNet's HDF5, ModelNet text, PCN)",
        description="Write a data set in the layout the field's training code reads as it is. From a data set of farm or "
        "generate (every storage and format): pointnet-h5 (PointNet, PointNet++ TF, DGCNN, PCT, PointMLP, CurveNet: "
        "name --out modelnet40_ply_hdf5_2048 for DGCNN) or modelnet-txt (Pointnet_Pointnet2_pytorch). From a "
        "`generate --protocol pcn` folder: pcn (PCN.json and .pcd files of PCN, PoinTr, SnowflakeNet, SeedFormer). "
        "Every target is written +y up, the frame these networks train in (their augmentation turns about y); "
        "--up chooses another. Streams the source; labels follow --label-set.",
    )
    p.add_argument(
        "dataset", metavar="DATASET", help="a data set folder (--out of farm or generate; for --to pcn, of generate --protocol pcn)"
    )
    p.add_argument("--to", required=True, choices=TARGET_NAMES, help="the layout to write")
    p.add_argument("--out", required=True, action=Checked, check=out_folder, help="the export's folder")
    p.add_argument("--label-set", default="own", choices=LABEL_SET_NAMES,
                   help="whose label ids: own (the data set's classes, default) or a pretrained network's set; "
                   "a class the set lacks is refused. pcn: own (ShapeNet's synset id for a ShapeNet class, else the "
                   "class name) or shapenet55 (synset ids only)")  # fmt: skip
    p.add_argument("--up", choices=UP_NAMES, default=None,
                   help="the axis that is up in the export (default: +y, the frame of every target's networks; "
                   "+z: the data set's own frame)")  # fmt: skip
    # default None: a target that does not shuffle refuses --seed when it is given
    p.add_argument(
        "--seed", action=Checked, check=seed, default=None, help=f"pointnet-h5: the shuffle across files (default: {DEFAULT_SEED})"
    )
    p.add_argument("--list-prefix", help="pointnet-h5: what each line of <split>_files.txt starts with (default: data/<--out's name>)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_export)
