"""``experiment returns``: the sweeps, the comparison with real scans, the sub-ray count and the figure.

:func:`run_returns` runs the experiment of :mod:`.returns` and writes, into an owned folder
(:data:`RETURNS_OUTPUTS`):

* ``real.md``: the real files' figures (:func:`~zbuf_occlude.sensors.fit.returns.return_statistics`
  per side);
* ``divergence_sweep.csv``: per divergence and sub-ray count K, the simulated multi-return share
  on vegetation, the shares of returns per vegetation pulse and the cost;
* ``k_sweep.csv``: per K at the fitted divergence, the same and the cost per pulse (interleaved
  repeats, median);
* ``comparison.csv``: every target, real against simulated, PASS or FAIL; the same against
  Autzen where it is given;
* ``comparison.md``: the same as a Markdown table (what the command prints);
* ``returns.png``: one simulated tree beside a real vegetation patch, coloured by return number;
* ``run.json``: the settings, the fitted divergences, the recommended K, the divergence compared
  (fitted with the recommended K: :func:`refits_divergence`) and the tree covers.

The plot's trees stand as far apart as makes its tree cover the real tile's
(:func:`~zbuf_occlude.experiments.tree_cover.tree_cover` on the tile,
:func:`~zbuf_occlude.experiments.tree_cover.spacing_for_cover` for the plot), so that the ground
returns under crowns compare like with like; the cover of the compared scans is measured on them
as on the tile and reported beside it (``run.json``'s ``tree_cover``, under the table).

A target passes when the simulated figure lies within the stated relative tolerance of the real
one (:data:`~zbuf_occlude.experiments.returns_comparison.TOLERANCES`); the smallest gap is held to the range resolution the simulation was
given, within :data:`~zbuf_occlude.experiments.returns_comparison.GAP_MIN_TOLERANCE`.  The scanner is the real file's fitted one
(:func:`~zbuf_occlude.sensors.fit.return_model.fit_return_model`, applied by
:meth:`~zbuf_occlude.sensors.fit.return_model.ReturnModelFit.apply`): its range resolution, most
returns per pulse and detection threshold (m⁻²).  So that the simulated echoes' energies are in the
threshold's units, the ground reflects with the fit's ground reflectance and every mesh with its
material's at 1064 nm (:func:`~zbuf_occlude.sensors.scene.materials.scene_optics`).  With
``ReturnsSettings(detection=False)`` the threshold is 0 and every surface reflects alike: every
echo returns.  The divergence is fitted by the sweep
(:func:`~zbuf_occlude.sensors.fit.divergence.divergence_from_shares`).
"""

from __future__ import annotations

import json
import logging
import math
import os
import platform
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.experiments.returns import (
    AUTZEN_CELL_M,
    GROUND_CLASS,
    IGN_ALTITUDE_M,
    IGN_DIVERGENCE_DEG,
    IGN_PULSES_PER_M2,
    PLOT_CROWN_SHELL_M,
    PLOT_LEAF_SIDE_M,
    PLOT_TREES,
    ign_scanner,
    plot_scene,
    pulse_subset,
    simulate,
)
from zbuf_occlude.experiments.tree_cover import (
    TREE_COVER_BLOCK_M,
    TREE_COVER_CELL_M,
    TREE_COVER_MIN_PULSES,
    plot_cover,
    spacing_for_cover,
    tree_cover,
)
from zbuf_occlude.experiments.returns_comparison import (
    RETURN_COUNTS,
    class_suffix,
    comparison_markdown,
    cover_markdown,
    comparison_rows,
    estimate_of,
    recommend_k,
)
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.las import LasPoints, read_las
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.sensors.fit import Estimate
from zbuf_occlude.sensors.fit.return_model import ReturnModelFit
from zbuf_occlude.sensors.kinds import with_beam
from zbuf_occlude.sensors.fit.returns import (
    VEGETATION_CLASSES,
    ReturnStatistics,
    return_statistics,
)
from zbuf_occlude.sensors.scene.objects import ScanScene

__all__ = ["RETURNS_OUTPUTS", "ReturnsSettings", "SimulatedModel", "cover_rays_per_cell", "ign_plot", "refits_divergence", "run_returns",
           "scans_of_run", "simulated_model"]  # fmt: skip

log = logging.getLogger(__name__)

RETURNS_OUTPUTS = ("real.md", "divergence_sweep.csv", "k_sweep.csv", "comparison.csv", "comparison.md", "returns.png", "run.json")


