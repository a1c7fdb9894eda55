/* The `voxelize` row of the job table (kind.h; api/openapi.yaml has the
 * params and stats schemas). The params are declared once, in spec (spec.h);
 * voxelize_check keeps the rules across fields and the grid limits. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/fsutil.h"
#include "util/path.h"
#include "voxel/io.h"
#include "voxel/job.h"
#include "voxel/lattice.h"
#include "voxel/voxel.h"
#include "util/json.h"

typedef enum vformat {
    F_VDB = 0,
    F_BINVOX,
    F_RAW8,
    F_RAW1,
    F_SUMMARY,
    F_VOX,
    F_NRRD,
    F_NPY
} vformat;

static const char *const method_names[] = {"auto", "peel", "slice", "scan", "cpu", NULL};
static const char *const fill_names[] = {"solid", "surface", NULL};
static const char *const samples_names[] = {"cube", "faces", NULL}; /* vx_samples order */
static const char *const format_names[] = {"vdb", "binvox", "raw8", "raw1", "summary",
                                           "vox", "nrrd",   "npy",  NULL};
static const char *const vdb_grid_names[] = {"level_set", "fog", "bool", NULL}; /* vx_vdb_class */

/* params.grid: an explicit box. */
typedef struct vbox {
    double origin[3], voxel_size;
    long dims[3];
    long index_offset[3]; /* the box's first voxel in the lattice of origin, voxel_size */
} vbox;

/* params.bricks. */
typedef struct vbricks {
    long size; /* cells per brick axis, a multiple of 8; 0 = one job */
} vbricks;

typedef struct vparams {
    long resolution;
    double voxel_size;
    vbox grid;
    int resolution_set, voxel_size_set, grid_set; /* which of the three makes the grid */
    int inside_set;                               /* null: winding on open meshes, else nonzero */
    long padding;
    int method, inside, fill; /* indices into the name arrays */
    long supersample;
    int samples; /* vx_samples */
    long threshold;
    int format;   /* vformat */
    int vdb_grid; /* vx_vdb_class */
    vbricks bricks;
    int bricks_set;         /* null: bricks of BRICK_DEFAULT past --brick-threshold (vdb only) */
    int merge;              /* bricks: one merged .vdb, else a manifest of the brick files */
    long vdb_index_base[3]; /* the lattice index at .vdb index 0 (a brick of a larger grid) */
    int vdb_index_base_set;
} vparams;

/* The brick edge of grids bricked by --brick-threshold: a multiple of
 * OpenVDB's 128^3 internal nodes; job_bytes puts a 512^3 brick's job at about
 * 160 MB (bool or 0/1 fog), the dense whole grid never being held. */
#define BRICK_DEFAULT 512

static const vx_pspec origin_item = VX_P_ITEM_NUM(-HUGE_VAL, HUGE_VAL);
static const vx_pspec dims_item = VX_P_ITEM_INT(1, VX_VOXELIZE_MAX_DIM);
static const vx_pspec index_item =
    VX_P_ITEM_INT(-(double)VX_GRID_INDEX_MAX, (double)VX_GRID_INDEX_MAX);
static const vx_pspec box_spec[] = {
    VX_P_VEC(vbox, origin, 3, NULL, &origin_item, "the corner of voxel (0, 0, 0)",
             .flags = VX_PF_NEEDED),
    VX_P_NUM(vbox, voxel_size, 0, 0, HUGE_VAL, "the edge of a voxel",
             .flags = VX_PF_NEEDED | VX_PF_GT_LO | VX_PF_TERSE),
    {.name = "dims",
     .type = VX_PT_ARRAY,
     .off = offsetof(vbox, dims),
     .sub = &dims_item,
     .item_size = sizeof(long),
     .min_items = 3,
     .max_items = 3,
     .flags = VX_PF_NEEDED,
     .doc = "voxels along x, y, z"},
    {.name = "index_offset",
     .type = VX_PT_ARRAY,
     .off = offsetof(vbox, index_offset),
     .sub = &index_item,
     .item_size = sizeof(long),
     .min_items = 3,
     .max_items = 3,
     .doc = "the lattice index of voxel (0, 0, 0): a brick of a larger grid"},
    VX_P_END,
};

static const vx_pspec bricks_spec[] = {
    VX_P_INT(vbricks, size, BRICK_DEFAULT, 0, VX_VOXELIZE_MAX_DIM,
             "cells per brick axis, a multiple of 8 (0 = one job, never bricked)"),
    VX_P_END,
};

#define SET(f) .set_off = offsetof(vparams, f##_set)
static const char *const not_vs[] = {"voxel_size", NULL}, *const not_res_vs[] = {
                                                              "resolution", "voxel_size", NULL};
static const vx_pspec spec[] = {
    VX_P_INT(vparams, resolution, 256, 1, VX_VOXELIZE_MAX_DIM, "voxels along the longest bbox side",
             .flags = VX_PF_NULLABLE, SET(resolution), .excludes = not_vs),
    VX_P_NUM(vparams, voxel_size, 1, 0, HUGE_VAL, "voxel edge (instead of resolution)",
             .flags = VX_PF_NULLABLE | VX_PF_GT_LO, SET(voxel_size)),
    {.name = "grid",
     .type = VX_PT_OBJECT,
     .off = offsetof(vparams, grid),
     .sub = box_spec,
     .flags = VX_PF_NULLABLE | VX_PF_LIST_FIELDS,
     SET(grid),
     .excludes = not_res_vs,
     .doc = "an explicit grid box {origin, voxel_size, dims}"},
    VX_P_INT(vparams, padding, 0, 0, 1024, "empty voxels around the bbox"),
    VX_P_ENUM(vparams, method, method_names, 0, "voxelization method"),
    VX_P_ENUM(vparams, inside, vx_inside_names, 0, "inside rule", .flags = VX_PF_NULLABLE,
              SET(inside)),
    VX_P_ENUM(vparams, fill, fill_names, 0, "solid or surface shell"),
    VX_P_INT(vparams, supersample, 1, 1, 2, "samples per voxel edge"),
    VX_P_ENUM(vparams, samples, samples_names, 0, "the sample pattern of supersample 2"),
    VX_P_INT(vparams, threshold, 4, 1, 8, "inside samples that make a voxel inside"),
    VX_P_ENUM(vparams, format, format_names, 0, "output format"),
    VX_P_ENUM(vparams, vdb_grid, vdb_grid_names, 1, "the grid a vdb output holds"),
    {.name = "bricks",
     .type = VX_PT_OBJECT,
     .off = offsetof(vparams, bricks),
     .sub = bricks_spec,
     .flags = VX_PF_NULLABLE,
     SET(bricks),
     .doc = "run the grid as bricks {size} merged into one .vdb (null: past --brick-threshold)"},
    VX_P_BOOL(vparams, merge, 1, "bricks: one merged .vdb, or false: a manifest of brick files"),
    {.name = "vdb_index_base",
     .type = VX_PT_ARRAY,
     .off = offsetof(vparams, vdb_index_base),
     .sub = &index_item,
     .item_size = sizeof(long),
     .min_items = 3,
     .max_items = 3,
     .flags = VX_PF_NULLABLE,
     SET(vdb_index_base),
     .doc = "vdb: the lattice index written as index 0 (bricks of one grid in one index space)"},
    VX_P_END,
};
#undef SET

static vx_inside inside_of(const vparams *p)
{
    return (vx_inside)p->inside; /* the names follow the enum's order */
}

static vx_fill fill_of(const vparams *p)
{
    return p->fill == 1 ? VX_FILL_SURFACE : VX_FILL_SOLID;
}

