#version 430
// Default z-buffer HSR ("zbuffer"): the faces the rasteriser kept in a (2r+1)^2 pixel
// neighbourhood of the point's projection are the only faces that can hide it; each
// distinct one (other than the point's own face) gets an exact segment test.
// If no candidate hits and the centre pixel does not show the point's own face, the image
// holds no direct evidence that its surface is the one in front (sub-pixel sliver faces,
// rays through cracks of triangle soup): the point is flagged uncertain.  (Measured: asking
// for the own face anywhere in the window sends fewer points to the CPU but lets more
// hidden points through; the centre pixel gives the better agreement at the same speed.)
// NEIGHBORHOOD (r) is defined by the loader at compile time: constant loop bounds let
// the compiler unroll the window, which llvmpipe needs to be fast.
//#include common.glsl

uniform float tolerance;       // self-hit distance, object units
uniform float edge_epsilon;    // barycentric widening
const int WINDOW = (2 * NEIGHBORHOOD + 1) * (2 * NEIGHBORHOOD + 1);

void main() {
    uint i = gl_GlobalInvocationID.x + point_offset;
    if (i >= n_points) return;
    vec3 p = points[i].xyz;
    vec2 window;
    if (!reproject(p, window)) return;
    ivec2 pixel = ivec2(floor(window));
    int own = point_face[i];
    // The centre pixel first: for a hidden point it is the likeliest occluder.
    int centre = int(texelFetch(depth_and_face, pixel, 0).g);
    if (centre >= 0 && centre != own && segment_hits_face(p, centre, tolerance, edge_epsilon)) return;
    int tested[WINDOW];
    int n_tested = 0;
    tested[n_tested++] = centre;
    for (int dy = -NEIGHBORHOOD; dy <= NEIGHBORHOOD; ++dy) {
        for (int dx = -NEIGHBORHOOD; dx <= NEIGHBORHOOD; ++dx) {
            ivec2 q = clamp(pixel + ivec2(dx, dy), ivec2(0), resolution - 1);
            int face = int(texelFetch(depth_and_face, q, 0).g);
            if (face < 0 || face == own) continue;
            bool seen = false;
            for (int k = 0; k < n_tested; ++k) seen = seen || (tested[k] == face);
            if (seen) continue;
            tested[n_tested++] = face;
            if (segment_hits_face(p, face, tolerance, edge_epsilon)) return;
        }
    }
    mark_visible(i);
    if (own >= 0 && centre != own) mark_uncertain(i);
}
