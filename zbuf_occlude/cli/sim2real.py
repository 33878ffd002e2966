"""``zbuf-occlude experiment sim2real MESH_ROOT --real PATH --model ... --out DIR``: the parser and its thin runner.

Added to ``experiment``'s subcommands by :mod:`zbuf_occlude.cli.learn`; torch is imported only
when the command runs.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from zbuf_occlude.cli.options import Checked, check_device, count, interval, out_folder, parse_interval, shown
from zbuf_occlude.cli.scan_request import returns_per_pulse
from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.caps import MAX_TABLE_BYTES
from zbuf_occlude.io.regular_files import read_text_file
from zbuf_occlude.mesh.formats import EXTENSIONS_TEXT
from zbuf_occlude.sensors.beam.adaptive_cast import FOOTPRINT_MODES
from zbuf_occlude.sensors.request import TRAINING_RETURNS

if TYPE_CHECKING:
    from zbuf_occlude.experiments.sim2real import Sim2RealConfig  # torch: imported when the command runs

__all__ = ["add_sim2real_parser", "parse_pairs", "parse_up_map", "sim2real_config", "THREADS_HELP"]

#: ``--threads``' help, the same for every training command (:mod:`zbuf_occlude.learn.reproducible`).
THREADS_HELP = (
    "torch CPU threads (default: 1, so that runs agree to the bit on every x86-64 CPU; a run reproduces with the same "
    "count; with ZBUF_OCCLUDE_NATIVE_CPU=1: torch's default and this CPU's own kernels)"
)


def parse_pairs(text: str | None, option: str) -> dict[str, str]:
    """``A=B,C=D`` → ``{"A": "B", "C": "D"}``; InvalidInputError naming ``option`` and the item."""
    out: dict[str, str] = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        if "=" not in item:
            raise InvalidInputError(f"{option} expects KEY=VALUE,..., got {item.strip()!r}")
        key, value = item.split("=", 1)
        out[key.strip()] = value.strip()
    return out


def parse_up_map(text: str | None) -> dict[str, str]:
    """``--up-map GLOB=AXIS,...`` → ``{glob: axis}``, each axis one of :data:`~zbuf_occlude.mesh.scene.UP_CHOICES`;
    InvalidInputError naming the option and the pairs that are not."""
    from zbuf_occlude.mesh.scene import UP_CHOICES

    up_map = parse_pairs(text, "--up-map")
    bad = {k: v for k, v in up_map.items() if v not in UP_CHOICES}
    if bad:
        raise InvalidInputError(f"--up-map: axis must be one of {', '.join(UP_CHOICES)}, got {bad}")
    return up_map


#: The flag of each :class:`~zbuf_occlude.experiments.sim2real.Sim2RealConfig` field, for its messages.
OPTION_NAMES = {
    "model": "--model", "sensor": "--sensor", "scale": "--scale", "points": "--points", "epochs": "--epochs",
    "per_class": "--per-class", "seeds": "--seeds", "keep_scale": "--keep-scale", "label_map": "--label-map", "up": "--up",
    "up_map": "--up-map", "sizes": "--sizes", "min_returns": "--min-returns", "method": "--method", "classes": "--classes",
    "occluded_elevation_deg": "--occluded-elevation", "fit_sensor": "--fit-sensor", "recipe": "--recipe",
    "validate_on": "--validate-on", "fitted_shape": "--fitted-shape", "aspect": "--augment aspect", "partial": "--augment partial", "best_epoch_by": "--best-epoch-by",
    "occluded_points": "--occluded-points", "returns": "--returns", "footprint_cast": "--footprint-cast",
    "fit_families": "--fit-families", "family_count": "--family-count", "family_heights": "--fit-family-heights", "sets": "--sets",
}  # fmt: skip


def _run(args: argparse.Namespace) -> int:
    # before anything imports torch: its CPU arithmetic is chosen at import (learn.reproducible)
    from zbuf_occlude.learn.reproducible import pin_cpu_arithmetic, training_threads

    pin_cpu_arithmetic()
    # the counts and --out were checked while parsing (cli.options); the device before any rendering
    check_device(args.device)
    from zbuf_occlude.experiments.sim2real import run_sim2real

    config = sim2real_config(args)
    summary = run_sim2real(
        config, args.out, device=args.device, threads=training_threads(args.threads), progress=not args.no_progress, say=_say
    )
    return print_table(args.out, summary)


def sim2real_config(args: argparse.Namespace) -> Sim2RealConfig:
    """The :class:`~zbuf_occlude.experiments.sim2real.Sim2RealConfig` of parsed ``experiment sim2real`` arguments
    (checked as the run checks it; its refusals name the options).

    Raises
    ------
    InvalidInputError
        A bad option or combination of options.
    """
    from zbuf_occlude.experiments.sim2real import Sim2RealConfig
    from zbuf_occlude.experiments.sim2real.config import FAMILY_COUNT
    from zbuf_occlude.mesh.sizes import parse_sizes

    up_map = parse_up_map(args.up_map)
    if args.family_count is not None and not args.fit_families:
        raise InvalidInputError(f"--family-count {args.family_count} adds objects of the fitted families: give --fit-families too")
    families = {"fit_families": True, "family_count": args.family_count or FAMILY_COUNT} if args.fit_families else {}
    families.update({"family_heights": True} if args.fit_family_heights else {})
    sets = () if args.sets is None else tuple(v.strip() for v in args.sets.split(",") if v.strip())
    if args.sets is not None and not sets:
        raise InvalidInputError(f"--sets must name one or more sets, got {shown(args.sets)}")
    real_options = {"dataset": args.real_format, "up": args.real_up, "units": args.real_units}
    return Sim2RealConfig(
        args.root, args.real, model=args.model, sensor=args.sensor, scale=args.scale, points=args.points, epochs=args.epochs,
        per_class=args.per_class, seeds=args.seeds, keep_scale=args.keep_scale, label_map=parse_pairs(args.label_map, "--label-map"),
        up=args.up, up_map=up_map, sizes=parse_sizes(args.sizes), real_options=real_options, min_returns=args.min_returns,
        method=args.method, classes=_classes_option(args.classes),
        occluded_elevation_deg=None if args.occluded_elevation is None else parse_interval(args.occluded_elevation, "--occluded-elevation"),
        fit_sensor=args.fit_sensor,
        recipe=args.recipe, best_epoch_by=args.best_epoch_by, validate_on=args.validate_on,
        fitted_shape=() if args.fitted_shape == "none" else tuple(v.strip() for v in args.fitted_shape.split(",")),
        aspect=args.augment == "aspect", partial=args.augment == "partial", occluded_points=args.occluded_points, returns=args.returns,
        footprint_cast=args.footprint_cast, sets=sets, **families, option_names=OPTION_NAMES,
    )  # fmt: skip


def _say(line: str) -> None:
    """A stage of the run, one line on stderr as it starts (reading, the fit: minutes on a large data set)."""
    print(f"sim2real: {line}", file=sys.stderr, flush=True)


def _classes_option(text: str | None) -> str | list[str] | None:
    if text is None or text.strip() == "real":
        return None if text is None else "real"
    names = [c.strip() for c in text.split(",") if c.strip()]
    if len(names) < 2:
        raise InvalidInputError(f"--classes needs 'real' or two or more class folders, got {text!r}")
    return names


def print_table(out: str, summary: dict[str, Any]) -> int:
    """Print an experiment's ``OUT/table.md`` (read inside ``OUT``, :func:`~zbuf_occlude.io.regular_files.read_text_file`)
    and its wall time; exit status 0."""
    table = f"{out}/table.md"
    sys.stdout.write(f"{table}\n{read_text_file(table, max_bytes=MAX_TABLE_BYTES, within=out)}")
    sys.stdout.write(f"wall time {summary['wall_s']['total']:.0f} s\n")
    return 0


def add_sim2real_parser(sub: Any) -> argparse.ArgumentParser:
    """Add ``sim2real`` to ``experiment``'s argparse subparsers."""
    from zbuf_occlude.experiments.sim2real import SIM2REAL_RECIPE, VALIDATION_CHOICES
    from zbuf_occlude.sensors.fit.class_placement import MIN_RETURNS
    from zbuf_occlude.mesh.scene import UP_CHOICES

    p = sub.add_parser(
        "sim2real", help="train only on clouds from meshes (complete / occluded / lidar / "
        "lidar+complete), test on real scans; several seeds, permutation tests",
        description="Make four training sets from the same meshes (complete, occluded, LiDAR crops, LiDAR + complete), "
        "train a classifier on each with validation on held-out whole meshes, then score each on a fixed held-out half "
        "of the real scans of --real (the half real->real is scored on; never used for training or settings) and on "
        "all of them, over several seeds, with chance and real->real rows.",
    )  # fmt: skip
    p.add_argument("root", help=f"mesh files ({EXTENSIONS_TEXT}) in CLASS/ folders")
    p.add_argument("--real", required=True, help="folder of real object scans (one folder per class, or labelled files)")
    p.add_argument(
        "--out",
        required=True,
        action=Checked,
        check=out_folder,
        help="output folder (settings.json, runs.jsonl, results.csv, summary.csv, table.md, run.json)",
    )
    p.add_argument("--model", choices=("pointnet", "voxnet", "3dmfv"), default="pointnet", help="classifier (default: %(default)s)")
    p.add_argument("--sensor", default="hdl32e", help="scanner of the lidar training set (a LiDAR preset; default %(default)s)")
    p.add_argument(
        "--fit-sensor",
        action="store_true",
        help="fit --sensor (a spinning LiDAR) to the fixed half of the real scans real->real trains on (written to "
        "OUT/fitted_sensor.json), and add training sets made with it ('fitted'; 'fitted+placed', also placed and "
        "sized as those scans; 'pooled', the three LiDAR sets in one)",
    )
    p.add_argument(
        "--validate-on",
        choices=VALIDATION_CHOICES,
        default="meshes",
        help="what the mesh-only sets validate on (best epoch, early stopping): clouds of held-out whole meshes, "
        "or, with --fit-sensor, the fit half's real scans (then every mesh trains; the scored half stays unseen) "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--fitted-shape",
        default="none",
        metavar="none|SHAPE[,outline]",
        help="with --fit-sensor, what the fitted+placed set changes in each mesh's shape to look like the fit "
        "half's scans: widths (a horizontal stretch to their widths across the line of sight), widen (the same, "
        "but never narrower than the mesh), occlude (a side occluder that leaves as much of it in view as they "
        "show, where the mesh shows wider), outline (a warp to their outline over the height), one of the "
        "first three with outline (widths,outline), or none (default: %(default)s)",
    )
    p.add_argument(
        "--recipe",
        choices=("stable", "plain"),
        default=SIM2REAL_RECIPE,
        help="training recipe: stable (class-balanced sampling, best epoch by the class-balanced validation loss, "
        "warm-up, gradient clipping) or plain (the models' own loop, best epoch by validation accuracy) (default: %(default)s)",
    )
    # checked by Sim2RealConfig against learn.training.SELECT_CHOICES (importing it here would import torch)
    p.add_argument(
        "--best-epoch-by",
        metavar="loss|mean_class_accuracy|accuracy",
        help="what every run's best epoch and early stopping go by on its validation set: loss (class-balanced "
        "cross-entropy, lower is better; it does not saturate when the validation set is classified without a "
        "mistake), mean_class_accuracy or accuracy (default: the recipe's)",
    )
    p.add_argument(
        "--augment",
        choices=("standard", "aspect", "partial"),
        default="standard",
        help="training augmentation of every run, not with --keep-scale: standard (rotation about z, scaling, jitter), aspect (also x, y, "
        "z stretched by factors in [2/3, 3/2]) or partial (also half the clouds cut up to 0.3 of their height from the bottom and "
        "thinned by up to 0.875) (default: %(default)s)",
    )
    p.add_argument(
        "--scale",
        choices=("quick", "paper"),
        default="quick",
        help="quick: 256 points, 100 clouds per class, 20 epochs (a 2-core CPU); paper: 1024, 1000, 100",
    )
    p.add_argument("--points", action=Checked, check=count("MAX_POINTS"), help="points per cloud (override the scale's)")
    p.add_argument("--epochs", action=Checked, check=count("MAX_EPOCHS"), help="epochs (override the scale's)")
    p.add_argument("--per-class", action=Checked, check=count("MAX_SAMPLES"), help="training clouds per class (override the scale's)")
    p.add_argument(
        "--seeds",
        action=Checked,
        check=count("MAX_REPETITIONS"),
        default=5,
        help="repetitions, each redrawing clouds and initialisation (default %(default)s)",
    )
    p.add_argument("--keep-scale", action="store_true", help="keep metres instead of normalising every cloud to max extent 1")
    p.add_argument("--label-map", help="real label to class folder, REAL=CLASS,... (e.g. Trunk=pole)")
    p.add_argument(
        "--classes",
        help="class folders to train on: 'real' (those the real scans have, after --label-map) "
        "or CLASS,CLASS,... (default: every class folder of ROOT)",
    )
    p.add_argument(
        "--occluded-elevation",
        metavar="LO:HI",
        action=Checked,
        check=interval,
        help="camera elevations of the occluded set, degrees, drawn uniformly (default: those --sensor sees objects "
        "from: a spinning LiDAR on the lidar set's mount, atan(height/distance) over heights 1.6-2 m and distances "
        "5-25 m, about 3.7:21.8; an airborne scanner, 90 minus its incidence angles up to half its swath, 61:90 "
        "for dales-q1560; settings.json records which; a negative LO needs =, as in --occluded-elevation=-5:30)",
    )
    p.add_argument(
        "--up", choices=UP_CHOICES, default="auto", help="up axis of the mesh files; auto: each format's convention (default: %(default)s)"
    )
    p.add_argument("--up-map", help="per-file up axis, GLOB=AXIS,... (globs of paths relative to ROOT)")
    p.add_argument("--sizes", help="real sizes per class, CLASS=length|height|max:LO-HI,... metres (over the defaults)")
    _add_real_scan_options(p)
    p.add_argument(
        "--min-returns",
        action=Checked,
        check=count("MAX_POINTS"),
        default=MIN_RETURNS,
        help="redraw LiDAR crops with fewer returns (default %(default)s; lower it for airborne or sparse sensors)",
    )
    p.add_argument("--method", default=DEFAULT_METHOD, help="HSR method of the occluded set (default: %(default)s)")
    p.add_argument(
        "--occluded-points",
        action="store_true",
        help="also train on 'occluded-points': the occluded set's clouds (the same dense samples and poses) with "
        "visibility decided from the points alone (point-splat, normals estimated, no mesh), tested against occluded",
    )
    p.add_argument(
        "--returns",
        metavar="WHICH",
        action=Checked,
        check=returns_per_pulse,
        default=TRAINING_RETURNS,
        help="what the lidar set keeps of each pulse's returns, as farm --sensor-returns: 1 or strongest (default) one, the "
        "footprint's strongest; first or last: the receiver's first or last echo; all: every return the device records; N: "
        "each pulse's footprint cast as sub-rays (the sensor's own, or 7, over its divergence) and its echoes resolved by its "
        "range resolution (or 0.75 m) into up to N (settings.json: lidar_returns; --fit-sensor: only what leaves it as it is)",
    )
    p.add_argument(
        "--footprint-cast", choices=FOOTPRINT_MODES, default="auto",
        help="how the lidar set's crops cast a footprint whose echoes are resolved (--returns above 1, or a sensor file with "
        "a return mode): adaptive casts a pulse's whole footprint only where its centre ray and its neighbours do not show one "
        "plane filling it (the same returns but for a surface inside the cone none of them meets, a fraction of the cost); "
        "exact casts every sub-ray; auto is adaptive where it applies, else exact (default: auto; settings.json: lidar_footprint)",
    )  # fmt: skip
    _add_family_options(p)
    p.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="torch device (default: %(default)s)")
    p.add_argument("--threads", action=Checked, check=count("MAX_WORKERS"), help=THREADS_HELP)
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_run)
    return p


