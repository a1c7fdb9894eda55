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

/* The params as given, in double: the normalised JSON echoes these rather
 * than their float conversions (0.85, not 0.85000002384185791). */
typedef struct pv_params {
    double azimuth, elevation;
    long width, height;
    double fov, color[3], background[4], ambient;
    long samples;
} pv_params;

static const double def_color[3] = {0.8, 0.8, 0.85}, def_bg[4] = {1, 1, 1, 1};
static const vx_pspec unit_item = VX_P_ITEM_NUM(0, 1);

static const vx_pspec spec[] = {
    VX_P_NUM(pv_params, azimuth, 30, -360, 360, "orbit camera azimuth in degrees"),
    VX_P_NUM(pv_params, elevation, 20, -89, 89, "orbit camera elevation in degrees"),
    VX_P_INT(pv_params, width, 512, 16, 8192, "image width in pixels"),
    VX_P_INT(pv_params, height, 512, 16, 8192, "image height in pixels"),
    VX_P_NUM(pv_params, fov, 30, 0, 120, "vertical field of view in degrees, 0 = orthographic"),
    VX_P_VEC(pv_params, color, 3, def_color, &unit_item, "surface colour, linear RGB"),
    VX_P_VEC(pv_params, background, 4, def_bg, &unit_item, "background RGBA"),
    VX_P_NUM(pv_params, ambient, 0.2, 0, 1, "ambient light share"),
    VX_P_INT(pv_params, samples, 4, 1, 8, "MSAA samples: 1, 2, 4 or 8"),
    VX_P_END,
};

/* The picture read back (4 bytes a pixel) and the single-sample color and
 * depth targets (8): what a software renderer keeps in host memory
 * (llvmpipe: ~8.4 bytes a pixel measured at 4096^2 for 1 to 8 samples; a
 * GPU holds the multisample targets in its own memory), against the job
 * memory limit: at submission 422 invalid_params, in the job (the limit
 * may have changed since) job_memory_limit. */
static int check_memory(long width, long height, const vx_limits *lim, int submission, vx_err *err)
{
    uint64_t bytes = (uint64_t)width * (uint64_t)height * 12;
    if (!lim || !lim->max_job_memory || bytes <= lim->max_job_memory) return 0;
    return vx_err_set(err, submission ? VX_EUNPROC : VX_ETOOBIG,
                      submission ? "invalid_params" : "job_memory_limit",
                      "%sa %ldx%ld preview needs %llu bytes (12 a pixel: the picture and its "
                      "color and depth targets), over the job memory limit of %llu",
                      submission ? "params.width * params.height: " : "", width, height,
                      (unsigned long long)bytes, (unsigned long long)lim->max_job_memory);
}

static int preview_check(void *params, const vx_limits *lim, vx_err *err)
{
    const pv_params *x = params;
    if (x->samples != 1 && x->samples != 2 && x->samples != 4 && x->samples != 8)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.samples must be 1, 2, 4 or 8, got %ld", x->samples);
    if (lim && lim->max_image_pixels &&
        (uint64_t)x->width * (uint64_t)x->height > lim->max_image_pixels)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.width * params.height = %ld exceeds the limit of %llu pixels",
                          x->width * x->height, (unsigned long long)lim->max_image_pixels);
    return check_memory(x->width, x->height, lim, 1, err);
}

/* The renderer's params (float) from the job's. */
static void to_render(const pv_params *x, vx_preview_params *p)
{
    memset(p, 0, sizeof *p); /* the fields params do not set: no poll, automatic bands */
    p->azimuth_deg = x->azimuth;
    p->elevation_deg = x->elevation;
    p->fov_deg = x->fov;
    p->width = (int)x->width;
    p->height = (int)x->height;
    for (int i = 0; i < 3; i++)
        p->color[i] = (float)x->color[i];
    for (int i = 0; i < 4; i++)
        p->background[i] = (float)x->background[i];
    p->ambient = (float)x->ambient;
    p->samples = (int)x->samples;
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

static int preview_run_gl(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                          vx_err *err)
{
    vx_preview_params p;
    to_render(params, &p);
    if (check_memory(p.width, p.height, vx_run_limits(r), 0, err)) return -1;
    uint64_t bytes = (uint64_t)p.width * (uint64_t)p.height * 4; /* the picture's own buffer */
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

static int preview_encode(vx_job_run *r, const void *params, void *state, vx_err *err)
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
    .spec = spec,
    .params_size = sizeof(pv_params),
    .check = preview_check,
    .run_gl = preview_run_gl,
    .run_cpu = NULL,
    .encode = preview_encode,
    .free_state = preview_free_state,
};
