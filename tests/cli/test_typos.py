"""A mistyped option is refused by its sub-command: that command's usage and the nearest option."""

from __future__ import annotations

import pytest

from zbuf_occlude.cli.main import main


@pytest.mark.parametrize(
    ("argv", "command", "nearest"),
    [
        (["generate", "data/samples", "--veiws", "0:0", "--out", "OUT"], "generate", "--views"),
        (["farm", "data/samples", "--out", "OUT", "--pionts=512"], "farm", "--points"),
        (["experiment", "elevation", "data/samples", "--out", "OUT", "--epohcs", "3"], "experiment elevation", "--epochs"),
    ],
)
def test_a_typo_names_the_sub_command_and_the_nearest_option(argv, command, nearest, tmp_path, capsys) -> None:
    argv = [str(tmp_path / "o") if a == "OUT" else a for a in argv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2
    assert f"usage: zbuf-occlude {command} " in err  # the sub-command's usage, not the top level's
    assert f"zbuf-occlude {command}: error: unrecognized arguments: " in err and f"did you mean {nearest}?" in err
    assert not (tmp_path / "o").exists()


def test_an_option_like_none_of_them_gets_no_guess(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["info", "--qqqqqq"])
    err = capsys.readouterr().err
    assert "usage: zbuf-occlude info" in err and "unrecognized arguments: --qqqqqq" in err and "did you mean" not in err


@pytest.mark.parametrize(
    ("argv", "nearest"),
    [(["generate", "--veiws", "0:0"], "--views"), (["generate", "data/samples", "--otu", "OUT"], "--out")],
)
def test_a_typo_is_named_before_a_missing_required_option(argv, nearest, tmp_path, capsys) -> None:
    # argparse alone says only "the following arguments are required: --out"
    argv = [str(tmp_path / "o") if a == "OUT" else a for a in argv]
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and "usage: zbuf-occlude generate " in err
    assert "unrecognized arguments: " in err and f"did you mean {nearest}?" in err and "required" not in err
    assert not (tmp_path / "o").exists()


def test_a_missing_required_option_alone_is_named_and_stays_required(capsys) -> None:
    for _ in range(2):  # the first look for typos leaves every option as required as it was
        with pytest.raises(SystemExit) as info:
            main(["generate", "data/samples"])
        assert info.value.code == 2 and "the following arguments are required: --out" in capsys.readouterr().err
