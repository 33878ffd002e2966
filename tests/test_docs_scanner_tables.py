"""docs/guide/scanners.md's tables are the code's: the Beam's fields and defaults, the kinds, every preset.

The tables are made here from :class:`~zbuf_occlude.sensors.beam.fields.Beam` and
:data:`~zbuf_occlude.sensors.kinds.SENSOR_KINDS`, and the page must hold them verbatim: a preset
or a default that changes fails this test until the page is remade.  Remake the tables with
``python tests/test_docs_scanner_tables.py`` and paste them over the page's.
"""

from __future__ import annotations

import math
import re
from dataclasses import fields
from pathlib import Path

import numpy as np

from zbuf_occlude.sensors import IDEAL_BEAM, SENSOR_KINDS, Beam
from zbuf_occlude.sensors.patterns.airborne import AIRBORNE_IDEAL_BEAM

PAGE = Path(__file__).resolve().parents[1] / "docs" / "guide" / "scanners.md"


def _g(value: float, digits: int = 3) -> str:
    """``value`` to ``digits`` significant digits, thousands separated, no trailing zeros."""
    if value == 0:
        return "0"
    if not 1e-3 <= abs(value) < 1e6:  # 8e-5, 1.67e9: the exponent without its zeros and plus sign
        return re.sub(r"e\+?(-?)0*(\d)", r"e\1\2", f"{value:.{digits}g}")
    return f"{float(f'{value:.{digits}g}'):,f}".rstrip("0").rstrip(".")


def _pattern(sensor, kind: str) -> str:
    """One line of what a preset's scan pattern and platform are."""
    if kind == "lidar":
        e = sensor.elevations_deg
        return (f"{sensor.n_beams} rings, {min(e):+g}° to {max(e):+g}°; {_g(sensor.rotation_hz)} Hz, "
                f"{_g(sensor.firing_rate_hz, 5)} firings/s ({_g(sensor.azimuth_step_deg)}° steps)")  # fmt: skip
    if kind == "airborne":
        headings = len(sensor.headings_deg)
        plan = f"{sensor.n_lines} lines × {headings} heading{'s' * (headings > 1)}, side overlap {_g(sensor.side_overlap)}"
        return (f"{sensor.pattern}, {_g(sensor.swath_deg)}° swath, {_g(sensor.pulse_rate_hz / 1e3)} kHz, {_g(sensor.line_rate_hz)} lines/s; "
                f"{_g(sensor.altitude_m, 4)} m at {_g(sensor.speed_mps)} m/s; "
                f"{plan if sensor.n_lines > 1 else 'one line'}: {_g(sensor.survey_density_m2)} points/m²")  # fmt: skip
    if kind == "ray_table":
        off_axis = np.degrees(np.arccos(np.cos(np.radians(sensor.elevation_deg)) * np.cos(np.radians(sensor.azimuth_deg))))
        return (f"{len(sensor):,} pulses over {_g(sensor.time_s[-1] - sensor.time_s[0] + np.diff(sensor.time_s).mean())} s, "
                f"{_g(2 * off_axis.max())}° circular field (Risley rosette)")  # fmt: skip
    return (f"{sensor.width} × {sensor.height} px, depth {_g(sensor.min_depth_m)} to {_g(sensor.max_depth_m)} m, "
            f"noise {sensor.noise}")  # fmt: skip


def _beam_cells(beam: Beam | None) -> list[str]:
    """The beam's columns of the preset table (dashes for a sensor without a beam)."""
    if beam is None:
        return ["—"] * 10
    mrad = _g(math.radians(beam.divergence_deg) * 1e3)
    scale = "—" if beam.intensity_scale is None else f"{beam.intensity_unit}: {_g(beam.intensity_scale)} / {beam.max_intensity:,}"
    return [mrad, str(beam.footprint_rays), str(beam.max_returns), _g(beam.range_resolution_m) if beam.range_resolution_m else "—",
            f"`{beam.return_mode}`", _g(beam.wavelength_nm, 6), _g(beam.detection_threshold) if beam.detection_threshold else "0",
            scale, _g(beam.range_noise_m), f"{_g(beam.min_range_m)} to {_g(beam.max_range_m)}"]  # fmt: skip


PRESET_HEADER = (
    "| preset | kind | scan pattern and platform | divergence (mrad) | sub-rays | max returns | range resolution (m) "
    "| return mode | wavelength (nm) | detection threshold (m⁻²) | intensity written: unit, scale / max | range noise σ (m) | range (m) |"
)


