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

# Nothing heavy is imported here: each public name is imported from its module the first time it
# is used (lazy_loader, from the imports listed in __init__.pyi): `import zbuf_occlude` pays for
# none of numba, moderngl, scipy, trimesh or h5py, and a program pays only for what it calls.
import lazy_loader as _lazy

__getattr__, __dir__, _stub_names = _lazy.attach_stub(__name__, __file__)

# The public API in the order the documentation lists it; the same names as __init__.pyi's (a test
# checks), written out because the API docs read __all__ from this file.
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
    "visible_mask",
    "visible_mask_points",
    "point_surfels",
    "PointSurfels",
    "VisibilitySession",
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
    "ArgumentTypeError",
    "UnsafePathError",
    "DatasetFormatError",
    "CheckpointError",
    "PaddedSamplesWarning",
    "CameraPlacementWarning",
    "occlude",
    "OccludedCloud",
    "OccludedDataset",
    "run_farm",
    "export",
    "merge_farm",
    "Lidar",
    "DepthCamera",
    "ScanScene",
    "SceneObject",
    "load_scene",
    "look_at_pose",
    "Scan",
    "scan",
]

from zbuf_occlude import _llvm  # noqa: E402 (after __all__, before any OpenGL or Triton import)

_llvm.install()  # Triton's LLVM binds to itself, whatever OpenGL context is made before or after (see _llvm)