typedef struct vstate {
    vx_bitgrid grid;
    vx_voxelize_stats st;
    int have_grid;
    vx_inside inside; /* as run */
    /* bricked: the whole grid, brick edge, and the n brick files (owned
     * copies of their paths; with merge their voxel offsets for the log) */
    vx_grid whole;
    int brick_size, nbricks, merge;
    char **brick_paths;
    int brick_jobs; /* cluster mode: the bricks are child jobs' files (theirs to keep) */
    char *out_path; /* the primary output: the merged .vdb or the manifest */
    /* the .vdb writer's tree, freed with the state: after the job has
     * finished and been told, before its worker takes another */
    vx_vdb_tree *vdb_tree;
} vstate;

/* Memory one job needs for a grid: the bit grid (and sample counts), the
 * GPU's copy of it plus float render targets the size of the largest grid
 * face (per sample), and the writer's own buffers (OpenVDB's tree; binvox's
 * events, at most a quarter of the bit grid, or its bounded coder's 32 MiB,
 * fit in the GPU copy's share, gone by then; the other writers stream). An
 * estimate, but an upper one. */
static uint64_t job_bytes(const int dims[3], int ss, vx_samples samples, vformat format,
                          vx_vdb_class cls)
{
    uint64_t bits = vx_bitgrid_bytes(dims, ss);
    const int coverage = ss == 2; /* the vdb writer's FloatGrid */
    if (ss == 2 && samples == VX_SAMPLES_FACES) {
        /* four centre-sampled grids, three of them one voxel longer */
        ss = 1;
        for (int a = 0; a < 3; a++) {
            int d1[3] = {dims[0], dims[1], dims[2]};
            d1[a]++;
            bits += vx_bitgrid_bytes(d1, 1);
        }
        bits += vx_bitgrid_bytes(dims, 1);
    }
    uint64_t a = (uint64_t)dims[0] * dims[1], b = (uint64_t)dims[1] * dims[2],
             c = (uint64_t)dims[0] * dims[2];
    uint64_t face = a > b ? (a > c ? a : c) : (b > c ? b : c);
    uint64_t gpu = bits + face * 16 * (uint64_t)(ss * ss);
    uint64_t enc = format == F_VDB ? vx_voxel_vdb_bytes(dims, cls, coverage) : 0;
    return bits + gpu + enc;
}

/* Checks the grid bounds and the memory limit. `what` names the params
 * that made the grid; kind is VX_EUNPROC at parse time (422) and
 * VX_ETOOBIG when the mesh decided the dims (the job fails). */
/* The brick edge a grid of dims runs with (0 = one job): params.bricks,
 * else BRICK_DEFAULT for a .vdb of more cells than --brick-threshold. */
/* Most bricks one grid is cut into (each a .vdb; in cluster mode each a
 * job): 2^16, a 16384^3 grid in bricks of 256. */
#define BRICKS_MAX 65536

/* The bricks of S^3 across dims into nb, and their count; -1 with err when
 * there are more than BRICKS_MAX (their product had overflowed an int:
 * bricks of 8 across 16384^3 are 2^33). */
static int brick_grid(const int dims[3], int S, int nb[3], vx_err *err)
{
    for (int a = 0; a < 3; a++)
        nb[a] = (dims[a] + S - 1) / S;
    uint64_t n = (uint64_t)nb[0] * (uint64_t)nb[1] * (uint64_t)nb[2];
    if (n > BRICKS_MAX)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.bricks.size %d cuts this %dx%dx%d grid into %llu bricks, over "
                          "the %d a grid may have: use larger bricks",
                          S, dims[0], dims[1], dims[2], (unsigned long long)n, BRICKS_MAX);
    return (int)n;
}

static int brick_size_of(const vparams *p, const int dims[3], const vx_limits *lim)
{
    if (p->bricks_set) return (int)p->bricks.size;
    if (p->format != F_VDB) return 0;
    uint64_t n = (uint64_t)dims[0] * (uint64_t)dims[1] * (uint64_t)dims[2];
    uint64_t t = lim && lim->brick_threshold ? lim->brick_threshold : (uint64_t)1 << 30;
    return n > t ? BRICK_DEFAULT : 0;
}

/* A .vdb's voxel size h against OpenVDB's smallest (vx_vdb_voxel_size_ok)
 * and a level set's largest: what names the parameter that gives h; at
 * submission invalid_params, once the mesh gives h voxel_size_too_small or
 * voxel_size_too_large. */
static int check_vdb_voxel(const vparams *p, double h, const char *what, int submission,
                           vx_err *err)
{
    if (p->format != F_VDB) return 0;
    if (!vx_vdb_voxel_size_ok(h))
        return vx_err_set(err, VX_EUNPROC, submission ? "invalid_params" : "voxel_size_too_small",
                          "%s gives a voxel size of %.6g, under the %.6g that OpenVDB's "
                          "transforms take: a .vdb needs larger voxels (a lower resolution, a "
                          "larger voxel size, or a mesh in smaller units); the other formats "
                          "have no such bound",
                          what, h, vx_vdb_min_voxel_size());
    const double max = vx_vdb_max_voxel_size(p->vdb_grid);
    if (h > max)
        return vx_err_set(err, VX_EUNPROC, submission ? "invalid_params" : "voxel_size_too_large",
                          "%s gives a voxel size of %.6g, over the %.6g whose 3-voxel distances "
                          "a level set's floats hold: smaller voxels, or vdb_grid fog or bool",
                          what, h, max);
    return 0;
}

static int check_grid(const int dims[3], const vparams *p, const vx_limits *lim, const char *what,
                      vx_err_kind kind, vx_err *err)
{
    const char *code = kind == VX_EUNPROC ? "invalid_params" : "job_memory_limit";
    uint64_t n = 1;
    for (int a = 0; a < 3; a++) {
        if (dims[a] < 1 || dims[a] > VX_VOXELIZE_MAX_DIM)
            return vx_err_set(err, kind, code, "%s gives %d voxels along axis %d, the limit is %d",
                              what, dims[a], a, VX_VOXELIZE_MAX_DIM);
        n *= (uint64_t)dims[a];
    }
    const int S = brick_size_of(p, dims, lim);
    if (S) {
        /* Bricked: one brick's job at a time (the merged sparse tree is
         * checked against the limit as it grows, in voxelize_encode). */
        int bd[3];
        for (int a = 0; a < 3; a++)
            bd[a] = dims[a] < S ? dims[a] : S;
        if ((uint64_t)bd[0] * (uint64_t)bd[1] * (uint64_t)bd[2] > VX_VOXELIZE_MAX_VOXELS)
            return vx_err_set(err, kind, code,
                              "%s: a %dx%dx%d brick is over one job's 2048^3 voxels (smaller "
                              "params.bricks.size)",
                              what, bd[0], bd[1], bd[2]);
        uint64_t bytes =
            job_bytes(bd, (int)p->supersample, (vx_samples)p->samples, F_VDB,
                      p->vdb_grid == VX_VDB_LEVEL_SET ? VX_VDB_BOOL : (vx_vdb_class)p->vdb_grid);
        if (lim && lim->max_job_memory && bytes > lim->max_job_memory)
            return vx_err_set(err, kind, code,
                              "%s: a %dx%dx%d brick needs about %llu bytes, over the job memory "
                              "limit of %llu (job_memory_limit; smaller params.bricks.size)",
                              what, bd[0], bd[1], bd[2], (unsigned long long)bytes,
                              (unsigned long long)lim->max_job_memory);
        return 0;
    }
    if (n > VX_VOXELIZE_MAX_VOXELS)
        return vx_err_set(err, kind, code,
                          "%s gives %dx%dx%d = %llu voxels, the limit is 2048^3 for one job "
                          "(format vdb runs larger grids as params.bricks)",
                          what, dims[0], dims[1], dims[2], (unsigned long long)n);
    /* binvox stores a d^3 cube, d the longest axis: a 4096 x 1 x 1 grid
     * wrote 539 MB of empty padding */
    int d = dims[0] > dims[1] ? dims[0] : dims[1];
    d = dims[2] > d ? dims[2] : d;
    if (p->format == F_BINVOX && (uint64_t)d * d * d > VX_VOXELIZE_MAX_VOXELS)
        return vx_err_set(err, kind, code,
                          "%s gives %dx%dx%d; binvox pads it to a %d^3 cube, over the 2048^3 "
                          "voxels of one job (use another format, or a grid nearer a cube)",
                          what, dims[0], dims[1], dims[2], d);
    uint64_t bytes = job_bytes(dims, (int)p->supersample, (vx_samples)p->samples,
                               (vformat)p->format, (vx_vdb_class)p->vdb_grid);
    if (lim && lim->max_job_memory && bytes > lim->max_job_memory)
        return vx_err_set(
            err, kind, code,
            "%s: a %dx%dx%d grid needs about %llu bytes, over the job memory limit of %llu "
            "(job_memory_limit)",
            what, dims[0], dims[1], dims[2], (unsigned long long)bytes,
            (unsigned long long)lim->max_job_memory);
    return 0;
}

