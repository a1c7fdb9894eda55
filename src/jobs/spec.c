/* The generic params reader and writer (spec.h). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "jobs/kind.h"
#include "store/store.h"

#define BAD(...) vx_err_set(err, VX_EUNPROC, "invalid_params", __VA_ARGS__)

static int *set_flag(const vx_pspec *f, char *base)
{
    return f->flags & (VX_PF_SET | VX_PF_NULLABLE) ? (int *)(base + f->set_off) : NULL;
}

/* "a, b, c" (sep ", ") or "a, b or c" (last " or "). */
static void name_list(const char *const *names, const char *last, char *buf, size_t n)
{
    buf[0] = 0;
    for (int i = 0; names[i]; i++)
        snprintf(buf + strlen(buf), n - strlen(buf), "%s%s",
                 i == 0         ? ""
                 : names[i + 1] ? ", "
                                : last,
                 names[i]);
}

/* "a, b, c": the names of the fields of list. */
static void field_list(const vx_pspec *list, char *buf, size_t n)
{
    buf[0] = 0;
    for (const vx_pspec *s = list; s->name; s++)
        snprintf(buf + strlen(buf), n - strlen(buf), "%s%s", s == list ? "" : ", ", s->name);
}

static const vx_pspec *sibling(const vx_pspec *list, const char *name)
{
    for (; list && list->name; list++)
        if (strcmp(list->name, name) == 0) return list;
    return NULL;
}

static int read_object(const vx_pspec *list, const cJSON *obj, char *base, const char *prefix,
                       const vx_limits *lim, vx_err *err);

static int read_number(const vx_pspec *f, const cJSON *it, double lo, double hi, const char *path,
                       double *out, vx_err *err)
{
    if ((f->flags & VX_PF_TERSE) && !(cJSON_IsNumber(it) && isfinite(it->valuedouble) &&
                                      it->valuedouble > lo && it->valuedouble <= hi))
        return BAD("params.%s must be a number > %g", path, lo);
    if (!cJSON_IsNumber(it)) return BAD("params.%s must be a number", path);
    if (!isfinite(it->valuedouble))
        return BAD("params.%s must be a finite number (it is past the largest double)", path);
    double v = it->valuedouble;
    /* the value as given (360.0001, not %g's 360) */
    if ((f->flags & VX_PF_GT_LO) && v <= lo)
        return BAD("params.%s must be > %g, got %.15g", path, lo, v);
    if (v < lo || v > hi)
        return BAD("params.%s must be in %c%g, %g], got %.15g", path,
                   f->flags & VX_PF_GT_LO ? '(' : '[', lo, hi, v);
    *out = v == 0 ? 0 : v; /* -0 as 0: the same normalised params (reuse, keys) */
    return 0;
}

static int read_enum(const vx_pspec *f, const cJSON *it, const char *path, int *out, vx_err *err)
{
    if (cJSON_IsString(it))
        for (int i = 0; f->names[i]; i++)
            if (strcmp(f->names[i], it->valuestring) == 0) {
                *out = i;
                return 0;
            }
    char list[256];
    name_list(f->names, ", ", list, sizeof list);
    return BAD("params.%s must be one of %s", path, list);
}

static int read_enum_set(const vx_pspec *f, const cJSON *it, const char *path, int *out,
                         vx_err *err)
{
    char list[256];
    if (!cJSON_IsArray(it)) {
        name_list(f->names, ", ", list, sizeof list);
        return BAD("params.%s must be an array of %s", path, list);
    }
    const cJSON *e;
    uint64_t seen = 0; /* a set: each name at most once (uniqueItems) */
    cJSON_ArrayForEach(e, it)
    {
        int k = -1;
        for (int i = 0; cJSON_IsString(e) && f->names[i] && i < 64; i++)
            if (strcmp(f->names[i], e->valuestring) == 0) k = i;
        if (k < 0) {
            name_list(f->names, " or ", list, sizeof list);
            return BAD("params.%s entries must be %s", path, list);
        }
        if (seen >> k & 1) return BAD("params.%s lists \"%s\" twice", path, f->names[k]);
        seen |= (uint64_t)1 << k;
        out[k] = 1;
    }
    return 0;
}

