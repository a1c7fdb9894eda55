/* The job table: one row per job kind (libvips operations, Redis commands).
 *
 * A job runs in stages on fixed threads:
 *   parse   HTTP thread   params JSON -> the typed struct (spec, check) ->
 *                         normalised JSON (vx_kind_parse)
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

#include "jobs/spec.h"
#include "mesh/mesh.h"
#include "util/err.h"

typedef struct vx_gl vx_gl;

/* Limits engines enforce on request-sized allocations (0 = default). */
typedef struct vx_limits {
    uint64_t max_upload_bytes;
    uint64_t max_triangles;
    uint64_t max_image_pixels; /* width * height of any rendered image */
    uint64_t max_cc_valence;   /* gregory approximate-cc: faces around a vertex (0 = none) */
    uint64_t max_job_memory;   /* bytes an engine may allocate for one job */
    uint64_t brick_threshold;  /* voxelize: grids of more cells run as bricks (0 = 1024^3) */
    double job_timeout_s;
} vx_limits;

/* One run of one job, owned by the job runner; kinds only use it through
 * the functions below, from the stage they are called in. */
typedef struct vx_job_run vx_job_run;

/* Sets progress (0..1, clamped, never decreasing). Returns -1 and fills err
 * (VX_ECANCELED / VX_ETIMEOUT) when the job must stop; the stage then
 * cleans up and returns -1 with that err. */
int vx_run_progress(vx_job_run *r, double fraction, vx_err *err);
/* Seconds this run has left before the job timeout (INFINITY when there
 * is none): a stage that knows it needs longer may fail at once. */
double vx_run_time_left(const vx_job_run *r);
/* The GL context; only valid in run_gl. */
vx_gl *vx_run_gl(vx_job_run *r);
/* The id of the job's mesh (64 hex digits), for outputs that record it. */
const char *vx_run_mesh_id(const vx_job_run *r);
/* The job's id, for outputs that name the job's result URLs. */
const char *vx_run_job_id(const vx_job_run *r);
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
/* Cluster mode, a job that its kind's split made into child jobs (which
 * all succeeded before it ran): how many there are (0 otherwise). */
size_t vx_run_children(const vx_job_run *r);
/* Child i (in no particular order): its id, its normalised params and its
 * stats (objects owned by the run), or -1 when there is no such child. */
int vx_run_child(const vx_job_run *r, size_t i, const char **id, const cJSON **params,
                 const cJSON **stats);
/* A local path of child i's output name (NULL = its primary one), fetched
 * from the store when another replica made it; 0, or -1 with err
 * (output_not_found, result_evicted, store_failed). */
int vx_run_child_output(vx_job_run *r, size_t i, const char *name, char *path, size_t n,
                        vx_err *err);
/* Child i's output child_name becomes this job's output name as it is, in
 * the child's place in the store (no copy); 0, or -1 with err. */
int vx_run_output_of_child(vx_job_run *r, const char *name, size_t i, const char *child_name,
                           vx_err *err);

typedef struct vx_kind {
    const char *name;
    const char *summary;
    /* The params, declared once (spec.h): the fields of a params_size
     * struct, in the order the normalised JSON lists them. */
    const vx_pspec *spec;
    size_t params_size;
    /* Optional: the rules that span fields (exclusions, defaults derived
     * from other fields, limits). Runs after the spec's reader on its
     * struct; may fill in VX_PF_DERIVED fields and set flags. Returns 0, or
     * -1 with err (VX_EUNPROC invalid_params naming the field). */
    int (*check)(void *params, const vx_limits *lim, vx_err *err);
    /* Optional: what the params rule out for the job's mesh, told at
     * submission from the mesh's metadata (its `vertices`, `bbox`...; the
     * bbox grown to hold the further meshes mesh_refs names): 0,
     * or -1 with err (VX_EUNPROC invalid_params naming the field), so that
     * it is a 422 rather than a job that fails. */
    int (*check_mesh)(const void *params, const cJSON *mesh_meta, const vx_limits *lim,
                      vx_err *err);
    /* The stages get the typed struct, read once when the run starts. */
    int (*run_gl)(vx_job_run *r, const vx_mesh *mesh, const void *params, void **state,
                  vx_err *err);
    int (*run_cpu)(vx_job_run *r, const void *params, void *state, vx_err *err);
    int (*encode)(vx_job_run *r, const void *params, void *state, vx_err *err);
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
    /* Optional, cluster mode: the separate jobs this one runs as (bricks
     * of a large grid, which any replica may claim), as an owned JSON
     * array of params of this kind, or NULL when it runs as one (err
     * untouched) or with err. Called at submission with the normalised
     * params' struct and the mesh's metadata (its `bbox`,
     * `boundary_edges`...). The job itself then runs once every child has
     * succeeded (vx_run_children); a child that fails fails it. */
    cJSON *(*split)(const void *params, const cJSON *mesh_meta, const vx_limits *lim, vx_err *err);
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

/* Reads params (NULL or null = {}) into an owned struct of k->params_size:
 * k->spec's reader, then k->check. Returns it (free it with
 * vx_kind_params_free), or NULL with err (VX_EUNPROC invalid_params naming
 * the field, VX_EINTERNAL out_of_memory). */
void *vx_kind_read(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err);
/* Frees what vx_kind_read returned (NULL is fine). */
void vx_kind_params_free(const vx_kind *k, void *params);
/* Returns an owned normalised copy of params (vx_kind_read, then the spec's
 * writer), or NULL with err as vx_kind_read. */
cJSON *vx_kind_parse(const vx_kind *k, const cJSON *params, const vx_limits *lim, vx_err *err);

/* Validates and normalises params for kind k, as submission does:
 * vx_kind_parse, then the check the runner and the journal replay rely on:
 * the normalised params, printed and read back, are accepted again with the
 * same result (so a default or derived value out of range is refused now,
 * not at run time). Returns owned normalised params, or NULL with err
 * (VX_EUNPROC invalid_params naming the field). */
cJSON *vx_params_normalize(const vx_kind *k, const cJSON *params, const vx_limits *lim,
                           vx_err *err);

#endif
