/* The `render` row of the job table (kind.h; api/openapi.yaml has the
 * RenderParams and RenderStats schemas). Stages:
 *   run_gl   the solid of every mesh at R^3 from the voxel engine (bit
 *            grids, 1 bit per sample; the only R^3 data ever held)
 *   run_cpu  Algorithm I (lowpass.c), then the band-limited interpolation
 *            to M = L N with the spectral gradient (interp.c); the older
 *            methods get the density at the N voxels and their own
 *            gradients (compare.c)
 *   encode   per frame: cast, shade, write the image and requested float
 *            outputs (so frames are never all held at once); the voxels.
 * Renders sample the precomputed M^3 grid trilinearly (L >= 4 is the
 * default; the unit tests measure it against exact evaluation). */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bandlimit/bandlimit.h"
#include "bandlimit/fft_int.h"
#include "bandlimit/job.h"
#include "image/png.h"
#include "util/fsutil.h"
#include "util/par.h"
#include "util/vec3.h"
#include "util/stop.h"
#include "voxel/io.h"
#include "voxel/voxel.h"

/* The share of the job's time limit one FFTW plan may take measuring. */
#define PLAN_SHARE 0.02

enum { CAM_AXIS = 0, CAM_ORBIT };
static const char *const cam_names[] = {"axis", "orbit", NULL};
static const char *const axis_names[] = {"+x", "-x", "+y", "-y", "+z", "-z", NULL};
/* "image" is taken and dropped (check): the image is always made. */
enum { OUT_NORMAL = 0, OUT_POSITION, OUT_DEPTH, OUT_VOXELS, OUT_IMAGE, OUT_COUNT };
static const char *const out_names[] = {"normal", "position", "depth", "voxels", "image", NULL};

typedef struct rfilter {
    int type;
    double D0, n;
    int D0_set;
} rfilter;

typedef struct rcamera {
    int type, axis;
    double azimuth, elevation, distance, fov, ortho_width;
    int fov_set;
} rcamera;

typedef struct rlight {
    double direction[3], color[3];
} rlight;

typedef struct rparams {
    long N, R;
    rfilter filter;
    long L;
    double iso;
    char meshes[VX_BL_MAX_MESHES][VX_MESH_ID_SIZE];
    rcamera camera;
    long width, height;
    rlight lights[VX_BL_MAX_LIGHTS];
    double ambient, color[3], background[3];
    int normals, compare;
    long bits;
    int outputs[OUT_COUNT];
    long frames;
    int nmeshes, nlights, R_set, L_set;
} rparams;

typedef struct rstate {
    int nmeshes;
    vx_bitgrid *grids;
    vx_inside inside[1 + VX_BL_MAX_MESHES]; /* each mesh's rule: voxelize's default for it */
    double box_origin[3], P, centre[3], radius;
    float *spec;
    vx_bl_volume vm; /* M^3 with the spectral gradient */
    vx_bl_volume vn; /* N^3 voxels, gradient = central differences */
    float *sobel[3]; /* N^3 3-D Sobel gradient */
    double sampling_ms, lowpass_ms, interp_ms;
    uint64_t peak;
} rstate;

static const cJSON *field(const cJSON *o, const char *name)
{
    const cJSON *it = o ? cJSON_GetObjectItemCaseSensitive(o, name) : NULL;
    return it && !cJSON_IsNull(it) ? it : NULL;
}

/* The voxels output's voxel (interp.c: the box P / N) must make a .vdb: 0,
 * or -1 with err (VX_EUNPROC code). */
static int voxels_fit(const rparams *p, double P, const char *code, vx_err *err)
{
    if (!p->outputs[OUT_VOXELS] || vx_vdb_voxel_size_ok(P / p->N)) return 0;
    return vx_err_set(err, VX_EUNPROC, code,
                      "params.outputs: the voxels output's voxel size would be %.6g (the box "
                      "%.6g / N %d), under the %.6g that OpenVDB's transforms take: a mesh in "
                      "smaller units, or no voxels output",
                      P / p->N, P, (int)p->N, vx_vdb_min_voxel_size());
}

/* Bytes one job needs, by stage (the largest stage counts): bit grids
 * held throughout; Algorithm I; the volumes; a frame's hits and image. */
