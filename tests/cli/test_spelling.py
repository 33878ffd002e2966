"""Options are taken as spelled: no abbreviation on any parser, required options shown as required
in ``--help``, and ``--format hdf5`` as another name of ``h5``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from zbuf_occlude.cli.main import build_parser, main

REPO_ROOT = Path(__file__).resolve().parents[2]
CHAIR = REPO_ROOT / "data" / "samples" / "chair"
SMALL = ["--views", "0:0", "--points", "32", "--samples-per-view", "1", "--dense-points", "500", "--resolution", "64", "--no-progress"]


def _parsers(parser: argparse.ArgumentParser, name: str = "zbuf-occlude"):
    """``(name, parser)`` of the top level and every sub-command, nested ones included."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub_name, sub in action.choices.items():
                yield from _parsers(sub, f"{name} {sub_name}")


PARSERS = dict(_parsers(build_parser()))


def test_no_parser_takes_an_abbreviation() -> None:
    # argparse does not pass allow_abbrev down to sub-commands: each one is checked
    assert len(PARSERS) > 15
    assert all(not parser.allow_abbrev for parser in PARSERS.values()), [n for n, p in PARSERS.items() if p.allow_abbrev]


@pytest.mark.parametrize(
    ("argv", "meant"),
    [
        (["farm", "data/samples", "--out", "OUT", "--sample", "2"], "--samples-per-view"),
        (["generate", "data/samples", "--out", "OUT", "--dense", "500"], "--dense-points"),
        (["experiment", "elevation", "data/samples", "--out", "OUT", "--epo", "2"], "--epochs"),
    ],
)
def test_an_abbreviation_is_refused_naming_the_option_it_starts(argv, meant, tmp_path, capsys) -> None:
    argv = [str(tmp_path / "o") if a == "OUT" else a for a in argv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert f"unrecognized arguments: {argv[-2]} {argv[-1]}" in err and f"did you mean {meant}?" in err, err
    assert not (tmp_path / "o").exists()


REQUIRES_OUT = sorted(name for name, p in PARSERS.items() if any("--out" in a.option_strings and a.required for a in p._actions))


def test_the_commands_that_require_out_are_found() -> None:
    assert {"zbuf-occlude generate", "zbuf-occlude farm", "zbuf-occlude scan", "zbuf-occlude contact-sheet",
            "zbuf-occlude export", "zbuf-occlude experiment sim2real"} <= set(REQUIRES_OUT)  # fmt: skip


@pytest.mark.parametrize("name", REQUIRES_OUT)
def test_help_shows_a_required_out_as_required(name: str, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main([*name.split()[1:], "--help"])
    usage = " ".join(capsys.readouterr().out.split("\n\n")[0].split())  # the usage, its lines joined
    assert info.value.code == 0
    assert " --out OUT " in f"{usage} " and "[--out OUT]" not in usage, usage


def test_help_is_the_same_however_it_is_asked_for(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    first = capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["generate", "data/samples", "--points", "64", "-h"])
    assert capsys.readouterr().out == first and PARSERS["zbuf-occlude generate"].format_help() == first


def test_format_hdf5_is_h5() -> None:
    parser = build_parser()
    assert parser.parse_args(["generate", "--out", "o", "--format", "hdf5"]).format == "h5"
    assert parser.parse_args(["generate", "--out", "o", "--format", "h5"]).format == "h5"
    assert "hdf5" in PARSERS["zbuf-occlude generate"].format_help()


@pytest.mark.slow
def test_generate_with_format_hdf5_writes_what_h5_writes(tmp_path: Path) -> None:
    outputs = {}
    for name in ("h5", "hdf5"):
        assert main(["generate", str(CHAIR), "--out", str(tmp_path / name), "--format", name, *SMALL]) == 0
        records = [json.loads(line) for line in (tmp_path / name / "manifest.jsonl").read_text().splitlines()]
        outputs[name] = sorted(sorted(r["sha256"]) for r in records)
        assert json.loads((tmp_path / name / "plan.json").read_text())["params"]["storage"] == "h5"
    assert outputs["h5"] == outputs["hdf5"] and outputs["h5"]
