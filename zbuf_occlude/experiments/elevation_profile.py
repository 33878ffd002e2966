"""Projected area of the visible surface vs camera elevation (Sryamkin et al. 2023, Fig. 12).

The paper explains why classifiers do better from some elevations than others by the
area of the visible part of an object projected onto the x-y, y-z and x-z planes, as a
function of the camera elevation.  It does not spell out the integral; the reading here
is the projected area of the visible surface,

    A_k(el) = ∫_visible |n · e_k| dA,   k ∈ {z (x-y plane), x (y-z plane), y (x-z plane)},

which equals the area of the visible part's shadow on that plane wherever the visible
surface does not overlap itself in that projection.  It is estimated by Monte Carlo from
N uniform surface samples (Algorithms 1-2): each visible sample stands for ``A / N`` of
surface, weighted by ``|n · e_k|`` of its face, and the estimate is averaged over
``azimuths`` evenly spaced camera azimuths at each elevation.

:func:`elevation_profile` writes the CSV and PNG through the output layer (their folder held,
:class:`~zbuf_occlude.io.owned.OwnedFolder`; an existing file of either name replaced only if a run
of ours wrote it and it is unchanged since); :func:`add_profile_parser` adds the
``zbuf-occlude elevation-profile`` subcommand.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude._version import install_hint
from zbuf_occlude.defaults import DEFAULT_METHOD, DEFAULT_RESOLUTION
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, camera_on_sphere
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.io.encodings import png_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.visibility.registry import resolution_option, visible_mask

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "PLANES",
    "DEFAULT_ELEVATIONS",
    "DEFAULT_AZIMUTHS",
    "DEFAULT_PROFILE_POINTS",
    "PROFILE_PNG",
    "profile_outputs",
    "projected_areas",
    "profile_table",
    "elevation_profile",
]

log = logging.getLogger(__name__)

#: Projection planes and the axis of their normal: x-y ⟂ z, y-z ⟂ x, x-z ⟂ y.
PLANES = {"xy": 2, "yz": 0, "xz": 1}
#: Elevations of Fig. 12, degrees: −90…90 in 10° steps (the paper's §4.3 schedule).
DEFAULT_ELEVATIONS = tuple(float(e) for e in range(-90, 91, 10))
#: Azimuths averaged at each elevation (evenly spaced over 360°).
DEFAULT_AZIMUTHS = 8
#: Surface samples of the Monte Carlo estimate: the relative standard error of a
#: projected area is about sqrt((1 - f) / (f N)) for a visible fraction f, i.e. ~1 % at
#: N = 20 000 and f = 0.3.
DEFAULT_PROFILE_POINTS = 20_000
#: The PNG :func:`elevation_profile` writes when ``out`` names a folder.
PROFILE_PNG = "elevation_profile.png"


def projected_areas(mesh: trimesh.Trimesh, face_index: NDArray[np.int64], visible: NDArray[np.bool_]) -> dict[str, float]:
    """Projected areas of the visible surface onto the x-y, y-z and x-z planes.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        World frame (normalised: object units).
    face_index : (N,) int64
        Face of each uniform surface sample.
    visible : (N,) bool
        Visibility of each sample.

    Returns
    -------
    dict
        ``{"xy": A_z, "yz": A_x, "xz": A_y, "visible": A_visible}``, object units²
        (see the module docstring).
    """
    n = len(face_index)
    if n == 0:
        return {**dict.fromkeys(PLANES, 0.0), "visible": 0.0}
    weight = float(mesh.area) / n
    normals = np.abs(np.asarray(mesh.face_normals, dtype=np.float64)[face_index[visible]])
    out = {name: weight * float(normals[:, axis].sum()) for name, axis in PLANES.items()}
    out["visible"] = weight * int(np.count_nonzero(visible))
    return out


def profile_table(
    mesh: trimesh.Trimesh,
    *,
    method: str = DEFAULT_METHOD,
    points: int = DEFAULT_PROFILE_POINTS,
    elevations: Sequence[float] = DEFAULT_ELEVATIONS,
    azimuths: int = DEFAULT_AZIMUTHS,
    resolution: int = DEFAULT_RESOLUTION,
    radius: float = DEFAULT_RADIUS,
    seed: int = 0,
    progress: bool = True,
    **options: Any,
) -> list[dict[str, float]]:
    """Fig. 12's curves: mean projected visible areas per elevation.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Normalised mesh.
    method : str
        HSR method (default ``"zbuffer"``; ``"oracle"`` is exact and slower).
    points : int
        Surface samples.
    elevations : sequence of float
        Degrees in [−90, 90].
    azimuths : int
        Evenly spaced azimuths averaged per elevation.
    resolution, radius, seed
        Camera image size (px), camera distance (object units), sampling seed.
    progress : bool
        Progress on stderr (:func:`zbuf_occlude.io.progress.progress`).
    **options
        Passed to the method.

    Returns
    -------
    rows : list of dict
        ``elevation_deg``, ``area_xy``, ``area_yz``, ``area_xz``, ``area_visible``
        (means over azimuths, object units²) and their standard deviations over azimuths
        (``*_std``), and ``surface_area``.

    Raises
    ------
    InvalidInputError
        ``azimuths < 1`` or ``points < 1``.
    """
    from zbuf_occlude.io.progress import progress as progress_bar

    if int(azimuths) < 1 or int(points) < 1:
        raise InvalidInputError(f"azimuths and points must be >= 1, got {azimuths} and {points}")
    pts, fi = sample_surface(mesh, count=int(points), seed=seed)
    az_list = [k * 360.0 / int(azimuths) for k in range(int(azimuths))]
    method_options = {**resolution_option(method, resolution), **options}
    rows = []
    for el in progress_bar(list(elevations), desc="elevation-profile", unit="elevation", enabled=progress):
        samples = []
        for az in az_list:
            camera = camera_on_sphere(float(el), az, radius, resolution=resolution)
            mask = visible_mask(mesh, pts, camera, method, face_index=fi, **method_options)
            samples.append(projected_areas(mesh, fi, mask))
        row: dict[str, float] = {"elevation_deg": float(el)}
        for key in (*PLANES, "visible"):
            values = np.array([s[key] for s in samples])
            row[f"area_{key}"] = float(values.mean())
            row[f"area_{key}_std"] = float(values.std())
        row["surface_area"] = float(mesh.area)
        rows.append(row)
    return rows


def profile_outputs(out: str | os.PathLike) -> tuple[Path, Path]:
    """The PNG and the CSV :func:`elevation_profile` writes for ``out``: ``out`` itself, or
    :data:`PROFILE_PNG` inside it when it is a folder (existing, or without suffix); the CSV beside
    the PNG with the suffix ``.csv``.  These two are every name it writes."""
    png = Path(out)
    if png.is_dir() or png.suffix == "":
        png = png / PROFILE_PNG
    return png, png.with_suffix(".csv")


def _plot(rows: list[dict[str, float]], title: str) -> bytes:
    """The profile's three areas against elevation, each with its spread: the bytes of a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    el = [r["elevation_deg"] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for key, label in (("xy", "x-y plane"), ("yz", "y-z plane"), ("xz", "x-z plane")):
        mean = np.array([r[f"area_{key}"] for r in rows])
        std = np.array([r[f"area_{key}_std"] for r in rows])
        line = ax.plot(el, mean, marker="o", ms=3, label=label)[0]
        ax.fill_between(el, mean - std, mean + std, color=line.get_color(), alpha=0.15)
    ax.set(xlabel="camera elevation (degrees)", ylabel="projected visible area (object units²)", title=title)
    ax.set_xticks(range(-90, 91, 30))
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    try:
        return png_bytes(fig, dpi=120)
    finally:
        plt.close(fig)


