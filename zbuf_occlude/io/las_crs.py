"""The coordinate unit of a LAS or LAZ file, from the coordinate reference system its header declares.

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

__all__ = ["linear_unit_m"]

#: EPSG codes of ProjLinearUnitsGeoKey (3076) → metres (metre, international foot, US survey foot).
_GEOKEY_UNITS_M = {9001: 1.0, 9002: 0.3048, 9003: 1200.0 / 3937.0}
#: Keywords of a projected CRS: WKT 1's, and WKT 2's two spellings.
_PROJECTED_WKT = ("PROJCS", "PROJCRS", "PROJECTEDCRS")
#: Deepest WKT nesting read: real CRSs nest a handful deep; a forged ``[[[[...`` stops here, unknown.
_WKT_MAX_DEPTH = 64
#: A WKT token: a quoted string ("" escapes a quote), a keyword with its opening bracket, a closing bracket, a bare value.
_WKT_TOKEN = re.compile(r'"((?:[^"]|"")*)"|([A-Za-z_][A-Za-z0-9_]*)\s*[\[(]|([\])])|([^,\[\]()"\s]+)')


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
