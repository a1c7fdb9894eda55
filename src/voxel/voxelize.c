/* The voxelizer dispatcher (voxel.h): validates a request and runs the
 * method that fits it. */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "util/log.h"
#include "voxel/voxel.h"

const char *const vx_inside_names[] = {"nonzero", "parity", "robust", "winding", NULL};

/* The GL methods place vertices as floats in voxels from the box
 * (vx_grid_unit): exact to the 1/256-voxel snap within 2^15 voxels of it
 * (the limit their brick-exact voxels are documented to), off by up to
 * 1/16 voxel at 2^20, whole voxels past 2^24. A face that reaches the
 * box's rays (its bbox within a voxel of the box along two axes) from a
 * vertex farther away would set voxels from such positions: the job is
 * refused, pointing at the CPU engines, exact to 2^50 voxels. */
#define GL_REACH 32768.0 /* 2^15 voxels */

static int gl_reach_check(const vx_mesh *m, const vx_grid *g, vx_err *err)
{
    int near = 1;
    for (int a = 0; a < 3; a++)
        near &= vx_grid_coord(g, a, m->bbox_min[a]) > -GL_REACH &&
                vx_grid_coord(g, a, m->bbox_max[a]) < g->dims[a] + GL_REACH;
    if (near) return 0; /* the bbox bounds every vertex a face uses */
    for (size_t t = 0; t < m->ntris; t++) {
        int far = 0, over = 0;
        for (int a = 0; a < 3; a++) {
            double lo = INFINITY, hi = -INFINITY;
            for (int i = 0; i < 3; i++) {
                double x = vx_grid_coord(g, a, m->pos[3 * (size_t)m->tri[3 * t + i] + a]);
                lo = fmin(lo, x);
                hi = fmax(hi, x);
            }
            far |= lo < -GL_REACH || hi > g->dims[a] + GL_REACH;
            over += lo <= g->dims[a] + 1 && hi >= -1;
        }
        if (far && over >= 2)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "face %zu reaches the grid from more than 2^15 voxels away, where "
                              "the GL methods' float positions are no longer exact; "
                              "use method cpu or inside winding (exact to 2^50 voxels), or a "
                              "larger voxel_size",
                              t);
    }
    return 0;
}