static uint64_t job_bytes(const rparams *p)
{
    uint64_t R = (uint64_t)p->R, N = (uint64_t)p->N, M = (uint64_t)(p->L * p->N);
    int dims[3] = {(int)R, (int)R, (int)R};
    uint64_t grids = vx_bitgrid_bytes(dims, 1) * (1 + (uint64_t)p->nmeshes);
    uint64_t spec = vx_bl_spectrum_len((int)N) * 8;
    int need_m = p->compare || p->normals == VX_BL_SPECTRAL;
    int need_n = p->compare || p->normals != VX_BL_SPECTRAL || p->outputs[OUT_VOXELS];
    uint64_t vols = (need_m ? vx_bl_volume_bytes((int)M, 1) + M * N * N / 2 * 16 : 0) +
                    (need_n ? N * N * N * 4 * 7 : 0);
    uint64_t panels = p->compare ? 6 : 1;
    uint64_t pix = (uint64_t)p->width * p->height * panels;
    uint64_t frame = pix * (7 * 4 + 3 * 4 + 6);
    uint64_t lp = vx_bl_lowpass_bytes((int)p->R, (int)p->N);
    uint64_t a = lp > vols ? lp : vols;
    return grids + spec + a + frame;
}

static const char *const flt_types[] = {"exponential", NULL};
static const vx_pspec flt_spec[] = {
    VX_P_ENUM(rfilter, type, flt_types, 0, "the low-pass filter"),
    VX_P_NUM(rfilter, D0, 0, 1e-6, 1e6, "cut-off frequency (default N / 4)",
             .flags = VX_PF_DERIVED | VX_PF_SET, .set_off = offsetof(rfilter, D0_set)),
    VX_P_NUM(rfilter, n, 2, 0.1, 64, "filter order"),
    VX_P_END,
};

static const vx_pspec cam_spec[] = {
    VX_P_ENUM(rcamera, type, cam_names, CAM_AXIS, "axis (orthographic) or orbit"),
    VX_P_ENUM(rcamera, axis, axis_names, 4, "the axis camera's view direction"),
    VX_P_NUM(rcamera, azimuth, 30, -360, 360, "orbit azimuth in degrees"),
    VX_P_NUM(rcamera, elevation, 20, -89, 89, "orbit elevation in degrees"),
    VX_P_NUM(rcamera, distance, 0, 0, 1e12, "eye distance, 0 = fit"),
    VX_P_NUM(rcamera, fov, 0, 0, 120,
             "field of view in degrees, 0 = orthographic (default 30 for orbit)",
             .flags = VX_PF_DERIVED | VX_PF_SET, .set_off = offsetof(rcamera, fov_set)),
    VX_P_NUM(rcamera, ortho_width, 0, 0, 1e12, "orthographic view width, 0 = fit"),
    VX_P_END,
};

static const double white[3] = {1, 1, 1}, def_color[3] = {0.8, 0.8, 0.85};
static const vx_pspec dir_item = VX_P_ITEM_NUM(-1e6, 1e6), light_item = VX_P_ITEM_NUM(0, 16),
                      unit_item = VX_P_ITEM_NUM(0, 1);
static const vx_pspec light_spec[] = {
    VX_P_VEC(rlight, direction, 3, NULL, &dir_item, "towards the light (not zero)",
             .flags = VX_PF_REQUIRED),
    VX_P_VEC(rlight, color, 3, white, &light_item, "light colour"),
    VX_P_END,
};
static const vx_pspec light_obj = {.type = VX_PT_OBJECT, .sub = light_spec};
static const vx_pspec mesh_item = {.type = VX_PT_MESH_ID};

#define P(f) offsetof(rparams, f)
static const vx_pspec spec[] = {
    VX_P_INT(rparams, N, 64, 2, 512, "kept frequencies per axis (even)"),
    VX_P_INT(rparams, R, 0, 2, 2048, "samples per axis (even, >= N; default min(8 N, 2048))",
             .lo_field = "N", .flags = VX_PF_DERIVED | VX_PF_SET, .set_off = P(R_set)),
    {.name = "filter",
     .type = VX_PT_OBJECT,
     .off = P(filter),
     .sub = flt_spec,
     .doc = "the low-pass filter"},
    VX_P_INT(rparams, L, 0, 1, 16, "upsampling factor, L N <= 1024 (default 4, fewer above N 256)",
             .flags = VX_PF_DERIVED | VX_PF_SET, .set_off = P(L_set)),
    VX_P_NUM(rparams, iso, 0.5, -1e6, 1e6, "iso level of the density"),
    {.name = "meshes",
     .type = VX_PT_ARRAY,
     .off = P(meshes),
     .sub = &mesh_item,
     .item_size = VX_MESH_ID_SIZE,
     .max_items = VX_BL_MAX_MESHES,
     .flags = VX_PF_COUNT,
     .count_off = P(nmeshes),
     .doc = "further stored meshes in the same scene"},
    {.name = "camera",
     .type = VX_PT_OBJECT,
     .off = P(camera),
     .sub = cam_spec,
     .doc = "the camera"},
    VX_P_INT(rparams, width, 512, 8, 8192, "image width in pixels"),
    VX_P_INT(rparams, height, 512, 8, 8192, "image height in pixels"),
    {.name = "lights",
     .type = VX_PT_ARRAY,
     .off = P(lights),
     .sub = &light_obj,
     .item_size = sizeof(rlight),
     .max_items = VX_BL_MAX_LIGHTS,
     .flags = VX_PF_COUNT,
     .count_off = P(nlights),
     .doc = "directional lights (default: a key light)"},
    VX_P_NUM(rparams, ambient, 0.15, 0, 1, "ambient light"),
    VX_P_VEC(rparams, color, 3, def_color, &unit_item, "surface colour"),
    VX_P_VEC(rparams, background, 3, white, &unit_item, "background colour"),
    VX_P_ENUM(rparams, normals, vx_bl_normals_names, 0, "how normals are made"),
    VX_P_BOOL(rparams, compare, 0, "render every normals method side by side"),
    VX_P_INT(rparams, bits, 8, 8, 16, "PNG bits per channel: 8 or 16"),
    {.name = "outputs",
     .type = VX_PT_ENUM_SET,
     .off = P(outputs),
     .names = out_names,
     .doc = "further outputs"},
    VX_P_INT(rparams, frames, 1, 1, VX_BL_MAX_FRAMES, "turntable frames (orbit camera)"),
    VX_P_END,
};
#undef P

