"""The command line's help, and small usage fixes: every subcommand describes itself, every
option has help, shown defaults are the real ones; methods whose extra is missing are not
offered; progress bars stay out of non-terminal logs; the SLURM script renders every mesh."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from zbuf_occlude.cli.main import build_parser, main
from zbuf_occlude.defaults import (
    DEFAULT_DENSE_POINTS,
    DEFAULT_FARM_DENSE_POINTS,
    DEFAULT_FARM_RESOLUTION,
    DEFAULT_N_POINTS,
    DEFAULT_RESOLUTION,
    DEFAULT_SEED,
    DEFAULT_VIEWS,
)
from zbuf_occlude.farm.config import DEFAULT_VIEWS as FARM_VIEWS
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS

REPO_ROOT = Path(__file__).resolve().parents[2]
BOX = REPO_ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"


def subcommands(parser: argparse.ArgumentParser, prefix: str = "") -> Iterator[tuple[str, argparse.ArgumentParser]]:
    """``(name, parser)`` of every subcommand, nested ones (``experiment elevation``) included."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield f"{prefix}{name}", sub
                yield from subcommands(sub, f"{prefix}{name} ")


def shown_default(parser: argparse.ArgumentParser, action: argparse.Action) -> str | None:
    """The text after ``(default:`` in the option's help as printed, or None."""
    if not action.help:
        return None
    text = parser._get_formatter()._expand_help(action)
    m = re.search(r"\(default: ([^;)]*)", text)
    return m.group(1) if m else None


def _option(parser: argparse.ArgumentParser, flag: str) -> argparse.Action:
    return next(a for a in parser._actions if flag in a.option_strings)


SUBCOMMANDS = dict(subcommands(build_parser()))


@pytest.mark.parametrize("name", sorted(SUBCOMMANDS))
def test_every_subcommand_has_a_description_and_every_option_help(name: str) -> None:
    sub = SUBCOMMANDS[name]
    assert sub.description and len(sub.description) > 20, f"{name}: no description"
    for action in sub._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue  # an old spelling is hidden on purpose
        assert action.help and action.help != argparse.SUPPRESS, f"{name} {action.option_strings or action.dest}: no help"


@pytest.mark.parametrize("name", sorted(SUBCOMMANDS))
def test_shown_defaults_are_the_defaults(name: str) -> None:
    sub = SUBCOMMANDS[name]
    for action in sub._actions:
        shown = shown_default(sub, action)
        if shown is None or action.default in (None, "", False):  # words such as "all" describe None
            continue
        assert shown == str(action.default), f"{name} {action.option_strings}: help shows {shown!r}, default {action.default!r}"


