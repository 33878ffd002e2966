"""Checks of the fields of scenes and sensors: one checker per kind of value, and the limits.

A scene or sensor file may come from anyone, and a field of :class:`~zbuf_occlude.sensors.scene.objects.SceneObject`,
:class:`~zbuf_occlude.sensors.scene.objects.ScanScene`, :class:`~zbuf_occlude.sensors.patterns.spinning.Lidar`,
:class:`~zbuf_occlude.sensors.patterns.airborne.AirborneScanner` or
:class:`~zbuf_occlude.sensors.patterns.depth_camera.DepthCamera` is checked where the dataclass is made
(``__post_init__``), by the functions here, whether it came from a file or from Python.  Each
raises :class:`~zbuf_occlude.errors.InvalidInputError` whose message starts with the field's
name and says what is expected (``yaw_deg must be a finite number, got NaN``); a file reader
puts the file and the place in the file in front (:func:`located`).

The rules every numeric field follows:

* a number is an ``int`` or a ``float`` (numpy's too); ``True`` is not a number (JSON's
  ``true`` would read as 1), nor is the string ``"5"``;
* it is finite: NaN and ±inf are refused (Python's ``json`` reads ``NaN`` and ``Infinity``;
  YAML has ``.nan`` and ``.inf``), and so is an integer too large for a float (``10**400``);
* a count is a whole number (``3`` or ``3.0``) within its named limit.

A message never quotes a value: the file may be anyone's (a class map linked to a credentials
file holds a token).  It names the field, what is expected, and what kind of thing was found and
its size (:func:`value_kind`: ``got a string of 41 characters``, ``got an object of 1 key``, ``got
NaN``, ``got a number outside that range``).  A key may be named, cut (:func:`key_text`).
"""

from __future__ import annotations

import math
import numbers
import unicodedata
from collections.abc import Collection, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.file_errors import key_text, value_kind

__all__ = [
    "MAX_COORDINATE_M", "MAX_RANGE_M", "MAX_SENSOR_RAYS", "MAX_SCENE_OBJECTS", "MAX_NAME_CHARS", "MAX_PATH_CHARS",
    "SHOWN_CHARS", "value_kind", "key_text", "given", "located", "is_number", "real", "count", "reals", "mapping", "text", "sensor_name", "preset", "replaced",
    "namer",
]  # fmt: skip

#: Largest coordinate or size in a scene, metres: the scene is ray-cast in float32 (Embree),
#: whose 24-bit mantissa keeps 1 mm steps up to 2**24 mm ≈ 16.8 km from the origin.
MAX_COORDINATE_M = 2.0**24 * 1e-3
#: Largest range, altitude, depth or noise σ of a sensor, metres (1,000 km): past the range of
#: any LiDAR, and small enough that its square (the range equation) is a finite float.
MAX_RANGE_M = 1e6
#: Most rays one LiDAR revolution, one camera frame or one airborne scan casts (before a 7-ray
#: footprint): 16 times the densest preset's revolution (HDL-64E: 64 × 4,000), a 2048 × 2048
#: camera, or 290 m × 290 m of ground at the ``dales-q1560`` survey's 51 points/m².  Each ray
#: costs ~100–200 bytes while a scan runs, so this bounds a scan to well under 1 GB.
MAX_SENSOR_RAYS = 2**22
#: Most objects and occluders one scene file may hold.  Each is built separately; a street
#: scene holds hundreds.
MAX_SCENE_OBJECTS = 10_000
#: Longest sensor name: it becomes part of output file names.
MAX_NAME_CHARS = 100
#: Longest mesh path a scene file may give (Linux's PATH_MAX).
MAX_PATH_CHARS = 4096
#: Characters of a key (or of a name the caller typed) quoted in a message; a value is never quoted.
SHOWN_CHARS = 80


def given(name: object) -> str:
    """``repr(name)`` cut to :data:`SHOWN_CHARS` characters: for a name the caller typed (a preset
    asked for on the command line or in Python), never for a value read from a file."""
    text = repr(name) if isinstance(name, str) else value_kind(name)
    return text if len(text) <= SHOWN_CHARS else text[: SHOWN_CHARS - 3] + "..."


def namer(names: Mapping[str, str | None] | None):
    """``n(field, default=None)``: how a caller calls ``field`` in a rule's message, ``names`` being its field → option map
    (``{"max_returns": "--max-returns"}``); ``default``, else the field's own name, where the map does not name it.  The one
    way every rule of :mod:`zbuf_occlude.sensors` words its refusals, so that a command never restates a rule and the
    library never spells an option."""
    table = names or {}
    return lambda field, default=None: table.get(field) or default or field


@contextmanager
def located(where: str) -> Iterator[None]:
    """Put ``where`` (a file, ``objects[2]``) in front of the message of an InvalidInputError
    raised inside: ``scene.yaml: objects[2]: yaw_deg must be ...``.  The error keeps its type
    (an UnsafePathError stays one)."""
    try:
        yield
    except InvalidInputError as exc:
        raise type(exc)(f"{where}: {exc}") from None