@dataclass(frozen=True)
class ReturnsSettings:
    """What a run sweeps; the defaults are the results page's run (about 3 CPU minutes).

    Attributes
    ----------
    divergence_factors : tuple of float
        Divergences swept, as multiples of :data:`~.returns.IGN_DIVERGENCE_DEG`.
    sweep_rays : tuple of int
        Sub-ray counts K of the divergence sweep.
    k_values : tuple of int
        Sub-ray counts of the K sweep (at the fitted divergence); the largest is the reference.
    seeds : tuple of int
        Scans pooled per setting (each its own flight line phase).
    repeats : int
        Interleaved timing rounds of the K sweep (median).
    copies : int
        Each mesh stands this many times in the plot (more vegetation pulses).
    spacing_m : float or None
        Distance between the plot's trees, metres; None (default): the spacing whose tree cover
        is the real tile's (:func:`~.tree_cover.spacing_for_cover`).
    scan_angle_deg : float
        Across-track angle of the plot's centre (the IGN sample's median absolute scan angle is 13°).
    bootstrap : int
        Resamples of every measure.
    detection : bool
        The fitted detection threshold on, and the surfaces' reflectances (module docstring);
        False: no threshold, every surface alike (every echo returns).
    echo_rule : {"chain", "waveform"}
        How the simulated receiver merges a pulse's hits into echoes
        (:attr:`Beam.echo_rule <zbuf_occlude.sensors.beam.fields.Beam.echo_rule>`): ``"waveform"`` (the
        default; its shares converge with K, the chain rule's drift) or ``"chain"``.
    leaf_area_density : float
        Leaves in the crowns of the plot's trees (:data:`~.returns.PLOT_TREES` with ``foliage``), one-sided m² per m³
        of crown, ≥ 0 (:func:`~zbuf_occlude.sensors.scene.foliage.add_foliage` with :data:`~.returns.PLOT_LEAF_SIDE_M`
        and :data:`~.returns.PLOT_CROWN_SHELL_M`); 0: the meshes as they are.  The default, 1, is the one of
        0, 0.5, 1, 1.5 and 2 that passes the most of the experiment's targets (the results page lists the runs).
    plot : {"street", "families"}
        The plot's vegetation: ``"street"`` (default), :data:`~.returns.PLOT_TREES` from the mesh folder, their
        crowns filled with ``leaf_area_density``; ``"families"``, :data:`FAMILY_PLOT`: procedural trees and
        shrubs (:mod:`zbuf_occlude.mesh.families`) at their own drawn sizes, whose crowns are leaf clusters
        with gaps (no leaves added; no mesh folder).

    Raises
    ------
    InvalidInputError
        A negative or non-finite ``leaf_area_density``, an ``echo_rule`` not in ``ECHO_RULES`` or a ``plot`` not in
        :data:`PLOT_CHOICES`, naming the value.
    """

    divergence_factors: tuple[float, ...] = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
    sweep_rays: tuple[int, ...] = (19, 37)
    k_values: tuple[int, ...] = (1, 7, 19, 37, 61, 91)
    seeds: tuple[int, ...] = (0, 1)
    repeats: int = 3
    copies: int = 2
    spacing_m: float | None = None
    scan_angle_deg: float = 13.0
    bootstrap: int = 200
    detection: bool = True
    echo_rule: str = "waveform"
    leaf_area_density: float = 1.0
    plot: str = "street"

    def __post_init__(self) -> None:
        from zbuf_occlude.sensors.checks import real, text
        from zbuf_occlude.sensors.beam.echoes import ECHO_RULES

        object.__setattr__(self, "leaf_area_density", real(self.leaf_area_density, "leaf_area_density", low=0.0))
        object.__setattr__(self, "echo_rule", text(self.echo_rule, "echo_rule", choices=ECHO_RULES))
        object.__setattr__(self, "plot", text(self.plot, "plot", choices=PLOT_CHOICES))


