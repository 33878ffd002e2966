"""The numbers the GLSL and the Python side must agree on: binding points and the work-group size.

Each name is written into every shader as a ``#define NAME value`` line after ``#version`` by
:func:`zbuf_occlude.render.shaders.load_shader`, so the GLSL says ``layout(std430, binding =
EXACT_TILE_START)`` and the Python side ``buffer.bind_to_storage_buffer(bindings.EXACT_TILE_START)``;
neither writes a number.

One name per buffer, prefixed by the pass that reads it.  A number names two buffers only in
different passes, each of which binds its own buffers before it runs: ``EXACT_TILE_COUNT`` and
``EXACT_TILE_START`` are both 6, the count/fill passes' per-tile counters and the points pass's
list starts.  There are no uniform blocks; plain uniforms are set by name
(:func:`zbuf_occlude.render.compute.set_uniforms`).
"""

from __future__ import annotations

__all__ = [
    "DECIDE_POINTS", "DECIDE_VISIBLE", "DEPTH_AND_FACE_UNIT", "DRAW_FACES", "EXACT_BIN_FACES", "EXACT_BITS", "EXACT_GLOBAL_FACES",
    "EXACT_PARAMS", "EXACT_PLANES", "EXACT_POINTS", "EXACT_POINTS64", "EXACT_POINT_FACES",
    "EXACT_POINT_INDEX", "EXACT_TILE_COUNT", "EXACT_TILE_FACES", "EXACT_TILE_START", "EXACT_TRIANGLES",
    "GROUP_SIZE", "PROBE_PAIRS", "PROBE_PAIR_FACES", "PROBE_PLANES", "PROBE_RESULT", "SCAN_HITS", "SCAN_RAYS",
    "SCAN_TRIANGLES", "SHADER_DEFINES", "SPLAT_DEPTH", "SPLAT_KEY_HIGH", "SPLAT_KEY_LOW", "SPLAT_SURFELS", "SPLAT_WINNER", "VISIBILITY_BITS", "VISIBILITY_POINTS", "VISIBILITY_POINT_FACES",
    "VISIBILITY_TRIANGLES",
]  # fmt: skip

#: ``local_size_x`` of every compute shader: invocations per work group
#: (:func:`zbuf_occlude.render.compute.dispatch` divides by it).
GROUP_SIZE = 256

#: Texture unit of the RG32F render target (linear depth, face index) that the compute passes read.
DEPTH_AND_FACE_UNIT = 0

# -- mesh.frag: the rasteriser ----------------------------------------------------------------------
#: int per drawn face: its row in ``mesh.faces`` (the lowest of its group of identical faces).
DRAW_FACES = 4

# -- visibility_candidates.comp, visibility_tolerance.comp (declared in common.glsl) -----------------
#: vec4 per point, world frame.
VISIBILITY_POINTS = 0
#: int per point: its own face, -1 unknown.
VISIBILITY_POINT_FACES = 1
#: 9 floats per face, world frame.
VISIBILITY_TRIANGLES = 2
#: Written: 1 bit visible per point, then 1 bit uncertain per point.
VISIBILITY_BITS = 3

# -- scan_candidates.comp: sensor rays ----------------------------------------------------------------
#: vec4 per ray: unit direction, world frame.
SCAN_RAYS = 0
#: Written: int per ray, the face hit first (-1 none seen, -2 seen but none hit).
SCAN_HITS = 1
#: 9 floats per face, world frame.
SCAN_TRIANGLES = 2

# -- exact_bin.comp (count and fill passes) and exact_points.comp (points pass) ----------------------
#: vec4 per point, float32 world frame (points pass).
EXACT_POINTS = 0
#: int per point: its own face's group, -1 unknown (points pass).
EXACT_POINT_FACES = 1
#: 9 floats per face, float32 world frame (all passes).
EXACT_TRIANGLES = 2
#: Written: 1 bit visible per point, then 1 bit "cpu" per point (points pass).
EXACT_BITS = 3
#: 16 doubles per face: segment_triangle.pack_planes rows (points pass).
EXACT_PLANES = 4
#: 3 doubles per point, world frame (points pass).
EXACT_POINTS64 = 5
#: Written: uint per tile, the count pass's counts, then the fill pass's write cursors.
EXACT_TILE_COUNT = 6
#: uint per tile plus one: where each tile's list starts in EXACT_TILE_FACES (points pass).
EXACT_TILE_START = 6
#: uvec2 per (tile, face) entry: face, bits of its smallest clip w (written by fill, read by points).
EXACT_TILE_FACES = 7
#: uint count, then the faces every point tests (written by count, read by points).
EXACT_GLOBAL_FACES = 8
#: 5 doubles: eye xyz, tolerance, edge-on sine (points pass).
EXACT_PARAMS = 9
#: int per binned face: the faces binned, one per group of identical faces (count and fill passes).
EXACT_BIN_FACES = 10
#: uint per stored point: its index in the caller's order (points pass).
EXACT_POINT_INDEX = 11

# -- pair64_probe.comp: the float64 pair test on given pairs (tests) ---------------------------------
#: 16 doubles per face: segment_triangle.pack_planes rows.
PROBE_PLANES = 0
#: 7 doubles per pair: point xyz, eye xyz, tolerance.
PROBE_PAIRS = 1
#: int per pair: the face tested.
PROBE_PAIR_FACES = 2
#: Written: int per pair, MISS, HIT or TIE.
PROBE_RESULT = 3

# point_splat.comp (point-splat's GPU z-buffer, zbuf_occlude.render.surfel_zbuffer)
#: Read: float64 per surfel, 7 each (centre, normal, radius).
SPLAT_SURFELS = 0
#: uint per pixel of the band: the high word of the least depth's bits.
SPLAT_KEY_HIGH = 1
#: uint per pixel: the low word of the least depth's bits among those with that high word.
SPLAT_KEY_LOW = 2
#: uint per pixel: the least surfel id among those with that depth.
SPLAT_WINNER = 3
#: Written by the resolve pass: float64 per pixel (as two uint words), the winner's depth, +inf where none.
SPLAT_DEPTH = 4
# point_decide.comp (reads SPLAT_SURFELS, SPLAT_WINNER and SPLAT_DEPTH too)
#: Read: float64 per point, 2 each (spacing, sided as 0 or 1).
DECIDE_POINTS = 5
#: Written: uint per point, 1 visible.
DECIDE_VISIBLE = 6

#: ``(name, value)`` of every constant above, as :func:`~zbuf_occlude.render.shaders.load_shader`
#: defines them in each shader.
SHADER_DEFINES: tuple[tuple[str, int], ...] = tuple((name, globals()[name]) for name in __all__ if name != "SHADER_DEFINES")
