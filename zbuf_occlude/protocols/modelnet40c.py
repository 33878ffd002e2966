"""ModelNet40-C's occlusion and LiDAR corruptions, headless (Sun et al., NeurIPS 2022).

Reproduces the code of https://github.com/jiachens/ModelNet40-C (file and function named beside
each step), with a ray-cast depth image in place of Open3D's ``Visualizer`` (which needs a window):

1. ``data/util.py::normalize``: the mesh's vertices centred on their bounding box, scaled so
   the longest side is 2 (:func:`normalize`).
2. ``data/occlusion.py::random_pose``: ``R = Rz(γ) Ry(0) Rx(α)``, ``α ~ U[2π/3, 5π/6]`` then
   ``γ ~ U[θ − π/5, θ + π/5]``, ``θ = 2π·severity/5``; camera at ``−3 R[:, 2]`` with axes ``R``
   (OpenCV), extrinsic ``[Rᵀ | −Rᵀ t]`` (:func:`occlusion_pose`).  ``lidar_pose``: ``α = 5π/8``,
   distance 5, one draw of ``γ`` (:func:`lidar_pose`).
3. ``get_default_camera_intrinsic`` at ``core_occlusion``'s 1080 × 720 window: ``fx = fy = 365``,
   ``cx = W/2 − 0.5``, ``cy = H/2 − 0.5`` (:func:`intrinsics`).
4. ``core_occlusion``: depth image → ``create_from_depth_image`` (row-major pixels); with
   ``n_points = 1024``: ``ratio = int(N / 1024)``; if ``ratio > 0`` the points are shuffled
   (``util.shuffle_data``) and every ``ratio``-th kept (``uniform_down_sample``).
   ``occlusion_1``: if fewer than 1024, ``np.random.choice(N, 1024)`` (with replacement); the first
   1024 are kept (:func:`depth_cloud`).
5. ``data/generate_c.py::simulate_lidar`` (LiDAR only): points moved to the sensor's origin,
   spherical coordinates (``util.appendSpherical_np``: polar angle from +z), polar angles binned
   in 1° steps from their minimum, the middle half ``[cur + δ/4, cur + 3δ/4)`` of each bin kept
   and snapped to the bin centre, back to Cartesian, ``np.random.choice(N, 768)``
   (:func:`simulate_lidar`).  Its loop bound reads ``np.max(pointcloud_new[:4])``, the first
   four *rows* (all six columns, so about the sensor distance, ~5 rad) rather than column 4;
   it only adds empty bins after the last polar angle, and is reproduced as written.
6. ``generate_c.py::occlusion`` / ``lidar``: ``p @ Rx(−π/2) @ Ry(0) @ Rz(π)`` (z-up → y-up:
   ``(x, y, z) → (−x, z, y)``), float32; occlusion then ``normalize`` again (in float32), LiDAR
   does not (:func:`to_modelnet40c_axes`).

Random draws use a legacy ``numpy.random.RandomState`` per object (their code uses the global
one, seeded once with 2021 for all corruptions in turn), so for one seed every draw above is
reproduced to the bit; the stream of their full run cannot be (it depends on every corruption
generated before occlusion).

Differences that remain, by design: the depth is exact (ray-cast in float64, stored float32)
where Open3D reads back an OpenGL depth buffer; faces are culled when seen from behind, as
Open3D's default ``mesh_show_back_face=False`` does (``cull_back_faces=False`` in
``ProtocolOptions.extra`` renders them two-sided instead); :func:`zbuf_occlude.load_mesh` drops
degenerate faces and unreferenced vertices before the normalisation, which Open3D keeps.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.errors import DatasetFormatError, InvalidInputError
from zbuf_occlude.io.encodings import npy_bytes
from zbuf_occlude.io.owned import OwnedFolder
from zbuf_occlude.io.regular_files import read_regular_file
from zbuf_occlude.mesh.inputs.plan import FarmObject
from zbuf_occlude.protocols.base import Protocol, ProtocolOptions, read_arrays_h5
from zbuf_occlude.protocols.depth import PinholeView, back_project, render_depth_image
from zbuf_occlude.resources import check_memory

if TYPE_CHECKING:  # trimesh is imported where it is used
    import trimesh

log = logging.getLogger(__name__)

__all__ = [
    "MODELNET40_CLASSES", "normalize", "occlusion_pose", "lidar_pose", "intrinsics", "depth_cloud", "simulate_lidar",
    "to_modelnet40c_axes", "occlusion_sample", "lidar_sample", "OCCLUSION", "LIDAR",
    "WIDTH", "HEIGHT", "FOCAL_PX", "N_POINTS", "LIDAR_POINTS",
]  # fmt: skip

#: ``core_occlusion``'s window, pixels, and ``get_default_camera_intrinsic``'s focal length.
WIDTH, HEIGHT, FOCAL_PX = 1080, 720, 365.0
#: Camera distances of ``random_pose`` and ``lidar_pose``, their normalised units (longest side 2).
OCCLUSION_DISTANCE, LIDAR_DISTANCE = 3.0, 5.0
#: Points per cloud: ``occlusion_1(..., n_points=1024)``, and ``simulate_lidar``'s 768.
N_POINTS, LIDAR_POINTS = 1024, 768
#: ``simulate_lidar``'s ring spacing, radians.
RING_STEP_RAD = 1.0 * np.pi / 180.0
#: ModelNet40's ``shape_names.txt`` (the labels of ``label.npy``).
MODELNET40_CLASSES = (
    "airplane", "bathtub", "bed", "bench", "bookshelf", "bottle", "bowl", "car", "chair", "cone", "cup", "curtain",
    "desk", "door", "dresser", "flower_pot", "glass_box", "guitar", "keyboard", "lamp", "laptop", "mantel", "monitor",
    "night_stand", "person", "piano", "plant", "radio", "range_hood", "sink", "sofa", "stairs", "stool", "table",
    "tent", "toilet", "tv_stand", "vase", "wardrobe", "xbox",
)  # fmt: skip


def _rx(a: float) -> NDArray[np.float64]:
    return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])


def _ry(a: float) -> NDArray[np.float64]:
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def _rz(a: float) -> NDArray[np.float64]:
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def normalize(points: NDArray[np.floating]) -> NDArray[np.floating]:
    """``util.normalize`` on a copy: centre each axis on its range, scale the longest side to 2 (dtype kept)."""
    p = np.array(points, copy=True)
    for axis in range(3):
        p[:, axis] -= (np.max(p[:, axis]) + np.min(p[:, axis])) / 2
    lengths = [np.max(p[:, a]) - np.min(p[:, a]) for a in range(3)]
    # their if/elif chain picks the first axis of maximal length
    p *= 2.0 / lengths[int(np.argmax(lengths))]
    return p


def _pose(angle_x: float, angle_z: float, distance: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    R = np.dot(_rz(angle_z), np.dot(_ry(0), _rx(angle_x)))
    t = np.expand_dims(-R[:, 2] * distance, 1)
    extrinsic = np.concatenate([np.concatenate([R.T, -np.dot(R.T, t)], 1), [[0, 0, 0, 1]]], 0)
    pose = np.concatenate([np.concatenate([R, t], 1), [[0, 0, 0, 1]]], 0)
    return extrinsic, pose


def _check_severity(severity: object) -> int:
    if severity is None:
        raise InvalidInputError("ModelNet40-C needs a severity: --severity 1..5 (severity=1..5 in Python)")
    if isinstance(severity, bool) or not isinstance(severity, (int, np.integer)) or not 1 <= severity <= 5:
        raise InvalidInputError(f"ModelNet40-C severity must be an integer 1..5, got {severity!r}")
    return int(severity)


def occlusion_pose(severity: int, rs: np.random.RandomState) -> NDArray[np.float64]:
    """``occlusion.py::random_pose``: (4, 4) float64 world → camera (OpenCV), two draws of ``rs``."""
    theta = 2 * np.pi * _check_severity(severity) / 5
    delta = np.pi / 5
    angle_x = rs.uniform(2.0 / 3.0 * np.pi, 5.0 / 6.0 * np.pi)
    angle_z = rs.uniform(theta - delta, theta + delta)
    return _pose(angle_x, angle_z, OCCLUSION_DISTANCE)[0]


def lidar_pose(severity: int, rs: np.random.RandomState) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``occlusion.py::lidar_pose``: ``(extrinsic, pose)`` (4, 4) float64, world → camera and camera → world."""
    theta = 2 * np.pi * _check_severity(severity) / 5
    delta = np.pi / 5
    return _pose(5.0 / 8.0 * np.pi, rs.uniform(theta - delta, theta + delta), LIDAR_DISTANCE)


