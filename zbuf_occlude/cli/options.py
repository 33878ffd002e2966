"""Options and wording shared by the commands: one name per meaning, one checker per kind of value.

Every counted, seeded, real-valued, pose or output option of every command is checked while the
command line is parsed, before a mesh is read or anything is written: the option's action
(:class:`Checked`) runs one checker of this module on the text given, and a refused value raises
:class:`~zbuf_occlude.errors.InvalidInputError` naming the option as typed and the value, which
``cli.main`` prints on one line with exit status 2.  Counts are capped by the ``MAX_*`` constants of
:mod:`zbuf_occlude.defaults`, looked up when a value is checked.
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

from zbuf_occlude import defaults
from zbuf_occlude.errors import InvalidInputError

__all__ = [
    "Parser", "Checked", "counted", "given_params", "count", "count_list", "seed", "real", "elevations", "interval", "parse_interval", "out_folder", "poses",
    "check_device", "shown",
]  # fmt: skip

#: A checker: ``(text, option) -> value``, raising InvalidInputError naming ``option`` and ``text``.
Check = Callable[[str, str], Any]

#: Characters of a value quoted in a message (an argument of 40 MB is not echoed whole).
SHOWN_CHARS = 60
#: Digits parsed as a count at most: a longer number is past every cap without int() reading it.
COUNT_DIGITS = 30


def shown(text: object) -> str:
    """``text`` for a message: as it is when short and plain (``-1``), else quoted, cut to
    :data:`SHOWN_CHARS` characters (an argument of 40 MB is not echoed whole)."""
    text = str(text)
    if len(text) > SHOWN_CHARS:
        return f"{text[:SHOWN_CHARS]!r}... ({len(text):,} characters)"
    plain = text and text.isprintable() and not any(c.isspace() for c in text)
    return text if plain else repr(text)


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` that takes options only as spelled (no abbreviations: ``--sample`` is not
    ``--samples-per-view``); its sub-commands are made of this class too (``add_subparsers``' default),
    and so take no abbreviation either, which argparse does not pass down by itself."""

    def __init__(self, *args: Any, allow_abbrev: bool = False, **kwargs: Any) -> None:
        super().__init__(*args, allow_abbrev=allow_abbrev, **kwargs)


class Checked(argparse.Action):
    """An option whose text, when given, is parsed and checked by ``check(text, option)``.

    The value stored is what ``check`` returns.  ``check`` raises InvalidInputError, which
    argparse does not catch in an action: ``cli.main`` prints it on one line and exits 2.
    """

    def __init__(self, option_strings: list[str], dest: str, *, check: Check, **kwargs: Any) -> None:
        self.check = check
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        setattr(namespace, self.dest, self.check(values, option_string or self.dest))
        # which options were given, beside their values (a default and a given equal value look alike)
        setattr(namespace, GIVEN, frozenset({*getattr(namespace, GIVEN, ()), self.dest}))


#: The ``args`` attribute that holds the destinations of the :class:`Checked` options given.
GIVEN = "given_options"


def given_params(args: argparse.Namespace, fields: dict[str, str]) -> frozenset[str]:
    """The :class:`~zbuf_occlude.farm.FarmParams` fields whose :class:`Checked` option was given on the
    command line: ``fields`` maps a field to its ``args`` attribute (the library then tells an option
    that does nothing for the inputs from one left out, :attr:`~zbuf_occlude.farm.RunOptions.set_params`)."""
    given = getattr(args, GIVEN, frozenset())
    return frozenset(field for field, attr in fields.items() if attr in given)


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``"1 mesh"``, ``"2 meshes"``: ``n`` and the noun in the number it takes (``plural``: default ``noun + "s"``)."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