static int bad(vx_err *err, const char *fmt, const char *what)
{
    return vx_err_set(err, VX_EUNPROC, "invalid_params", fmt, what);
}

/* The defaults that depend on other fields. */
static void derive(rparams *p)
{
    /* 8 samples per kept frequency, as many as the sampler takes (2048)
     * above N = 256 */
    if (!p->R_set) p->R = p->N <= 256 ? 8 * p->N : 2048;
    if (!p->filter.D0_set) p->filter.D0 = p->N / 4.0;
    /* default 4, fewer where L N would pass 1024 */
    if (!p->L_set) p->L = p->N <= 256 ? 4 : 1024 / p->N;
    if (!p->camera.fov_set) p->camera.fov = p->camera.type == CAM_ORBIT ? 30 : 0;
    p->R_set = p->L_set = p->filter.D0_set = p->camera.fov_set = 1;
}

static int render_check(void *params, const vx_limits *lim, vx_err *err)
{
    rparams *p = params;
    p->outputs[OUT_IMAGE] = 0; /* always made: the normalised params do not list it */
    if (p->N % 2) return bad(err, "params.%s must be even", "N");
    derive(p);
    if (p->R % 2) return bad(err, "params.%s must be even", "R");
    if (p->L * p->N > 1024) return bad(err, "params.%s: L * N must be at most 1024", "L");
    if (p->camera.type == CAM_AXIS && p->camera.fov != 0)
        return bad(err, "params.%s: the axis camera is orthographic (fov must be 0)", "camera.fov");
    if (p->bits != 8 && p->bits != 16) return bad(err, "params.%s must be 8 or 16", "bits");
    if (p->frames > 1 && p->camera.type != CAM_ORBIT)
        return bad(err, "params.%s > 1 (a turntable) needs params.camera.type orbit", "frames");
    for (int i = 0; i < p->nlights; i++) {
        const double *d = p->lights[i].direction;
        /* not the length: [1e-200, 0, 0]'s square underflows to 0 */
        if (!(fmax(fabs(d[0]), fmax(fabs(d[1]), fabs(d[2]))) > 0))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.lights[%d].direction must not be zero", i);
    }
    /* sizes */
    uint64_t panels = p->compare ? 6 : 1;
    uint64_t pix = (uint64_t)p->width * (uint64_t)p->height * panels;
    if (lim && lim->max_image_pixels && pix > lim->max_image_pixels)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.width * params.height%s = %llu exceeds the limit of %llu pixels",
                          p->compare ? " * 6 (compare)" : "", (unsigned long long)pix,
                          (unsigned long long)lim->max_image_pixels);
    uint64_t bytes = job_bytes(p);
    if (lim && lim->max_job_memory && bytes > lim->max_job_memory)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.R, params.N, params.L: R=%ld, N=%ld, M=%ld need about %llu "
                          "bytes, over the job memory limit of %llu",
                          p->R, p->N, p->L * p->N, (unsigned long long)bytes,
                          (unsigned long long)lim->max_job_memory);
    return 0;
}

static size_t render_mesh_refs(const cJSON *params, const char **ids, size_t max)
{
    const cJSON *m = field(params, "meshes"), *e;
    size_t n = 0;
    if (!cJSON_IsArray(m)) return 0;
    cJSON_ArrayForEach(e, m)
    {
        if (!cJSON_IsString(e)) continue;
        if (n < max) ids[n] = e->valuestring;
        n++;
    }
    return n;
}

static void render_free_state(void *state)
{
    rstate *s = state;
    if (!s) return;
    for (int i = 0; i < s->nmeshes; i++)
        vx_bitgrid_free(&s->grids[i]);
    free(s->grids);
    vx_bl_free(s->spec);
    vx_bl_volume_free(&s->vm);
    vx_bl_volume_free(&s->vn);
    for (int a = 0; a < 3; a++)
        free(s->sobel[a]);
    free(s);
}

