/* Job params through a kind's spec: read, check, normalise (kind.h). */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jobs/kind.h"
#include "util/json.h"

void *vx_kind_read(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err)
{
    void *p = calloc(1, k->params_size ? k->params_size : 1);
    if (!p) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %s params", k->name);
        return NULL;
    }
    if (vx_spec_read(k->spec, params, lim, p, err) || (k->check && k->check(p, lim, err))) {
        vx_kind_params_free(k, p);
        return NULL;
    }
    return p;
}

void vx_kind_params_free(const vx_kind *k, void *params)
{
    if (!params) return;
    vx_spec_free(k->spec, params);
    free(params);
}

cJSON *vx_kind_parse(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err)
{
    void *p = vx_kind_read(k, params, lim, err);
    if (!p) return NULL;
    cJSON *o = vx_spec_write(k->spec, p);
    vx_kind_params_free(k, p);
    if (!o) vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %s params", k->name);
    return o;
}

cJSON *vx_params_normalize(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err)
{
    cJSON *norm = vx_kind_parse(k, params, lim, err);
    if (!norm) return NULL;
    /* What the journal keeps and the runner reads back. */
    char *text = vx_json_print(norm, 0);
    cJSON *back = text ? cJSON_Parse(text) : NULL;
    free(text);
    if (!back) {
        cJSON_Delete(norm);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to check the params");
        return NULL;
    }
    vx_err e2;
    vx_err_clear(&e2);
    cJSON *again = vx_kind_parse(k, back, lim, &e2);
    cJSON_Delete(back);
    if (!again) {
        cJSON_Delete(norm);
        if (e2.kind == VX_EUNPROC) {
            /* a default or a derived value is out of range: name it */
            vx_err_set(err, VX_EUNPROC, "invalid_params", "%.400s (with the defaults filled in)",
                       e2.message);
        } else {
            *err = e2;
        }
        return NULL;
    }
    int same = cJSON_Compare(norm, again, 1);
    cJSON_Delete(again);
    if (!same) {
        cJSON_Delete(norm);
        vx_err_set(err, VX_EUNPROC, "invalid_params",
                   "params: the %s params do not read back the same once normalised", k->name);
        return NULL;
    }
    return norm;
}

const vx_kind *vx_kinds_find(const vx_kinds *t, const char *name)
{
    for (size_t i = 0; t && name && i < t->n; i++)
        if (strcmp(t->rows[i]->name, name) == 0) return t->rows[i];
    return NULL;
}
