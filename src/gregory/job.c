/* The `gregory` job kind (job.h): polygon or Bézier mesh -> Gregory patches
 * (build.c) -> GPU tessellation (tess.c) of frame 0 and of every deformation
 * frame, reusing the topology tables (interpolate) or OpenSubdiv's plan
 * (approximate-cc, osd.h) and the output layout -> OBJ / PLY / Draco per
 * frame. */
#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <time.h>
#include <unistd.h>

#include "gregory/job.h"
#include "gregory/osd.h"
#include "gregory/tess.h"
#include "mesh/intake.h"
#include "store/store.h"
#include "util/fsutil.h"
#include "util/child.h"
#include "util/stop.h"

enum { CONS_INTERPOLATE = 0, CONS_APPROX_CC };
enum { FMT_OBJ = 0, FMT_PLY, FMT_DRC, FMT_GLB };
static const char *const cons_names[] = {"interpolate", "approximate-cc", NULL};
static const char *const fmt_names[] = {"obj", "ply", "drc", "glb", NULL};
static const char *const fmt_types[] = {"model/obj", "model/x-ply", "model/x-draco",
                                        "model/gltf-binary"};

#define DEFAULT_DIVISIONS 8
/* approximate-cc's distance to the limit surface: samples per patch side,
 * and the largest patch set it is measured on (OpenSubdiv's isolation-6
 * reference grows with every extraordinary vertex). */
#define CC_DISTANCE_SAMPLES 5
#define CC_DISTANCE_MAX_PATCHES 20000
/* How often the encoder (and the distance) check the time limit while a
 * child process works. */
#define ENCODE_POLL_MS 20

/* params.frames: further frames as mesh ids or as positions. */
typedef struct gframes {
    int n;   /* frames after frame 0 */
    int ids; /* id[] holds them, else pos[] */
    long nv; /* vertices per frame (positions) */
    char (*id)[VX_MESH_ID_SIZE];
    double *pos; /* n * nv * 3 */
} gframes;

typedef struct gparams {
    long divisions;  /* used when max_edge is not */
    double max_edge; /* used when set */
    int divisions_set, max_edge_set, frames_set;
    int construction, weld, format;
    gframes frames;
} gparams;

/* One frame given as positions: [x0, y0, z0, x1, ...] or [[x, y, z], ...].
 * Returns the number of vertices it holds, or -1 with err. */
static long frame_count(const cJSON *f, size_t index, vx_err *err)
{
    long n = 0;
    int nested = -1;
    const cJSON *e;
    cJSON_ArrayForEach(e, f)
    {
        /* positions are tessellated in floats: within what meshes may hold */
        int is_num = cJSON_IsNumber(e) && fabs(e->valuedouble) <= VX_MESH_COORD_MAX;
        int is_triple = cJSON_IsArray(e) && cJSON_GetArraySize(e) == 3;
        if (is_triple)
            for (int c = 0; c < 3; c++) {
                const cJSON *x = cJSON_GetArrayItem(e, c);
                is_triple &= cJSON_IsNumber(x) && fabs(x->valuedouble) <= VX_MESH_COORD_MAX;
            }
        if (nested < 0) nested = is_triple;
        if (nested ? !is_triple : !is_num)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.frames[%zu][%ld] must be a number within +-%g (flat x, y, "
                              "z list) or an [x, y, z] array of them, the same form throughout",
                              index, n, VX_MESH_COORD_MAX);
        n++;
    }
    if (nested) return n;
    if (n % 3)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.frames[%zu] has %ld numbers, not a multiple of 3", index, n);
    return n / 3;
}

static void frames_free(void *field)
{
    gframes *g = field;
    free(g->id);
    free(g->pos);
    g->id = NULL;
    g->pos = NULL;
}

/* The positions of frame f (its JSON array) into out (3 * nv). */
static void frame_read(const cJSON *f, double *out)
{
    size_t i = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, f)
    {
        if (cJSON_IsArray(e))
            for (int c = 0; c < 3; c++)
                out[i++] = cJSON_GetArrayItem(e, c)->valuedouble;
        else
            out[i++] = e->valuedouble;
    }
}