static void stat_set(cJSON *stats, const char *name, double v)
{
    if (!stats) return;
    cJSON_DeleteItemFromObjectCaseSensitive(stats, name);
    cJSON_AddNumberToObject(stats, name, v);
}

typedef struct gl_progress {
    vx_job_run *r;
    int i, n;
} gl_progress;

static int voxel_progress(void *ud, double fraction, vx_err *err)
{
    gl_progress *g = ud;
    return vx_run_progress(g->r, 0.3 * (g->i + fraction) / g->n, err);
}

static int render_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                         vx_err *err)
{
    const rparams *pp = params, p = *pp;
    const vx_limits *lim = vx_run_limits(r);
    double t0 = vx_mono_ms();
    rstate *s = calloc(1, sizeof *s);
    int nm = 1 + p.nmeshes;
    if (s) s->grids = calloc((size_t)nm, sizeof *s->grids);
    if (!s || !s->grids) {
        free(s);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the job state");
    }
    *state = s;
    /* load the further meshes; the union bbox frames the sampling box */
    vx_mesh **extra = calloc((size_t)nm, sizeof *extra);
    if (!extra) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for meshes");
    int rc = -1;
    for (int i = 1; i < nm; i++)
        if (!(extra[i] = vx_run_load_mesh(r, pp->meshes[i - 1], err))) goto out;
    double lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = mesh->bbox_min[a];
        hi[a] = mesh->bbox_max[a];
        for (int k = 1; k < nm; k++) {
            if (extra[k]->bbox_min[a] < lo[a]) lo[a] = extra[k]->bbox_min[a];
            if (extra[k]->bbox_max[a] > hi[a]) hi[a] = extra[k]->bbox_max[a];
        }
    }
    double ext = 0, diag = 0;
    for (int a = 0; a < 3; a++) {
        double d = hi[a] - lo[a];
        if (d > ext) ext = d;
        diag += d * d;
        s->centre[a] = 0.5 * (lo[a] + hi[a]);
    }
    if (!(ext > 0)) {
        vx_err_set(err, VX_EUNPROC, "degenerate_mesh", "the meshes' bounding box is empty");
        goto out;
    }
    s->radius = 0.5 * sqrt(diag);
    s->P = ext * (1 + 2 * VX_BL_PAD);
    if (voxels_fit(&p, s->P, "voxel_size_too_small", err)) goto out;
    vx_voxelize_desc d = {0};
    for (int a = 0; a < 3; a++) {
        s->box_origin[a] = s->centre[a] - s->P / 2;
        d.grid.origin[a] = s->box_origin[a];
        d.grid.dims[a] = (int)p.R;
    }
    d.grid.h = s->P / p.R;
    d.method = VX_METHOD_AUTO;
    d.fill = VX_FILL_SOLID;
    d.max_memory = lim ? lim->max_job_memory : 0;
    d.progress = voxel_progress;
    d.max_slab_rows = vx_voxelize_slab_rows(d.grid.dims);
    for (int k = 0; k < nm; k++) {
        gl_progress gp = {r, k, nm};
        d.ud = &gp;
        vx_voxelize_stats vst;
        /* an open mesh or one whose faces disagree on their way round
         * takes the rule voxelize takes for it (nonzero drew streaks out
         * to the box's edge, or left an open box a wall) */
        s->inside[k] = d.inside = vx_voxelize_default_inside(k ? extra[k] : mesh, &d);
        if (vx_voxelize(vx_run_gl(r), k ? extra[k] : mesh, &d, &s->grids[k], &vst, err)) goto out;
        s->nmeshes = k + 1;
    }
    s->sampling_ms = vx_mono_ms() - t0;
    rc = 0;
out:
    for (int k = 1; k < nm; k++)
        vx_mesh_free(extra[k]);
    free(extra);
    return rc;
}

static int lowpass_progress(void *ud, double fraction, vx_err *err)
{
    return vx_run_progress(ud, 0.3 + 0.3 * fraction, err);
}