/* The rules between fields; the grid and memory limits. */
static int voxelize_check(void *params, const vx_limits *lim, vx_err *err)
{
    vparams *p = params;
    if (p->samples == VX_SAMPLES_FACES) {
        if (p->supersample != 2)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.samples \"faces\" needs params.supersample 2");
        if (p->threshold > 7)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.threshold must be 1..7 with params.samples \"faces\" (7 "
                              "samples per voxel), got %ld",
                              p->threshold);
        if (fill_of(p) != VX_FILL_SOLID)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.samples \"faces\" needs params.fill solid");
    }
    /* Peeling and scan sample each voxel once, at its centre; only slicing
     * supersamples the seed's way (seed 003's accuracy improvement). The
     * faces pattern runs any method on four grids. */
    if (p->supersample == 2 && p->samples == VX_SAMPLES_CUBE &&
        (p->method == VX_METHOD_PEEL || p->method == VX_METHOD_SCAN))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.supersample 2 needs params.method slice or auto (%s samples "
                          "voxel centres only)",
                          p->method == VX_METHOD_PEEL ? "peel" : "scan");
    if (p->inside_set && p->inside == VX_INSIDE_WINDING) {
        if (p->method != VX_METHOD_AUTO)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.inside \"winding\" runs its own CPU method: params.method "
                              "must be auto");
        if (p->supersample == 2 && p->samples == VX_SAMPLES_CUBE)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.inside \"winding\" samples voxel centres: params.supersample "
                              "2 needs params.samples \"faces\"");
        if (fill_of(p) == VX_FILL_SURFACE)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.inside \"winding\" fills solids: params.fill \"surface\" "
                              "(peel's shell) takes no winding number");
    }
    /* Slicing fills solids only; auto slices whenever it supersamples
     * (cube pattern). Refused here, not when the job runs (issue 14). */
    if (fill_of(p) == VX_FILL_SURFACE && p->method == VX_METHOD_SLICE)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.fill \"surface\" needs params.method peel or auto (slice fills "
                          "solids only)");
    if (p->method == VX_METHOD_CPU &&
        (fill_of(p) == VX_FILL_SURFACE || (p->inside_set && p->inside == VX_INSIDE_ROBUST) ||
         (p->supersample == 2 && p->samples == VX_SAMPLES_CUBE)))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.method \"cpu\" fills solids by nonzero or parity at voxel "
                          "centres (params.supersample 2 with params.samples \"faces\"); use "
                          "peel, slice or auto");
    if (fill_of(p) == VX_FILL_SURFACE && p->method == VX_METHOD_AUTO && p->supersample == 2)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.fill \"surface\" cannot be supersampled: with "
                          "params.supersample 2, auto runs slice, which fills solids only");
    if (p->bricks_set && p->bricks.size % 8)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.bricks.size must be a multiple of 8 (OpenVDB's leaf edge), or 0 "
                          "for one job; got %ld",
                          p->bricks.size);
    if (p->bricks_set && p->bricks.size && p->format != F_VDB)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.bricks needs params.format \"vdb\" (one merged sparse grid, or "
                          "with merge false a manifest of brick .vdb files); %s runs as one job",
                          format_names[p->format]);
    if (!p->merge) {
        if (!p->bricks_set || !p->bricks.size)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.merge false needs params.bricks {\"size\": S}");
        if (p->vdb_grid == VX_VDB_LEVEL_SET)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.merge false needs params.vdb_grid fog or bool (a level set "
                              "of each brick alone would have a false surface at its faces)");
    }
    if (p->vdb_index_base_set) {
        if (p->format != F_VDB)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.vdb_index_base needs params.format \"vdb\"");
        if (!p->grid_set || (p->bricks_set && p->bricks.size) || !p->bricks_set)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.vdb_index_base needs params.grid (the box's index_offset "
                              "says where it lies) and params.bricks {\"size\": 0}");
        for (int a = 0; a < 3; a++) {
            const long at = p->grid.index_offset[a] - p->vdb_index_base[a];
            if (at % 8)
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "params.grid.index_offset - params.vdb_index_base must be a "
                                  "multiple of 8 on every axis (OpenVDB's leaf edge)");
            if (at < -VX_VDB_MAX_INDEX || at + (long)p->grid.dims[a] > VX_VDB_MAX_INDEX)
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "params.grid.index_offset - params.vdb_index_base puts the "
                                  "box at %ld..%ld along axis %d of the .vdb's index space, "
                                  "outside +-2^30 (OpenVDB's coordinates are 32-bit)",
                                  at, at + (long)p->grid.dims[a] - 1, a);
        }
    }
    if (p->grid_set) {
        if (p->padding)
            return vx_err_set(
                err, VX_EUNPROC, "invalid_params",
                "params.padding is not allowed with params.grid (make the box larger)");
        int dims[3] = {(int)p->grid.dims[0], (int)p->grid.dims[1], (int)p->grid.dims[2]};
        if (check_vdb_voxel(p, p->grid.voxel_size, "params.grid.voxel_size", 1, err)) return -1;
        /* An explicit box must lie where meshes can (within +-1e30, as every
         * coordinate): past it an origin became inf in the nrrd and binvox
         * headers and a singular .vdb transform. */
        for (int a = 0; a < 3; a++) {
            /* every voxel's index, not only the first: a bricked box's
             * last brick is an index_offset of its own */
            const long last = p->grid.index_offset[a] + (long)p->grid.dims[a] - 1;
            if (last > VX_GRID_INDEX_MAX)
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "params.grid.index_offset[%d] + dims[%d] - 1 is %ld: every "
                                  "voxel's lattice index must lie within +-2^40",
                                  a, a, last);
            const double h = p->grid.voxel_size;
            const double lo = p->grid.origin[a] + (double)p->grid.index_offset[a] * h;
            const double hi = lo + (double)p->grid.dims[a] * h;
            if (!(fabs(lo) <= 1e30 && fabs(hi) <= 1e30))
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "params.grid puts axis %d's voxels from %.6g to %.6g: outside "
                                  "+-1e30, where every mesh lies",
                                  a, lo, hi);
        }
        return check_grid(dims, p, lim, "params.grid", VX_EUNPROC, err);
    }
    if (p->voxel_size_set) /* the dims depend on the mesh: checked in run_gl */
        return check_vdb_voxel(p, p->voxel_size, "params.voxel_size", 1, err);
    p->resolution_set = 1; /* the default */
    /* The dims depend on the mesh's bbox: voxelize_check_mesh checks the
     * grid the resolution gives it at submission (a flat mesh at 4096 is
     * far under the limit a cube of 4096 is over), the run again. */
    return 0;
}