int vx_voxelize(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                vx_voxelize_stats *st, vx_err *err)
{
    const vx_grid *g = &d->grid;
    for (int a = 0; a < 3; a++)
        if (g->dims[a] < 1 || g->dims[a] > (1 << 20))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "grid dims must be 1..1048576, got %d along %c", g->dims[a],
                              "xyz"[a]);
    if (!(g->h > 0) || !isfinite(g->h))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "voxel size must be positive");
    for (int a = 0; a < 3; a++)
        if (!isfinite(g->origin[a]))
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "grid origin must be finite");
    for (int a = 0; a < 3; a++)
        if (g->index[a] > VX_GRID_INDEX_MAX || g->index[a] < -VX_GRID_INDEX_MAX)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "grid index offset must be within +-2^40");
    if (d->supersample != 0 && d->supersample != 1 && d->supersample != 2)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "supersample must be 1 or 2, got %d",
                          d->supersample);
    if (d->samples != VX_SAMPLES_CUBE && d->samples != VX_SAMPLES_FACES)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown sample pattern %d",
                          (int)d->samples);
    const int faces = d->supersample == 2 && d->samples == VX_SAMPLES_FACES, most = faces ? 7 : 8;
    if (d->threshold < 0 || d->threshold > most)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "threshold must be 1..%d, got %d",
                          most, d->threshold);
    if (faces && d->fill != VX_FILL_SOLID)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "the faces sample pattern needs fill solid");
    if (d->method < VX_METHOD_AUTO || d->method > VX_METHOD_CPU)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown method %d", (int)d->method);
    if (d->inside < VX_INSIDE_NONZERO || d->inside > VX_INSIDE_WINDING)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown inside rule %d",
                          (int)d->inside);
    if (d->fill < VX_FILL_SOLID || d->fill > VX_FILL_SURFACE)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown fill %d", (int)d->fill);
    if (d->max_layers < 0 || d->max_slab_rows < 0)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "max_layers and max_slab_rows must be >= 0");

    vx_voxelize_desc dd = *d;
    if (dd.supersample == 0) dd.supersample = 1;
    if (dd.threshold == 0) dd.threshold = 4;
    if (faces) return vx_voxelize_faces(gl, m, &dd, out, st, err);
    if (dd.inside == VX_INSIDE_WINDING && dd.fill == VX_FILL_SOLID) {
        if (dd.supersample == 2)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "inside winding samples voxel centres: supersample 2 needs samples "
                              "faces");
        return vx_voxelize_winding(m, &dd, out, st, err);
    }
    if (dd.inside == VX_INSIDE_WINDING) dd.inside = VX_INSIDE_NONZERO; /* surface: no inside */
    vx_method method = dd.method;
    /* Peeling, scan and cpu sample each voxel once at its centre; only
     * slicing supersamples (seed 003's accuracy improvement). Scan and cpu
     * count crossings along x only: robust (three axes) and the surface
     * fill are peel's. cpu gives scan's voxels on every renderer: on a CPU
     * rasterizer scan's draw and sums are its work behind a driver, and on
     * the one GPU tried (an NVIDIA H200, bench/RESULTS.md) the GL engines
     * lost a context's later work after a stage stalled, so auto takes the
     * CPU until they pass there; scan stays a request away. */
    int scan_fits = dd.supersample == 1 && dd.fill == VX_FILL_SOLID &&
                    (dd.inside == VX_INSIDE_NONZERO || dd.inside == VX_INSIDE_PARITY);
    if (method == VX_METHOD_AUTO)
        method = dd.supersample == 2 ? VX_METHOD_SLICE
                 : !scan_fits        ? VX_METHOD_PEEL
                                     : VX_METHOD_CPU;
    if (method == VX_METHOD_CPU) {
        if (!scan_fits)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "method cpu fills solids by nonzero or parity at voxel centres; use "
                              "peel, slice or auto");
        return vx_voxelize_cpu(m, &dd, out, st, err);
    }
    if (gl_reach_check(m, g, err)) return -1;
    if (method == VX_METHOD_PEEL || method == VX_METHOD_SCAN) {
        if (dd.supersample == 2)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "method %s has no supersampling; use slice or auto",
                              method == VX_METHOD_PEEL ? "peel" : "scan");
        if (method != VX_METHOD_PEEL) return vx_voxelize_scan(gl, m, &dd, out, st, err);
        vx_err pe;
        vx_err_clear(&pe);
        if (vx_voxelize_peel(gl, m, &dd, out, st, &pe) == 0) return 0;
        /* auto: a mesh with more depth layers than peeling holds along a
         * ray, in the GL's array textures or in the job's memory, is sliced
         * instead (a solid fill: slicing has no surface; it keeps no
         * layers) */
        if (dd.method != VX_METHOD_AUTO || dd.fill != VX_FILL_SOLID ||
            (strcmp(pe.code, "too_many_layers") != 0 && strcmp(pe.code, "job_memory_limit") != 0)) {
            if (err) *err = pe;
            return -1;
        }
        VX_INFO("voxelize.peel_to_slice", "reason=%s", VX_Q(pe.message));
    }
    return vx_voxelize_slice(gl, m, &dd, out, st, err);
}

int vx_voxelize_slab_rows(const int dims[3])
{
    uint64_t layer = (uint64_t)(dims[0] > 0 ? dims[0] : 1) * (uint64_t)(dims[1] > 0 ? dims[1] : 1);
    uint64_t rows = VX_VOXELIZE_SLAB_VOXELS / layer;
    return rows < 1 ? 1 : rows > INT32_MAX ? INT32_MAX : (int)rows;
}