static int run_cpu(vx_job_run *r, const rparams *pp, void *state, vx_err *err)
{
    const rparams p = *pp;
    rstate *s = state;
    const int N = (int)p.N, R = (int)p.R, M = (int)(p.L * p.N), nt = vx_par_cpus();
    vx_bl_filter flt = {p.filter.D0, p.filter.n};
    vx_bl_bits bits = {s->grids, s->nmeshes, lowpass_progress, r};
    vx_bl_lowpass_stats lst;
    vx_bl_wisdom_dir(vx_run_cache_dir(r)); /* measured plans, kept across restarts */
    /* Measuring a new size takes seconds: a few per cent of the time limit
     * each (a plan is made between two polls). */
    double limit = vx_run_limits(r)->job_timeout_s;
    vx_bl_plan_time_limit(limit > 0 ? PLAN_SHARE * limit : 0);
    s->spec = vx_bl_lowpass(R, N, &flt, vx_bl_sample_bits, &bits, nt, &lst, err);
    if (!s->spec) return -1;
    s->sampling_ms += lst.sample_ms;
    s->lowpass_ms = lst.ms;
    int dims[3] = {R, R, R};
    s->peak = lst.peak_bytes + vx_bitgrid_bytes(dims, 1) * (uint64_t)s->nmeshes;
    /* the grids are done with: free them before the volumes exist */
    for (int i = 0; i < s->nmeshes; i++)
        vx_bitgrid_free(&s->grids[i]);
    s->nmeshes = 0;
    if (vx_run_progress(r, 0.6, err)) return -1;
    double t0 = vx_mono_ms(), x0[3];
    for (int a = 0; a < 3; a++)
        x0[a] = s->box_origin[a] + 0.5 * s->P / R;
    uint64_t vbytes = 0;
    if (p.compare || p.normals == VX_BL_SPECTRAL) {
        if (vx_bl_interp(s->spec, N, M, x0, s->P, 1, nt, &s->vm, err) ||
            vx_bl_volume_blocks(&s->vm, err))
            return -1;
        vbytes += vx_bl_volume_bytes(M, 1) + (uint64_t)M * N * N / 2 * 16;
    }
    if (p.compare || p.normals != VX_BL_SPECTRAL || p.outputs[OUT_VOXELS]) {
        if (vx_bl_interp(s->spec, N, N, x0, s->P, 0, nt, &s->vn, err) ||
            vx_bl_volume_blocks(&s->vn, err))
            return -1;
        if (p.compare || p.normals == VX_BL_SOBEL3D) {
            vx_bl_volume t = s->vn;
            t.g[0] = t.g[1] = t.g[2] = NULL;
            if (vx_bl_voxel_gradient(&t, VX_BL_SOBEL3D, err)) {
                for (int a = 0; a < 3; a++)
                    free(t.g[a]);
                return -1;
            }
            for (int a = 0; a < 3; a++)
                s->sobel[a] = t.g[a];
        }
        if (vx_bl_voxel_gradient(&s->vn, VX_BL_CENTRAL, err)) return -1;
        vbytes += (uint64_t)N * N * N * 4 * 7;
    }
    if (vbytes > s->peak) s->peak = vbytes;
    s->interp_ms = vx_mono_ms() - t0;
    return vx_run_progress(r, 0.75, err);
}

/* The camera of frame f (turntable: azimuth + 360 f / frames). */
static void make_camera(const rparams *p, const rstate *s, int f, vx_bl_camera *c)
{
    memset(c, 0, sizeof *c);
    double dir[3], worldup[3] = {0, 1, 0};
    if (p->camera.type == CAM_AXIS) {
        int ax = p->camera.axis / 2;
        double sg = p->camera.axis % 2 ? -1 : 1;
        for (int a = 0; a < 3; a++)
            dir[a] = a == ax ? sg : 0;
        if (ax == 1) {
            worldup[1] = 0;
            worldup[2] = -sg; /* from +y: +z down the image */
        }
    } else {
        double az = (p->camera.azimuth + 360.0 * f / p->frames) * M_PI / 180,
               el = p->camera.elevation * M_PI / 180;
        dir[0] = sin(az) * cos(el);
        dir[1] = sin(el);
        dir[2] = cos(az) * cos(el);
    }
    for (int a = 0; a < 3; a++)
        c->fwd[a] = -dir[a];
    vx_v3_cross(c->fwd, worldup, c->right);
    vx_v3_unit(c->right);
    vx_v3_cross(c->right, c->fwd, c->up);
    double fit = 2 * s->radius * 1.05;
    c->ortho = p->camera.fov == 0;
    c->fov_deg = p->camera.fov;
    /* a fitted eye stays within 1.2e8 radii (VX_BL_MIN_FIT_FOV) */
    if (!c->ortho && !(p->camera.distance > 0) && c->fov_deg < VX_BL_MIN_FIT_FOV)
        c->fov_deg = VX_BL_MIN_FIT_FOV;
    double aspect = (double)p->width / p->height;
    double ow = p->camera.ortho_width > 0 ? p->camera.ortho_width : fit;
    c->ortho_height = aspect >= 1 ? ow : ow / aspect;
    double half = c->fov_deg * M_PI / 360 * (aspect >= 1 ? 1 : aspect);
    double dist = p->camera.distance > 0 ? p->camera.distance
                  : c->ortho             ? 2 * s->P
                                         : s->radius * 1.05 / sin(half);
    /* Orthographic rays from farther than the fitting distance see the
     * same image: they start there (from 1e12 mesh sizes away the rays'
     * entry points would lose all precision), the depths made up for. */
    c->depth_add = 0;
    if (c->ortho && dist > 2 * s->P) {
        c->depth_add = dist - 2 * s->P;
        dist = 2 * s->P;
    }
    for (int a = 0; a < 3; a++)
        c->eye[a] = s->centre[a] + dir[a] * dist;
}