static cJSON *array3(const double *v)
{
    return cJSON_CreateDoubleArray(v, 3);
}

/* The job's progress: the engine's 0..1 takes the first 1 - share of the
 * bar, the encoder's the rest; share is the encoder's part of the job time
 * as bench/voxel measured it (relative to the engine's), so that the bar
 * moves evenly through both. */
typedef struct vprog {
    vx_job_run *r;
    double share;
} vprog;

static double encode_share(const vparams *p)
{
    switch ((vformat)p->format) {
    case F_SUMMARY:
        return 0.0;
    case F_VDB:
        return p->vdb_grid == VX_VDB_LEVEL_SET ? 0.9 : p->vdb_grid == VX_VDB_FOG ? 0.5 : 0.25;
    case F_RAW1:
        return 0.2;
    case F_BINVOX:
        return 0.3;
    default:
        return 0.5; /* raw8, nrrd, npy (the disk), vox */
    }
}

static int engine_progress(void *ud, double fraction, vx_err *err)
{
    const vprog *p = ud;
    return vx_run_progress(p->r, (1.0 - p->share) * fraction, err);
}

static int encode_progress(void *ud, double fraction, vx_err *err)
{
    const vprog *p = ud;
    return vx_run_progress(p->r, 1.0 - p->share + p->share * fraction, err);
}

/* Sets a stats field, replacing one left by an earlier attempt (run_gl is
 * retried after a context loss). */
static void stat_set(cJSON *stats, const char *name, cJSON *v)
{
    if (!stats || !v) {
        cJSON_Delete(v);
        return;
    }
    cJSON_DeleteItemFromObjectCaseSensitive(stats, name);
    if (!cJSON_AddItemToObject(stats, name, v)) cJSON_Delete(v);
}

/* The grid of p: explicit, or from the mesh (not checked). */
static int make_grid(const vparams *p, const vx_mesh *mesh, vx_grid *g, vx_err *err)
{
    memset(g, 0, sizeof *g);
    if (p->grid_set) {
        g->h = p->grid.voxel_size;
        for (int a = 0; a < 3; a++) {
            g->origin[a] = p->grid.origin[a];
            g->dims[a] = (int)p->grid.dims[a];
            g->index[a] = p->grid.index_offset[a];
        }
        return 0;
    }
    return p->resolution_set
               ? vx_grid_from_resolution(mesh, (int)p->resolution, (int)p->padding, g, err)
               : vx_grid_from_voxel_size(mesh, p->voxel_size, (int)p->padding, g, err);
}

/* A grid made from the mesh against the bounds (an explicit one was
 * checked with the params): at submission VX_EUNPROC invalid_params, in
 * the job VX_ETOOBIG and the .vdb voxel size codes. */
static int check_mesh_grid(const vparams *p, const vx_grid *g, const vx_limits *lim, int submission,
                           vx_err *err)
{
    if (p->grid_set) return 0;
    const char *what = p->resolution_set ? "params.resolution" : "params.voxel_size";
    if (check_vdb_voxel(p, g->h, what, submission, err)) return -1;
    return check_grid(g->dims, p, lim, what, submission ? VX_EUNPROC : VX_ETOOBIG, err);
}

/* The grid of p (explicit, or from the mesh and checked: VX_ETOOBIG). */
static int grid_of(const vparams *p, const vx_mesh *mesh, const vx_limits *lim, vx_grid *g,
                   vx_err *err)
{
    return make_grid(p, mesh, g, err) || check_mesh_grid(p, g, lim, 0, err) ? -1 : 0;
}

/* The engine's desc for p on grid g (no progress hook yet). */
static void desc_of(const vparams *p, const vx_mesh *mesh, const vx_limits *lim, const vx_grid *g,
                    vx_voxelize_desc *d)
{
    memset(d, 0, sizeof *d);
    d->grid = *g;
    d->method = (vx_method)p->method; /* the name arrays follow the enums' order */
    d->fill = fill_of(p);
    d->supersample = (int)p->supersample;
    d->threshold = (int)p->threshold;
    d->samples = (vx_samples)p->samples;
    d->inside = p->inside_set ? inside_of(p) : vx_voxelize_default_inside(mesh, d);
    d->max_memory = lim ? lim->max_job_memory : 0;
    d->max_slab_rows = vx_voxelize_slab_rows(d->grid.dims);
}

static void stats_engine(cJSON *stats, const vx_voxelize_stats *st)
{
    stat_set(stats, "layers", cJSON_CreateNumber(st->layers));
    stat_set(stats, "passes", cJSON_CreateNumber(st->passes));
    stat_set(stats, "slices", cJSON_CreateNumber(st->slices));
    stat_set(stats, "chunks", cJSON_CreateNumber(st->chunks));
    stat_set(stats, "upload_ms", cJSON_CreateNumber(st->upload_ms));
    stat_set(stats, "gpu_peel_ms", cJSON_CreateNumber(st->gpu_peel_ms));
    stat_set(stats, "gpu_fill_ms", cJSON_CreateNumber(st->gpu_fill_ms));
    stat_set(stats, "gpu_slice_ms", cJSON_CreateNumber(st->gpu_slice_ms));
    stat_set(stats, "readback_ms", cJSON_CreateNumber(st->readback_ms));
}

/* The stats both paths give: the grid as a whole and the mesh. */
static void stats_grid(cJSON *stats, const vx_grid *g, const vx_mesh *mesh, const char *method,
                       vx_inside inside, uint64_t voxels_inside)
{
    double dims[3] = {g->dims[0], g->dims[1], g->dims[2]};
    stat_set(stats, "method", cJSON_CreateString(method ? method : "unknown"));
    stat_set(stats, "inside", cJSON_CreateString(vx_inside_names[inside]));
    stat_set(stats, "boundary_edges", cJSON_CreateNumber((double)mesh->boundary_edges));
    stat_set(stats, "boundary_edges_welded",
             cJSON_CreateNumber((double)mesh->boundary_edges_welded));
    stat_set(stats, "misoriented_edges", cJSON_CreateNumber((double)mesh->misoriented_edges));
    stat_set(stats, "dims", array3(dims));
    stat_set(stats, "origin", array3(g->origin));
    double index[3] = {(double)g->index[0], (double)g->index[1], (double)g->index[2]};
    stat_set(stats, "index_offset", array3(index));
    stat_set(stats, "voxel_size", cJSON_CreateNumber(g->h));
    stat_set(stats, "triangles", cJSON_CreateNumber((double)mesh->ntris));
    stat_set(stats, "voxels_inside", cJSON_CreateNumber((double)voxels_inside));
    stat_set(stats, "volume", cJSON_CreateNumber((double)voxels_inside * g->h * g->h * g->h));
}

/* The grid's corner for the writers: origin + index_offset * h, index 0
 * (the voxels themselves were decided in the lattice's frame). */
static vx_grid corner_of(const vx_grid *g)
{
    vx_grid c = *g;
    for (int a = 0; a < 3; a++) {
        c.origin[a] += (double)c.index[a] * c.h;
        c.index[a] = 0;
    }
    return c;
}

/* The params of one brick of a bricked voxelize, a job spec of its own:
 * an explicit-box voxelize on the whole grid's lattice (grid.origin and
 * voxel_size the whole grid's, grid.index_offset the brick's first voxel
 * in that lattice: whole index + at), the inside rule as decided for the
 * whole mesh, format vdb of class cls, never bricked again. Owned JSON,
 * NULL on OOM. The brick's result goes to index `at` of the whole grid's
 * .vdb index space (vx_voxel_write_vdb_at). */
