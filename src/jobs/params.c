/* Typed, range-checked reads of job parameters (kind.h). */
#include <math.h>
#include <string.h>

#include "jobs/kind.h"

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
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s must be in [%g, %g], got %g",
                          field, lo, hi, it->valuedouble);
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
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "params.%s must be true or false", field);
    *out = cJSON_IsTrue(it);
    return 0;
}

int vx_param_only(const cJSON *params, const char *const *known, vx_err *err)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, params)
    {
        int ok = 0;
        for (size_t i = 0; known[i]; i++)
            if (strcmp(known[i], it->string) == 0) ok = 1;
        if (!ok)
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown parameter params.%s",
                              it->string);
    }
    return 0;
}
