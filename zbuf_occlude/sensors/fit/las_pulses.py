"""The points of a LAS/LAZ scan grouped into the pulses that fired them.

A LAS point carries its pulse only through its GPS time (with its flight line and channel): the returns of one
pulse share them.  :func:`las_pulses` groups the points so; :func:`check_pulses` and :func:`check_return_pairs`
refuse scans whose times cannot group them.  :mod:`~zbuf_occlude.sensors.fit.returns` measures per-pulse
statistics on the groups.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.io.las import LasPoints

__all__ = ["MAX_AMBIGUOUS_SHARE", "LasPulses", "check_pulses", "check_return_pairs", "las_pulses"]

#: Largest share of a scan's points in groups that hold a return number twice (:func:`check_pulses`): real surveys
#: hold none (the IGN LiDAR HD sample 0 of its 32,231 pulses, Autzen 0 of 99,331); a few are tolerated and left out.
MAX_AMBIGUOUS_SHARE = 0.01


@dataclass(frozen=True)
class LasPulses:
    """The points of a scan grouped into pulses (module docstring), sorted by pulse, then return number.

    Attributes
    ----------
    order : (N,) int64
        Sorted position -> point of the scan.
    pulse : (N,) int64
        Sorted position -> pulse, 0 to ``count - 1``, non-decreasing.
    count : int
        Pulses.
    complete : (count,) bool
        Whether each pulse is complete.
    returns : (count,) int64
        Each pulse's smallest ``number_of_returns``.
    ambiguous : (count,) bool
        Whether a return number occurs twice in the group: its points share a GPS time but are not
        one pulse's returns (module docstring; :func:`check_pulses`).  Never complete, no gaps.
    """

    order: NDArray[np.int64]
    pulse: NDArray[np.int64]
    count: int
    complete: NDArray[np.bool_]
    returns: NDArray[np.int64]
    ambiguous: NDArray[np.bool_]

    def pairs(self, return_number: NDArray) -> NDArray[np.bool_]:
        """(N - 1,) bool: sorted positions ``i`` whose points ``i`` and ``i + 1`` are returns k and k + 1 of one pulse
        (``return_number``: the scan's, in its own order), ambiguous groups left out."""
        rn = return_number[self.order].astype(np.int64)
        same = self.pulse[1:] == self.pulse[:-1]
        return same & (rn[1:] == rn[:-1] + 1) & ~self.ambiguous[self.pulse[1:]]


def las_pulses(las: LasPoints) -> LasPulses:
    """The pulses of ``las``: points sharing a GPS time, point source and scanner channel (module docstring)."""
    order = np.lexsort((las.return_number, las.gps_time, las.scanner_channel, las.point_source_id))
    t, source, channel = las.gps_time[order], las.point_source_id[order], las.scanner_channel[order]
    new = np.ones(len(order), dtype=bool)
    new[1:] = (t[1:] != t[:-1]) | (source[1:] != source[:-1]) | (channel[1:] != channel[:-1])
    starts = np.flatnonzero(new)
    size = np.diff(np.append(starts, len(order)))
    number, rn = las.number_of_returns[order].astype(np.int64), las.return_number[order]
    fewest, most = np.minimum.reduceat(number, starts), np.maximum.reduceat(number, starts)
    # each return number as one bit: a complete pulse of n returns holds exactly bits 1..n
    bits = np.bitwise_or.reduceat(np.left_shift(1, rn.astype(np.int64)), starts)
    complete = (size == fewest) & (fewest == most) & (bits == np.left_shift(1, fewest + 1) - 2)
    pulse = np.cumsum(new) - 1
    repeated = (pulse[1:] == pulse[:-1]) & (rn[1:] == rn[:-1])  # sorted by return number within a group
    ambiguous = np.zeros(len(starts), dtype=bool)
    ambiguous[pulse[1:][repeated]] = True
    return LasPulses(order, pulse, len(starts), complete & ~ambiguous, fewest, ambiguous)


def check_pulses(las: LasPoints, pulses: LasPulses, name: str = "the scan") -> None:
    """Refuse a scan whose GPS times do not tell its pulses apart.

    A pulse is the points that share a GPS time (within a point source and channel); where the
    times do not identify pulses (all 0, rounded to the second) every figure of the pulses would
    be a silent wrong number: the gaps between returns of different pulses read as a range
    resolution.  So a scan is refused when more than :data:`MAX_AMBIGUOUS_SHARE` of its points lie
    in groups that hold a return number twice (fewer are left out of the gaps and of the complete
    pulses: :attr:`LasPulses.ambiguous`).

    Parameters
    ----------
    las : LasPoints
    pulses : LasPulses
        :func:`las_pulses` of ``las``.
    name : str
        The scan in messages (its file).

    Raises
    ------
    InvalidInputError
        One line naming ``name``, what is wrong and what to do.
    """
    in_ambiguous = int(np.count_nonzero(pulses.ambiguous[pulses.pulse]))
    if in_ambiguous > MAX_AMBIGUOUS_SHARE * len(pulses.pulse):
        times = np.unique(las.gps_time)
        seen = f"all {len(las):,} points have GPS time {times[0]:g}" if len(times) == 1 else f"{len(times):,} distinct GPS times"
        raise InvalidInputError(
            f"{name}: its GPS times do not identify pulses ({seen}; {in_ambiguous:,} of {len(las):,} points share a time with "
            "another return of the same number: duplicates, or times that are not the pulses'): the returns of one pulse cannot "
            "be grouped; give a scan whose points carry their pulse's GPS time (remove duplicated points of overlapping tiles)"
        )


def check_return_pairs(las: LasPoints, pulses: LasPulses, name: str = "the scan") -> None:
    """Refuse a scan whose pulses had several returns but that holds no two returns of one pulse.

    Its points say so (``number_of_returns`` above 1) but no pulse holds returns k and k + 1: a
    scan filtered to first returns, or each return stamped with its own time.  The gaps between
    a pulse's returns, and so the range resolution, cannot be measured on it.

    Parameters
    ----------
    las : LasPoints
    pulses : LasPulses
        :func:`las_pulses` of ``las``.
    name : str
        The scan in messages (its file).

    Raises
    ------
    InvalidInputError
        One line naming ``name``, what is wrong and what to do.
    """
    most = int(las.number_of_returns.max()) if len(las) else 0
    if most <= 1 or np.any(pulses.pairs(las.return_number)):
        return
    if not np.any(las.return_number > 1):
        raise InvalidInputError(
            f"{name}: holds first returns only (return_number 1 on every point, though its pulses recorded up to {most}): "
            "with no two returns of one pulse the range resolution cannot be fitted; give the scan with all its returns"
        )
    raise InvalidInputError(
        f"{name}: no two returns of one pulse share a GPS time (its pulses recorded up to {most} returns): the gaps between "
        "a pulse's returns, and so the range resolution, cannot be measured; give a scan whose points carry their pulse's GPS time"
    )
