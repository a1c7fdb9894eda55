/* The `voxelize` row of the job table (kind.h; api/openapi.yaml has the
 * params and stats schemas). Structure as in preview/job.c: read_params is
 * the one place that knows the fields, used by parse and run_gl. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/fsutil.h"
#include "voxel/io.h"
#include "voxel/job.h"
#include "voxel/voxel.h"

typedef enum grid_mode { GRID_RESOLUTION, GRID_VOXEL_SIZE, GRID_BOX } grid_mode;
typedef enum vformat { F_VDB = 0, F_BINVOX, F_RAW8, F_RAW1, F_SUMMARY } vformat;

static const char *const method_names[] = {"auto", "peel", "slice", "scan", NULL};
static const char *const inside_names[] = {"nonzero", "parity", "robust", NULL};
static const char *const fill_names[] = {"solid", "surface", NULL};
static const char *const samples_names[] = {"cube", "faces", NULL}; /* vx_samples order */
static const char *const format_names[] = {"vdb", "binvox", "raw8", "raw1", "summary", NULL};

typedef struct vparams {
    grid_mode mode;
    long resolution;
    double voxel_size;
    vx_grid box; /* GRID_BOX */
    long padding;
    vx_method method;
    vx_inside inside;
    vx_fill fill;
    int supersample, threshold;
    vx_samples samples;
    vformat format;
} vparams;

typedef struct vstate {
    vx_bitgrid grid;
    vx_voxelize_stats st;
    int have_grid;
} vstate;

static const char *const known[] = {"resolution", "voxel_size", "grid",   "padding",
                                    "method",     "inside",     "fill",   "supersample",
                                    "samples",    "threshold",  "format", NULL};

static const cJSON *field(const cJSON *params, const char *name)
{
    const cJSON *it = params ? cJSON_GetObjectItemCaseSensitive(params, name) : NULL;
    return it && !cJSON_IsNull(it) ? it : NULL;
}

/* params.grid: {"origin": [x,y,z], "voxel_size": h, "dims": [nx,ny,nz]}. */
static int read_box(const cJSON *g, vx_grid *box, vx_err *err)
{
    static const char *const box_known[] = {"origin", "voxel_size", "dims", NULL};
    if (!cJSON_IsObject(g))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.grid must be an object {origin, voxel_size, dims}");
    const cJSON *it;
    cJSON_ArrayForEach(it, g)
    {
        int ok = 0;
        for (int i = 0; box_known[i]; i++)
            ok |= strcmp(box_known[i], it->string) == 0;
        if (!ok)
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown parameter params.grid.%s",
                              it->string);
    }
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(g, "origin");
    const cJSON *h = cJSON_GetObjectItemCaseSensitive(g, "voxel_size");
    const cJSON *d = cJSON_GetObjectItemCaseSensitive(g, "dims");
    if (!cJSON_IsArray(o) || cJSON_GetArraySize(o) != 3)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.grid.origin must be an array of 3 numbers");
    if (!cJSON_IsArray(d) || cJSON_GetArraySize(d) != 3)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.grid.dims must be an array of 3 integers");
    if (!cJSON_IsNumber(h) || !isfinite(h->valuedouble) || !(h->valuedouble > 0))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.grid.voxel_size must be a number > 0");
    box->h = h->valuedouble;
    for (int a = 0; a < 3; a++) {
        const cJSON *x = cJSON_GetArrayItem(o, a), *n = cJSON_GetArrayItem(d, a);
        if (!cJSON_IsNumber(x) || !isfinite(x->valuedouble))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.grid.origin[%d] must be a number", a);
        if (!cJSON_IsNumber(n) || n->valuedouble != floor(n->valuedouble) || n->valuedouble < 1 ||
            n->valuedouble > VX_VOXELIZE_MAX_DIM)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.grid.dims[%d] must be an integer in [1, %d]", a,
                              VX_VOXELIZE_MAX_DIM);
        box->origin[a] = x->valuedouble;
        box->dims[a] = (int)n->valuedouble;
    }
    return 0;
}

/* Memory one job needs for a grid: the bit grid (and sample counts), the
 * GPU's copy of it plus float render targets the size of the largest grid
 * face (per sample), and the writer's own buffers (OpenVDB's tree; the
 * other writers stream a row at a time). An estimate, but an upper one. */
static uint64_t job_bytes(const int dims[3], int ss, vx_samples samples, vformat format)
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
    uint64_t enc = format == F_VDB ? vx_voxel_vdb_bytes(dims, coverage) : 0;
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
    uint64_t bytes = job_bytes(dims, p->supersample, p->samples, p->format);
    if (lim && lim->max_job_memory && bytes > lim->max_job_memory)
        return vx_err_set(
            err, kind, code,
            "%s: a %dx%dx%d grid needs about %llu bytes, over the job memory limit of %llu "
            "(job_memory_limit)",
            what, dims[0], dims[1], dims[2], (unsigned long long)bytes,
            (unsigned long long)lim->max_job_memory);
    return 0;
}