/* Casts one panel with the given method into h. */
static int cast_method(const rstate *s, const rparams *p, const vx_bl_camera *cam, int method,
                       vx_bl_hits *h, vx_err *err)
{
    int nt = vx_par_cpus();
    if (method == VX_BL_SPECTRAL) return vx_bl_cast(&s->vm, p->iso, cam, nt, h, err);
    vx_bl_volume v = s->vn;
    if (method == VX_BL_SOBEL3D)
        for (int a = 0; a < 3; a++)
            v.g[a] = s->sobel[a];
    if (vx_bl_cast(&v, p->iso, cam, nt, h, err)) return -1;
    if (method == VX_BL_DEPTH_ONLY || method == VX_BL_CROSS_MASK || method == VX_BL_SOBEL2D)
        vx_bl_screen_normals(h, cam, (vx_bl_normals)method);
    return 0;
}

/* PFM: "PF" (3 channels) or "Pf" (1), rows bottom to top, little-endian. */
static int write_pfm(const char *path, const float *v, int w, int h, int ch, vx_err *err)
{
    FILE *f = fopen(path, "wb");
    /* messages name the file, not where the server keeps it */
    const char *name = vx_path_base(path);
    if (!f)
        return vx_err_set(err, VX_EIO, "io_error", "cannot write %s: %s", name, strerror(errno));
    fprintf(f, "%s\n%d %d\n-1.0\n", ch == 3 ? "PF" : "Pf", w, h);
    int e = 0;
    for (int y = h - 1; y >= 0 && !e; y--) {
        if (vx_stop_poll(err)) {
            fclose(f);
            unlink(path);
            return -1;
        }
        if (fwrite(v + (size_t)y * w * ch, sizeof(float), (size_t)w * ch, f) != (size_t)w * ch)
            e = errno;
    }
    if (fclose(f) && !e) e = errno;
    if (!e) return 0;
    unlink(path); /* no partial file left (a full disk) */
    return vx_err_set(err, VX_EIO, "io_error", "cannot write %s: %s", name, strerror(e ? e : EIO));
}

static int png_poll(void *ud, double fraction, vx_err *err)
{
    (void)ud;
    (void)fraction;
    return vx_stop_poll(err);
}

static int write_png(const char *path, const float *rgb, int w, int h, int bits, vx_err *err)
{
    size_t n = (size_t)w * h * 3;
    void *buf = malloc(n * (bits == 16 ? 2 : 1));
    if (!buf) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the PNG");
    for (size_t i = 0; i < n; i++) {
        if ((i & 0xfffff) == 0 && vx_stop_poll(err)) {
            free(buf);
            return -1;
        }
        double x = rgb[i] < 0 ? 0 : rgb[i] > 1 ? 1 : rgb[i];
        if (bits == 16)
            ((uint16_t *)buf)[i] = (uint16_t)lrint(x * 65535);
        else
            ((uint8_t *)buf)[i] = (uint8_t)lrint(x * 255);
    }
    vx_png_poll poll = {png_poll, NULL};
    int rc = vx_png_write_path_poll(path, buf, w, h, 3, bits, &poll, err);
    free(buf);
    return rc;
}

/* Output name NAME or NAME_fff for turntables. */
static const char *output(vx_job_run *r, const rparams *p, const char *name, int f, const char *ext,
                          const char *type, vx_err *err)
{
    char nm[64];
    if (p->frames > 1)
        snprintf(nm, sizeof nm, "%s_%03d", name, f);
    else
        snprintf(nm, sizeof nm, "%s", name);
    return vx_run_output(r, nm, ext, type, err);
}

