#version 430
// One surfel per GL point sprite, or, where SPLAT_QUADS is defined, per instanced quad (a
// 4-vertex triangle strip): the surfels whose sprite GL cannot draw (larger than its largest
// point size, or centred outside the tile: GL drops a point whose centre is clipped, however
// large).  Either covers the surfel's pixel box (visibility/point_kernels.py's, clamped to the
// image) plus one pixel on each side.  The image is mapped orthographically onto clip space, one
// tile at a time; the fragment stage decides the coverage (point_splat.frag).
uniform ivec2 tile_offset;     // first pixel (i, j) of the tile drawn
uniform vec2 tile_size;        // pixels
in int in_id;                  // the surfel's row in the caller's arrays
in ivec4 in_box;               // first and last pixel (i0, j0, i1, j1) the surfel may cover
flat out int v_id;
flat out ivec4 v_box;

void main() {
    vec2 low = vec2(in_box.xy - tile_offset);        // the box's corner, pixels of the tile
    vec2 side = vec2(in_box.zw - in_box.xy + 1);     // its sides, pixels
    vec2 centre = low + 0.5 * side;
#ifdef SPLAT_QUADS
    vec2 corner = vec2(gl_VertexID & 1, gl_VertexID >> 1) * 2.0 - 1.0;
    gl_Position = vec4((centre + corner * (0.5 * side + 1.0)) * 2.0 / tile_size - 1.0, 0.0, 1.0);
#else
    gl_Position = vec4(centre * 2.0 / tile_size - 1.0, 0.0, 1.0);
    gl_PointSize = max(side.x, side.y) + 2.0;
#endif
    v_id = in_id;
    v_box = in_box;
}
