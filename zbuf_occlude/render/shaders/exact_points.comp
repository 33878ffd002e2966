#version 430
// "zbuffer-exact", pass 3: decide every point exactly against every face binned into its
// tile (exact_bin.comp), i.e. against a complete candidate set.
//
// Each (point, face) pair is first classified in float32 with an error bound (hit, miss,
// or tie); a tie is re-decided in float64 with the oracle's own formulas, written out
// operation by operation (visibility/oracle.py `_pair_occludes`, visibility/definition.py),
// so that it gives the oracle's bits.  Only a float64 result within 1e-12 (relative) of a
// decision boundary, or a point within a hair of the frustum's border, is left to the CPU
// ("cpu" bit).  Output: 1 bit visible, 1 bit cpu per point.
layout(local_size_x = GROUP_SIZE) in;

layout(std430, binding = EXACT_POINTS) readonly buffer Points { vec4 points[]; };          // float32 xyz
layout(std430, binding = EXACT_POINT_FACES) readonly buffer PointFaces { int point_face[]; };    // -1: unknown
layout(std430, binding = EXACT_TRIANGLES) readonly buffer Triangles { float triangles[]; };    // 9 per face
layout(std430, binding = EXACT_BITS) buffer Bits { uint bits[]; };                        // visible | cpu
layout(std430, binding = EXACT_PLANES) readonly buffer Planes { double planes[]; };         // 16 per face
layout(std430, binding = EXACT_POINTS64) readonly buffer Points64 { double points64[]; };     // 3 per point
layout(std430, binding = EXACT_TILE_START) readonly buffer TileStart { uint tile_start[]; };    // n_tiles + 1
layout(std430, binding = EXACT_TILE_FACES) readonly buffer TileFaces { uvec2 tile_faces[]; };   // face, min depth bits
layout(std430, binding = EXACT_GLOBAL_FACES) readonly buffer GlobalFaces { uint global_faces[]; };
layout(std430, binding = EXACT_PARAMS) readonly buffer Params { double params[]; };         // eye xyz, tol, edge_sin
layout(std430, binding = EXACT_POINT_INDEX) readonly buffer PointIndex { uint point_index[]; }; // caller's order

uniform mat4 view_projection;
uniform vec4 depth_row;      // linear depth = dot(depth_row, (p, 1))
uniform ivec2 resolution;
uniform int tile;
uniform ivec2 tiles;
uniform uint n_points;
uniform uint point_offset;
uniform vec3 eye;
uniform float tolerance;     // float32 copy of params[3]
uniform float edge_sin;      // float32 copy of params[4]
uniform float coord_err;     // bound on the float32 error of a vertex minus a point, object units
uniform float dir_err;       // bound on the float32 error of eye - point
uniform vec2 depth_range;    // znear, zfar
uniform float frustum_margin;  // pixels

const float EPS = 5.9604645e-8;   // 2^-24
const int MAX_DEFERRED = 8;  // float64 re-checks queued per point before deciding in line

//#include exact_pair64.glsl
dvec3 P64(uint i) { return dvec3(points64[3u * i], points64[3u * i + 1u], points64[3u * i + 2u]); }

// ---- float32 with an error bound ------------------------------------------------------------
vec3 V32(int f, int k) { int o = 9 * f + 3 * k; return vec3(triangles[o], triangles[o + 1], triangles[o + 2]); }

// Segment p -> eye (d = eye - p, |d| <= md) against face f: HIT, MISS or TIE.  Triple
// products relative to p, error bounds from max-norms (no square roots on the common path).
// `maybe_own` (asked only without face_index) is set when the face may contain p and be
// seen edge-on (rule (b)).
const float SQRT3 = 1.7320508;
float mnorm(vec3 v) { return SQRT3 * max(abs(v.x), max(abs(v.y), abs(v.z))); }

int pair32(vec3 p, vec3 d, float md, int f, bool ask_own, out bool maybe_own) {
    vec3 a = V32(f, 0) - p, b = V32(f, 1) - p, c = V32(f, 2) - p;
    float la = mnorm(a), lb = mnorm(b), lc = mnorm(c);
    float de = coord_err + 2.0 * EPS * max(la, max(lb, lc));
    vec3 bc = cross(b, c), ca = cross(c, a), ab = cross(a, b);
    float wa = dot(d, bc), wb = dot(d, ca), wc = dot(d, ab);
    float ea = dir_err * lb * lc + md * de * (lb + lc + de) + 8.0 * EPS * md * lb * lc;
    float eb = dir_err * lc * la + md * de * (lc + la + de) + 8.0 * EPS * md * lc * la;
    float ec = dir_err * la * lb + md * de * (la + lb + de) + 8.0 * EPS * md * la * lb;
    maybe_own = false;
    bool some_pos = wa > ea || wb > eb || wc > ec;
    bool some_neg = wa < -ea || wb < -eb || wc < -ec;
    float det = wa + wb + wc;
    float ed = ea + eb + ec + 4.0 * EPS * (abs(wa) + abs(wb) + abs(wc));
    float num = dot(a, bc);
    float en = de * (lb * lc + la * lc + la * lb + de * (la + lb + lc) + de * de) + 8.0 * EPS * la * lb * lc;
    if (ask_own) {
        float nl = mnorm(cross(b - a, c - a));  // >= |n|
        maybe_own = abs(num) <= tolerance * nl + en && abs(det) <= edge_sin * nl * md * 1.0001 + ed;
    }
    if (some_pos && some_neg) return MISS;  // the line misses the closed triangle
    if (abs(det) > ed) {
        float t = num / det;
        float terr = (en + abs(t) * ed) / (abs(det) - ed) + 4.0 * EPS * abs(t);
        float d_lo = (t - terr) * md * (1.0 - 4.0 * EPS), d_hi = (t + terr) * md * (1.0 + 4.0 * EPS);
        float tol_lo = tolerance * (1.0 - 1.0e-5), tol_hi = tolerance * (1.0 + 1.0e-5);
        if (t + terr < 0.0 || d_hi < tol_lo || t - terr > 1.0 + 4.0 * EPS) return MISS;
        bool inside = (wa > ea && wb > eb && wc > ec) || (wa < -ea && wb < -eb && wc < -ec);
        // md bounds |d| from above: the lower distance bound needs |d| itself.
        if (inside && (t - terr) * length(d) * (1.0 - 4.0 * EPS) > tol_hi && t + terr < 1.0 - 4.0 * EPS) return HIT;
    }
    return TIE;
}