# -- the checkers ----------------------------------------------------------------------------------
def _whole(text: str) -> int | None:
    """``text`` as a whole number (Python's int syntax), None if it is not one; a number of more
    than :data:`COUNT_DIGITS` digits is returned as 10**COUNT_DIGITS (past every cap) unparsed."""
    text = text.strip()
    if len(text) > COUNT_DIGITS:
        digits = text.lstrip("+-")
        return (-1 if text.startswith("-") else 1) * 10**COUNT_DIGITS if digits.isdecimal() else None
    try:
        return int(text)
    except ValueError:
        return None


def _check_count(value: int | None, text: str, option: str, cap_name: str | None, lowest: int, hint: str = "") -> int:
    if value is None:
        raise InvalidInputError(f"{option} must be a whole number, got {shown(text)}")
    if value < lowest:
        raise InvalidInputError(f"{option} must be an integer >= {lowest}{f' ({hint})' if hint else ''}, got {shown(text)}")
    cap = getattr(defaults, cap_name) if cap_name else None
    if cap is not None and value > cap:
        raise InvalidInputError(f"{option} must be at most {cap:,} ({cap_name}), got {shown(text)}")
    return value


def resamples(text: str, option: str) -> int:
    """``--bootstrap N``: bootstrap resamples, 2 to the fits' cap (:func:`~zbuf_occlude.sensors.fit.lidar.check_bootstrap`)."""
    from zbuf_occlude.sensors.fit.lidar import check_bootstrap

    return check_bootstrap(count(None, lowest=2, hint="a spread needs two resamples")(text, option), name=option)


def count(cap_name: str | None, *, lowest: int = 1, hint: str = "") -> Check:
    """A count from ``lowest`` to the cap ``zbuf_occlude.defaults.<cap_name>`` (None: no cap, a selection
    such as ``--per-class`` that allocates nothing); ``hint`` says what ``lowest`` means."""

    def check(text: str, option: str) -> int:
        return _check_count(_whole(text), text, option, cap_name, lowest, hint)

    return check


def count_list(cap_name: str, *, lowest: int = 1, empty: bool = False) -> Check:
    """Comma-separated counts (``1000,10000,50k``: ``k`` is 1,000), each checked as :func:`count`, at
    most :data:`~zbuf_occlude.defaults.MAX_LIST_VALUES` of them; returns the list of ints (``empty``:
    a blank list is ``[]``, no values)."""

    def check(text: str, option: str) -> list[int]:
        if text.count(",") + 1 > defaults.MAX_LIST_VALUES:  # counted before the split
            raise InvalidInputError(f"{option} must list at most {defaults.MAX_LIST_VALUES:,} values (MAX_LIST_VALUES), got {shown(text)}")
        values = []
        for item in (i.strip() for i in text.split(",")):
            if not item:
                continue
            thousands = item.lower().endswith("k")
            value = _whole(item[:-1] if thousands else item)
            values.append(_check_count(None if value is None else value * (1000 if thousands else 1), item, option, cap_name, lowest))
        if not values and not empty:
            raise InvalidInputError(f"{option} must list one or more whole numbers, got {shown(text)}")
        return values

    return check


def seed(text: str, option: str) -> int:
    """A seed: a whole number from 0 to :data:`~zbuf_occlude.defaults.MAX_SEED` (2**63 - 1), the one rule of every command."""
    from zbuf_occlude.geometry.sampling import check_seed  # the library's rule, numpy only

    value = _whole(text)
    if value is None:
        raise InvalidInputError(f"{option} must be a non-negative integer, got {shown(text)}")
    return check_seed(value, name=option)