@dataclass(frozen=True)
class SimulatedModel:
    """A real file's fitted return model as the simulation uses it (:func:`simulated_model`).

    Attributes
    ----------
    fit : ReturnModelFit
        The real file's fit (:func:`~zbuf_occlude.sensors.fit.return_model.fit_return_model`).
    reflectivity : tuple of float or None
        Per object id, ground first; None: every surface alike.
    detection : bool
        The fitted detection threshold on; False: 0.
    echo_rule : {"chain", "waveform"}
        The simulated receiver's (:attr:`Beam.echo_rule <zbuf_occlude.sensors.beam.fields.Beam.echo_rule>`).
    """

    fit: ReturnModelFit
    reflectivity: tuple[float, ...] | None  # per object id, ground first; None: every surface alike
    detection: bool
    echo_rule: str = "chain"

    def scanner(self, divergence_deg: float, k: int):
        """:func:`~.returns.ign_scanner` at ``divergence_deg`` (degrees) and ``k`` sub-rays, as the fit sets it (``k`` kept:
        the fit gives a beam of one ray a footprint)."""
        scanner = with_beam(self.fit.apply(ign_scanner(divergence_deg, k)), footprint_rays=k, echo_rule=self.echo_rule)
        return scanner if self.detection else with_beam(scanner, detection_threshold=0.0)

    @property
    def range_resolution_m(self) -> float:
        """The fitted range resolution, metres."""
        return self.fit.estimates["range_resolution_m"].value

    def to_json(self) -> dict[str, Any]:
        """The model for ``run.json``: range resolution, most returns, and with detection the threshold and reflectivities."""
        e = self.fit.estimates
        out = {"range_resolution_m": e["range_resolution_m"].value, "range_resolution_sd_m": e["range_resolution_m"].std,
               "max_returns": int(e["max_returns"].value), "detection": self.detection, "echo_rule": self.echo_rule}  # fmt: skip
        if self.detection:  # the threshold the simulated scanner holds
            out |= {"detection_threshold": self.scanner(IGN_DIVERGENCE_DEG, 1).beam.detection_threshold, "detection_threshold_sd": e["detection_threshold"].std,
                    "detection_threshold_counts": e["detection_threshold_counts"].value, "intensity_scale": e["intensity_scale"].value,
                    "ground_reflectance": self.fit.ground_reflectance, "reflectivity": list(self.reflectivity or ())}  # fmt: skip
        return out


def simulated_model(fit: ReturnModelFit, scene: ScanScene, detection: bool, echo_rule: str = "chain") -> SimulatedModel:
    """The fit's scanner over ``scene``: the ground at the fit's reflectance, each mesh at its material's at 1064 nm
    (``detection`` False: no threshold, every surface alike), its receiver merging echoes by ``echo_rule``."""
    if not detection:
        return SimulatedModel(fit, None, False, echo_rule)
    from zbuf_occlude.sensors.scene.materials import AIRBORNE_WAVELENGTH_NM, scene_optics
    from zbuf_occlude.sensors.scan import build_scene

    rho = scene_optics(build_scene(scene), AIRBORNE_WAVELENGTH_NM).reflectivity.copy()
    rho[0] = fit.ground_reflectance  # the threshold in m⁻² was measured against it
    return SimulatedModel(fit, tuple(float(v) for v in rho), True, echo_rule)


def _sweep_row(result, divergence_deg: float, k: int, suffix: str) -> dict[str, Any]:
    share, share_sd = estimate_of(result.statistics["all"], f"multi_return_points_{suffix}")
    row = {"divergence_deg": divergence_deg, "divergence_mrad": math.radians(divergence_deg) * 1e3, "K": k, "multi_return_share": share,
           "multi_return_share_sd": share_sd, "vegetation_pulses": result.statistics["vegetation"].n_complete_pulses}  # fmt: skip
    for n in RETURN_COUNTS:
        row[f"returns_{n}"], row[f"returns_{n}_sd"] = estimate_of(result.statistics["vegetation"], f"returns_{n}")
    row["seconds_per_mpulse"] = result.seconds / max(result.pulses, 1) * 1e6
    return row


def _real(las: LasPoints, classes: Sequence[int], bootstrap: int) -> tuple[dict[str, ReturnStatistics], ReturnModelFit]:
    """The real file's figures per side and the return model fitted to it
    (:func:`~zbuf_occlude.sensors.fit.return_model.fit_return_model` at the IGN flying height: the
    threshold in m⁻² is the same share of a single ground return at any height the simulation flies)."""
    from zbuf_occlude.sensors.fit.return_model import fit_return_model

    out = {"all": return_statistics(las, classes=classes, bootstrap=bootstrap)}
    for side in ("vegetation", "ground"):
        out[side] = return_statistics(pulse_subset(las, side, classes=classes), classes=classes, bootstrap=bootstrap)
    return out, fit_return_model(las, altitude_m=IGN_ALTITUDE_M, classes=classes, bootstrap=bootstrap)


def cover_rays_per_cell(settings: ReturnsSettings, cell_m: float = TREE_COVER_CELL_M) -> int:
    """Vertical rays per ``cell_m`` cell of :func:`~.tree_cover.plot_cover`: the pulses a cell of the pooled scans holds
    (one flight line per seed at :data:`~.returns.IGN_PULSES_PER_M2`)."""
    return max(1, round(len(settings.seeds) * IGN_PULSES_PER_M2 * cell_m**2))


#: The plot's vegetation choices (:attr:`ReturnsSettings.plot`).
PLOT_CHOICES = ("street", "families")
#: The procedural plot (:func:`family_plot`): objects of each family, drawn with seed :data:`FAMILY_PLOT_SEED`.
FAMILY_PLOT = (("tree", 6), ("shrub", 2))
FAMILY_PLOT_SEED = 0


