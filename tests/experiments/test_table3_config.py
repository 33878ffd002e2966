"""zbuf_occlude.experiments.table3.config: the settings of ``experiment elevation|augmentation``, checked once."""

from __future__ import annotations

import inspect

import pytest

from zbuf_occlude.cli.main import main
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.table3 import augmentation, elevation
from zbuf_occlude.experiments.table3.config import SCALES, Table3Config


@pytest.mark.parametrize(
    "field, value",
    [("model", "resnet"), ("scale", "huge"), ("epochs", 0), ("points", 2.5), ("threads", True), ("seed", -1),
     ("seed", "0"), ("method", "no-such-method")],
)  # fmt: skip
def test_a_bad_setting_is_refused_when_made_naming_the_field_or_its_option(field, value) -> None:
    kwargs = {"model": "pointnet", field: value}
    with pytest.raises(InvalidInputError, match=field):
        Table3Config(**kwargs)
    with pytest.raises(InvalidInputError, match="--the-flag"):
        Table3Config(**kwargs, option_names={field: "--the-flag"})


def test_the_config_gives_the_scales_sizes_and_the_training_config() -> None:
    pytest.importorskip("torch", reason="TrainConfig is zbuf_occlude.learn's: pip install -e '.[learn]'")
    config = Table3Config("voxnet", scale="paper", epochs=3, classes=["chair"], seed=7, threads=1)
    assert config.classes == ("chair",) and config.n_points == SCALES["paper"].points
    train = config.train_config()
    assert (train.model, train.epochs, train.patience, train.width, train.seed, train.threads) == ("voxnet", 3, 20, 1.0, 7, 1)
    assert Table3Config("3dmfv", points=64).n_points == 64 and Table3Config("3dmfv").train_config().epochs == SCALES["quick"].epochs


@pytest.mark.parametrize("experiment", ["elevation", "augmentation"])
def test_an_unknown_method_is_refused_naming_the_flag_before_anything_is_written(tmp_path, capsys, experiment) -> None:
    pytest.importorskip("torch", reason="the experiment commands check --device with torch")
    out = tmp_path / "out"
    assert main(["experiment", experiment, str(tmp_path), "--method", "no-such-method", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("zbuf-occlude: error: --method") and "\n" not in err, err
    assert not out.exists()


def test_the_experiments_take_a_config_not_a_keyword_list() -> None:
    for fn in (elevation.run_elevation, augmentation.run_augmentation, elevation._elevation_into, augmentation._augmentation_into):
        params = inspect.signature(fn).parameters
        assert len(params) <= 12 and "config" in params, fn
        assert len(inspect.getsource(fn).splitlines()) < 150, fn
