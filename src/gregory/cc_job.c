/* The `catmull-clark` row of the job table (kind.h; api/openapi.yaml has
 * the params and stats schemas). Runs on a CPU worker: run_gl only copies
 * the faces of the GL thread's cached mesh into the job state. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gregory/catmull_clark.h"
#include "util/child.h"
#include "util/fsutil.h"

typedef enum cc_format { CC_OBJ = 0, CC_PLY, CC_DRC, CC_GLB } cc_format;
static const char *const format_names[] = {"obj", "ply", "drc", "glb", NULL};

/* Bytes one output quad costs while refining (OpenSubdiv's topology of
 * every level, the double primvars, limit tangents, the output mesh and its
 * triangulated view); measured 500 at levels 5-6 on spot and suzanne,
 * checked against max_job_memory with some margin. */
#define CC_BYTES_PER_QUAD 600
/* How often run_cpu checks the time limit while the child works. */
#define CC_POLL_MS 20

static int max_levels(const vx_limits *lim);
static double levels_hi(const vx_limits *lim)
{
    return max_levels(lim);
}

typedef struct cc_params {
    long levels;
    int format, limit; /* format: cc_format */
} cc_params;

static const vx_pspec spec[] = {
    VX_P_INT(cc_params, levels, 1, 1, VX_CC_MAX_LEVELS,
             "subdivision levels (fewer where max_triangles is lower)", .hi_of = levels_hi),
    VX_P_ENUM(cc_params, format, format_names, CC_OBJ, "output mesh format"),
    VX_P_BOOL(cc_params, limit, 0, "push the vertices to the limit surface, with limit normals"),
    VX_P_END,
};

typedef struct cc_state {
    vx_mesh *in; /* the faces and positions, copied on the GL thread */
} cc_state;

/* Most levels one face of four corners can take with 2 * 4^levels
 * triangles within max_triangles (the bound parse can check before the
 * mesh is known). */
static int max_levels(const vx_limits *lim)
{
    int l = VX_CC_MAX_LEVELS;
    if (lim && lim->max_triangles)
        while (l > 1 && (UINT64_C(2) << (2 * l)) > lim->max_triangles)
            l--;
    return l;
}

/* A copy of what refinement needs: positions and faces. */
static vx_mesh *copy_faces(const vx_mesh *m)
{
    vx_mesh *c = vx_mesh_new();
    if (!c) return NULL;
    size_t nidx = m->face_start ? m->face_start[m->nfaces] : 3 * m->nfaces;
    c->nfaces = m->nfaces;
    c->pos = malloc(3 * m->nverts * sizeof(double) + 1);
    c->face_idx = malloc(nidx * sizeof(uint32_t) + 1);
    uint32_t *map = malloc(m->nverts * sizeof(uint32_t) + 1);
    if (m->face_start) c->face_start = malloc((m->nfaces + 1) * sizeof(uint32_t));
    if (!c->pos || !c->face_idx || !map || (m->face_start && !c->face_start)) {
        free(map);
        vx_mesh_free(c);
        return NULL;
    }
    /* Only the vertices a face uses (a .bpt's control points, an OBJ's
     * stray ones): OpenSubdiv would carry the rest into the output with no
     * face to give them a normal (a zero NORMAL is invalid glTF). */
    memset(map, 0xff, m->nverts * sizeof(uint32_t));
    for (size_t i = 0; i < nidx; i++)
        map[m->face_idx[i]] = 0;
    for (size_t v = 0; v < m->nverts; v++)
        if (map[v] == 0) {
            map[v] = (uint32_t)c->nverts;
            memcpy(c->pos + 3 * c->nverts++, m->pos + 3 * v, 3 * sizeof(double));
        }
    for (size_t i = 0; i < nidx; i++)
        c->face_idx[i] = map[m->face_idx[i]];
    free(map);
    if (m->face_start) memcpy(c->face_start, m->face_start, (m->nfaces + 1) * sizeof(uint32_t));
    return c;
}

/* Whether `quads` output quads at `levels` fit max_triangles and the job
 * memory: 0, or -1 with err, invalid_params at submission, else
 * output_too_big or job_memory_limit. */
static int cc_fits(long levels, double quads, const vx_limits *lim, int at_submission, vx_err *err)
{
    vx_err_kind kind = at_submission ? VX_EUNPROC : VX_ETOOBIG;
    if (lim && lim->max_triangles && 2 * quads > (double)lim->max_triangles)
        return vx_err_set(err, kind, at_submission ? "invalid_params" : "output_too_big",
                          "params.levels = %ld gives %.0f triangles on this mesh, over "
                          "max_triangles (%llu)",
                          levels, 2 * quads, (unsigned long long)lim->max_triangles);
    if (lim && lim->max_job_memory && quads * CC_BYTES_PER_QUAD > (double)lim->max_job_memory)
        return vx_err_set(err, kind, at_submission ? "invalid_params" : "job_memory_limit",
                          "params.levels = %ld needs about %.0f bytes on this mesh, over the job "
                          "memory limit (%llu)",
                          levels, quads * CC_BYTES_PER_QUAD,
                          (unsigned long long)lim->max_job_memory);
    return 0;
}

/* The output's size, from the mesh's metadata: its corners are its
 * triangles (fans) plus two a face. The job checks the mesh it reads
 * again (a .bpt's patches: only there). */