def family_plot() -> list[tuple[Any, float]]:
    """The procedural plot's objects: ``(mesh, largest dimension in metres)`` of each of :data:`FAMILY_PLOT`'s objects,
    object ``k`` of a family drawn as ``zbuf-occlude families FAMILY --seed FAMILY_PLOT_SEED`` writes it."""
    from zbuf_occlude.mesh.families import FAMILIES
    from zbuf_occlude.mesh.families.fitted import draw_object

    meshes = [draw_object(FAMILIES[name], FAMILY_PLOT_SEED, k)[1] for name, count in FAMILY_PLOT for k in range(count)]
    return [(mesh, float(mesh.extents.max())) for mesh in meshes]


def ign_plot(mesh_root: str | os.PathLike | None, settings: ReturnsSettings, *, tree_cover: float | None = None, height_scale: float = 1.0,
             cover_cell_m: float = TREE_COVER_CELL_M) -> tuple[ScanScene, tuple[int, ...], tuple[float, float], float]:  # fmt: skip
    """The experiment's plot: :data:`~.returns.PLOT_TREES` from ``mesh_root``, their crowns filled with
    ``settings.leaf_area_density`` of leaves (or, with ``settings.plot`` "families", :func:`family_plot`'s objects; no
    ``mesh_root``), ``settings.copies`` of each, on a grid ``settings.spacing_m``
    apart (None: as far apart as gives the tree cover ``tree_cover`` measured on cells of
    ``cover_cell_m``, :func:`~.tree_cover.spacing_for_cover`), its centre ``settings.scan_angle_deg``
    across track.

    ``height_scale`` scales every mesh (each :attr:`~.returns.PlotTree.size_m` times it, > 0) before
    its crown is filled: the leaves keep their size and the crown's filled depth its metres.

    Returns
    -------
    scene, vegetation_ids
        As :func:`~.returns.plot_scene`.
    center_xy : (float, float)
        The plot's centre, metres (world frame: the aircraft flies along +x over y = 0).
    half_size_m : float
        Half the side of the square of ground the scan covers, metres.

    Raises
    ------
    MeshLoadError
        A mesh file that is missing or unreadable (named).
    InvalidInputError
        No spacing and no tree cover, or a cover the meshes cannot give.
    """
    from zbuf_occlude.mesh.load import load_mesh
    from zbuf_occlude.sensors.checks import real
    from zbuf_occlude.sensors.scene.foliage import add_foliage, in_metres

    if settings.spacing_m is None and tree_cover is None:
        raise InvalidInputError("ign_plot needs settings.spacing_m or a tree cover to space the trees for")
    height_scale = real(height_scale, "height_scale", low=0.0, low_open=True)

    meshes, sizes = [], []
    for mesh, size in family_plot() if settings.plot == "families" else ():
        meshes += [mesh] * settings.copies
        sizes += [size * height_scale] * settings.copies
    for i, tree in enumerate(PLOT_TREES if settings.plot == "street" else ()):
        mesh, size = load_mesh(Path(mesh_root) / tree.file, up=tree.up), tree.size_m * height_scale
        if tree.foliage and settings.leaf_area_density > 0:
            mesh = add_foliage(in_metres(mesh, size), leaf_area_density=settings.leaf_area_density, leaf_side_m=PLOT_LEAF_SIDE_M,
                               shell_m=PLOT_CROWN_SHELL_M, seed=i)  # fmt: skip
            size = float(np.ptp(mesh.vertices, axis=0).max())  # leaves at the hull's edge reach out by up to half a leaf
        meshes += [mesh] * settings.copies
        sizes += [size] * settings.copies
    y = IGN_ALTITUDE_M * math.tan(math.radians(settings.scan_angle_deg))
    spacing = settings.spacing_m
    if spacing is None:
        spacing = spacing_for_cover(
            meshes,
            sizes,
            tree_cover,
            center_xy=(0.0, y),
            cell_m=cover_cell_m,
            rays_per_cell=cover_rays_per_cell(settings, cover_cell_m),
            seed=0,
        )
    scene, vegetation = plot_scene(meshes, sizes, spacing_m=spacing, center_xy=(0.0, y), seed=0)
    side = math.ceil(math.sqrt(len(meshes)))
    return scene, vegetation, (0.0, y), side * spacing / 2.0


def scans_of_run(settings: ReturnsSettings, *, autzen: bool = False, refit: bool = False) -> int:
    """The scans :func:`run_returns` makes with ``settings`` (its progress bar's total): the divergence
    sweep, the K sweep and its timing rounds, the two comparisons, with ``autzen`` its sweep and
    comparison, and with ``refit`` the divergence sweep at the recommended K (:func:`refits_divergence`;
    the bar's total grows by it once that K is known)."""
    seeds, factors = len(settings.seeds), len(settings.divergence_factors)
    ks = len(settings.k_values)
    total = factors * len(settings.sweep_rays) * seeds + ks * seeds + (settings.repeats - 1) * ks + 2 * seeds
    return total + (factors * seeds + seeds if autzen else 0) + (factors * seeds if refit else 0)


