"""Meshes made to show what real scans of their class show, fitted on their own simulated crops.

A mesh is made as wide across the line of sight as the class's scans by a horizontal stretch
(:func:`fit_width_scale`) or, where the scans are narrow because they hold part of an object, by
a side occluder that leaves that much of it in view (:func:`fit_visible_across_sight`); it is
given the class's outline over the height by a warp (:func:`fit_width_profile`);
:func:`fit_object_shape` fits what a class asks for.  Each fit draws :data:`WIDTH_SAMPLES` crops
with :func:`zbuf_occlude.sensors.crops.object_crop` and measures them as the real scans are
measured (:mod:`zbuf_occlude.sensors.fit.scans`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.scans import (
    _across_sight_width,
    _nan_median_or_one,
    _width_profile,
)
from zbuf_occlude.sensors.kinds import capabilities

__all__ = ["fit_object_shape", "fit_visible_across_sight", "fit_width_profile", "fit_width_scale", "WIDTH_SAMPLES"]
#: Simulated crops of a mesh that :func:`fit_width_scale` and :func:`fit_width_profile` measure.
WIDTH_SAMPLES = 16
_WIDTH_STREAM = 0x57D7  # fit_width_scale's crops
_PROFILE_STREAM = 0x9F0F  # fit_width_profile's crops
_WIDTH_GROWTHS = 6  # fit_width_scale widens a mesh that shows no width up to 4**6 times
#: The width fits' second round widens the first's estimate by at most this factor.  A larger
#: one means the crops it measured are narrower than the sensor resolves (two returns of one
#: azimuth column in a band, a width of 1e-9 m), not that they widen out of proportion.
_MAX_CORRECTION = 4.0


def fit_width_scale(mesh, sensor, distributions, width_m: tuple[float, float], *, n_samples: int = WIDTH_SAMPLES,
                    seed: int = 0, name: str = "the mesh") -> tuple[float, float]:  # fmt: skip
    """The horizontal stretch that makes a mesh's crops as wide as real scans, for :class:`~zbuf_occlude.sensors.placement.CropDistributions` ``width_scale``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` are measured with
    :func:`across_sight_width`, first at the mesh's own proportions (its ``width_scale``
    ignored; a mesh that shows no width, a post thinner than the sensor's azimuth step, is
    widened 4x at a time until it does), then once more at the stretch ``s`` that this first
    median asks for; ``s`` is corrected by the second median (a thin post's width does not
    grow in proportion at first: one return per ring has no width).  The
    interval ``width_m · s / w̄``, with ``w̄`` the middle of ``width_m``, then gives crops whose
    median width is about ``w̄`` and whose spread is ``width_m``'s, and that keep the height and
    placement they would have had.  The stretch changes how the object looks, not only how
    large it is: fit it where the real objects are thicker or thinner than the mesh (trunks
    scanned as posts, shrubs as slim trees), not where the real scans are narrow because they
    show part of an object (a car squeezed to a partial view's width is a tall narrow lump), and
    compare the crops with the real scans (:mod:`zbuf_occlude.experiments.realism`).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A normalised, z-up mesh (:func:`zbuf_occlude.load_mesh`).
    sensor : Lidar
    distributions : CropDistributions
    width_m : (lo, hi)
        Metres, 0 <= lo <= hi, hi > 0 (:func:`fit_crop_widths`).
    n_samples, seed : int
        Crops measured per round (>= 1) and their seed (placements and sensor noise).
    name : str
        The mesh as errors name it (its file).

    Returns
    -------
    (lo, hi) : tuple of float
        Stretch factors, > 0.

    Raises
    ------
    InvalidInputError
        A bad ``width_m`` or ``n_samples``, a sensor that is not a :class:`Lidar`, or no crop of
        the mesh with a band of two returns (naming ``name``).
    """
    lo, hi = _check_width_fit(width_m, n_samples, sensor)

    def median_width(scale: float) -> float:
        return _median_crop_width(mesh, sensor, replace(distributions, width_scale=scale), int(n_samples), seed)

    middle, scale = (lo + hi) / 2, 1.0
    w = median_width(scale)
    for _ in range(_WIDTH_GROWTHS):  # a mesh too thin to show a width: widen it until it shows one
        if w > 0:
            break
        scale *= 4.0
        w = median_width(scale)
    if not w > 0:
        raise InvalidInputError(f"{name}: no crop of {n_samples} shows it two returns wide in a band, even {scale:g}x as wide")
    scale *= middle / w
    scale *= _correction(middle, median_width(scale))
    return max(lo, 1e-3 * hi) * scale / middle, hi * scale / middle


def fit_visible_across_sight(mesh, sensor, distributions, width_m: tuple[float, float], *, n_samples: int = WIDTH_SAMPLES,
                             seed: int = 0, name: str = "the mesh") -> tuple[float, float]:  # fmt: skip
    """The share of a mesh's width to leave visible so that its crops are as wide as real scans, for :class:`~zbuf_occlude.sensors.placement.CropDistributions` ``visible_across_sight``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` with nothing hidden are
    measured with :func:`across_sight_width` (median ``w``); where ``w`` is wider than the
    middle ``w̄`` of ``width_m``, the share ``v = w̄ / w`` is measured once more under a side
    occluder (:func:`~zbuf_occlude.sensors.scene.occluders.side_occluders`) and corrected by that median.
    The interval ``width_m · v / w̄`` then gives crops whose median width is about ``w̄`` where
    the mesh shows wider, and whole crops where the real scans are wider than the mesh's (the
    share is capped at 1 when drawn).  Fit it where real scans are narrow because they show
    part of an object (a parked car's one end), where :func:`fit_width_scale` would squeeze it.

    Parameters and errors as :func:`fit_width_scale`.

    Returns
    -------
    (lo, hi) : tuple of float
        Shares > 0 (values of 1 or more: nothing hidden).
    """
    lo, hi = _check_width_fit(width_m, n_samples, sensor)
    dist = replace(distributions, visible_across_sight=None)
    w = _median_crop_width(mesh, sensor, dist, int(n_samples), seed)
    if not w > 0:  # narrower than the sensor resolves: every real width is wider
        return 1.0, 1.0
    middle = (lo + hi) / 2
    share = middle / w
    if share < 1.0:  # the correction: a side occluder's edge does not cut the band widths in proportion
        share *= _correction(
            middle, _median_crop_width(mesh, sensor, replace(dist, visible_across_sight=(share, share)), int(n_samples), seed)
        )
    return max(lo, 1e-3 * hi) * share / middle, hi * share / middle


def _correction(target: float, measured: float) -> float:
    """The second round's factor ``target / measured``; 1 (the first round's estimate kept) where
    the crops show no width or it is above :data:`_MAX_CORRECTION` (a target narrower than the
    sensor resolves: the width measured is noise, and dividing by it asks for any stretch)."""
    if not measured > 0:
        return 1.0
    factor = target / measured
    return factor if factor <= _MAX_CORRECTION else 1.0


def _check_width_fit(width_m, n_samples, sensor) -> tuple[float, float]:
    """``width_m`` as ``(lo, hi)`` metres, with ``n_samples`` >= 1 and a spinning LiDAR (the width fits' arguments)."""
    try:
        lo, hi = (float(v) for v in width_m)
    except (TypeError, ValueError):
        lo, hi = math.nan, math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi and hi > 0):
        raise InvalidInputError(f"width_m must be an interval 0 <= lo <= hi, hi > 0 metres, got {width_m!r}")
    _check_measure(n_samples, sensor)
    return lo, hi