static cJSON *brick_params(const vparams *p, const vx_grid *whole, const int at[3],
                           const int dims[3], vx_inside inside, vx_vdb_class cls)
{
    cJSON *o = cJSON_CreateObject(), *g = cJSON_AddObjectToObject(o, "grid");
    double idx[3], d[3];
    for (int a = 0; a < 3; a++) {
        idx[a] = (double)(whole->index[a] + at[a]);
        d[a] = dims[a];
    }
    cJSON_AddItemToObject(g, "origin", array3(whole->origin));
    cJSON_AddNumberToObject(g, "voxel_size", whole->h);
    cJSON_AddItemToObject(g, "dims", array3(d));
    cJSON_AddItemToObject(g, "index_offset", array3(idx));
    cJSON_AddStringToObject(o, "method", method_names[p->method]);
    cJSON_AddStringToObject(o, "inside", vx_inside_names[inside]);
    cJSON_AddStringToObject(o, "fill", fill_names[p->fill]);
    cJSON_AddNumberToObject(o, "supersample", (double)p->supersample);
    cJSON_AddStringToObject(o, "samples", samples_names[p->samples]);
    cJSON_AddNumberToObject(o, "threshold", (double)p->threshold);
    cJSON_AddStringToObject(o, "format", "vdb");
    cJSON_AddStringToObject(o, "vdb_grid", vdb_grid_names[cls]);
    cJSON_AddNumberToObject(cJSON_AddObjectToObject(o, "bricks"), "size", 0);
    return o;
}

static vx_vdb_meta meta_of(const vparams *p, vx_job_run *r, const char *method, vx_inside inside)
{
    vx_vdb_meta m = {
        .method = method,
        .inside = vx_inside_names[inside],
        .fill = fill_names[p->fill],
        .mesh = vx_run_mesh_id(r),
        .supersample = (int)p->supersample,
        .threshold = (int)p->threshold,
        .samples = samples_names[p->samples],
    };
    return m;
}

/* Progress of brick b of n: its engine's 0..1 within the run's share. */
typedef struct bprog {
    vprog *prog;
    int b, n;
} bprog;

static int brick_progress(void *ud, double fraction, vx_err *err)
{
    const bprog *q = ud;
    return engine_progress(q->prog, (q->b + fraction) / q->n, err);
}

/* Runs one brick from its spec (brick_params, printed and read back as a
 * job's params are, so that the spec alone decides it) and writes its
 * .vdb to path at index `at`. GL thread. */
static int run_brick(vx_job_run *r, const vx_mesh *mesh, const cJSON *bspec, const int at[3],
                     bprog *q, const char *path, vx_voxelize_stats *st, vx_err *err)
{
    const vx_limits *lim = vx_run_limits(r);
    char *text = vx_json_print(bspec, 0);
    cJSON *back = text ? cJSON_Parse(text) : NULL;
    free(text);
    vparams *bp = back ? vx_kind_read(&vx_kind_voxelize, back, lim, err) : NULL;
    cJSON_Delete(back);
    if (!bp) return text ? -1 : vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    vx_grid g;
    vx_voxelize_desc d;
    vx_bitgrid bits = {0};
    int rc = grid_of(bp, mesh, lim, &g, err);
    if (!rc) {
        desc_of(bp, mesh, lim, &g, &d);
        d.progress = brick_progress;
        d.ud = q;
        rc = vx_voxelize(vx_run_gl(r), mesh, &d, &bits, st, err);
    }
    if (!rc) {
        /* the whole grid's corner, computed as one job computes it */
        for (int a = 0; a < 3; a++) {
            bits.grid.origin[a] += (double)(bits.grid.index[a] - at[a]) * bits.grid.h;
            bits.grid.index[a] = 0;
        }
        vx_vdb_meta m = meta_of(bp, r, st->method, inside_of(bp));
        rc = vx_voxel_write_vdb_at(&bits, at, (vx_vdb_class)bp->vdb_grid, &m, path, NULL, err);
    }
    vx_bitgrid_free(&bits);
    vx_kind_params_free(&vx_kind_voxelize, bp);
    return rc;
}

/* A bricked run: the grid d->grid in bricks of S^3 from its voxel
 * (0,0,0), one after another on this thread (each an independent spec,
 * brick_params), each written as a brick .vdb; voxelize_encode merges them
 * or lists them. Peak memory: one brick. */
static int run_bricks(vx_job_run *r, const vx_mesh *mesh, const vparams *p,
                      const vx_voxelize_desc *d, int S, vprog *prog, vstate *s, vx_err *err)
{
    const vx_grid *w = &d->grid;
    int nb[3];
    const int n = brick_grid(w->dims, S, nb, err);
    if (n < 0) return -1;
    s->whole = *w;
    s->brick_size = S;
    s->inside = d->inside;
    s->brick_paths = calloc((size_t)n, sizeof *s->brick_paths);
    if (!s->brick_paths)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the brick list");
    /* The primary output first: the merged grid or the manifest. */
    const char *first = p->merge ? vx_run_output(r, "voxels", "vdb", "application/x-openvdb", err)
                                 : vx_run_output(r, "manifest", "json", "application/json", err);
    if (!first || !(s->out_path = strdup(first)))
        return first ? vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory") : -1;
    s->merge = p->merge;
    const vx_vdb_class cls =
        p->vdb_grid == VX_VDB_LEVEL_SET ? VX_VDB_BOOL : (vx_vdb_class)p->vdb_grid;
    cJSON *list = cJSON_CreateArray();
    vx_voxelize_stats sum = {0};
    uint64_t inside = 0;
    int rc = list ? 0 : vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    for (int b = 0; !rc && b < n; b++) {
        const int bi[3] = {b % nb[0], b / nb[0] % nb[1], b / (nb[0] * nb[1])};
        int at[3], bd[3];
        for (int a = 0; a < 3; a++) {
            at[a] = bi[a] * S;
            bd[a] = w->dims[a] - at[a] < S ? w->dims[a] - at[a] : S;
        }
        char path[VX_PATH_MAX];
        if (p->merge) {
            snprintf(path, sizeof path, "%s.brick-%d", first, b);
        } else {
            char name[64];
            snprintf(name, sizeof name, "brick_%d_%d_%d", bi[0], bi[1], bi[2]);
            const char *o = vx_run_output(r, name, "vdb", "application/x-openvdb", err);
            if (!o) {
                rc = -1;
                break;
            }
            snprintf(path, sizeof path, "%s", o);
        }
        s->brick_paths[b] = strdup(path);
        s->nbricks = b + 1;
        cJSON *bspec = brick_params(p, w, at, bd, d->inside, cls);
        if (!s->brick_paths[b] || !bspec) {
            cJSON_Delete(bspec);
            rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
            break;
        }
        bprog q = {prog, b, n};
        vx_voxelize_stats st = {0};
        double t0 = vx_mono();
        rc = run_brick(r, mesh, bspec, at, &q, path, &st, err);
        cJSON_Delete(bspec);
        if (rc) break;
        inside += st.voxels_inside;
        sum.method = st.method;
        sum.layers = st.layers > sum.layers ? st.layers : sum.layers;
        sum.passes += st.passes;
        sum.slices += st.slices;
        sum.chunks += st.chunks;
        sum.upload_ms += st.upload_ms;
        sum.gpu_peel_ms += st.gpu_peel_ms;
        sum.gpu_fill_ms += st.gpu_fill_ms;
        sum.gpu_slice_ms += st.gpu_slice_ms;
        sum.readback_ms += st.readback_ms;
        double off[3] = {at[0], at[1], at[2]}, dd[3] = {bd[0], bd[1], bd[2]}, idx[3];
        for (int a = 0; a < 3; a++)
            idx[a] = (double)(w->index[a] + at[a]);
        cJSON *e = cJSON_CreateObject();
        cJSON_AddItemToObject(e, "offset", array3(off));
        cJSON_AddItemToObject(e, "index_offset", array3(idx));
        cJSON_AddItemToObject(e, "dims", array3(dd));
        cJSON_AddNumberToObject(e, "voxels_inside", (double)st.voxels_inside);
        cJSON_AddNumberToObject(e, "ms", (vx_mono() - t0) * 1e3);
        if (!cJSON_AddItemToArray(list, e)) cJSON_Delete(e);
        stat_set(vx_run_stats(r), "bricks_done", cJSON_CreateNumber(b + 1));
    }
    cJSON *stats = vx_run_stats(r);
    stat_set(stats, "bricks", list);
    if (rc) return -1;
    double nbd[3] = {nb[0], nb[1], nb[2]};
    stat_set(stats, "brick_size", cJSON_CreateNumber(S));
    stat_set(stats, "brick_grid", array3(nbd));
    stats_grid(stats, w, mesh, sum.method, d->inside, inside);
    stats_engine(stats, &sum);
    return vx_run_progress(r, 1.0 - prog->share, err);
}