static int read_field(const vx_pspec *f, const vx_pspec *list, const cJSON *it, char *base,
                      const char *path, const vx_limits *lim, vx_err *err);

/* Whether an item number range is worth printing. */
static int bounded(const vx_pspec *it)
{
    return isfinite(it->lo) || isfinite(it->hi);
}

static int array_shape_err(const vx_pspec *f, const char *path, int n, vx_err *err)
{
    const vx_pspec *it = f->sub;
    if (it->type == VX_PT_MESH_ID) {
        if (n < 0) return BAD("params.%s must be an array of mesh ids", path);
        return BAD("params.%s has %d entries (at most %d)", path, n, f->max_items);
    }
    if (it->type == VX_PT_OBJECT) {
        char names[256];
        field_list(it->sub, names, sizeof names);
        return BAD("params.%s must be an array of at most %d {%s}", path, f->max_items, names);
    }
    const char *what = it->type == VX_PT_INT ? "integers" : "numbers";
    if (f->min_items == f->max_items && it->type == VX_PT_NUMBER && bounded(it))
        return BAD("params.%s must be an array of %d %s in [%g, %g]", path, f->max_items, what,
                   it->lo, it->hi);
    if (f->min_items == f->max_items)
        return BAD("params.%s must be an array of %d %s", path, f->max_items, what);
    return BAD("params.%s must be an array of %d to %d %s", path, f->min_items, f->max_items, what);
}

static int read_item(const vx_pspec *it, const cJSON *e, char *p, const char *apath,
                     const char *path, const vx_limits *lim, vx_err *err)
{
    if (it->type == VX_PT_OBJECT && !cJSON_IsObject(e))
        return BAD("params.%s[] must be objects", apath);
    if (it->type == VX_PT_NUMBER) {
        if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble) || e->valuedouble < it->lo ||
            e->valuedouble > it->hi)
            return bounded(it) ? BAD("params.%s must be a number in [%g, %g]", path, it->lo, it->hi)
                               : BAD("params.%s must be a number", path);
        *(double *)p = e->valuedouble;
        return 0;
    }
    if (it->type == VX_PT_INT) {
        if (!cJSON_IsNumber(e) || e->valuedouble != floor(e->valuedouble) ||
            e->valuedouble < it->lo || e->valuedouble > it->hi)
            return BAD("params.%s must be an integer in [%g, %g]", path, it->lo, it->hi);
        *(long *)p = (long)e->valuedouble;
        return 0;
    }
    return read_field(it, NULL, e, p - it->off, path, lim, err);
}

static int read_array(const vx_pspec *f, const cJSON *a, char *base, const char *path,
                      const vx_limits *lim, vx_err *err)
{
    if (!cJSON_IsArray(a)) return array_shape_err(f, path, -1, err);
    int n = cJSON_GetArraySize(a);
    if (n < f->min_items || n > f->max_items) return array_shape_err(f, path, n, err);
    const cJSON *e;
    int i = 0;
    cJSON_ArrayForEach(e, a)
    {
        char ip[160];
        snprintf(ip, sizeof ip, "%s[%d]", path, i);
        if (read_item(f->sub, e, base + f->off + (size_t)i * f->item_size + f->sub->off, path, ip,
                      lim, err))
            return -1;
        i++;
    }
    if (f->flags & VX_PF_COUNT) *(int *)(base + f->count_off) = n;
    return 0;
}

