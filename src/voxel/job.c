/* The `voxelize` row of the job table (kind.h; api/openapi.yaml has the
 * params and stats schemas). The params are declared once, in spec (spec.h);
 * voxelize_check keeps the rules across fields and the grid limits. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/fsutil.h"
#include "voxel/io.h"
#include "voxel/job.h"
#include "voxel/voxel.h"

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

static const char *const method_names[] = {"auto", "peel", "slice", "scan", NULL};
static const char *const inside_names[] = {"nonzero", "parity", "robust", "winding",
                                           NULL}; /* vx_inside order */
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
} vparams;

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

#define SET(f) .set_off = offsetof(vparams, f##_set)
static const char *const not_vs[] = {"voxel_size", NULL}, *const not_res_vs[] = {
                                                              "resolution", "voxel_size", NULL};
static const vx_pspec spec[] = {
    VX_P_INT(vparams, resolution, 256, 1, 2048, "voxels along the longest bbox side",
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
    VX_P_ENUM(vparams, inside, inside_names, 0, "inside rule", .flags = VX_PF_NULLABLE,
              SET(inside)),
    VX_P_ENUM(vparams, fill, fill_names, 0, "solid or surface shell"),
    VX_P_INT(vparams, supersample, 1, 1, 2, "samples per voxel edge"),
    VX_P_ENUM(vparams, samples, samples_names, 0, "the sample pattern of supersample 2"),
    VX_P_INT(vparams, threshold, 4, 1, 8, "inside samples that make a voxel inside"),
    VX_P_ENUM(vparams, format, format_names, 0, "output format"),
    VX_P_ENUM(vparams, vdb_grid, vdb_grid_names, 1, "the grid a vdb output holds"),
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
} vstate;

/* Memory one job needs for a grid: the bit grid (and sample counts), the
 * GPU's copy of it plus float render targets the size of the largest grid
 * face (per sample), and the writer's own buffers (OpenVDB's tree; the
 * other writers stream a row at a time). An estimate, but an upper one. */
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
    if (n > VX_VOXELIZE_MAX_VOXELS)
        return vx_err_set(err, kind, code, "%s gives %dx%dx%d = %llu voxels, the limit is 2048^3",
                          what, dims[0], dims[1], dims[2], (unsigned long long)n);
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
    }
    /* Slicing fills solids only; auto slices whenever it supersamples
     * (cube pattern). Refused here, not when the job runs (issue 14). */
    if (fill_of(p) == VX_FILL_SURFACE && p->method == VX_METHOD_SLICE)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.fill \"surface\" needs params.method peel or auto (slice fills "
                          "solids only)");
    if (fill_of(p) == VX_FILL_SURFACE && p->method == VX_METHOD_AUTO && p->supersample == 2)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.fill \"surface\" cannot be supersampled: with "
                          "params.supersample 2, auto runs slice, which fills solids only");
    if (p->grid_set) {
        if (p->padding)
            return vx_err_set(
                err, VX_EUNPROC, "invalid_params",
                "params.padding is not allowed with params.grid (make the box larger)");
        int dims[3] = {(int)p->grid.dims[0], (int)p->grid.dims[1], (int)p->grid.dims[2]};
        return check_grid(dims, p, lim, "params.grid", VX_EUNPROC, err);
    }
    if (p->voxel_size_set) return 0; /* the dims depend on the mesh: checked in run_gl */
    p->resolution_set = 1;           /* the default */
    /* The dims depend on the mesh's bbox; check the largest grid the
     * resolution can give (a cubic bbox), so that a job never fails for a
     * limit its params already broke. */
    int n = (int)(p->resolution + 2 * p->padding), cube[3] = {n, n, n};
    return check_grid(cube, p, lim, "params.resolution (checked as a cube)", VX_EUNPROC, err);
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

