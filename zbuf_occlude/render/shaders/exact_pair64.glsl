// The float64 pair tests of "zbuffer-exact": the oracle's arithmetic, operation by operation
// (zbuf_occlude/visibility/kernels.py `pair_occludes_one`, visibility/definition.py), in `precise`
// double so that no contraction or reordering changes a bit.  Included by exact_points.comp and by
// pair64_probe.comp (the test that runs these functions beside the CPU kernel on random pairs).
// The includer declares `double planes[]`: 16 per face, the rows of segment_triangle.pack_planes.

const double REL = 1.0e-12;       // float64 results this close to a boundary go to the CPU
const int MISS = 0, HIT = 1, TIE = 2;

double dot3(dvec3 a, dvec3 b) { precise double r = a.x * b.x + a.y * b.y + a.z * b.z; return r; }
dvec3 N64(int f) { int o = 16 * f; return dvec3(planes[o], planes[o + 1], planes[o + 2]); }
double OFF64(int f) { return planes[16 * f + 3]; }
dvec3 EN64(int f, int k) { int o = 16 * f + 4 + 3 * k; return dvec3(planes[o], planes[o + 1], planes[o + 2]); }
double EO64(int f, int k) { return planes[16 * f + 13 + k]; }

// Equal zeros are exact (no rounding can separate them); anything else this close may be.
bool near_boundary(double lhs, double rhs) { return abs(lhs - rhs) < REL * (abs(lhs) + abs(rhs)); }

// Closed-triangle test of a point x of (or near) face f's plane: 1 inside, 0 outside, 2 too close to call.
int inside64(int f, dvec3 x) {
    bool inside = true, close = false;
    for (int k = 0; k < 3; ++k) {
        precise double s = dot3(x, EN64(f, k));
        double o = EO64(f, k);
        inside = inside && (s >= o);
        close = close || near_boundary(s, o);
    }
    return close ? TIE : (inside ? HIT : MISS);
}

// oracle._pair_occludes for one pair: HIT, MISS or TIE (within REL of a boundary).
int pair64(dvec3 p, dvec3 seg, double seg_len, int f, double tol) {
    dvec3 n = N64(f);
    precise double num = OFF64(f) - dot3(n, p);
    precise double den = dot3(n, seg);
    if (den == 0.0) return MISS;  // parallel: numpy's t is inf or nan, which fails the tests
    precise double t = num / den;
    bool tie = near_boundary(t, 1.0);
    if (!(t >= 0.0 && t <= 1.0) && !tie) return MISS;
    precise double dist = t * seg_len;
    tie = tie || near_boundary(dist, tol);
    if (!(dist > tol) && !tie) return MISS;
    precise dvec3 x = dvec3(p.x + t * seg.x, p.y + t * seg.y, p.z + t * seg.z);
    int in_tri = inside64(f, x);
    if (in_tri == MISS) return MISS;
    return (tie || in_tri == TIE) ? TIE : HIT;
}

// definition.edge_on_own: face f seen within the edge-on angle from p.
int edge_on64(dvec3 p, dvec3 seg, double seg_len, int f, double esin) {
    dvec3 n = N64(f);
    if (n == dvec3(0.0)) return MISS;  // degenerate faces are never edge-on (0 < 0 fails)
    precise double lhs = abs(dot3(n, seg));
    precise double rhs = esin * sqrt(dot3(n, n)) * seg_len;
    if (near_boundary(lhs, rhs)) return TIE;
    return lhs < rhs ? HIT : MISS;
}

// definition._own_and_edge_on: p within tol of face f, inside it, and f seen edge-on.
int own_edge_on64(dvec3 p, dvec3 seg, double seg_len, int f, double tol, double esin) {
    dvec3 n = N64(f);
    precise double lhs = abs(dot3(n, p) - OFF64(f));
    precise double rhs = tol * sqrt(dot3(n, n));
    bool tie = near_boundary(lhs, rhs);
    if (!(lhs <= rhs) && !tie) return MISS;
    int in_tri = inside64(f, p);
    if (in_tri == MISS) return MISS;
    int e = edge_on64(p, seg, seg_len, f, esin);
    if (e == MISS) return MISS;
    return (tie || in_tri == TIE || e == TIE) ? TIE : HIT;
}