static int cc_check_mesh(const void *params, const cJSON *meta, const vx_limits *lim, vx_err *err)
{
    const cc_params *p = params;
    /* no limit surface along an edge of three faces or more (the run
     * says which edge, for metadata without the count) */
    double nm = cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(meta, "nonmanifold_edges"));
    if (p->limit && nm > 0)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.limit: the mesh has %.0f edges that three or more faces "
                          "border, where there is no limit surface (limit: false subdivides it)",
                          nm);
    const cJSON *t = cJSON_GetObjectItemCaseSensitive(meta, "triangles");
    const cJSON *f =
        cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(meta, "faces"), "total");
    if (!cJSON_IsNumber(t) || !cJSON_IsNumber(f) ||
        cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(meta, "patches")) > 0)
        return 0;
    double quads = (t->valuedouble + 2 * f->valuedouble) * ldexp(1, 2 * ((int)p->levels - 1));
    return cc_fits(p->levels, quads, lim, 1, err);
}

static int cc_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                     vx_err *err)
{
    const cc_params p = *(const cc_params *)params;
    const vx_limits *lim = vx_run_limits(r);
    if (cc_fits(p.levels, (double)vx_cc_quads(mesh, p.levels), lim, 0, err)) return -1;
    cc_state *s = calloc(1, sizeof *s);
    if (!s) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job state");
    *state = s;
    if (!(s->in = copy_faces(mesh)))
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a copy of the mesh");
    return 0;
}

/* What the child process (util/child.h) of run_cpu does and hands back:
 * OpenSubdiv's refinement and the encoder are single library calls that
 * run for seconds on big meshes and cannot be stopped from inside; in a
 * child they are killed at the job's time limit. */
typedef struct cc_work {
    const vx_mesh *in;
    cc_params p;
    const char *path;
} cc_work;

typedef struct cc_result {
    double refine_ms, encode_ms;
    uint64_t vertices, faces, triangles, boundary_edges;
} cc_result;

static int cc_child(void *ud, void *out, size_t out_size, vx_err *err)
{
    const cc_work *w = ud;
    cc_result *res = out;
    (void)out_size;
    vx_mesh *m = NULL;
    float *normals = NULL;
    double t0 = vx_mono();
    if (vx_cc_refine(w->in, (int)w->p.levels, w->p.limit, &m, &normals, err)) return -1;
    double t1 = vx_mono();
    vx_mesh_write_opts o = {.normals = normals};
    int rc = w->p.format == CC_OBJ   ? vx_obj_write_path(m, &o, w->path, err)
             : w->p.format == CC_PLY ? vx_ply_write_path(m, &o, w->path, err)
             : w->p.format == CC_GLB ? vx_glb_write_path(m, &o, w->path, err)
                                     : vx_draco_write_path(m, &o, w->path, err);
    res->refine_ms = (t1 - t0) * 1e3;
    res->encode_ms = (vx_mono() - t1) * 1e3;
    res->vertices = m->nverts;
    res->faces = m->nfaces;
    res->triangles = m->ntris;
    res->boundary_edges = m->boundary_edges;
    vx_mesh_free(m);
    free(normals);
    return rc;
}

static int cc_poll(void *ud, vx_err *err)
{
    return vx_run_progress(ud, 0.1, err);
}

static int cc_run_cpu(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    cc_state *s = state;
    const cc_params p = *(const cc_params *)params;
    static const char *const ctype[] = {"model/obj", "model/x-ply", "model/x-draco",
                                        "model/gltf-binary"};
    const char *path = vx_run_output(r, "mesh", format_names[p.format], ctype[p.format], err);
    if (!path) return -1;
    cc_work w = {s->in, p, path};
    cc_result res;
    memset(&res, 0, sizeof res);
    if (vx_child_call(cc_child, &w, &res, sizeof res, cc_poll, r, CC_POLL_MS, err)) return -1;
    vx_mesh_free(s->in);
    s->in = NULL;
    cJSON *st = vx_run_stats(r);
    cJSON_AddNumberToObject(st, "levels", (double)p.levels);
    cJSON_AddNumberToObject(st, "vertices", (double)res.vertices);
    cJSON_AddNumberToObject(st, "faces", (double)res.faces);
    cJSON_AddNumberToObject(st, "triangles", (double)res.triangles);
    cJSON_AddNumberToObject(st, "boundary_edges", (double)res.boundary_edges);
    cJSON_AddNumberToObject(st, "refine_ms", res.refine_ms);
    cJSON_AddNumberToObject(st, "encode_ms", res.encode_ms);
    return vx_run_progress(r, 1.0, err);
}

static void cc_free_state(void *state)
{
    cc_state *s = state;
    if (!s) return;
    vx_mesh_free(s->in);
    free(s);
}

const vx_kind vx_kind_catmull_clark = {
    .name = "catmull-clark",
    .summary = "Uniform Catmull-Clark subdivision (OpenSubdiv) to OBJ, PLY, Draco or glb, with "
               "limit normals",
    .spec = spec,
    .params_size = sizeof(cc_params),
    .check_mesh = cc_check_mesh,
    .run_gl = cc_run_gl,
    .run_cpu = cc_run_cpu,
    .encode = NULL,
    .free_state = cc_free_state,
};
