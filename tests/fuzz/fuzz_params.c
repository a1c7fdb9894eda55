/* libFuzzer target: every job kind's params reader. The first byte picks the
 * kind (byte % kinds) and the limits (byte / kinds: the daemon's defaults,
 * none, small ones); the rest is the params JSON. Oracle, as the runner and
 * the journal replay need it: when parse accepts, the normalised params
 * print, parse back as JSON and are accepted again by the kind with an
 * identical normalised result; vx_params_normalize, which the daemon
 * submits through, agrees with that; no crash, no leak. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jobs/kind.h"
#include "kinds.h"

static const vx_limits presets[] = {
    /* the daemon's defaults (daemon/config.c) */
    {.max_upload_bytes = 1ull << 30,
     .max_triangles = 20000000,
     .max_image_pixels = 67108864,
     .max_job_memory = 4ull << 30,
     .job_timeout_s = 600},
    /* none */
    {0},
    /* small */
    {.max_upload_bytes = 1 << 20,
     .max_triangles = 1000,
     .max_image_pixels = 64 * 64,
     .max_job_memory = 16 << 20,
     .job_timeout_s = 2},
};

static void fail(const char *what, const vx_kind *k, const char *text, const vx_err *err)
{
    fprintf(stderr, "fuzz_params: %s: kind %s\n  params: %.2000s\n  error: %s %s\n", what, k->name,
            text ? text : "(none)", err ? err->code : "-", err ? err->message : "-");
    abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (size < 1) return 0;
    size_t nk = vx_kind_count();
    const vx_kind *k = vx_kind_at(data[0] % nk);
    const vx_limits *lim = &presets[(data[0] / nk) % (sizeof presets / sizeof presets[0])];
    cJSON *in = cJSON_ParseWithLength((const char *)data + 1, size - 1);
    if (!in && size > 1) return 0; /* not JSON: the HTTP layer answers 400 */
    vx_err err;
    vx_err_clear(&err);
    cJSON *norm = vx_kind_parse(k, in, lim, &err);
    if (!norm) {
        if (err.kind == VX_EOK || !err.code[0])
            fail("parse failed without saying why", k, NULL, &err);
        if (err.kind == VX_EUNPROC && strncmp(err.message, "params", 6) != 0 &&
            strncmp(err.message, "unknown parameter params", 24) != 0)
            fail("invalid params error does not name the field", k, NULL, &err);
    } else {
        char *text = cJSON_PrintUnformatted(norm);
        if (!text) fail("normalised params do not print", k, NULL, NULL);
        cJSON *back = cJSON_Parse(text);
        if (!back) fail("printed params do not parse back", k, text, NULL);
        vx_err err2;
        vx_err_clear(&err2);
        cJSON *again = vx_kind_parse(k, back, lim, &err2);
        if (!again) fail("normalised params are refused", k, text, &err2);
        if (!cJSON_Compare(norm, again, 1)) {
            char *t2 = cJSON_PrintUnformatted(again);
            fprintf(stderr, "  second: %.2000s\n", t2 ? t2 : "");
            fail("normalised params normalise differently", k, text, NULL);
        }
        cJSON_Delete(again);
        cJSON_Delete(back);
        free(text);
    }
    /* The daemon's path: the same verdict, the same params. */
    vx_err err3;
    vx_err_clear(&err3);
    cJSON *n3 = vx_params_normalize(k, in, lim, &err3);
    if ((n3 != NULL) != (norm != NULL)) fail("vx_params_normalize disagrees", k, NULL, &err3);
    if (n3 && !cJSON_Compare(n3, norm, 1)) fail("vx_params_normalize differs", k, NULL, NULL);
    if (!n3 && strcmp(err3.code, err.code) != 0)
        fail("vx_params_normalize: other error", k, NULL, &err3);
    cJSON_Delete(n3);
    cJSON_Delete(norm);
    cJSON_Delete(in);
    return 0;
}
