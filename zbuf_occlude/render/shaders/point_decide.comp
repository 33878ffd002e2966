#version 430
// The per-point decision of point-only visibility on the GPU: visibility/point_kernels.py's decide
// (_decide_point, _in_a_gap, _curvature_allowance), in the same float64 operations and order, each
// `precise`, quotients and square roots correctly rounded (splat64.glsl), so that the GPU gives
// the kernel's answer bit for bit.  It reads the z-buffer point_splat.comp filled (the winners'
// ids and depths of one tile holding the whole image) and writes one uint per point: 1 visible.
layout(local_size_x = GROUP_SIZE) in;

uniform uint offset;           // first point of this dispatch (render/compute.py's dispatch)
uniform uint n_points;
uniform ivec2 size;            // the image's width and height, pixels
uniform double pix;            // pixel side, normalised coordinates
uniform double x0;             // the image's top-left corner, normalised coordinates
uniform double y0;
uniform double tolerance;      // spacings
uniform double crease_cos;
uniform int oriented;          // normals == NORMALS_ORIENTED
uniform int estimated;         // normals == NORMALS_ESTIMATED
uniform double coplanar;       // point_kernels.COPLANAR
uniform double depth_slack;    // point_kernels.DEPTH_SLACK
uniform double half_slack;     // point_kernels.CURVATURE_SLACK * 0.5
uniform double gap_reach;      // point_kernels.GAP_REACH
layout(std430, binding = SPLAT_SURFELS) readonly buffer Surfels { double surfel[]; };  // q, n, r: 7 per point
layout(std430, binding = SPLAT_WINNER) readonly buffer Winner { uint winner[]; };     // a pixel each
layout(std430, binding = SPLAT_DEPTH) readonly buffer Depth { uvec2 depth_bits[]; };  // (low, high) words of t
layout(std430, binding = DECIDE_POINTS) readonly buffer Points { double point[]; };   // spacing, sided: 2 per point
layout(std430, binding = DECIDE_VISIBLE) writeonly buffer Visible { uint visible[]; };

//#include splat64.glsl

dvec3 q_of(int k) { return dvec3(surfel[7 * k], surfel[7 * k + 1], surfel[7 * k + 2]); }
dvec3 n_of(int k) { return dvec3(surfel[7 * k + 3], surfel[7 * k + 4], surfel[7 * k + 5]); }
int id_at(int i, int j) { return int(winner[j * size.x + i]); }  // -1: none

// point_kernels._curvature_allowance
double curvature_allowance(int p, int q, double reach_factor) {
    dvec3 np = n_of(p), nq = n_of(q), cp = q_of(p), cq = q_of(q);
    precise double cos_pq = np.x * nq.x + np.y * nq.y + np.z * nq.z;
    if (abs(cos_pq) < crease_cos) return 0.0;
    precise double dx = cp.x - cq.x, dy = cp.y - cq.y, dz = cp.z - cq.z;
    precise double d2 = dx * dx + dy * dy + dz * dz;
    precise double reach = reach_factor * (surfel[7 * p + 6] + surfel[7 * q + 6]);
    if (d2 > reach * reach) return 0.0;
    double s = cos_pq >= 0.0 ? 1.0 : -1.0;
    precise double ex = np.x - s * nq.x;
    precise double ey = np.y - s * nq.y;
    precise double ez = np.z - s * nq.z;
    precise double allowance = half_slack * sqrt_rn((ex * ex + ey * ey + ez * ez) * d2);
    return allowance;
}