static int frames_read(const cJSON *fr, void *field, const char *path, vx_err *err)
{
    gframes *g = field;
    if (!cJSON_IsArray(fr) || cJSON_GetArraySize(fr) > VX_GREGORY_MAX_FRAMES)
        return vx_err_set(
            err, VX_EUNPROC, "invalid_params",
            "params.frames must be an array of at most %d position arrays or mesh ids",
            VX_GREGORY_MAX_FRAMES);
    int n = cJSON_GetArraySize(fr);
    const cJSON *first = cJSON_GetArrayItem(fr, 0), *f;
    g->ids = first && cJSON_IsString(first);
    size_t i = 0;
    if (g->ids) {
        if (!(g->id = calloc((size_t)n, sizeof *g->id)))
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the frames");
        cJSON_ArrayForEach(f, fr)
        {
            if (!cJSON_IsString(f) || !vx_store_valid_mesh_id(f->valuestring))
                return vx_err_set(err, VX_EUNPROC, "invalid_params",
                                  "params.frames[%zu] is not a mesh id (64 lowercase hex digits)",
                                  i);
            snprintf(g->id[i++], VX_MESH_ID_SIZE, "%s", f->valuestring);
        }
        g->n = n;
        return 0;
    }
    long n0 = -1;
    cJSON_ArrayForEach(f, fr)
    {
        if (!cJSON_IsArray(f))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.frames[%zu] must be an array of positions (or every "
                              "entry a mesh id)",
                              i);
        long nv = frame_count(f, i, err);
        if (nv < 0) return -1;
        if (n0 >= 0 && nv != n0)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.frames[%zu] has %ld vertices, frames[0] %ld", i, nv, n0);
        n0 = nv;
        i++;
    }
    g->nv = n0 < 0 ? 0 : n0;
    if (!(g->pos = malloc((size_t)n * (size_t)g->nv * 3 * sizeof *g->pos + 1)))
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the frames");
    i = 0;
    cJSON_ArrayForEach(f, fr)
    {
        frame_read(f, g->pos + i * (size_t)g->nv * 3);
        i++;
    }
    g->n = n;
    return 0;
}

/* Frame f, normalised flat (x0, y0, z0, x1, ...) however it was given:
 * the same positions are the same request for reuse and Idempotency-Key. */
static cJSON *frame_json(const gframes *g, int f)
{
    return cJSON_CreateDoubleArray(g->pos + (size_t)f * (size_t)g->nv * 3, (int)(3 * g->nv));
}

static cJSON *frames_write(const void *field)
{
    const gframes *g = field;
    cJSON *a = cJSON_CreateArray();
    for (int f = 0; a && f < g->n; f++) {
        cJSON *e = g->ids ? cJSON_CreateString(g->id[f]) : frame_json(g, f);
        if (!e || !cJSON_AddItemToArray(a, e)) {
            cJSON_Delete(e);
            cJSON_Delete(a);
            return NULL;
        }
    }
    return a;
}

static const vx_pcustom frames_type = {
    frames_read, frames_write, frames_free,
    "{\"type\": \"array\", \"maxItems\": 256, \"nullable\": true}"};

#define SET(f) .set_off = offsetof(gparams, f##_set)
static const char *const not_max_edge[] = {"max_edge", NULL};
static const vx_pspec spec[] = {
    VX_P_INT(gparams, divisions, DEFAULT_DIVISIONS, 1, VX_GREGORY_MAX_DIVISIONS,
             "uniform divisions per patch side", .flags = VX_PF_NULLABLE, SET(divisions),
             .excludes = not_max_edge),
    VX_P_NUM(gparams, max_edge, 0, 0, 1e300, "adaptive: the longest tessellated edge",
             .flags = VX_PF_NULLABLE | VX_PF_GT_LO, SET(max_edge)),
    VX_P_ENUM(gparams, construction, cons_names, CONS_INTERPOLATE, "how patches are made"),
    VX_P_BOOL(gparams, weld, 1, "weld the patches' shared edges"),
    VX_P_ENUM(gparams, format, fmt_names, FMT_OBJ, "output mesh format"),
    {.name = "frames",
     .type = VX_PT_CUSTOM,
     .off = offsetof(gparams, frames),
     .custom = &frames_type,
     .flags = VX_PF_NULLABLE,
     SET(frames),
     .doc = "deformation frames: mesh ids, or position arrays"},
    VX_P_END,
};
#undef SET

static int greg_check(void *params, const vx_limits *lim, vx_err *err)
{
    gparams *p = params;
    /* no further frames is the default: [] normalises to null, so that a
     * request with [] and one without are the same (reuse, idempotency) */
    if (p->frames.n == 0) p->frames_set = 0;
    if (p->max_edge_set) return 0;
    p->divisions_set = 1; /* given or the default */
    /* Known at submission: the smallest mesh has one patch. */
    if (lim && lim->max_triangles &&
        2 * (uint64_t)p->divisions * (uint64_t)p->divisions > lim->max_triangles)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.divisions = %ld makes %llu triangles per patch, over the limit "
                          "of %llu",
                          p->divisions, 2ull * p->divisions * p->divisions,
                          (unsigned long long)lim->max_triangles);
    return 0;
}

static size_t greg_mesh_refs(const cJSON *params, const char **ids, size_t max)
{
    const cJSON *fr = cJSON_GetObjectItemCaseSensitive(params, "frames");
    const cJSON *first = cJSON_IsArray(fr) ? cJSON_GetArrayItem(fr, 0) : NULL;
    if (!first || !cJSON_IsString(first)) return 0; /* positions, or their blob */
    size_t n = 0;
    const cJSON *e;
    cJSON_ArrayForEach(e, fr)
    {
        if (!cJSON_IsString(e)) continue;
        if (n < max) ids[n] = e->valuestring;
        n++;
    }
    return n;
}

