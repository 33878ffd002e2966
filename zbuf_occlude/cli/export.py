"""``zbuf-occlude export DATASET --to TARGET --out DIR``: the argparse face of :func:`zbuf_occlude.exporters.export`."""

from __future__ import annotations

import argparse

from zbuf_occlude.cli.options import Checked, counted, out_folder, seed
from zbuf_occlude.defaults import DEFAULT_SEED

__all__ = ["add_export_parser"]

#: The targets and label sets, named here so that ``--help`` needs no import of the writers.
TARGET_NAMES = ("pointnet-h5", "modelnet-txt", "pcn")
LABEL_SET_NAMES = ("own", "modelnet40", "modelnet10", "shapenet55")


def cmd_export(args: argparse.Namespace) -> int:
    """Export, then print the samples per split and the files a user opens first."""
    from zbuf_occlude.exporters import export

    result = export(args.dataset, args.to, args.out, label_set_name=args.label_set, seed=args.seed, list_prefix=args.list_prefix)
    per_split = ", ".join(f"{split} {counted(n, result.unit)}" for split, n in sorted(result.samples.items()))
    print(f"{result.target}: {per_split} -> {result.out}")
    for path in result.files:
        print(f"  {path}")
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
        "Streams the source; labels follow --label-set.",
    )
    p.add_argument("dataset", metavar="DATASET", help="a data set folder (--out of farm or generate; for --to pcn, of generate --protocol pcn)")
    p.add_argument("--to", required=True, choices=TARGET_NAMES, help="the layout to write")
    p.add_argument("--out", required=True, action=Checked, check=out_folder, help="the export's folder")
    p.add_argument("--label-set", default="own", choices=LABEL_SET_NAMES,
                   help="whose label ids: own (the data set's classes, default) or a pretrained network's set; "
                   "a class the set lacks is refused. pcn: own (ShapeNet's synset id for a ShapeNet class, else the "
                   "class name) or shapenet55 (synset ids only)")  # fmt: skip
    # default None: a target that does not shuffle refuses --seed when it is given
    p.add_argument("--seed", action=Checked, check=seed, default=None, help=f"pointnet-h5: the shuffle across files (default: {DEFAULT_SEED})")
    p.add_argument("--list-prefix", help="pointnet-h5: what each line of <split>_files.txt starts with (default: data/<--out's name>)")
    p.set_defaults(func=cmd_export)