#: The defaults of the defaults module and the farm's config, as each command must show them.
EXPECTED = {
    "generate": {"--views": DEFAULT_VIEWS, "--points": DEFAULT_N_POINTS, "--resolution": DEFAULT_RESOLUTION,
                 "--radius": DEFAULT_RADIUS, "--seed": DEFAULT_SEED, "--dense-points": DEFAULT_DENSE_POINTS},
    "validate": {"--views": DEFAULT_VIEWS, "--dense-points": DEFAULT_DENSE_POINTS, "--resolution": DEFAULT_RESOLUTION,
                 "--radius": DEFAULT_RADIUS, "--seed": DEFAULT_SEED},
    "farm": {"--views": FARM_VIEWS, "--points": DEFAULT_N_POINTS, "--resolution": DEFAULT_FARM_RESOLUTION,
             "--radius": DEFAULT_RADIUS, "--seed": DEFAULT_SEED, "--dense-points": DEFAULT_FARM_DENSE_POINTS},
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_views_points_resolution_radius_seed_show_the_defaults_module_values(name: str) -> None:
    sub = SUBCOMMANDS[name]
    for flag, value in EXPECTED[name].items():
        action = _option(sub, flag)
        assert shown_default(sub, action) == str(value), f"{name} {flag}"
        if action.default is not None:
            assert action.default == value, f"{name} {flag}"


def test_generate_notes_where_its_defaults_differ_from_the_farms() -> None:
    g, f = SUBCOMMANDS["generate"], SUBCOMMANDS["farm"]
    assert f"the farm's: {FARM_VIEWS}" in _option(g, "--views").help
    assert f"the farm's: {DEFAULT_FARM_RESOLUTION}" in _option(g, "--resolution").help
    assert f"the farm's: {DEFAULT_FARM_DENSE_POINTS}" in _option(g, "--dense-points").help
    assert f"generate's: {DEFAULT_RESOLUTION}" in _option(f, "--resolution").help


def test_one_meaning_per_option_name() -> None:
    # --points: the points of one sample; --dense-points: the cloud sampled on each mesh
    for name in ("generate", "farm"):
        assert "per sample" in _option(SUBCOMMANDS[name], "--points").help
    for name in ("validate", "compare", "elevation-profile"):
        assert (
            "surface" in _option(SUBCOMMANDS[name], "--dense-points").help
            or "each mesh" in _option(SUBCOMMANDS[name], "--dense-points").help
        )
        assert "--points" not in SUBCOMMANDS[name]._option_string_actions  # one spelling: --dense-points


@pytest.mark.parametrize(
    "command",
    [
        ["validate", "--views", "0:0", "--resolution", "64"],
        ["compare", "--methods", "oracle", "--views", "0:0", "--resolution", "64", "--no-progress"],
    ],
)
def test_dense_points_is_the_one_spelling(command, tmp_path, capsys) -> None:
    extra = ["--out", str(tmp_path / "c")] if command[0] == "compare" else []
    assert main([command[0], str(BOX), *command[1:], *extra, "--dense-points", "150"]) == 0
    with pytest.raises(SystemExit) as exit_info:
        main([command[0], str(BOX), *command[1:], *extra, "--points", "150"])
    assert exit_info.value.code == 2 and "--points" in capsys.readouterr().err


# -- methods whose extra is missing ------------------------------------------------------------
@pytest.fixture
def no_open3d(monkeypatch):
    """Open3D not importable, whether or not it is installed here."""
    monkeypatch.setitem(sys.modules, "open3d", None)


def test_info_does_not_offer_open3d_methods_without_open3d(no_open3d, capsys) -> None:
    assert main(["info"]) == 0
    out = capsys.readouterr().out
    methods = next(line for line in out.splitlines() if line.startswith("methods"))
    assert "open3d" not in methods and "oracle" in methods
    assert re.search(r"^not here +open3d-hpr, open3d-raycast", out, re.M)


def test_validate_refuses_a_missing_extra_before_printing_anything(no_open3d, capsys) -> None:
    assert main(["validate", str(BOX), "--methods", "open3d-raycast", "--views", "0:0", "--dense-points", "100"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # no table header
    assert "method 'open3d-raycast' needs the open3d extra" in captured.err


# -- scan --distance -------------------------------------------------------------------------------
def test_scan_refuses_a_sensor_inside_the_object(tmp_path: Path, capsys) -> None:
    assert main(["scan", "box", "--distance", "0.1", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert "--distance 0.1 m may put the sensor inside the object (up to 4.5 m across): use a distance of at least 2.25 m" in err


def test_scan_distance_limit_is_half_the_largest_horizontal_size() -> None:
    from zbuf_occlude.errors import InvalidInputError
    from zbuf_occlude.sensors.placement import CropDistributions, check_outside

    check_outside(CropDistributions(distance_m=(2.25, 9.0), size_m=(4.5, 4.5)))
    with pytest.raises(InvalidInputError, match="at least 2.25 m"):
        check_outside(CropDistributions(distance_m=(2.2, 9.0), size_m=(4.0, 4.5)))
    with pytest.raises(InvalidInputError, match="at least 3 m"):
        check_outside(CropDistributions(distance_m=(2.5, 9.0), extents_m=((1.0, 2.0), (1.0, 6.0), (1.0, 1.0))))
    # a mesh's own proportions: a post 9 m tall and 0.9 m wide may stand 0.45 m away, and 3x as wide, 1.35 m
    post = CropDistributions(distance_m=(0.45, 9.0), size_m=(6.0, 9.0))
    check_outside(post, (0.1, 0.05, 1.0))
    with pytest.raises(InvalidInputError, match="at least 4.5 m"):
        check_outside(post)
    with pytest.raises(InvalidInputError, match=r"up to 2.7 m across\): use a distance of at least 1.35 m"):
        check_outside(CropDistributions(distance_m=(0.45, 9.0), size_m=(6.0, 9.0), width_scale=(1.0, 3.0)), (0.1, 0.05, 1.0))


# -- a wheel has no sample meshes --------------------------------------------------------------
def test_generate_without_path_says_a_wheel_ships_no_samples(tmp_path: Path, capsys, monkeypatch) -> None:
    import zbuf_occlude.cli.main as cli

    monkeypatch.setattr(cli, "SAMPLE_MESHES", tmp_path / "site-packages" / "data" / "samples")
    assert main(["generate", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "an installed wheel has none): pass mesh files or folders" in err
    assert "an installed wheel has none: pass PATH" in _option_help(SUBCOMMANDS["generate"], "paths")


def _option_help(parser: argparse.ArgumentParser, dest: str) -> str:
    return next(a.help for a in parser._actions if a.dest == dest)


# -- progress bars only on a terminal ------------------------------------------------------------
@pytest.mark.parametrize(
    "argv",
    [["compare", str(BOX), "--methods", "oracle", "--dense-points", "200", "--views", "0:0", "--resolution", "64", "--out", "{tmp}/c"],
     ["elevation-profile", str(BOX), "--method", "oracle", "--dense-points", "200", "--azimuths", "1", "--elevations", "0,30",
      "--resolution", "64", "--out", "{tmp}/p.png"]],
    ids=["compare", "elevation-profile"],
)  # fmt: skip
def test_no_progress_bar_into_a_log(tmp_path: Path, capsys, argv: list[str]) -> None:
    assert not sys.stderr.isatty()  # capsys: stderr is a file, as in a batch job's log
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 0
    err = capsys.readouterr().err
    assert "%|" not in err and "it/s" not in err, err


# -- docs/slurm_farm.sh renders every mesh -------------------------------------------------------
def _slurm_task_args(tmp_path: Path, **env: str) -> list[str]:
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    log = tmp_path / "args.txt"
    fake = bin_dir / "zbuf-occlude"
    fake.write_text(f'#!/bin/bash\nprintf "%s\\n" "$@" > {log}\n')
    fake.chmod(0o755)
    run_env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "SLURM_ARRAY_TASK_ID": "3",
               "ROOT": "/data/ModelNet40", "OUT": str(tmp_path / "out"), **env}  # fmt: skip
    subprocess.run(["bash", str(REPO_ROOT / "docs" / "slurm_farm.sh"), "task"], env=run_env, check=True, timeout=60)
    return log.read_text().splitlines()


def test_slurm_script_renders_every_mesh_unless_asked_for_a_subset(tmp_path: Path) -> None:
    args = _slurm_task_args(tmp_path)
    assert args[:2] == ["farm", "/data/ModelNet40"] and "--shard" in args and "3/16" in args
    assert not {"--per-class", "--classes", "--splits"} & set(args), args
    subset = _slurm_task_args(tmp_path, SUBSET="--per-class 5")
    assert subset[subset.index("--per-class") + 1] == "5"


def test_every_command_taking_meshes_lists_every_supported_extension(capsys):
    from zbuf_occlude.cli.main import main
    from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

    for command in ("generate", "validate", "compare", "elevation-profile"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert all(ext in text for ext in SUPPORTED_EXTENSIONS), (command, [e for e in SUPPORTED_EXTENSIONS if e not in text])


def test_counts_take_the_right_number() -> None:
    from zbuf_occlude.cli.options import counted

    assert [counted(n, "mesh", "meshes") for n in (0, 1, 2)] == ["0 meshes", "1 mesh", "2 meshes"]
    assert counted(1, "file") == "1 file" and counted(3, "file") == "3 files"


# -- --up ------------------------------------------------------------------------------------------
def test_scan_reads_the_mesh_with_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import trimesh

    import zbuf_occlude.mesh.load as load

    mesh = tmp_path / "box.obj"
    trimesh.creation.box(extents=(1.0, 3.0, 0.6)).export(mesh)
    seen = []
    real = load.load_mesh
    monkeypatch.setattr(load, "load_mesh", lambda path, **kw: seen.append(kw.get("up")) or real(path, **kw))
    assert main(["scan", str(mesh), "--up", "+y", "--distance", "8", "--out", str(tmp_path / "s")]) == 0
    assert seen == ["+y"]
    for command in (["generate", "--out", "o"], ["farm", "root", "--out", "o"], ["scan", "box", "--out", "o"]):
        assert build_parser().parse_args(command).up == "auto"


def test_every_argument_that_takes_meshes_lists_every_mesh_format() -> None:
    """Where the help says an argument takes mesh files, it names every extension load_mesh reads
    (glTF and COLLADA were missing from some)."""
    from zbuf_occlude.mesh.formats import SUPPORTED_EXTENSIONS

    takes_meshes = []
    for name, sub in SUBCOMMANDS.items():
        for action in sub._actions:
            text = sub._get_formatter()._expand_help(action) if action.help else ""
            if not action.option_strings and re.search(r"\bmesh (files?|folders?|tree)\b|\bmeshes in\b", text):
                takes_meshes.append(f"{name} {action.dest}")
                missing = [ext for ext in SUPPORTED_EXTENSIONS if ext not in text]
                assert not missing, f"{name} {action.dest}: its help lacks {missing}: {text}"
    assert {"generate paths", "farm root", "scan mesh_or_scene", "experiment sim2real root"} <= set(takes_meshes), takes_meshes


def test_scan_size_of_says_which_side_size_measures(tmp_path: Path) -> None:
    import trimesh

    from zbuf_occlude.sensors.scan_data import read_scan_npz

    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(tmp_path / "box.obj")
    base = ["scan", str(tmp_path / "box.obj"), "--size", "1", "--distance", "6", "--height", "2", "--yaw", "90", "--crop"]
    for size_of, top in (("max", 0.25), ("length", 0.25), ("height", 1.0)):  # a box 1 m long and 0.25 m tall, or 1 m tall
        assert main([*base, "--size-of", size_of, "--out", str(tmp_path / size_of)]) == 0
        points = read_scan_npz(next((tmp_path / size_of).glob("*.npz"))).points
        assert float(points[:, 2].max()) + 2.0 == pytest.approx(top, abs=0.02)  # the top face above the ground, seen from above
    assert (
        main(["scan", "box", "--size", "1", "--size-of", "height", "--out", str(tmp_path / "p")]) == 2
    )  # a primitive has no proportions here
    assert main([*base, "--size-of", "height", "--extents", "1,1,1", "--out", str(tmp_path / "e")]) == 2