/* Reads and validates params into p; the one place that knows the fields,
 * their ranges and defaults (parse and run_gl both use it). */
static int read_params(const cJSON *params, const vx_limits *lim, vparams *p, vx_err *err)
{
    memset(p, 0, sizeof *p);
    if (vx_param_object(&params, known, err)) return -1;
    const cJSON *res = field(params, "resolution"), *vs = field(params, "voxel_size"),
                *box = field(params, "grid");
    if (res && vs)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.resolution and params.voxel_size exclude each other");
    if (box && (res || vs))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.grid excludes params.%s",
                          res ? "resolution" : "voxel_size");
    int method, inside, fill, format, samples;
    long ss, thr;
    if (vx_param_int(params, "resolution", 256, 1, 2048, &p->resolution, err) ||
        vx_param_number(params, "voxel_size", 1, 0, HUGE_VAL, &p->voxel_size, err) ||
        vx_param_int(params, "padding", 0, 0, 1024, &p->padding, err) ||
        vx_param_enum(params, "method", method_names, 0, &method, err) ||
        vx_param_enum(params, "inside", inside_names, 0, &inside, err) ||
        vx_param_enum(params, "fill", fill_names, 0, &fill, err) ||
        vx_param_int(params, "supersample", 1, 1, 2, &ss, err) ||
        vx_param_enum(params, "samples", samples_names, 0, &samples, err) ||
        vx_param_int(params, "threshold", 4, 1, 8, &thr, err) ||
        vx_param_enum(params, "format", format_names, 0, &format, err))
        return -1;
    if (vs && !(p->voxel_size > 0))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.voxel_size must be > 0");
    /* the name arrays follow the enums' order */
    p->method = (vx_method)method; /* auto, peel, slice, scan */
    p->inside = inside == 1 ? VX_INSIDE_PARITY : inside == 2 ? VX_INSIDE_ROBUST : VX_INSIDE_NONZERO;
    p->fill = fill == 1 ? VX_FILL_SURFACE : VX_FILL_SOLID;
    p->supersample = (int)ss;
    p->threshold = (int)thr;
    p->samples = (vx_samples)samples;
    p->format = (vformat)format;
    if (p->samples == VX_SAMPLES_FACES) {
        if (p->supersample != 2)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.samples \"faces\" needs params.supersample 2");
        if (p->threshold > 7)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.threshold must be 1..7 with params.samples \"faces\" (7 "
                              "samples per voxel), got %d",
                              p->threshold);
        if (p->fill != VX_FILL_SOLID)
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
    if (box) {
        if (p->padding)
            return vx_err_set(
                err, VX_EUNPROC, "invalid_params",
                "params.padding is not allowed with params.grid (make the box larger)");
        p->mode = GRID_BOX;
        if (read_box(box, &p->box, err)) return -1;
        return check_grid(p->box.dims, p, lim, "params.grid", VX_EUNPROC, err);
    }
    if (vs) {
        p->mode = GRID_VOXEL_SIZE;
        return 0; /* the dims depend on the mesh: checked in run_gl */
    }
    p->mode = GRID_RESOLUTION;
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

static cJSON *voxelize_parse(const cJSON *params, const vx_limits *lim, vx_err *err)
{
    vparams p;
    if (read_params(params, lim, &p, err)) return NULL;
    cJSON *o = cJSON_CreateObject();
    int ok = o != NULL;
    if (ok && p.mode == GRID_RESOLUTION)
        ok = cJSON_AddNumberToObject(o, "resolution", (double)p.resolution) != NULL;
    else if (ok)
        ok = cJSON_AddNullToObject(o, "resolution") != NULL;
    if (ok && p.mode == GRID_VOXEL_SIZE)
        ok = cJSON_AddNumberToObject(o, "voxel_size", p.voxel_size) != NULL;
    else if (ok)
        ok = cJSON_AddNullToObject(o, "voxel_size") != NULL;
    if (ok && p.mode == GRID_BOX) {
        cJSON *g = cJSON_AddObjectToObject(o, "grid");
        double dims[3] = {p.box.dims[0], p.box.dims[1], p.box.dims[2]};
        cJSON * or = array3(p.box.origin), *di = array3(dims);
        ok = g && or &&di && cJSON_AddItemToObject(g, "origin", or);
        if (!ok) cJSON_Delete(or);
        ok = ok && cJSON_AddNumberToObject(g, "voxel_size", p.box.h) &&
             cJSON_AddItemToObject(g, "dims", di);
        if (!ok) cJSON_Delete(di);
    } else if (ok) {
        ok = cJSON_AddNullToObject(o, "grid") != NULL;
    }
    ok = ok && cJSON_AddNumberToObject(o, "padding", (double)p.padding) &&
         cJSON_AddStringToObject(o, "method", method_names[p.method]) &&
         cJSON_AddStringToObject(o, "inside",
                                 inside_names[p.inside == VX_INSIDE_PARITY   ? 1
                                              : p.inside == VX_INSIDE_ROBUST ? 2
                                                                             : 0]) &&
         cJSON_AddStringToObject(o, "fill", fill_names[p.fill == VX_FILL_SURFACE ? 1 : 0]) &&
         cJSON_AddNumberToObject(o, "supersample", p.supersample) &&
         cJSON_AddStringToObject(o, "samples", samples_names[p.samples]) &&
         cJSON_AddNumberToObject(o, "threshold", p.threshold) &&
         cJSON_AddStringToObject(o, "format", format_names[p.format]);
    if (!ok) {
        cJSON_Delete(o);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for voxelize params");
        return NULL;
    }
    return o;
}

