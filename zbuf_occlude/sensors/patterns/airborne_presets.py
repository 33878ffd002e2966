"""Airborne scanner presets: real scanners, each with its data sheet's beam, flown as a survey flies them.

The pattern (:class:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner`) and the beam
(:class:`~zbuf_occlude.sensors.beam.fields.Beam`) of each preset, with their sources beside them.
"""

from __future__ import annotations

import math


from zbuf_occlude.sensors.patterns.airborne import AirborneScanner
from zbuf_occlude.sensors.beam.fields import Beam
from zbuf_occlude.sensors.checks import preset

__all__ = ["AIRBORNE_PRESETS", "airborne_preset"]

# RIEGL LMS-Q1560 (the scanner of DALES: Varney, Asari & Graehling, "DALES: A Large-scale Aerial
# LiDAR Data Set for Semantic Segmentation", CVPR Workshops 2020, flown at about 1,300 m): data
# sheet "RIEGL LMS-Q1560" (2015): two channels, up to 800 kHz laser pulse rate in all, 58° field of
# view, rotating polygon mirrors (parallel scan lines), up to 2 x 200 lines/s, ranging accuracy
# 20 mm.  Speed 72 m/s (140 kn) is a typical survey speed of the twin-engine aircraft such systems
# fly in (an ASSUMPTION); 209 lines/s makes the along- and across-track spacings equal (0.34 m).
# One pass: 7.7 points/m² (DALES reaches ~50 with overlapping strips).  The beam: _Q1560_BEAM below.
#
# "dales-q1560" is the same scanner flown as a survey block with DALES's density.  From the DALES
# paper: the abstract gives over half a billion labelled points on 10 km², i.e. about 50 points/m²
# (every return, vegetation's multiple returns included); its data-collection section gives the
# RIEGL Q1560 and 1,300 m (as cited above) and, as recalled (not re-read for this preset), a "400%
# minimum overlap".  ASSUMPTIONS: that overlap read as every ground point lying in at least four strips;
# the speed (72 m/s, as above); lines all parallel, one heading.  Given those, a side overlap of
# 0.85 (lines 216 m apart, 6 to 7 strips on every point) gives PRR / (v · s) = 51.4 points/m² on
# flat open ground (single returns).  Nine lines: any object within ±250 m of the plan centre
# lies where the block is unbounded (module docstring), wherever the lines' random shift puts them.
# The presets' beams.  Divergences, pulse lengths, maximum returns and ranging accuracies: the
# data sheets as HELIOS++ lists them (pyhelios/data/scanners_als.xml; Winiwarter et al. 2022,
# "Virtual laser scanning with HELIOS++", Remote Sens. Environ. 269, 112772), 1/e² full angles.
# Sub-rays: 19 per pulse, the count at which a tree's multi-return share settles within a few points
# (docs/results/returns.md).
# The receiver: what the RIEGL receiver of the IGN LiDAR HD sample (a RIEGL full-waveform scanner flown at ~1,500 m,
# the only record of a RIEGL receiver here) records, as fit-sensor measures it on that file
# (sensors/fit/return_model.py, 200 resamples over pulses), each figure rounded to its spread:
# - range resolution 0.83 m (± 0.01): the lower end of the gaps between consecutive returns of a pulse (no gap of
#   5,574 is under 0.82 m).  None of the RIEGL data sheets cited here gives a multi-target resolution; half the
#   4 ns pulse, c·τ/2 = 0.60 m (what HELIOS++ models), is a bound this receiver does not reach.  The Leica keeps
#   its data sheet's vertical discrimination (ALS50-II: 3.5 m); the Optech, of which no record is here, half its
#   8 ns pulse (1.20 m);
# - detection floor 23 counts (± 1): the lower end of the intensities of every return, on the scale below.  The
#   file's least intensity, 12 counts, is one echo's: 3 of its 37,805 read under 16;
# - intensity: 1.67e9 counts per unit of received energy (counts·m²), from its single ground returns, 16-bit
#   (RIEGL: "16-bit intensity per echo").
# For the Leica and Optech scanners the floor and the scale are the same figures, an ASSUMPTION.
# Neither the range resolution nor the floor is measured on vegetation's share of multi-return pulses, which the
# presets are compared with (docs/results/scanners.md).  Power noise: σ = 0.3 of the natural log of each
# firing's received power, a spread of about 30 % in the intensity of one surface (speckle averaged over the receiver's
# aperture, and the reflectance of natural ground varying from spot to spot): an ASSUMPTION, chosen before any
# comparison and not fitted (the IGN sample's single ground returns, p95 / p5 = 3.7, would give 0.4 by the same
# measure; docs/results/scanners/user_path.py).
_SUBRAYS = 19
_IGN_COUNTS = 1.67e9
_IGN_FLOOR_COUNTS = 23.0
_IGN_RANGE_RESOLUTION_M = 0.83
_POWER_NOISE = 0.3
#: The end of a RIEGL preset's beam source: where its receiver comes from.
_IGN_RECEIVER = f"; receiver: the IGN LiDAR HD sample's RIEGL (fit-sensor), {_IGN_RANGE_RESOLUTION_M:g} m, {_IGN_FLOOR_COUNTS:g} counts"


