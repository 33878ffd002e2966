"""PCN's partial scans, headless (Yuan et al., "PCN: Point Completion Network", 3DV 2018).

Reproduces https://github.com/wentaoyuan/pcn, ``render/render_depth.py`` (Blender) and
``render/process_exr.py``, with a ray-cast depth image in place of Blender:

1. ``render_depth.py``: the OBJ is imported and rotated back by −π/2 about x, so Blender's world
   is the OBJ's own (ShapeNet: y up).  Our meshes are loaded z-up (ModelNet's convention), so
   they are turned to y-up first (``(x, y, z) → (x, z, −y)``; a file stored y-up, such as a
   ShapeNet OBJ, was turned to z up by :func:`~zbuf_occlude.load_mesh` with ``up="+y"``, which
   ``auto`` picks at a ShapeNetCore path) and scaled to ShapeNetCore v1's normalisation, a bounding-box
   diagonal of 1 centred at the origin (:func:`pcn_mesh`).
2. ``render_depth.py::random_pose``: ``α, β, γ ~ 2π·U[0, 1)`` in that order, ``R = Rz(γ) Ry(β)
   Rx(α)``, camera at ``t = R[:, 2]`` (1 unit from the origin), ``pose = [R | t]`` camera → world
   in Blender's camera axes (looks down −z, y up) (:func:`random_pose`).  These are uniform
   Euler angles, *not* rotations uniform on SO(3) (the camera directions crowd near the poles
   of the z axis); reproduced as written.
3. ``setup_blender``: 160 × 120 pixels, ``camera.data.angle = 2 atan(W / 2 / f)`` with f = 100
   px (square pixels, principal point at the image centre); ``intrinsics.txt`` =
   ``[[100, 0, 80], [0, 100, 60], [0, 0, 1]]`` (:func:`intrinsics`).  The Z pass is taken as
   the planar depth along the optical axis (Blender Internal's Z), 8 views per model.
4. ``process_exr.py::depth2pcd``: ``inv_K`` with ``inv_K[2, 2] = −1``, the depth flipped
   upside down, ``(x·d, y·d, d)`` for every ``d > 0`` through ``inv_K``, then ``pose``
   (:func:`depth2pcd`).  It uses integer pixel indices with ``cx = W/2`` where pixel centres
   sit at ``W/2 − 0.5``: each partial point lies on the ray through ``(u − ½, v + ½)`` instead
   of the pixel centre ``(u, v)`` (OpenCV indices), half a pixel off (0.005 object units at
   depth 1).  Reproduced as written; :func:`~zbuf_occlude.protocols.back_project` with the
   shard's ``K_opencv`` gives the exact points.

The complete cloud beside each model: 16,384 points uniform on the surface (PCN's ground
truth size), same frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.geometry.sampling import sample_surface
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.protocols.base import Protocol, ProtocolOptions
from zbuf_occlude.protocols.depth import PinholeView, render_depth_image

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

__all__ = [
    "random_pose", "intrinsics", "opencv_intrinsics", "depth2pcd", "pcn_mesh", "pcn_views", "PROTOCOL",
    "WIDTH", "HEIGHT", "FOCAL_PX", "N_VIEWS", "COMPLETE_POINTS", "Z_UP_TO_Y_UP",
]  # fmt: skip

#: ``render_depth.py``'s image and focal length, pixels, and scans per model (its ``num_scans``
#: argument; the PCN data set has 8).
WIDTH, HEIGHT, FOCAL_PX, N_VIEWS = 160, 120, 100.0, 8
#: Points of PCN's complete (ground-truth) clouds.
COMPLETE_POINTS = 16384
#: z-up → y-up, the inverse of Blender's OBJ import rotation: ``(x, y, z) → (x, z, −y)``.
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
#: Blender (OpenGL) camera axes → OpenCV camera axes.
_GL_TO_CV = np.diag([1.0, -1.0, -1.0, 1.0])


def random_pose(rs: np.random.RandomState) -> NDArray[np.float64]:
    """``render_depth.py::random_pose``: (4, 4) float64 camera → world, Blender camera axes; three draws of ``rs``."""
    angle_x = rs.uniform() * 2 * np.pi
    angle_y = rs.uniform() * 2 * np.pi
    angle_z = rs.uniform() * 2 * np.pi
    Rx = np.array([[1, 0, 0], [0, np.cos(angle_x), -np.sin(angle_x)], [0, np.sin(angle_x), np.cos(angle_x)]])
    Ry = np.array([[np.cos(angle_y), 0, np.sin(angle_y)], [0, 1, 0], [-np.sin(angle_y), 0, np.cos(angle_y)]])
    Rz = np.array([[np.cos(angle_z), -np.sin(angle_z), 0], [np.sin(angle_z), np.cos(angle_z), 0], [0, 0, 1]])
    R = np.dot(Rz, np.dot(Ry, Rx))
    t = np.expand_dims(R[:, 2], 1)
    return np.concatenate([np.concatenate([R, t], 1), [[0, 0, 0, 1]]], 0)


def intrinsics(width: int = WIDTH, height: int = HEIGHT, focal: float = FOCAL_PX) -> NDArray[np.float64]:
    """``render_depth.py``'s ``intrinsics.txt``: ``[[f, 0, W/2], [0, f, H/2], [0, 0, 1]]``."""
    return np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1]], dtype=np.float64)


