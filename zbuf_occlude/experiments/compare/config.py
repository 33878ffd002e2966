"""What a comparison runs (:class:`CompareConfig`): its methods, point counts, poses and sweeps, checked once.

:class:`CompareConfig` checks every setting when it is made, before any mesh is read or any folder
held; its messages name the fields, or the options of the caller's ``option_names`` (the command
line passes its flags, :data:`~zbuf_occlude.cli.compare`).  :func:`~zbuf_occlude.experiments.compare.run.compare`
and :func:`~zbuf_occlude.experiments.compare.job.run_compare` take one.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import InitVar, dataclass, field
from typing import Any

from zbuf_occlude.defaults import DEFAULT_RESOLUTION, DEFAULT_VIEWS
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, view_schedule
from zbuf_occlude.geometry.sampling import check_seed
from zbuf_occlude.visibility import available_methods

__all__ = ["CompareConfig", "parse_methods", "parse_int_list", "DEFAULT_METHODS", "DEFAULT_POINTS", "DEFAULT_REFERENCE"]

#: Methods compared by default (open3d-* are added when asked for).
DEFAULT_METHODS = (
    "zbuffer",
    "oracle",
    "paper-vertex",
    "paper-exact",
    "paper-pruned",
    "og32",
    "og64",
    "naive-zbuffer",
)
#: Point counts of Table 1B of Sryamkin et al. 2023.
DEFAULT_POINTS = (1000, 10000, 50000, 100000)
#: The method every other is scored against: exact (Embree candidates, float64 decisions).
DEFAULT_REFERENCE = "oracle"


def parse_methods(spec: str | Sequence[str], option: str = "--methods") -> list[str]:
    """Method names from ``"a,b,c"`` or a sequence, duplicates dropped, in order.

    Raises
    ------
    InvalidInputError
        None given, or unknown names (the message names ``option`` and the methods available).
    """
    names = [m.strip() for m in spec.split(",")] if isinstance(spec, str) else [str(m).strip() for m in spec]
    names = [m for m in names if m]
    if not names:
        raise InvalidInputError(f"no visibility method given to {option}; e.g. {option} zbuffer,oracle,paper-exact")
    known = set(available_methods())
    unknown = [m for m in names if m not in known]
    if unknown:
        raise InvalidInputError(f"{option}: unknown visibility method(s) {', '.join(unknown)}; available: {', '.join(sorted(known))}")
    return list(dict.fromkeys(names))


def parse_int_list(spec: str | Iterable[int], what: str = "values") -> list[int]:
    """Positive integers from ``"1000,10000"`` (``k`` suffix allowed: ``"50k"``) or an iterable.

    Raises
    ------
    InvalidInputError
        An item that is no integer, or below 1 (the message names ``what`` and the text).
    """
    items = spec.split(",") if isinstance(spec, str) else list(spec)
    out = []
    for item in items:
        text = str(item).strip().lower()
        if not text:
            continue
        scale = 1000 if text.endswith("k") else 1
        try:
            value = int(float(text.rstrip("k")) * scale)
        except ValueError:
            raise InvalidInputError(f"bad {what} {spec!r}: {item!r} is not an integer") from None
        if value < 1:
            raise InvalidInputError(f"bad {what} {spec!r}: {value} < 1")
        out.append(value)
    return out


@dataclass(frozen=True)
class CompareConfig:
    """Every setting of a comparison (:func:`~zbuf_occlude.experiments.compare.run.compare`), checked when made.

    Parameters
    ----------
    methods : str or sequence of str
        Registered method names (:func:`zbuf_occlude.available_methods`), ``"a,b,c"`` or a
        sequence; stored as a tuple, duplicates dropped.
    points : str or sequence of int
        Sample counts (``"1000,10000,50k"`` or a sequence); the same ``seed`` gives the same
        samples for every method.  Stored as a tuple of int, in the order given.
    views : str or sequence of (elevation_deg, azimuth_deg)
        A :func:`zbuf_occlude.view_schedule` spec (``"grid25"``, ``"paper100"``,
        ``"fibonacci:N"``, ``"EL:AZ,..."``) or explicit poses, degrees; :attr:`poses` holds them.
    resolution : int
        Image size of the cameras, pixels (the z-buffer methods' resolution).
    seed : int
        Sampling seed (:func:`~zbuf_occlude.geometry.sampling.check_seed`).
    reference : str
        Method that defines the truth (default ``"oracle"``).  Its time is recorded too.
    resolution_sweep, grid_sweep : str or sequence of int
        Extra rows (``sweep="resolution"``/``"grid"``) for the image-space methods among
        ``methods`` at each resolution (pixels), and for ``og`` at each grid size (cells per
        axis), at ``sweep_points`` points; empty: no sweep.  Stored as tuples of int.
    sweep_points : int, optional
        Point count of the sweeps (default: the smallest of ``points``).
    radius : float
        Camera distance, object units (default 4, the paper's §4.1).
    method_options : mapping, optional
        Per-method keyword options, e.g. ``{"paper-vertex": {"max_edge": 0.05}}``.
    memory : bool
        Also record each method's peak traced memory (``peak_mib``, MiB) from one extra,
        untimed call per mesh × point count (first view).
    method_budget_s : float, optional
        Seconds: a method whose call took longer than this is skipped for the larger point
        counts of that mesh (rows say so in ``error``), so one slow O(N·F) method cannot stall a run.
    warmup : bool
        Call every method once, untimed, on the first view of each mesh before timing it, so
        that one-off costs (numba compilation, Embree's BVH, uploading the mesh to the GPU) are
        not charged to a view.
    option_names : mapping of str to str, optional
        What the messages call each field (``{"points": "--dense-points", ...}``: the command
        line's flags); a field not named here is called by its name.  Not stored.

    Attributes
    ----------
    poses : tuple of (float, float)
        ``views`` as ``(elevation_deg, azimuth_deg)`` pairs, degrees.

    Raises
    ------
    InvalidInputError
        Unknown or no methods, an unknown reference, no point count, a count, resolution or
        sweep value below 1 or no integer, a bad view schedule, a bad seed, a radius that is
        not a finite number > 0 or a negative budget, naming the field or its option.
    """

    methods: str | Sequence[str] = DEFAULT_METHODS
    points: str | Sequence[int] = DEFAULT_POINTS
    views: str | Sequence[tuple[float, float]] = DEFAULT_VIEWS
    resolution: int = DEFAULT_RESOLUTION
    seed: int = 0
    reference: str = DEFAULT_REFERENCE
    resolution_sweep: str | Sequence[int] = ()
    grid_sweep: str | Sequence[int] = ()
    sweep_points: int | None = None
    radius: float = DEFAULT_RADIUS
    method_options: Mapping[str, Mapping[str, Any]] | None = None
    memory: bool = False
    method_budget_s: float | None = None
    warmup: bool = True
    option_names: InitVar[Mapping[str, str] | None] = None
    poses: tuple[tuple[float, float], ...] = field(init=False, default=())

    def __post_init__(self, option_names: Mapping[str, str] | None) -> None:
        def n(name: str) -> str:
            return (option_names or {}).get(name, name)

        def setattr_(name: str, value: Any) -> None:
            object.__setattr__(self, name, value)

        setattr_("methods", tuple(parse_methods(self.methods, n("methods"))))
        setattr_("reference", parse_methods([self.reference], n("reference"))[0])
        setattr_("points", tuple(parse_int_list(self.points, n("points"))))
        if not self.points:
            raise InvalidInputError(f"{n('points')} must list one or more point counts, e.g. 1000,10000; got none")
        setattr_("resolution_sweep", tuple(parse_int_list(self.resolution_sweep, n("resolution_sweep"))))
        setattr_("grid_sweep", tuple(parse_int_list(self.grid_sweep, n("grid_sweep"))))
        setattr_("resolution", _count(self.resolution, n("resolution")))
        if self.sweep_points is not None:
            setattr_("sweep_points", _count(self.sweep_points, n("sweep_points")))
        setattr_("seed", check_seed(self.seed, name=n("seed")))
        if not (isinstance(self.radius, numbers.Real) and math.isfinite(self.radius) and self.radius > 0):
            raise InvalidInputError(f"{n('radius')} must be a finite number > 0 (object units), got {self.radius!r}")
        if self.method_budget_s is not None and not (isinstance(self.method_budget_s, numbers.Real) and self.method_budget_s >= 0):
            raise InvalidInputError(f"{n('method_budget_s')} must be a number of seconds >= 0, got {self.method_budget_s!r}")
        setattr_("method_options", {k: dict(v) for k, v in (self.method_options or {}).items()})
        setattr_("poses", _poses(self.views, n("views")))

    @property
    def sweeps(self) -> list[str]:
        """The sweeps that have values: ``"resolution"`` and/or ``"grid"``, the plots the run draws."""
        return [sweep for sweep, values in (("resolution", self.resolution_sweep), ("grid", self.grid_sweep)) if values]


def _count(value: object, name: str) -> int:
    """``value`` as an int >= 1 (an int, a numpy integer or a whole float)."""
    whole = isinstance(value, numbers.Integral) or (isinstance(value, float) and value.is_integer())
    if isinstance(value, bool) or not whole:
        raise InvalidInputError(f"{name} must be a whole number, got {value!r}")
    if value < 1:
        raise InvalidInputError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def _poses(views: str | Sequence[tuple[float, float]], name: str) -> tuple[tuple[float, float], ...]:
    if isinstance(views, str):
        try:
            return tuple(view_schedule(views))
        except InvalidInputError as exc:
            raise InvalidInputError(f"{name}: {exc}") from None
    try:
        return tuple((float(e), float(a)) for e, a in views)
    except (TypeError, ValueError):
        raise InvalidInputError(f"{name} must be a pose schedule or (elevation_deg, azimuth_deg) pairs, got {views!r}") from None
