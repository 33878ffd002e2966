"""The public API of zbuf_occlude: what ``import zbuf_occlude as zo`` exposes.

Read by ``lazy_loader.attach_stub`` in ``__init__.py`` (each name is imported from its module
the first time it is used) and by type checkers and the API docs (these imports, as written).
"""

from . import (
    dataset,
    errors,
    experiments,
    farm,
    geometry,
    io,
    learn,
    mesh,
    pipeline,
    protocols,
    real_scans,
    render,
    sensors,
    visibility,
)
from ._version import __version__
from .dataset.reader import OccludedDataset
from .errors import (
    ArgumentTypeError,
    BackendUnavailable,
    CameraError,
    CameraPlacementWarning,
    CheckpointError,
    DatasetBusy,
    DatasetFormatError,
    InsufficientMemoryError,
    InvalidInputError,
    MeshLoadError,
    OutputError,
    PaddedSamplesWarning,
    RegistryError,
    ShardChecksumError,
    UnknownOptionError,
    UnsafePathError,
    ZbufOccludeError,
)
from .exporters import export
from .farm import merge_farm, run_farm
from .geometry.cameras import DEFAULT_RADIUS, Camera, camera_on_sphere, cameras_from_schedule, view_schedule
from .geometry.samples import OccludedCloud
from .geometry.sampling import points_from_barycentric, sample_faces, sample_surface
from .mesh.load import load_mesh, normalize_mesh
from .pipeline import occlude
from .render import ModernGLRenderer, context_info, render_depth
from .sensors import DepthCamera, Lidar, Scan, ScanScene, SceneObject, load_scene, look_at_pose, scan
from .visibility import MethodInfo, available_methods, method_info, register, visible_mask
from .visibility.point_splats import PointSurfels, point_surfels, visible_mask_points
from .visibility.session import VisibilitySession
