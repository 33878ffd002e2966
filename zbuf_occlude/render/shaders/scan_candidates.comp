#version 430
// Sensor scans (zbuf_occlude.sensors.raycast): each ray's first hit among the faces seen in
// the (2 NEIGHBORHOOD + 1)^2 pixels around its projection, as the z-buffer visibility method
// takes candidates.  Moller-Trumbore in float32 with the origin moved to the sensor.  Output
// per ray: the face (>= 0); -1: the window shows no face (a miss); -2: faces seen but none
// hit (sub-pixel faces, cracks: the caller decides the ray exactly).  The caller recomputes
// the distance on the chosen face in float64.
layout(local_size_x = GROUP_SIZE) in;

layout(std430, binding = SCAN_RAYS) readonly buffer Rays { vec4 rays[]; };          // xyz: unit direction, world
layout(std430, binding = SCAN_HITS) writeonly buffer Hits { int hit_face[]; };
layout(std430, binding = SCAN_TRIANGLES) readonly buffer Triangles { float triangles[]; };  // 9 floats per face

layout(binding = DEPTH_AND_FACE_UNIT) uniform sampler2D depth_and_face;  // RG32F render target: linear depth, face index (-1: none)
uniform mat4 view_projection;      // world -> clip space
uniform vec3 origin;               // sensor centre, world frame
uniform ivec2 resolution;          // (width, height) pixels
uniform uint n_rays;
uniform uint ray_offset;           // first ray of this dispatch (dispatch size limits)
uniform float znear;               // hits nearer than this are ignored, metres
uniform float edge_epsilon;        // barycentric widening, so a ray cannot slip between faces

vec3 triangle_vertex(int face, int k) {
    int o = 9 * face + 3 * k;
    return vec3(triangles[o], triangles[o + 1], triangles[o + 2]);
}

// Ray parameter of the hit of origin + t d on `face`, or -1.
float ray_hit(int face, vec3 d) {
    vec3 a = triangle_vertex(face, 0) - origin;
    vec3 e1 = triangle_vertex(face, 1) - origin - a;
    vec3 e2 = triangle_vertex(face, 2) - origin - a;
    vec3 p = cross(d, e2);
    float det = dot(e1, p);
    if (abs(det) <= 1e-30) return -1.0;
    float inv_det = 1.0 / det;
    vec3 s = -a;
    float u = dot(s, p) * inv_det;
    if (u < -edge_epsilon || u > 1.0 + edge_epsilon) return -1.0;
    vec3 q = cross(s, e1);
    float v = dot(d, q) * inv_det;
    if (v < -edge_epsilon || u + v > 1.0 + edge_epsilon) return -1.0;
    float t = dot(e2, q) * inv_det;
    return t >= znear ? t : -1.0;
}

void main() {
    uint i = gl_GlobalInvocationID.x + ray_offset;
    if (i >= n_rays) return;
    vec3 d = rays[i].xyz;
    vec4 clip = view_projection * vec4(origin + d, 1.0);
    // window coordinates: origin bottom-left, as the texture's rows
    ivec2 pixel = clamp(ivec2(floor((clip.xy / clip.w * 0.5 + 0.5) * vec2(resolution))), ivec2(0), resolution - 1);
    int best = -1;
    float best_t = 3.0e38;
    bool seen = false;
    for (int dy = -NEIGHBORHOOD; dy <= NEIGHBORHOOD; ++dy) {
        for (int dx = -NEIGHBORHOOD; dx <= NEIGHBORHOOD; ++dx) {
            ivec2 q = clamp(pixel + ivec2(dx, dy), ivec2(0), resolution - 1);
            int face = int(texelFetch(depth_and_face, q, 0).g);
            if (face < 0) continue;
            seen = true;
            float t = ray_hit(face, d);
            if (t > 0.0 && t < best_t) {
                best_t = t;
                best = face;
            }
        }
    }
    hit_face[i] = best >= 0 ? best : (seen ? -2 : -1);
}