typedef struct greg_state {
    vx_gtess_layout *layout;
    size_t nframes;
    double **pos; /* per frame: 3 * layout->nverts */
    float **nrm;
} greg_state;

static void greg_free_state(void *state)
{
    greg_state *s = state;
    if (!s) return;
    for (size_t f = 0; f < s->nframes; f++) {
        if (s->pos) free(s->pos[f]);
        if (s->nrm) free(s->nrm[f]);
    }
    free(s->pos);
    free(s->nrm);
    vx_gregory_layout_free(s->layout);
    free(s);
}

/* The patch set of one frame. The topology tables (topo) are made for the
 * first frame and reused; Bézier input rebuilds its (trivial) set. */
typedef struct builder {
    const vx_mesh *mesh;
    int construction;
    vx_gregory_topo *topo;  /* interpolate */
    vx_gregory_cc_plan *cc; /* approximate-cc */
    vx_gpatch_set *set;
    int fd; /* the child's memfd of every frame's patches (construct_all), or -1 */
} builder;

static int construct(builder *b, const double *pos, vx_err *err)
{
    if (b->mesh->npatches > 0) {
        vx_gpatch_set *s = vx_gregory_from_bezier(b->mesh, pos, err);
        if (!s) return -1;
        vx_gpatch_set_free(b->set);
        b->set = s;
        return 0;
    }
    switch (b->construction) {
    case CONS_APPROX_CC:
        if (!b->cc) {
            b->cc = vx_gregory_cc_plan_new(b->mesh, err);
            if (!b->cc) return -1;
            b->set = vx_gpatch_set_new(vx_gregory_cc_plan_patches(b->cc));
            if (!b->set)
                return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for patches");
        }
        return vx_gregory_cc_plan_eval(b->cc, pos, b->set, err);
    default:
        if (!b->topo) {
            b->topo = vx_gregory_topo_new(b->mesh, err);
            if (!b->topo) return -1;
            b->set = vx_gpatch_set_new(vx_gregory_topo_npatches(b->topo));
            if (!b->set)
                return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for patches");
        }
        vx_gregory_build(b->topo, pos, b->set);
        return 0;
    }
}

/* Reads n bytes at off, 16 MiB at a time with a poll of the stop hook
 * between (-1 with its err, or on a short read without). */
static int read_all(int fd, off_t off, void *p, size_t n, vx_err *err)
{
    char *c = p;
    while (n > 0) {
        if (vx_stop_poll(err)) return -1;
        ssize_t k = pread(fd, c, n < ((size_t)16 << 20) ? n : (size_t)16 << 20, off);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        c += k;
        off += k;
        n -= (size_t)k;
    }
    return 0;
}

/* The patch sets are built in a child process (util/child.h), killed at the
 * time limit: OpenSubdiv's patch table for approximate-cc is one call of
 * seconds on big meshes, and so are the topology tables of interpolate. The
 * child builds the tables once and evaluates every frame with them; the
 * sets come back through a memfd: npatches as the answer, then corner_key
 * and face (the same for every frame), then cp of frame 0, 1, ... */
typedef struct build_work {
    const vx_mesh *mesh;
    int construction, fd;
    size_t nframes;
    const double *const *pos; /* per frame */
    uint64_t max_bytes;       /* the memfd's budget (the job memory limit), 0 = none */
} build_work;

static int build_child(void *ud, void *out, size_t out_size, vx_err *err)
{
    const build_work *w = ud;
    (void)out_size;
    builder b = {.mesh = w->mesh, .construction = w->construction};
    int rc = 0;
    for (size_t k = 0; k < w->nframes && rc == 0; k++) {
        rc = construct(&b, w->pos[k], err);
        if (rc) break;
        const vx_gpatch_set *set = b.set;
        size_t cpb = set->npatches * VX_GPATCH_POINTS * 3 * sizeof *set->cp;
        if (k == 0) {
            *(uint64_t *)out = set->npatches;
            uint64_t bytes = (uint64_t)w->nframes * cpb;
            if (w->max_bytes && bytes > w->max_bytes) {
                rc = vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                                "%zu frames of %zu patches need about %llu bytes of patches, over "
                                "the job memory limit of %llu",
                                w->nframes, set->npatches, (unsigned long long)bytes,
                                (unsigned long long)w->max_bytes);
                break;
            }
            if (vx_write_all(w->fd, set->corner_key, set->npatches * 4 * sizeof *set->corner_key) ||
                vx_write_all(w->fd, set->face, set->npatches * sizeof *set->face))
                rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patch set");
        }
        if (rc == 0 && vx_write_all(w->fd, set->cp, cpb))
            rc = vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patch set");
    }
    vx_gpatch_set_free(b.set);
    vx_gregory_topo_free(b.topo);
    vx_gregory_cc_plan_free(b.cc);
    return rc;
}

