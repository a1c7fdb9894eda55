/* The `preview` row of the job table (kind.h). Kept apart from render.c so
 * that programs using only the renderer need not link the job runner. */
#include <stdlib.h>
#include <string.h>

#include "image/png.h"
#include "preview/preview.h"
#include "util/log.h"

typedef struct preview_state {
    int width, height;
    uint8_t *rgba;
} preview_state;

static const char *const known[] = {"azimuth", "elevation",  "width",   "height",  "fov",
                                    "color",   "background", "ambient", "samples", NULL};

/* Optional [r,g,b] / [r,g,b,a] array of numbers in 0..1. */
static int param_rgba(const cJSON *params, const char *field, int n, const double *def, double *out,
                      vx_err *err)
{
    const cJSON *it = params ? cJSON_GetObjectItemCaseSensitive(params, field) : NULL;
    if (!it || cJSON_IsNull(it)) {
        for (int i = 0; i < n; i++)
            out[i] = def[i];
        return 0;
    }
    if (!cJSON_IsArray(it) || cJSON_GetArraySize(it) != n)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.%s must be an array of %d numbers in [0, 1]", field, n);
    for (int i = 0; i < n; i++) {
        const cJSON *v = cJSON_GetArrayItem(it, i);
        if (!cJSON_IsNumber(v) || !(v->valuedouble >= 0 && v->valuedouble <= 1))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.%s[%d] must be a number in [0, 1]", field, i);
        out[i] = v->valuedouble;
    }
    return 0;
}

/* The params as given, in double: the normalised JSON echoes these rather
 * than their float conversions (0.85, not 0.85000002384185791). */
typedef struct exact {
    double color[3], background[4], ambient;
} exact;

/* Reads and validates params into p (and x); the one place that knows the
 * fields, their ranges and defaults (parse and run_gl both use it). */
static int read_params(const cJSON *params, const vx_limits *lim, vx_preview_params *p, exact *x,
                       vx_err *err)
{
    memset(p, 0, sizeof *p); /* the fields params do not set: no poll, automatic bands */
    if (vx_param_object(&params, known, err)) return -1;
    static const double def_color[3] = {0.8, 0.8, 0.85}, def_bg[4] = {1, 1, 1, 1};
    long w, h, samples;
    if (vx_param_number(params, "azimuth", 30, -360, 360, &p->azimuth_deg, err) ||
        vx_param_number(params, "elevation", 20, -89, 89, &p->elevation_deg, err) ||
        vx_param_int(params, "width", 512, 16, 8192, &w, err) ||
        vx_param_int(params, "height", 512, 16, 8192, &h, err) ||
        vx_param_number(params, "fov", 30, 0, 120, &p->fov_deg, err) ||
        param_rgba(params, "color", 3, def_color, x->color, err) ||
        param_rgba(params, "background", 4, def_bg, x->background, err) ||
        vx_param_number(params, "ambient", 0.2, 0, 1, &x->ambient, err) ||
        vx_param_int(params, "samples", 4, 1, 8, &samples, err))
        return -1;
    if (samples != 1 && samples != 2 && samples != 4 && samples != 8)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.samples must be 1, 2, 4 or 8, got %ld", samples);
    if (lim && lim->max_image_pixels && (uint64_t)w * (uint64_t)h > lim->max_image_pixels)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.width * params.height = %ld exceeds the limit of %llu pixels",
                          w * h, (unsigned long long)lim->max_image_pixels);
    p->width = (int)w;
    p->height = (int)h;
    for (int i = 0; i < 3; i++)
        p->color[i] = (float)x->color[i];
    for (int i = 0; i < 4; i++)
        p->background[i] = (float)x->background[i];
    p->ambient = (float)x->ambient;
    p->samples = (int)samples;
    return 0;
}

static cJSON *rgba_array(const double *v, int n)
{
    cJSON *a = cJSON_CreateArray();
    for (int i = 0; a && i < n; i++) {
        cJSON *x = cJSON_CreateNumber(v[i]);
        if (!x || !cJSON_AddItemToArray(a, x)) {
            cJSON_Delete(x);
            cJSON_Delete(a);
            return NULL;
        }
    }
    return a;
}

