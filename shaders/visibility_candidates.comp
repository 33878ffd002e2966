#version 430
// Default z-buffer HSR ("zbuffer"): the faces the rasteriser kept in a (2r+1)^2 pixel
// neighbourhood of the point's projection are the only faces that can hide it; each
// distinct one (other than the point's own face) gets an exact segment test.
// If no candidate hits and the point's own face appears nowhere in the window, the image
// holds no evidence that its surface is the one in front (sub-pixel sliver faces, rays
// through cracks of triangle soup): the point is flagged uncertain.
//#include common.glsl

uniform int neighborhood;      // r, pixels
uniform float tolerance;       // self-hit distance, object units
uniform float edge_epsilon;    // barycentric widening
const int MAX_CANDIDATES = 81; // (2r+1)^2 for r <= 4

void main() {
    uint i = gl_GlobalInvocationID.x + point_offset;
    if (i >= n_points) return;
    vec3 p = points[i].xyz;
    vec2 window;
    float ndc_z;
    if (!reproject(p, window, ndc_z)) return;
    ivec2 pixel = ivec2(floor(window));
    int own = point_face[i];
    int tested[MAX_CANDIDATES];
    int n_tested = 0;
    bool own_seen = false;
    for (int dy = -neighborhood; dy <= neighborhood; ++dy) {
        for (int dx = -neighborhood; dx <= neighborhood; ++dx) {
            ivec2 q = clamp(pixel + ivec2(dx, dy), ivec2(0), resolution - 1);
            int face = int(texelFetch(depth_and_face, q, 0).g);
            own_seen = own_seen || (face == own);
            if (face < 0 || face == own) continue;
            bool seen = false;
            for (int k = 0; k < n_tested; ++k) seen = seen || (tested[k] == face);
            if (seen) continue;
            tested[n_tested++] = face;
            if (segment_hits_face(p, face, tolerance, edge_epsilon)) return;
        }
    }
    mark_visible(i);
    if (own >= 0 && !own_seen) mark_uncertain(i);
}
