/* Typed parameter specs: each job parameter declared once (libvips'
 * VIPS_ARG_*), with its type, default, range and doc line, straight into
 * the kind's C params struct. One generic reader validates params JSON into
 * the struct; one generic writer prints the normalised params that are
 * journaled, fields in spec order. Null is the same as absent everywhere.
 *
 * Adding a parameter to a kind: a member of its params struct named as the
 * JSON field, one entry in its spec[] (where it goes in the normalised
 * JSON), a rule in its check() only if it spans fields, and the field in
 * the kind's params schema in api/openapi.yaml (unit.params_openapi fails
 * until the two agree). The stages read the member. */
#ifndef VX_JOBS_SPEC_H
#define VX_JOBS_SPEC_H

#include <stddef.h>

#include <cjson/cJSON.h>

#include "util/err.h"

typedef enum vx_ptype {
    VX_PT_NUMBER,   /* double */
    VX_PT_INT,      /* long */
    VX_PT_BOOL,     /* int 0/1 */
    VX_PT_ENUM,     /* int: index into names */
    VX_PT_MESH_ID,  /* char[VX_MESH_ID_SIZE] */
    VX_PT_ARRAY,    /* inline C array of max_items items of item_size */
    VX_PT_ENUM_SET, /* array of names, kept as int[n names] flags, written in names order */
    VX_PT_OBJECT,   /* nested struct at off, fields in sub */
    VX_PT_CUSTOM,   /* read/write/free by the kind (custom) */
} vx_ptype;

#define VX_MESH_ID_SIZE 65

/* flags */
#define VX_PF_SET 1           /* set_off holds an int: 1 when given (or check() set it) */
#define VX_PF_NULLABLE 2      /* written as null while its set flag is 0 (implies SET) */
#define VX_PF_REQUIRED 4      /* absent is an error */
#define VX_PF_DERIVED 8       /* no fixed default: check() fills it in when not given */
#define VX_PF_GT_LO 16        /* lo is exclusive (value > lo) */
#define VX_PF_COUNT 32        /* ARRAY: count_off holds the int number of items */
#define VX_PF_NEEDED 64       /* absent is an error, told as for a value of the wrong type */
#define VX_PF_TERSE 128       /* NUMBER: every fault is "must be a number > lo" */
#define VX_PF_LIST_FIELDS 256 /* OBJECT: "must be an object {a, b, c}" */

typedef struct vx_limits vx_limits;

typedef struct vx_pspec vx_pspec;

/* A field the generic reader cannot say: the kind reads it (it is non-null
 * JSON; path is its name for messages, "frames"), writes it back and frees
 * what read allocated. schema is a JSON text for the contract check. */
typedef struct vx_pcustom {
    int (*read)(const cJSON *it, void *field, const char *path, vx_err *err);
    cJSON *(*write)(const void *field);
    void (*free)(void *field);
    const char *schema;
} vx_pcustom;

struct vx_pspec {
    const char *name; /* NULL ends a list */
    vx_ptype type;
    size_t off;
    const char *doc;
    double def, lo, hi;          /* NUMBER/INT/BOOL/ENUM (index) default; NUMBER/INT range */
    const char *const *excludes; /* NULL-terminated siblings it may not be given with */
    const char *lo_field;        /* INT: an earlier sibling INT field that is the minimum */
    double (*hi_of)(const vx_limits *lim); /* INT: the maximum under the limits (hi: none) */
    const char *const *names;              /* ENUM, ENUM_SET */
    const vx_pspec *sub;                   /* OBJECT: its fields; ARRAY: the item (one entry) */
    size_t item_size;                      /* ARRAY: bytes per item */
    int min_items, max_items;              /* ARRAY */
    const double *defs;        /* ARRAY of numbers: the default items (min_items of them) */
    size_t count_off, set_off; /* VX_PF_COUNT, VX_PF_SET */
    int flags;
    const vx_pcustom *custom;
};

/* Declarations of the common fields of struct T, whose member is named as
 * the JSON field; further designated initialisers (.flags, .set_off) may
 * follow. */
#define VX_P_NUM(T, f, d, l, h, doc_, ...)                                                         \
    {                                                                                              \
        .name = #f, .type = VX_PT_NUMBER, .off = offsetof(T, f), .def = (d), .lo = (l), .hi = (h), \
        .doc = (doc_), __VA_ARGS__                                                                 \
    }
#define VX_P_INT(T, f, d, l, h, doc_, ...)                                                         \
    {                                                                                              \
        .name = #f, .type = VX_PT_INT, .off = offsetof(T, f), .def = (d), .lo = (l), .hi = (h),    \
        .doc = (doc_), __VA_ARGS__                                                                 \
    }
#define VX_P_BOOL(T, f, d, doc_, ...)                                                              \
    {                                                                                              \
        .name = #f, .type = VX_PT_BOOL, .off = offsetof(T, f), .def = (d), .doc = (doc_),          \
        __VA_ARGS__                                                                                \
    }
#define VX_P_ENUM(T, f, nm, d, doc_, ...)                                                          \
    {                                                                                              \
        .name = #f, .type = VX_PT_ENUM, .off = offsetof(T, f), .names = (nm), .def = (d),          \
        .doc = (doc_), __VA_ARGS__                                                                 \
    }
/* A fixed array of n doubles in [l, h], default defs. */
#define VX_P_VEC(T, f, n, defs_, item, doc_, ...)                                                  \
    {                                                                                              \
        .name = #f, .type = VX_PT_ARRAY, .off = offsetof(T, f), .sub = (item),                     \
        .item_size = sizeof(double), .min_items = (n), .max_items = (n), .defs = (defs_),          \
        .doc = (doc_), __VA_ARGS__                                                                 \
    }
/* The item of a number array, and the end of a list. */
#define VX_P_ITEM_NUM(l, h)                                                                        \
    {                                                                                              \
        .type = VX_PT_NUMBER, .lo = (l), .hi = (h)                                                 \
    }
#define VX_P_ITEM_INT(l, h)                                                                        \
    {                                                                                              \
        .type = VX_PT_INT, .lo = (l), .hi = (h)                                                    \
    }
#define VX_P_END                                                                                   \
    {                                                                                              \
        .name = NULL                                                                               \
    }

/* Reads params (NULL or null = {}) into out (spec's struct, zeroed first):
 * types, ranges, defaults, unknown fields refused. Returns 0, or -1 with
 * err (VX_EUNPROC invalid_params naming the field path); out is then freed
 * with vx_spec_free. lim (may be NULL) is for hi_of. */
int vx_spec_read(const vx_pspec *spec, const cJSON *params, const vx_limits *lim, void *out,
                 vx_err *err);
/* The normalised params of in: every field, in spec order; NULL on OOM. */
cJSON *vx_spec_write(const vx_pspec *spec, const void *in);
/* Frees what the reader allocated in in (custom fields), not in itself. */
void vx_spec_free(const vx_pspec *spec, void *in);
/* The spec as JSON ({"name": {"type", "default", "minimum", ...}}), for
 * the check of api/openapi.yaml against it; NULL on OOM. */
cJSON *vx_spec_describe(const vx_pspec *spec);

#endif
