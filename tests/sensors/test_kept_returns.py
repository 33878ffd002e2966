"""What a training cloud keeps of each pulse's returns: one rule (``sensors.request.kept_returns``) for ``farm --sensor``
and ``experiment sim2real``, with the same default, recorded on the card and in ``settings.json``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.dataset.layout import CARD_FILE
from zbuf_occlude.dataset.reader import OccludedDataset
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.farm import FarmParams, SensorCropParams
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam
from zbuf_occlude.sensors.request import KEPT_RETURNS, RETURNS_RANGE_RESOLUTION_M, TRAINING_RETURNS, check_kept_returns, kept_returns

SAMPLES = Path(__file__).resolve().parents[2] / "data" / "samples"


def _sensors():
    """Presets of every pulsed pattern, and beams that record one return from a footprint or several from one ray."""
    hdl = sensor_from_name("hdl32e")
    return {
        "hdl32e": hdl, "vlp16": sensor_from_name("vlp16"), "livox-mid70": sensor_from_name("livox-mid70"),
        "riegl-q1560": sensor_from_name("riegl-q1560"), "dales-q1560": sensor_from_name("dales-q1560"),
        "hdl32e strongest footprint": with_beam(hdl, footprint_rays=7, return_mode="strongest", max_returns=1, range_resolution_m=0.75),
        "hdl32e two returns": with_beam(hdl, max_returns=2, range_resolution_m=0.5),
    }  # fmt: skip


SENSORS = _sensors()


@settings(max_examples=80, deadline=None)
@given(name=st.sampled_from(sorted(SENSORS)), returns=st.sampled_from([*KEPT_RETURNS, 1, 2, 3, 15]))
def test_what_a_cloud_keeps_is_what_it_asked_and_nothing_else(name: str, returns) -> None:
    sensor = SENSORS[name]
    kept = kept_returns(sensor, returns)
    beam, base = kept.beam, sensor.beam
    if returns == "all":
        assert kept is sensor  # what the device records
        return
    one = returns in (1, "strongest", "first", "last")
    assert beam.max_returns == (1 if one else returns)
    if one and base.max_returns == 1 and (base.footprint_rays == 1 or returns in (1, "strongest")) and not base.resolves_echoes:
        assert kept is sensor  # one return already: its one return is the first, the strongest and the last
    if returns in ("first", "last") and kept is not sensor:
        assert beam.return_mode == returns and beam.range_resolution_m > 0
    if not one:  # the multi-return model: a footprint of sub-rays, echoes resolved in range order
        assert beam.return_mode == "all" and beam.footprint_rays > 1 and beam.echo_separation_m == 0.0
        assert beam.range_resolution_m == (base.range_resolution_m or RETURNS_RANGE_RESOLUTION_M)
    # what is not about returns stays the device's
    for field in ("wavelength_nm", "divergence_deg", "profile", "intensity_scale", "intensity_unit", "range_noise_m", "dropout"):
        assert getattr(beam, field) == getattr(base, field), field
    assert kept_returns(kept, returns).beam == beam  # asking again changes nothing


def test_one_return_of_a_multi_return_beam_is_its_footprints_strongest_surface() -> None:
    q = SENSORS["riegl-q1560"]
    one = kept_returns(q).beam
    assert TRAINING_RETURNS == 1 and check_kept_returns("strongest") == 1
    assert (one.max_returns, one.return_mode, one.range_resolution_m, one.footprint_rays) == (1, "all", 0.0, q.beam.footprint_rays)
    first = kept_returns(q, "first").beam
    assert (first.max_returns, first.return_mode, first.range_resolution_m) == (1, "first", q.beam.range_resolution_m)


@pytest.mark.parametrize("bad", [0, 16, True, 2.0, "second", None, [1]])
def test_a_bad_choice_is_refused_by_its_kind_not_its_value(bad) -> None:
    with pytest.raises(InvalidInputError, match=r"^--x must be a whole number from 1 to 15 \(returns per pulse\) or one of strongest"):
        kept_returns(SENSORS["hdl32e"], bad, names={"returns": "--x"})
    if isinstance(bad, str):
        with pytest.raises(InvalidInputError) as caught:
            check_kept_returns(bad, "sensor_returns")
        assert bad not in str(caught.value)  # a card's value is never echoed


@pytest.mark.parametrize("name", ["hdl32e", "riegl-q1560", "hdl32e two returns"])
@pytest.mark.parametrize("returns", [1, "first", "all", 2])
def test_farm_and_sim2real_keep_the_same_returns(tmp_path: Path, name: str, returns) -> None:
    pytest.importorskip("torch")
    from zbuf_occlude.experiments.sim2real.config import Sim2RealConfig
    from zbuf_occlude.sensors.kinds import sensor_to_json

    path = tmp_path / "sensor.json"
    path.write_text(json.dumps(sensor_to_json(SENSORS[name])))
    try:
        farm = SensorCropParams(str(path), returns=returns).model()
    except InvalidInputError as exc:  # refused alike by both, in each command's words
        with pytest.raises(InvalidInputError):
            Sim2RealConfig("m", "r", sensor=str(path), returns=returns)
        assert "--sensor-returns" in str(exc)
        return
    assert farm == Sim2RealConfig("m", "r", sensor=str(path), returns=returns).sensor == kept_returns(sensor_from_name(str(path)), returns)


def test_the_card_records_the_kept_returns_only_where_they_change_the_sensor() -> None:
    assert "sensor_returns" not in FarmParams(sensor=SensorCropParams("hdl32e")).to_dict()  # earlier data sets keep their digest
    assert FarmParams(sensor=SensorCropParams("hdl32e")) == FarmParams(sensor=SensorCropParams("hdl32e", returns="all"))
    air = FarmParams(sensor=SensorCropParams("riegl-q1560"))
    assert air.to_dict()["sensor_returns"] == 1 and air.sensor.model().beam.max_returns == 1
    assert FarmParams.from_dict(air.to_dict()) == air
    # a card without the key: the data set was made before the option, with every return the device records
    earlier = {k: v for k, v in air.to_dict().items() if k != "sensor_returns"}
    assert FarmParams.from_dict(earlier).sensor.model().beam.max_returns == 15
    with pytest.raises(InvalidInputError, match="^--sensor-returns must be a whole number"):
        FarmParams.from_dict({**air.to_dict(), "sensor_returns": "every"})


def _air_farm(out: Path, *extra: str) -> OccludedDataset:
    argv = ["farm", str(SAMPLES), "--out", str(out), "--sensor", "riegl-q1560", "--samples-per-view", "1", "--points", "64",
            "--per-class", "1", "--splits", "train", "--classes", "chair", "--sensor-size", "4:5", "--no-progress", *extra]  # fmt: skip
    assert cli_main(argv) == 0
    return OccludedDataset(out)


def test_an_airborne_farm_keeps_one_return_a_pulse_unless_asked_for_all(tmp_path: Path) -> None:
    import h5py

    one, every = _air_farm(tmp_path / "one"), _air_farm(tmp_path / "all", "--sensor-returns", "all")
    assert json.loads((tmp_path / "one" / CARD_FILE).read_text())["params"]["sensor_returns"] == 1
    assert "sensor_returns" not in json.loads((tmp_path / "all" / CARD_FILE).read_text())["params"]
    assert len(one) > 0 and len(every) > 0
    for root, several in ((tmp_path / "one", False), (tmp_path / "all", True)):
        (shard,) = sorted(root.rglob("*.h5"))
        with h5py.File(shard, "r") as h:  # the return fields are written where a pulse may have several
            assert ("number_of_returns" in h) == several
            if several:
                assert h["number_of_returns"][()].max() > 1


@pytest.mark.parametrize(("argv", "said"), [
    (["--sensor", "riegl-q1560", "--sensor-returns", "0"], "--sensor-returns must be a whole number of returns per pulse (1 to 15) or one of"),
    (["--sensor", "riegl-q1560", "--sensor-returns", "most"], "or one of strongest, first, last, all, got most"),
    (["--sensor-returns", "all"], "--sensor-returns needs --sensor"),
])  # fmt: skip
def test_bad_returns_options_exit_2_naming_them(tmp_path: Path, capsys, argv: list[str], said: str) -> None:
    assert cli_main(["farm", str(SAMPLES), "--out", str(tmp_path / "ds"), "--no-progress", *argv]) == 2
    assert said in capsys.readouterr().err
    assert not (tmp_path / "ds").exists()


def test_a_farm_asking_returns_of_a_beam_without_a_divergence_is_told_its_own_option(tmp_path: Path) -> None:
    """Several returns need a footprint, and a footprint a divergence: the farm names the option that gives one."""
    path = tmp_path / "nodiv.json"
    path.write_text(json.dumps({"kind": "lidar", "preset": "hdl32e", "name": "nodiv", "beam": {"divergence_deg": 0.0}}))
    with pytest.raises(InvalidInputError, match=r"^--sensor-returns 2: .* give --sensor-divergence DEG"):
        SensorCropParams(str(path), returns=2)