def elevation_profile(
    mesh_path: str | os.PathLike,
    out: str | os.PathLike = "elevation_profile.png",
    *,
    method: str = DEFAULT_METHOD,
    points: int = DEFAULT_PROFILE_POINTS,
    elevations: Sequence[float] = DEFAULT_ELEVATIONS,
    azimuths: int = DEFAULT_AZIMUTHS,
    resolution: int = DEFAULT_RESOLUTION,
    seed: int = 0,
    progress: bool = True,
) -> Path:
    """``zbuf-occlude elevation-profile``: Fig. 12 of Sryamkin et al. 2023 for one mesh.

    Parameters
    ----------
    mesh_path : path
        Mesh file.
    out : path
        The PNG to write; the CSV goes next to it with the suffix ``.csv``.  A folder
        (existing, or without suffix) gets ``elevation_profile.png`` inside.
    method : str
        HSR method (default ``zbuffer``).
    points : int
        Surface samples (default 20 000).
    elevations : sequence of float
        Degrees (default −90…90 step 10).
    azimuths : int
        Azimuths averaged per elevation (default 8).
    resolution : int
        Camera image size, pixels.
    seed : int
        Sampling seed.
    progress : bool
        Progress bar.

    Returns
    -------
    Path
        The PNG (the CSV is ``png.with_suffix(".csv")``).

    Raises
    ------
    MeshLoadError
        The mesh cannot be read.
    InvalidInputError
        Bad arguments.
    OutputError
        The output cannot be written.
    UnsafePathError
        The PNG or the CSV exists and was not written by a run of ours, or was changed since
        (checked before the profile is computed; nothing is written).
    DatasetBusy
        Another live process holds the folder of the output.
    BackendUnavailable
        matplotlib is missing (the ``plot`` extra), or the method's
        backend is.
    """
    from zbuf_occlude.errors import BackendUnavailable

    try:
        import matplotlib  # noqa: F401  (checked before the long run, used by _plot)
    except ImportError:
        raise BackendUnavailable(f"elevation-profile needs matplotlib: {install_hint('plot')}") from None
    from zbuf_occlude.mesh.load import load_mesh  # trimesh: imported when a profile runs

    mesh = load_mesh(mesh_path)
    png, csv = profile_outputs(out)
    names = (png.name, csv.name)
    with OwnedFolder(png.parent, files=names, what="the elevation profile") as folder:
        folder.check_writable(names)  # both before the profile is computed: a refusal writes nothing
        rows = profile_table(
            mesh,
            method=method,
            points=points,
            elevations=elevations,
            azimuths=azimuths,
            resolution=resolution,
            seed=seed,
            progress=progress,
        )
        folder.write_csv(csv.name, rows)
        title = f"Projected visible area vs elevation: {Path(mesh_path).stem} ({method}, {points} points)"
        folder.write_bytes(png.name, _plot(rows, title))
    log.info("elevation profile written to %s", png)
    return png