/* A mesh with only what the grid and the default inside rule read: the
 * bbox and the boundary edges, from a stored mesh's metadata. */
static int mesh_of_meta(const cJSON *meta, vx_mesh *m, vx_err *err)
{
    memset(m, 0, sizeof *m);
    const cJSON *bb = cJSON_GetObjectItemCaseSensitive(meta, "bbox");
    const cJSON *lo = cJSON_GetObjectItemCaseSensitive(bb, "min"),
                *hi = cJSON_GetObjectItemCaseSensitive(bb, "max");
    if (cJSON_GetArraySize(lo) != 3 || cJSON_GetArraySize(hi) != 3)
        return vx_err_set(err, VX_EINTERNAL, "mesh_meta", "the mesh's metadata has no bbox");
    for (int a = 0; a < 3; a++) {
        m->bbox_min[a] = cJSON_GetNumberValue(cJSON_GetArrayItem(lo, a));
        m->bbox_max[a] = cJSON_GetNumberValue(cJSON_GetArrayItem(hi, a));
    }
    m->boundary_edges =
        (size_t)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(meta, "boundary_edges"));
    /* metadata stored before the welded count: the plain one */
    const cJSON *w = cJSON_GetObjectItemCaseSensitive(meta, "boundary_edges_welded");
    m->boundary_edges_welded = cJSON_IsNumber(w) ? (size_t)w->valuedouble : m->boundary_edges;
    return 0;
}

/* Cluster mode (kind.h split): a bricked grid as one child job per brick,
 * each an explicit box of the grid's lattice written in the grid's index
 * space (vdb_index_base), the inside rule decided for the whole mesh. */
/* At submission, from the mesh's metadata (its bbox, printed to round
 * trip): a grid the mesh makes over the size bounds, voxels too small or
 * large for a .vdb, or a bricked grid of more than BRICKS_MAX bricks is
 * 422 (what the grid's making itself finds wrong, the job says). */
static int voxelize_check_mesh(const void *params, const cJSON *mesh_meta, const vx_limits *lim,
                               vx_err *err)
{
    const vparams *p = params;
    vx_mesh m;
    vx_grid w;
    vx_err e;
    if (mesh_of_meta(mesh_meta, &m, &e)) return 0;
    if (make_grid(p, &m, &w, &e)) /* past the per-axis bound: "voxel_size ... gives ..." */
        return e.kind == VX_ETOOBIG
                   ? vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s", e.message)
                   : 0;
    if (check_mesh_grid(p, &w, lim, 1, err)) return -1;
    /* No engine runs a face vertex more than 2^50 voxels from the lattice
     * origin (lattice.h; the cpu and winding engines failed the job, the
     * GPU ones set voxels from floats that far off): the bbox's corners
     * bound every vertex a face uses. */
    double u[3];
    if (vx_lattice_unit(&w, m.bbox_min, u) || vx_lattice_unit(&w, m.bbox_max, u))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.grid: the mesh reaches more than 2^50 voxels from the grid "
                          "origin; use a larger voxel_size");
    const int S = brick_size_of(p, w.dims, lim);
    int nb[3];
    return S && brick_grid(w.dims, S, nb, err) < 0 ? -1 : 0;
}

static cJSON *voxelize_split(const void *params, const cJSON *mesh_meta, const vx_limits *lim,
                             vx_err *err)
{
    const vparams *p = params;
    vx_mesh m;
    vx_grid w;
    if (mesh_of_meta(mesh_meta, &m, err) || grid_of(p, &m, lim, &w, err)) return NULL;
    const int S = brick_size_of(p, w.dims, lim);
    if (!S) return NULL;
    vx_voxelize_desc d;
    desc_of(p, &m, lim, &w, &d);
    const vx_vdb_class cls =
        p->vdb_grid == VX_VDB_LEVEL_SET ? VX_VDB_BOOL : (vx_vdb_class)p->vdb_grid;
    int nb[3];
    if (brick_grid(w.dims, S, nb, err) < 0) return NULL;
    cJSON *list = cJSON_CreateArray();
    double base[3] = {(double)w.index[0], (double)w.index[1], (double)w.index[2]};
    for (int b = 0; list && b < nb[0] * nb[1] * nb[2]; b++) {
        const int bi[3] = {b % nb[0], b / nb[0] % nb[1], b / (nb[0] * nb[1])};
        int at[3], bd[3];
        for (int a = 0; a < 3; a++) {
            at[a] = bi[a] * S;
            bd[a] = w.dims[a] - at[a] < S ? w.dims[a] - at[a] : S;
        }
        cJSON *c = brick_params(p, &w, at, bd, d.inside, cls);
        if (!c || !cJSON_AddItemToObject(c, "vdb_index_base", array3(base)) ||
            !cJSON_AddItemToArray(list, c)) {
            cJSON_Delete(c);
            cJSON_Delete(list);
            list = NULL;
        }
    }
    if (!list) vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the brick jobs");
    return list;
}

/* A bricked run whose bricks were child jobs (cluster mode): their .vdb
 * files, in the grid's index space, become the brick list that
 * voxelize_encode merges (or, merge false, lists by their URLs); the stats
 * list each brick with its job and sum theirs. No GL work. */
