"""Options and wording shared by the commands: one name per meaning, old spellings kept for one release."""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["RenamedOption", "add_renamed", "counted"]


class RenamedOption(argparse.Action):
    """An old spelling of an option: stores into the new option's ``dest`` and says so on stderr."""

    def __init__(self, option_strings: list[str], dest: str, *, new: str, **kwargs: Any) -> None:
        self.new = new
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(f"{parser.prog}: {option_string} is deprecated here and goes in the next release: use {self.new}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_renamed(parser: argparse.ArgumentParser, old: str, new: str, dest: str, **kwargs: Any) -> None:
    """Accept ``old`` as a hidden spelling of the option ``new`` (stored in ``dest``)."""
    parser.add_argument(old, dest=dest, action=RenamedOption, new=new, help=argparse.SUPPRESS, **kwargs)


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``"1 mesh"``, ``"2 meshes"``: ``n`` and the noun in the number it takes (``plural``: default ``noun + "s"``)."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"
