/* /v1/jobs: submission (with ?wait), listing, state (with ?wait), cancel
 * and results (sendfile, ETag). */
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "http_int.h"

/* The ?wait of r in seconds, capped to the request timeout. */
static double wait_seconds(vx_http *h, const req *r)
{
    double v = (double)r->q.wait_us / 1e6;
    return v > h->d.cfg->request_timeout_s ? h->d.cfg->request_timeout_s : v;
}

static int answer_job(vx_http *h, struct MHD_Connection *c, req *r, const char *jid,
                      unsigned status)
{
    vx_err err;
    cJSON *doc = vx_jobs_get(h->d.jobs, jid, NULL, &err);
    if (!doc) return vx_resp_err(c, r, &err);
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/jobs/%s", jid);
    return vx_resp_json(c, r, status, doc, status == 202 ? MHD_HTTP_HEADER_LOCATION : NULL, loc);
}

/* Why doc is not a job request ({"mesh", "kind", "params"?}), or NULL. */
static const char *job_request_error(const cJSON *doc)
{
    const cJSON *mesh = cJSON_GetObjectItemCaseSensitive(doc, "mesh");
    const cJSON *kind = cJSON_GetObjectItemCaseSensitive(doc, "kind");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(doc, "params");
    if (!cJSON_IsObject(doc)) return "the body must be a JSON object";
    if (!cJSON_IsString(mesh)) return "\"mesh\" (a mesh id string) is required";
    if (!cJSON_IsString(kind)) return "\"kind\" (a job kind string) is required";
    if (params && !cJSON_IsObject(params)) return "\"params\" must be an object";
    const char *msg = NULL;
    const cJSON *it;
    cJSON_ArrayForEach(it, doc)
    {
        if (strcmp(it->string, "mesh") && strcmp(it->string, "kind") &&
            strcmp(it->string, "params"))
            msg = "unknown field in the job request";
    }
    return msg;
}

int vx_route_job_post(vx_http *h, struct MHD_Connection *c, req *r)
{
    if (r->too_big)
        return vx_resp_fail(c, r, VX_ETOOBIG, "too_large",
                            "the JSON body is larger than max-json-bytes");
    double wait_s = wait_seconds(h, r);
    char why[128];
    if (vx_req_json_text_ok(r->buf ? r->buf : "", r->len, why, sizeof why))
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_json", "%s", why);
    cJSON *doc = cJSON_ParseWithLength(r->buf ? r->buf : "", r->len);
    if (!doc) return vx_resp_fail(c, r, VX_EINVAL, "invalid_json", "the body is not valid JSON");
    const char *msg = job_request_error(doc);
    const cJSON *mesh = cJSON_GetObjectItemCaseSensitive(doc, "mesh");
    const cJSON *kind = cJSON_GetObjectItemCaseSensitive(doc, "kind");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(doc, "params");
    if (msg) {
        cJSON_Delete(doc);
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request", "%s", msg);
    }
    vx_err err;
    vx_err_clear(&err);
    cJSON *job = NULL;
    if (!vx_store_valid_mesh_id(mesh->valuestring))
        vx_err_set(&err, VX_EINVAL, "invalid_request",
                   "\"mesh\" must be a mesh id (64 hex digits)");
    else
        job = vx_jobs_submit(h->d.jobs, mesh->valuestring, kind->valuestring, params, &err);
    cJSON_Delete(doc);
    if (!job) return vx_resp_err(c, r, &err);
    char jid[33];
    snprintf(jid, sizeof jid, "%s",
             cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id")));
    if (wait_s > 0) {
        r->post_job = 1;
        snprintf(r->id, sizeof r->id, "%s", jid);
        if (vx_wait_hold(h->wait, &r->w, c, jid, wait_s)) {
            cJSON_Delete(job);
            return MHD_YES;
        }
        cJSON_Delete(job);
        return answer_job(h, c, r, jid, 202);
    }
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/jobs/%s", jid);
    return vx_resp_json(c, r, 202, job, MHD_HTTP_HEADER_LOCATION, loc);
}

int vx_route_job_list(vx_http *h, struct MHD_Connection *c, req *r)
{
    int limit = r->q.limit;
    const char *after = r->q.has_after ? r->q.after : NULL,
               *state = r->q.has_state ? r->q.state : NULL;
    char next[40];
    cJSON *items = vx_jobs_list(h->d.jobs, after, limit, state, next);
    return vx_resp_page(c, r, items, next);
}

int vx_route_job(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!strcmp(r->method, "DELETE")) {
        int running;
        cJSON *doc = vx_jobs_cancel(h->d.jobs, r->id, &running, &err);
        if (!doc) return vx_resp_err(c, r, &err);
        return vx_resp_json(c, r, running ? 202 : 200, doc, NULL, NULL);
    }
    double wait_s = wait_seconds(h, r);
    if (wait_s > 0 && vx_wait_hold(h->wait, &r->w, c, r->id, wait_s)) return MHD_YES;
    return answer_job(h, c, r, r->id, 200);
}

int vx_route_result(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    char path[2400], ctype[64], fname[128];
    if (vx_jobs_output(h->d.jobs, r->id, r->route == VX_R_RESULT_NAME ? r->name : NULL, path,
                       sizeof path, ctype, fname, &err))
        return vx_resp_err(c, r, &err);
    char etag[160], disp[600];
    snprintf(etag, sizeof etag, "\"%s\"", fname);
    /* Named after the job's mesh when the upload gave it a name. */
    cJSON *job = vx_jobs_get(h->d.jobs, r->id, NULL, NULL), *meta = NULL;
    const cJSON *mj = cJSON_GetObjectItemCaseSensitive(job, "mesh");
    if (cJSON_IsString(mj)) meta = vx_store_mesh_meta(h->d.store, mj->valuestring, NULL);
    const cJSON *nj = cJSON_GetObjectItemCaseSensitive(meta, "name");
    if (cJSON_IsString(nj))
        vx_resp_disposition(disp, sizeof disp, nj->valuestring, fname, fname, NULL);
    else
        snprintf(disp, sizeof disp, "attachment; filename=\"%s\"", fname);
    cJSON_Delete(meta);
    cJSON_Delete(job);
    const char *inm = vx_resp_header(c, MHD_HTTP_HEADER_IF_NONE_MATCH);
    if (inm && (strstr(inm, etag) || !strcmp(inm, "*"))) {
        struct MHD_Response *resp =
            MHD_create_response_from_buffer(0, (void *)"", MHD_RESPMEM_PERSISTENT);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
        return vx_resp_queue(c, r, 304, resp, 0);
    }
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        if (fd >= 0) close(fd);
        return vx_resp_fail(c, r, VX_EGONE, "result_evicted", "the result file is gone");
    }
    /* from_fd lets MHD use sendfile(2); it closes fd with the response. */
    struct MHD_Response *resp = MHD_create_response_from_fd64((uint64_t)st.st_size, fd);
    if (!resp) {
        close(fd);
        return MHD_NO;
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
    MHD_add_response_header(resp, "Content-Disposition", disp);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL,
                            "private, max-age=86400, immutable");
    return vx_resp_queue(c, r, 200, resp, (uint64_t)st.st_size);
}

int vx_route_job_resumed(vx_http *h, struct MHD_Connection *c, req *r)
{
    return answer_job(h, c, r, r->id, r->post_job ? 202 : 200);
}