def preset_table() -> str:
    """The Markdown table of every preset of every kind, then the ``ideal`` beams."""
    rows = [PRESET_HEADER, "|" + "---|" * PRESET_HEADER.count(" | ") + "---|"]
    for kind in SENSOR_KINDS:
        for name in sorted(kind.presets):
            sensor = kind.presets[name]
            cells = [f"`{name}`", kind.name, _pattern(sensor, kind.name), *_beam_cells(getattr(sensor, "beam", None))]
            rows.append("| " + " | ".join(cells) + " |")
    for beam, who in ((IDEAL_BEAM, "the beam of a `Lidar` or `RayTable` given none"),
                      (AIRBORNE_IDEAL_BEAM, "the beam of an `AirborneScanner` given none")):  # fmt: skip
        rows.append("| " + " | ".join([f"**`{beam.name}`** (idealised mode)", "beam", who, *_beam_cells(beam)]) + " |")
    return "\n".join(rows)


def sources_table() -> str:
    """The Markdown table of every pulsed preset's citations: its pattern's ``source`` and its beam's."""
    rows = ["| preset | scan pattern's `source` | beam's `source` |", "|---|---|---|"]
    for kind in SENSOR_KINDS:
        for name in sorted(kind.presets):
            sensor = kind.presets[name]
            beam = getattr(sensor, "beam", None)
            rows.append(f"| `{name}` | {sensor.source} | {beam.source if beam is not None else '—'} |")
    return "\n".join(rows)


def kinds_table() -> str:
    """The Markdown table of :data:`SENSOR_KINDS`."""
    rows = [
        '| `"kind"` | what | class | presets | fires a beam | flies its own plan | fires an azimuth sector | array fields |',
        "|---|---|---|---|---|---|---|---|",
    ]
    for k in SENSOR_KINDS:
        presets = ", ".join(f"`{n}`" for n in sorted(k.presets))
        arrays = ", ".join(f"`{n}`" for n in k.array_fields) or "—"
        rows.append(f"| `{k.name}` | {k.title} | `{k.cls.__name__}` | {presets} | {'yes' if k.pulsed else 'no'} "
                    f"| {'yes' if k.flies else 'no'} | {'yes' if k.sweeps_sectors else 'no'} | {arrays} |")  # fmt: skip
    return "\n".join(rows)


def _default(f) -> str:
    value = f.default
    if value is None:
        return "None"
    if isinstance(value, str):
        return f'`"{value}"`'
    return _g(value, 6) if isinstance(value, float) else f"{value:,}" if isinstance(value, int) else str(value)


def beam_defaults() -> list[tuple[str, str]]:
    """``(field, default)`` of every Beam field, in order: the first two columns of the page's beam table."""
    return [(f.name, _default(f)) for f in fields(Beam) if f.init]


def _page_table_after(heading_text: str) -> str:
    """The first Markdown table on the page after a line holding ``heading_text``."""
    text = PAGE.read_text(encoding="utf-8")
    rest = text[text.index(heading_text) :]
    lines = rest.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("|"))
    end = next((i for i in range(start, len(lines)) if not lines[i].startswith("|")), len(lines))
    return "\n".join(lines[start:end])


def test_the_preset_table_is_the_codes() -> None:
    assert preset_table() in PAGE.read_text(encoding="utf-8"), "remake it: python tests/test_docs_scanner_tables.py"


def test_the_sources_table_is_the_codes() -> None:
    assert sources_table() in PAGE.read_text(encoding="utf-8"), "remake it: python tests/test_docs_scanner_tables.py"


def test_the_kinds_table_is_the_codes() -> None:
    assert kinds_table() in PAGE.read_text(encoding="utf-8"), "remake it: python tests/test_docs_scanner_tables.py"


def test_the_beam_table_names_every_field_with_its_default() -> None:
    rows = _page_table_after("<!-- beam fields -->").splitlines()[2:]
    cells = [[c.strip() for c in row.strip("|").split(" | ")] for row in rows]
    page = [(re.sub(r"`", "", c[0]), c[1]) for c in cells]
    assert page == beam_defaults()


def test_the_tables_see_every_preset() -> None:
    """A table made from an empty kinds table would pass the tests above on an empty page: the rows are there."""
    assert preset_table().count("\n") == 1 + sum(len(k.presets) for k in SENSOR_KINDS) + 2  # the header, the presets, two ideal beams
    assert "`riegl-q1560`" in sources_table() and "`livox-mid70`" in preset_table() and "`kinect-v1`" in kinds_table()


if __name__ == "__main__":
    print(kinds_table(), preset_table(), sources_table(), sep="\n\n")
    print("\n| field | default |\n|---|---|")
    print("\n".join(f"| `{name}` | {default} |" for name, default in beam_defaults()))
