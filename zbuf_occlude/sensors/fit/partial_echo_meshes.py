"""A spinning LiDAR's detection of partial echoes (``Beam.min_echo_reflectance``) fitted to real object scans by scanning meshes.

Where a pulse's footprint straddles an object's outline, a sliver of it meets the object; a
receiver that reports such partial echoes makes scan lines that run on past the outline, one
that drops them makes shorter lines and more broken ones.  The threshold is read from what it does
to whole objects (:mod:`zbuf_occlude.sensors.fit.partial_echoes`): per class shared by the real
scans and a folder of meshes, the real scans' outline share (the share of points that end a run of
their ring's scan line, :func:`~zbuf_occlude.sensors.fit.scan_lines.outline_share`) against the
same statistic of the meshes scanned at each threshold of a grid, and the threshold whose
simulated medians meet the real ones (:func:`~zbuf_occlude.sensors.fit.partial_echoes.fit_min_echo_reflectance`).

The meshes are scanned as ``experiment sim2real``'s ``lidar`` set, and only scans whose centroid lies
:data:`~zbuf_occlude.sensors.fit.mesh_crops.MATCHED_RANGE_M` away count, real and simulated
(:mod:`zbuf_occlude.sensors.fit.mesh_crops`, which holds the crops, their placements and
the outline share of each).  This module holds the fit: the beam it scans with, the fit from a
folder of meshes or from meshes already loaded, its result, and the step ``fit-sensor --meshes`` runs.

The beam (:func:`partial_echo_sensor`): the fitted sensor's, with a footprint where it has none
(:func:`~zbuf_occlude.sensors.beam.fields.footprint_changes`: :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS`
sub-rays over the beam's data-sheet divergence; a beam without a divergence is refused), and
**one return per pulse, the strongest** (Velodyne's strongest-return mode).  That is an
assumption about the real scans, not read from them: LiDARNet's HDL-32E scans hold one point per
pulse (almost no two points share a direction), as the device's default strongest mode records.
Scans recorded in last-return or dual mode need another fit.

The fitted threshold is written as fitted, not rounded to a coarser step: a multiple of the
search's step (0.0025; :mod:`~zbuf_occlude.sensors.fit.partial_echoes`), its bootstrap spread
beside it in the table.  The sensor returned carries that beam: the footprint and return mode
the threshold was fitted with, since the threshold means nothing without them.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from zbuf_occlude.defaults import MAX_SAMPLES
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.sensors.fit.mesh_crops import MATCHED_RANGE_M, Say, real_shares, simulated_shares
from zbuf_occlude.mesh.inputs.class_folders import MeshEntry, MeshFolder
from zbuf_occlude.sensors.fit.class_placement import CropPlacement
from zbuf_occlude.real_scans.records import real_label
from zbuf_occlude.mesh.sizes import CLASS_SIZES_M, SizeRange
from zbuf_occlude.sensors.beam.fields import footprint_changes
from zbuf_occlude.sensors.checks import count, namer
from zbuf_occlude.sensors.fit.engine import Refine, Refinement
from zbuf_occlude.sensors.fit.lidar import BOOTSTRAP
from zbuf_occlude.sensors.fit.partial_echoes import FIT_GRID, PartialEchoFit, fit_min_echo_reflectance
from zbuf_occlude.sensors.kinds import capabilities, with_beam

if TYPE_CHECKING:
    from zbuf_occlude.real_scans.records import RealScan
    from zbuf_occlude.sensors.patterns.spinning import Lidar

__all__ = [
    "SIMULATION_RANGE_RESOLUTION_M", "PartialEchoResult", "fit_partial_echoes", "fit_partial_echoes_to_meshes", "mesh_classes",
    "partial_echo_refine", "partial_echo_sensor",
]  # fmt: skip

log = logging.getLogger(__name__)

#: The least range between two echoes of one pulse where the beam gives none, metres: a 5 ns pulse's c·τ/2.  An
#: assumption (Velodyne does not publish the HDL-32E's pulse length); with one return per pulse it only decides
#: which sub-ray hits merge into one echo before the strongest is taken.
SIMULATION_RANGE_RESOLUTION_M = 0.75


def _quiet(_: str) -> None:
    """A ``say`` that says nothing."""


def partial_echo_sensor(sensor: Lidar, min_echo_reflectance: float | None = None, *, names: Mapping[str, str] | None = None) -> Lidar:
    """``sensor`` with the beam a partial-echo fit scans with (module docstring), and ``min_echo_reflectance`` where given.

    The footprint: :func:`~zbuf_occlude.sensors.beam.fields.footprint_changes` (at least
    :data:`~zbuf_occlude.sensors.beam.footprint.FOOTPRINT_RAYS` sub-rays over the beam's divergence); the
    receiver: the strongest echo, one return per pulse, echoes resolved at the beam's
    ``range_resolution_m`` or :data:`SIMULATION_RANGE_RESOLUTION_M` where it has none (no mixed
    pixels: ``echo_separation_m`` 0, which resolved echoes refuse).  Every other field is ``sensor``'s.

    Raises
    ------
    InvalidInputError
        ``sensor`` is no spinning LiDAR; its beam has no divergence (naming ``meshes`` and the beam's
        ``divergence_deg``); a ``min_echo_reflectance`` outside [0, 1].  Messages name ``meshes`` and ``sensor`` as
        ``names`` maps them (``{"meshes": "--meshes"}``).
    """
    n = namer(names)
    if not capabilities(sensor).spins:
        raise InvalidInputError(f"{n('meshes')}: the partial echoes are fitted for a spinning LiDAR, not a {type(sensor).__name__}")
    beam = sensor.beam
    changes = footprint_changes(beam, footprint=True, divergence_deg=None, sensor=sensor.name,
                                names=(n("meshes"), f"a {n('sensor')} JSON whose beam has divergence_deg"))  # fmt: skip
    changes |= {"return_mode": "strongest", "max_returns": 1, "echo_separation_m": 0.0,
                "range_resolution_m": beam.range_resolution_m if beam.range_resolution_m > 0 else SIMULATION_RANGE_RESOLUTION_M}  # fmt: skip
    if min_echo_reflectance is not None:
        changes["min_echo_reflectance"] = min_echo_reflectance
    return with_beam(sensor, **changes)


@dataclass(frozen=True)
class PartialEchoResult:
    """A fitted ``min_echo_reflectance`` and the sensor that carries it (:func:`fit_partial_echoes`).

    Attributes
    ----------
    fit : PartialEchoFit
        The threshold ± its bootstrap spread, and the curves behind it.
    sensor : Lidar
        The sensor given with the simulation's beam (:func:`partial_echo_sensor`) and the fitted threshold.
    classes : tuple of str
        The classes fitted on.
    skipped : dict of str to str
        Each class left out, and why (no meshes, no real scans, none at
        :data:`~zbuf_occlude.sensors.fit.mesh_crops.MATCHED_RANGE_M`, ...).
    crops : dict of str to int
        Per class fitted, the simulated crops compared (the same at every threshold).
    crops_per_mesh, seed : int
    """

    fit: PartialEchoFit
    sensor: Any
    classes: tuple[str, ...]
    skipped: dict[str, str] = field(default_factory=dict)
    crops: dict[str, int] = field(default_factory=dict)
    crops_per_mesh: int = 0
    seed: int = 0

    def markdown(self) -> str:
        """What was scanned, the fit's table (:meth:`PartialEchoFit.markdown`) and the classes left out."""
        b = self.sensor.beam
        lo, hi = MATCHED_RANGE_M
        crops = ", ".join(f"{c}: {n} crop{'s' * (n != 1)}" for c, n in ((c, self.crops[c]) for c in self.classes))
        text = (f"\n## Detection of partial echoes (`min_echo_reflectance`)\n\nThe outline share of scans whose centroid lies "
                f"{lo:g}-{hi:g} m away, per class: the median of the real scans against the median of meshes scanned at each "
                f"threshold τ ({crops}; {self.crops_per_mesh} per mesh, "
                f"seed {self.seed}), with {b.footprint_rays} sub-rays over a {b.divergence_deg:g}° divergence and the strongest "
                f"return of each pulse (assumed to be how the real scans were recorded).\n\n")  # fmt: skip
        text += self.fit.markdown()
        if self.skipped:
            text += "\nClasses left out: " + "; ".join(f"{c} ({why})" for c, why in sorted(self.skipped.items())) + ".\n"
        return text

    def to_json(self) -> dict:
        """The fit as strict-JSON values: what the sensor file's ``fit.partial_echoes`` holds."""
        f = self.fit
        b = self.sensor.beam
        return {"estimate": f.estimate.to_json(), "grid": list(f.grid), "real": dict(f.real),
                "simulated": {c: list(v) for c, v in f.simulated.items()}, "objective": list(f.objective),
                "statistic": "outline_share", "range_m": list(MATCHED_RANGE_M), "classes": list(self.classes),
                "skipped": dict(self.skipped), "crops": dict(self.crops), "crops_per_mesh": self.crops_per_mesh, "seed": self.seed,
                "footprint_rays": b.footprint_rays, "divergence_deg": b.divergence_deg, "return_mode": b.return_mode}  # fmt: skip


def fit_partial_echoes_to_meshes(scans: Sequence[RealScan], sensor: Lidar, meshes: Sequence[MeshEntry], *, crops_per_mesh: int = 4,
                                 seed: int = 0, bootstrap: int = BOOTSTRAP, grid: Sequence[float] = FIT_GRID,
                                 placement: CropPlacement | None = None, sizes: Mapping[str, SizeRange] = CLASS_SIZES_M,
                                 say: Say | None = None, names: Mapping[str, str] | None = None) -> PartialEchoResult:  # fmt: skip
    """:func:`fit_partial_echoes` on meshes already loaded: every class of ``meshes`` is fitted on, with the real
    scans labelled with it (its name, or in lower case); other real scans are left out.

    Parameters
    ----------
    scans : sequence of RealScan
        Real object scans with ``label`` and ``points_sensor_m`` ((N, 3) float64, sensor at the origin, z up, metres).
    sensor : Lidar
        The sensor the geometry was fitted to (firing rate, noise, dropout): its beam is scanned with
        (:func:`partial_echo_sensor`).
    meshes : sequence of MeshEntry
    crops_per_mesh, seed, placement, sizes
        :func:`~zbuf_occlude.sensors.fit.mesh_crops.mesh_crops`'s (the seed also seeds the bootstrap).
    bootstrap : int
        Resamples of the fit's bootstrap (:func:`~zbuf_occlude.sensors.fit.partial_echoes.fit_min_echo_reflectance`).
    grid : sequence of float
        The thresholds simulated, two or more in [0, 1] (default :data:`~zbuf_occlude.sensors.fit.partial_echoes.FIT_GRID`).
    say : callable, optional
        Told each step (the command line prints it).
    names : mapping of str to str, optional
        How the caller calls ``meshes``, ``sizes`` and ``sensor`` in messages (:func:`~zbuf_occlude.sensors.checks.namer`).

    Returns
    -------
    PartialEchoResult

    Raises
    ------
    InvalidInputError
        A sensor :func:`partial_echo_sensor` refuses (before anything is scanned); a real scan without sensor-frame points;
        no class left with real scans and crops at :data:`~zbuf_occlude.sensors.fit.mesh_crops.MATCHED_RANGE_M`
        (naming each class and why); what :func:`~zbuf_occlude.sensors.fit.mesh_crops.mesh_crops` and
        :func:`~zbuf_occlude.sensors.fit.partial_echoes.fit_min_echo_reflectance` refuse.
    """
    say = say or _quiet
    base = partial_echo_sensor(sensor, names=names)
    crops_per_mesh = count(crops_per_mesh, "crops_per_mesh", low=1, high=MAX_SAMPLES)
    classes = sorted({m.class_name for m in meshes})
    _check_sizes(classes, sizes, namer(names))
    real = real_shares(scans, classes)
    skipped = {c: f"no real scan {MATCHED_RANGE_M[0]:g}-{MATCHED_RANGE_M[1]:g} m away" for c in classes if not real[c]}
    fitted = [c for c in classes if c not in skipped]
    if not fitted:
        raise InvalidInputError(
            f"no class to fit the partial echoes on: {'; '.join(f'{c}: {w}' for c, w in skipped.items()) or 'no meshes'}"
        )
    meshes = [m for m in meshes if m.class_name in fitted]
    grid = sorted(float(t) for t in grid)
    say(f"fitting the partial echoes: {len(meshes)} meshes of {', '.join(fitted)}, {crops_per_mesh} crop{'s' * (crops_per_mesh != 1)} each, at {len(grid)} "
        f"thresholds; {sum(len(real[c]) for c in fitted)} real scans {MATCHED_RANGE_M[0]:g}-{MATCHED_RANGE_M[1]:g} m away ...")  # fmt: skip
    simulated = simulated_shares(meshes, base, grid, fitted, crops_per_mesh=crops_per_mesh, seed=seed, placement=placement, sizes=sizes,
                                  say=say)  # fmt: skip
    first = simulated[grid[0]]
    for c in fitted:
        if not first[c]:
            skipped[c] = f"no crop of its meshes {MATCHED_RANGE_M[0]:g}-{MATCHED_RANGE_M[1]:g} m away, kept at every threshold"
    fitted = [c for c in fitted if c not in skipped]
    if not fitted:
        raise InvalidInputError(f"no class to fit the partial echoes on: {'; '.join(f'{c}: {w}' for c, w in skipped.items())}; "
                                "draw more crops per mesh")  # fmt: skip
    fit = fit_min_echo_reflectance({c: real[c] for c in fitted}, {t: {c: simulated[t][c] for c in fitted} for t in grid}, seed=seed,
                                   bootstrap=bootstrap)  # fmt: skip
    fitted_sensor = with_beam(base, min_echo_reflectance=round(fit.estimate.value, 6))  # the search's step, without float noise
    return PartialEchoResult(fit, fitted_sensor, tuple(fitted), skipped, {c: len(first[c]) for c in fitted}, crops_per_mesh, seed)


def mesh_classes(root: str | os.PathLike, *, names: Mapping[str, str] | None = None) -> list[str]:
    """The class folders of ``root`` that hold mesh files (as :func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes`
    finds them: hidden entries passed over, links and special files as
    :func:`~zbuf_occlude.mesh.inputs.discovery.walk_mesh_files` treats them), sorted.

    Raises
    ------
    InvalidInputError
        ``root`` is not a folder (naming ``meshes`` as ``names`` maps it).
    UnsafePathError
        As :func:`~zbuf_occlude.mesh.inputs.discovery.walk_mesh_files`.
    """
    from zbuf_occlude.mesh.inputs.discovery import walk_mesh_files

    root = Path(root)
    if not root.is_dir():
        raise InvalidInputError(f"{namer(names)('meshes')} {root} is not a folder")
    files, _ = walk_mesh_files(root, skip_hidden=True)
    return sorted({f.relative_to(root).parts[0] for f in files if len(f.relative_to(root).parts) >= 2})


def _check_sizes(classes: Sequence[str], sizes: Mapping[str, SizeRange], n) -> None:
    """Refuse classes without a real size in ``sizes``, naming ``sizes`` as ``n`` does: their meshes' crops have no scale."""
    missing = [c for c in classes if c not in sizes]
    if missing:
        raise InvalidInputError(f"{n('meshes')}: classes {missing} have no real size to scale their meshes to: give {n('sizes')} "
                                f"CLASS=DIMENSION:LO-HI,... (e.g. {missing[0]}=height:0.5-1.5; known: {sorted(sizes)})")  # fmt: skip


def _real_folder(scans: Sequence[RealScan]) -> str:
    """The folder the real scans came from, for messages: their sources' common folder."""
    try:
        return os.path.commonpath([os.path.dirname(str(s.source)) for s in scans]) or "."
    except ValueError:  # sources on different drives, or none
        return "the real scans"


def fit_partial_echoes(scans: Sequence[RealScan], sensor: Lidar, meshes: str | os.PathLike | MeshFolder, *, crops_per_mesh: int = 4,
                       seed: int = 0, bootstrap: int = BOOTSTRAP, placement: CropPlacement | None = None,
                       sizes: Mapping[str, SizeRange] = CLASS_SIZES_M, grid: Sequence[float] = FIT_GRID,
                       say: Say | None = None, names: Mapping[str, str] | None = None) -> PartialEchoResult:  # fmt: skip
    """Fit ``sensor``'s ``min_echo_reflectance`` to real object scans by scanning the meshes of the same classes (module docstring).

    The classes are the real scans' labels that have a class folder under ``meshes`` (a label matches its
    folder's name, or the name in lower case); the others, real labels without meshes and mesh folders
    without real scans, are named (logged, told to ``say``, and in the result's ``skipped``).

    Parameters
    ----------
    scans : sequence of RealScan
        The real scans (:func:`~zbuf_occlude.real_scans.datasets.load_real_scans`), each with ``label`` and
        ``points_sensor_m`` ((N, 3) float64, sensor at the origin, z up, metres); recorded with one return per
        pulse, the strongest (module docstring).
    sensor : Lidar
        The spinning LiDAR already fitted to the scans' geometry (``fit-sensor``'s firing rate, noise and dropout),
        whose beam has a divergence (its data sheet's).
    meshes : path or MeshFolder
        One sub-folder per class of mesh files, as ``experiment sim2real`` reads them
        (:func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes`: byte-identical files dropped;
        two classes or more shared with the scans, two meshes or more each); a
        :class:`~zbuf_occlude.mesh.inputs.class_folders.MeshFolder` with the meshes' up axes (a path: ``auto``).
    crops_per_mesh : int
        Crops of each mesh at each threshold (:func:`~zbuf_occlude.sensors.fit.mesh_crops.mesh_crops`), 1 to
        :data:`~zbuf_occlude.defaults.MAX_SAMPLES`.
    seed : int
        Seeds the crops' draws and the bootstrap.
    bootstrap : int
        Resamples of the fit's bootstrap.
    placement, sizes, grid, say
        As :func:`fit_partial_echoes_to_meshes`.
    names : mapping of str to str, optional
        As :func:`fit_partial_echoes_to_meshes`'s (``fit-sensor``: ``--meshes`` ...); default the fields' own names.

    Returns
    -------
    PartialEchoResult
        ``result.fit`` (the threshold ± its bootstrap spread, the curves) and ``result.sensor``: ``sensor`` with the
        simulation's footprint and return mode (:func:`partial_echo_sensor`) and the fitted threshold, not rounded.

    Raises
    ------
    InvalidInputError
        ``sensor`` no spinning LiDAR or its beam without a divergence, ``crops_per_mesh`` out of range, ``meshes`` not a
        folder (all before a mesh is read); no class shared by the scans and the mesh folders (naming both folders and
        their classes); what :func:`~zbuf_occlude.mesh.inputs.class_folders.find_class_meshes` and
        :func:`fit_partial_echoes_to_meshes` refuse.
    MeshLoadError
        A mesh that cannot be loaded, named.
    UnsafePathError
        A link under ``meshes`` that leads out of it to a file of another kind.
    """
    say, n = say or _quiet, namer(names)
    partial_echo_sensor(sensor, names=names)  # refused before any mesh is read
    crops_per_mesh = count(crops_per_mesh, "crops_per_mesh", low=1, high=MAX_SAMPLES)
    meshes = meshes if isinstance(meshes, MeshFolder) else MeshFolder(meshes)
    folders = mesh_classes(meshes.root, names=names)
    labels = sorted({real_label(s.label, folders) for s in scans})
    shared = [c for c in folders if c in labels]
    if not shared:
        raise InvalidInputError(f"{n('meshes')} {meshes.root} and {_real_folder(scans)} share no class: meshes of {folders or 'none'}, "
                                f"real scans of {labels or 'none'} (a class folder of meshes is named as the scans' label)")  # fmt: skip
    _check_sizes(shared, sizes, n)  # before a mesh is read
    skipped = {c: "no meshes" for c in labels if c not in shared} | {c: "no real scans" for c in folders if c not in shared}
    if skipped:
        log.info("partial echoes: classes left out: %s", skipped)
        say(f"partial echoes: fitting on {', '.join(shared)}; left out: {', '.join(f'{c} ({w})' for c, w in sorted(skipped.items()))}")
    entries = meshes.find(classes=shared)
    result = fit_partial_echoes_to_meshes(scans, sensor, entries, crops_per_mesh=crops_per_mesh, seed=seed, bootstrap=bootstrap,
                                          grid=grid, placement=placement, sizes=sizes, say=say, names=names)  # fmt: skip
    return replace(result, skipped={**skipped, **result.skipped})


def partial_echo_refine(meshes: str | os.PathLike, *, crops_per_mesh: int = 4, seed: int = 0, up: str = "auto",
                        up_map: Mapping[str, str] | None = None, sizes: Mapping[str, SizeRange] = CLASS_SIZES_M,
                        say: Say | None = None, names: Mapping[str, str] | None = None) -> Refine:  # fmt: skip
    """``fit-sensor --meshes``: the step :func:`~zbuf_occlude.sensors.fit.engine.fit_sensor` runs after a spinning LiDAR's
    fit and before it writes: :func:`fit_partial_echoes` on the scans it read, the fitted sensor written in place of
    the geometry's, the fit under ``fit.partial_echoes`` in its JSON and its table in the ``.md``.

    Messages name ``meshes``, ``sizes`` and ``sensor`` as ``names`` maps them (:func:`fit_partial_echoes`).

    Raises
    ------
    InvalidInputError
        ``meshes`` not a folder, ``crops_per_mesh`` out of range (both now, before any scan is read).
    """
    crops_per_mesh = count(crops_per_mesh, "crops_per_mesh", low=1, high=MAX_SAMPLES)
    mesh_classes(meshes, names=names)  # a missing folder is refused before the scans are read

    def run(fit: Any, scans: Sequence[RealScan]) -> Refinement:
        result = fit_partial_echoes(scans, fit.sensor, MeshFolder(meshes, up, dict(up_map or {})), crops_per_mesh=crops_per_mesh,
                                    seed=seed, sizes=sizes, say=say, names=names)  # fmt: skip
        e = result.fit.estimate
        if say is not None:
            say(
                f"min_echo_reflectance {e.value:.4g} ± {e.std:.2g} (bootstrap)"
                if math.isfinite(e.std)
                else f"min_echo_reflectance {e.value:.4g}"
            )
        return Refinement(result.sensor, {"partial_echoes": result.to_json()}, result.markdown(), result)

    return Refine(namer(names)("meshes"), run)
