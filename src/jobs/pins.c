/* What an unfinished job holds in the store: its meshes pinned, its large
 * inline params kept as blobs and read back for the stages. jobs_int.h. */
#include "jobs/jobs_int.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/log.h"
#include "util/json.h"

static int pinset_add(char (**arr)[65], size_t *n, const char *id)
{
    char(*a)[65] = realloc(*arr, (*n + 1) * sizeof *a);
    if (!a) return -1;
    snprintf(a[*n], 65, "%s", id);
    *arr = a;
    (*n)++;
    return 0;
}

/* Releases what a job held: a deleted mesh or a blob may go now. */
void unpin_job(vx_jobs *j, pinset *ps)
{
    for (size_t i = 0; i < ps->nmesh; i++)
        vx_store_mesh_unpin(j->desc.store, ps->mesh[i]);
    for (size_t i = 0; i < ps->nblob; i++)
        vx_store_blob_unpin(j->desc.store, ps->blob[i]);
    pinset_free(ps);
}

/* A blob reference in normalised params: {"blob": SHA-256, ...}. */
static const char *blob_ref(const cJSON *it)
{
    const char *id = cJSON_IsObject(it)
                         ? cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(it, "blob"))
                         : NULL;
    return id && vx_store_valid_mesh_id(id) ? id : NULL;
}

/* Pins the job's mesh and those its params name, and (replay) the blobs its
 * params reference. At submission (replay = 0) a mesh that is not there is
 * 404 and nothing stays pinned; at replay a deleted mesh still counts, and
 * what is gone is left out (the job fails when it runs). */
int pin_job(vx_jobs *j, const char *mesh, const vx_kind *k, const cJSON *params, int replay,
            pinset *ps, vx_err *err)
{
    const char *ids[257] = {mesh};
    size_t n = 1;
    if (k->mesh_refs) {
        size_t m = k->mesh_refs(params, ids + 1, 256);
        n += m < 256 ? m : 256;
    }
    for (size_t i = 0; i < n; i++) {
        vx_err e;
        if (!ids[i] || !vx_store_valid_mesh_id(ids[i])) continue;
        if (vx_store_mesh_pin(j->desc.store, ids[i], replay, &e) == 0) {
            if (pinset_add(&ps->mesh, &ps->nmesh, ids[i]) == 0) continue;
            vx_store_mesh_unpin(j->desc.store, ids[i]);
            vx_err_set(&e, VX_EINTERNAL, "out_of_memory", "no memory");
        } else if (replay) {
            VX_WARN("jobs.mesh_gone", "mesh=%s", ids[i]);
            continue;
        }
        if (err) *err = e;
        unpin_job(j, ps);
        return -1;
    }
    for (size_t f = 0; replay && k->blob_fields && k->blob_fields[f]; f++) {
        const char *id = blob_ref(cJSON_GetObjectItemCaseSensitive(params, k->blob_fields[f]));
        vx_err e;
        if (!id) continue;
        if (vx_store_blob_pin(j->desc.store, id, &e) == 0) {
            if (pinset_add(&ps->blob, &ps->nblob, id)) vx_store_blob_unpin(j->desc.store, id);
        } else {
            VX_WARN("jobs.blob_gone", "blob=%s", id);
        }
    }
    return 0;
}

/* Moves the large inline fields of normalised params (kind->blob_fields)
 * into blobs, stored and pinned (ps) before the job is acknowledged, and
 * puts references in their place. */
int externalize(vx_jobs *j, const vx_kind *k, cJSON *params, pinset *ps, vx_err *err)
{
    for (size_t f = 0; k->blob_fields && k->blob_fields[f]; f++) {
        const char *name = k->blob_fields[f];
        cJSON *it = cJSON_GetObjectItemCaseSensitive(params, name);
        if (!cJSON_IsArray(it) && !cJSON_IsObject(it)) continue;
        if (k->mesh_refs) { /* mesh ids stay visible: pins and replay read them */
            cJSON *probe = cJSON_CreateObject();
            const char *ids[1];
            size_t m = probe && cJSON_AddItemReferenceToObject(probe, name, it)
                           ? k->mesh_refs(probe, ids, 1)
                           : 1;
            cJSON_Delete(probe);
            if (m) continue;
        }
        char *text = vx_json_print(it, 0);
        if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        size_t len = strlen(text);
        if (len < VX_BLOB_MIN_BYTES) {
            free(text);
            continue;
        }
        char id[65];
        int rc = vx_store_blob_put(j->desc.store, text, len, id, err);
        free(text);
        if (rc) return -1;
        if (pinset_add(&ps->blob, &ps->nblob, id)) {
            vx_store_blob_unpin(j->desc.store, id);
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
        cJSON *ref = cJSON_CreateObject();
        if (!ref || !cJSON_AddStringToObject(ref, "blob", id) ||
            !cJSON_AddNumberToObject(ref, "bytes", (double)len) ||
            !cJSON_AddNumberToObject(ref, "count", cJSON_GetArraySize(it)) ||
            !cJSON_ReplaceItemInObjectCaseSensitive(params, name, ref)) {
            cJSON_Delete(ref);
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        }
    }
    return 0;
}

/* The params the stages get: an owned copy with every blob read back. */
cJSON *inline_params(vx_jobs *j, const vx_kind *k, const cJSON *params, int *big, vx_err *err)
{
    cJSON *p = cJSON_Duplicate(params, 1);
    if (!p) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the params");
        return NULL;
    }
    for (size_t f = 0; k->blob_fields && k->blob_fields[f]; f++) {
        const char *id = blob_ref(cJSON_GetObjectItemCaseSensitive(p, k->blob_fields[f]));
        if (!id) continue;
        if (big) *big = 1;
        size_t n = 0;
        char *text = vx_store_blob_read(j->desc.store, id, &n, err);
        cJSON *v = text ? cJSON_ParseWithLength(text, n) : NULL;
        free(text);
        if (!v || !cJSON_ReplaceItemInObjectCaseSensitive(p, k->blob_fields[f], v)) {
            if (text && !v)
                vx_err_set(err, VX_EINTERNAL, "blob_corrupt",
                           "the job's inline data (params.%s) cannot be read back",
                           k->blob_fields[f]);
            cJSON_Delete(v);
            cJSON_Delete(p);
            return NULL;
        }
    }
    return p;
}
