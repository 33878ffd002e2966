"""The field's occlusion protocols, headless: depth images, ModelNet40-C, PCN.

Each recipe is one module that cites the code it reproduces; :data:`PROTOCOLS` names them for
``zbuf-occlude generate --protocol NAME`` (``paper``, the default, is ``generate`` itself).
"""

from __future__ import annotations

from zbuf_occlude.errors import InvalidInputError
from zbuf_occlude.protocols.base import Protocol, ProtocolOptions, ProtocolRun, read_arrays_h5, run_protocol, write_arrays_h5
from zbuf_occlude.protocols.depth import (
    DOWNSAMPLERS,
    SAMPLINGS,
    DepthImage,
    PinholeView,
    back_project,
    downsample,
    farthest_point_sample,
    project,
    render_depth_image,
)
from zbuf_occlude.protocols.depth_views import PROTOCOL as _DEPTH
from zbuf_occlude.protocols.modelnet40c import LIDAR as _MN40C_LIDAR
from zbuf_occlude.protocols.modelnet40c import OCCLUSION as _MN40C_OCCLUSION
from zbuf_occlude.protocols.pcn import PROTOCOL as _PCN

__all__ = [
    "PROTOCOLS", "PROTOCOL_NAMES", "get_protocol", "Protocol", "ProtocolOptions", "ProtocolRun", "run_protocol",
    "read_arrays_h5", "write_arrays_h5", "PinholeView", "DepthImage", "render_depth_image", "back_project", "project",
    "downsample", "farthest_point_sample", "SAMPLINGS", "DOWNSAMPLERS",
]  # fmt: skip

#: The protocols by name (``paper`` is ``generate``'s own pipeline and is not listed here).
PROTOCOLS: dict[str, Protocol] = {p.name: p for p in (_MN40C_OCCLUSION, _MN40C_LIDAR, _PCN, _DEPTH)}
#: Every value of ``generate --protocol``.
PROTOCOL_NAMES = ("paper", *PROTOCOLS)


def get_protocol(name: str) -> Protocol:
    """The protocol called ``name``.

    Raises
    ------
    InvalidInputError
        Unknown name (the message lists the known ones).
    """
    if name not in PROTOCOLS:
        raise InvalidInputError(f"unknown protocol {name!r}; use one of {', '.join(PROTOCOL_NAMES)}")
    return PROTOCOLS[name]
