/* The `preview` job-table row: parameter parsing and normalisation, and the
 * run_gl -> encode -> free_state path through a stand-in for the job runner.
 *
 * The vx_run_* functions below replace the real runner's: the linker takes
 * them from this file, so the runner's object is never pulled out of
 * libvoxel.a for this program. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>
#include <png.h>

#include "gl/gl.h"
#include "preview/preview.h"

/* ---- stand-in runner ------------------------------------------------------ */

struct vx_job_run {
    vx_gl *gl;
    vx_limits lim;
    cJSON *stats;
    double progress;
    int calls;
    int cancel;
    char path[64];
    char output_name[32], content_type[32];
};

int vx_run_progress(vx_job_run *r, double fraction, vx_err *err)
{
    r->progress = fraction;
    r->calls++;
    if (r->cancel) return vx_err_set(err, VX_ECANCELED, "canceled", "job canceled");
    return 0;
}
vx_gl *vx_run_gl(vx_job_run *r)
{
    return r->gl;
}
const vx_limits *vx_run_limits(const vx_job_run *r)
{
    return &r->lim;
}
cJSON *vx_run_stats(vx_job_run *r)
{
    return r->stats;
}
const char *vx_run_output(vx_job_run *r, const char *name, const char *file_ext,
                          const char *content_type, vx_err *err)
{
    snprintf(r->output_name, sizeof r->output_name, "%s", name);
    snprintf(r->content_type, sizeof r->content_type, "%s", content_type);
    snprintf(r->path, sizeof r->path, "/tmp/vx_test_job_%d.%s", (int)getpid(), file_ext);
    return r->path;
}

/* ---- helpers -------------------------------------------------------------- */

static const vx_kind *K = &vx_kind_preview;

static cJSON *parse_str(const char *json, const vx_limits *lim, vx_err *err)
{
    cJSON *in = json ? cJSON_Parse(json) : NULL;
    if (json) assert_non_null(in);
    cJSON *out = vx_kind_parse(K, in, lim, err);
    cJSON_Delete(in);
    return out;
}

static double num(const cJSON *o, const char *f)
{
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(o, f);
    assert_true(cJSON_IsNumber(it));
    return it->valuedouble;
}

static void expect_invalid(const char *json, const vx_limits *lim, const char *mention)
{
    vx_err err = {0};
    cJSON *out = parse_str(json, lim, &err);
    if (out) fprintf(stderr, "accepted: %s\n", json);
    assert_null(out);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "invalid_params");
    if (!strstr(err.message, mention))
        fprintf(stderr, "message \"%s\" lacks \"%s\"\n", err.message, mention);
    assert_non_null(strstr(err.message, mention));
}

/* ---- tests ------------------------------------------------------------------ */

static void test_row(void **state)
{
    assert_string_equal(K->name, "preview");
    assert_non_null(K->summary);
    assert_non_null(K->spec);
    assert_non_null(K->run_gl);
    assert_null(K->run_cpu);
    assert_non_null(K->encode);
    assert_non_null(K->free_state);
    K->free_state(NULL);
}

static void test_defaults(void **state)
{
    vx_err err = {0};
    vx_limits lim = {0};
    const char *inputs[] = {NULL, "{}", "null"};
    for (int i = 0; i < 3; i++) {
        cJSON *o = parse_str(inputs[i], &lim, &err);
        assert_non_null(o);
        char *s = cJSON_PrintUnformatted(o);
        printf("defaults: %s\n", s);
        assert_string_equal(s, "{\"azimuth\":30,\"elevation\":20,\"width\":512,\"height\":512,"
                               "\"fov\":30,\"color\":[0.8,0.8,0.85],\"background\":[1,1,1,1],"
                               "\"ambient\":0.2,\"samples\":4}");
        free(s);
        cJSON_Delete(o);
    }
}

static void test_values_kept(void **state)
{
    vx_err err = {0};
    vx_limits lim = {.max_image_pixels = 1000 * 1000};
    cJSON *o = parse_str("{\"azimuth\":-360,\"elevation\":89,\"width\":1000,\"height\":1000,"
                         "\"fov\":0,\"color\":[0,0.5,1],\"background\":[0,0,0,0],"
                         "\"ambient\":1,\"samples\":8}",
                         &lim, &err);
    assert_non_null(o);
    assert_true(num(o, "azimuth") == -360);
    assert_true(num(o, "elevation") == 89);
    assert_true(num(o, "width") == 1000);
    assert_true(num(o, "fov") == 0);
    assert_true(num(o, "ambient") == 1);
    assert_true(num(o, "samples") == 8);
    const cJSON *c = cJSON_GetObjectItemCaseSensitive(o, "color");
    assert_int_equal(cJSON_GetArraySize(c), 3);
    assert_true(cJSON_GetArrayItem(c, 1)->valuedouble == 0.5);
    /* Parsing the normalised copy again gives the same object. */
    cJSON *again = vx_kind_parse(K, o, &lim, &err);
    assert_non_null(again);
    assert_true(cJSON_Compare(o, again, 1));
    cJSON_Delete(again);
    cJSON_Delete(o);
}

