"""The table of families: name → :class:`Family` (class folder, generator, drawn ranges, open parts).

A new family is one module (``NAME``, ``CLASS_NAME``, ``RANGES``, ``OPEN_PARTS``, ``parts(rng)``)
and one entry in :data:`_MODULES`.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.mesh.families import hedge, pedestrian, shrub, sign_post, street_light, tree, trunk, utility_pole
from zbuf_occlude.mesh.families.parts import assemble

__all__ = ["FAMILIES", "Family", "family_rng", "get_family"]

if TYPE_CHECKING:
    import trimesh

    Parts = dict[str, list[trimesh.Trimesh]]


@dataclass(frozen=True)
class Family:
    """One family of procedural objects.

    Attributes
    ----------
    name : str
        The family (``"utility_pole"``); files are named ``<name>_<k>.ply``.
    class_name : str
        The class folder its files go to (``"pole"``).
    parts : callable
        ``parts(rng) -> (parts, params)``: the named parts (metres, z up, on z = 0) and the drawn parameters.
    ranges : mapping
        Each drawn parameter's ``(low, high)``, as cited in the module's docstring.
    open_parts : frozenset of str
        The parts that are open by design (wires, foliage with gaps); every other part is closed.
    module : str
        The module that holds the generator and its citations.
    """

    name: str
    class_name: str
    parts: Callable[[np.random.Generator], tuple[Parts, dict[str, Any]]]
    ranges: Mapping[str, tuple[float, float]]
    open_parts: frozenset[str]
    module: str

    @classmethod
    def of(cls, module: ModuleType) -> Family:
        """The family a module declares."""
        return cls(module.NAME, module.CLASS_NAME, module.parts, module.RANGES, module.OPEN_PARTS, module.__name__)

    def make(self, rng: np.random.Generator) -> tuple[trimesh.Trimesh, dict[str, Any]]:
        """One object: its parts as one mesh (metres, z up, standing on z = 0) and its drawn parameters."""
        pieces, params = self.parts(rng)
        return assemble(pieces), params


_MODULES = (trunk, shrub, hedge, tree, utility_pole, street_light, sign_post, pedestrian)
#: Every family, by name.
FAMILIES: dict[str, Family] = {m.NAME: Family.of(m) for m in _MODULES}


def get_family(name: str) -> Family:
    """The family called ``name``.

    Raises
    ------
    InvalidInputError
        No family has that name (the message lists the families).
    """
    try:
        return FAMILIES[name]
    except (KeyError, TypeError):
        raise InvalidInputError(f"no family {name!r}; the families are {', '.join(FAMILIES)}") from None


def family_rng(name: str, seed: int, index: int) -> np.random.Generator:
    """The generator of object ``index`` of family ``name`` under ``seed``: ``default_rng([seed, index, crc32(name)])``,
    so each file is reproducible alone and two families under one seed draw independent streams."""
    return np.random.default_rng([int(seed), int(index), zlib.crc32(name.encode("utf-8"))])
