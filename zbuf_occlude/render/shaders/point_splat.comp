#version 430
// The surfel z-buffer of point-only visibility: visibility/point_kernels.py's splat_surfels, in
// the same float64 operations, so that the GPU fills the kernel's buffers bit for bit.  A pixel
// of the surfel's box is covered where its central ray (x, y, 1) meets the surfel's plane within
// the radius r of its centre q, at depth t = (n . q) / (n . ray); the nearest surfel wins, and of
// surfels at the same t the lowest id (the kernel's first drawn: it keeps a depth only if less).
//
// One invocation per surfel and slice: it computes the surfel's pixel box as the kernel does and
// tests the box's rows j = j0 + slice, j0 + slice + SPLAT_SLICES, ... within the tile of pixels
// [tile_offset, tile_offset + tile_size) whose pixels the buffers hold (row by row).
//
// The winner is found without a depth test, in three stages over the same pixels (a barrier
// between): SPLAT_STAGE_HIGH takes the least high word of t's key at each pixel, SPLAT_STAGE_LOW
// the least low word among the surfels that hold that high word, SPLAT_STAGE_ID the least id
// among those that hold both.  The key is t's bits made to order as t does (key64), so the three
// minima are the least t and the least id at it, whatever order the invocations run in.  Compiled
// with SPLAT_RESOLVE, the shader is a fourth pass, one invocation per pixel of the tile: it turns
// the key back into t's bits (+inf where no surfel won), the depth buffer the CPU reads.
//
// Every expression of the coverage test and of t is written as the kernel writes it and
// `precise`, so that no contraction or reordering changes a bit.  The quotient is corrected once
// from its exact residual (Dekker's product, from multiplications and additions alone: Mesa lowers
// fma to them), which leaves a correctly rounded quotient as it is and corrects one that a
// driver's division leaves an ulp off.  The box needs no such care: it is the disk's box widened
// by box_margin (a millionth of r), and a rounding of its corners moves it by far less than that.
layout(local_size_x = GROUP_SIZE) in;

uniform uint offset;           // first surfel of this dispatch (render/compute.py's dispatch)
uniform uint n_surfels;
uniform int stage;             // SPLAT_STAGE_HIGH, SPLAT_STAGE_LOW or SPLAT_STAGE_ID
uniform ivec2 size;            // the image's width and height, pixels
uniform ivec2 tile_offset;     // first pixel (i, j) the buffers hold
uniform ivec2 tile_size;       // their columns and rows
uniform double pix;            // pixel side, normalised coordinates
uniform double x0;             // the image's top-left corner, normalised coordinates
uniform double y0;
uniform double edge_on_cos2;   // point_kernels.EDGE_ON_COS2
uniform double box_margin;     // point_kernels.BOX_MARGIN
layout(std430, binding = SPLAT_SURFELS) readonly buffer Surfels { double surfel[]; };  // q, n, r: 7 per surfel
layout(std430, binding = SPLAT_KEY_HIGH) buffer KeyHigh { uint key_high[]; };           // a pixel of the tile each
layout(std430, binding = SPLAT_KEY_LOW) buffer KeyLow { uint key_low[]; };
layout(std430, binding = SPLAT_WINNER) buffer Winner { uint winner[]; };
layout(std430, binding = SPLAT_DEPTH) writeonly buffer Depth { uvec2 depth_bits[]; };  // (low, high) words of t

// (low, high) words of t's bits, flipped so that they order as t: all bits of a negative t, the
// sign bit of any other (t is positive in front of the camera; this keeps the order anyway).
uvec2 key64(double t) {
    uvec2 bits = unpackDouble2x32(t);
    return (bits.y >> 31) != 0u ? ~bits : uvec2(bits.x, bits.y | 0x80000000u);
}

//#include splat64.glsl

#ifdef SPLAT_RESOLVE
void main() {
    uint p = gl_GlobalInvocationID.x + offset;
    if (p >= uint(tile_size.x * tile_size.y)) return;
    uvec2 key = uvec2(key_low[p], key_high[p]);
    // key64 undone: the sign bit set held a positive t, every bit flipped a negative one
    uvec2 bits = (key.y >> 31) != 0u ? uvec2(key.x, key.y & 0x7FFFFFFFu) : ~key;
    depth_bits[p] = winner[p] == 0xFFFFFFFFu ? uvec2(0u, 0x7FF00000u) : bits;  // +inf where none
}
#else
void main() {
    uint k = gl_GlobalInvocationID.x + offset;
    if (k >= n_surfels) return;
    int o = 7 * int(k);
    double qx = surfel[o], qy = surfel[o + 1], qz = surfel[o + 2];
    double nx = surfel[o + 3], ny = surfel[o + 4], nz = surfel[o + 5];
    double r = surfel[o + 6];
    if (qz - r <= 0.0 || r <= 0.0) return;
    // the disk lies inside the box q ± e, e_a = r sqrt(1 - n_a^2) (a little wider), whose
    // projection (x/z, y/z) is extreme at corners
    double ex = r * (sqrt(max(1.0 - nx * nx, 0.0)) + box_margin);
    double ey = r * (sqrt(max(1.0 - ny * ny, 0.0)) + box_margin);
    double ez = min(r * (sqrt(max(1.0 - nz * nz, 0.0)) + box_margin), r);
    double near = qz - ez, far = qz + ez;
    int j0 = max(cell((min((qy - ey) / near, (qy - ey) / far) - y0) / pix, size.y), tile_offset.y);
    int j1 = min(cell((max((qy + ey) / near, (qy + ey) / far) - y0) / pix, size.y), tile_offset.y + tile_size.y - 1);
    if (j0 > j1) return;
    int i0 = max(cell((min((qx - ex) / near, (qx - ex) / far) - x0) / pix, size.x), tile_offset.x);
    int i1 = min(cell((max((qx + ex) / near, (qx + ex) / far) - x0) / pix, size.x), tile_offset.x + tile_size.x - 1);
    precise double nq = nx * qx + ny * qy + nz * qz;
    precise double r2 = r * r;
    for (int j = j0 + int(gl_GlobalInvocationID.y); j <= j1; j += SPLAT_SLICES) {
        precise double y = y0 + (double(j) + 0.5) * pix;
        int row = (j - tile_offset.y) * tile_size.x - tile_offset.x;
        for (int i = i0; i <= i1; ++i) {
            precise double x = x0 + (double(i) + 0.5) * pix;
            precise double den = nx * x + ny * y + nz;
            precise double slant = edge_on_cos2 * (x * x + y * y + 1.0);
            precise double den2 = den * den;
            if (den2 < slant) continue;  // edge-on: a line of no area
            precise double wx = nq * x - den * qx;
            precise double wy = nq * y - den * qy;
            precise double wz = nq - den * qz;
            precise double w2 = wx * wx + wy * wy + wz * wz;
            precise double reach = r2 * den * den;
            if (w2 > reach) continue;
            precise double t0 = nq / den;
            precise double t = t0 + residual(nq, t0, den) / den;
            uvec2 key = key64(t);
            int p = row + i;
            if (stage == SPLAT_STAGE_HIGH) {
                atomicMin(key_high[p], key.y);
            } else if (key_high[p] == key.y) {
                if (stage == SPLAT_STAGE_LOW) {
                    atomicMin(key_low[p], key.x);
                } else if (key_low[p] == key.x) {
                    atomicMin(winner[p], k);
                }
            }
        }
    }
}
#endif