def refits_divergence(k: int, settings: ReturnsSettings) -> bool:
    """Whether :func:`run_returns` sweeps the divergence again at the recommended K = ``k``: where ``k`` is not
    among ``settings.sweep_rays`` and above 1 (one ray a pulse gives one return at any divergence).  With a
    detection threshold the multi-return share at one divergence moves with K, so the divergence compared at
    a K is the one fitted with it."""
    return k > 1 and k not in settings.sweep_rays


def _divergence_sweep(plot, settings: ReturnsSettings, model: SimulatedModel, ks: Sequence[int], tick) -> list[dict[str, Any]]:
    scene, vegetation, centre, half = plot
    rows = []
    for factor in settings.divergence_factors:
        for k in ks:
            divergence = IGN_DIVERGENCE_DEG * factor
            result = simulate(scene, model.scanner(divergence, k), vegetation, center_xy=centre, half_size_m=half,
                              seeds=settings.seeds, bootstrap=settings.bootstrap, reflectivity=model.reflectivity,
                              on_scan=tick)  # fmt: skip
            rows.append(_sweep_row(result, divergence, k, class_suffix(VEGETATION_CLASSES)) | {"resolution_m": model.range_resolution_m})
            log.info("divergence %.4f° K %d: share %.3f", divergence, k, rows[-1]["multi_return_share"])
    return rows


def _fit_divergence(rows: Sequence[dict[str, Any]], k: int, measured: Estimate) -> dict[str, Any]:
    """Invert the K curve of the sweep at the real share: the value and ``± sd`` of
    :func:`~zbuf_occlude.sensors.fit.divergence.divergence_from_shares` (the real share's sd and the
    simulated shares' added in quadrature, through the curve).  A curve that dips is made monotone
    by a running maximum first (``monotone_fix``); one that never rises gives NaN."""
    from zbuf_occlude.sensors.fit.divergence import divergence_from_shares

    mine = sorted((r for r in rows if r["K"] == k), key=lambda r: r["divergence_deg"])
    x = np.array([r["divergence_deg"] for r in mine])
    y = np.array([r["multi_return_share"] for r in mine])
    fixed = np.maximum.accumulate(y)
    value = std = math.nan
    if fixed[-1] > fixed[0]:
        fit = divergence_from_shares(x, fixed, measured, np.array([r["multi_return_share_sd"] for r in mine]))
        value, std = fit.value, fit.std
    return {"K": k, "divergence_deg": value, "sd_deg": std, "divergence_mrad": math.radians(value) * 1e3, "sd_mrad": math.radians(std) * 1e3,
            "monotone_fix": bool(np.any(fixed != y))}  # fmt: skip


def _k_sweep(plot, settings: ReturnsSettings, divergence_deg: float, model: SimulatedModel, tick) -> list[dict[str, Any]]:
    """Every K measured once, then timed in ``repeats`` interleaved rounds (the measured round included)."""
    from zbuf_occlude.sensors.scan import scan_airborne

    scene, vegetation, centre, half = plot
    rows, times = {}, {k: [] for k in settings.k_values}
    for k in settings.k_values:
        result = simulate(scene, model.scanner(divergence_deg, k), vegetation, center_xy=centre, half_size_m=half,
                          seeds=settings.seeds, bootstrap=settings.bootstrap, reflectivity=model.reflectivity, on_scan=tick)  # fmt: skip
        rows[k] = _sweep_row(result, divergence_deg, k, class_suffix(VEGETATION_CLASSES))
        times[k].append(result.seconds / result.pulses)
    for _ in range(settings.repeats - 1):
        for k in settings.k_values:
            scanner = model.scanner(divergence_deg, k)
            start = time.perf_counter()
            scan = scan_airborne(scene, scanner, centre, half, seed=settings.seeds[0], reflectivity=model.reflectivity, footprint="exact")
            times[k].append((time.perf_counter() - start) / scan.meta["n_rays"])
            tick()
    base = float(np.median(times[min(settings.k_values)]))
    for k, row in rows.items():
        row["seconds_per_mpulse"] = float(np.median(times[k])) * 1e6
        row["cost_vs_smallest_K"] = float(np.median(times[k])) / base
    return list(rows.values())


def _vegetation_patch(las: LasPoints, width_m: float) -> np.ndarray:
    """The vegetation points (3–5) of the ``width_m`` square cell of ``las`` that holds the most, with their pulses' returns."""
    keep = np.isin(las.classification, VEGETATION_CLASSES)
    xy = las.points[keep, :2]
    cells, counts = np.unique(np.floor(xy / width_m).astype(np.int64), axis=0, return_counts=True)
    best = cells[np.argmax(counts)] * width_m
    inside = np.all((las.points[:, :2] >= best) & (las.points[:, :2] < best + width_m), axis=1)
    return inside