// Bits go to the point's index in the caller's order (points are stored in Morton order).
void mark(uint i, uint word_offset) {
    uint j = point_index[i];
    atomicOr(bits[word_offset + (j >> 5)], 1u << (j & 31u));
}

void main() {
    uint i = gl_GlobalInvocationID.x + point_offset;
    if (i >= n_points) return;
    uint cpu_words = (n_points + 31u) >> 5;
    vec3 p = points[i].xyz;
    // Frustum, as Camera.in_frustum: depth in [znear, zfar], pixel in [0, W) x [0, H)
    // (OpenCV rows; window y runs the other way).  Within frustum_margin: the CPU decides.
    vec4 clip = view_projection * vec4(p, 1.0);
    float depth = dot(depth_row, vec4(p, 1.0));
    float dm = 1.0e-5 * abs(depth);
    if (depth < depth_range.x - dm || depth > depth_range.y + dm || clip.w <= 0.0) return;
    vec2 w = (clip.xy / clip.w * 0.5 + 0.5) * vec2(resolution);
    vec2 res = vec2(resolution);
    float m = frustum_margin;
    if (w.x < -m || w.x >= res.x + m || w.y <= -m || w.y > res.y + m) return;
    if (depth < depth_range.x + dm || depth > depth_range.y - dm || w.x < m || w.x >= res.x - m || w.y <= m || w.y > res.y - m) {
        mark(i, cpu_words);
        return;
    }
    dvec3 eye64 = dvec3(params[0], params[1], params[2]);
    double tol = params[3], esin = params[4];
    dvec3 p64 = P64(i);
    precise dvec3 seg = eye64 - p64;
    precise double seg_len = sqrt(dot3(seg, seg));
    int own = point_face[i];
    bool cpu = false;
    if (own >= 0) {
        int e = edge_on64(p64, seg, seg_len, own, esin);
        if (e == HIT) return;
        cpu = e == TIE;
    }
    vec3 d = eye - p;
    float md = max(length(d), mnorm(d) / SQRT3) * (1.0 + 4.0 * EPS);
    ivec2 t = clamp(ivec2(floor(w / float(tile))), ivec2(0), tiles - 1);
    uint id = uint(t.y * tiles.x + t.x);
    uint n_global = global_faces[0];
    uint start = tile_start[id], stop = tile_start[id + 1u];
    // A face whose nearest vertex is deeper than the point cannot lie between it and the
    // eye (depth is linear along the segment); the slack covers float32 rounding.
    float depth_cut = depth * (1.0 + 1.0e-5) + coord_err;
    bool ask_own = own < 0;
    // Float64 work is deferred until the float32 pass found no certain occluder (most
    // hidden points never need it, and the SIMD batch stays on the float32 path).
    int deferred[MAX_DEFERRED];
    int n_deferred = 0;
    for (uint k = 0u; k < n_global + (stop - start); ++k) {
        int f;
        if (k < n_global) {
            f = int(global_faces[1u + k]);
        } else {
            uvec2 entry = tile_faces[start + k - n_global];
            f = int(entry.x);
            if (uintBitsToFloat(entry.y) > depth_cut) continue;
        }
        if (f == own) continue;
        bool maybe_own;
        int r = pair32(p, d, md, f, ask_own, maybe_own);
        if (r == HIT) return;
        int kinds = (r == TIE ? 1 : 0) | (maybe_own ? 2 : 0);
        if (kinds == 0) continue;
        if (n_deferred < MAX_DEFERRED) {
            deferred[n_deferred++] = 4 * f + kinds;
        } else {  // list full: decide now
            if ((kinds & 2) != 0) {
                int e = own_edge_on64(p64, seg, seg_len, f, tol, esin);
                if (e == HIT) return;
                cpu = cpu || e == TIE;
            }
            if ((kinds & 1) != 0) {
                r = pair64(p64, seg, seg_len, f, tol);
                if (r == HIT) return;
                cpu = cpu || r == TIE;
            }
        }
    }
    for (int k = 0; k < n_deferred; ++k) {
        int f = deferred[k] >> 2, kinds = deferred[k] & 3;
        if ((kinds & 2) != 0) {
            int e = own_edge_on64(p64, seg, seg_len, f, tol, esin);
            if (e == HIT) return;
            cpu = cpu || e == TIE;
        }
        if ((kinds & 1) != 0) {
            int r = pair64(p64, seg, seg_len, f, tol);
            if (r == HIT) return;
            cpu = cpu || r == TIE;
        }
    }
    mark(i, 0u);
    if (cpu) mark(i, cpu_words);
}
