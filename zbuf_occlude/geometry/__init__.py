"""Pure numpy geometry: cameras and pinhole intrinsics, surface sampling, seeds and sample draws.

:mod:`.cameras` (poses on a sphere, view schedules, ``K`` and extrinsics), :mod:`.sampling`
(area-weighted surface sampling, Algorithms 1–2), :mod:`.samples` (per-sample seeds, fixed-size
draws from the visible points, :class:`OccludedCloud`).  Imports numpy only.
"""

from zbuf_occlude.geometry.cameras import DEFAULT_RADIUS, Camera, camera_on_sphere, cameras_from_schedule, view_schedule
from zbuf_occlude.geometry.samples import OccludedCloud
from zbuf_occlude.geometry.sampling import points_from_barycentric, sample_faces, sample_surface

__all__ = [
    "Camera", "camera_on_sphere", "view_schedule", "cameras_from_schedule", "DEFAULT_RADIUS",
    "sample_surface", "sample_faces", "points_from_barycentric", "OccludedCloud",
]  # fmt: skip
