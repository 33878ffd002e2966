"""Run the GPU's float64 pair test on given pairs: the test harness of the GLSL twin of the CPU kernel.

``zbuffer-exact`` decides near-ties in float64 on the GPU with ``shaders/exact_pair64.glsl``, a
transcription of :func:`zbuf_occlude.visibility.kernels.pair_occludes_one`.  :func:`pair64_on_gpu`
runs that GLSL function (through ``shaders/pair64_probe.comp``, which includes the same file)
on arbitrary (point, eye, face) triples, so that a test can compare the two pair by pair.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from zbuf_occlude.render import bindings
from zbuf_occlude.render.compute import dispatch, read_through
from zbuf_occlude.render.context import shared_context
from zbuf_occlude.render.shaders import load_shader

__all__ = ["MISS", "HIT", "TIE", "pair64_on_gpu"]

#: pair64's answers: the face does not occlude, it occludes, or float64 is within 1e-12 (relative)
#: of a decision boundary (``zbuffer-exact`` leaves those points to the CPU).
MISS, HIT, TIE = 0, 1, 2


def pair64_on_gpu(
    packed_planes: NDArray[np.float64],
    points: NDArray[np.float64],
    eyes: NDArray[np.float64],
    faces: NDArray[np.integer],
    tolerance: float,
) -> NDArray[np.int32]:
    """``(K,) int32`` of :data:`MISS`, :data:`HIT`, :data:`TIE`: does face ``faces[k]`` occlude
    ``points[k]`` from ``eyes[k]`` (float64 GLSL).

    Parameters
    ----------
    packed_planes : (F, 16) float64
        :func:`zbuf_occlude.visibility.segment_triangle.pack_planes` rows.
    points, eyes : (K, 3) float64
        World frame.
    faces : (K,) int
        Indices into ``packed_planes``.
    tolerance : float
        Self-hit tolerance, object units.
    """
    ctx = shared_context()
    k = len(points)
    pairs = np.empty((k, 7), dtype=np.float64)
    pairs[:, 0:3], pairs[:, 3:6], pairs[:, 6] = points, eyes, float(tolerance)
    with ctx:  # another context of this process may be current
        return _run(ctx, packed_planes, pairs, faces, k)


def _run(ctx, packed_planes, pairs, faces, k):
    shader = ctx.compute_shader(load_shader("pair64_probe.comp"))
    planes = ctx.buffer(np.ascontiguousarray(packed_planes, dtype=np.float64).tobytes() or b"\0" * 8)
    pairs_buffer = ctx.buffer(pairs.tobytes() or b"\0" * 8)
    pair_faces = ctx.buffer(np.ascontiguousarray(faces, dtype=np.int32).tobytes() or b"\0" * 4)
    result = ctx.buffer(reserve=max(4 * k, 4))
    staging = ctx.buffer(reserve=max(4 * k, 4))
    try:
        planes.bind_to_storage_buffer(bindings.PROBE_PLANES)
        pairs_buffer.bind_to_storage_buffer(bindings.PROBE_PAIRS)
        pair_faces.bind_to_storage_buffer(bindings.PROBE_PAIR_FACES)
        result.bind_to_storage_buffer(bindings.PROBE_RESULT)
        shader["n_pairs"].value = k
        dispatch(shader, k, "pair_offset")
        return np.frombuffer(read_through(ctx, result, staging, 4 * k), dtype=np.int32).copy()
    finally:
        for obj in (planes, pairs_buffer, pair_faces, result, staging, shader):
            obj.release()