def intrinsics(width: int = WIDTH, height: int = HEIGHT) -> NDArray[np.float64]:
    """``get_default_camera_intrinsic``: (3, 3) K, ``fx = fy = 365``, ``cx = W/2 − 0.5``, ``cy = H/2 − 0.5``."""
    return np.array([[FOCAL_PX, 0.0, width / 2 - 0.5], [0.0, FOCAL_PX, height / 2 - 0.5], [0.0, 0.0, 1.0]])


def depth_cloud(
    mesh: trimesh.Trimesh, extrinsic: NDArray[np.float64], rs: np.random.RandomState, *,
    n_points: int = N_POINTS, cull_back_faces: bool = True, width: int = WIDTH, height: int = HEIGHT,
) -> tuple[NDArray[np.float64], int]:  # fmt: skip
    """``core_occlusion`` + ``occlusion_1``: back-projected depth, down-sampled to ``n_points``.

    Returns
    -------
    points : (n_points, 3) float64
        Their normalised frame.
    n_visible : int
        Back-projected pixels before down-sampling.

    Raises
    ------
    InvalidInputError
        Nothing in view (their code would fail in ``np.random.choice(0, ...)``).
    """
    view = PinholeView(intrinsics(width, height), extrinsic[:3], width, height)
    image = render_depth_image(mesh, view, cull_back_faces=cull_back_faces)
    points = back_project(image.depth, view.K, view.extrinsics)[0]
    n_visible = len(points)
    if n_visible == 0:
        raise InvalidInputError("the mesh is not in view of the ModelNet40-C camera (empty depth image)")
    ratio = int(points.shape[0] / n_points)
    if ratio > 0:
        idx = np.arange(points.shape[0])
        rs.shuffle(idx)
        points = points[idx][::ratio]
    if points.shape[0] < n_points:
        points = points[rs.choice(points.shape[0], n_points)]
    return points[:n_points], n_visible


