// float64 arithmetic that gives the numba kernels' bits on any GL whose addition and multiplication
// round to nearest (visibility/point_kernels.py): a quotient and a square root corrected once from
// their exact residuals (Dekker's product, from multiplications and additions alone: Mesa lowers
// fma to them), which leaves a correctly rounded result as it is and corrects one that a driver
// leaves an ulp off; and point_kernels._cell.  Included by point_splat.comp and point_decide.comp.

// The halves of a that hold 26 and 27 bits of its mantissa: their products are exact (Veltkamp).
dvec2 split(double a) {
    precise double c = 134217729.0 * a;  // 2^27 + 1
    precise double high = c - (c - a);
    precise double low = a - high;
    return dvec2(high, low);
}

// a - b c, exactly where b c is within a few ulps of a (Dekker 1971: p + e = b c exactly, and
// a - p is exact, Sterbenz).
double residual(double a, double b, double c) {
    dvec2 x = split(b), y = split(c);
    precise double p = b * c;
    precise double e = ((x.x * y.x - p) + x.x * y.y + x.y * y.x) + x.y * y.y;
    precise double r = (a - p) - e;
    return r;
}

// a / b, correctly rounded.
double div_rn(double a, double b) {
    precise double q = a / b;
    precise double corrected = q + residual(a, q, b) / b;
    return corrected;
}

// sqrt(a), correctly rounded (a >= 0).
double sqrt_rn(double a) {
    precise double s = sqrt(a);
    if (s == 0.0 || isinf(s)) return s;
    precise double corrected = s + residual(a, s, s) / (2.0 * s);
    return corrected;
}

// floor(v) as an int, v clamped to [-1, n] first (NaN: -1): point_kernels._cell.
int cell(double v, int n) {
    if (!(v >= -1.0)) return -1;
    if (v >= double(n)) return n;
    return int(floor(v));
}