static void test_invalid(void **state)
{
    vx_limits lim = {.max_image_pixels = 1024 * 1024};
    expect_invalid("{\"zoom\":2}", &lim, "zoom");
    expect_invalid("[1,2]", &lim, "object");
    expect_invalid("{\"azimuth\":361}", &lim, "azimuth");
    expect_invalid("{\"azimuth\":\"30\"}", &lim, "azimuth");
    expect_invalid("{\"elevation\":90}", &lim, "elevation");
    expect_invalid("{\"width\":15}", &lim, "width");
    expect_invalid("{\"width\":8193}", &lim, "width");
    expect_invalid("{\"height\":100.5}", &lim, "height");
    expect_invalid("{\"fov\":121}", &lim, "fov");
    expect_invalid("{\"fov\":-1}", &lim, "fov");
    expect_invalid("{\"color\":[1,1]}", &lim, "color");
    expect_invalid("{\"color\":[1,1,1,1]}", &lim, "color");
    expect_invalid("{\"color\":[1,1,2]}", &lim, "color");
    expect_invalid("{\"color\":\"red\"}", &lim, "color");
    expect_invalid("{\"background\":[1,1,1]}", &lim, "background");
    expect_invalid("{\"background\":[1,1,1,null]}", &lim, "background");
    expect_invalid("{\"ambient\":1.5}", &lim, "ambient");
    expect_invalid("{\"samples\":3}", &lim, "samples");
    expect_invalid("{\"samples\":16}", &lim, "samples");
    expect_invalid("{\"samples\":0}", &lim, "samples");
    /* 2048 x 1024 = 2 Mpx > the 1 Mpx limit; each side alone is fine. */
    expect_invalid("{\"width\":2048,\"height\":1024}", &lim, "limit");
    vx_err err = {0};
    cJSON *o = parse_str("{\"width\":1024,\"height\":1024}", &lim, &err);
    assert_non_null(o);
    cJSON_Delete(o);
    /* No limit configured: the range check alone applies. */
    vx_limits none = {0};
    o = parse_str("{\"width\":8192,\"height\":8192}", &none, &err);
    assert_non_null(o);
    cJSON_Delete(o);
}

static vx_mesh *cube(void)
{
    static const double v[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                   {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
    static const uint32_t q[6][4] = {{4, 5, 6, 7}, {1, 0, 3, 2}, {5, 1, 2, 6},
                                     {0, 4, 7, 3}, {7, 6, 2, 3}, {0, 1, 5, 4}};
    vx_mesh *m = vx_mesh_new();
    m->nverts = 8;
    m->pos = malloc(sizeof v);
    memcpy(m->pos, v, sizeof v);
    m->nfaces = 6;
    m->face_start = malloc(7 * sizeof(uint32_t));
    m->face_idx = malloc(sizeof q);
    for (int f = 0; f <= 6; f++)
        m->face_start[f] = 4u * (uint32_t)f;
    memcpy(m->face_idx, q, sizeof q);
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    return m;
}

static void test_run(void **state)
{
    vx_err err = {0};
    vx_gl *gl = vx_gl_new(NULL, &err);
    assert_non_null(gl);
    vx_job_run r = {.gl = gl, .stats = cJSON_CreateObject()};
    cJSON *params = parse_str("{\"width\":96,\"height\":64,\"azimuth\":0,\"elevation\":0,"
                              "\"background\":[0,0,0,1]}",
                              &r.lim, &err);
    assert_non_null(params);
    void *tp = vx_kind_read(K, params, &r.lim, &err); /* as the runner does, once */
    assert_non_null(tp);
    vx_mesh *m = cube();
    void *st = NULL;
    assert_int_equal(K->run_gl(&r, m, tp, &st, &err), 0);
    assert_non_null(st);
    /* The render polls as it goes (upload, bands); it ends at 0.8, the
     * encoder has the rest. */
    assert_true(r.progress == 0.8);
    assert_true(r.calls >= 3);
    char *s = cJSON_PrintUnformatted(r.stats);
    printf("stats: %s\n", s);
    free(s);
    assert_true(num(r.stats, "triangles") == 12);
    assert_true(num(r.stats, "width") == 96);
    assert_true(num(r.stats, "height") == 64);
    assert_true(num(r.stats, "pixels_covered") > 0);
    assert_true(num(r.stats, "gpu_ms") >= 0);
    assert_true(num(r.stats, "upload_ms") >= 0);
    assert_int_equal(K->encode(&r, tp, st, &err), 0);
    assert_true(r.progress == 1.0);
    assert_string_equal(r.output_name, "image");
    assert_string_equal(r.content_type, "image/png");
    K->free_state(st);

    /* The PNG is RGBA 8-bit, the right size, black around a lit cube. */
    png_image img;
    memset(&img, 0, sizeof img);
    img.version = PNG_IMAGE_VERSION;
    assert_true(png_image_begin_read_from_file(&img, r.path));
    assert_int_equal(img.width, 96);
    assert_int_equal(img.height, 64);
    assert_int_equal(PNG_IMAGE_SAMPLE_CHANNELS(img.format), 4);
    img.format = PNG_FORMAT_RGBA;
    uint8_t px[96 * 64 * 4];
    assert_true(png_image_finish_read(&img, NULL, px, 0, NULL));
    assert_int_equal(px[0], 0);
    assert_int_equal(px[3], 255);
    const uint8_t *c = px + 4 * (32 * 96 + 48);
    assert_true(c[0] > 100);
    unlink(r.path);

    /* Cancelled at the progress report: -1 with the runner's error, and the
     * state is still handed over for free_state. */
    r.cancel = 1;
    st = NULL;
    assert_int_equal(K->run_gl(&r, m, tp, &st, &err), -1);
    assert_int_equal(err.kind, VX_ECANCELED);
    K->free_state(st);

    /* The job memory limit is checked before allocating. */
    r.cancel = 0;
    r.lim.max_job_memory = 1000;
    st = NULL;
    assert_int_equal(K->run_gl(&r, m, tp, &st, &err), -1);
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_null(st);

    vx_kind_params_free(K, tp);
    cJSON_Delete(params);
    cJSON_Delete(r.stats);
    vx_mesh_free(m);
    vx_gl_free(gl);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_row),         cmocka_unit_test(test_defaults),
        cmocka_unit_test(test_values_kept), cmocka_unit_test(test_invalid),
        cmocka_unit_test(test_run),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
