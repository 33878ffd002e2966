#version 430
// The surfel z-buffer of point-only visibility: visibility/point_kernels.py's splat_surfels, in
// the same float64 operations, so that the GPU fills the kernel's buffers bit for bit.  A pixel
// of the surfel's box is covered where its central ray (x, y, 1) meets the surfel's plane within
// the radius r of its centre q, at depth t = (n . q) / (n . ray); the nearest surfel wins, and of
// surfels at the same t the lowest id (the kernel's first drawn: it keeps a depth only if less).
//
// The winner is found without a depth test, in three stages over the same fragments (a barrier
// between): SPLAT_STAGE_HIGH takes the least high word of t's key at each pixel, SPLAT_STAGE_LOW
// the least low word among the fragments that hold that high word, SPLAT_STAGE_ID the least id
// among those that hold both.  The key is t's bits made to order as t does (key64), so the three
// minima are the least t and the least id at it, whatever order the fragments run in.
//
// Every expression is written as the kernel writes it and `precise`, so that no contraction or
// reordering changes a bit.  The quotient is corrected once from its exact residual (Dekker's
// product, from multiplications and additions alone: Mesa lowers fma to them), which leaves a
// correctly rounded quotient as it is and corrects one that a driver's division leaves an ulp off.
uniform ivec2 tile_offset;     // first pixel (i, j) of the tile drawn
uniform int stage;             // SPLAT_STAGE_HIGH, SPLAT_STAGE_LOW or SPLAT_STAGE_ID
uniform double pix;            // pixel side, normalised coordinates
uniform double x0;             // the image's top-left corner, normalised coordinates
uniform double y0;
uniform double edge_on_cos2;   // point_kernels.EDGE_ON_COS2
layout(std430, binding = SPLAT_SURFELS) readonly buffer Surfels { double surfel[]; };  // q, n, r: 7 per surfel
layout(binding = SPLAT_KEY_HIGH, r32ui) uniform coherent uimage2D key_high;
layout(binding = SPLAT_KEY_LOW, r32ui) uniform coherent uimage2D key_low;
layout(binding = SPLAT_WINNER, r32ui) uniform coherent uimage2D winner;
flat in int v_id;
flat in ivec4 v_box;

// (low, high) words of t's bits, flipped so that they order as t: all bits of a negative t, the
// sign bit of any other (t is positive in front of the camera; this keeps the order anyway).
uvec2 key64(double t) {
    uvec2 bits = unpackDouble2x32(t);
    return (bits.y >> 31) != 0u ? ~bits : uvec2(bits.x, bits.y | 0x80000000u);
}

// The halves of a that hold 26 and 27 bits of its mantissa: their products are exact (Veltkamp).
dvec2 split(double a) {
    precise double c = 134217729.0 * a;  // 2^27 + 1
    precise double high = c - (c - a);
    precise double low = a - high;
    return dvec2(high, low);
}

// nq - t0 den, exactly where t0 is nq / den to a few ulps (Dekker 1971: p + e = t0 den exactly,
// and nq - p is exact, Sterbenz).
double residual(double nq, double t0, double den) {
    dvec2 a = split(t0), b = split(den);
    precise double p = t0 * den;
    precise double e = ((a.x * b.x - p) + a.x * b.y + a.y * b.x) + a.y * b.y;
    precise double r = (nq - p) - e;
    return r;
}

void main() {
    ivec2 local = ivec2(gl_FragCoord.xy);
    ivec2 pixel = tile_offset + local;
    if (any(lessThan(pixel, v_box.xy)) || any(greaterThan(pixel, v_box.zw))) discard;  // as the kernel
    int o = 7 * v_id;
    double qx = surfel[o], qy = surfel[o + 1], qz = surfel[o + 2];
    double nx = surfel[o + 3], ny = surfel[o + 4], nz = surfel[o + 5];
    double r = surfel[o + 6];
    precise double x = x0 + (double(pixel.x) + 0.5) * pix;
    precise double y = y0 + (double(pixel.y) + 0.5) * pix;
    precise double den = nx * x + ny * y + nz;
    precise double slant = edge_on_cos2 * (x * x + y * y + 1.0);
    precise double den2 = den * den;
    if (den2 < slant) discard;  // edge-on: a line of no area
    precise double nq = nx * qx + ny * qy + nz * qz;
    precise double wx = nq * x - den * qx;
    precise double wy = nq * y - den * qy;
    precise double wz = nq - den * qz;
    precise double w2 = wx * wx + wy * wy + wz * wz;
    precise double r2 = r * r;
    precise double reach = r2 * den * den;
    if (w2 > reach) discard;
    precise double t0 = nq / den;
    precise double t = t0 + residual(nq, t0, den) / den;
    uvec2 key = key64(t);
    if (stage == SPLAT_STAGE_HIGH) {
        imageAtomicMin(key_high, local, key.y);
    } else if (imageLoad(key_high, local).x == key.y) {
        if (stage == SPLAT_STAGE_LOW) {
            imageAtomicMin(key_low, local, key.x);
        } else if (imageLoad(key_low, local).x == key.x) {
            imageAtomicMin(winner, local, uint(v_id));
        }
    }
}
