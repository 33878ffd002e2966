// Shared by the visibility compute shaders: buffers, reprojection, and the exact
// segment-triangle test.  Included by the loader at the //#include line.
layout(local_size_x = GROUP_SIZE) in;

layout(std430, binding = VISIBILITY_POINTS) readonly buffer Points { vec4 points[]; };     // xyz world frame
layout(std430, binding = VISIBILITY_POINT_FACES) readonly buffer PointFaces { int point_face[]; }; // -1: unknown
layout(std430, binding = VISIBILITY_TRIANGLES) readonly buffer Triangles { float triangles[]; }; // 9 floats per face
// 1 bit per point: words [0, n_words) visible, [n_words, 2 n_words) uncertain (the image
// holds no evidence either way; the caller decides those points exactly on the CPU).
layout(std430, binding = VISIBILITY_BITS) buffer Visible { uint visible_bits[]; };

layout(binding = DEPTH_AND_FACE_UNIT) uniform sampler2D depth_and_face;  // RG32F render target: linear depth, face index (-1: none)
uniform mat4 view_projection;      // world -> clip space
uniform vec3 eye;                  // camera centre, world frame
uniform vec4 depth_row;            // -(row 2 of view_matrix): linear depth = dot(depth_row, (p, 1))
uniform ivec2 resolution;          // (width, height) pixels
uniform uint n_points;
uniform uint point_offset;         // first point of this dispatch (dispatch size limits)

// Window coordinates (pixels, origin bottom-left) of a world point; false if outside the
// frustum (behind the camera, outside the image or the clip planes).
bool reproject(vec3 p, out vec2 window) {
    vec4 clip = view_projection * vec4(p, 1.0);
    if (clip.w <= 0.0) return false;
    vec3 ndc = clip.xyz / clip.w;
    if (any(lessThan(ndc, vec3(-1.0))) || any(greaterThanEqual(ndc, vec3(1.0)))) return false;
    window = (ndc.xy * 0.5 + 0.5) * vec2(resolution);
    return true;
}

float linear_depth(vec3 p) { return dot(depth_row, vec4(p, 1.0)); }

vec3 triangle_vertex(int face, int k) {
    int o = 9 * face + 3 * k;
    return vec3(triangles[o], triangles[o + 1], triangles[o + 2]);
}

// Does `face` meet the segment p -> eye farther than `tolerance` (object units) from p?
// Moller-Trumbore with the origin moved to p, which keeps float32 error relative to the
// small vectors (A - p) rather than to world coordinates.  Barycentric bounds are widened
// by `edge_epsilon` so a segment through an edge shared by two faces cannot slip between
// them.  Parallel (edge-on) faces do not occlude.
bool segment_hits_face(vec3 p, int face, float tolerance, float edge_epsilon) {
    vec3 a = triangle_vertex(face, 0) - p;
    vec3 e1 = triangle_vertex(face, 1) - p - a;
    vec3 e2 = triangle_vertex(face, 2) - p - a;
    vec3 d = eye - p;
    vec3 pvec = cross(d, e2);
    float det = dot(e1, pvec);
    if (abs(det) <= 1e-30) return false;
    float inv_det = 1.0 / det;
    vec3 tvec = -a;
    float u = dot(tvec, pvec) * inv_det;
    if (u < -edge_epsilon || u > 1.0 + edge_epsilon) return false;
    vec3 qvec = cross(tvec, e1);
    float v = dot(d, qvec) * inv_det;
    if (v < -edge_epsilon || u + v > 1.0 + edge_epsilon) return false;
    float t = dot(e2, qvec) * inv_det;
    return t * length(d) > tolerance && t <= 1.0;
}

void mark_visible(uint i) {
    atomicOr(visible_bits[i >> 5], 1u << (i & 31u));
}

void mark_uncertain(uint i) {
    atomicOr(visible_bits[((n_points + 31u) >> 5) + (i >> 5)], 1u << (i & 31u));
}
