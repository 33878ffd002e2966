"""zbuf_occlude: real-like occluded point clouds from meshes.

Pipeline: mesh → samples → camera → render → visibility → output.  Reproduces and extends
Sryamkin, Msallam, Klestov, "A method to create real-like point clouds for 3D object
classification" (2023) with headless z-buffer hidden surface removal (HSR), validated
against an exact geometric oracle.

>>> import zbuf_occlude as zo
>>> clouds = zo.occlude(path, views="grid25", n_points=2048)   # list of OccludedCloud, one per pose
>>> mesh = zo.load_mesh(path)                                # centred, max extent 1
>>> points, face_index = zo.sample_surface(mesh, count=100_000, seed=0)
>>> camera = zo.camera_on_sphere(elevation_deg=30.0, azimuth_deg=45.0, radius=4.0)
>>> mask = zo.visible_mask(mesh, points, camera, method="zbuffer", resolution=1024, face_index=face_index)
"""

from ._version import __version__
from .cameras import DEFAULT_RADIUS, Camera, camera_on_sphere, cameras_from_schedule, view_schedule
from .errors import (
    BackendUnavailable,
    CameraError,
    CheckpointError,
    DatasetBusy,
    DatasetFormatError,
    InvalidInputError,
    MeshLoadError,
    OutputError,
    InsufficientMemoryError,
    RegistryError,
    ShardChecksumError,
    UnknownOptionError,
    UnsafePathError,
    ZbufOccludeError,
)
from .mesh import load_mesh, normalize_mesh
from .render import ModernGLRenderer, context_info, render_depth
from .sampling import points_from_barycentric, sample_faces, sample_surface
from .visibility import MethodInfo, available_methods, method_info, register, visible_mask
from .visibility.zbuffer import ResidentPoints, Scene  # Scene: deprecated alias of ResidentPoints
from .occlude import OccludedCloud, PaddedSamplesWarning, occlude
from .dataset import OccludedDataset
from .farm import merge_farm, run_farm
from .sensors import DepthCamera, Lidar, Scan, ScanScene, SceneObject, load_scene, look_at_pose, scan

__all__ = [
    "__version__",
    "load_mesh",
    "normalize_mesh",
    "sample_surface",
    "sample_faces",
    "points_from_barycentric",
    "Camera",
    "camera_on_sphere",
    "view_schedule",
    "cameras_from_schedule",
    "DEFAULT_RADIUS",
    "ModernGLRenderer",
    "render_depth",
    "context_info",
    "ResidentPoints",
    "Scene",
    "visible_mask",
    "available_methods",
    "method_info",
    "MethodInfo",
    "register",
    "ZbufOccludeError",
    "MeshLoadError",
    "InvalidInputError",
    "CameraError",
    "BackendUnavailable",
    "OutputError",
    "RegistryError",
    "UnknownOptionError",
    "ShardChecksumError",
    "InsufficientMemoryError",
    "DatasetBusy",
    "UnsafePathError",
    "DatasetFormatError",
    "CheckpointError",
    "PaddedSamplesWarning",
    "occlude",
    "OccludedCloud",
    "OccludedDataset",
    "run_farm",
    "merge_farm",
    "Lidar", "DepthCamera", "ScanScene", "SceneObject", "load_scene", "look_at_pose", "Scan", "scan",
]


def __getattr__(name: str):
    # ``zbuf_occlude.profile`` was renamed ``elevation_profile`` (it shadowed the standard
    # library's ``profile``); the old name keeps working, with a warning, for one release.
    if name == "profile":
        import importlib
        import warnings

        warnings.warn(
            "zbuf_occlude.profile is deprecated, use zbuf_occlude.elevation_profile", DeprecationWarning, stacklevel=2
        )
        return importlib.import_module(".elevation_profile", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