// point_kernels._in_a_gap
bool in_a_gap(int p, int i, int j, double spacing) {
    dvec3 c = q_of(p), n = n_of(p);
    precise double toward = -(n.x * c.x + n.y * c.y + n.z * c.z);
    double side = toward >= 0.0 ? 1.0 : -1.0;
    bool p_faces = toward > 0.0;
    precise double allowance = tolerance * spacing;
    precise double steps = div_rn(div_rn(gap_reach * surfel[7 * p + 6], c.z), pix);
    int reach = steps >= double(size.x + size.y) ? size.x + size.y : int(ceil(steps));
    if (reach < 1) return false;
    for (int d = 0; d < 8; ++d) {
        // point_kernels._GAP_DIRECTIONS: (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1)
        int di = d == 0 || d == 1 || d == 7 ? 1 : (d == 3 || d == 4 || d == 5 ? -1 : 0);
        int dj = d == 1 || d == 2 || d == 3 ? 1 : (d == 5 || d == 6 || d == 7 ? -1 : 0);
        bool blocked = false;
        for (int step = 1; step <= reach; ++step) {
            int ii = i + di * step, jj = j + dj * step;
            if (ii < 0 || jj < 0 || ii >= size.x || jj >= size.y) break;
            int q = id_at(ii, jj);
            if (q < 0) break;
            if (q == p) continue;
            dvec3 cq = q_of(q), nq = n_of(q);
            precise double rise = side * ((cq.x - c.x) * n.x + (cq.y - c.y) * n.y + (cq.z - c.z) * n.z);
            precise double q_toward = nq.x * cq.x + nq.y * cq.y + nq.z * cq.z;
            if (oriented != 0 && !p_faces && q_toward < 0.0) {
                blocked = true;
                break;
            }
            precise double limit = allowance + curvature_allowance(p, q, gap_reach + 1.0);
            if (rise > limit) {
                blocked = true;
                break;
            }
            if (rise < -allowance) break;
        }
        if (!blocked) return false;
    }
    return true;
}

// point_kernels._decide_point
bool decide_point(int p) {
    dvec3 c = q_of(p), n = n_of(p);
    double spacing = point[2 * p];
    bool sided = point[2 * p + 1] != 0.0;
    if (c.z <= 0.0) return false;
    precise double facing = n.x * c.x + n.y * c.y + n.z * c.z;
    if (sided && facing > 0.0) return false;  // the far side of a thin wall
    int i = cell(div_rn(div_rn(c.x, c.z) - x0, pix), size.x);
    int j = cell(div_rn(div_rn(c.y, c.z) - y0, pix), size.y);
    if (i < 0 || j < 0 || i >= size.x || j >= size.y) return false;
    int q = id_at(i, j);
    if (q < 0 || q == p) return !in_a_gap(p, i, j, spacing);
    dvec3 cq = q_of(q), nq = n_of(q);
    if (oriented != 0) {
        precise double q_toward = nq.x * cq.x + nq.y * cq.y + nq.z * cq.z;
        precise double p_toward = n.x * c.x + n.y * c.y + n.z * c.z;
        if (q_toward < 0.0 && !(p_toward < 0.0)) return false;
    }
    precise double dx = c.x - cq.x, dy = c.y - cq.y, dz = c.z - cq.z;
    precise double toward = -(n.x * c.x + n.y * c.y + n.z * c.z);
    precise double rise = -(dx * n.x + dy * n.y + dz * n.z);
    precise double in_plane = coplanar * spacing * abs(toward);
    precise double rise_toward = rise * toward;
    if (rise_toward < in_plane) return !in_a_gap(p, i, j, spacing);
    precise double x = x0 + (double(i) + 0.5) * pix;
    precise double y = y0 + (double(j) + 0.5) * pix;
    double t = packDouble2x32(depth_bits[j * size.x + i]);
    precise double dist = abs((x * t - c.x) * n.x + (y * t - c.y) * n.y + (t - c.z) * n.z);
    precise double allowance = tolerance * spacing + curvature_allowance(p, q, 1.0);
    precise double front = c.z - (estimated != 0 ? max(t, cq.z) : t);
    precise double slack = depth_slack * spacing;
    if (dist <= allowance || front <= slack) return !in_a_gap(p, i, j, spacing);
    return false;
}

void main() {
    uint p = gl_GlobalInvocationID.x + offset;
    if (p >= n_points) return;
    visible[p] = decide_point(int(p)) ? 1u : 0u;
}
