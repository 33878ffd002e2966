#version 430
// Test harness: exact_pair64.glsl's pair64 on given (point, eye, face) triples, so that a test can
// hold the GPU's float64 decisions against the CPU kernel (visibility/kernels.py) pair by pair.
layout(local_size_x = GROUP_SIZE) in;

layout(std430, binding = PROBE_PLANES) readonly buffer Planes { double planes[]; };   // 16 per face
layout(std430, binding = PROBE_PAIRS) readonly buffer Pairs { double pairs[]; };     // point xyz, eye xyz, tolerance
layout(std430, binding = PROBE_PAIR_FACES) readonly buffer PairFaces { int pair_face[]; };
layout(std430, binding = PROBE_RESULT) buffer Result { int result[]; };                // MISS, HIT or TIE
uniform uint n_pairs;
uniform uint pair_offset;

//#include exact_pair64.glsl

void main() {
    uint i = gl_GlobalInvocationID.x + pair_offset;
    if (i >= n_pairs) return;
    uint o = 7u * i;
    dvec3 p = dvec3(pairs[o], pairs[o + 1u], pairs[o + 2u]);
    dvec3 e = dvec3(pairs[o + 3u], pairs[o + 4u], pairs[o + 5u]);
    precise dvec3 seg = e - p;
    precise double seg_len = sqrt(dot3(seg, seg));
    result[i] = pair64(p, seg, seg_len, pair_face[i], pairs[o + 6u]);
}
