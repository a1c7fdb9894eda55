/* The job table: one row per job kind (libvips operations, Redis commands).
 *
 * A job runs in stages on fixed threads:
 *   parse   HTTP thread   validate + normalise params (defaults filled in)
 *   run_gl  GL thread     the GL part; the only stage that may call GL
 *   run_cpu CPU worker    heavy CPU work (FFT, meshing), may be NULL
 *   encode  CPU worker    write the outputs, may be NULL
 * `state` carries data between stages; free_state frees it whatever happens.
 * Stages report progress through vx_run_progress, which also tells them to
 * stop (cancel, time limit). */
#ifndef VX_JOBS_KIND_H
#define VX_JOBS_KIND_H

#include <stddef.h>
#include <stdint.h>

#include <cjson/cJSON.h>

#include "mesh/mesh.h"
#include "util/err.h"

typedef struct vx_gl vx_gl;

/* Limits engines enforce on request-sized allocations (0 = default). */
typedef struct vx_limits {
    uint64_t max_upload_bytes;
    uint64_t max_triangles;
    uint64_t max_image_pixels; /* width * height of any rendered image */
    uint64_t max_job_memory;   /* bytes an engine may allocate for one job */
    double job_timeout_s;
} vx_limits;

/* One run of one job, owned by the job runner; kinds only use it through
 * the functions below, from the stage they are called in. */
typedef struct vx_job_run vx_job_run;

/* Sets progress (0..1, clamped, never decreasing). Returns -1 and fills err
 * (VX_ECANCELED / VX_ETIMEOUT) when the job must stop; the stage then
 * cleans up and returns -1 with that err. */
int vx_run_progress(vx_job_run *r, double fraction, vx_err *err);
/* The GL context; only valid in run_gl. */
vx_gl *vx_run_gl(vx_job_run *r);
/* The id of the job's mesh (64 hex digits), for outputs that record it. */
const char *vx_run_mesh_id(const vx_job_run *r);
/* Loads another stored mesh that the params name (render's `meshes`,
 * gregory's `frames`). Returns an owned mesh the caller frees, or NULL
 * (VX_ENOTFOUND mesh_not_found when its file is gone: a delete keeps the
 * meshes of unfinished jobs; or the reader's error). Callable from run_gl
 * and run_cpu. */
vx_mesh *vx_run_load_mesh(vx_job_run *r, const char *id, vx_err *err);
/* The daemon's cache directory (kept across restarts, safe to delete: FFT
 * wisdom and the like), or NULL when there is none. */
const char *vx_run_cache_dir(const vx_job_run *r);
/* The limits in force. */
const vx_limits *vx_run_limits(const vx_job_run *r);
/* The stats object of the job (owned by the run): kinds add numbers to it. */
cJSON *vx_run_stats(vx_job_run *r);
/* Declares an output NAME (first declared = primary result) and returns the
 * path to write it to (owned by the run, valid until the run ends). */
const char *vx_run_output(vx_job_run *r, const char *name, const char *file_ext,
                          const char *content_type, vx_err *err);

typedef struct vx_kind {
    const char *name;
    const char *summary;
    /* Returns an owned normalised copy of params (NULL input = {}), or NULL
     * with err (VX_EUNPROC, code "invalid_params", message naming the field). */
    cJSON *(*parse)(const cJSON *params, const vx_limits *lim, vx_err *err);
    int (*run_gl)(vx_job_run *r, const vx_mesh *mesh, const cJSON *params, void **state,
                  vx_err *err);
    int (*run_cpu)(vx_job_run *r, const cJSON *params, void *state, vx_err *err);
    int (*encode)(vx_job_run *r, const cJSON *params, void *state, vx_err *err);
    void (*free_state)(void *state);
    /* Optional: the further mesh ids the normalised params name. Writes at
     * most max of them (pointers into params) and returns how many there
     * are; submission answers 404 mesh_not_found when one is not stored. */
    size_t (*mesh_refs)(const cJSON *params, const char **ids, size_t max);
    /* Optional, NULL-terminated: fields of the normalised params that can
     * hold large inline data (gregory's frames as positions). The job keeps
     * one over VX_BLOB_MIN_BYTES printed, naming no mesh, as a blob in the
     * store and its params as {"blob": SHA-256, "bytes": n, "count": array
     * length}; the stages get the params with the data back in place. */
    const char *const *blob_fields;
} vx_kind;

/* Inline data smaller than this stays in the params (bytes of JSON). */
#define VX_BLOB_MIN_BYTES 4096

/* A table of kinds. The daemon's (daemon/kinds.c) reaches the job runner
 * through vx_jobs_desc.kinds, so that src/jobs names no engine. */
typedef struct vx_kinds {
    const vx_kind *const *rows;
    size_t n;
} vx_kinds;

/* The row of t named name; NULL when there is none (or t is NULL). Any
 * thread. */
const vx_kind *vx_kinds_find(const vx_kinds *t, const char *name);

/* Validates and normalises params for kind k, as submission does: k->parse,
 * then the check the runner and the journal replay rely on: the normalised
 * params, printed and read back, are accepted again by k->parse with the
 * same result (so a default or derived value out of range is refused now,
 * not at run time). Returns owned normalised params, or NULL with err
 * (VX_EUNPROC invalid_params naming the field). */
cJSON *vx_params_normalize(const vx_kind *k, const cJSON *params, const vx_limits *lim,
                           vx_err *err);

/* Helpers for parse functions: read an optional number/int/bool field,
 * checking type and range; the default is used when absent. Return 0 or -1
 * with err naming the field. */
int vx_param_number(const cJSON *params, const char *field, double def, double lo, double hi,
                    double *out, vx_err *err);
int vx_param_int(const cJSON *params, const char *field, long def, long lo, long hi, long *out,
                 vx_err *err);
int vx_param_bool(const cJSON *params, const char *field, int def, int *out, vx_err *err);
/* Reads an optional array of mesh ids (64 lowercase hex digits each) of at
 * most max entries; *out is the array (owned by params) or NULL when
 * absent. */
int vx_param_mesh_ids(const cJSON *params, const char *field, size_t max, const cJSON **out,
                      vx_err *err);
/* Reads an optional string that must be one of the NULL-terminated names;
 * *out = its index (def when absent). */
int vx_param_enum(const cJSON *params, const char *field, const char *const *names, int def,
                  int *out, vx_err *err);
/* The start of every kind's params reader: NULL or JSON null means no
 * params (*params becomes NULL); anything else must be an object whose
 * fields are all in the NULL-terminated known list (else VX_EUNPROC
 * invalid_params). */
int vx_param_object(const cJSON **params, const char *const *known, vx_err *err);
/* Fails (VX_EUNPROC) if params has a field not in the NULL-terminated list. */
int vx_param_only(const cJSON *params, const char *const *known, vx_err *err);
/* The same two for a nested object of params: prefix is its path with a
 * trailing dot ("camera.", "lights[1].") for the messages. */
int vx_param_enum_in(const cJSON *obj, const char *prefix, const char *field,
                     const char *const *names, int def, int *out, vx_err *err);
int vx_param_only_in(const cJSON *obj, const char *prefix, const char *const *known, vx_err *err);

#endif