def _airborne_beam(name: str, source: str, **fields) -> Beam:
    """An airborne preset's beam: 1064 nm, 19 sub-rays, every echo resolved, the IGN receiver's intensity scale and
    detection floor of 23 counts, and a power noise of 0.3 (comment above)."""
    fields = {"wavelength_nm": 1064.0, "footprint_rays": _SUBRAYS, "intensity_scale": _IGN_COUNTS,
              "detection_threshold": _IGN_FLOOR_COUNTS / _IGN_COUNTS, "power_noise": _POWER_NOISE, **fields}  # fmt: skip
    return Beam(name, source=source, **fields)


# RIEGL LMS-Q1560: two LMS-Q780 channels in one housing (ASSUMPTION from RIEGL's product line;
# HELIOS++ lists the LMS-Q780: 0.25 mrad, 4 ns pulses, 20 mm accuracy, unlimited echoes per pulse,
# full waveform, which LAS 1.4 caps at 15 return numbers).
_Q1560_BEAM = _airborne_beam(
    "riegl-q1560", "RIEGL LMS-Q1560 data sheet (2015): ≤ 0.25 mrad, 20 mm; LMS-Q780 in HELIOS++ scanners_als.xml: 4 ns pulse, unlimited echoes" + _IGN_RECEIVER,
    divergence_deg=math.degrees(0.25e-3), max_returns=15, range_resolution_m=_IGN_RANGE_RESOLUTION_M, range_noise_m=0.02,
)  # fmt: skip
AIRBORNE_PRESETS: dict[str, AirborneScanner] = {
    "riegl-q1560": AirborneScanner(
        "riegl-q1560", swath_deg=58.0, pulse_rate_hz=800_000.0, line_rate_hz=209.0, altitude_m=1300.0,
        speed_mps=72.0, pattern="linear", beam=_Q1560_BEAM,
        source="RIEGL LMS-Q1560 data sheet (2015); DALES (Varney et al., CVPRW 2020) flight altitude 1,300 m",
    ),
    "dales-q1560": AirborneScanner(
        "dales-q1560", swath_deg=58.0, pulse_rate_hz=800_000.0, line_rate_hz=209.0, altitude_m=1300.0,
        speed_mps=72.0, pattern="linear", beam=_Q1560_BEAM, n_lines=9, side_overlap=0.85,
        source="riegl-q1560 flown as a survey block: 9 parallel lines, side overlap 0.85, 51.4 points/m² "
               "(DALES, Varney et al., CVPRW 2020: ~50 points/m² at 1,300 m; overlap and speed are assumptions)",
    ),
    # RIEGL LMS-Q780 (HELIOS++ scanners_als.xml lines 116-127): 0.25 mrad, 4 ns, 100-400 kHz,
    # 10-200 lines/s, rotating polygon, 60° field of view (±30° effective), 20 mm.  Flown here at
    # 1,000 m and 60 m/s (ASSUMPTIONS: a typical survey), 400 kHz and 200 lines/s.
    "riegl-q780": AirborneScanner(
        "riegl-q780", swath_deg=60.0, pulse_rate_hz=400_000.0, line_rate_hz=200.0, altitude_m=1000.0, speed_mps=60.0,
        pattern="linear", source="RIEGL LMS-Q780 as HELIOS++ lists it (scanners_als.xml); altitude and speed assumed",
        beam=_airborne_beam("riegl-q780", "HELIOS++ scanners_als.xml riegl_lms-q780: 0.25 mrad, 4 ns, 20 mm, unlimited echoes" + _IGN_RECEIVER,
                            divergence_deg=math.degrees(0.25e-3), max_returns=15, range_resolution_m=_IGN_RANGE_RESOLUTION_M,
                            range_noise_m=0.02),
    ),
    # RIEGL VQ-780i (scanners_als.xml lines 132-146): 0.25 mrad, 4 ns, 150-1000 kHz, 20-300 lines/s,
    # 60° field of view; echoes per pulse 15 at 150-250 kHz falling to 5 at 1 MHz (its comment).
    # Flown at 250 kHz (15 echoes), 150 lines/s, 1,000 m, 60 m/s (ASSUMPTIONS).
    "riegl-vq780i": AirborneScanner(
        "riegl-vq780i", swath_deg=60.0, pulse_rate_hz=250_000.0, line_rate_hz=150.0, altitude_m=1000.0, speed_mps=60.0,
        pattern="linear", source="RIEGL VQ-780i as HELIOS++ lists it (scanners_als.xml); altitude, speed and rates assumed",
        beam=_airborne_beam("riegl-vq780i", "HELIOS++ scanners_als.xml riegl_vq_780i: 0.25 mrad, 4 ns, 20 mm, 15 echoes at 250 kHz" + _IGN_RECEIVER,
                            divergence_deg=math.degrees(0.25e-3), max_returns=15, range_resolution_m=_IGN_RANGE_RESOLUTION_M,
                            range_noise_m=0.02),
    ),
    # Leica ALS50-II (scanners_als.xml lines 24-35): 0.22 mrad, 10 ns, 20/60/150 kHz, oscillating
    # mirror 0-90 Hz (two lines a period), ±37.5°, 5 cm accuracy; "up to 4 targets for each pulse,
    # vertical discrimination distance approx. 3.5 m".  Flown at 150 kHz, 40 Hz (80 lines/s),
    # 1,000 m, 60 m/s (ASSUMPTIONS).
    "leica-als50-ii": AirborneScanner(
        "leica-als50-ii", swath_deg=75.0, pulse_rate_hz=150_000.0, line_rate_hz=80.0, altitude_m=1000.0, speed_mps=60.0,
        pattern="oscillating", source="Leica ALS50-II as HELIOS++ lists it (scanners_als.xml); altitude, speed and rates assumed",
        beam=_airborne_beam("leica-als50-ii", "HELIOS++ scanners_als.xml leica_als50-ii: 0.22 mrad, 10 ns, 5 cm, 4 targets 3.5 m apart",
                            divergence_deg=math.degrees(0.22e-3), max_returns=4, range_resolution_m=3.5,
                            range_noise_m=0.05),
    ),
    # Optech Galaxy (scanners_als.xml lines 82-95): 0.354 mrad, 1064 nm, 8 ns, 35-550 kHz,
    # oscillating 0-120 Hz, ±30°, 3 cm, 8 returns per pulse.  Flown at 550 kHz, 60 Hz (120 lines/s),
    # 1,000 m, 60 m/s (ASSUMPTIONS).
    "optech-galaxy": AirborneScanner(
        "optech-galaxy", swath_deg=60.0, pulse_rate_hz=550_000.0, line_rate_hz=120.0, altitude_m=1000.0, speed_mps=60.0,
        pattern="oscillating", source="Optech Galaxy as HELIOS++ lists it (scanners_als.xml); altitude, speed and rates assumed",
        beam=_airborne_beam("optech-galaxy", "HELIOS++ scanners_als.xml optech_galaxy: 0.354 mrad, 1064 nm, 8 ns, 3 cm, 8 returns",
                            divergence_deg=math.degrees(0.354e-3), max_returns=8,
                            range_resolution_m=0.5 * 299_792_458.0 * 8e-9, range_noise_m=0.03),
    ),
}  # fmt: skip


def airborne_preset(name: str, **changes) -> AirborneScanner:
    """The preset ``name`` of :data:`AIRBORNE_PRESETS`, with optional field changes.

    Raises
    ------
    InvalidInputError
        Unknown name.
    """
    return preset(AIRBORNE_PRESETS, name, "airborne scanner", **changes)
