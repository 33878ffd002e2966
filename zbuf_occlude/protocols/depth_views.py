"""``--protocol depth``: depth images, K, extrinsics and back-projected clouds from the paper's poses.

Per pose of ``--views`` (:func:`zbuf_occlude.geometry.cameras.camera_on_sphere`, Sryamkin et al. 2023,
§3.3 and Eq. 11–12 for ``paper100``), a depth image is ray-cast
(:func:`~zbuf_occlude.protocols.depth.render_depth_image`), every hit pixel is lifted to 3D
(:func:`~zbuf_occlude.protocols.depth.back_project`, ``sampling="depth"``) and the cloud is
down-sampled to ``n_points`` (``random`` or ``fps``, repeats when fewer).

Shard datasets (one row per view, V views; object units, world frame = the normalised mesh):

* ``depth (V, H, W) float32`` (0 = no hit), ``K (V, 3, 3)``, ``extrinsics (V, 3, 4)`` float64
  (OpenCV, pixel centres at integers, world → camera);
* ``data (V, n, 3) float32``, ``face_index (V, n) int32``, ``n_visible (V,)`` (lifted pixels),
  ``label``, ``elevation_deg``, ``azimuth_deg``, ``radius``, ``sample_index``, ``source``,
  ``class_name``: the keys of :func:`zbuf_occlude.io.clouds.write_h5`, so
  :func:`zbuf_occlude.io.clouds.read_h5_clouds` reads the clouds;
* options: ``normals (V, n, 3) float32`` (the hit face's unit normal, winding as stored),
  ``camera_points (V, n, 3) float32`` (OpenCV camera frame), ``complete (C, 3) float32`` with
  ``complete_face_index (C,)`` (uniform on the whole surface: a partial/complete pair).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from zbuf_occlude.defaults import DEFAULT_N_POINTS
from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.cameras import camera_on_sphere, view_schedule
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.protocols.base import Protocol, ProtocolOptions
from zbuf_occlude.protocols.depth import DOWNSAMPLERS, PinholeView, back_project, downsample, render_depth_image

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = ["depth_views", "PROTOCOL"]


def depth_views(
    mesh: trimesh.Trimesh,
    views: list[PinholeView],
    *,
    n_points: int,
    rng: np.random.Generator,
    downsampler: str = "random",
    normals: bool = False,
    camera_frame: bool = False,
    complete_points: int = 0,
) -> dict[str, np.ndarray]:
    """Depth image, back-projected cloud and camera of each view (shard datasets of the module docstring).

    Raises
    ------
    InvalidInputError
        No view sees the mesh (every depth image empty), or a bad ``downsampler``.
    """
    out: dict[str, list] = {k: [] for k in ("depth", "K", "extrinsics", "data", "face_index", "n_visible")}
    if normals:
        out["normals"] = []
    if camera_frame:
        out["camera_points"] = []
    face_normals = np.asarray(mesh.face_normals) if normals else None
    for view in views:
        image = render_depth_image(mesh, view)
        points, cam, pixels = back_project(image.depth, view.K, view.extrinsics)
        face = image.face_index[pixels[:, 1], pixels[:, 0]]
        chosen = downsample(points, n_points, rng, downsampler)
        pad = n_points - len(chosen)  # an empty view gives a zero cloud with n_visible 0

        def take(a: np.ndarray, chosen=chosen, pad=pad) -> np.ndarray:
            return np.concatenate([a[chosen], np.zeros((pad, *a.shape[1:]), a.dtype)]) if pad else a[chosen]

        out["depth"].append(image.depth)
        out["K"].append(view.K)
        out["extrinsics"].append(view.extrinsics)
        out["data"].append(take(points).astype(np.float32))
        out["face_index"].append(take(face).astype(np.int32))
        out["n_visible"].append(len(points))
        if normals:
            out["normals"].append(take(face_normals[face]).astype(np.float32))
        if camera_frame:
            out["camera_points"].append(take(cam).astype(np.float32))
    if not any(out["n_visible"]):
        raise InvalidInputError("the mesh is outside every view (empty depth images)")
    arrays = {k: np.asarray(v) for k, v in out.items()}
    if complete_points:
        pts, fi = sample_surface(mesh, count=complete_points, seed=rng)
        arrays["complete"] = pts.astype(np.float32)
        arrays["complete_face_index"] = fi.astype(np.int32)
    return arrays


def _check(options: ProtocolOptions) -> None:
    if options.downsample not in DOWNSAMPLERS:
        raise InvalidInputError(f"unknown --downsample {options.downsample!r}; use one of {DOWNSAMPLERS}")
    if options.resolution < 1 or (options.n_points is not None and options.n_points < 1) or options.complete_points < 0:
        raise InvalidInputError(
            f"need --resolution >= 1, --points >= 1, --complete-points >= 0; got {options.resolution}, "
            f"{options.n_points}, {options.complete_points}"
        )
    view_schedule(options.views)


def _make(mesh: trimesh.Trimesh, obj: FarmObject, options: ProtocolOptions, rng: np.random.Generator) -> dict[str, np.ndarray]:
    poses = view_schedule(options.views)
    cameras = [camera_on_sphere(el, az, options.radius, resolution=options.resolution) for el, az in poses]
    n_points = options.n_points or DEFAULT_N_POINTS
    arrays = depth_views(
        mesh, [PinholeView.from_camera(c) for c in cameras], n_points=n_points, rng=rng, downsampler=options.downsample,
        normals=options.normals, camera_frame=options.camera_frame, complete_points=options.complete_points,
    )  # fmt: skip
    v = len(poses)
    arrays.update(
        label=np.full(v, obj.label, dtype=np.int64),
        elevation_deg=np.array([p[0] for p in poses], dtype=np.float64),
        azimuth_deg=np.array([p[1] for p in poses], dtype=np.float64),
        radius=np.full(v, options.radius),
        sample_index=np.zeros(v, dtype=np.int64),
        source=np.array([obj.source] * v, dtype=object),
        class_name=np.array([obj.class_name] * v, dtype=object),
    )
    return arrays


#: Depth images + K + extrinsics + back-projected clouds from the paper's poses.
PROTOCOL = Protocol(
    name="depth",
    summary="depth images, K, extrinsics and back-projected clouds (sampling=depth) from --views poses",
    make=_make,
    check=_check,
)
