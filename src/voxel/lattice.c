/* The lattice rules of the CPU engines (lattice.h). */
#include "voxel/lattice.h"

int vx_lattice_unit(const vx_grid *g, const double p[3], double u[3])
{
    for (int a = 0; a < 3; a++)
        u[a] = (p[a] - g->origin[a]) / g->h;
    return vx_lattice_in_range(u) ? 0 : -1;
}

/* floor(a / b), b > 0 */
static int64_t floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

void vx_lattice_centres(int64_t lo, int64_t hi, int64_t index, int n, int *a, int *b)
{
    const int64_t S = (int64_t)VX_GRID_SNAP, H = S / 2;
    int64_t first = -floor_div(-(lo - H), S) - index, last = floor_div(hi - H, S) - index;
    *a = first < 0 ? 0 : first > n ? n : (int)first;
    *b = last > n - 1 ? n - 1 : last < -1 ? -1 : (int)last;
}

void vx_lattice_edge_set(vx_lattice_edge *e, const int64_t A[2], const int64_t B[2], int64_t cy0,
                         int64_t cz0)
{
    const int64_t S = (int64_t)VX_GRID_SNAP;
    int64_t dy = B[0] - A[0], dz = B[1] - A[1];
    int bias = dz != 0 ? dz < 0 : dy > 0;
    e->at = (vx_i128)dy * (cz0 - A[1]) - (vx_i128)dz * (cy0 - A[0]) + bias;
    e->d1 = -(vx_i128)dz * S;
    e->d2 = (vx_i128)dy * S;
}

/* Closest point to x of the segment p -> q: (squared distance, parameter),
 * as xing_seg in voxel_xing.glsl. */
static void seg(const double p[2], const double q[2], const double x[2], double out[2])
{
    double d[2] = {q[0] - p[0], q[1] - p[1]};
    double dd = d[0] * d[0] + d[1] * d[1];
    double s = dd > 0.0 ? ((x[0] - p[0]) * d[0] + (x[1] - p[1]) * d[1]) / dd : 0.0;
    s = s < 0.0 ? 0.0 : s > 1.0 ? 1.0 : s;
    double r[2] = {x[0] - p[0] - s * d[0], x[1] - p[1] - s * d[1]};
    out[0] = r[0] * r[0] + r[1] * r[1];
    out[1] = s;
}

int32_t vx_lattice_xing(const double a[3], const double e1[3], const double e2[3], double cy,
                        double cz, double ix)
{
    const double XING_REACH = 1.0 / 64.0;
    double x[2] = {cy - a[1], cz - a[2]};
    double p1[2] = {e1[1], e1[2]}, p2[2] = {e2[1], e2[2]};
    double t1 = e1[0], t2 = e2[0];
    double det = p1[0] * p2[1] - p1[1] * p2[0];
    double bb = (x[0] * p2[1] - x[1] * p2[0]) / det, bc = (p1[0] * x[1] - p1[1] * x[0]) / det;
    double dt = bb * t1 + bc * t2;
    if (det == 0.0 || bb < 0.0 || bc < 0.0 || bb + bc > 1.0) {
        const double o[2] = {0.0, 0.0};
        double s0[2], s1[2], s2[2];
        seg(o, p1, x, s0);
        seg(p1, p2, x, s1);
        seg(p2, o, x, s2);
        double near = s0[1] * t1;
        if (s1[0] < s0[0]) near = t1 + s1[1] * (t2 - t1);
        if (s2[0] < fmin(s0[0], s1[0])) near = (1.0 - s2[1]) * t2;
        if (det == 0.0)
            dt = near;
        else
            dt = dt < near - XING_REACH   ? near - XING_REACH
                 : dt > near + XING_REACH ? near + XING_REACH
                                          : dt;
    }
    double t = a[0] + dt;
    double cb =
        ceil((nearbyint(t * VX_GRID_XING_SNAP) - VX_GRID_XING_SNAP / 2) / VX_GRID_XING_SNAP) - ix;
    cb = cb < -VX_LATTICE_XING_MAX  ? -VX_LATTICE_XING_MAX
         : cb > VX_LATTICE_XING_MAX ? VX_LATTICE_XING_MAX
                                    : cb;
    return (int32_t)cb;
}
