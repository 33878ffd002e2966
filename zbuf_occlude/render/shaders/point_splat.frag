#version 430
// The surfel z-buffer of point-only visibility, visibility/point_kernels.py's splat_surfels in
// float32: a pixel of the surfel's box is covered where its central ray (x, y, 1) meets the
// surfel's plane within the radius of its centre q, at depth t (the intersection's z).  The
// depth test (LESS) keeps the nearest; window depth is t mapped linearly onto [0, 1).
//
// Computed from the pixel's offset d from q's projection c = (qx/qz, qy/qz), not from the ray
// itself: with the ray (c + d, 1), t = qz + dt where dt = -qz (n.xy . d) / (n . ray), and the
// intersection's offset from q is h = (c, 1) dt + (d, 0) t.  Every term is of the disk's size,
// so float32 keeps about 1e-7 of the radius; the direct h = ray t - q would cancel down to
// 1e-7 of the depth (1e-4 of the radius at a few pixels per splat).
uniform ivec2 tile_offset;  // first pixel (i, j) of the tile drawn
uniform float pix;          // pixel side, normalised coordinates
uniform float edge_on_cos;  // |cos| between normal and ray below which nothing is covered
uniform float depth_near;   // object units: window depth 0
uniform float depth_scale;  // window depth per object unit
flat in vec4 v_centre_radius;
flat in vec3 v_normal;
flat in int v_id;
flat in ivec2 v_centre_pixel;
flat in vec2 v_centre_fraction;
flat in ivec4 v_box;
layout(location = 0) out int out_id;       // surfel id + 1; the clear value 0 is "none"
layout(location = 1) out float out_depth;  // t, object units

void main() {
    ivec2 pixel = tile_offset + ivec2(gl_FragCoord.xy);
    if (any(lessThan(pixel, v_box.xy)) || any(greaterThan(pixel, v_box.zw))) discard;  // as the kernel
    vec2 d = (vec2(pixel - v_centre_pixel) + (0.5 - v_centre_fraction)) * pix;
    vec3 q = v_centre_radius.xyz;
    vec3 c = vec3(q.xy / q.z, 1.0);
    vec3 ray = c + vec3(d, 0.0);
    float den = dot(v_normal, c) + dot(v_normal.xy, d);
    if (abs(den) < edge_on_cos * length(ray)) discard;  // edge-on: a line of no area
    float dt = -q.z * dot(v_normal.xy, d) / den;
    float t = q.z + dt;
    vec3 h = c * dt + vec3(d, 0.0) * t;
    if (dot(h, h) > v_centre_radius.w * v_centre_radius.w) discard;
    gl_FragDepth = clamp((t - depth_near) * depth_scale, 0.0, 1.0);
    out_id = v_id + 1;
    out_depth = t;
}
