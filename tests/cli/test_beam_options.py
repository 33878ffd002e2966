"""``scan``'s beam options for every pulsed pattern, and its surface optics for a mesh and an airborne flight.

Every beam option (``--footprint``, ``--divergence``, ``--max-returns``, ``--range-resolution``,
``--power-noise``, ``--echo-separation``, ``--return-mode``) changes the sensor's beam through
``kinds.with_beam`` whatever fires it: a spinning LiDAR, an airborne scanner, a ray table; a depth
camera refuses each, naming it.  ``--reflectance-table`` and ``--transmittance`` reach a mesh's
scan and an airborne scanner's as they reach a scene file's spinning scan.  Runs on the shipped
chair and street scene.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from zbuf_occlude.cli.main import build_parser
from zbuf_occlude.cli.main import main as cli_main
from zbuf_occlude.cli.scan_request import scan_request
from zbuf_occlude.sensors.kinds import kind_of, sensor_from_name, sensor_to_json
from zbuf_occlude.sensors.scene.materials import GROUND_MATERIAL, reflectance
from zbuf_occlude.sensors.scan_data import read_scan_npz

ROOT = Path(__file__).resolve().parents[2]
CHAIR = ROOT / "data" / "samples" / "chair" / "train" / "chair_0001.off"
STREET = ROOT / "data" / "scenes" / "street.json"
#: Several returns per pulse from a 7-ray footprint.
RETURNS = ["--footprint", "--max-returns", "3", "--range-resolution", "0.5"]


def _run(argv: list[str], capsys) -> tuple[int, str]:
    code = cli_main([*argv, "--no-progress"])
    return code, capsys.readouterr().err.strip()


def _scan(argv: list[str], out: Path, capsys):
    code, err = _run(["scan", *argv, "--out", str(out)], capsys)
    assert code == 0, err
    (npz,) = out.glob("*.npz")
    return read_scan_npz(npz)


def _beam(sensor: str, options: list[str]):
    """The sensor ``scan --sensor SENSOR OPTIONS`` fires (parsed as the command parses it)."""
    args = build_parser().parse_args(["scan", "box", "--sensor", sensor, "--out", "unused", *options])
    return scan_request(args, sensor_from_name(sensor)).scanner


@pytest.mark.parametrize("sensor", ["vlp16", "riegl-q1560", "livox-mid70"])
@pytest.mark.parametrize(
    ("options", "changes"),
    [
        (RETURNS, {"footprint_rays": 7, "max_returns": 3, "range_resolution_m": 0.5, "echo_separation_m": 0.0}),
        (["--footprint", "--power-noise", "0.3", "--echo-separation", "0.4", "--max-returns", "1"],
         {"footprint_rays": 7, "power_noise": 0.3, "echo_separation_m": 0.4, "max_returns": 1, "range_resolution_m": 0.0}),
        (["--footprint", "--divergence", "0.5"], {"footprint_rays": 7, "divergence_deg": 0.5}),
        (["--footprint", "--return-mode", "dual", "--range-resolution", "0.8"],
         {"footprint_rays": 7, "return_mode": "dual", "max_returns": 2, "range_resolution_m": 0.8}),
        (["--footprint", "--return-mode", "strongest", "--range-resolution", "0.8"],
         {"footprint_rays": 7, "return_mode": "strongest", "max_returns": 1, "range_resolution_m": 0.8}),
        ([*RETURNS, "--min-echo-reflectance", "0.3"], {"footprint_rays": 7, "max_returns": 3, "range_resolution_m": 0.5,
                                                       "echo_separation_m": 0.0, "min_echo_reflectance": 0.3}),
        ([*RETURNS, "--echo-rule", "waveform"], {"footprint_rays": 7, "max_returns": 3, "range_resolution_m": 0.5, "echo_separation_m": 0.0,
                                                 "echo_rule": "waveform"}),
    ],
    ids=["returns", "mixed-pixels", "divergence", "dual", "strongest", "partial-echoes", "waveform"],
)  # fmt: skip
def test_every_beam_option_changes_the_beam_of_every_pulsed_pattern(sensor: str, options: list[str], changes: dict) -> None:
    base = sensor_from_name(sensor)
    changed = _beam(sensor, options)
    assert kind_of(changed) is kind_of(base)
    if "footprint_rays" in changes:  # --footprint: 7 sub-rays for a one-ray beam; a wider footprint of its own stays (airborne: 19)
        changes = changes | {"footprint_rays": max(7, base.beam.footprint_rays)}
    wanted = base.beam.with_(
        **{k: v for k, v in changes.items() if k != "echo_separation_m"} | {"echo_separation_m": changes.get("echo_separation_m", 0.0)}
    )
    assert changed.beam == wanted
    assert sensor_to_json(changed.with_(beam=base.beam)) == sensor_to_json(base)  # the pattern and the platform as they were


@pytest.mark.parametrize("sensor", ["vlp16", "riegl-q1560", "livox-mid70"])
def test_every_pulsed_pattern_scans_a_mesh_with_several_returns(tmp_path: Path, capsys, sensor: str) -> None:
    s = _scan([str(CHAIR), "--sensor", sensor, *RETURNS, "--power-noise", "0.2", "--divergence", "1.0"], tmp_path / "o", capsys)
    assert len(s) > 0 and s.number_of_returns.max() <= 3
    assert np.any(s.number_of_returns >= 2)  # a 1° footprint over the chair's edges: pulses with several returns
    assert np.all((s.return_number >= 1) & (s.return_number <= s.number_of_returns))


def test_a_ray_table_file_takes_the_beam_options(tmp_path: Path, capsys) -> None:
    table = tmp_path / "table.csv"
    az, el = np.meshgrid(np.linspace(-20.0, 20.0, 81), np.linspace(-12.0, 4.0, 17))
    rows = [f"{i * 1e-5:.6f},{a:.4f},{e:.4f}" for i, (a, e) in enumerate(zip(az.ravel(), el.ravel()))]
    table.write_text("time_s,azimuth_deg,elevation_deg\n" + "\n".join(rows) + "\n")
    code, err = _run(["scan", str(CHAIR), "--ray-table", str(table), "--footprint", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "--footprint samples the beam's divergence cone" in err and "give --divergence DEG" in err, err
    s = _scan([str(CHAIR), "--ray-table", str(table), "--footprint", "--divergence", "1.0", "--max-returns", "2", "--range-resolution",
               "0.5"], tmp_path / "p", capsys)  # fmt: skip
    assert len(s) > 0 and s.number_of_returns.max() == 2


def test_a_preset_without_a_divergence_takes_one_for_its_footprint(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", str(CHAIR), "--sensor", "hdl64e", "--footprint", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err, err
    assert "hdl64e's beam (hdl64e) has no divergence (divergence_deg 0): give --divergence DEG" in err
    plain = _scan([str(CHAIR), "--sensor", "hdl64e"], tmp_path / "plain", capsys)
    wide = _scan([str(CHAIR), "--sensor", "hdl64e", "--footprint", "--divergence", "0.5", "--max-returns", "3", "--range-resolution",
                  "0.3"], tmp_path / "wide", capsys)  # fmt: skip
    assert plain.number_of_returns.max() == 1 and wide.number_of_returns.max() >= 2  # the chair's edges split the wide footprints


@pytest.mark.parametrize(
    "option",
    [["--footprint"], ["--divergence", "0.2"], ["--max-returns", "2"], ["--range-resolution", "0.5"], ["--power-noise", "0.2"],
     ["--echo-separation", "0.5"], ["--return-mode", "last"], ["--min-echo-reflectance", "0.2"], ["--echo-rule", "waveform"]],
)  # fmt: skip
def test_a_depth_camera_refuses_every_beam_option_naming_it(tmp_path: Path, capsys, option: list[str]) -> None:
    code, err = _run(["scan", str(STREET), "--sensor", "kinect-v1", *option, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert err.endswith(f"{option[0]}: kinect-v1 is a depth camera, which has no beam to change (a pulsed LiDAR has one)"), err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("options", "words"),
    [(["--return-mode", "dual"], "--return-mode dual needs --range-resolution > 0"),
     (["--return-mode", "dual", "--max-returns", "3", "--range-resolution", "1"], "--return-mode dual records 2 returns per pulse; --max-returns 3 contradicts it"),
     (["--return-mode", "all", "--range-resolution", "1"], "--range-resolution 1 separates several returns per pulse"),
     (["--echo-rule", "waveform"], "--echo-rule waveform tells resolved echoes apart: it needs --max-returns above 1"),
     # one ray a pulse onto opaque surfaces has one return: several asked would change nothing
     (["--max-returns", "4", "--range-resolution", "0.75"], "--max-returns 4 resolves the echoes of a footprint or of surfaces the "
      "beam goes through; vlp16 fires one ray a pulse onto opaque surfaces, so each pulse has one return: give --footprint"),
     (["--return-mode", "last", "--range-resolution", "0.75"], "--return-mode last resolves the echoes of a footprint")],
)  # fmt: skip
def test_return_mode_mistakes_are_usage_errors(tmp_path: Path, capsys, options: list[str], words: str) -> None:
    code, err = _run(["scan", str(STREET), "--sensor", "vlp16", *options, "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and words in err, err


def test_returns_of_one_ray_are_taken_where_the_beam_goes_through_surfaces(tmp_path: Path, capsys) -> None:
    # the rule that refuses several returns from one opaque ray lets them through a crown: hits behind a surface
    s = _scan([str(STREET), "--sensor", "vlp16", "--max-returns", "4", "--range-resolution", "0.75", "--transmittance", "0.5"],
              tmp_path / "o", capsys)  # fmt: skip
    assert s.number_of_returns.max() > 1


def test_a_depth_camera_scans_a_scene_file_not_a_mesh(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", str(CHAIR), "--sensor", "kinect-v1", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and err.endswith("scan of a mesh file places a LiDAR; use a scene file for a depth camera"), err
    assert not (tmp_path / "o").exists()


def test_return_modes_pick_the_echoes_a_receiver_records(tmp_path: Path, capsys) -> None:
    base = [str(STREET), "--sensor", "vlp16", "--footprint", "--divergence", "1.5", "--range-resolution", "0.5"]
    every = _scan([*base, "--max-returns", "15"], tmp_path / "all", capsys)
    dual = _scan([*base, "--return-mode", "dual"], tmp_path / "dual", capsys)
    last = _scan([*base, "--return-mode", "last"], tmp_path / "last", capsys)
    first = _scan([*base, "--return-mode", "first"], tmp_path / "first", capsys)
    assert every.number_of_returns.max() > 2  # the street's edges give footprints of several echoes
    assert dual.number_of_returns.max() == 2
    assert set(np.unique(last.number_of_returns).tolist()) == set(np.unique(first.number_of_returns).tolist()) == {1}
    # the last echo of a pulse is its farthest, the first its nearest: each mode's range is the largest (smallest) of the
    # pulse's echoes, but for the range noise (each run draws it per echo, so the two runs' draws differ)
    for kept, pick in ((last, max), (first, min)):
        end: dict[int, float] = {}
        for p, r in zip(every.pulse_id.tolist(), every.range_m.tolist()):
            end[p] = pick(r, end.get(p, r))
        got = dict(zip(kept.pulse_id.tolist(), kept.range_m.tolist()))
        shared = sorted(set(got) & set(end))
        assert len(shared) > 100
        gap = np.abs(np.array([got[p] - end[p] for p in shared]))
        # another echo of the pulse lies at least a range resolution (0.5 m) from the kept one
        assert np.median(gap) < 0.05 and np.mean(gap > 0.4) < 0.005, np.percentile(gap, [50, 95, 99])
    several = every.number_of_returns > 1
    assert np.mean(np.isin(first.pulse_id, every.pulse_id[several])) > 0.01  # pulses where first and last differ are tested


def test_reflectance_table_reaches_a_mesh_scan(tmp_path: Path, capsys) -> None:
    from zbuf_occlude.mesh.load import load_mesh
    from zbuf_occlude.sensors.scene.materials import material_of

    plain = _scan([str(CHAIR), "--sensor", "vlp16"], tmp_path / "plain", capsys)
    table = _scan([str(CHAIR), "--sensor", "vlp16", "--reflectance-table"], tmp_path / "table", capsys)
    assert 0 < len(table) < len(plain)  # the dark asphalt's grazing returns fall below the threshold
    kept = np.isin(plain.pulse_id, table.pulse_id)
    assert np.array_equal(plain.pulse_id[kept], table.pulse_id) and np.array_equal(plain.object_id[kept], table.object_id)
    rho = {0: reflectance(GROUND_MATERIAL), 1: reflectance(material_of(load_mesh(CHAIR), "chair_0001"))}
    for oid, value in rho.items():
        on = table.object_id == oid
        assert on.sum() > 10
        assert np.allclose(table.intensity[on], value * plain.intensity[kept][on], rtol=1e-5)  # the energy ρ·|cos θ|/R²


def test_transmittance_reaches_a_mesh_scan(tmp_path: Path, capsys) -> None:
    opaque = _scan([str(CHAIR), "--sensor", "vlp16", *RETURNS], tmp_path / "opaque", capsys)
    through = _scan([str(CHAIR), "--sensor", "vlp16", *RETURNS, "--transmittance", "chair_0001=0.6"], tmp_path / "through", capsys)
    behind = [int(np.sum((s.object_id == 0) & (s.return_number > 1))) for s in (opaque, through)]
    assert behind[1] > behind[0]  # the ground seen through the chair, as a later return of its pulses
    code, err = _run(
        ["scan", str(CHAIR), "--sensor", "vlp16", *RETURNS, "--transmittance", "bush=0.3", "--out", str(tmp_path / "x")], capsys
    )
    assert code == 2 and "--transmittance bush=0.3: no object of the scene has the class 'bush'" in err, err


def test_surface_optics_reach_an_airborne_scan(tmp_path: Path, capsys) -> None:
    import zbuf_occlude as zo
    from zbuf_occlude.sensors import airborne_preset, scan_airborne

    # --transmittance 0 alone keeps the airborne default's reflectances (the table's materials), as --reflectance-table gives them
    plain = _scan([str(STREET), "--sensor", "riegl-q1560", "--transmittance", "0"], tmp_path / "plain", capsys)
    table = _scan([str(STREET), "--sensor", "riegl-q1560", "--transmittance", "0", "--reflectance-table"], tmp_path / "table", capsys)
    through = _scan([str(STREET), "--sensor", "riegl-q1560", "--transmittance", "car=0.5"], tmp_path / "through", capsys)
    ground = lambda s: (s.object_id == 0) & (s.number_of_returns == 1)  # noqa: E731 - one echo: its energy alone
    assert np.array_equal(plain.intensity, table.intensity)
    # against ρ = 1 (the library's reflectivity=None): the ground's reflectance at 1064 nm
    scene = zo.load_scene(STREET)
    rho_1 = scan_airborne(scene, airborne_preset("riegl-q1560"), (0.0, 0.0), scene.ground_half_extent_m, seed=0, reflectivity=None,
                          transmittance=0.0)  # fmt: skip
    ratio = np.median(table.intensity[ground(table)]) / np.median(rho_1.intensity[ground(rho_1)])
    assert ratio == pytest.approx(reflectance(GROUND_MATERIAL, 1064.0), rel=0.05)
    # the car (object 1) lets half of each sub-ray on: the pulses that meet it first return its far faces and the ground
    # behind it as later returns; opaque, only the sub-rays of a footprint that misses the car's edge go on
    later = []
    for s in (plain, through):
        on_car_first = np.unique(s.pulse_id[(s.return_number == 1) & (s.object_id == 1)])
        later.append(int(np.sum(np.isin(s.pulse_id, on_car_first) & (s.return_number > 1))))
    assert later[1] > 1.5 * later[0] > 0, later


def test_reflectance_table_and_reflectivity_are_one_or_the_other(tmp_path: Path, capsys) -> None:
    code, err = _run(["scan", str(CHAIR), "--reflectance-table", "--reflectivity", "0.3", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and "--reflectance-table gives each surface its material's reflectivity; --reflectivity gives the object one" in err


def test_a_sensor_files_beam_is_changed_not_replaced(tmp_path: Path) -> None:
    spec = {"kind": "airborne", "preset": "riegl-q1560", "beam": {"power_noise": 0.25, "range_noise_m": 0.05}}
    path = tmp_path / "als.json"
    path.write_text(json.dumps(spec))
    changed = _beam(str(path), ["--max-returns", "4"])
    assert changed.beam.max_returns == 4 and changed.beam.power_noise == 0.25 and changed.beam.range_noise_m == 0.05


@pytest.mark.parametrize(("source", "sensor"), [(STREET, "vlp16"), (CHAIR, "vlp16"), (CHAIR, "riegl-q1560")])
def test_the_adaptive_footprint_reaches_scene_and_mesh_scans(tmp_path: Path, capsys, monkeypatch, source: Path, sensor: str) -> None:
    import importlib

    scan_module = importlib.import_module("zbuf_occlude.sensors.scan")  # the module: the package's name `scan` is the function
    uniform_shares = []

    def spy(*args, **kwargs):
        out = adaptive(*args, **kwargs)
        uniform_shares.append(float(out[-1].mean()))
        return out

    adaptive = scan_module.adaptive_echo_returns
    monkeypatch.setattr(scan_module, "adaptive_echo_returns", spy)
    base = [str(source), "--sensor", sensor, *RETURNS, "--seed", "3"]
    exact = _scan([*base, "--footprint-cast", "exact"], tmp_path / "exact", capsys)
    assert uniform_shares == []
    fast = _scan([*base, "--footprint-cast", "adaptive"], tmp_path / "fast", capsys)
    assert len(uniform_shares) == 1 and uniform_shares[0] > 0.5  # most footprints not cast
    default = _scan(base, tmp_path / "default", capsys)  # --footprint-cast auto: adaptive here
    assert len(uniform_shares) == 2 and np.array_equal(default.points, fast.points)
    if source == STREET:  # the same scan as the Python API's
        import zbuf_occlude as zo

        lidar = _beam(sensor, RETURNS)
        api = zo.scan(zo.load_scene(STREET), lidar, seed=3, footprint="adaptive")
        assert np.array_equal(api.points, fast.points) and np.array_equal(api.number_of_returns, fast.number_of_returns)
    # one plane's echo in place of the cast sub-rays: the same returns, to a few
    assert abs(len(fast) - len(exact)) <= max(4, 0.002 * len(exact))


@pytest.mark.parametrize(
    ("options", "words"),
    [(["--sensor", "vlp16"], "--footprint-cast adaptive skips the sub-rays of a footprint whose echoes are resolved; vlp16 fires one ray"),
     (["--sensor", "vlp16", *RETURNS, "--backend", "zbuffer"], "--footprint-cast adaptive casts rays with Embree; --backend zbuffer renders"),
     (["--sensor", "kinect-v1"], "--footprint-cast: kinect-v1 is a depth camera, which has no beam to change")],
)  # fmt: skip
def test_the_adaptive_footprint_is_refused_where_it_does_not_apply(tmp_path: Path, capsys, options: list[str], words: str) -> None:
    code, err = _run(["scan", str(STREET), *options, "--footprint-cast", "adaptive", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and words in err and "\n" not in err, err


def test_an_unknown_footprint_cast_is_a_usage_error_naming_it(tmp_path: Path, capsys) -> None:
    with pytest.raises(SystemExit) as exit_info:
        _run(["scan", str(STREET), "--footprint-cast", "fast", "--out", str(tmp_path / "o")], capsys)
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and "--footprint-cast: invalid choice: 'fast'" in err, err
