"""ASPRS classes of a simulated scan's points: the rule by class name and height, and a user's class map.

A LAS file's ``classification`` (ASPRS LAS 1.4 specification R15, "ASPRS Standard Point Classes
(Point Data Record Formats 6-10)") is given per point from the scene object the point lies on
(its class name, index 0 the ground) and its height above the ground, as a national survey
classifies its points (:func:`asprs_classification`):

* the ground (object 0) is **2**;
* an object whose class names vegetation (:data:`VEGETATION_NAMES`) is **3**, **4** or **5**, low,
  medium or high vegetation, by the point's height above the ground: below 0.5 m, 0.5 to 1.5 m,
  1.5 m and above (:data:`VEGETATION_HEIGHTS_M`, IGN LiDAR HD's classes);
* an object whose class names a building (:data:`BUILDING_NAMES`) is **6**;
* any other object is **1**, unclassified (classified, but in no standard class: R15 keeps 0 for
  points never classified).

A class name names vegetation or a building when one of its words (split at anything but letters
and digits, lower case) is one of the names, or that name with an ``s`` or ``es``: ``oak_tree``,
``Trees`` and ``hedge-row`` are vegetation, ``office building`` a building, ``treehouse`` neither.

A **class map** (:func:`load_class_map`: a JSON object of class name → ASPRS code, ``{"car": 1,
"oak_tree": 5}``) overrides the rule for the names it holds, matched exactly; its codes are
0 to 255 outside R15's reserved codes (:data:`RESERVED_CODES`).
"""

from __future__ import annotations

import numbers
import os
import re
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.checks import key_text, value_kind
from zbuf_occlude.io.spec_files import read_spec_file

__all__ = [
    "BUILDING_CODE", "BUILDING_NAMES", "GROUND_CODE", "MAX_CLASS_MAP_KEYS", "MAX_CLASS_NAME_CHARS", "RESERVED_CODES",
    "UNCLASSIFIED_CODE", "VEGETATION_CODES", "VEGETATION_HEIGHTS_M", "VEGETATION_NAMES", "asprs_classification",
    "check_class_map", "load_class_map", "rule_code",
]  # fmt: skip

#: ASPRS codes (R15, formats 6-10): unclassified, ground, building; low, medium, high vegetation.
UNCLASSIFIED_CODE, GROUND_CODE, BUILDING_CODE = 1, 2, 6
VEGETATION_CODES = (3, 4, 5)
#: Heights above the ground, metres, where low vegetation (3) ends and where medium (4) ends;
#: high vegetation (5) above.  IGN LiDAR HD's classes: "Végétation basse (< 50cm), Végétation
#: moyenne (50cm – 1 m50), Végétation haute (> 1 m 50)" (geoservices.ign.fr, "LiDAR HD – Point
#: sur les traitements", 20 April 2023).  IGN does not say where a point exactly at 0.5 or 1.5 m
#: goes: here it goes to the class above.
VEGETATION_HEIGHTS_M = (0.5, 1.5)
#: Words of a class name that make it vegetation: the plants of the scenes and data sets we scan
#: (ModelNet's ``plant``, scene files' ``tree`` and ``bush``) and the words of reflectance.py's foliage.
VEGETATION_NAMES = ("vegetation", "tree", "bush", "shrub", "hedge", "plant", "grass", "foliage", "leaf", "leaves", "canopy",
                    "conifer", "palm", "fern", "flower")  # fmt: skip
#: Words of a class name that make it a building (R15's class 6).  ``wall`` is not one: a garden
#: or a retaining wall is no building; map it with a class map where yours are.
BUILDING_NAMES = ("building", "house", "roof", "facade", "garage", "shed", "barn", "hut", "cabin")
#: Codes R15 reserves for formats 6-10 (8, 12, 23-63): a class map may not write them; 64-255 are
#: user definable.  Source: ASPRS LAS 1.4 R15, "ASPRS Standard Point Classes (Point Data Record
#: Formats 6-10)" (github.com/ASPRSorg/LAS, source/02.06_point.sub).
RESERVED_CODES = frozenset({8, 12, *range(23, 64)})
#: Most names a class map holds: a map of more is not a map of scene classes.
MAX_CLASS_MAP_KEYS = 1024
#: Longest class name a class map holds.
MAX_CLASS_NAME_CHARS = 256

_WORD = re.compile(r"[^a-z0-9]+")


def _names(name: str, words: Sequence[str]) -> bool:
    """Whether one of ``name``'s words is one of ``words`` (or its plural in ``s``/``es``)."""
    return any(w in words or (w.endswith("s") and w[:-1] in words) or (w.endswith("es") and w[:-2] in words)
               for w in _WORD.split(name.lower()) if w)  # fmt: skip


def rule_code(name: str) -> int:
    """The rule's code for an object of class ``name`` (module docstring): 6 for a building, 1 for
    anything but vegetation, and 3 (the caller splits it by height) for vegetation."""
    if _names(name, VEGETATION_NAMES):
        return VEGETATION_CODES[0]
    return BUILDING_CODE if _names(name, BUILDING_NAMES) else UNCLASSIFIED_CODE


