"""``scan``'s return physics options: the ground's reflectivity, the beam's options and the surface optics.

Each sets a field of the scan's :class:`~zbuf_occlude.sensors.request.ScanRequest`
(:func:`~zbuf_occlude.cli.scan_request.scan_request`), which checks them against each other and the sensor.
"""

from __future__ import annotations

import argparse

from zbuf_occlude.cli.options import Checked, real
from zbuf_occlude.cli.scan_request import check_max_returns, check_transmittance
from zbuf_occlude.sensors.beam.adaptive_cast import FOOTPRINT_MODES
from zbuf_occlude.sensors.beam.fields import RETURN_MODES
from zbuf_occlude.sensors.beam.echoes import ECHO_RULES, MAX_POWER_NOISE

__all__ = ["add_return_physics_arguments"]


def add_return_physics_arguments(p: argparse.ArgumentParser) -> None:
    """``scan``'s return physics group: the ground's reflectivity, power noise, the beam options and the surface optics."""
    r = p.add_argument_group("return physics (LiDAR)", "with --reflectivity and --footprint above")
    r.add_argument(
        "--ground-reflectivity",
        action=Checked,
        check=real(0.0),
        default=0.15,
        help="the ground's reflectivity with --reflectivity (default: %(default)s)",
    )
    r.add_argument(
        "--power-noise", metavar="SIGMA", action=Checked, check=real(0.0, MAX_POWER_NOISE), default=None,
        help=f"sigma of ln(received power) per firing, 0 to {MAX_POWER_NOISE:g}: the most a real return's power fluctuates is "
        "speckle through saturated turbulence, sigma 1.81; beyond, the noise and not the range would set every intensity; "
        "0: a sharp threshold (default: the sensor's beam's)",
    )  # fmt: skip
    r.add_argument(
        "--echo-separation", metavar="M", action=Checked, check=real(0.0, unit="metres"), default=None,
        help="with --footprint: echoes within M metres of the strongest merge into one return at their energy-weighted "
        "range (mixed pixels at shallow depth edges; half the pulse length, ~0.75 m for 5 ns); 0: never (default: the sensor's beam's)",
    )  # fmt: skip
    r.add_argument(
        "--min-echo-reflectance", metavar="R", action=Checked, check=real(0.0, 1.0), default=None,
        help="echoes whose apparent reflectance (energy x range^2: reflectivity x |cos incidence| x the share of the footprint "
        "the surface takes; reflectivity 1 where the scan is given none) is below R are not detected: partial echoes at an "
        "object's outline and grazing hits, alike at every range and sub-ray count; 0: none (default: the sensor's beam's)",
    )  # fmt: skip
    r.add_argument("--max-returns", metavar="N", action=Checked, check=check_max_returns, default=None,
                   help="with --footprint (or a sensor's own footprint): up to N returns per pulse (1..15), the "
                        "footprint's echoes resolved by --range-resolution, each with its return number, number of returns and "
                        "intensity (default: the sensor's beam's: 1 for spinning presets, 4 to 15 for airborne ones)")  # fmt: skip
    r.add_argument("--range-resolution", metavar="M", action=Checked, check=real(0.0, above=True, unit="metres"), default=None,
                   help="with --max-returns above 1: echoes closer than M metres merge into one return (half the pulse length, "
                        "~0.75 m for 5 ns) (default: the sensor's)")  # fmt: skip
    r.add_argument("--reflectance-table", action="store_true",
                   help="the surfaces reflect as the cited table gives their material at the beam's wavelength (by each object's "
                        "material or class: leaves, bark, car paint, glass, metal, ...; the ground asphalt), and returns must clear "
                        "the sensor's radiometric threshold (an airborne scanner with a multi-return beam and an intensity scale "
                        "takes the table and --transmittance table unless either is given)")  # fmt: skip
    r.add_argument("--transmittance", metavar="SPEC", action=Checked, check=check_transmittance, default=None,
                   help="with --max-returns above 1: the share of each sub-ray that goes on through an object's "
                        "surface and comes back, in [0, 1] (a leafy crown's gap fraction); table (foliage 0.3 from the reflectance "
                        "table), one number (every object), or CLASS=VALUE,... (bush=0.3,tree=0.3; a mesh's class: its file name) "
                        "(default: 0, opaque; airborne: see --reflectance-table)")  # fmt: skip
    r.add_argument("--footprint-cast", choices=FOOTPRINT_MODES, default=None,
                   help="how a footprint whose echoes are resolved is cast: adaptive casts a pulse's sub-rays only where its "
                        "centre ray and its neighbouring pulses do not all meet one plane, and gives the others that plane's echo "
                        "(the echo of a surface inside the cone that neither meets is lost); exact casts every sub-ray (slower); "
                        "auto is adaptive where it applies (the embree backend), else exact; a depth camera casts no footprint "
                        "and refuses it (default: auto)")  # fmt: skip
    r.add_argument(
        "--return-mode", choices=RETURN_MODES, default=None,
        help="which echoes of a pulse the receiver records: all (up to --max-returns, in range order), first, strongest or last "
        "(one: Hesai's single-return modes, Velodyne's strongest and last), dual (the last and the strongest, Velodyne's dual mode); all but 'all' "
        "need --range-resolution (default: the sensor's, 'all' for presets)",
    )  # fmt: skip
    r.add_argument(
        "--echo-rule", choices=ECHO_RULES, default=None,
        help="with resolved echoes (--max-returns above 1 or --return-mode): how a pulse's sub-ray hits merge into echoes: "
        "chain (a new echo at a gap of --range-resolution after the previous hit) or waveform (one echo per peak of the pulse's "
        "summed waveform, split where it dips: returns per pulse that do not drift with the sub-ray count) "
        "(default: the sensor's, chain for presets)",
    )  # fmt: skip