def _figure(sim_las: LasPoints, tree_xy: tuple[float, float], tree_half_m: float, real_las: LasPoints, settings_note: str) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5.2))
    colours = {1: "#1b9e77", 2: "#d95f02", 3: "#7570b3", 4: "#e7298a", 5: "#66a61e"}
    near = np.all(np.abs(sim_las.points[:, :2] - np.asarray(tree_xy)) <= tree_half_m, axis=1)
    # the real cell's ground and vegetation only (its noise and other classes left out)
    real_inside = _vegetation_patch(real_las, 2.0 * tree_half_m) & np.isin(real_las.classification, (GROUND_CLASS, *VEGETATION_CLASSES))
    for ax, las, mask, title in (
        (axes[0], sim_las, near, "simulated tree"),
        (axes[1], real_las, real_inside, "real vegetation patch (IGN LiDAR HD)"),
    ):
        p = las.points[mask]
        rn = las.return_number[mask]
        ground = las.classification[mask] == GROUND_CLASS
        base = float(np.median(p[ground, 2])) if ground.any() else float(p[:, 2].min())
        # side view: x along the first axis, height above the cell's median ground return
        for n in sorted(set(rn.tolist())):
            sel = rn == n
            ax.scatter(p[sel, 0] - p[:, 0].min(), p[sel, 2] - base, s=4, c=colours.get(int(n), "k"), label=f"return {n}")
        ax.set_title(f"{title}: {mask.sum():,} points")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("height above the ground (m)")
        ax.set_aspect("equal")
        ax.legend(loc="upper right", fontsize=8, markerscale=2)
    fig.suptitle(f"Returns by return number, {2 * tree_half_m:.0f} m squares seen from the side (ground and vegetation classes)\n"
                 f"{settings_note}", fontsize=9)  # fmt: skip
    fig.tight_layout()
    data = png_bytes(fig, dpi=110)
    plt.close(fig)
    return data


def _csv_rows(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()} for row in rows]


def _compare(plot, real, real_classes, divergence_deg: float, k: int, model: SimulatedModel, settings: ReturnsSettings, label: str, tick):
    scene, vegetation, centre, half = plot
    result = simulate(scene, model.scanner(divergence_deg, k), vegetation, center_xy=centre, half_size_m=half, seeds=settings.seeds,
                      bootstrap=settings.bootstrap, reflectivity=model.reflectivity, on_scan=tick)  # fmt: skip
    rows = comparison_rows(real, result.statistics, real_classes=real_classes, range_resolution_m=model.range_resolution_m, label=label)
    return rows, result


def _covers(tile: Estimate, plot, settings: ReturnsSettings, scans: dict[str, LasPoints]) -> dict[str, Any]:
    """``run.json``'s ``tree_cover``: the tile's (:func:`~.tree_cover.tree_cover`), the plot's by vertical rays
    (:func:`~.tree_cover.plot_cover`) and each compared scan's, measured as the tile's."""
    scene, vegetation, centre, half = plot
    rays = cover_rays_per_cell(settings)
    return {
        "cell_m": TREE_COVER_CELL_M, "min_pulses": TREE_COVER_MIN_PULSES, "block_m": TREE_COVER_BLOCK_M, "tile": tile.to_json(),
        "spacing_m": 2.0 * half / math.ceil(math.sqrt(len(vegetation))), "rays_per_cell": rays,
        "plot_vertical_rays": plot_cover(scene, centre, half, vegetation, rays_per_cell=rays),
        "scans": {label: tree_cover(las, bootstrap=settings.bootstrap).to_json() for label, las in scans.items()},
    }  # fmt: skip