def _check_measure(n_samples, sensor) -> None:
    """A fit's crops: ``n_samples`` >= 1 of a spinning LiDAR (widths are measured across its line of sight)."""
    if int(n_samples) < 1:
        raise InvalidInputError(f"n_samples must be >= 1, got {n_samples}")
    if not capabilities(sensor).spins:
        raise InvalidInputError(
            f"widths are measured across a spinning LiDAR's line of sight; {getattr(sensor, 'name', sensor)!r} is not one"
        )


def _median_crop_width(mesh, sensor, distributions, n: int, seed: int) -> float:
    """The median :func:`across_sight_width` of a width fit's ``n`` crops (metres)."""
    crops = _fit_crops(mesh, sensor, distributions, n, seed, _WIDTH_STREAM)
    return float(np.median([_across_sight_width(crop.scan.points.astype(np.float64)) for crop in crops]))


def fit_width_profile(mesh, sensor, distributions, profile: Sequence[float], *, n_samples: int = WIDTH_SAMPLES, seed: int = 0,
                      name: str = "the mesh") -> tuple[float, ...]:  # fmt: skip
    """The warp over the height that gives a mesh's crops a class's outline, for :class:`~zbuf_occlude.sensors.placement.CropDistributions` ``width_profile``.

    ``n_samples`` crops of ``mesh`` drawn from ``distributions`` (its ``width_scale`` and
    ``width_profile`` as given) are measured with :func:`width_profile`; the stretch of each bin
    is the target ``profile`` over their median, clipped to [1/8, 8] (1 where either is
    unknown).  Those bins are of the crops' relative height, which starts above the mesh's
    bottom where the placement hides it; they are mapped to the mesh's own relative height by
    the crops' median lowest and highest return, then the crops are measured once more under
    the warp and each bin corrected once.  Both profiles are over the scan's median width, which
    the warp moves too, so the crops get the outline's shape up to a common factor (a person's
    knees at 0.5 and shoulders at 1.2 may come out 0.57 and 1.36); fit ``width_scale`` again
    under the warp (:func:`fit_width_scale`) for the widths in metres.  A mesh made to look
    like the user's scans, not a sensor setting: its parts move (a T-posed person's arms are
    pulled in; a sign's plate is made as narrow as its post; a tree's trunk as wide as its
    crown).

    Parameters
    ----------
    mesh : trimesh.Trimesh or dict
        A normalised, z-up mesh (:func:`zbuf_occlude.load_mesh`), or a primitive spec
        (:mod:`zbuf_occlude.sensors.scene.objects`).
    sensor : Lidar
    distributions : CropDistributions
    profile : sequence of float
        The class's outline, ``K >= 2`` values > 0 (:func:`fit_crop_width_profile`).
    n_samples, seed : int
        Crops measured per round (>= 1) and their seed.
    name : str
        The mesh as errors name it.

    Returns
    -------
    tuple of K float
        Stretch factors in [1/8, 8] at the centres of ``K`` equal bins of the mesh's relative height.

    Raises
    ------
    InvalidInputError
        A bad ``profile`` or ``n_samples``, a sensor that is not a :class:`Lidar`, or no crop of
        the mesh that shows a width (naming ``name``).
    """
    from zbuf_occlude.sensors.scene.object_shapes import check_width_profile
    from zbuf_occlude.sensors.scene.objects import SceneObject

    target = np.asarray(check_width_profile(profile))
    _check_measure(n_samples, sensor)
    k = len(target)
    z_lo, z_hi = (float(v) for v in np.asarray(SceneObject(mesh).build()[0].bounds, dtype=np.float64)[:, 2])  # a primitive's too
    centres = (np.arange(k) + 0.5) / k

    def measure(dist) -> tuple[NDArray[np.float64], float, float]:
        """The crops' median profile, and their median lowest and highest return in the mesh's relative height."""
        rows, spans = [], []
        for crop in _fit_crops(mesh, sensor, dist, int(n_samples), seed, _PROFILE_STREAM):
            row = _width_profile(crop.scan.points.astype(np.float64), k)
            if np.any(np.isfinite(row)):
                rows.append(row)
                spans.append((crop.local_points[:, 2].min(), crop.local_points[:, 2].max()))
        if not rows:
            raise InvalidInputError(f"{name}: no crop of {n_samples} shows a width to fit its outline to")
        lo, hi = (np.median(np.array(spans), axis=0) - z_lo) / max(z_hi - z_lo, 1e-12)
        return np.array(_nan_median_or_one(np.array(rows))), float(lo), float(hi)

    def stretch(measured, lo, hi) -> NDArray[np.float64]:
        """Target over measured per crop bin, at the mesh's bin centres."""
        ratio = np.clip(target / measured, 1 / 8, 8)
        return np.interp(centres, lo + centres * (hi - lo), ratio)

    first = stretch(*measure(distributions))
    dist = replace(distributions, width_profile=tuple(float(v) for v in first))
    factors = np.clip(first * stretch(*measure(dist)), 1 / 8, 8)  # the correction
    return tuple(float(v) for v in factors)


