#version 430
// Depth-test z-buffer HSR ("zbuffer-tolerance", and "naive-zbuffer" with zero tolerances):
// a point is visible iff its linear depth is within a tolerance of the depth the rasteriser
// kept at the nearest pixel centre.  The tolerance is slope-scaled as in shadow mapping:
//   depth_tolerance + slope_scale * pixel_footprint(depth) * min(tan(theta), max_slope)
// with theta the angle between the point's face normal and the viewing ray.
//#include common.glsl

uniform float depth_tolerance;  // constant part, object units
uniform float slope_scale;      // multiples of one pixel's depth change
uniform float max_slope;        // clamp of tan(theta) near grazing
uniform float focal_px;         // focal length, pixels

void main() {
    uint i = gl_GlobalInvocationID.x + point_offset;
    if (i >= n_points) return;
    vec3 p = points[i].xyz;
    vec2 window;
    if (!reproject(p, window)) return;
    vec2 texel = texelFetch(depth_and_face, ivec2(floor(window)), 0).rg;
    if (texel.g < 0.0) { mark_visible(i); return; }  // silhouette: nothing drawn in front
    int own = point_face[i];
    float slope = 0.0;
    if (own >= 0 && slope_scale > 0.0) {
        vec3 a = triangle_vertex(own, 0);
        vec3 n = normalize(cross(triangle_vertex(own, 1) - a, triangle_vertex(own, 2) - a));
        float c = abs(dot(n, normalize(eye - p)));
        slope = min(sqrt(max(1.0 - c * c, 0.0)) / max(c, 1e-6), max_slope);
    }
    float point_depth = linear_depth(p);
    float allowed = depth_tolerance + slope_scale * (point_depth / focal_px) * slope;
    if (point_depth <= texel.r + allowed) mark_visible(i);
}