static int read_field(const vx_pspec *f, const vx_pspec *list, const cJSON *it, char *base,
                      const char *path, const vx_limits *lim, vx_err *err)
{
    char *p = base + f->off;
    switch (f->type) {
    case VX_PT_NUMBER:
        return read_number(f, it, f->lo, f->hi, path, (double *)p, err);
    case VX_PT_INT: {
        double lo = f->lo, hi = f->hi_of ? f->hi_of(lim) : f->hi, d;
        const vx_pspec *s = f->lo_field ? sibling(list, f->lo_field) : NULL;
        if (s) lo = (double)*(long *)(base + s->off);
        if (read_number(f, it, lo, hi, path, &d, err)) return -1;
        if (d != floor(d)) return BAD("params.%s must be an integer", path);
        *(long *)p = (long)d;
        return 0;
    }
    case VX_PT_BOOL:
        if (!cJSON_IsBool(it)) return BAD("params.%s must be true or false", path);
        *(int *)p = cJSON_IsTrue(it);
        return 0;
    case VX_PT_ENUM:
        return read_enum(f, it, path, (int *)p, err);
    case VX_PT_MESH_ID:
        if (!cJSON_IsString(it) || !vx_store_valid_mesh_id(it->valuestring))
            return BAD("params.%s is not a mesh id (64 lowercase hex digits)", path);
        snprintf(p, VX_MESH_ID_SIZE, "%s", it->valuestring);
        return 0;
    case VX_PT_ARRAY:
        return read_array(f, it, base, path, lim, err);
    case VX_PT_ENUM_SET:
        return read_enum_set(f, it, path, (int *)p, err);
    case VX_PT_OBJECT: {
        if (!cJSON_IsObject(it)) {
            if (!(f->flags & VX_PF_LIST_FIELDS)) return BAD("params.%s must be an object", path);
            char names[256];
            field_list(f->sub, names, sizeof names);
            return BAD("params.%s must be an object {%s}", path, names);
        }
        char prefix[160];
        snprintf(prefix, sizeof prefix, "%s.", path);
        return read_object(f->sub, it, p, prefix, lim, err);
    }
    case VX_PT_CUSTOM:
        return f->custom->read(it, p, path, err);
    }
    return BAD("params.%s has an unknown type", path);
}

/* Fills the default of an absent field. */
static void fill_default(const vx_pspec *f, char *base)
{
    char *p = base + f->off;
    if (f->flags & VX_PF_DERIVED) return; /* check() fills it in */
    switch (f->type) {
    case VX_PT_NUMBER:
        *(double *)p = f->def;
        break;
    case VX_PT_INT:
        *(long *)p = (long)f->def;
        break;
    case VX_PT_BOOL:
    case VX_PT_ENUM:
        *(int *)p = (int)f->def;
        break;
    case VX_PT_ARRAY:
        for (int i = 0; f->defs && i < f->min_items; i++)
            *(double *)(p + (size_t)i * f->item_size) = f->defs[i];
        if (f->flags & VX_PF_COUNT) *(int *)(base + f->count_off) = f->defs ? f->min_items : 0;
        break;
    case VX_PT_OBJECT:
        read_object(f->sub, NULL, p, "", NULL, NULL);
        break;
    default:
        break;
    }
}

static int given(const cJSON *obj, const char *name)
{
    const cJSON *it = cJSON_GetObjectItemCaseSensitive(obj, name);
    return it && !cJSON_IsNull(it);
}

/* The exclusions, on presence alone, before any type. */
static int excluded(const vx_pspec *list, const cJSON *obj, const char *prefix, vx_err *err)
{
    for (const vx_pspec *f = list; f->name; f++) {
        if (!f->excludes || !given(obj, f->name)) continue;
        for (int i = 0; f->excludes[i]; i++) {
            if (!given(obj, f->excludes[i])) continue;
            if (!f->excludes[1])
                return BAD("params.%s%s and params.%s%s exclude each other", prefix, f->name,
                           prefix, f->excludes[i]);
            return BAD("params.%s%s excludes params.%s%s", prefix, f->name, prefix, f->excludes[i]);
        }
    }
    return 0;
}