static int stop_hook(void *ud, vx_err *err);

/* Frame k's control points from the child's memfd into b->set. */
static int load_frame(builder *b, size_t k, vx_err *err)
{
    vx_gpatch_set *set = b->set;
    size_t cpb = set->npatches * VX_GPATCH_POINTS * 3 * sizeof *set->cp;
    off_t off =
        (off_t)(set->npatches * (4 * sizeof *set->corner_key + sizeof *set->face) + k * cpb);
    if (read_all(b->fd, off, set->cp, cpb, err) == 0) return 0;
    if (!err || err->kind == VX_EOK)
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patch set");
    return -1;
}

/* Builds the patch sets of all nframes frames (positions pos[k]) in a child
 * and loads frame 0's into b->set; b->fd keeps the others for load_frame. */
static int construct_all(vx_job_run *r, builder *b, const double *const *pos, size_t nframes,
                         vx_err *err)
{
    if (b->mesh->npatches > 0) return construct(b, pos[0], err); /* Bézier: trivial */
    int fd = memfd_create("voxeld-gregory", MFD_CLOEXEC);
    if (fd < 0) return construct(b, pos[0], err);
    build_work w = {b->mesh, b->construction, fd, nframes, pos, vx_run_limits(r)->max_job_memory};
    uint64_t np = 0;
    int rc = vx_child_call(build_child, &w, &np, sizeof np, stop_hook, r, ENCODE_POLL_MS, err);
    if (rc == 0) {
        vx_gpatch_set *set = vx_gpatch_set_new((size_t)np);
        size_t keyb = (size_t)np * 4 * sizeof *set->corner_key;
        vx_err_clear(err);
        if (!set || read_all(fd, 0, set->corner_key, keyb, err) ||
            read_all(fd, (off_t)keyb, set->face, (size_t)np * sizeof *set->face, err)) {
            vx_gpatch_set_free(set);
            if (!err || err->kind == VX_EOK)
                vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patch set");
            rc = -1;
        } else {
            b->set = set;
            b->fd = fd;
            rc = load_frame(b, 0, err);
            if (rc == 0) return 0;
        }
    }
    b->fd = -1;
    close(fd);
    return rc;
}

/* Where face f's indices start in m->face_idx (f = nfaces: their count). */
static size_t face_at(const vx_mesh *m, size_t f)
{
    return m->face_start ? (size_t)m->face_start[f] : 3 * f;
}

/* Positions of frame k >= 1: from the params, or a loaded mesh. */
static const double *frame_positions(vx_job_run *r, const vx_mesh *mesh, const gparams *p, size_t k,
                                     vx_mesh **loaded, vx_err *err)
{
    const gframes *g = &p->frames;
    if (g->ids) {
        const char *id = g->id[k - 1];
        vx_mesh *m = vx_run_load_mesh(r, id, err);
        if (!m) return NULL;
        int same =
            m->nverts == mesh->nverts && m->nfaces == mesh->nfaces && m->npatches == mesh->npatches;
        /* the same faces, however each reader stored them (no face_start:
         * every face a triangle; an OFF of triangles has one, an OBJ not) */
        for (size_t f = 0; same && f <= mesh->nfaces; f++)
            same = face_at(m, f) == face_at(mesh, f);
        if (same) {
            size_t nidx = face_at(mesh, mesh->nfaces);
            same = memcmp(m->face_idx, mesh->face_idx, nidx * sizeof *mesh->face_idx) == 0;
        }
        if (same && mesh->npatches)
            same =
                memcmp(m->patch_idx, mesh->patch_idx, 16 * mesh->npatches * sizeof(uint32_t)) == 0;
        if (!same) {
            vx_mesh_free(m);
            vx_err_set(err, VX_EUNPROC, "frame_topology",
                       "frame %zu (mesh %s) does not have the topology of the job's mesh", k, id);
            return NULL;
        }
        *loaded = m;
        return m->pos;
    }
    size_t nv = (size_t)g->nv;
    if (nv != mesh->nverts) {
        vx_err_set(err, VX_EUNPROC, "frame_topology",
                   "params.frames[%zu] has %zu vertices, the mesh %zu", k - 1, nv, mesh->nverts);
        return NULL;
    }
    return g->pos + (k - 1) * nv * 3;
}

/* The positions of every frame into pos[0 .. nframes-1]: the mesh's, the
 * params' and copies of the frame meshes' (held in *copies, one block). */
