/* /v1/jobs: submission (with ?wait), listing, state (with ?wait) and
 * cancel; results are in routes_results.c. */
#include <stdio.h>
#include <string.h>

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
    return vx_resp_json(c, r, status, doc,
                        status == 202 || r->post_job ? MHD_HTTP_HEADER_LOCATION : NULL, loc);
}

/* Why doc is not a job request ({"mesh", "kind", "params"?, "reuse"?}),
 * (a message of its own in buf[n] when it names a field), or NULL. */
static const char *job_request_error(const cJSON *doc, char *buf, size_t n)
{
    const cJSON *mesh = cJSON_GetObjectItemCaseSensitive(doc, "mesh");
    const cJSON *kind = cJSON_GetObjectItemCaseSensitive(doc, "kind");
    const cJSON *params = cJSON_GetObjectItemCaseSensitive(doc, "params");
    if (!cJSON_IsObject(doc)) return "the body must be a JSON object";
    if (!mesh) return "\"mesh\" (a mesh id string) is required";
    if (!cJSON_IsString(mesh)) return "\"mesh\" must be a mesh id string";
    if (!kind) return "\"kind\" (a job kind string) is required";
    if (!cJSON_IsString(kind)) return "\"kind\" must be a job kind string";
    if (params && !cJSON_IsObject(params)) return "\"params\" must be an object";
    const cJSON *reuse = cJSON_GetObjectItemCaseSensitive(doc, "reuse");
    if (reuse && !cJSON_IsBool(reuse)) return "\"reuse\" must be true or false";
    const cJSON *it;
    cJSON_ArrayForEach(it, doc)
    {
        if (strcmp(it->string, "mesh") && strcmp(it->string, "kind") &&
            strcmp(it->string, "params") && strcmp(it->string, "reuse")) {
            snprintf(buf, n,
                     "unknown field \"%.60s\" in the job request (it takes mesh, kind, params "
                     "and reuse; a kind's parameters go in params)",
                     it->string);
            return buf;
        }
    }
    return NULL;
}

/* What reading a JSON job body may take, per byte of it (cJSON's nodes,
 * the normalised params, the job's copies). */
#define JSON_COST_X 32

static int job_post(vx_http *h, struct MHD_Connection *c, req *r, double wait_s);

int vx_route_job_post(vx_http *h, struct MHD_Connection *c, req *r)
{
    if (r->too_big)
        return vx_resp_fail(c, r, VX_ETOOBIG, "too_large",
                            "the JSON body is larger than max-json-bytes");
    double wait_s = wait_seconds(h, r);
    /* The tree of a large body, and its normalised copies, take many times
     * its bytes (16 MiB of "[]," is 420 MB): reserved from max-parse-memory
     * first, as an upload's parse is. */
    uint64_t cost = JSON_COST_X * (uint64_t)r->len + (64 << 10);
    vx_budget_result br = vx_budget_reserve(&h->parse_budget, cost, h->d.cfg->max_parse_memory);
    if (br == VX_BUDGET_TOO_BIG)
        return vx_resp_fail(c, r, VX_ETOOBIG, "too_large",
                            "a %zu-byte JSON body may take up to %llu bytes of memory to read, "
                            "more than the max-parse-memory limit of %llu bytes",
                            r->len, (unsigned long long)cost,
                            (unsigned long long)h->d.cfg->max_parse_memory);
    if (br != VX_BUDGET_OK)
        return vx_resp_fail(c, r, VX_EOVERLOAD, "busy_parsing",
                            "other requests being parsed hold the memory this %zu-byte JSON body "
                            "may need (%llu of max-parse-memory's %llu bytes); retry later",
                            r->len, (unsigned long long)cost,
                            (unsigned long long)h->d.cfg->max_parse_memory);
    int rc = job_post(h, c, r, wait_s);
    vx_budget_release(&h->parse_budget, cost);
    return rc;
}

