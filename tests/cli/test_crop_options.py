"""The crop options of ``scan`` and ``farm --sensor``: one table, both names in both commands, one path
to the library's settings, whose checks name the option as typed."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import pytest

from zbuf_occlude.cli.crops import CROP_OPTIONS, crop_settings
from zbuf_occlude.cli.farm import _sensor_params
from zbuf_occlude.cli.main import build_parser, main
from zbuf_occlude.cli.sensors import SCAN_CROP_DISTRIBUTIONS
from zbuf_occlude.farm.config import FarmParams

SUB = {name: p for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction) for name, p in a.choices.items()}

#: Every crop option with a value, as scan names it; farm's name is ``--sensor-`` and the same words.
VALUES = {
    "--distance": "6:9", "--height": "1.7", "--size": "2:3", "--reflectivity": "0.2:0.4", "--footprint": None,
    "--ground-margin": "0.3", "--hidden-below": "0.1:0.2", "--across-sight-width": "0.4:0.6", "--divergence": "0.25",
    "--min-returns": "12",
}  # fmt: skip


def _argv(prefix: str) -> list[str]:
    out = []
    for flag, value in VALUES.items():
        out += [flag.replace("--", prefix, 1)] + ([] if value is None else [value])
    return out


def test_the_table_is_every_option_of_both_commands() -> None:
    assert {f"--{o.name}" for o in CROP_OPTIONS} == set(VALUES)
    for command in ("scan", "farm"):
        options = SUB[command]._option_string_actions
        for flag in VALUES:
            assert options[flag] is options[flag.replace("--", "--sensor-", 1)], (command, flag)  # one option, two names


@pytest.mark.parametrize("command", ["scan", "farm"])
def test_both_names_give_the_same_settings(command: str) -> None:
    head = [command, "box" if command == "scan" else "meshes", "--out", "o"]
    short, long = (SUB[command].parse_args(head[1:] + _argv(p)) for p in ("--", "--sensor-"))
    base = SCAN_CROP_DISTRIBUTIONS
    a, b = crop_settings(short, base), crop_settings(long, base)
    assert a.distributions == b.distributions and (a.footprint, a.across_sight_width_m) == (b.footprint, b.across_sight_width_m)
    assert a.divergence_deg == b.divergence_deg == 0.25
    d = a.distributions
    assert (d.distance_m, d.height_m, d.size_m, d.reflectivity) == ((6.0, 9.0), (1.7, 1.7), (2.0, 3.0), (0.2, 0.4))
    assert (d.ground_margin_m, d.hidden_below_m, a.footprint, a.across_sight_width_m) == (0.3, (0.1, 0.2), True, (0.4, 0.6))
    assert d.min_returns == 12


def test_farm_records_the_same_data_set_under_either_name() -> None:
    parser = SUB["farm"]
    digests = set()
    for prefix in ("--", "--sensor-"):
        args = parser.parse_args(["meshes", "--out", "o", "--sensor", "hdl32e", *_argv(prefix)])
        digests.add(FarmParams(**_sensor_params(args)).digest())
    assert len(digests) == 1
    plain = parser.parse_args(["meshes", "--out", "o", "--sensor", "hdl32e"])
    # the defaults of farm --sensor, as before the table: the digest of data sets already made
    assert FarmParams(**_sensor_params(plain)).digest() == FarmParams(sensor="hdl32e").digest()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        # the width is checked by the library (sensors.placement.check_across_sight_width), naming the option typed
        (["scan", "box", "--crop", "--across-sight-width", "0:0"], "--across-sight-width must have HI > 0 metres"),
        (["scan", "box", "--crop", "--sensor-across-sight-width=-1:2"], "--sensor-across-sight-width must be >= 0 metres"),
        (["farm", "MESHES", "--sensor", "hdl32e", "--across-sight-width", "0:0"], "--across-sight-width must have HI > 0 metres"),
        (["scan", "box", "--sensor-size", "0:2"], "--sensor-size must be > 0 metres"),
        (["farm", "MESHES", "--sensor", "hdl32e", "--hidden-below=-1"], "--hidden-below must be >= 0 metres above the ground"),
        (["farm", "MESHES", "--distance", "5:9"], "--distance needs --sensor"),
        (
            ["scan", "box", "--sensor-hidden-below", "0.5"],
            "--sensor-hidden-below hides the bottom of the object in a crop: it needs --crop",
        ),
        (
            ["scan", "box", "--crop", "--occlude"],
            "--occlude meets --across-sight-width with a side occluder: it needs --across-sight-width",
        ),
    ],
)
def test_refusals_name_the_option_as_typed(argv: list[str], message: str, tmp_path: Path, capsys) -> None:
    meshes = Path(__file__).resolve().parents[2] / "data" / "samples" / "chair"
    argv = [str(meshes) if a == "MESHES" else a for a in argv]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not (tmp_path / "o").exists()


def test_scan_keeps_its_placement_defaults() -> None:
    args = SUB["scan"].parse_args(["box", "--out", "o"])
    d = crop_settings(args, SCAN_CROP_DISTRIBUTIONS).distributions
    assert (d.distance_m, d.height_m, d.size_m, d.azimuth_deg, d.yaw_deg) == ((10.0, 10.0), (1.8, 1.8), (4.5, 4.5), (0.0, 0.0), (0.0, 0.0))
    help_text = " ".join(SUB["scan"].format_help().split())
    assert re.search(r"--distance LO:HI, --sensor-distance LO:HI .*\(default: 10\)", help_text)
