"""The library's errors name ``export()``'s parameters; the CLI names its flags for them."""

from __future__ import annotations

import pytest

from zbuf_occlude.cli.export import FLAGS, as_flags
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.exporters import export


@pytest.mark.parametrize(
    "said, shown",
    [
        ("label_set_name='modelnet10' has no class 'stool'; use label_set_name='own'",
         "--label-set modelnet10 has no class 'stool'; use --label-set own"),
        ("seed=1 applies to to='pointnet-h5', not to to='pcn'; leave it out", "--seed 1 applies to --to pointnet-h5, not to --to pcn; leave it out"),
        ("list_prefix=' ' is blank", "--list-prefix ' ' is blank"),  # a value a shell would need quoted keeps its quotes
        ("list_prefix='data/x\\rdata/y' holds", "--list-prefix 'data/x\\rdata/y' holds"),
        ("out='/tmp/my out': its name ...; give list_prefix", "--out '/tmp/my out': its name ...; give --list-prefix"),
        ("dataset='': name a folder", "DATASET '': name a folder"),
        ("/data/to=3/ds lies inside out='/data'", "/data/to=3/ds lies inside --out /data"),  # a path's "to=" is no parameter
        ("up='y': give one of +x, -x", "--up y: give one of +x, -x"),
        ("leave it out, go to it", "leave it out, go to it"),  # words are not parameters
    ],
)  # fmt: skip
def test_parameters_become_flags(said, shown):
    assert as_flags(said) == shown


def test_every_parameter_of_export_but_progress_has_a_flag():
    import inspect

    assert set(inspect.signature(export).parameters) - {"progress"} == set(FLAGS)


def test_the_library_names_parameters_and_the_cli_flags(tmp_path, capsys):
    from conftest import tiny_dataset

    ds = tiny_dataset(tmp_path / "ds")
    with pytest.raises(InvalidInputError, match=r"^label_set_name='shapenet55' has no class 'desk'"):
        export(ds, "pointnet-h5", tmp_path / "a", label_set_name="shapenet55", progress=False)
    with pytest.raises(InvalidInputError, match=r"^list_prefix='data/PCN' applies to to='pointnet-h5', not to to='modelnet-txt'"):
        export(ds, "modelnet-txt", tmp_path / "a", list_prefix="data/PCN")
    assert cli_main(["export", str(ds), "--to", "pointnet-h5", "--out", str(tmp_path / "b"), "--label-set", "shapenet55"]) == 2
    err = capsys.readouterr().err
    assert "--label-set shapenet55 has no class 'desk'; use --label-set own" in err and "label_set_name" not in err
    assert cli_main(["export", str(ds), "--to", "pointnet-h5", "--out", str(ds / "inside")]) == 2
    err = capsys.readouterr().err
    assert f"--out {ds / 'inside'} lies inside the data set" in err and len(err.strip().splitlines()) == 1