def fit_object_shape(mesh, sensor, distributions, width_m: tuple[float, float] | None = None, profile: Sequence[float] | None = None, *,
                     occlude: bool = False, seed: int = 0, name: str = "the mesh") -> dict:  # fmt: skip
    """What makes a mesh's crops as wide as real scans and gives them a real outline, as :class:`~zbuf_occlude.sensors.placement.CropDistributions` keywords.

    With ``width_m`` only: ``{"width_scale": (lo, hi)}`` (:func:`fit_width_scale`), or with
    ``occlude`` ``{"visible_across_sight": (lo, hi)}`` (:func:`fit_visible_across_sight`: a
    partial view instead of a thinner object).  With ``profile`` only: ``{"width_profile": (K
    factors)}`` (:func:`fit_width_profile`).  With both, the warp is fitted at the width stretch
    (or at the mesh's own width, with ``occlude``), then the width again under the warp.
    Neither: ``{}``.  Parameters and errors as those functions.
    """
    fit_width = fit_visible_across_sight if occlude else fit_width_scale
    key = "visible_across_sight" if occlude else "width_scale"
    out: dict = {}
    if profile is not None:
        at = distributions  # the warp is fitted at the width stretch, or at the mesh's own width
        if width_m is not None and not occlude:
            at = replace(distributions, width_scale=fit_width_scale(mesh, sensor, distributions, width_m, seed=seed, name=name))
        out["width_profile"] = fit_width_profile(mesh, sensor, at, profile, seed=seed, name=name)
        distributions = replace(distributions, width_profile=out["width_profile"])
    if width_m is not None:
        out[key] = fit_width(mesh, sensor, distributions, width_m, seed=seed, name=name)
    return out


def _fit_crops(mesh, sensor, distributions, n: int, seed: int, stream: int):
    """The ``n`` crops a fit measures, crop ``k`` drawn from ``derive_rng(seed, stream, k)`` (a generator)."""
    from zbuf_occlude.geometry.samples import derive_rng
    from zbuf_occlude.sensors.crops import (  # scans: trimesh and embree, imported when a fit measures
        draw_placement,
        object_crop,
    )

    for k in range(n):
        rng = derive_rng(seed, stream, k)
        yield object_crop(mesh, sensor, draw_placement(distributions, rng), seed=int(rng.integers(2**63)))