def _add_family_options(p: argparse.ArgumentParser) -> None:
    """The options that add the fitted families to the meshes, and pick the sets to train."""
    p.add_argument(
        "--fit-families",
        action="store_true",
        help="fit the procedural families (zbuf-occlude families) of each class to the half of the real scans that "
        "real->real trains on (which families look like those crops, and how wide to draw them; written to "
        "OUT/fitted_families.json) and add --family-count objects of them per class to the meshes of every mesh-only set "
        "(settings.json: fit_families); a class no family writes to (car) keeps the meshes alone",
    )
    p.add_argument(
        "--fit-family-heights",
        action="store_true",
        help="with --fit-families, each class a family writes to (pole, bush, pedestrian) takes the heights of its crops in "
        "that half (10th-90th percentile of the top return above the ground) as its size, for its meshes and families "
        "in every mesh-only set, in place of --sizes (settings.json: fit_families.heights_m)",
    )
    p.add_argument(
        "--family-count",
        action=Checked,
        check=count("MAX_FAMILY_MESHES"),
        help="with --fit-families, family objects added per class (default: 8)",
    )
    p.add_argument(
        "--sets",
        metavar="SET,...",
        help="train only these mesh-only sets (of complete, occluded, lidar, lidar+complete; occluded-points with "
        "--occluded-points; fitted, fitted+placed, pooled with --fit-sensor); real->real always trains (default: every set)",
    )


def _add_real_scan_options(p: argparse.ArgumentParser) -> None:
    """The options of the reader of ``--real``: its format, up axis and units."""
    from zbuf_occlude.mesh.scene import UP_CHOICES

    p.add_argument(
        "--real-format",
        choices=("auto", "folder", "lidarnet", "suo"),
        default="auto",
        help="reader of --real: a folder of class folders (any point-cloud files), LiDARNet v2, Sydney Urban Objects; auto: detected (default: %(default)s)",
    )
    p.add_argument(
        "--real-up", choices=UP_CHOICES[1:], default="+z", help="up axis of the real scans' files (folder reader; default %(default)s)"
    )
    p.add_argument("--real-units", default="m", help="unit of the real scans' files: m, cm, mm, in, ft or metres per unit (folder reader)")