static cJSON *preview_parse(const cJSON *params, const vx_limits *lim, vx_err *err)
{
    vx_preview_params p;
    exact x;
    if (read_params(params, lim, &p, &x, err)) return NULL;
    cJSON *o = cJSON_CreateObject();
    cJSON *color = rgba_array(x.color, 3), *bg = rgba_array(x.background, 4);
    if (!o || !color || !bg || !cJSON_AddNumberToObject(o, "azimuth", p.azimuth_deg) ||
        !cJSON_AddNumberToObject(o, "elevation", p.elevation_deg) ||
        !cJSON_AddNumberToObject(o, "width", p.width) ||
        !cJSON_AddNumberToObject(o, "height", p.height) ||
        !cJSON_AddNumberToObject(o, "fov", p.fov_deg) ||
        !cJSON_AddItemToObject(o, "color", color)) {
        cJSON_Delete(color);
        goto oom;
    }
    if (!cJSON_AddItemToObject(o, "background", bg)) goto oom;
    bg = NULL;
    if (!cJSON_AddNumberToObject(o, "ambient", x.ambient) ||
        !cJSON_AddNumberToObject(o, "samples", p.samples))
        goto oom;
    return o;
oom:
    cJSON_Delete(bg);
    cJSON_Delete(o);
    vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for preview params");
    return NULL;
}

/* The render's 0..1 is the job's 0..0.8; the PNG encoder has the rest. */
static int render_poll(void *ud, double fraction, vx_err *err)
{
    return vx_run_progress(ud, 0.8 * fraction, err);
}

static int encode_poll(void *ud, double fraction, vx_err *err)
{
    return vx_run_progress(ud, 0.8 + 0.2 * fraction, err);
}

static int preview_run_gl(vx_job_run *r, const vx_mesh *mesh, const cJSON *params, void **state,
                          vx_err *err)
{
    vx_preview_params p;
    exact x;
    if (read_params(params, vx_run_limits(r), &p, &x, err)) return -1;
    const vx_limits *lim = vx_run_limits(r);
    uint64_t bytes = (uint64_t)p.width * (uint64_t)p.height * 4;
    if (lim && lim->max_job_memory && bytes > lim->max_job_memory)
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                          "a %dx%d preview needs %llu bytes, over the job memory limit of %llu",
                          p.width, p.height, (unsigned long long)bytes,
                          (unsigned long long)lim->max_job_memory);
    preview_state *s = calloc(1, sizeof *s);
    if (s) s->rgba = malloc((size_t)bytes);
    if (!s || !s->rgba) {
        free(s);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a %dx%d preview",
                          p.width, p.height);
    }
    s->width = p.width;
    s->height = p.height;
    *state = s; /* from here on the runner frees it through free_state */

    vx_preview_stats st;
    p.poll = render_poll;
    p.poll_ud = r;
    if (vx_preview_render(vx_run_gl(r), mesh, &p, s->rgba, &st, err)) return -1;
    if (vx_run_progress(r, 0.8, err)) return -1;
    cJSON *stats = vx_run_stats(r);
    if (stats) {
        cJSON_AddNumberToObject(stats, "triangles", (double)mesh->ntris);
        cJSON_AddNumberToObject(stats, "width", p.width);
        cJSON_AddNumberToObject(stats, "height", p.height);
        cJSON_AddNumberToObject(stats, "pixels_covered", (double)st.pixels_covered);
        cJSON_AddNumberToObject(stats, "samples", st.samples);
        cJSON_AddNumberToObject(stats, "gpu_ms", st.gpu_ms);
        cJSON_AddNumberToObject(stats, "upload_ms", st.upload_ms);
    }
    return 0;
}

static int preview_encode(vx_job_run *r, const cJSON *params, void *state, vx_err *err)
{
    preview_state *s = state;
    const char *path = vx_run_output(r, "image", "png", "image/png", err);
    if (!path) return -1;
    vx_png_poll poll = {encode_poll, r};
    if (vx_png_write_path_poll(path, s->rgba, s->width, s->height, 4, 8, &poll, err)) return -1;
    return vx_run_progress(r, 1.0, err);
}

static void preview_free_state(void *state)
{
    preview_state *s = state;
    if (!s) return;
    free(s->rgba);
    free(s);
}

const vx_kind vx_kind_preview = {
    .name = "preview",
    .summary = "Shaded PNG of the mesh from an orbit camera (Lambert + ambient, MSAA)",
    .parse = preview_parse,
    .run_gl = preview_run_gl,
    .run_cpu = NULL,
    .encode = preview_encode,
    .free_state = preview_free_state,
};
