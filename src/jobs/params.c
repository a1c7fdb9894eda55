/* Typed, range-checked reads of job parameters (kind.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jobs/kind.h"
#include "store/store.h"

int vx_param_number(const cJSON *params, const char *field, double def, double lo, double hi,
                    double *out, vx_err *err)
{
    const cJSON *it = params ? cJSON_GetObjectItemCaseSensitive(params, field) : NULL;
    if (!it || cJSON_IsNull(it)) {
        *out = def;
        return 0;
    }
    if (!cJSON_IsNumber(it) || !isfinite(it->valuedouble))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s must be a number", field);
    if (it->valuedouble < lo || it->valuedouble > hi)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.%s must be in [%g, %g], got %g", field, lo, hi, it->valuedouble);
    *out = it->valuedouble;
    return 0;
}

int vx_param_int(const cJSON *params, const char *field, long def, long lo, long hi, long *out,
                 vx_err *err)
{
    double d;
    if (vx_param_number(params, field, (double)def, (double)lo, (double)hi, &d, err)) return -1;
    if (d != floor(d))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s must be an integer", field);
    *out = (long)d;
    return 0;
}

int vx_param_bool(const cJSON *params, const char *field, int def, int *out, vx_err *err)
{
    const cJSON *it = params ? cJSON_GetObjectItemCaseSensitive(params, field) : NULL;
    if (!it || cJSON_IsNull(it)) {
        *out = def;
        return 0;
    }
    if (!cJSON_IsBool(it))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s must be true or false",
                          field);
    *out = cJSON_IsTrue(it);
    return 0;
}

int vx_param_only_in(const cJSON *obj, const char *prefix, const char *const *known, vx_err *err)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, obj)
    {
        int ok = 0;
        for (size_t i = 0; known[i]; i++)
            if (strcmp(known[i], it->string) == 0) ok = 1;
        if (!ok)
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown parameter params.%s%s",
                              prefix, it->string);
    }
    return 0;
}

int vx_param_object(const cJSON **params, const char *const *known, vx_err *err)
{
    if (*params && cJSON_IsNull(*params)) *params = NULL;
    if (!*params) return 0;
    if (!cJSON_IsObject(*params))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params must be an object");
    return vx_param_only(*params, known, err);
}

int vx_param_only(const cJSON *params, const char *const *known, vx_err *err)
{
    return vx_param_only_in(params, "", known, err);
}

int vx_param_mesh_ids(const cJSON *params, const char *field, size_t max, const cJSON **out,
                      vx_err *err)
{
    const cJSON *it = params ? cJSON_GetObjectItemCaseSensitive(params, field) : NULL;
    *out = NULL;
    if (!it || cJSON_IsNull(it)) return 0;
    if (!cJSON_IsArray(it))
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.%s must be an array of mesh ids", field);
    size_t n = (size_t)cJSON_GetArraySize(it);
    if (n > max)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "params.%s has %zu entries (at most %zu)", field, n, max);
    const cJSON *e;
    size_t i = 0;
    cJSON_ArrayForEach(e, it)
    {
        if (!cJSON_IsString(e) || !vx_store_valid_mesh_id(e->valuestring))
            return vx_err_set(err, VX_EUNPROC, "invalid_params",
                              "params.%s[%zu] is not a mesh id (64 lowercase hex digits)", field,
                              i);
        i++;
    }
    *out = it;
    return 0;
}

int vx_param_enum_in(const cJSON *obj, const char *prefix, const char *field,
                     const char *const *names, int def, int *out, vx_err *err)
{
    const cJSON *it = obj ? cJSON_GetObjectItemCaseSensitive(obj, field) : NULL;
    if (!it || cJSON_IsNull(it)) {
        *out = def;
        return 0;
    }
    if (cJSON_IsString(it))
        for (int i = 0; names[i]; i++)
            if (strcmp(names[i], it->valuestring) == 0) {
                *out = i;
                return 0;
            }
    char list[256] = "";
    for (int i = 0; names[i]; i++)
        snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", i ? ", " : "", names[i]);
    return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s%s must be one of %s", prefix,
                      field, list);
}

int vx_param_enum(const cJSON *params, const char *field, const char *const *names, int def,
                  int *out, vx_err *err)
{
    return vx_param_enum_in(params, "", field, names, def, out, err);
}

cJSON *vx_params_normalize(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err)
{
    cJSON *norm = k->parse(params, lim, err);
    if (!norm) return NULL;
    /* What the journal keeps and the runner reads back. */
    char *text = cJSON_PrintUnformatted(norm);
    cJSON *back = text ? cJSON_Parse(text) : NULL;
    free(text);
    if (!back) {
        cJSON_Delete(norm);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to check the params");
        return NULL;
    }
    vx_err e2;
    vx_err_clear(&e2);
    cJSON *again = k->parse(back, lim, &e2);
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