def _autzen(
    path, mesh_root, base_plot, settings: ReturnsSettings, k: int, tick
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], dict[str, Any], str]:
    """Autzen alone, compared like with like: its class 1 (trees, buildings and open ground the
    classifier left) classed by height (:func:`~.canopy.classes_by_height`), its own fitted return
    model (range resolution, most returns, threshold), a plot of its own (the IGN plot's meshes
    scaled to the tile's canopy height, spaced for the tile's tree cover, both measured on
    :data:`~.returns.AUTZEN_CELL_M` cells) and the divergence fitted to its multi-return share."""
    from zbuf_occlude.experiments.canopy import CANOPY_QUANTILE, canopy_height, classes_by_height, heights_above_ground, plot_canopy_height

    las = read_las(path)
    heights = heights_above_ground(las)  # the ground model, once: for the classes and the canopy
    las = classes_by_height(las, heights)
    real, return_fit = _real(las, VEGETATION_CLASSES, settings.bootstrap)
    cover = tree_cover(las, cell_m=AUTZEN_CELL_M, bootstrap=settings.bootstrap)
    rays = cover_rays_per_cell(settings, AUTZEN_CELL_M)
    tile_height = canopy_height(las, cell_m=AUTZEN_CELL_M, heights_m=heights)
    scene, vegetation, centre, half = base_plot
    plot_height = plot_canopy_height(scene, centre, half, vegetation, cell_m=AUTZEN_CELL_M, rays_per_cell=rays)
    scale = tile_height / plot_height
    plot = ign_plot(mesh_root, settings, tree_cover=cover.value, height_scale=scale, cover_cell_m=AUTZEN_CELL_M)
    model = simulated_model(return_fit, plot[0], settings.detection, settings.echo_rule)
    sweep = _divergence_sweep(plot, settings, model, (k,), tick)
    fit = _fit_divergence(sweep, k, real["all"].estimates[f"multi_return_points_{class_suffix(VEGETATION_CLASSES)}"])
    divergence = fit["divergence_deg"] if math.isfinite(fit["divergence_deg"]) else IGN_DIVERGENCE_DEG
    rows, result = _compare(plot, real, VEGETATION_CLASSES, divergence, k, model, settings, "Autzen", tick)
    cover_by_rays = plot_cover(plot[0], plot[2], plot[3], plot[1], cell_m=AUTZEN_CELL_M, rays_per_cell=rays)
    canopy = {"cell_m": AUTZEN_CELL_M, "quantile": CANOPY_QUANTILE, "tile_m": tile_height, "ign_plot_m": plot_height, "height_scale": scale,
              "tile_cover": cover.to_json(), "plot_vertical_rays_cover": cover_by_rays,
              "scan_cover": tree_cover(result.las, cell_m=AUTZEN_CELL_M, bootstrap=settings.bootstrap).to_json(),
              "spacing_m": 2.0 * plot[3] / math.ceil(math.sqrt(len(plot[1])))}  # fmt: skip
    md = (f"{real['all'].markdown()}\n\n### canopy and tree cover ({AUTZEN_CELL_M:g} m cells)\n\n"
          f"* canopy height, {CANOPY_QUANTILE:.0%} quantile: the tile {tile_height:.2f} m, the IGN plot {plot_height:.2f} m: "
          f"the Autzen plot's meshes scaled {scale:.3g}×\n"
          f"* tree cover: the tile {cover.value:.1%} ± {cover.std:.1%} ({cover.n:,} cells), the plot by vertical rays {cover_by_rays:.1%}, "
          f"the compared scan {canopy['scan_cover']['value']:.1%}")  # fmt: skip
    return rows, sweep, fit | model.to_json() | {"canopy": canopy}, md


