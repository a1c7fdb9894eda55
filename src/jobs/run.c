/* The vx_run_* service the kinds call from their stages (kind.h). */
#include "jobs/jobs_int.h"

#include <math.h>
#include <pthread.h>
#include <stdio.h>

#include "util/fsutil.h"

int vx_run_progress(vx_job_run *r, double fraction, vx_err *err)
{
    vx_jobs *j = r->jobs;
    if (fraction < 0) fraction = 0;
    if (fraction > 1) fraction = 1;
    pthread_mutex_lock(&j->lock);
    if (fraction > r->job->progress) r->job->progress = fraction;
    int cancel = r->job->cancel_requested;
    pthread_mutex_unlock(&j->lock);
    double now = vx_mono();
    if (r->on_gl_thread && now - r->last_ping > 1.0) {
        jobs_alive(j);
        r->last_ping = now;
    }
    if (cancel) return vx_err_set(err, VX_ECANCELED, "canceled", "the job was canceled");
    if (j->stopping)
        return vx_err_set_flagged(err, VX_ECANCELED, VX_EF_SHUTDOWN, "shutdown",
                                  "the daemon is shutting down");
    if (vx_run_time_left(r) < 0)
        return vx_err_set(err, VX_ETIMEOUT, "job_timeout", "the job ran longer than %g s",
                          j->desc.limits.job_timeout_s);
    return 0;
}

double vx_run_time_left(const vx_job_run *r)
{
    double limit = r->jobs->desc.limits.job_timeout_s;
    return limit > 0 ? limit - (vx_mono() - r->t0 - r->waited) : INFINITY;
}

vx_gl *vx_run_gl(vx_job_run *r)
{
    return r->gl;
}

const vx_limits *vx_run_limits(const vx_job_run *r)
{
    return &r->jobs->desc.limits;
}

const char *vx_run_cache_dir(const vx_job_run *r)
{
    return r->jobs->desc.cache_dir;
}

const char *vx_run_mesh_id(const vx_job_run *r)
{
    return r->job->mesh;
}

const char *vx_run_job_id(const vx_job_run *r)
{
    return r->job->id;
}

vx_mesh *vx_run_load_mesh(vx_job_run *r, const char *id, vx_err *err)
{
    return vx_jobs_read_mesh(r->jobs, id, err);
}

cJSON *vx_run_stats(vx_job_run *r)
{
    return r->stats;
}

size_t vx_run_children(const vx_job_run *r)
{
    return r->job->children ? (size_t)cJSON_GetArraySize(r->job->children) : 0;
}

int vx_run_child(const vx_job_run *r, size_t i, const char **id, const cJSON **params,
                 const cJSON **stats)
{
    const cJSON *c = r->job->children ? cJSON_GetArrayItem(r->job->children, (int)i) : NULL;
    if (!c) return -1;
    if (id) *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(c, "id"));
    if (params) *params = cJSON_GetObjectItemCaseSensitive(c, "params");
    if (stats)
        *stats = cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(c, "result"),
                                                  "stats");
    return 0;
}

/* Child i, its outputs object and its place in the store (rid, "ID/ATTEMPT"),
 * or NULL when there is no such child. */
static const cJSON *child_outputs(const vx_job_run *r, size_t i, char rid[48])
{
    const cJSON *c = r->job->children ? cJSON_GetArrayItem(r->job->children, (int)i) : NULL;
    const char *id = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(c, "id"));
    if (!id) return NULL;
    snprintf(rid, 48, "%s/%d", id,
             (int)cJSON_GetNumberValue(cJSON_GetObjectItemCaseSensitive(c, "attempt")));
    return cJSON_GetObjectItemCaseSensitive(cJSON_GetObjectItemCaseSensitive(c, "result"),
                                            "outputs");
}

int vx_run_child_output(vx_job_run *r, size_t i, const char *name, char *path, size_t n,
                        vx_err *err)
{
    char rid[48];
    const cJSON *outs = child_outputs(r, i, rid);
    const cJSON *o =
        name ? cJSON_GetObjectItemCaseSensitive(outs, name) : (outs ? outs->child : NULL);
    const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file"));
    if (!file)
        return vx_err_set(err, VX_ENOTFOUND, "output_not_found", "child job %zu has no output %s",
                          i, name ? name : "");
    return vx_store_result_file(r->jobs->desc.store, rid, file, path, n, err);
}

int vx_run_output_of_child(vx_job_run *r, const char *name, size_t i, const char *child_name,
                           vx_err *err)
{
    char rid[48];
    const cJSON *o = cJSON_GetObjectItemCaseSensitive(child_outputs(r, i, rid), child_name);
    if (!cJSON_IsObject(o))
        return vx_err_set(err, VX_ENOTFOUND, "output_not_found", "child job %zu has no output %s",
                          i, child_name);
    cJSON *d = cJSON_Duplicate(o, 1);
    cJSON_DeleteItemFromObjectCaseSensitive(d, "location");
    if (!d || !cJSON_AddStringToObject(d, "rid", rid)) {
        cJSON_Delete(d);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    }
    cJSON_DeleteItemFromObjectCaseSensitive(r->outputs, name);
    cJSON_AddItemToObject(r->outputs, name, d);
    return 0;
}

const char *vx_run_output(vx_job_run *r, const char *name, const char *file_ext,
                          const char *content_type, vx_err *err)
{
    if (!r->dir[0] && vx_store_result_dir(r->jobs->desc.store, r->rid, r->dir, sizeof r->dir, err))
        return NULL;
    char file[160];
    snprintf(file, sizeof file, "%s.%s", name, file_ext);
    cJSON_DeleteItemFromObjectCaseSensitive(r->outputs, name);
    cJSON *o = cJSON_AddObjectToObject(r->outputs, name);
    cJSON_AddStringToObject(o, "file", file);
    cJSON_AddStringToObject(o, "content_type", content_type);
    char path[VX_PATH_MAX];
    snprintf(path, sizeof path, "%s/%s", r->dir, file);
    cJSON *s = cJSON_CreateString(path);
    if (!s || !cJSON_AddItemToArray(r->paths, s)) {
        cJSON_Delete(s);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    return s->valuestring;
}