def real(low: float | None = None, high: float | None = None, *, above: bool = False, unit: str = "") -> Check:
    """A finite real number, ``>= low`` (``> low`` with ``above``) when ``low`` is given and ``<= high`` when
    ``high`` is; ``unit`` (``"metres"``) is named in the message."""
    units = f" {unit}" if unit else ""

    def check(text: str, option: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise InvalidInputError(f"{option} must be a finite number{units and ' of' + units}, got {shown(text)}")
        if low is not None and (value <= low if above else value < low):
            raise InvalidInputError(f"{option} must be a number {'>' if above else '>='} {low:g}{units}, got {shown(text)}")
        if high is not None and value > high:
            raise InvalidInputError(f"{option} must be a number <= {high:g}{units}, got {shown(text)}")
        return value

    return check


def elevations(text: str, option: str) -> list[float]:
    """Comma-separated elevations, degrees, each finite and in [-90, 90], at most
    :data:`~zbuf_occlude.defaults.MAX_VIEWS` of them; a blank list is ``[]``."""
    if text.count(",") + 1 > defaults.MAX_VIEWS:  # counted before the split
        raise InvalidInputError(f"{option} must list at most {defaults.MAX_VIEWS:,} elevations (MAX_VIEWS), got {shown(text)}")
    values = []
    for item in (i.strip() for i in text.split(",")):
        if item:
            value = real(-90.0)(item, option)
            if value > 90.0:
                raise InvalidInputError(f"{option} must be elevations in [-90, 90] degrees, got {shown(item)}")
            values.append(value)
    return values


def parse_interval(text: str, option: str) -> tuple[float, float]:
    """``"10"`` → (10, 10); ``"5:25"`` → (5, 25) (a uniform draw per sample); finite numbers only.

    Raises InvalidInputError naming ``option`` and the text.
    """
    quoted = repr(str(text)) if len(str(text)) <= SHOWN_CHARS else shown(text)
    try:
        parts = [float(v) for v in str(text).split(":", 2)]
    except ValueError:
        raise InvalidInputError(f"{option} must be a number or LO:HI, got {quoted}") from None
    if not all(math.isfinite(v) for v in parts):
        raise InvalidInputError(f"{option} must be finite numbers, N or LO:HI, got {quoted}")
    if len(parts) == 1:
        parts *= 2
    if len(parts) != 2 or not parts[0] <= parts[1]:
        raise InvalidInputError(f"{option} must be a number or LO:HI with LO <= HI, got {quoted}")
    return parts[0], parts[1]


def interval(text: str, option: str) -> str:
    """A number or ``LO:HI`` (:func:`parse_interval`), checked; the text is kept for the command to parse."""
    parse_interval(text, option)
    return text


def out_folder(text: str, option: str) -> str:
    """An output folder: not blank, not an existing file, and no file where one of its parents would go.

    Raises InvalidInputError naming ``option`` and the value (``farm.checks.check_out_option`` for a blank one).
    """
    from zbuf_occlude.farm.checks import check_out_option

    check_out_option(text, option)
    path = Path(text)
    for folder in (path, *path.parents):
        if os.path.isdir(folder):
            break
        if os.path.lexists(folder):
            kind = "a file" if os.path.exists(folder) else "a link to nothing"
            if folder == path:
                raise InvalidInputError(f"{option} {text}: the output folder {path} is {kind}, not a folder; choose another {option}")
            raise InvalidInputError(
                f"{option} {text}: {folder} is {kind}, not a folder, so no folder can be made in it; choose another {option}"
            )
    return text


def poses(text: str, option: str) -> str:
    """A pose schedule (:func:`~zbuf_occlude.geometry.cameras.view_schedule`: at most ``MAX_VIEWS`` poses); the text is kept."""
    from zbuf_occlude.geometry.cameras import view_schedule

    try:
        view_schedule(text)
    except InvalidInputError as exc:
        raise InvalidInputError(f"{option}: {exc}") from None
    return text


def check_device(name: str) -> None:
    """Refuse ``--device name`` before any work when torch cannot run there; the message says what is missing.

    Raises BackendUnavailable (:func:`zbuf_occlude.learn.training.resolve_device`).
    """
    from zbuf_occlude.learn import require_torch

    require_torch()
    from zbuf_occlude.learn.training import resolve_device

    resolve_device(name)