def opencv_intrinsics(width: int = WIDTH, height: int = HEIGHT, focal: float = FOCAL_PX) -> NDArray[np.float64]:
    """The camera Blender renders, in OpenCV's convention (pixel centres at integers): ``cx = W/2 − ½``."""
    return np.array([[focal, 0, width / 2 - 0.5], [0, focal, height / 2 - 0.5], [0, 0, 1]], dtype=np.float64)


def depth2pcd(depth: NDArray[np.floating], intrinsics: NDArray[np.floating], pose: NDArray[np.floating]) -> NDArray[np.float64]:
    """``process_exr.py::depth2pcd``: (M, 3) float64 world points of the pixels with ``depth > 0``.

    ``depth`` (H, W), row 0 at the top (as the EXR is read); rows are taken bottom-up.
    """
    inv_K = np.linalg.inv(intrinsics)
    inv_K[2, 2] = -1
    depth = np.flipud(depth)
    y, x = np.where(depth > 0)
    points = np.dot(inv_K, np.stack([x, y, np.ones_like(x)] * depth[y, x], 0))
    points = np.dot(pose, np.concatenate([points, np.ones((1, points.shape[1]))], 0)).T[:, :3]
    return points


def pcn_mesh(mesh: trimesh.Trimesh, up_axis: str = "z") -> trimesh.Trimesh:
    """The mesh in PCN's frame: y up (turned from ``up_axis="z"``), bounding-box diagonal 1, centred.

    Raises
    ------
    InvalidInputError
        ``up_axis`` is not ``"z"`` or ``"y"``.
    """
    import trimesh

    if up_axis not in ("z", "y"):
        raise InvalidInputError(f"up axis must be 'z' or 'y', got {up_axis!r}")
    v = np.asarray(mesh.vertices, dtype=np.float64)
    if up_axis == "z":
        v = v @ Z_UP_TO_Y_UP.T
    lo, hi = v.min(axis=0), v.max(axis=0)
    v = (v - (lo + hi) / 2) / np.linalg.norm(hi - lo)
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)


def pcn_views(mesh: trimesh.Trimesh, rs: np.random.RandomState, n_views: int = N_VIEWS) -> dict[str, np.ndarray]:
    """Render ``n_views`` PCN scans of ``mesh`` (already in PCN's frame, :func:`pcn_mesh`).

    Returns
    -------
    dict
        ``depth (V, H, W) float32``, ``pose (V, 4, 4)`` (camera → world, Blender axes),
        ``extrinsics (V, 3, 4)`` (world → camera, OpenCV), ``K (3, 3)`` (PCN's), ``K_opencv
        (3, 3)``, ``partial (M, 3) float32`` (every view's :func:`depth2pcd`, concatenated),
        ``partial_offsets (V + 1,) int64`` (view ``i`` is ``partial[offsets[i]:offsets[i+1]]``),
        ``partial_face_index (M,) int32``.
    """
    K, K_cv = intrinsics(), opencv_intrinsics()
    depth, poses, extrinsics, partial, faces, offsets = [], [], [], [], [], [0]
    for _ in range(n_views):
        pose = random_pose(rs)
        view = PinholeView.from_pose(K_cv, pose @ _GL_TO_CV, WIDTH, HEIGHT)
        image = render_depth_image(mesh, view)
        pts = depth2pcd(image.depth, K, pose)
        flipped = np.flipud(image.face_index)  # depth2pcd's pixel order
        faces.append(flipped[np.nonzero(np.flipud(image.depth) > 0)].astype(np.int32))
        depth.append(image.depth)
        poses.append(pose)
        extrinsics.append(view.extrinsics)
        partial.append(pts.astype(np.float32))
        offsets.append(offsets[-1] + len(pts))
    return {
        "depth": np.asarray(depth), "pose": np.asarray(poses), "extrinsics": np.asarray(extrinsics), "K": K,
        "K_opencv": K_cv, "partial": np.concatenate(partial), "partial_offsets": np.asarray(offsets, dtype=np.int64),
        "partial_face_index": np.concatenate(faces),
    }  # fmt: skip


def _make(mesh: trimesh.Trimesh, obj: FarmObject, options: ProtocolOptions, rng: np.random.Generator) -> dict:
    m = pcn_mesh(mesh)  # load_mesh gave it z up (options.up)
    arrays = pcn_views(m, np.random.RandomState(int(rng.integers(2**32))))
    if arrays["partial_offsets"][-1] == 0:
        raise InvalidInputError("every PCN view is empty (the mesh is not in front of the cameras)")
    complete, face = sample_surface(m, count=options.complete_points or COMPLETE_POINTS, seed=rng)
    arrays.update(complete=complete.astype(np.float32), complete_face_index=face.astype(np.int32))
    arrays.update(label=np.int64(obj.label))
    return arrays


def _check(options: ProtocolOptions) -> None:
    if options.complete_points < 0:
        raise InvalidInputError(f"--complete-points must be >= 0, got {options.complete_points}")


#: ``--protocol pcn``: per model 8 partial scans (depth, K, pose) and a complete cloud.
PROTOCOL = Protocol(
    name="pcn", summary="PCN (Yuan et al. 2018): 8 depth scans per model, partial clouds, complete cloud, K and poses",
    make=_make, check=_check,
)  # fmt: skip
