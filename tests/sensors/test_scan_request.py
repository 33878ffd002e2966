"""The scan request: every rule that ties a scan's options together, checked once in the library and named in the
caller's words; each rule stated in one module only; no error of ``sensors/`` spells a command's option."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.kinds import sensor_from_name, with_beam
from zbuf_occlude.sensors.platform import Trajectory
from zbuf_occlude.sensors.request import ScanRequest

PACKAGE = Path(__file__).resolve().parents[2] / "zbuf_occlude"
#: A caller's words for some fields (as scan's options are spelled).
WORDS = {"max_returns": "--max-returns", "range_resolution_m": "--range-resolution", "footprint": "--footprint",
         "footprint_rays": "--footprint", "return_mode": "--return-mode", "sensor": "my-lidar"}  # fmt: skip


def test_a_refusal_names_the_fields_in_the_library_words_or_the_callers() -> None:
    vlp16 = sensor_from_name("vlp16")
    with pytest.raises(InvalidInputError, match=r"^max_returns 3 needs range_resolution_m > 0 \(metres"):
        ScanRequest(vlp16, beam={"footprint": True, "max_returns": 3})
    with pytest.raises(InvalidInputError, match=r"^--max-returns 3 needs --range-resolution > 0 \(metres"):
        ScanRequest(vlp16, beam={"footprint": True, "max_returns": 3}, names=WORDS)
    with pytest.raises(InvalidInputError, match=r"^footprint: kinect-v1 is a depth camera, which has no beam to change"):
        ScanRequest(sensor_from_name("kinect-v1"), beam={"footprint": True})
    with pytest.raises(InvalidInputError, match=r"changes no beam field 'footprint_ray'"):
        ScanRequest(vlp16, beam={"footprint_ray": 7})


@pytest.mark.parametrize(
    ("fields", "words"),
    [({"backend": "optix"}, r"^backend must be one of embree, zbuffer, got 'optix'"),
     ({"formats": ("npz", "xyz")}, r"^format must be a tuple of npz, ply, las, laz"),
     ({"formats": "las"}, r"^format must be a tuple of"),
     ({"samples": 0}, r"^samples must be an integer from 1 to"),
     ({"samples": 2.5}, r"^samples must be an integer from 1 to")],
)  # fmt: skip
def test_each_value_of_a_request_is_checked_alone_too(fields: dict, words: str) -> None:
    with pytest.raises(InvalidInputError, match=words):
        ScanRequest(sensor_from_name("vlp16"), **fields)


def test_returns_asked_of_one_opaque_ray_are_refused_as_changing_nothing() -> None:
    vlp16 = sensor_from_name("vlp16")
    asked = {"max_returns": 4, "range_resolution_m": 0.75}
    with pytest.raises(
        InvalidInputError, match=r"^--max-returns 4 resolves the echoes .* my-lidar fires one ray a pulse .* give --footprint"
    ):
        ScanRequest(vlp16, beam=asked, names=WORDS)
    assert ScanRequest(vlp16, beam={**asked, "footprint": True}).scanner.beam.max_returns == 4  # a footprint's echoes
    assert ScanRequest(vlp16, beam=asked, transmittance=0.5).scanner.beam.max_returns == 4  # hits behind a surface
    own = with_beam(vlp16, max_returns=2, range_resolution_m=0.5)  # a device's own returns stay as it has them
    assert ScanRequest(own).scanner is own


def test_the_frame_follows_the_platform() -> None:
    assert ScanRequest(sensor_from_name("vlp16")).frame == "sensor"
    assert ScanRequest(sensor_from_name("riegl-q1560")).frame == "world"  # flies: no one sensor frame
    with pytest.raises(InvalidInputError, match=r"^frame sensor: riegl-q1560 flies along its lines"):
        ScanRequest(sensor_from_name("riegl-q1560"), frame="sensor")


def test_a_moving_platform_needs_rays_cast_from_each_pulse() -> None:
    drive = Trajectory(np.array([0.0, 1.0]), np.array([[0.0, 0.0, 1.8], [10.0, 0.0, 1.8]]), np.stack([np.eye(3)] * 2))
    vlp16 = sensor_from_name("vlp16")
    assert ScanRequest(vlp16, trajectory=drive).trajectory is drive
    with pytest.raises(InvalidInputError, match=r"^trajectory: backend zbuffer renders from one point"):
        ScanRequest(vlp16, trajectory=drive, backend="zbuffer")
    with pytest.raises(InvalidInputError, match=r"^trajectory lasts 1 s, and samples 20 sweeps of vlp16 take 2 s"):
        ScanRequest(vlp16, trajectory=drive, samples=20)
    with pytest.raises(InvalidInputError, match=r"^trajectory: a depth camera takes one pose"):
        ScanRequest(sensor_from_name("kinect-v1"), trajectory=drive)


@settings(max_examples=150, deadline=None)
@given(
    footprint=st.booleans(),
    max_returns=st.sampled_from([None, 1, 2, 4]),
    return_mode=st.sampled_from([None, "all", "first", "strongest", "last", "dual"]),
    range_resolution_m=st.sampled_from([None, 0.5]),
    echo_separation_m=st.sampled_from([None, 0.3]),
    echo_rule=st.sampled_from([None, "chain", "waveform"]),
    sensor=st.sampled_from(["hdl32e", "riegl-q1560"]),
)
def test_a_request_is_refused_in_the_library_words_or_its_beam_is_what_it_asked(sensor: str, **asked) -> None:
    base = sensor_from_name(sensor)
    try:
        beam = ScanRequest(base, beam=asked, transmittance=0.3).scanner.beam
    except InvalidInputError as exc:
        assert "--" not in str(exc)  # the library never spells an option
        return
    for field in ("max_returns", "return_mode", "range_resolution_m", "echo_separation_m", "echo_rule"):
        if asked[field] is not None:
            assert getattr(beam, field) == asked[field], field
    assert beam.footprint_rays == (max(7, base.beam.footprint_rays) if asked["footprint"] else base.beam.footprint_rays)
    if asked["return_mode"] in ("first", "strongest", "last", "dual") and asked["max_returns"] is None:
        assert beam.max_returns == {"dual": 2}.get(asked["return_mode"], 1)


def _modules_saying(phrase: str) -> list[str]:
    return sorted(str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if phrase in p.read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("phrase", "home"),
    [
        ("skips the sub-rays of a footprint", "sensors/beam/adaptive_cast.py"),
        ("casts rays with Embree", "sensors/beam/adaptive_cast.py"),
        ("separates several returns per pulse", "sensors/beam/fields.py"),
        ("tells resolved echoes apart", "sensors/beam/fields.py"),
        ("the least range between two returns, c·τ/2)", "sensors/beam/fields.py"),
        ("mixed pixels come from a wide footprint", "sensors/beam/fields.py"),
        ("merges echoes into one return", "sensors/beam/fields.py"),
        ("samples the beam's divergence cone", "sensors/beam/fields.py"),
        ("resolves the echoes of a footprint or of surfaces", "sensors/request.py"),
        ("gives hits behind a surface", "sensors/beam/echo_energy.py"),
        ("needs every hit along each sub-ray", "sensors/beam/echo_energy.py"),
        ("which has no beam to change", "sensors/request.py"),
        ("labels world coordinates", "sensors/scan_data.py"),
        ("the footprint's strongest surface (``strongest_echo``)", "sensors/request.py"),
        ("lie each in its own pulse's frame", "sensors/scan_data.py"),
    ],
)
def test_each_rule_of_a_scan_is_stated_in_one_module(phrase: str, home: str) -> None:
    assert _modules_saying(phrase) == [home]


def _error_texts(tree: ast.AST):
    """The literal text of every exception a module raises with a message."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and node.exc.args:
            arg = node.exc.args[0]
            parts = arg.values if isinstance(arg, ast.JoinedStr) else [arg]
            yield node.lineno, "".join(p.value for p in parts if isinstance(p, ast.Constant) and isinstance(p.value, str))


def test_no_error_of_the_sensors_package_spells_a_commands_option() -> None:
    spelled = [f"{path.relative_to(PACKAGE)}:{line}: {text}"
               for path in sorted((PACKAGE / "sensors").rglob("*.py"))
               for line, text in _error_texts(ast.parse(path.read_text(encoding="utf-8")))
               if re.search(r"(^|[\s(])--[a-z]", text)]  # fmt: skip
    assert not spelled, "\n".join(spelled)