def is_number(value: object) -> bool:
    """A real number from Python or numpy, not a bool (JSON's ``true`` would read as 1), not a string."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _as_float(value: object) -> float:
    """``float(value)`` of a number; NaN for an integer too large for a float (``10**400``)."""
    try:
        return float(value)  # type: ignore[arg-type]
    except OverflowError:
        return math.nan


def _range_text(low: float | None, high: float | None, low_open: bool, high_open: bool) -> str:
    """`` in (0, 1]``, `` > 0`` or `` <= 90``: the bounds for a message."""
    lo = None if low is None else f"{'>' if low_open else '>='} {low:.10g}"
    hi = None if high is None else f"{'<' if high_open else '<='} {high:.10g}"
    if lo and hi:
        return f" in {'(' if low_open else '['}{low:.10g}, {high:.10g}{')' if high_open else ']'}"
    return f" {lo or hi}" if lo or hi else ""


def _refused(name: str, expected: str, value: object, found: str | None = None) -> InvalidInputError:
    """The one refusal of a checker: ``"{name} must be {expected}, got {found}"``, ``found`` what the checker saw (``a
    number outside that range``), else the kind of value (:func:`value_kind`), never the value."""
    found = found or value_kind(value)
    return InvalidInputError(f"{name} must be {expected}, got {found}")


def real(
    value: object, name: str, *, low: float | None = None, high: float | None = None, low_open: bool = False,
    high_open: bool = False, expected: str | None = None,
) -> float:  # fmt: skip
    """``value`` as a float, checked: a number, finite, within ``[low, high]`` (or open ends).

    Parameters
    ----------
    value : object
    name : str
        The field, first word of the message.
    low, high : float, optional
        Bounds (None: none); ``low_open`` / ``high_open`` exclude them.
    expected : str, optional
        What the message says the value must be (default: ``a finite number`` and the range).

    Raises
    ------
    InvalidInputError
        ``"{name} must be {expected}, got {what}"``, ``what`` the kind of value found
        (:func:`value_kind`, ``NaN``) or ``a number outside that range``, never the value.
    """
    v = _as_float(value) if is_number(value) else math.nan
    ok = math.isfinite(v)
    if ok and low is not None:
        ok = v > low if low_open else v >= low
    if ok and high is not None:
        ok = v < high if high_open else v <= high
    if not ok:
        expected = expected or "a finite number" + _range_text(low, high, low_open, high_open)
        raise _refused(name, expected, value, "a number outside that range" if math.isfinite(v) else None)
    return v


def count(value: object, name: str, *, low: int, high: int) -> int:
    """``value`` as an int: a whole number (``3`` or ``3.0``, not ``True``) from ``low`` to ``high``.

    Raises
    ------
    InvalidInputError
        ``"{name} must be an integer from {low} to {high}, got {what}"``, ``what`` the kind of value
        found (:func:`value_kind`), ``a number that is not whole`` or ``a whole number outside that
        range``, never the value.
    """
    finite = is_number(value) and math.isfinite(_as_float(value))
    whole = finite and float(value).is_integer()  # type: ignore[arg-type]
    if not (whole and low <= int(value) <= high):  # type: ignore[call-overload]
        found = ("a whole number outside that range" if whole else "a number that is not whole") if finite else None
        raise _refused(name, f"an integer from {low} to {high}", value, found)
    return int(value)  # type: ignore[call-overload]


def reals(
    value: object, name: str, *, lengths: Collection[int] | None = None, max_length: int | None = None,
    low: float | None = None, high: float | None = None, low_open: bool = False, high_open: bool = False,
    expected: str | None = None,
) -> tuple[float, ...]:  # fmt: skip
    """``value`` as a tuple of floats: a list, tuple or 1-D array of numbers, each as :func:`real` checks.

    Parameters
    ----------
    lengths : collection of int, optional
        The lengths allowed (e.g. ``(2, 3)``); default: any length from 1 to ``max_length``.
    max_length : int, optional
        Longest sequence accepted (checked before any item is).
    expected : str, optional
        What the message says the sequence must be.

    Raises
    ------
    InvalidInputError
        Not a sequence, a wrong length, or an item that :func:`real` refuses (the message
        names the item: ``position_m[1]``).
    """
    if isinstance(value, np.ndarray):
        value = value.tolist() if value.ndim == 1 else None
    n = len(value) if isinstance(value, (list, tuple)) else -1
    fits = n in lengths if lengths is not None else 1 <= n <= (max_length or n)
    if not fits:
        if expected is None:
            if lengths is not None:
                expected = f"a list of {' or '.join(str(k) for k in sorted(lengths))} numbers"
            else:
                expected = f"a list of 1 to {max_length:,} numbers" if max_length else "a list of one or more numbers"
        raise _refused(name, expected, value)
    return tuple(real(v, f"{name}[{i}]", low=low, high=high, low_open=low_open, high_open=high_open) for i, v in enumerate(value))  # type: ignore[arg-type]


def mapping(value: object, name: str, allowed: Collection[str], *, required: Collection[str] = ()) -> dict[str, Any]:
    """``value`` if it is a mapping whose keys are among ``allowed`` and include ``required``.

    Raises
    ------
    InvalidInputError
        Not a mapping (saying what it is), an unknown key (named, cut: :func:`key_text`, with the keys
        allowed), or a missing one.
    """
    if not isinstance(value, Mapping):
        raise _refused(name, f"a mapping of {', '.join(allowed)}", value)
    unknown = [k for k in value if k not in allowed]
    if unknown:
        first = sorted(unknown[:5], key=lambda k: (not isinstance(k, str), k if isinstance(k, str) else ""))
        keys = ", ".join(key_text(k) for k in first) + (f" and {len(unknown) - 5:,} more" if len(unknown) > 5 else "")
        raise InvalidInputError(f"unknown {name} keys {keys}; allowed: {', '.join(allowed)}")
    missing = [k for k in required if k not in value]
    if missing:
        raise InvalidInputError(f"{name} needs {', '.join(missing)}")
    return dict(value)


def text(value: object, name: str, *, choices: Collection[str] | None = None) -> str:
    """``value`` if it is a string (one of ``choices`` when given).

    Raises
    ------
    InvalidInputError
        Not a string, or not one of ``choices`` (``got another string of 5 characters``).
    """
    if not isinstance(value, str) or (choices is not None and value not in choices):
        expected = f"one of {', '.join(repr(c) for c in choices)}" if choices is not None else "a string"
        found = value_kind(value)
        raise InvalidInputError(f"{name} must be {expected}, got {'another ' + found[2:] if isinstance(value, str) and value else found}")
    return value


def sensor_name(value: object, what: str) -> str:
    """``value`` if it can name a sensor: a string of 1 to :data:`MAX_NAME_CHARS` printable
    characters without ``/`` or ``\\`` (it becomes part of output file names and of a PLY
    header line), not ``.`` or ``..``.

    Raises
    ------
    InvalidInputError
        Naming ``what`` (``lidar name``) and the kind of value found, never the value.
    """
    ok = isinstance(value, str) and 1 <= len(value) <= MAX_NAME_CHARS and value not in (".", "..")
    if ok and (any(c in "/\\" for c in value) or any(unicodedata.category(c)[0] in "CZ" and c != " " for c in value)):  # type: ignore[union-attr]
        ok = False
    if not ok:
        raise InvalidInputError(
            f"{what} must be 1 to {MAX_NAME_CHARS} printable characters without '/' or '\\' (it names output files), got "
            + (
                f"{value_kind(value)} holding '/', '\\' or a control character, or naming '.' or '..'"
                if isinstance(value, str) and 1 <= len(value) <= MAX_NAME_CHARS
                else value_kind(value)
            )
        )
    return value  # type: ignore[return-value]


def preset(presets: Mapping[str, Any], name: object, what: str, **changes) -> Any:
    """The preset ``name`` (any case) of a kind's table ``presets``, with optional field changes (checked again).

    The one lookup of :func:`~zbuf_occlude.sensors.patterns.spinning.lidar_preset`,
    :func:`~zbuf_occlude.sensors.patterns.airborne_presets.airborne_preset` and
    :func:`~zbuf_occlude.sensors.patterns.depth_camera.depth_camera_preset`; ``what`` names the table in the
    message ("lidar preset").

    Raises
    ------
    InvalidInputError
        Unknown name, naming the presets there are.
    """
    key = str(name).lower()
    if key not in presets:
        raise InvalidInputError(f"unknown {what} {given(name)}; choose one of {sorted(presets)}")
    return replaced(presets[key], **changes) if changes else presets[key]


def replaced(obj: Any, **changes) -> Any:
    """``dataclasses.replace(obj, **changes)``, the copy checked again by its class, naming unknown fields first.

    The one ``with_`` of the sensors and the beam.

    Raises
    ------
    InvalidInputError
        A field ``obj``'s class does not have (a beam's field given to a scanner is named as one), or what
        the class refuses.
    """
    from dataclasses import fields, replace

    known = {f.name for f in fields(obj) if f.init}
    unknown = sorted(set(changes) - known)
    if unknown:
        beam_fields = {f.name for f in fields(obj.beam)} & set(unknown) if "beam" in known else set()
        hint = f" ({', '.join(sorted(beam_fields))}: the beam's; change them with with_beam)" if beam_fields else ""
        raise InvalidInputError(f"{type(obj).__name__} has no field {', '.join(unknown)}{hint}; its fields: {', '.join(sorted(known))}")
    return replace(obj, **changes)