static int gather_positions(vx_job_run *r, const vx_mesh *mesh, const gparams *p, size_t nframes,
                            const double **pos, double **copies, vx_err *err)
{
    pos[0] = mesh->pos;
    *copies = NULL;
    size_t per = 3 * mesh->nverts;
    if (p->frames.ids) {
        uint64_t bytes = (uint64_t)(nframes - 1) * per * sizeof **copies;
        uint64_t lim = vx_run_limits(r)->max_job_memory;
        if (lim && bytes > lim)
            return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                              "%zu frames of %zu vertices need about %llu bytes, over the job "
                              "memory limit of %llu",
                              nframes, mesh->nverts, (unsigned long long)bytes,
                              (unsigned long long)lim);
        *copies = malloc(bytes + 1);
        if (!*copies) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for frames");
    }
    for (size_t k = 1; k < nframes; k++) {
        vx_mesh *loaded = NULL;
        const double *q = frame_positions(r, mesh, p, k, &loaded, err);
        if (!q) return -1;
        if (loaded) {
            memcpy(*copies + (k - 1) * per, q, per * sizeof *q);
            vx_mesh_free(loaded);
            q = *copies + (k - 1) * per;
        }
        pos[k] = q;
        if (vx_run_progress(r, 0, err)) return -1;
    }
    return 0;
}

typedef struct distance_work {
    const vx_mesh *mesh;
    const vx_gpatch_set *set;
} distance_work;

static int distance_child(void *ud, void *out, size_t out_size, vx_err *err)
{
    const distance_work *w = ud;
    (void)out_size;
    double d = vx_gregory_cc_distance(w->mesh, w->set, CC_DISTANCE_SAMPLES, err);
    *(double *)out = d;
    return d < 0 ? -1 : 0;
}

/* The layout, the tessellation and the gather poll the stop hook: the job's
 * time limit and cancel reach into them. */
static int stop_hook(void *ud, vx_err *err)
{
    return vx_run_progress(ud, 0, err);
}

/* Counts the tessellation and checks it against the triangle and memory
 * limits; *gv gets the grid vertex count. */
static int check_size(const vx_limits *lim, const vx_gpatch_set *set, const uint32_t *ndiv,
                      size_t nframes, uint64_t *gv, vx_err *err)
{
    uint64_t nv, nt;
    if (vx_gregory_count(set, ndiv, gv, &nv, &nt, err)) return -1;
    if (lim->max_triangles && nt > lim->max_triangles) {
        vx_err_set(err, VX_ETOOBIG, "triangle_limit",
                   "%zu patches at these divisions make %llu triangles, over the limit of %llu",
                   set->npatches, (unsigned long long)nt, (unsigned long long)lim->max_triangles);
        return -1;
    }
    /* Grid, per-frame outputs, layout (rep, and share when unwelded: nv
     * counts the unwelded vertices, an upper bound either way). */
    uint64_t bytes = *gv * 6 * sizeof(float) + 2 * nv * sizeof(uint64_t) +
                     (uint64_t)nframes * nv * (3 * sizeof(double) + 3 * sizeof(float)) +
                     nt * 4 * sizeof(uint32_t) + set->npatches * VX_GPATCH_POINTS * 3 * 8;
    if (lim->max_job_memory && bytes > lim->max_job_memory) {
        vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                   "%zu frames of %llu vertices need about %llu bytes, over the job memory limit "
                   "of %llu",
                   nframes, (unsigned long long)nv, (unsigned long long)bytes,
                   (unsigned long long)lim->max_job_memory);
        return -1;
    }
    return 0;
}

/* GPU timings of the frame loop. */
typedef struct tess_times {
    double gpu_ms, first_tess_ms;
} tess_times;

/* The centre of the box of a set's control points: the grid holds floats
 * relative to it, so each frame has its own (a frame far from the mesh, or
 * much smaller, lost its digits against the mesh's centre). */
static void set_centre(const vx_gpatch_set *set, double origin[3])
{
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    const size_t n = set->npatches * VX_GPATCH_POINTS;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            lo[c] = fmin(lo[c], set->cp[3 * i + c]);
            hi[c] = fmax(hi[c], set->cp[3 * i + c]);
        }
    for (int c = 0; c < 3; c++)
        origin[c] = n ? 0.5 * lo[c] + 0.5 * hi[c] : 0;
}

/* Tessellates every frame (positions pos[k]) on the GPU and gathers its
 * positions and normals into s; appends each frame's time to frame_ms when it is not NULL. */