def check_class_map(class_map: Mapping[str, int], where: str = "class map") -> dict[str, int]:
    """``class_map`` checked: at most :data:`MAX_CLASS_MAP_KEYS` names (non-empty strings of at most
    :data:`MAX_CLASS_NAME_CHARS` characters), each to a whole number 0 to 255 not in :data:`RESERVED_CODES`.

    Raises
    ------
    InvalidInputError
        Naming ``where`` and the key (cut: :func:`~zbuf_occlude.sensors.checks.key_text`): not a mapping,
        too many keys, a bad name, a code that is not a whole number (``true``, ``5.0``, a string, an
        object) or out of range or reserved.  The message says what kind of value was found, never the
        value: a class map may be a link to a private file.
    """
    if not isinstance(class_map, Mapping):
        raise InvalidInputError(f"{where}: must be a JSON object of class name to ASPRS code ({{\"car\": 1}}), got "
                                f"{value_kind(class_map)}")  # fmt: skip
    if len(class_map) > MAX_CLASS_MAP_KEYS:
        raise InvalidInputError(f"{where}: holds {len(class_map):,} class names; at most {MAX_CLASS_MAP_KEYS:,}")
    out = {}
    for key, code in class_map.items():
        if not isinstance(key, str) or not 0 < len(key) <= MAX_CLASS_NAME_CHARS:
            raise InvalidInputError(
                f"{where}: a class name must be 1 to {MAX_CLASS_NAME_CHARS} characters, got {'an empty one' if key == '' else key_text(key)}"
            )
        if isinstance(code, (bool, np.bool_)) or not isinstance(code, numbers.Integral) or not 0 <= code <= 255:
            found = (
                "a whole number outside that range"
                if isinstance(code, numbers.Integral) and not isinstance(code, (bool, np.bool_))
                else value_kind(code)
            )
            raise InvalidInputError(f"{where}: {key_text(key)}: the ASPRS code must be a whole number 0 to 255, got {found}")
        if int(code) in RESERVED_CODES:
            raise InvalidInputError(f"{where}: {key_text(key)}: the ASPRS code is one LAS 1.4 reserves (8, 12, 23-63); "
                                    "use a standard code or one of 64-255 (user definable)")  # fmt: skip
        out[key] = int(code)
    return out


def load_class_map(path: str | os.PathLike) -> dict[str, int]:
    """A class map file: a JSON object of class name → ASPRS code (``{"car": 1, "oak_tree": 5}``).

    Read by :func:`~zbuf_occlude.io.spec_files.read_spec_file` (a regular file of ``.json`` of at
    most :data:`~zbuf_occlude.io.caps.MAX_SPEC_FILE_BYTES`, UTF-8, nesting bounded), then checked
    by :func:`check_class_map`.

    Raises
    ------
    InvalidInputError
        One line naming the file (and the key): missing, a directory, a FIFO, too large, not JSON,
        nested too deep, or a map :func:`check_class_map` refuses.
    """
    return check_class_map(read_spec_file(path, what="class map", yaml_ok=False), str(path))


def asprs_classification(
    object_id: NDArray[np.integer],
    object_classes: Sequence[str],
    height_above_ground_m: NDArray[np.floating],
    class_map: Mapping[str, int] | None = None,
) -> NDArray[np.uint8]:
    """The ASPRS class of each point, by the rule (module docstring) or ``class_map``.

    Parameters
    ----------
    object_id : (N,) int
        The scene object each point lies on, 0 the ground, each ``< len(object_classes)``.
    object_classes : sequence of str
        Class name by object id; index 0 is the ground's.
    height_above_ground_m : (N,) float
        Each point's height above the ground plane, metres (world z minus the ground's z).
    class_map : mapping of str to int, optional
        Class name → ASPRS code, overriding the rule for the names it holds (:func:`check_class_map`).

    Returns
    -------
    (N,) uint8
        2 on object 0, 3/4/5 on vegetation by height, 6 on buildings, 1 elsewhere; a class map's code
        where it names the class.

    Raises
    ------
    InvalidInputError
        Arrays of other shapes, an object id outside ``object_classes``, a NaN height on vegetation,
        a class map :func:`check_class_map` refuses.
    """
    ids = np.asarray(object_id)
    height = np.asarray(height_above_ground_m, dtype=np.float64)
    if ids.ndim != 1 or ids.dtype.kind not in "iu" or height.shape != ids.shape:
        raise InvalidInputError(f"object_id must be (N,) integers and height_above_ground_m (N,) numbers, got {ids.shape} "
                                f"{ids.dtype} and {height.shape}")  # fmt: skip
    names = [str(n) for n in object_classes]
    if len(ids) and (ids.min() < 0 or ids.max() >= len(names)):
        raise InvalidInputError(f"object ids run from {ids.min()} to {ids.max()}, but object_classes names {len(names)} objects (0 to "
                                f"{len(names) - 1})")  # fmt: skip
    mapped = {} if class_map is None else check_class_map(class_map)
    codes = np.array([mapped.get(n, rule_code(n)) for n in names], dtype=np.uint8)  # per object
    if names and names[0] not in mapped:
        codes[0] = GROUND_CODE
    vegetation = np.array([n not in mapped and k > 0 and rule_code(n) == VEGETATION_CODES[0] for k, n in enumerate(names)], bool)
    out = codes[ids] if len(names) else np.zeros(0, np.uint8)
    on_plants = vegetation[ids] if len(names) else np.zeros(0, bool)
    if on_plants.any():
        h = height[on_plants]
        if not np.all(np.isfinite(h)):
            raise InvalidInputError(f"height_above_ground_m holds {int((~np.isfinite(h)).sum())} NaN/inf values on vegetation")
        low, medium = VEGETATION_HEIGHTS_M
        out[on_plants] = np.where(h < low, VEGETATION_CODES[0], np.where(h < medium, VEGETATION_CODES[1], VEGETATION_CODES[2]))
    return out
