/* Answering a submission with a job that exists already (jobs_int.h):
 * the request fingerprint, Idempotency-Key and `reuse`. The fingerprint
 * is a 64-bit FNV-1a of the kind, the mesh and the params as journaled
 * (normalised, large fields as their blob references), so replayed jobs get
 * the same one; a match is confirmed by comparing the params themselves. */
#include "jobs/jobs_int.h"
#include "util/json.h"

#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

static uint64_t fnv(uint64_t h, const char *s, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        h ^= (unsigned char)s[i];
        h *= 1099511628211ull;
    }
    return h;
}

uint64_t request_fp(const char *kind, const char *mesh, const cJSON *params)
{
    uint64_t h = 14695981039346656037ull;
    h = fnv(h, kind, strlen(kind) + 1);
    h = fnv(h, mesh, strlen(mesh) + 1);
    char *text = params ? vx_json_print(params, 0) : NULL;
    if (text) h = fnv(h, text, strlen(text));
    free(text);
    return h;
}

int vx_jobs_valid_idem_key(const char *s)
{
    size_t n = s ? strlen(s) : 0;
    if (!n || n > 200) return 0;
    for (size_t i = 0; i < n; i++)
        if ((unsigned char)s[i] < 0x21 || (unsigned char)s[i] > 0x7e) return 0;
    return 1;
}

/* 1 when old is the same request as jb: kind, mesh and params. */
static int same_request(const job *old, const job *jb)
{
    if (old->fp != jb->fp || old->kind != jb->kind || strcmp(old->mesh, jb->mesh)) return 0;
    if (old->params) return cJSON_Compare(old->params, jb->params, 1);
    cJSON *f = old->frozen ? cJSON_Parse(old->frozen) : NULL;
    int same = f && cJSON_Compare(cJSON_GetObjectItemCaseSensitive(f, "params"), jb->params, 1);
    cJSON_Delete(f);
    return same;
}

/* 1 when old succeeded and its results can still be downloaded. */
/* A succeeded job whose every output is still there, the size it wrote
 * (what a download checks): a result evicted, removed or damaged since
 * is no result to hand back. */
static int reusable(vx_jobs *j, const job *old)
{
    if (old->state != ST_SUCCEEDED) return 0;
    cJSON *outputs = NULL;
    job_parts(old, NULL, NULL, &outputs);
    int ok = 1;
    const cJSON *o;
    cJSON_ArrayForEach(o, outputs)
    {
        const char *file = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(o, "file"));
        const cJSON *b = cJSON_GetObjectItemCaseSensitive(o, "bytes");
        char path[VX_PATH_MAX];
        struct stat st;
        vx_err e;
        if (!file || vx_store_result_file(j->desc.store, old->id, file, path, sizeof path, &e) ||
            stat(path, &st) != 0 ||
            job_output_check_size(old->id, path, cJSON_IsNumber(b) ? b->valuedouble : -1, &e)) {
            ok = 0;
            break;
        }
    }
    cJSON_Delete(outputs);
    return ok;
}

job *find_existing_locked(vx_jobs *j, const job *jb, int reuse, vx_err *err)
{
    if (jb->idem) {
        for (size_t i = j->jobs.n; i-- > 0;) {
            job *old = job_at(j, i);
            if (!old->idem || strcmp(old->idem, jb->idem)) continue;
            if (same_request(old, jb)) return old;
            vx_err_set(err, VX_EUNPROC, "idempotency_key_reused",
                       "the Idempotency-Key was used for another request (job %s)", old->id);
            return NULL;
        }
    }
    /* With a key, the key's own job answers every retry (a reused job
     * would answer only this one: the key stays with the job it queues),
     * as in cluster mode. */
    if (reuse && !jb->idem)
        for (size_t i = j->jobs.n; i-- > 0;) {
            job *old = job_at(j, i);
            if (old->fp == jb->fp && reusable(j, old) && same_request(old, jb)) return old;
        }
    return NULL;
}