static int tessellate_frames(vx_job_run *r, builder *b, const double *const *pos, greg_state *s,
                             vx_gtess *tess, float *grid, cJSON *frame_ms, tess_times *t,
                             vx_err *err)
{
    size_t nframes = s->nframes;
    for (size_t k = 0; k < nframes; k++) {
        double f0 = vx_mono_ms();
        if (k > 0 && (b->fd >= 0 ? load_frame(b, k, err) : construct(b, pos[k], err))) return -1;
        double origin[3], ms;
        set_centre(b->set, origin);
        if (vx_gtess_run(tess, b->set, origin, grid, &ms, err)) return -1;
        t->gpu_ms += ms;
        if (k == 0) t->first_tess_ms = ms;
        s->pos[k] = malloc((3 * s->layout->nverts + 1) * sizeof **s->pos);
        s->nrm[k] = malloc((3 * s->layout->nverts + 1) * sizeof **s->nrm);
        if (!s->pos[k] || !s->nrm[k]) {
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for frame %zu", k);
            return -1;
        }
        if (vx_gregory_gather(s->layout, grid, origin, s->pos[k], s->nrm[k], err)) return -1;
        if (frame_ms) cJSON_AddItemToArray(frame_ms, cJSON_CreateNumber(vx_mono_ms() - f0));
        if (vx_run_progress(r, 0.9 * (double)(k + 1) / (double)nframes, err)) return -1;
    }
    return 0;
}

/* Adds the gregory stats to the run's stats; takes *frame_ms over (sets it
 * to NULL) when there are stats. */
static void add_stats(vx_job_run *r, const vx_mesh *mesh, const gparams *p, const builder *b,
                      const uint32_t *ndiv, const greg_state *s, uint64_t gv, double build_ms,
                      double cc_distance, const tess_times *t, cJSON **frame_ms)
{
    cJSON *stats = vx_run_stats(r);
    if (!stats) return;
    uint32_t nmin = UINT32_MAX, nmax = 0;
    for (size_t i = 0; i < b->set->npatches; i++) {
        if (ndiv[i] < nmin) nmin = ndiv[i];
        if (ndiv[i] > nmax) nmax = ndiv[i];
    }
    cJSON_AddStringToObject(stats, "construction",
                            mesh->npatches ? "bezier" : cons_names[p->construction]);
    cJSON_AddNumberToObject(stats, "patches", (double)b->set->npatches);
    cJSON_AddNumberToObject(stats, "vertices", (double)s->layout->nverts);
    cJSON_AddNumberToObject(stats, "triangles", (double)s->layout->ntris);
    cJSON_AddNumberToObject(stats, "divisions_min", b->set->npatches ? nmin : 0);
    cJSON_AddNumberToObject(stats, "divisions_max", nmax);
    cJSON_AddNumberToObject(stats, "frames", (double)s->nframes);
    cJSON_AddNumberToObject(stats, "build_ms", build_ms);
    if (cc_distance >= 0) cJSON_AddNumberToObject(stats, "cc_distance", cc_distance);
    cJSON_AddNumberToObject(stats, "gpu_ms", t->first_tess_ms);
    cJSON_AddNumberToObject(stats, "gpu_total_ms", t->gpu_ms);
    cJSON_AddNumberToObject(stats, "vertices_per_s",
                            t->first_tess_ms > 0 ? (double)gv / (t->first_tess_ms / 1e3) : 0);
    if (*frame_ms) {
        cJSON_AddItemToObject(stats, "frame_ms", *frame_ms);
        *frame_ms = NULL;
    }
}

/* approximate-cc's limit on the faces around a vertex of the quad mesh
 * OpenSubdiv gets (the input, or it refined once unless all quads: an
 * n-gon's centre has n): its end caps' stencils take the square of it
 * (a fan of 2,000 triangles took 20 s). 0, or -1 with cc_valence_limit. */
static int cc_valence_ok(const vx_mesh *m, uint64_t limit, vx_err *err)
{
    if (!limit || m->npatches) return 0;
    int quads = m->faces_by_size[0] == 0 && m->faces_by_size[2] == 0;
    for (size_t f = 0; f < m->nfaces && !quads; f++) {
        uint32_t n = vx_mesh_face_size(m, f);
        if (n != 4 && n > limit)
            return vx_err_set(err, VX_ETOOBIG, "cc_valence_limit",
                              "face %zu has %u vertices; approximate-cc takes faces of at most "
                              "%llu (--max-cc-valence: its patches there cost the square of it; "
                              "the interpolate construction takes any)",
                              f + 1, n, (unsigned long long)limit);
    }
    uint32_t *deg = calloc(m->nverts ? m->nverts : 1, sizeof *deg);
    if (!deg) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for valences");
    size_t ncorners = m->face_start ? m->face_start[m->nfaces] : 3 * m->nfaces;
    for (size_t i = 0; i < ncorners; i++)
        if (++deg[m->face_idx[i]] > limit) {
            uint32_t v = m->face_idx[i];
            free(deg);
            return vx_err_set(err, VX_ETOOBIG, "cc_valence_limit",
                              "vertex %u has more than %llu faces around it; approximate-cc takes "
                              "at most that (--max-cc-valence: its patches there cost the square "
                              "of it; the interpolate construction takes any)",
                              v + 1, (unsigned long long)limit);
        }
    free(deg);
    return 0;
}