def _spherical(xyz: NDArray[np.float64]) -> NDArray[np.float64]:
    # util.appendSpherical_np: (x, y, z, r, polar angle from +z, azimuth)
    out = np.hstack((xyz, np.zeros(xyz.shape)))
    xy = xyz[:, 0] ** 2 + xyz[:, 1] ** 2
    out[:, 3] = np.sqrt(xy + xyz[:, 2] ** 2)
    out[:, 4] = np.arctan2(np.sqrt(xy), xyz[:, 2])
    out[:, 5] = np.arctan2(xyz[:, 1], xyz[:, 0])
    return out


def _cartesian(rpa: NDArray[np.float64]) -> NDArray[np.float64]:
    # util.appendCart_np
    out = np.hstack((rpa, np.zeros(rpa.shape)))
    out[:, 3] = out[:, 0] * np.sin(out[:, 1]) * np.cos(out[:, 2])
    out[:, 4] = out[:, 0] * np.sin(out[:, 1]) * np.sin(out[:, 2])
    out[:, 5] = out[:, 0] * np.cos(out[:, 1])
    return out


def simulate_lidar(
    points: NDArray[np.float64], pose: NDArray[np.float64], rs: np.random.RandomState, n_points: int = LIDAR_POINTS
) -> NDArray[np.float64]:
    """``generate_c.py::simulate_lidar``: 1° rings around the sensor, ``n_points`` drawn with replacement.

    Returns
    -------
    (n_points, 3) float64
        Their normalised frame.
    """
    pose = pose.transpose().copy()
    pose[:3, :3] = 0
    pose[0, 0] = pose[1, 1] = pose[2, 2] = 1
    pose[3, [0, 1, 2]] = -pose[3, [0, 1, 2]]
    pc = np.concatenate([points, np.ones((points.shape[0], 1))], axis=1)
    pc = _spherical(np.dot(pc, pose)[:, :3])
    delta = RING_STEP_RAD
    cur = np.min(pc[:, 4])
    rings = []
    while cur + delta < np.max(pc[:4]):  # sic: rows, not column 4 (module docstring, step 5)
        band = (pc[:, 4] >= cur + delta / 4) & (pc[:, 4] < cur + delta * 3 / 4)
        pc[band, 4] = cur + delta / 2.0
        rings.append(pc[(pc[:, 4] >= cur + delta / 4) & (pc[:, 4] < cur + delta * 3 / 4)])
        cur += delta
    kept = np.concatenate(rings, axis=0) if rings else np.zeros((0, 6))
    if len(kept) == 0:
        raise InvalidInputError("no point falls in the middle half of a LiDAR ring")
    kept = _cartesian(kept[:, 3:])
    kept = np.dot(np.concatenate([kept[:, 3:], np.ones((kept.shape[0], 1))], axis=1), np.linalg.inv(pose))
    return kept[rs.choice(kept.shape[0], n_points)][:, :3]