static int job_post(vx_http *h, struct MHD_Connection *c, req *r, double wait_s)
{
    char why[128];
    cJSON *doc = vx_req_json_parse(r->buf ? r->buf : "", r->len, why, sizeof why);
    if (!doc) return vx_resp_fail(c, r, VX_EINVAL, "invalid_json", "%s", why);
    char mbuf[200];
    const char *msg = job_request_error(doc, mbuf, sizeof mbuf);
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
    char kbuf[256];
    const char *key = vx_resp_header_trim(c, "Idempotency-Key", kbuf, sizeof kbuf);
    vx_jobs_submit_opts opts = {.idempotency_key = key,
                                .reuse =
                                    cJSON_IsTrue(cJSON_GetObjectItemCaseSensitive(doc, "reuse")),
                                .refuse_new = &r->new_refused};
    int existing = 0;
    if (!vx_store_valid_mesh_id(mesh->valuestring))
        vx_err_set(&err, VX_EINVAL, "invalid_request",
                   "\"mesh\" must be a mesh id (64 hex digits)");
    else if (key && !vx_jobs_valid_idem_key(key))
        vx_err_set(&err, VX_EINVAL, "invalid_request",
                   "Idempotency-Key must be 1 to 200 visible ASCII characters");
    else
        job = vx_jobs_submit_with(h->d.jobs, mesh->valuestring, kind->valuestring, params, &opts,
                                  &existing, &err);
    cJSON_Delete(doc);
    if (!job) return vx_resp_err(c, r, &err);
    unsigned status = existing ? 200 : 202; /* an existing job: nothing new was accepted */
    char jid[33];
    snprintf(jid, sizeof jid, "%s",
             cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(job, "id")));
    if (wait_s > 0) {
        r->post_job = 1;
        snprintf(r->id, sizeof r->id, "%s", jid);
        r->post_existing = existing;
        /* not held (finished, or --max-waits held already): answered now,
         * never refused: the job is in */
        if (vx_wait_hold(h->wait, &r->w, c, jid, wait_s) > 0) {
            cJSON_Delete(job);
            return MHD_YES;
        }
        cJSON_Delete(job);
        return answer_job(h, c, r, jid, status);
    }
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/jobs/%s", jid);
    return vx_resp_json(c, r, status, job, MHD_HTTP_HEADER_LOCATION, loc);
}

int vx_route_job_list(vx_http *h, struct MHD_Connection *c, req *r)
{
    int limit = r->q.limit;
    const char *after = r->q.has_after ? r->q.after : NULL;
    if (r->q.has_kind && !vx_jobs_has_kind(h->d.jobs, r->q.kind))
        return vx_resp_fail(c, r, VX_EINVAL, "invalid_request",
                            "query parameter kind must be a job kind (see /v1/info)");
    vx_jobs_filter f = {.state = r->q.has_state ? r->q.state : NULL,
                        .kind = r->q.has_kind ? r->q.kind : NULL,
                        .mesh = r->q.has_mesh ? r->q.mesh : NULL,
                        .desc = r->q.desc};
    char next[40];
    vx_err err;
    cJSON *items = vx_jobs_list(h->d.jobs, after, limit, &f, next, &err);
    if (!items) return vx_resp_err(c, r, &err);
    return vx_resp_page(c, r, items, next);
}

int vx_route_job(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!strcmp(r->method, "DELETE")) {
        int running;
        cJSON *doc = vx_jobs_cancel(h->d.jobs, r->id, &running, &err);
        if (!doc && err.kind == VX_ECONFLICT) { /* finished: delete it and its results */
            if (vx_jobs_delete(h->d.jobs, r->id, &err)) return vx_resp_err(c, r, &err);
            return vx_resp_text(c, r, 204, NULL, NULL, NULL, NULL);
        }
        if (!doc) return vx_resp_err(c, r, &err);
        return vx_resp_json(c, r, running ? 202 : 200, doc, NULL, NULL);
    }
    double wait_s = wait_seconds(h, r);
    r->w.by_progress = r->q.has_progress; /* ?progress: wake there too */
    r->w.wake_progress = r->q.progress_ppm / 1e6;
    int held = wait_s > 0 ? vx_wait_hold(h->wait, &r->w, c, r->id, wait_s) : 0;
    if (held > 0) return MHD_YES;
    if (held < 0)
        return vx_resp_fail(
            c, r, VX_EOVERLOAD, "too_many_waits",
            "%llu requests are held by ?wait, the most --max-waits allows (with event "
            "streams, at most half of --max-connections); ask "
            "again after Retry-After seconds, or without wait",
            (unsigned long long)h->d.cfg->max_waits);
    return answer_job(h, c, r, r->id, 200);
}

int vx_route_job_resumed(vx_http *h, struct MHD_Connection *c, req *r)
{
    return answer_job(h, c, r, r->id, r->post_job && !r->post_existing ? 202 : 200);
}