static int bricks_from_children(vx_job_run *r, const vx_mesh *mesh, const vparams *p,
                                const vx_voxelize_desc *d, int S, vprog *prog, vstate *s,
                                vx_err *err)
{
    const vx_grid *w = &d->grid;
    int nb[3];
    const int n = brick_grid(w->dims, S, nb, err);
    if (n < 0) return -1;
    if ((size_t)n != vx_run_children(r))
        return vx_err_set(err, VX_EINTERNAL, "bricks_mismatch",
                          "the grid has %d bricks, the job %zu brick jobs", n, vx_run_children(r));
    s->whole = *w;
    s->brick_size = S;
    s->inside = d->inside;
    s->merge = p->merge;
    s->nbricks = n;
    s->brick_paths = calloc((size_t)n, sizeof *s->brick_paths);
    s->brick_jobs = 1;
    cJSON **entry = calloc((size_t)n, sizeof *entry);
    if (!s->brick_paths || !entry) {
        free(entry);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the brick list");
    }
    const char *first = p->merge ? vx_run_output(r, "voxels", "vdb", "application/x-openvdb", err)
                                 : vx_run_output(r, "manifest", "json", "application/json", err);
    int rc = first && (s->out_path = strdup(first)) ? 0 : -1;
    if (first && !s->out_path) vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    vx_voxelize_stats sum = {0};
    uint64_t inside = 0;
    for (size_t i = 0; !rc && i < (size_t)n; i++) {
        const char *cid;
        const cJSON *cp, *cst;
        vx_run_child(r, i, &cid, &cp, &cst);
        const cJSON *io = cJSON_GetObjectItemCaseSensitive(
            cJSON_GetObjectItemCaseSensitive(cp, "grid"), "index_offset");
        int at[3], b = 0, ok = cJSON_GetArraySize(io) == 3;
        for (int a = 0; ok && a < 3; a++) {
            at[a] = (int)(cJSON_GetNumberValue(cJSON_GetArrayItem(io, a)) - (double)w->index[a]);
            ok = at[a] >= 0 && at[a] % S == 0 && at[a] / S < nb[a];
        }
        if (ok) b = at[0] / S + nb[0] * (at[1] / S + nb[1] * (at[2] / S));
        if (!ok || s->brick_paths[b]) {
            rc = vx_err_set(err, VX_EINTERNAL, "bricks_mismatch",
                            "brick job %s is not one of the grid's bricks", cid);
            break;
        }
        char path[VX_PATH_MAX];
        if (vx_run_child_output(r, i, "voxels", path, sizeof path, err)) {
            rc = -1;
            break;
        }
        if (!(s->brick_paths[b] = strdup(path))) {
            rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
            break;
        }
        char bname[64];
        snprintf(bname, sizeof bname, "brick_%d_%d_%d", at[0] / S, at[1] / S, at[2] / S);
        if (!p->merge && vx_run_output_of_child(r, bname, i, "voxels", err)) {
            rc = -1;
            break;
        }
        double v = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(cst, "voxels_inside"));
        inside += v > 0 ? (uint64_t)v : 0;
        const cJSON *mt = cJSON_GetObjectItemCaseSensitive(cst, "method");
        if (cJSON_IsString(mt)) sum.method = mt->valuestring;
        double off[3] = {at[0], at[1], at[2]}, dd[3], idx[3];
        const cJSON *dims =
            cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(cp, "grid"), "dims");
        for (int a = 0; a < 3; a++) {
            dd[a] = cJSON_GetNumberValue(cJSON_GetArrayItem(dims, a));
            idx[a] = (double)(w->index[a] + at[a]);
        }
        cJSON *e = cJSON_CreateObject();
        cJSON_AddItemToObject(e, "offset", array3(off));
        cJSON_AddItemToObject(e, "index_offset", array3(idx));
        cJSON_AddItemToObject(e, "dims", array3(dd));
        cJSON_AddNumberToObject(e, "voxels_inside", v);
        cJSON_AddNumberToObject(
            e, "ms", cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(cst, "run_ms")));
        cJSON_AddStringToObject(e, "job", cid);
        entry[b] = e;
    }
    cJSON *list = cJSON_CreateArray();
    for (int b = 0; b < n; b++)
        if (entry[b] && !cJSON_AddItemToArray(list, entry[b])) cJSON_Delete(entry[b]);
    free(entry);
    cJSON *stats = vx_run_stats(r);
    stat_set(stats, "bricks", list);
    if (rc) return -1;
    double nbd[3] = {nb[0], nb[1], nb[2]};
    stat_set(stats, "bricks_done", cJSON_CreateNumber(n));
    stat_set(stats, "brick_size", cJSON_CreateNumber(S));
    stat_set(stats, "brick_grid", array3(nbd));
    stats_grid(stats, w, mesh, sum.method, d->inside, inside);
    stats_engine(stats, &sum);
    return vx_run_progress(r, 1.0 - prog->share, err);
}

static int voxelize_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                           vx_err *err)
{
    const vparams p = *(const vparams *)params;
    const vx_limits *lim = vx_run_limits(r);
    vx_grid grid;
    if (grid_of(&p, mesh, lim, &grid, err)) return -1;
    vx_voxelize_desc d;
    desc_of(&p, mesh, lim, &grid, &d);
    vprog prog = {r, encode_share(&p)};
    d.progress = engine_progress;
    d.ud = &prog;

    vstate *s = calloc(1, sizeof *s);
    if (!s) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job state");
    *state = s; /* from here on the runner frees it through free_state */
    s->inside = d.inside;
    const int S = brick_size_of(&p, d.grid.dims, lim);
    if (S && vx_run_children(r)) return bricks_from_children(r, mesh, &p, &d, S, &prog, s, err);
    if (S) return run_bricks(r, mesh, &p, &d, S, &prog, s, err);
    if (vx_voxelize(vx_run_gl(r), mesh, &d, &s->grid, &s->st, err)) return -1;
    s->have_grid = 1;
    if (vx_run_progress(r, 1.0 - prog.share, err)) return -1;

    cJSON *stats = vx_run_stats(r);
    stats_grid(stats, &s->grid.grid, mesh, s->st.method, s->inside, s->st.voxels_inside);
    stats_engine(stats, &s->st);
    return 0;
}

/* Merges the brick files into the job's .vdb (their memory checked as the
 * tree grows) and removes them; or writes the manifest that lists them. */
static int encode_bricks(vx_job_run *r, const vparams *p, vstate *s, vprog *prog, vx_err *err)
{
    const vx_grid corner = corner_of(&s->whole);
    const uint64_t lim = vx_run_limits(r)->max_job_memory;
    if (!p->merge) {
        const char *path = s->out_path;
        cJSON *m = cJSON_CreateObject(), *stats = vx_run_stats(r);
        cJSON *g = cJSON_AddObjectToObject(m, "grid");
        double dims[3] = {s->whole.dims[0], s->whole.dims[1], s->whole.dims[2]};
        double idx[3] = {(double)s->whole.index[0], (double)s->whole.index[1],
                         (double)s->whole.index[2]};
        cJSON_AddItemToObject(g, "origin", array3(s->whole.origin));
        cJSON_AddNumberToObject(g, "voxel_size", s->whole.h);
        cJSON_AddItemToObject(g, "dims", array3(dims));
        cJSON_AddItemToObject(g, "index_offset", array3(idx));
        cJSON_AddNumberToObject(m, "brick_size", s->brick_size);
        cJSON_AddStringToObject(m, "vdb_grid", vdb_grid_names[p->vdb_grid]);
        cJSON *list = cJSON_AddArrayToObject(m, "bricks");
        const cJSON *e = cJSON_GetObjectItemCaseSensitive(stats, "bricks"), *it;
        int b = 0;
        cJSON_ArrayForEach(it, e)
        {
            cJSON *o = cJSON_Duplicate(it, 1);
            const char *slash = strrchr(s->brick_paths[b], '/');
            char name[64], url[160];
            snprintf(name, sizeof name, "%s", slash ? slash + 1 : s->brick_paths[b]);
            char *dot = strrchr(name, '.');
            if (dot) *dot = 0;
            if (s->brick_jobs) {
                /* cluster mode: the output of that name is the brick job's file */
                const cJSON *off = cJSON_GetObjectItemCaseSensitive(it, "offset");
                int q[3];
                for (int a = 0; a < 3; a++)
                    q[a] = (int)cJSON_GetNumberValue(cJSON_GetArrayItem(off, a)) / s->brick_size;
                snprintf(name, sizeof name, "brick_%d_%d_%d", q[0], q[1], q[2]);
            }
            snprintf(url, sizeof url, "/v1/jobs/%s/result/%s", vx_run_job_id(r), name);
            cJSON_AddStringToObject(o, "name", name);
            cJSON_AddStringToObject(o, "url", url);
            if (!cJSON_AddItemToArray(list, o)) cJSON_Delete(o);
            b++;
        }
        char *text = vx_json_print(m, 1);
        cJSON_Delete(m);
        if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        int rc = vx_write_atomic(path, text, strlen(text), err);
        free(text);
        return rc;
    }
    const char *path = s->out_path;
    vx_vdb_merge *m = vx_vdb_merge_new(err);
    if (!m) return -1;
    int rc = 0;
    const int S = s->brick_size;
    const int brick[3] = {S, S, S};
    const vx_vdb_class bcls =
        p->vdb_grid == VX_VDB_LEVEL_SET ? VX_VDB_BOOL : (vx_vdb_class)p->vdb_grid;
    const uint64_t one = vx_voxel_vdb_bytes(brick, bcls, p->supersample == 2);
    for (int b = 0; !rc && b < s->nbricks; b++) {
        rc = vx_run_progress(r, 1.0 - prog->share + prog->share * 0.7 * b / s->nbricks, err);
        if (!rc) rc = vx_vdb_merge_add(m, s->brick_paths[b], err);
        if (!rc && !s->brick_jobs) remove(s->brick_paths[b]); /* the brick jobs' stay theirs */
        if (!rc && lim && vx_vdb_merge_bytes(m) + one > lim)
            rc = vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                            "the merged OpenVDB tree of %d of %d bricks holds %llu bytes, "
                            "near the job memory limit of %llu (vdb_grid \"bool\" needs less)",
                            b + 1, s->nbricks, (unsigned long long)vx_vdb_merge_bytes(m),
                            (unsigned long long)lim);
    }
    if (!rc && p->vdb_grid == VX_VDB_LEVEL_SET && lim &&
        vx_vdb_merge_bytes(m) + vx_vdb_merge_level_set_bytes(m, corner.dims) > lim)
        rc = vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                        "the level set of the merged grid needs about %llu bytes, over the job "
                        "memory limit of %llu (vdb_grid \"fog\" or \"bool\" needs less)",
                        (unsigned long long)(vx_vdb_merge_bytes(m) +
                                             vx_vdb_merge_level_set_bytes(m, corner.dims)),
                        (unsigned long long)lim);
    if (!rc) {
        stat_set(vx_run_stats(r), "merged_tree_bytes",
                 cJSON_CreateNumber((double)vx_vdb_merge_bytes(m)));
        const char *method = NULL;
        const cJSON *mt = cJSON_GetObjectItemCaseSensitive(vx_run_stats(r), "method");
        if (cJSON_IsString(mt)) method = mt->valuestring;
        vx_vdb_meta meta = meta_of(p, r, method, s->inside);
        vprog tail = {r, prog->share * 0.3};
        vx_voxel_io io = {.progress = encode_progress, .ud = &tail};
        rc = vx_vdb_merge_write(m, (vx_vdb_class)p->vdb_grid, &corner, &meta, path, &io, err);
    }
    vx_vdb_merge_free(m);
    return rc;
}