static int read_object(const vx_pspec *list, const cJSON *obj, char *base, const char *prefix,
                       const vx_limits *lim, vx_err *err)
{
    const cJSON *it;
    cJSON_ArrayForEach(it, obj)
    {
        if (!sibling(list, it->string))
            return BAD("unknown parameter params.%s%s", prefix, it->string);
    }
    if (obj && excluded(list, obj, prefix, err)) return -1;
    for (const vx_pspec *f = list; f->name; f++) {
        it = obj ? cJSON_GetObjectItemCaseSensitive(obj, f->name) : NULL;
        char path[160];
        snprintf(path, sizeof path, "%s%s", prefix, f->name);
        int *set = set_flag(f, base);
        if (!it || cJSON_IsNull(it)) {
            if (f->flags & VX_PF_REQUIRED) return BAD("params.%s is required", path);
            if (f->flags & VX_PF_NEEDED) return read_field(f, list, NULL, base, path, lim, err);
            fill_default(f, base);
            continue;
        }
        if (set) *set = 1;
        if (read_field(f, list, it, base, path, lim, err)) return -1;
    }
    return 0;
}

int vx_spec_read(const vx_pspec *spec, const cJSON *params, const vx_limits *lim, void *out,
                 vx_err *err)
{
    if (params && cJSON_IsNull(params)) params = NULL;
    if (params && !cJSON_IsObject(params)) return BAD("params must be an object");
    return read_object(spec, params, out, "", lim, err);
}

static cJSON *write_object(const vx_pspec *list, const char *base);

static cJSON *write_value(const vx_pspec *f, const char *base)
{
    const char *p = base + f->off;
    switch (f->type) {
    case VX_PT_NUMBER:
        return cJSON_CreateNumber(*(const double *)p);
    case VX_PT_INT:
        return cJSON_CreateNumber((double)*(const long *)p);
    case VX_PT_BOOL:
        return cJSON_CreateBool(*(const int *)p);
    case VX_PT_ENUM:
        return cJSON_CreateString(f->names[*(const int *)p]);
    case VX_PT_MESH_ID:
        return cJSON_CreateString(p);
    case VX_PT_ARRAY: {
        int n = f->flags & VX_PF_COUNT ? *(const int *)(base + f->count_off) : f->min_items;
        cJSON *a = cJSON_CreateArray();
        for (int i = 0; a && i < n; i++) {
            cJSON *v = write_value(f->sub, p + (size_t)i * f->item_size);
            if (!v || !cJSON_AddItemToArray(a, v)) {
                cJSON_Delete(v);
                cJSON_Delete(a);
                return NULL;
            }
        }
        return a;
    }
    case VX_PT_ENUM_SET: {
        cJSON *a = cJSON_CreateArray();
        for (int i = 0; a && f->names[i]; i++)
            if (((const int *)p)[i] && !cJSON_AddItemToArray(a, cJSON_CreateString(f->names[i]))) {
                cJSON_Delete(a);
                return NULL;
            }
        return a;
    }
    case VX_PT_OBJECT:
        return write_object(f->sub, p);
    case VX_PT_CUSTOM:
        return f->custom->write(p);
    }
    return NULL;
}

static cJSON *write_object(const vx_pspec *list, const char *base)
{
    cJSON *o = cJSON_CreateObject();
    for (const vx_pspec *f = list; o && f->name; f++) {
        const int *set = set_flag(f, (char *)base);
        cJSON *v = (f->flags & VX_PF_NULLABLE) && !*set ? cJSON_CreateNull() : write_value(f, base);
        if (!v || !cJSON_AddItemToObject(o, f->name, v)) {
            cJSON_Delete(v);
            cJSON_Delete(o);
            return NULL;
        }
    }
    return o;
}

cJSON *vx_spec_write(const vx_pspec *spec, const void *in)
{
    return write_object(spec, in);
}

void vx_spec_free(const vx_pspec *spec, void *in)
{
    char *base = in;
    for (const vx_pspec *f = spec; in && f->name; f++) {
        if (f->type == VX_PT_CUSTOM && f->custom->free) f->custom->free(base + f->off);
        if (f->type == VX_PT_OBJECT) vx_spec_free(f->sub, base + f->off);
        if (f->type == VX_PT_ARRAY && f->sub->type == VX_PT_OBJECT)
            for (int i = 0; i < f->max_items; i++)
                vx_spec_free(f->sub->sub, base + f->off + (size_t)i * f->item_size);
    }
}

