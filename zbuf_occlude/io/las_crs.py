"""The coordinate reference system of a LAS or LAZ file: the one a scan may declare, and the unit one declares.

:func:`epsg_crs` is the CRS a scan's LAS file may declare (:func:`~zbuf_occlude.io.las.las_bytes`
writes it as a WKT VLR): the points are in metres on a plane, so the CRS must be a projected CRS
whose axes are in metres (EPSG:32633, a UTM zone), or a compound CRS of one and a vertical CRS in
metres (EPSG:2154+5720, Lambert-93 with NGF-IGN69 heights; a single code such as EPSG:7415 too).
A geographic CRS (degrees), a geocentric one (X, Y, Z through the Earth's centre), a vertical one
alone (a height, no plane) or one in feet are refused: a reader (this module's
:func:`linear_unit_m`, PDAL, LAStools) takes a file's x and y in the projected CRS's unit, and the
writer does not convert.

A LAS file (ASPRS LAS 1.4 specification R15, 2019) declares its CRS as an OGC WKT string (a WKT
VLR, WKT 1 or 2; required for point formats 6 to 10) or as GeoTIFF keys (a GeoKeyDirectory VLR).  :func:`linear_unit_m`
reads the metres per coordinate unit from the header laspy parsed: the unit of the projected CRS
of the WKT, or GeoTIFF's ProjLinearUnitsGeoKey (3076).  The WKT is parsed by a tokenizer of
bounded depth, never evaluated; anything not read (a geographic CRS, a malformed WKT, a unit code
not in the table) is NaN, unknown.  :mod:`zbuf_occlude.io.las` reads the points.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from zbuf_occlude._version import install_hint
from zbuf_occlude.errors import ArgumentTypeError, BackendUnavailable, InvalidInputError
from zbuf_occlude.geometry.arguments import described

__all__ = ["epsg_crs", "linear_unit_m"]

#: Digits of an EPSG code at most (codes run to 6 digits; 10 bounds int() of what is typed).
_EPSG_DIGITS = 10
#: What a scan's CRS must be, for messages.
SCAN_CRS_TEXT = ("a scan needs a projected CRS in metres (e.g. EPSG:32633), or one compound with a vertical CRS in metres "
                 "(e.g. EPSG:2154+5720)")  # fmt: skip

#: EPSG codes of ProjLinearUnitsGeoKey (3076) → metres (metre, international foot, US survey foot).
_GEOKEY_UNITS_M = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}
#: Keywords of a projected CRS: WKT 1's, and WKT 2's two spellings.
_PROJECTED_WKT = ("PROJCS", "PROJCRS", "PROJECTEDCRS")
#: Deepest WKT nesting read: real CRSs nest a handful deep; a forged ``[[[[...`` stops here, unknown.
_WKT_MAX_DEPTH = 64
#: A WKT token: a quoted string ("" escapes a quote), a keyword with its opening bracket, a closing bracket, a bare value.
_WKT_TOKEN = re.compile(r'"((?:[^"]|"")*)"|([A-Za-z_][A-Za-z0-9_]*)\s*[\[(]|([\])])|([^,\[\]()"\s]+)')


def epsg_crs(crs: int | str) -> Any:
    """The ``pyproj.CRS`` of an EPSG code, checked to be one a scan's points can be in.

    Parameters
    ----------
    crs : int or str
        An EPSG code: ``2154``, ``"EPSG:2154"``, or a compound of a horizontal and a vertical
        code, ``"EPSG:2154+5720"`` (PROJ's notation, as PDAL takes it).

    Returns
    -------
    pyproj.CRS
        A projected CRS whose axes are in metres, or a compound CRS of one and a vertical CRS in
        metres.

    Raises
    ------
    ArgumentTypeError
        ``crs`` neither an int nor a string.
    InvalidInputError
        Not ``EPSG:N`` or ``EPSG:H+V``, a code (or pair) PROJ does not know, or a CRS of another
        kind (geographic, geocentric, vertical alone, a compound whose horizontal part is not
        projected) or with an axis not in metres (a CRS in feet): a scan's coordinates are
        metres on a plane, written as they are.
    BackendUnavailable
        pyproj is not installed (the ``crs`` extra).
    """
    if isinstance(crs, bool) or not isinstance(crs, (int, np.integer, str)):
        raise ArgumentTypeError(f"crs must be an EPSG code (2154 or 'EPSG:2154'), got {described(crs)}")
    text = str(crs).strip()
    code = text[5:] if text[:5].upper() == "EPSG:" else text if not isinstance(crs, str) else ""
    parts = code.split("+")
    if not (len(parts) <= 2 and all(p.isascii() and p.isdecimal() and 0 < len(p) <= _EPSG_DIGITS for p in parts)):
        raise InvalidInputError(f"crs must be an EPSG code, EPSG:N (EPSG:2154) or EPSG:H+V (EPSG:2154+5720), got {described(crs)}")
    label = "EPSG:" + "+".join(str(int(p)) for p in parts)
    try:
        import pyproj
    except ImportError:
        raise BackendUnavailable(f"writing a CRS (crs={text}) needs pyproj: {install_hint('crs')}") from None
    try:
        out = pyproj.CRS.from_user_input(label)
    except pyproj.exceptions.CRSError:
        what = "a pair of a horizontal and a vertical CRS" if len(parts) == 2 else "a coordinate reference system"
        raise InvalidInputError(f"crs {label} is not {what} PROJ knows") from None
    subs = out.sub_crs_list if out.is_compound else [out]
    kinds = " + ".join(c.type_name[:1].lower() + c.type_name[1:] for c in subs)  # "geographic 2D CRS + vertical CRS"
    plane = subs[0].is_projected and not subs[0].is_compound
    height = len(subs) == 1 or (len(subs) == 2 and subs[1].is_vertical)
    units = ", ".join(sorted({axis.unit_name for axis in out.axis_info})) or "no unit"
    if not (plane and height):
        article = "an" if kinds[:1] in "aeiou" else "a"
        raise InvalidInputError(f"crs {label} ({out.name}) has axes in {units}: it is {article} {kinds}; {SCAN_CRS_TEXT}")
    if not out.axis_info or any(axis.unit_conversion_factor != 1.0 for axis in out.axis_info):
        raise InvalidInputError(f"crs {label} ({out.name}) has axes in {units}: a scan's points are written in metres, unconverted; "
                                f"{SCAN_CRS_TEXT}")  # fmt: skip
    return out


def linear_unit_m(header: Any) -> float:
    """Metres per coordinate unit from the WKT VLR (the projected CRS's unit) or GeoTIFF's ProjLinearUnitsGeoKey.

    Parameters
    ----------
    header : laspy.LasHeader
        The header laspy parsed.

    Returns
    -------
    float
        Metres per unit (0.3048 for international feet); NaN where the file does not say, or says
        it in a form not read (a geographic CRS, a malformed WKT, a unit code not in the table).
    """
    for vlr in header.vlrs.get("WktCoordinateSystemVlr"):
        found = _wkt_linear_unit_m(str(vlr.string))
        if math.isfinite(found):
            return found
    for vlr in header.vlrs.get("GeoKeyDirectoryVlr"):
        for key in vlr.geo_keys:
            if key.id == 3076 and key.tiff_tag_location == 0:
                return _GEOKEY_UNITS_M.get(int(key.value_offset), math.nan)
    return math.nan


def _wkt_tree(text: str) -> list | None:
    """``[KEYWORD, children]`` of a WKT (1 or 2) string, children strings or nodes; None when malformed."""
    root: list = ["", []]
    stack = [root]
    for quoted, keyword, close, bare in _WKT_TOKEN.findall(text):
        if keyword:
            node: list = [keyword.upper(), []]
            stack[-1][1].append(node)
            stack.append(node)
            if len(stack) > _WKT_MAX_DEPTH:
                return None
        elif close:
            if len(stack) == 1:
                return None
            stack.pop()
        else:
            stack[-1][1].append(quoted or bare)
    first = root[1][0] if root[1] else None
    return first if isinstance(first, list) else None


def _wkt_linear_unit_m(text: str) -> float:
    node = _wkt_tree(text)
    if node is not None and node[0] in ("COMPD_CS", "COMPOUNDCRS"):
        node = next((c for c in node[1] if isinstance(c, list) and c[0] in _PROJECTED_WKT), None)
    if node is None or node[0] not in _PROJECTED_WKT:
        return math.nan
    axes = [c for c in node[1] if isinstance(c, list) and c[0] == "AXIS"]
    for holder in [node, *axes]:  # WKT1 and WKT2 put the unit under the CRS; WKT2 may put it on each axis
        for c in holder[1]:
            if isinstance(c, list) and c[0] in ("UNIT", "LENGTHUNIT") and len(c[1]) > 1:
                try:
                    factor = float(c[1][1])
                except (TypeError, ValueError):
                    return math.nan
                return factor if math.isfinite(factor) and factor > 0 else math.nan
    return math.nan