static int voxelize_encode(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    vstate *s = state;
    const vparams p = *(const vparams *)params;
    double t0 = vx_mono();
    vprog prog = {r, encode_share(&p)};
    if (s->brick_paths) {
        if (encode_bricks(r, &p, s, &prog, err)) return -1;
        stat_set(vx_run_stats(r), "encode_ms", cJSON_CreateNumber((vx_mono() - t0) * 1e3));
        return vx_run_progress(r, 1.0, err);
    }
    /* The writers place voxel (0,0,0) at grid.origin: a brick's own corner,
     * origin + index_offset * h; with vdb_index_base B the file's index 0 is
     * lattice voxel B (corner origin + B h) and the box goes to
     * index_offset - B. */
    int at[3] = {0, 0, 0};
    if (p.vdb_index_base_set)
        for (int a = 0; a < 3; a++) {
            at[a] = (int)(s->grid.grid.index[a] - p.vdb_index_base[a]);
            s->grid.grid.index[a] = p.vdb_index_base[a];
        }
    s->grid.grid = corner_of(&s->grid.grid);
    vx_voxel_io io = {.progress = encode_progress, .ud = &prog};
    int rc = 0;
    const char *path = NULL;
    switch ((vformat)p.format) {
    case F_SUMMARY:
        break;
    case F_RAW8:
    case F_RAW1:
        path = vx_run_output(r, "voxels", "raw", "application/octet-stream", err);
        if (!path) return -1;
        rc = p.format == F_RAW8 ? vx_voxel_write_raw8(&s->grid, path, &io, err)
                                : vx_voxel_write_raw1(&s->grid, path, &io, err);
        break;
    case F_BINVOX:
        path = vx_run_output(r, "voxels", "binvox", "application/x-binvox", err);
        if (!path) return -1;
        rc = vx_voxel_write_binvox(&s->grid, path, &io, err);
        break;
    case F_VOX:
    case F_NRRD:
    case F_NPY: {
        static const char *const ext[] = {"vox", "nrrd", "npy"};
        const int f = (int)p.format - F_VOX;
        path = vx_run_output(r, "voxels", ext[f], "application/octet-stream", err);
        if (!path) return -1;
        rc = f == 0   ? vx_voxel_write_vox(&s->grid, path, &io, err)
             : f == 1 ? vx_voxel_write_nrrd(&s->grid, path, &io, err)
                      : vx_voxel_write_npy(&s->grid, path, &io, err);
        break;
    }
    case F_VDB: {
        path = vx_run_output(r, "voxels", "vdb", "application/x-openvdb", err);
        if (!path) return -1;
        vx_vdb_meta m = meta_of(&p, r, s->st.method, s->inside);
        /* A level set's band is known only now: within the limit? (The
         * other classes' worst case was counted at submission.) */
        uint64_t lim = vx_run_limits(r)->max_job_memory;
        uint64_t voxels = vx_bitgrid_bytes(s->grid.grid.dims, s->grid.counts ? 2 : 1);
        int band = p.vdb_grid == VX_VDB_LEVEL_SET;
        uint64_t need =
            lim && band ? vx_voxel_vdb_grid_bytes(&s->grid, (vx_vdb_class)p.vdb_grid) : 0;
        if (lim && band && need + voxels > lim)
            return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                              "the OpenVDB grid of these voxels needs about %llu bytes, over the "
                              "job memory limit of %llu (vdb_grid \"bool\" or another format "
                              "needs less)",
                              (unsigned long long)need, (unsigned long long)lim);
        io.vdb_keep = &s->vdb_tree;
        rc = p.vdb_index_base_set
                 ? vx_voxel_write_vdb_at(&s->grid, at, (vx_vdb_class)p.vdb_grid, &m, path, &io, err)
                 : vx_voxel_write_vdb(&s->grid, (vx_vdb_class)p.vdb_grid, &m, path, &io, err);
        break;
    }
    }
    if (rc) return -1;
    stat_set(vx_run_stats(r), "encode_ms", cJSON_CreateNumber((vx_mono() - t0) * 1e3));
    return vx_run_progress(r, 1.0, err);
}

static void voxelize_free_state(void *state)
{
    vstate *s = state;
    if (!s) return;
    vx_vdb_tree_free(s->vdb_tree);
    vx_bitgrid_free(&s->grid);
    for (int b = 0; b < s->nbricks; b++) {
        /* a failed merge's (the brick jobs' files stay theirs) */
        if (s->merge && s->brick_paths && s->brick_paths[b] && !s->brick_jobs)
            remove(s->brick_paths[b]);
        if (s->brick_paths) free(s->brick_paths[b]);
    }
    free(s->brick_paths);
    free(s->out_path);
    free(s);
}

const vx_kind vx_kind_voxelize = {
    .name = "voxelize",
    .summary = "Solid voxelization (depth peeling, slicing or crossing counts on the GPU, or "
               "crossing counts and winding numbers on the CPU) to OpenVDB, binvox, raw bytes, "
               "MagicaVoxel .vox, NRRD or NumPy .npy",
    .spec = spec,
    .params_size = sizeof(vparams),
    .check = voxelize_check,
    .check_mesh = voxelize_check_mesh,
    .run_gl = voxelize_run_gl,
    .run_cpu = NULL,
    .encode = voxelize_encode,
    .free_state = voxelize_free_state,
    .split = voxelize_split,
};