def to_modelnet40c_axes(points: NDArray[np.floating]) -> NDArray[np.float64]:
    """``generate_c.py``'s final change of axes: ``p @ Rx(−π/2) @ Ry(0) @ Rz(π)``, i.e. ``(−x, z, y)``."""
    return np.matmul(np.matmul(np.matmul(points, _rx(-np.pi / 2.0)), _ry(0)), _rz(np.pi))


def _their_mesh(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    import trimesh

    return trimesh.Trimesh(normalize(np.asarray(mesh.vertices, dtype=np.float64)), np.asarray(mesh.faces), process=False)


def occlusion_sample(
    mesh: trimesh.Trimesh, severity: int, rs: np.random.RandomState, *, cull_back_faces: bool = True
) -> tuple[NDArray[np.float32], dict]:
    """One ``data_occlusion_<severity>.npy`` row: (1024, 3) float32, and the camera it was seen from."""
    extrinsic = occlusion_pose(severity, rs)
    pts, n_visible = depth_cloud(_their_mesh(mesh), extrinsic, rs, cull_back_faces=cull_back_faces)
    out = normalize(to_modelnet40c_axes(pts).astype("float32"))
    return out, {"extrinsics": extrinsic[:3], "K": intrinsics(), "n_visible": n_visible}


def lidar_sample(
    mesh: trimesh.Trimesh, severity: int, rs: np.random.RandomState, *, cull_back_faces: bool = True
) -> tuple[NDArray[np.float32], dict]:
    """One ``data_lidar_<severity>.npy`` row: (768, 3) float32, and the sensor pose."""
    extrinsic, pose = lidar_pose(severity, rs)
    pts, n_visible = depth_cloud(_their_mesh(mesh), extrinsic, rs, cull_back_faces=cull_back_faces)
    out = to_modelnet40c_axes(simulate_lidar(pts, pose, rs)).astype("float32")
    return out, {"extrinsics": extrinsic[:3], "K": intrinsics(), "n_visible": n_visible}


def _check(options: ProtocolOptions) -> None:
    _check_severity(options.severity)
    if options.n_points not in (None, N_POINTS):
        raise InvalidInputError(f"ModelNet40-C's clouds have a fixed size; drop --points (got {options.n_points})")


def _maker(sample):
    def make(mesh: trimesh.Trimesh, obj: FarmObject, options: ProtocolOptions, rng: np.random.Generator) -> dict:
        rs = np.random.RandomState(int(rng.integers(2**32)))
        points, cam = sample(mesh, options.severity, rs, cull_back_faces=bool(options.extra.get("cull_back_faces", True)))
        return {"points": points, **cam}

    return make


def _check_shared(folder: OwnedFolder, name: str, content: bytes) -> None:
    """Refuse to replace a file that the folder's other runs share (``label.npy``, ``shape_names.txt``)
    with other content: their ``data_*.npy`` rows follow it.

    Raises
    ------
    InvalidInputError
        ``name`` exists with other content (another run in this folder has other meshes).
    UnsafePathError
        ``name`` leads outside the folder (a link).
    """
    path = folder.root / name
    if not path.is_file():
        return  # nothing there, or no regular file: the owned folder refuses to replace it
    # a file of another size differs: it is not read (a file of any size may stand there)
    if path.stat().st_size != len(content) or read_regular_file(path, max_bytes=len(content), within=folder.root) != content:
        raise InvalidInputError(
            f"{path} holds the labels of other meshes (another corruption or severity in {folder.root}); the runs of one "
            "folder share it, as ModelNet40-C's do: run these meshes into another --out"
        )


def _outputs(corruption: str) -> tuple[str, ...]:
    """The names ``finish`` writes: ModelNet40-C's files for each severity, and the sources of their rows."""
    return (rf"data_{corruption}_[1-5]\.npy", r"label\.npy", r"shape_names\.txt", rf"data_{corruption}_[1-5]_sources\.txt")


def _finisher(corruption: str, n_points: int):
    def finish(folder: OwnedFolder, objects: list[FarmObject], shards, options: ProtocolOptions):
        row_bytes = n_points * 3 * np.dtype(np.float32).itemsize
        check_memory(  # the rows, and their .npy bytes
            2 * len(shards) * row_bytes, option=f"data_{corruption}_{options.severity}.npy ({len(shards):,} clouds of {n_points:,} points)",
            hint="run fewer meshes into one --out",
        )  # fmt: skip
        data = np.empty((len(shards), n_points, 3), dtype=np.float32)
        for i, shard in enumerate(shards):
            points = read_arrays_h5(shard, within=folder.root, names=("points",))["points"]
            if points.shape != (n_points, 3):
                raise DatasetFormatError(
                    f"{shard} holds points of shape {points.shape}, not ({n_points}, 3); move it away and run again to redo it"
                )
            data[i] = points
        classes = sorted({o.class_name for o in objects})
        names = list(MODELNET40_CLASSES) if set(classes) <= set(MODELNET40_CLASSES) else classes
        if names is classes:  # said out loud: a ModelNet40-C model's outputs do not index these labels
            log.warning(
                "label.npy indexes this folder's %d classes (shape_names.txt), not ModelNet40's 40: "
                "classes %s are not ModelNet40's", len(names), sorted(set(classes) - set(MODELNET40_CLASSES)),
            )  # fmt: skip
        else:
            log.info("label.npy holds ModelNet40's class indices (shape_names.txt: its 40 classes)")
        labels = np.array([[names.index(o.class_name)] for o in objects], dtype=np.uint8 if len(names) < 256 else np.int64)
        label_bytes, names_text = npy_bytes(labels), "\n".join(names) + "\n"
        _check_shared(folder, "label.npy", label_bytes)  # the corruptions and severities of one folder share them
        _check_shared(folder, "shape_names.txt", names_text.encode("utf-8"))
        files = [
            folder.write_bytes(f"data_{corruption}_{options.severity}.npy", npy_bytes(data)),
            folder.write_bytes("label.npy", label_bytes),
            folder.write_text("shape_names.txt", names_text),
            folder.write_text(f"data_{corruption}_{options.severity}_sources.txt", "".join(o.source + "\n" for o in objects)),
        ]
        return files

    return finish


#: ``--protocol modelnet40-c-occlusion --severity 1..5``: ``data_occlusion_<s>.npy`` (N, 1024, 3) float32 + ``label.npy``.
OCCLUSION = Protocol(
    name="modelnet40-c-occlusion", summary="ModelNet40-C occlusion (Sun et al. 2022): data_occlusion_<s>.npy, label.npy",
    make=_maker(occlusion_sample), finish=_finisher("occlusion", N_POINTS), check=_check, outputs=_outputs("occlusion"),
    run_key=lambda options: f"modelnet40-c-occlusion-s{options.severity}",
)  # fmt: skip
#: ``--protocol modelnet40-c-lidar --severity 1..5``: ``data_lidar_<s>.npy`` (N, 768, 3) float32 + ``label.npy``.
LIDAR = Protocol(
    name="modelnet40-c-lidar", summary="ModelNet40-C LiDAR (Sun et al. 2022): data_lidar_<s>.npy, label.npy",
    make=_maker(lidar_sample), finish=_finisher("lidar", LIDAR_POINTS), check=_check, outputs=_outputs("lidar"),
    run_key=lambda options: f"modelnet40-c-lidar-s{options.severity}",
)  # fmt: skip