static int run_gl(vx_job_run *r, const vx_mesh *mesh, const gparams *pp, void **state, vx_err *err)
{
    const gparams p = *pp;
    const vx_limits *lim = vx_run_limits(r);
    size_t nframes = 1 + (size_t)p.frames.n;
    builder b = {.mesh = mesh, .construction = p.construction, .fd = -1};
    const double *pos[VX_GREGORY_MAX_FRAMES + 1];
    double *copies = NULL;
    vx_gtess *tess = NULL;
    uint32_t *ndiv = NULL;
    float *grid = NULL;
    int rc = -1;
    cJSON *frame_ms = cJSON_CreateArray();
    double t0 = vx_mono_ms();
    if ((p.construction == CONS_APPROX_CC && cc_valence_ok(mesh, lim->max_cc_valence, err)) ||
        gather_positions(r, mesh, &p, nframes, pos, &copies, err) ||
        construct_all(r, &b, pos, nframes, err))
        goto done;
    size_t folded = vx_gpatch_folded(b.set, mesh); /* of the mesh itself (frame 0) */
    double build_ms = vx_mono_ms() - t0;
    /* How far approximate-cc is from the true limit surface (frame 0). */
    double cc_distance = -1;
    if (p.construction == CONS_APPROX_CC && !mesh->npatches &&
        b.set->npatches <= CC_DISTANCE_MAX_PATCHES) {
        /* OpenSubdiv's reference surface takes seconds on big sets: in a
         * child process, killed at the time limit. */
        distance_work w = {mesh, b.set};
        if (vx_child_call(distance_child, &w, &cc_distance, sizeof cc_distance, stop_hook, r,
                          ENCODE_POLL_MS, err))
            goto done;
    }
    ndiv = vx_gregory_divisions(b.set, p.max_edge_set ? 0 : (int)p.divisions,
                                p.max_edge_set ? p.max_edge : 0, err);
    if (!ndiv) goto done;
    uint64_t gv;
    if (check_size(lim, b.set, ndiv, nframes, &gv, err)) goto done;
    greg_state *s = calloc(1, sizeof *s);
    if (!s) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the gregory state");
        goto done;
    }
    *state = s; /* from here on the runner frees it through free_state */
    s->pos = calloc(nframes, sizeof *s->pos);
    s->nrm = calloc(nframes, sizeof *s->nrm);
    grid = malloc((gv + 1) * 6 * sizeof *grid);
    if (!s->pos || !s->nrm || !grid) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the tessellation");
        goto done;
    }
    s->nframes = nframes;
    s->layout = vx_gregory_layout_new(b.set, ndiv, p.weld, err);
    if (!s->layout) goto done;
    tess_times t = {0, 0};
    tess = vx_gtess_new(vx_run_gl(r), s->layout, err);
    if (!tess) goto done;
    if (tessellate_frames(r, &b, pos, s, tess, grid, frame_ms, &t, err)) goto done;
    add_stats(r, mesh, &p, &b, ndiv, s, gv, build_ms, cc_distance, &t, &frame_ms);
    if (vx_run_stats(r)) {
        cJSON_AddNumberToObject(vx_run_stats(r), "folded_patches", (double)folded);
        cJSON_AddStringToObject(vx_run_stats(r), "tess_engine", vx_gtess_engine_name(tess));
    }
    rc = 0;
done:
    vx_gtess_free(tess);
    cJSON_Delete(frame_ms);
    free(ndiv);
    free(grid);
    vx_gpatch_set_free(b.set);
    vx_gregory_topo_free(b.topo);
    vx_gregory_cc_plan_free(b.cc);
    if (b.fd >= 0) close(b.fd);
    free(copies);
    return rc;
}

static int greg_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                       vx_err *err)
{
    vx_stop_set(stop_hook, r);
    int rc = run_gl(r, mesh, params, state, err);
    vx_stop_set(NULL, NULL);
    return rc;
}

/* One frame's file, written by a child process (util/child.h): the OBJ,
 * PLY and Draco writers are single calls that take seconds on big outputs
 * and cannot be stopped from inside; a child is killed at the time limit. */
typedef struct frame_write {
    const vx_mesh *m;
    const vx_mesh_write_opts *o;
    int format;
    const char *path;
} frame_write;

static int write_frame(void *ud, void *out, size_t out_size, vx_err *err)
{
    const frame_write *w = ud;
    (void)out;
    (void)out_size;
    return w->format == FMT_OBJ   ? vx_obj_write_path(w->m, w->o, w->path, err)
           : w->format == FMT_PLY ? vx_ply_write_path(w->m, w->o, w->path, err)
           : w->format == FMT_GLB ? vx_glb_write_path(w->m, w->o, w->path, err)
                                  : vx_draco_write_path(w->m, w->o, w->path, err);
}

typedef struct encode_poll {
    vx_job_run *r;
    double fraction;
} encode_poll;