/* The engine's 0..1 becomes the job's 0..0.9; encoding has the rest. */
static int engine_progress(void *ud, double fraction, vx_err *err)
{
    return vx_run_progress(ud, 0.9 * fraction, err);
}

static int encode_progress(void *ud, double fraction, vx_err *err)
{
    return vx_run_progress(ud, 0.9 + 0.1 * fraction, err);
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

static int voxelize_run_gl(vx_job_run *r, const vx_mesh *mesh, const cJSON *params, void **state,
                           vx_err *err)
{
    vparams p;
    const vx_limits *lim = vx_run_limits(r);
    if (read_params(params, lim, &p, err)) return -1;
    vx_voxelize_desc d = {0};
    if (p.mode == GRID_BOX) {
        d.grid = p.box;
    } else {
        int rc =
            p.mode == GRID_RESOLUTION
                ? vx_grid_from_resolution(mesh, (int)p.resolution, (int)p.padding, &d.grid, err)
                : vx_grid_from_voxel_size(mesh, p.voxel_size, (int)p.padding, &d.grid, err);
        if (rc) return -1;
        if (check_grid(d.grid.dims, &p, lim,
                       p.mode == GRID_RESOLUTION ? "params.resolution" : "params.voxel_size",
                       VX_ETOOBIG, err))
            return -1;
    }
    d.method = p.method;
    d.inside = p.inside;
    d.fill = p.fill;
    d.supersample = p.supersample;
    d.threshold = p.threshold;
    d.samples = p.samples;
    d.max_memory = lim ? lim->max_job_memory : 0;
    d.progress = engine_progress;
    d.ud = r;
    d.max_slab_rows = vx_voxelize_slab_rows(d.grid.dims);

    vstate *s = calloc(1, sizeof *s);
    if (!s) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job state");
    *state = s; /* from here on the runner frees it through free_state */
    if (vx_voxelize(vx_run_gl(r), mesh, &d, &s->grid, &s->st, err)) return -1;
    s->have_grid = 1;
    if (vx_run_progress(r, 0.9, err)) return -1;

    const vx_grid *g = &s->grid.grid;
    const vx_voxelize_stats *st = &s->st;
    double dims[3] = {g->dims[0], g->dims[1], g->dims[2]};
    cJSON *stats = vx_run_stats(r);
    stat_set(stats, "method", cJSON_CreateString(st->method ? st->method : "unknown"));
    stat_set(stats, "dims", array3(dims));
    stat_set(stats, "origin", array3(g->origin));
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

static int voxelize_encode(vx_job_run *r, const cJSON *params, void *state, vx_err *err)
{
    vstate *s = state;
    vparams p;
    if (read_params(params, NULL, &p, err)) return -1;
    double t0 = vx_mono();
    vx_voxel_io io = {encode_progress, r};
    int rc = 0;
    const char *path = NULL;
    switch (p.format) {
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
    case F_VDB: {
        path = vx_run_output(r, "voxels", "vdb", "application/x-openvdb", err);
        if (!path) return -1;
        vx_vdb_meta m = {
            .method = s->st.method,
            .inside = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(params, "inside")),
            .fill = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(params, "fill")),
            .mesh = vx_run_mesh_id(r),
            .supersample = p.supersample,
            .threshold = p.threshold,
            .samples = samples_names[p.samples],
        };
        rc = vx_voxel_write_vdb(&s->grid, p.supersample == 2, &m, path, &io, err);
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
    .parse = voxelize_parse,
    .run_gl = voxelize_run_gl,
    .run_cpu = NULL,
    .encode = voxelize_encode,
    .free_state = voxelize_free_state,
};