static int render_frame(vx_job_run *r, const rparams *p, const rstate *s, int f, double *render_ms,
                        double *encode_ms, uint64_t *covered, vx_err *err)
{
    const int W = (int)p->width, H = (int)p->height, panels = p->compare ? 6 : 1;
    const int cols = p->compare ? 3 : 1, IW = W * cols, IH = H * (p->compare ? 2 : 1);
    vx_bl_camera cam;
    make_camera(p, s, f, &cam);
    vx_bl_light lights[VX_BL_MAX_LIGHTS];
    int nl = p->nlights;
    if (nl == 0) { /* a key light from the camera's upper left */
        nl = 1;
        double v[3] = {-0.25, 0.35, 1};
        vx_v3_unit(v);
        for (int a = 0; a < 3; a++) {
            lights[0].dir[a] = cam.right[a] * v[0] + cam.up[a] * v[1] - cam.fwd[a] * v[2];
            lights[0].color[a] = 1 - p->ambient;
        }
    }
    for (int i = 0; i < p->nlights; i++) {
        double d[3] = {p->lights[i].direction[0], p->lights[i].direction[1],
                       p->lights[i].direction[2]};
        /* scaled to its largest component first: a tiny direction's square
         * underflows (check: not all zero) */
        double big = fmax(fabs(d[0]), fmax(fabs(d[1]), fabs(d[2])));
        for (int a = 0; a < 3; a++)
            d[a] /= big;
        vx_v3_unit(d);
        for (int a = 0; a < 3; a++) {
            lights[i].dir[a] = d[a];
            lights[i].color[a] = p->lights[i].color[a];
        }
    }
    vx_bl_shade_desc sd = {.lights = lights, .nlights = nl, .ambient = p->ambient};
    for (int a = 0; a < 3; a++) {
        sd.color[a] = p->color[a];
        sd.background[a] = p->background[a];
    }
    /* One frame holds the selected method's hits, the image and (for the
     * six panels) a panel's picture and the next method's hits; each big
     * buffer is made between two polls. */
    float *img = NULL, *rgb = NULL;
    vx_bl_hits h = {0}, keep = {0};
    int rc = -1;
    if (vx_stop_poll(err) || vx_bl_hits_alloc(&h, W, H, err) || vx_stop_poll(err)) goto out;
    img = malloc(sizeof(float) * 3 * (size_t)IW * IH);
    rgb = panels == 1 ? img : malloc(sizeof(float) * 3 * (size_t)W * H);
    if (!img || !rgb) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the image");
        goto out;
    }
    double t0 = vx_mono_ms();
    for (int k = 0; k < panels; k++) {
        /* the selected method first: its hits are the float outputs */
        int method = !p->compare ? p->normals : k;
        if (vx_stop_poll(err) || cast_method(s, p, &cam, method, &h, err)) goto out;
        sd.depth_only = method == VX_BL_DEPTH_ONLY;
        if (vx_bl_shade(&h, &sd, rgb, err)) goto out;
        if (p->compare) {
            float ink[3] = {0.1f, 0.1f, 0.1f};
            int sc = W >= 256 ? W / 128 : 1;
            vx_bl_label(rgb, W, H, 3 * sc, 3 * sc, sc, vx_bl_normals_names[method], ink);
        }
        int ox = (k % cols) * W, oy = (k / cols) * H;
        for (int y = 0; rgb != img && y < H; y++) {
            if (vx_stop_poll(err)) goto out;
            memcpy(img + 3 * ((size_t)(oy + y) * IW + ox), rgb + 3 * (size_t)y * W,
                   sizeof(float) * 3 * W);
        }
        if (method == p->normals) {
            keep = h;
            memset(&h, 0, sizeof h);
            if (k + 1 < panels && (vx_stop_poll(err) || vx_bl_hits_alloc(&h, W, H, err))) goto out;
        }
    }
    *render_ms += vx_mono_ms() - t0;
    t0 = vx_mono_ms();
    for (size_t i = 0; i < (size_t)W * H; i++) {
        if ((i & 0xfffff) == 0 && vx_stop_poll(err)) goto out;
        *covered += !isnan(keep.depth[i]);
    }
    const char *path = output(r, p, "image", f, "png", "image/png", err);
    if (!path || write_png(path, img, IW, IH, (int)p->bits, err)) goto out;
    static const char *pfm = "image/x-portable-floatmap";
    if (p->outputs[OUT_NORMAL] && (!(path = output(r, p, "normal", f, "pfm", pfm, err)) ||
                                   write_pfm(path, keep.nrm, W, H, 3, err)))
        goto out;
    if (p->outputs[OUT_POSITION] && (!(path = output(r, p, "position", f, "pfm", pfm, err)) ||
                                     write_pfm(path, keep.pos, W, H, 3, err)))
        goto out;
    if (p->outputs[OUT_DEPTH] && (!(path = output(r, p, "depth", f, "pfm", pfm, err)) ||
                                  write_pfm(path, keep.depth, W, H, 1, err)))
        goto out;
    *encode_ms += vx_mono_ms() - t0;
    rc = 0;
out:
    vx_bl_hits_free(&h);
    vx_bl_hits_free(&keep);
    if (rgb != img) free(rgb);
    free(img);
    return rc;
}

