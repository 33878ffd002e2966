"""Ray drop on vegetation (:attr:`Beam.foliage_dropout <zbuf_occlude.sensors.beam.fields.Beam.foliage_dropout>`) fitted to real object scans.

Real scans of bushes lose more firings than scans of cars, pedestrians and poles at the same
range: a footprint on leaves often meets too little of them for an echo.  A crown mesh is a
closed surface and cannot lose them.  The measure is ``fit-sensor``'s dropout
(:func:`~zbuf_occlude.sensors.fit.fit_lidar`: firings missing in gaps of at most
:data:`~zbuf_occlude.sensors.fit.MAX_DROPOUT_GAP` azimuth steps along a ring's run over the
object, pooled over scans, with its bootstrap over scans), taken separately over the scans of
**crown classes** (a class whose material is a crown's: :func:`is_crown_class`, "bush", "tree",
"hedge", ...) and of the other, **solid**, classes (:func:`dropout_by_surface`).

The fit (:func:`fit_foliage_dropout`) compares the real scans with meshes of the same classes
scanned without ray drop.  A class keeps ``1 − p`` of its firings; the contrast between crowns
and solid surfaces is ``S = (1 − p_crown) / (1 − p_solid)``.  Ray drop ``f`` on crown surfaces
multiplies the simulated crowns' share by ``1 − f`` and leaves solid surfaces alone, so

    f = 1 − S_real / S_simulated,

which holds for any loss that both groups have at the same rate (the sensor's own ``dropout``
where it does not change with range, holes that meshes and real objects share); a ``dropout``
growing with range enters it as far as the crowns and the solid objects stand at other ranges.  ``f`` is clipped to [0, 0.95]: real crowns that lose no more than
the meshes give 0.  Its standard deviation propagates the four rates' bootstrap deviations
(first order, relative errors in quadrature).  The trunk of a tree mesh whose file names it bark
is no crown surface; ``f`` is fitted as if the whole crop were crown, so its bushes' loss after
the fit is a little under the real one where trunks show.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP, Estimate, fit_lidar
from zbuf_occlude.sensors.scene.materials import CROWN_MATERIALS, material_named

__all__ = ["CROWN", "SOLID", "MAX_FOLIAGE_DROPOUT", "dropout_by_surface", "fit_foliage_dropout", "is_crown_class"]

#: The two groups of classes :func:`dropout_by_surface` measures.
CROWN, SOLID = "crown", "solid"
#: The largest ray drop fitted (as :meth:`Beam.dropout_probability <zbuf_occlude.sensors.beam.fields.Beam.dropout_probability>` clips).
MAX_FOLIAGE_DROPOUT = 0.95


def is_crown_class(name: str) -> bool:
    """Whether objects of the class ``name`` are crowns: its material (:func:`~zbuf_occlude.sensors.scene.materials.material_named`)
    is one of :data:`~zbuf_occlude.sensors.scene.materials.CROWN_MATERIALS` ("bush", "Tree", "hedge": yes; "car", "pole": no)."""
    return material_named(name) in CROWN_MATERIALS


def dropout_by_surface(clouds: Sequence[NDArray[np.floating]], labels: Sequence[str], base, *, bootstrap: int = BOOTSTRAP,
                       seed: int = 0) -> dict[str, Estimate]:  # fmt: skip
    """fit-sensor's pooled dropout over the scans of crown classes and over the rest (module docstring).

    Parameters
    ----------
    clouds : sequence of (N, 3) float arrays
        Object scans in the sensor frame (sensor at the origin, z up), metres.
    labels : sequence of str
        Each scan's class.
    base : Lidar
        The spinning LiDAR the scans were made with (its beam table), as :func:`~zbuf_occlude.sensors.fit.fit_lidar` takes it.
    bootstrap, seed
        :func:`~zbuf_occlude.sensors.fit.fit_lidar`'s.

    Returns
    -------
    dict
        ``{CROWN: Estimate, SOLID: Estimate}``: the ``dropout`` estimate of each group (``n``: its firings).

    Raises
    ------
    InvalidInputError
        Scans and labels of different lengths; a group without scans (naming the classes given); what
        :func:`~zbuf_occlude.sensors.fit.fit_lidar` refuses of a group's scans.
    """
    if len(clouds) != len(labels):
        raise InvalidInputError(f"ray drop: {len(clouds)} scans but {len(labels)} labels")
    crown = [is_crown_class(str(y)) for y in labels]
    out = {}
    for group, wanted in ((CROWN, True), (SOLID, False)):
        mine = [c for c, k in zip(clouds, crown) if k == wanted]
        if not mine:
            raise InvalidInputError(
                f"ray drop: no scan of a {group} class among {sorted(set(map(str, labels)))} (crowns: classes whose material is one of "
                f"{', '.join(CROWN_MATERIALS)}, as 'bush' or 'tree'; both kinds are needed)"
            )
        out[group] = fit_lidar(mine, base, seed=seed, bootstrap=bootstrap).estimates["dropout"]
    return out


def fit_foliage_dropout(real: Mapping[str, Estimate], simulated: Mapping[str, Estimate]) -> Estimate:
    """``foliage_dropout = 1 − S_real / S_simulated``, ``S = (1 − p_crown) / (1 − p_solid)`` (module docstring).

    Parameters
    ----------
    real, simulated : mapping
        ``{CROWN: Estimate, SOLID: Estimate}`` of the real scans and of meshes of the same classes scanned
        without ray drop (:func:`dropout_by_surface`).

    Returns
    -------
    Estimate
        The ray drop in [0, :data:`MAX_FOLIAGE_DROPOUT`], its first-order standard deviation, ``n`` the real crowns'
        firings; ``set_in_sensor`` (the beam's ``foliage_dropout``).

    Raises
    ------
    InvalidInputError
        A group missing, or a rate that is not in [0, 1).
    """
    survival = {}
    for name, rates in (("real", real), ("simulated", simulated)):
        for group in (CROWN, SOLID):
            e = rates.get(group)
            if e is None or not (0.0 <= e.value < 1.0) or not math.isfinite(e.std):
                raise InvalidInputError(
                    f"ray drop: the {name} scans' {group} dropout is {e if e is None else e.value}: need a rate in [0, 1)"
                )
        c, s = rates[CROWN], rates[SOLID]
        ratio = (1.0 - c.value) / (1.0 - s.value)
        survival[name] = (ratio, ratio * math.hypot(c.std / (1.0 - c.value), s.std / (1.0 - s.value)))
    (sr, er), (sm, em) = survival["real"], survival["simulated"]
    q = sr / sm
    value = min(max(1.0 - q, 0.0), MAX_FOLIAGE_DROPOUT)
    return Estimate(value, q * math.hypot(er / sr, em / sm), real[CROWN].n,
                    "1 − S_real / S_simulated, S = (1 − crown dropout) / (1 − solid dropout)", set_in_sensor=True)  # fmt: skip