static int voxelize_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                           vx_err *err)
{
    const vparams p = *(const vparams *)params;
    const vx_limits *lim = vx_run_limits(r);
    vx_voxelize_desc d = {0};
    if (p.grid_set) {
        d.grid.h = p.grid.voxel_size;
        for (int a = 0; a < 3; a++) {
            d.grid.origin[a] = p.grid.origin[a];
            d.grid.dims[a] = (int)p.grid.dims[a];
            d.grid.index[a] = p.grid.index_offset[a];
        }
    } else {
        int rc =
            p.resolution_set
                ? vx_grid_from_resolution(mesh, (int)p.resolution, (int)p.padding, &d.grid, err)
                : vx_grid_from_voxel_size(mesh, p.voxel_size, (int)p.padding, &d.grid, err);
        if (rc) return -1;
        if (check_grid(d.grid.dims, &p, lim,
                       p.resolution_set ? "params.resolution" : "params.voxel_size", VX_ETOOBIG,
                       err))
            return -1;
    }
    d.method = (vx_method)p.method; /* the name arrays follow the enums' order */
    d.fill = fill_of(&p);
    d.supersample = (int)p.supersample;
    d.threshold = (int)p.threshold;
    d.samples = (vx_samples)p.samples;
    d.inside = p.inside_set ? inside_of(&p) : vx_voxelize_default_inside(mesh, &d);
    d.max_memory = lim ? lim->max_job_memory : 0;
    vprog prog = {r, encode_share(&p)};
    d.progress = engine_progress;
    d.ud = &prog;
    d.max_slab_rows = vx_voxelize_slab_rows(d.grid.dims);

    vstate *s = calloc(1, sizeof *s);
    if (!s) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job state");
    *state = s; /* from here on the runner frees it through free_state */
    s->inside = d.inside;
    if (vx_voxelize(vx_run_gl(r), mesh, &d, &s->grid, &s->st, err)) return -1;
    s->have_grid = 1;
    if (vx_run_progress(r, 1.0 - prog.share, err)) return -1;

    const vx_grid *g = &s->grid.grid;
    const vx_voxelize_stats *st = &s->st;
    double dims[3] = {g->dims[0], g->dims[1], g->dims[2]};
    cJSON *stats = vx_run_stats(r);
    stat_set(stats, "method", cJSON_CreateString(st->method ? st->method : "unknown"));
    stat_set(stats, "inside", cJSON_CreateString(inside_names[s->inside]));
    stat_set(stats, "boundary_edges", cJSON_CreateNumber((double)mesh->boundary_edges));
    stat_set(stats, "dims", array3(dims));
    stat_set(stats, "origin", array3(g->origin));
    double index[3] = {(double)g->index[0], (double)g->index[1], (double)g->index[2]};
    stat_set(stats, "index_offset", array3(index));
    stat_set(stats, "voxel_size", cJSON_CreateNumber(g->h));
    stat_set(stats, "triangles", cJSON_CreateNumber((double)mesh->ntris));
    stat_set(stats, "voxels_inside", cJSON_CreateNumber((double)st->voxels_inside));
    stat_set(stats, "volume", cJSON_CreateNumber((double)st->voxels_inside * g->h * g->h * g->h));
    stat_set(stats, "layers", cJSON_CreateNumber(st->layers));
    stat_set(stats, "passes", cJSON_CreateNumber(st->passes));
    stat_set(stats, "slices", cJSON_CreateNumber(st->slices));
    stat_set(stats, "chunks", cJSON_CreateNumber(st->chunks));
    stat_set(stats, "upload_ms", cJSON_CreateNumber(st->upload_ms));
    stat_set(stats, "gpu_peel_ms", cJSON_CreateNumber(st->gpu_peel_ms));
    stat_set(stats, "gpu_fill_ms", cJSON_CreateNumber(st->gpu_fill_ms));
    stat_set(stats, "gpu_slice_ms", cJSON_CreateNumber(st->gpu_slice_ms));
    stat_set(stats, "readback_ms", cJSON_CreateNumber(st->readback_ms));
    return 0;
}

static int voxelize_encode(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    vstate *s = state;
    const vparams p = *(const vparams *)params;
    double t0 = vx_mono();
    /* The writers place voxel (0,0,0) at grid.origin: a brick's own corner,
     * origin + index_offset * h (the voxels themselves were decided in the
     * lattice's frame). */
    for (int a = 0; a < 3; a++) {
        s->grid.grid.origin[a] += (double)s->grid.grid.index[a] * s->grid.grid.h;
        s->grid.grid.index[a] = 0;
    }
    vprog prog = {r, encode_share(&p)};
    vx_voxel_io io = {encode_progress, &prog};
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
        vx_vdb_meta m = {
            .method = s->st.method,
            .inside = inside_names[s->inside],
            .fill = fill_names[p.fill],
            .mesh = vx_run_mesh_id(r),
            .supersample = (int)p.supersample,
            .threshold = (int)p.threshold,
            .samples = samples_names[p.samples],
        };
        /* A fog grid's float leaves are known only now: within the limit? */
        uint64_t lim = vx_run_limits(r)->max_job_memory;
        uint64_t need = lim ? vx_voxel_vdb_grid_bytes(&s->grid, (vx_vdb_class)p.vdb_grid) : 0;
        if (lim && need + vx_bitgrid_bytes(s->grid.grid.dims, s->grid.counts ? 2 : 1) > lim)
            return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                              "the OpenVDB grid of these voxels needs about %llu bytes, over the "
                              "job memory limit of %llu (vdb_grid \"bool\" or another format "
                              "needs less)",
                              (unsigned long long)need, (unsigned long long)lim);
        rc = vx_voxel_write_vdb(&s->grid, (vx_vdb_class)p.vdb_grid, &m, path, &io, err);
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
    vx_bitgrid_free(&s->grid);
    free(s);
}

const vx_kind vx_kind_voxelize = {
    .name = "voxelize",
    .summary = "Solid voxelization on the GPU (depth peeling, slicing or crossing counts) to "
               "OpenVDB, binvox or raw bits",
    .spec = spec,
    .params_size = sizeof(vparams),
    .check = voxelize_check,
    .run_gl = voxelize_run_gl,
    .run_cpu = NULL,
    .encode = voxelize_encode,
    .free_state = voxelize_free_state,
};