static const char *type_name(vx_ptype t)
{
    static const char *const n[] = {"number", "integer", "boolean", "string", "string",
                                    "array",  "array",   "object",  "custom"};
    return n[t];
}

static cJSON *describe_field(const vx_pspec *f);

static cJSON *describe_list(const vx_pspec *list)
{
    cJSON *o = cJSON_CreateObject();
    for (const vx_pspec *f = list; o && f->name; f++)
        cJSON_AddItemToObject(o, f->name, describe_field(f));
    return o;
}

static cJSON *describe_field(const vx_pspec *f)
{
    cJSON *d = cJSON_CreateObject();
    if (!d) return NULL;
    if (f->type == VX_PT_CUSTOM) {
        cJSON *s = cJSON_Parse(f->custom->schema);
        if (s) cJSON_AddItemToObject(d, "schema", s);
    }
    cJSON_AddStringToObject(d, "type", type_name(f->type));
    if (f->doc) cJSON_AddStringToObject(d, "doc", f->doc);
    if (f->flags & VX_PF_NULLABLE) cJSON_AddBoolToObject(d, "nullable", 1);
    if (f->excludes) {
        cJSON *x = cJSON_AddArrayToObject(d, "excludes");
        for (int i = 0; x && f->excludes[i]; i++)
            cJSON_AddItemToArray(x, cJSON_CreateString(f->excludes[i]));
    }
    if (f->flags & (VX_PF_REQUIRED | VX_PF_NEEDED)) cJSON_AddBoolToObject(d, "required", 1);
    /* array items have no default of their own */
    int dflt = f->name && !(f->flags & (VX_PF_DERIVED | VX_PF_REQUIRED | VX_PF_NEEDED));
    switch (f->type) {
    case VX_PT_NUMBER:
    case VX_PT_INT:
        if (dflt) cJSON_AddNumberToObject(d, "default", f->def);
        if (f->lo_field) cJSON_AddStringToObject(d, "minimum_field", f->lo_field);
        if (isfinite(f->lo))
            cJSON_AddNumberToObject(d, f->flags & VX_PF_GT_LO ? "exclusiveMinimum" : "minimum",
                                    f->lo);
        if (isfinite(f->hi)) cJSON_AddNumberToObject(d, "maximum", f->hi);
        break;
    case VX_PT_BOOL:
        if (dflt) cJSON_AddBoolToObject(d, "default", f->def != 0);
        break;
    case VX_PT_ENUM:
    case VX_PT_ENUM_SET: {
        cJSON *e = cJSON_CreateArray();
        for (int i = 0; e && f->names[i]; i++)
            cJSON_AddItemToArray(e, cJSON_CreateString(f->names[i]));
        cJSON_AddItemToObject(d, "enum", e);
        if (f->type == VX_PT_ENUM && dflt)
            cJSON_AddStringToObject(d, "default", f->names[(int)f->def]);
        if (f->type == VX_PT_ENUM_SET && dflt) cJSON_AddArrayToObject(d, "default");
        break;
    }
    case VX_PT_MESH_ID:
        cJSON_AddStringToObject(d, "format", "mesh-id");
        break;
    case VX_PT_ARRAY:
        cJSON_AddNumberToObject(d, "minItems", f->min_items);
        cJSON_AddNumberToObject(d, "maxItems", f->max_items);
        cJSON_AddItemToObject(d, "items", describe_field(f->sub));
        if (f->defs && dflt)
            cJSON_AddItemToObject(d, "default", cJSON_CreateDoubleArray(f->defs, f->min_items));
        break;
    case VX_PT_OBJECT:
        cJSON_AddItemToObject(d, "properties", describe_list(f->sub));
        break;
    case VX_PT_CUSTOM:
        break;
    }
    return d;
}

cJSON *vx_spec_describe(const vx_pspec *spec)
{
    return describe_list(spec);
}