static int poll_encode(void *ud, vx_err *err)
{
    encode_poll *e = ud;
    return vx_run_progress(e->r, e->fraction, err);
}

static int greg_encode(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    greg_state *s = state;
    const gparams p = *(const gparams *)params;
    const vx_gtess_layout *l = s->layout;
    for (size_t k = 0; k < s->nframes; k++) {
        char name[32];
        if (k == 0)
            snprintf(name, sizeof name, "mesh");
        else
            snprintf(name, sizeof name, "frame_%03zu", k);
        const char *path = vx_run_output(r, name, fmt_names[p.format], fmt_types[p.format], err);
        if (!path) return -1;
        vx_mesh m = {.nverts = l->nverts,
                     .pos = s->pos[k],
                     .nfaces = l->ntris,
                     .face_idx = l->tri,
                     .ntris = l->ntris,
                     .tri = l->tri};
        vx_mesh_write_opts o = {.normals = s->nrm[k],
                                /* OBJ groups per patch only when each patch is its own part */
                                .face_group = p.format == FMT_OBJ && p.weld ? NULL : l->tri_patch,
                                .group_prefix = "patch"};
        frame_write w = {&m, &o, p.format, path};
        encode_poll ep = {r, 0.9 + 0.1 * (double)k / (double)s->nframes};
        if (vx_child_call(write_frame, &w, NULL, 0, poll_encode, &ep, ENCODE_POLL_MS, err))
            return -1;
        if (vx_run_progress(r, 0.9 + 0.1 * (double)(k + 1) / (double)s->nframes, err)) return -1;
    }
    return 0;
}

/* Frames as positions can be megabytes: kept as a blob while the job waits. */
static const char *const blob_fields[] = {"frames", NULL};

/* Frames given as positions: as many vertices as the mesh (its metadata's
 * `vertices`, what the job reads), else 422 rather than a failed job. */
/* At least how many patches the mesh gives, from its metadata: a Bezier
 * upload's patches; one a face when every face is a quad; else one a face
 * corner (an n-gon counted as 5, its fewest); 0 when the metadata does not
 * say. */
static uint64_t patches_at_least(const cJSON *meta)
{
    const cJSON *f = cJSON_GetObjectItemCaseSensitive(meta, "faces");
    double bez = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(meta, "patches"));
    double tri = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(f, "triangles"));
    double quad = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(f, "quads"));
    double ngon = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(f, "ngons"));
    if (bez > 0) return (uint64_t)bez;
    if (!(tri >= 0 && quad >= 0 && ngon >= 0)) return 0; /* NaN: not in the metadata */
    return tri == 0 && ngon == 0 ? (uint64_t)quad : (uint64_t)(3 * tri + 4 * quad + 5 * ngon);
}

static int greg_check_mesh(const void *params, const cJSON *meta, const vx_limits *lim, vx_err *err)
{
    const gparams *p = params;
    /* Uniform divisions: 2N^2 triangles a patch (max_edge's are the job's
     * to count). */
    uint64_t np = patches_at_least(meta), nt = 2 * (uint64_t)p->divisions * (uint64_t)p->divisions;
    if (!p->max_edge_set && lim && lim->max_triangles &&
        (double)nt * (double)np > (double)lim->max_triangles)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.divisions = %ld makes at least %.0f triangles on the mesh's %llu "
                          "patches, over the limit of %llu (--max-triangles)",
                          p->divisions, (double)nt * (double)np, (unsigned long long)np,
                          (unsigned long long)lim->max_triangles);
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(meta, "vertices");
    if (!p->frames.n || !cJSON_IsNumber(v)) return 0;
    if (p->frames.ids) { /* each frame mesh has the mesh's vertices: copied as doubles */
        double bytes = (double)p->frames.n * 3 * v->valuedouble * sizeof(double);
        if (lim && lim->max_job_memory && bytes > (double)lim->max_job_memory)
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.frames: %d frame meshes of %.0f vertices need about %.0f "
                              "bytes, over the job memory limit of %llu (--max-job-memory)",
                              p->frames.n, v->valuedouble, bytes,
                              (unsigned long long)lim->max_job_memory);
        return 0;
    }
    if ((double)p->frames.nv != v->valuedouble)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.frames[0] has %ld vertices, the mesh %.0f", p->frames.nv,
                          v->valuedouble);
    return 0;
}

const vx_kind vx_kind_gregory = {
    .name = "gregory",
    .summary = "Smooth surface of bicubic Gregory patches (seed 001), tessellated on the GPU",
    .spec = spec,
    .params_size = sizeof(gparams),
    .check = greg_check,
    .check_mesh = greg_check_mesh,
    .run_gl = greg_run_gl,
    .run_cpu = NULL,
    .encode = greg_encode,
    .free_state = greg_free_state,
    .mesh_refs = greg_mesh_refs,
    .blob_fields = blob_fields,
};
