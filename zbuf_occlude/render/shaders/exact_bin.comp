#version 430
// "zbuffer-exact", pass 1 and 2: bin every (distinct) face into the screen tiles that its
// projected triangle overlaps (bounding box, then the three edge lines), grown by `margin` pixels (conservative: a face that meets
// the segment from a point to the eye contains the point's projection, so it is in the
// point's tile).  BIN_FILL 0 counts faces per tile; the CPU turns the counts into list
// starts; BIN_FILL 1 writes the face ids (tile_count then holds each tile's write cursor).
// Faces reaching behind near_w (clip w, i.e. depth) cannot be projected: they go to one
// global list that every point tests.  Each entry carries the face's smallest clip w
// (its nearest linear depth), so that a point skips faces entirely behind it.
// The dispatch's y dimension splits each face's tiles: invocation (face, s) of S takes the
// tiles s, s + S, s + 2S, ... of the face's box, so that a face covering thousands of tiles
// is not one thread's serial loop.  The order of a tile's list does not change any result.
layout(local_size_x = GROUP_SIZE) in;

layout(std430, binding = EXACT_TRIANGLES) readonly buffer Triangles { float triangles[]; };  // 9 floats per face
layout(std430, binding = EXACT_TILE_COUNT) buffer TileCount { uint tile_count[]; };
layout(std430, binding = EXACT_TILE_FACES) writeonly buffer TileFaces { uvec2 tile_faces[]; };  // face, min depth bits
layout(std430, binding = EXACT_GLOBAL_FACES) buffer GlobalFaces { uint global_faces[]; };  // [0]: count
layout(std430, binding = EXACT_BIN_FACES) readonly buffer BinFaces { int bin_faces[]; };

uniform mat4 view_projection;
uniform ivec2 resolution;
uniform int tile;          // tile side, pixels
uniform ivec2 tiles;       // tiles per row, per column
uniform uint n_bin_faces;
uniform uint face_offset;  // first face of this dispatch
uniform float near_w;      // faces with a vertex at clip w <= near_w are global
uniform float margin;      // pixels

void main() {
    uint k = gl_GlobalInvocationID.x + face_offset;
    if (k >= n_bin_faces) return;
    int f = bin_faces[k];
    vec2 lo = vec2(3.0e38), hi = vec2(-3.0e38);
    bool global_face = false;
    float min_w = 3.0e38;
    vec2 v[3];
    for (int j = 0; j < 3; ++j) {
        int o = 9 * f + 3 * j;
        vec4 c = view_projection * vec4(triangles[o], triangles[o + 1], triangles[o + 2], 1.0);
        min_w = min(min_w, c.w);
        if (!(c.w > near_w)) {
            global_face = true;
            v[j] = vec2(0.0);
        } else {
            v[j] = (c.xy / c.w * 0.5 + 0.5) * vec2(resolution);
            lo = min(lo, v[j]);
            hi = max(hi, v[j]);
        }
    }
    uint slice = gl_GlobalInvocationID.y, n_slices = gl_NumWorkGroups.y;
    if (global_face) {
#if BIN_FILL == 0
        if (slice != 0u) return;
        uint slot = atomicAdd(global_faces[0], 1u);
        global_faces[1u + slot] = uint(f);
#endif
        return;
    }
    vec2 res = vec2(resolution);
    if (hi.x < -margin || hi.y < -margin || lo.x > res.x + margin || lo.y > res.y + margin) return;
    lo = clamp(lo - margin, vec2(0.0), res);
    hi = clamp(hi + margin, vec2(0.0), res);
    ivec2 t0 = clamp(ivec2(floor(lo / float(tile))), ivec2(0), tiles - 1);
    ivec2 t1 = clamp(ivec2(floor(hi / float(tile))), ivec2(0), tiles - 1);
    // Edge lines of the projected triangle, oriented inwards, for the tile test below.
    float area = (v[1].x - v[0].x) * (v[2].y - v[0].y) - (v[1].y - v[0].y) * (v[2].x - v[0].x);
    bool edge_test = abs(area) > 1.0e-3 && (t1.x > t0.x || t1.y > t0.y);
    vec3 edge[3];
    for (int j = 0; j < 3; ++j) {
        vec2 a = v[j], b = v[(j + 1) % 3];
        vec2 nrm = vec2(a.y - b.y, b.x - a.x) * sign(area);  // inward normal (unnormalised)
        // A tile is off the triangle if its nearest corner is outside this edge by more
        // than the margin plus float32 slack (relative to the coordinates).
        float slack = margin * length(nrm) + 1.0e-5 * (abs(dot(nrm, a)) + length(nrm) * float(max(resolution.x, resolution.y)));
        edge[j] = vec3(nrm, -dot(nrm, a) + slack);
    }
    uint nx = uint(t1.x - t0.x + 1), n_box = nx * uint(t1.y - t0.y + 1);
    for (uint k = slice; k < n_box; k += n_slices) {
        int x = t0.x + int(k % nx), y = t0.y + int(k / nx);
        if (edge_test) {
            vec2 c0 = vec2(float(x * tile), float(y * tile)), c1 = c0 + float(tile);
            bool off = false;
            for (int j = 0; j < 3; ++j) {
                // the tile corner farthest along the inward normal
                vec2 corner = vec2(edge[j].x >= 0.0 ? c1.x : c0.x, edge[j].y >= 0.0 ? c1.y : c0.y);
                off = off || dot(edge[j].xy, corner) + edge[j].z < 0.0;
            }
            if (off) continue;
        }
        uint id = uint(y * tiles.x + x);
#if BIN_FILL == 0
        atomicAdd(tile_count[id], 1u);
#else
        uint slot = atomicAdd(tile_count[id], 1u);
        tile_faces[slot] = uvec2(uint(f), floatBitsToUint(min_w));
#endif
    }
}