def run_returns(out: str | os.PathLike, mesh_root: str | os.PathLike | None, real_path: str | os.PathLike, *, autzen_path: str | os.PathLike | None = None,
                settings: ReturnsSettings | None = None, progress: bool = True) -> dict[str, Any]:  # fmt: skip
    """Run the experiment (module docstring) and write :data:`RETURNS_OUTPUTS` into ``out``.

    Parameters
    ----------
    out : str or PathLike
        Output folder (owned: only these names are written).
    mesh_root : str or PathLike or None
        The folder holding :data:`~.returns.PLOT_TREES`' files (``street_objects/bush``); None with
        ``settings.plot`` "families" (and only then).
    real_path : str or PathLike
        The IGN LiDAR HD sample (LAS/LAZ with vegetation classes 3–5).
    autzen_path : str or PathLike, optional
        A second real file for the cross-check (its class 1, trees, buildings and open ground, classed by
        height: :func:`~.canopy.classes_by_height`; its own plot, scaled to its canopy height).
    settings : ReturnsSettings, optional
    progress : bool
        A progress bar of the scans on stderr (:func:`~zbuf_occlude.io.progress.progress`; total
        :func:`scans_of_run`); False: none.

    Returns
    -------
    dict
        ``run.json``'s content: settings, fitted divergences, recommended K, verdict counts; and
        ``table``, ``comparison.md``'s text.

    Raises
    ------
    InvalidInputError, MeshLoadError, OutputError
        A file that cannot be read, a folder that cannot be written, a ``mesh_root`` with the families plot
        or none with the street plot.
    """
    from zbuf_occlude.io.progress import progress as progress_bar

    settings = settings or ReturnsSettings()
    if (mesh_root is None) != (settings.plot == "families"):
        raise InvalidInputError(f"the {settings.plot} plot takes {'no mesh folder' if mesh_root is not None else 'a mesh folder'}")
    started, cpu_started, load_start = time.perf_counter(), time.process_time(), list(os.getloadavg())
    bar = progress_bar(total=scans_of_run(settings, autzen=autzen_path is not None), desc="returns", unit="scan", enabled=progress)
    with bar, OwnedFolder(out, files=RETURNS_OUTPUTS, what="the returns experiment") as folder:
        tick = bar.update
        folder.check_writable(RETURNS_OUTPUTS)
        real_las = read_las(real_path)
        real, fit = _real(real_las, VEGETATION_CLASSES, settings.bootstrap)
        cover = tree_cover(real_las, bootstrap=settings.bootstrap)
        plot = ign_plot(mesh_root, settings, tree_cover=cover.value)
        model = simulated_model(fit, plot[0], settings.detection, settings.echo_rule)
        resolution = model.range_resolution_m
        sweep = _divergence_sweep(plot, settings, model, settings.sweep_rays, tick)
        real_share = real["all"].estimates[f"multi_return_points_{class_suffix(VEGETATION_CLASSES)}"]
        fits = [_fit_divergence(sweep, k, real_share) for k in settings.sweep_rays]
        fitted = fits[-1]["divergence_deg"]
        divergence = fitted if math.isfinite(fitted) else IGN_DIVERGENCE_DEG
        k_rows = _k_sweep(plot, settings, divergence, model, tick)
        k_best = recommend_k(k_rows)
        if refits_divergence(k_best, settings):
            bar.total = scans_of_run(settings, autzen=autzen_path is not None, refit=True)  # shown from the next scan on
            more = _divergence_sweep(plot, settings, model, (k_best,), tick)
            sweep += more
            fits.append(_fit_divergence(more, k_best, real_share))
            if math.isfinite(fits[-1]["divergence_deg"]):
                divergence = fits[-1]["divergence_deg"]
        rows, fitted_result = _compare(plot, real, VEGETATION_CLASSES, divergence, k_best, model, settings, "IGN, fitted divergence", tick)
        nominal_rows, nominal_result = _compare(
            plot, real, VEGETATION_CLASSES, IGN_DIVERGENCE_DEG, k_best, model, settings, "IGN, data-sheet divergence", tick
        )
        rows += nominal_rows
        covers = _covers(
            cover, plot, settings, {"IGN, fitted divergence": fitted_result.las, "IGN, data-sheet divergence": nominal_result.las}
        )
        summary: dict[str, Any] = {}
        real_md = "## IGN LiDAR HD sample\n\n" + "\n\n".join(f"### {side}\n\n{s.markdown()}" for side, s in real.items())
        real_md += f"\n\n### tree cover\n\n{cover_markdown(covers, tile_only=True)}"
        if autzen_path is not None:
            autzen_rows, autzen_sweep, autzen_fit, autzen_md = _autzen(autzen_path, mesh_root, plot, settings, k_best, tick)
            rows += autzen_rows
            sweep += autzen_sweep
            summary["autzen_fit"] = autzen_fit
            real_md += "\n\n## Autzen (class 1 classed by height)\n\n" + autzen_md
        tree = plot[0].objects[0]
        note = (f"simulated: {math.radians(divergence) * 1e3:.3g} mrad, K = {k_best}, range resolution {resolution:.2f} m, "
                f"echo rule {settings.echo_rule}, "
                f"{'fitted detection threshold' if settings.detection else 'no detection threshold'}")  # fmt: skip
        png = _figure(fitted_result.las, tree.position_m[:2], 6.0, real_las, note)
        summary |= {
            "settings": {k: list(v) if isinstance(v, tuple) else v for k, v in settings.__dict__.items()},
            "model": model.to_json(), "divergence_fits": fits, "recommended_k": k_best, "tree_cover": covers,
            "compared_divergence_deg": divergence, "compared_divergence_mrad": math.radians(divergence) * 1e3,
            "verdicts": {v: sum(r["verdict"] == v for r in rows) for v in ("PASS", "FAIL", "not measured")},
            "machine": f"{platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}",
            "load_average_start": load_start, "load_average": list(os.getloadavg()), "seconds": time.perf_counter() - started,
            "cpu_seconds": time.process_time() - cpu_started,
        }  # fmt: skip
        folder.write_text("real.md", real_md)
        folder.write_csv("divergence_sweep.csv", _csv_rows(sweep), fieldnames=list(sweep[-1].keys()))
        folder.write_csv("k_sweep.csv", _csv_rows(k_rows))
        folder.write_csv("comparison.csv", _csv_rows(rows))
        table = comparison_markdown(rows) + "\n" + cover_markdown(covers)
        folder.write_text("comparison.md", table)
        folder.write_bytes("returns.png", png)
        folder.write_text("run.json", json.dumps(summary, indent=2, default=float) + "\n")
    return summary | {"table": table}