static int encode(vx_job_run *r, const rparams *pp, void *state, vx_err *err)
{
    const rparams p = *pp;
    rstate *s = state;
    double render_ms = 0, encode_ms = 0;
    uint64_t covered = 0;
    double fastest = INFINITY; /* seconds of the quickest frame so far */
    for (int f = 0; f < p.frames; f++) {
        double t0 = vx_mono_ms();
        if (render_frame(r, &p, s, f, &render_ms, &encode_ms, &covered, err)) return -1;
        if (vx_run_progress(r, 0.75 + 0.2 * (f + 1) / p.frames, err)) return -1;
        /* A turntable that cannot finish in time, even at its fastest
         * frame's pace, stops now rather than at the timeout. */
        fastest = fmin(fastest, (vx_mono_ms() - t0) / 1e3);
        const long left = p.frames - f - 1;
        if (left > 0 && left * fastest > vx_run_time_left(r))
            return vx_err_set(err, VX_ETIMEOUT, "job_timeout",
                              "the turntable would run past the job timeout of %g s: %ld of %ld "
                              "frames left at %.3g s or more each (fewer frames, or smaller ones)",
                              vx_run_limits(r)->job_timeout_s, left, p.frames, fastest);
    }
    if (p.outputs[OUT_VOXELS]) {
        double t0 = vx_mono_ms();
        const char *path = vx_run_output(r, "voxels", "vdb", "application/x-openvdb", err);
        int dims[3] = {(int)p.N, (int)p.N, (int)p.N};
        if (!path || vx_voxel_write_vdb_float(s->vn.f, dims, s->vn.origin, s->vn.h, "density",
                                              vx_run_mesh_id(r), path, err))
            return -1;
        encode_ms += vx_mono_ms() - t0;
    }
    cJSON *st = vx_run_stats(r);
    stat_set(st, "N", (double)p.N);
    stat_set(st, "R", (double)p.R);
    stat_set(st, "M", (double)(p.L * p.N));
    stat_set(st, "iso", p.iso);
    stat_set(st, "meshes", 1 + p.nmeshes);
    cJSON *in = cJSON_AddArrayToObject(st, "inside");
    for (int k = 0; in && k < 1 + p.nmeshes; k++)
        cJSON_AddItemToArray(in, cJSON_CreateString(vx_inside_names[s->inside[k]]));
    stat_set(st, "box_size", s->P);
    stat_set(st, "mean_density", s->spec[0]);
    stat_set(st, "pixels_covered", (double)covered);
    stat_set(st, "sampling_ms", s->sampling_ms);
    stat_set(st, "lowpass_ms", s->lowpass_ms);
    stat_set(st, "interp_ms", s->interp_ms);
    stat_set(st, "render_ms", render_ms);
    stat_set(st, "encode_ms", encode_ms);
    stat_set(st, "peak_bytes", (double)s->peak);
    return 0;
}

/* The caster, the shader and the writers poll the stop hook: the job's time
 * limit and cancel reach into them. */
static int stop_hook(void *ud, vx_err *err)
{
    return vx_run_progress(ud, 0, err);
}

static int render_run_cpu(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    vx_stop_set(stop_hook, r);
    int rc = run_cpu(r, params, state, err);
    vx_stop_set(NULL, NULL);
    return rc;
}

static int render_encode(vx_job_run *r, const void *params, void *state, vx_err *err)
{
    vx_stop_set(stop_hook, r);
    int rc = encode(r, params, state, err);
    vx_stop_set(NULL, NULL);
    return rc;
}

/* The voxels output of meshes whose box makes voxels under what OpenVDB's
 * transforms take: 422 at submission, from the meshes' union bbox. */
static int render_check_mesh(const void *params, const cJSON *meta, const vx_limits *lim,
                             vx_err *err)
{
    const rparams *p = params;
    (void)lim;
    if (!p->outputs[OUT_VOXELS]) return 0;
    const cJSON *bb = cJSON_GetObjectItemCaseSensitive(meta, "bbox");
    const cJSON *lo = cJSON_GetObjectItemCaseSensitive(bb, "min");
    const cJSON *hi = cJSON_GetObjectItemCaseSensitive(bb, "max");
    if (cJSON_GetArraySize(lo) != 3 || cJSON_GetArraySize(hi) != 3) return 0;
    double ext = 0;
    for (int a = 0; a < 3; a++) {
        double d = cJSON_GetNumberValue(cJSON_GetArrayItem(hi, a)) -
                   cJSON_GetNumberValue(cJSON_GetArrayItem(lo, a));
        if (d > ext) ext = d;
    }
    return ext > 0 ? voxels_fit(p, ext * (1 + 2 * VX_BL_PAD), "invalid_params", err) : 0;
}

const vx_kind vx_kind_render = {
    .name = "render",
    .summary = "Band-limited iso-surface render of one or more meshes (seed 002): Algorithm I "
               "low-pass, zero-padded interpolation, spectral normals; PNG, PFM and VDB outputs",
    .spec = spec,
    .params_size = sizeof(rparams),
    .check = render_check,
    .check_mesh = render_check_mesh,
    .run_gl = render_run_gl,
    .run_cpu = render_run_cpu,
    .encode = render_encode,
    .free_state = render_free_state,
    .mesh_refs = render_mesh_refs,
};
