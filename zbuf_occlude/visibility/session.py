"""Many poses of one point set: :class:`VisibilitySession`, the one way to keep points set up across views.

A method that can keep state between views declares a ``session`` factory in its
:func:`~zbuf_occlude.visibility.registry.register` line (the points uploaded to the GPU once, an
Embree scene and the points' Morton order built once); :class:`VisibilitySession` opens it, or
calls the method per view when it declares none, so every method answers the same way.  The
README's and the docs' speed figures for "a kept session" are this class with the default method.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.defaults import DEFAULT_METHOD
from zbuf_occlude.geometry.arguments import check_camera, check_mesh
from zbuf_occlude.geometry.placement import warn_camera_placement
from zbuf_occlude.visibility.registry import (
    SessionBase,
    check_face_index,
    check_keywords,
    check_points,
    get_method,
    method_info,
)

if TYPE_CHECKING:
    import trimesh

    from zbuf_occlude.geometry.cameras import Camera

__all__ = ["VisibilitySession"]


class VisibilitySession(SessionBase):
    """HSR for many cameras of one mesh and one point set: set up once, then ``visible(camera)`` per view.

    Gives the same masks as :func:`~zbuf_occlude.visibility.registry.visible_mask` with the same
    method and options, faster when the method keeps state between views (``auto``,
    ``zbuffer-exact``, ``embree-fast``, ``zbuffer``).

    >>> with zo.VisibilitySession(mesh, points, face_index) as session:
    ...     masks = [session.visible(camera) for camera in cameras]

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The occluding surface, world frame.
    points : (N, 3) float
        Points on the surface, world frame.
    face_index : (N,) int, optional
        The face each point was sampled on (a face never hides its own points).
    method : str
        A name of :func:`~zbuf_occlude.visibility.registry.available_methods` (default ``"auto"``).
    **options
        The method's keywords (``resolution``, ``tolerance``, ...), used for every view.

    Raises
    ------
    InvalidInputError
        Unknown method, or bad ``points``/``face_index``.
    UnknownOptionError
        (a ``TypeError``) A keyword the method does not take (named).
    BackendUnavailable
        The method needs OpenGL or Embree and it cannot be had.
    """

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        points: NDArray[np.floating],
        face_index: NDArray[np.integer] | None = None,
        *,
        method: str = DEFAULT_METHOD,
        **options: Any,
    ) -> None:
        self.method = method
        self.options = dict(options)
        self._function = get_method(method)
        check_keywords(method, self.options)
        self._mesh = check_mesh(mesh)
        self._points = check_points(points)
        self._face_index = check_face_index(face_index, len(self._points), len(mesh.faces))
        factory = method_info(method).session
        self._session = factory(mesh, self._points, self._face_index) if factory is not None else None

    def visible(self, camera: Camera) -> NDArray[np.bool_]:
        """The visibility of every point from ``camera``: ``(N,) bool``, in the order given."""
        check_camera(camera)
        warn_camera_placement(camera, self._mesh)
        if self._session is not None:
            return self._session.visible(camera, **self.options)
        return self._function(self._mesh, self._points, camera, face_index=self._face_index, **self.options)

    def release(self) -> None:
        """Free what the method holds (GPU buffers, Embree scenes); later views are computed one call each."""
        if self._session is not None:
            self._session.release()
            self._session = None
