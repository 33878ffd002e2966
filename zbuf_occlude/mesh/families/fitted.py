"""A families fit: per class, which families to add and how wide to draw them, as a JSON file.

A fit (:class:`FamiliesFit`) says, for each class of the user's real scans that a family writes to,
which families were chosen and each one's ``width_scale`` range: an object of the family is drawn
as :meth:`~zbuf_occlude.mesh.families.registry.Family.make` draws it, then stretched horizontally
(x and y, about its vertical axis; the height unchanged) by a factor drawn uniformly in that range
(:func:`widen`).  :func:`zbuf_occlude.experiments.family_fit.fit_families` makes one from real
crops; ``experiment sim2real --fit-families`` writes it as ``fitted_families.json``; and
``zbuf-occlude families FAMILY --fit FILE`` draws a family with the file's range.

The file is untrusted input: :func:`read_families_fit` checks every key and number it uses and
names the key at fault, never a value read from the file.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.file_errors import key_text, value_kind
from zbuf_occlude.io.json_files import read_json_file

if TYPE_CHECKING:
    import trimesh

    from zbuf_occlude.mesh.families.registry import Family, Parts

__all__ = ["FAMILIES_FIT_FORMAT", "MAX_WIDTH_SCALE", "MIN_WIDTH_SCALE", "ChosenFamily", "FamiliesFit", "check_width_scale",
           "draw_object", "parse_families_fit", "read_families_fit", "widen"]  # fmt: skip

#: The ``format`` key of a families fit file.
FAMILIES_FIT_FORMAT = "zbuf_occlude.families_fit/1"
#: The widest and the narrowest horizontal stretch a fit may draw: a tenth to ten times a family's own width.
MIN_WIDTH_SCALE, MAX_WIDTH_SCALE = 0.1, 10.0


def check_width_scale(value: object, what: str = "width_scale") -> tuple[float, float]:
    """``value`` as ``(lo, hi)`` with ``MIN_WIDTH_SCALE <= lo <= hi <= MAX_WIDTH_SCALE``.

    Raises
    ------
    InvalidInputError
        Not two finite numbers in that order and range; the message names ``what`` and what it found
        (its kind, not its value: it may come from a user's file).
    """
    ok = isinstance(value, (list, tuple)) and len(value) == 2
    pair = [v for v in value if isinstance(v, (int, float)) and not isinstance(v, bool)] if ok else []
    # an int is finite however large (math.isfinite(10**400) would raise OverflowError): compared exactly, then converted
    if len(pair) != 2 or not all(isinstance(v, int) or math.isfinite(v) for v in pair):
        raise InvalidInputError(f"{what} must be two numbers [lo, hi], got {value_kind(value)}")
    lo, hi = pair
    if not MIN_WIDTH_SCALE <= lo <= hi <= MAX_WIDTH_SCALE:
        raise InvalidInputError(f"{what} must hold {MIN_WIDTH_SCALE:g} <= lo <= hi <= {MAX_WIDTH_SCALE:g}")
    return float(lo), float(hi)


def widen(mesh: trimesh.Trimesh, rng: np.random.Generator, width_scale: tuple[float, float]) -> float:
    """Stretch ``mesh`` in place horizontally by a factor drawn uniformly in ``width_scale``, about the
    vertical axis through its base's centre (x and y times the factor, z unchanged); return the factor.

    The factor is drawn after the object (one more draw of ``rng``), so a fit changes an object's
    width and nothing else of it.
    """
    lo, hi = width_scale
    factor = float(rng.uniform(lo, hi))
    centre = mesh.bounds.mean(axis=0)
    t = np.diag([factor, factor, 1.0, 1.0])
    t[:2, 3] = centre[:2] * (1.0 - factor)
    mesh.apply_transform(t)
    return factor


def draw_object(
    family: Family, seed: int, index: int, width_scale: tuple[float, float] | None = None
) -> tuple[Parts, trimesh.Trimesh, dict[str, Any]]:
    """Object ``index`` of ``family`` under ``seed``: what ``zbuf-occlude families`` writes as file ``index``.

    Drawn from :func:`~zbuf_occlude.mesh.families.registry.family_rng`; with a fitted ``width_scale``
    (``(lo, hi)``), the assembled mesh is then stretched by :func:`widen` (one more draw of the same
    generator) and ``params["width_scale"]`` is its factor.

    Returns
    -------
    parts, mesh, params
        The named parts (before any stretch), them as one mesh (metres, z up, on z = 0) and the drawn parameters.
    """
    from zbuf_occlude.mesh.families.parts import assemble
    from zbuf_occlude.mesh.families.registry import family_rng

    rng = family_rng(family.name, seed, index)
    pieces, params = family.parts(rng)
    mesh = assemble(pieces)
    if width_scale is not None:
        params = {**params, "width_scale": widen(mesh, rng, width_scale)}
    return pieces, mesh, params


@dataclass(frozen=True)
class ChosenFamily:
    """One family of a fitted class: its ``width_scale`` range and its share of the class's added objects."""

    width_scale: tuple[float, float]
    share: float


@dataclass(frozen=True)
class FamiliesFit:
    """A families fit: per class, the chosen families (:class:`ChosenFamily`), and what the fit saw.

    Attributes
    ----------
    classes : mapping
        ``{class: {family: ChosenFamily}}``; the shares of a class sum to 1.
    record : dict
        The whole JSON document (what was measured, per family tried), as written.
    """

    classes: Mapping[str, Mapping[str, ChosenFamily]]
    record: dict = field(default_factory=dict, compare=False)

    def width_scale(self, family: str) -> tuple[float, float]:
        """The range ``family`` is drawn with.

        Raises
        ------
        InvalidInputError
            The fit chose no such family.
        """
        for chosen in self.classes.values():
            if family in chosen:
                return chosen[family].width_scale
        have = sorted(f for chosen in self.classes.values() for f in chosen)
        raise InvalidInputError(f"the fit chose no {family!r} family; it chose {', '.join(have) or 'none'}")

    def counts(self, per_class: int) -> dict[str, int]:
        """``{family: objects}``: ``per_class`` objects per class split by the shares (largest remainder)."""
        out: dict[str, int] = {}
        for chosen in self.classes.values():
            names = sorted(chosen)
            raw = np.array([chosen[f].share * per_class for f in names])
            n = np.floor(raw).astype(int)
            for i in np.argsort(-(raw - n), kind="stable")[: per_class - int(n.sum())]:
                n[i] += 1
            out.update({f: int(k) for f, k in zip(names, n) if k > 0})
        return out


def _object(doc: Any, where: str) -> dict:
    if not isinstance(doc, dict):
        raise InvalidInputError(f"{where} must be an object, got {value_kind(doc)}")
    return doc


def parse_families_fit(doc: Any, name: str = "the families fit") -> FamiliesFit:
    """A :class:`FamiliesFit` from a parsed document, checked (:func:`read_families_fit`)."""
    from zbuf_occlude.mesh.families.registry import FAMILIES

    doc = _object(doc, name)
    if doc.get("format") != FAMILIES_FIT_FORMAT:
        raise InvalidInputError(f"{name}: 'format' must be {FAMILIES_FIT_FORMAT!r} (a file that zbuf-occlude writes)")
    classes = _object(doc.get("classes"), f"{name}: 'classes'")
    out: dict[str, dict[str, ChosenFamily]] = {}
    for cls, entry in classes.items():
        where = f"{name}: classes.{key_text(cls)}"
        chosen = _object(_object(entry, where).get("chosen"), f"{where}.chosen")
        if not chosen:
            raise InvalidInputError(f"{where}.chosen holds no family")
        out[cls] = {}
        for fam, item in chosen.items():
            here = f"{where}.chosen.{key_text(fam)}"
            if fam not in FAMILIES:
                raise InvalidInputError(f"{here}: no such family; the families are {', '.join(FAMILIES)}")
            if FAMILIES[fam].class_name != cls:
                raise InvalidInputError(f"{here}: the family writes class {FAMILIES[fam].class_name!r}, not this class")
            item = _object(item, here)
            scale = check_width_scale(item.get("width_scale"), f"{here}.width_scale")
            share = item.get("share")
            if isinstance(share, bool) or not isinstance(share, (int, float)) or not 0 < share <= 1:
                raise InvalidInputError(f"{here}.share must be a number in (0, 1], got {value_kind(share)}")
            out[cls][fam] = ChosenFamily(scale, float(share))
        if abs(sum(c.share for c in out[cls].values()) - 1.0) > 1e-6:
            raise InvalidInputError(f"{where}.chosen: the shares must sum to 1")
    return FamiliesFit(out, doc)


def read_families_fit(path: str | os.PathLike) -> FamiliesFit:
    """Read a families fit file (``fitted_families.json``), checked.

    Raises
    ------
    InvalidInputError
        The file cannot be read (:func:`~zbuf_occlude.io.json_files.read_json_file`: a FIFO, too
        large, not JSON, too deep), is not a families fit, or holds a key of the wrong kind, an
        unknown family, a family under a class it does not write, a ``width_scale`` out of
        ``[MIN_WIDTH_SCALE, MAX_WIDTH_SCALE]`` or shares that do not sum to 1; the message names
        the file and the key, never a value read from it.
    """
    return parse_families_fit(read_json_file(path), str(path))
