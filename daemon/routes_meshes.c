/* /v1/meshes: listing, metadata, delete and the end of an upload (the body
 * has been streamed to a temp file by http.c): what it is (mesh/intake.c),
 * a parse under the --max-parse-memory budget, the store. */
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "http_int.h"
#include "util/budget.h"
#include "util/fsutil.h"
#include "util/log.h"

int vx_route_mesh_list(vx_http *h, struct MHD_Connection *c, req *r)
{
    int limit = r->q.limit;
    const char *after = r->q.has_after ? r->q.after : NULL;
    char next[65];
    vx_err err;
    vx_err_clear(&err);
    cJSON *items = vx_store_mesh_list(h->d.store, after, limit, next, &err);
    if (!items) return vx_resp_err(c, r, &err);
    return vx_resp_page(c, r, items, next);
}

int vx_route_mesh(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!vx_store_valid_mesh_id(r->id))
        return vx_resp_fail(c, r, VX_ENOTFOUND, "mesh_not_found",
                            "no mesh with that id (ids are 64 hex digits)");
    if (!strcmp(r->method, "DELETE")) {
        if (vx_store_mesh_delete(h->d.store, r->id, &err)) return vx_resp_err(c, r, &err);
        VX_INFO("mesh.deleted", "mesh=%s", r->id);
        return vx_resp_text(c, r, 204, NULL, NULL, NULL, NULL);
    }
    cJSON *meta = vx_store_mesh_meta(h->d.store, r->id, &err);
    if (!meta) return vx_resp_err(c, r, &err);
    return vx_resp_json(c, r, 200, meta, NULL, NULL);
}

int vx_route_mesh_file(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    if (!vx_store_valid_mesh_id(r->id))
        return vx_resp_fail(c, r, VX_ENOTFOUND, "mesh_not_found",
                            "no mesh with that id (ids are 64 hex digits)");
    cJSON *meta = vx_store_mesh_meta(h->d.store, r->id, &err);
    if (!meta) return vx_resp_err(c, r, &err);
    const cJSON *fj = cJSON_GetObjectItemCaseSensitive(meta, "format");
    const cJSON *nj = cJSON_GetObjectItemCaseSensitive(meta, "name");
    vx_mesh_format fmt = vx_intake_format_by_name(cJSON_IsString(fj) ? fj->valuestring : NULL);
    char etag[80], disp[400];
    /* The id is the SHA-256 of the bytes: a strong validator. */
    snprintf(etag, sizeof etag, "\"%s\"", r->id);
    vx_resp_disposition(disp, sizeof disp, cJSON_IsString(nj) ? nj->valuestring : NULL, NULL, r->id,
                        vx_intake_format_ext(fmt ? fmt : VX_MESH_OBJ));
    cJSON_Delete(meta);
    int fd = -1;
    struct stat st;
    /* the fd checked is the one served: a file replaced meanwhile is not */
    if ((fd = vx_store_mesh_open(h->d.store, r->id, &err)) < 0) {
        /* the blob store unreachable (503 store_failed) or a damaged file
         * (410 mesh_damaged) is not a deleted mesh */
        if (err.kind != VX_ENOTFOUND) return vx_resp_err(c, r, &err);
    }
    if (fd < 0 || fstat(fd, &st) != 0) {
        if (fd >= 0) close(fd);
        return vx_resp_fail(c, r, VX_ENOTFOUND, "mesh_not_found", "the mesh was deleted");
    }
    /* 304 and 412 only for a file that is there and intact (so "*" too) */
    int pre = vx_resp_preconditions(c, etag, NULL);
    if (pre == 412) {
        close(fd);
        return vx_resp_precondition_failed(c, r, etag);
    }
    if (pre == 304) {
        close(fd);
        struct MHD_Response *nm = vx_resp_headers_only(); /* no Content-Length */
        if (!nm) return MHD_NO;
        MHD_add_response_header(nm, MHD_HTTP_HEADER_ETAG, etag);
        MHD_add_response_header(nm, MHD_HTTP_HEADER_CACHE_CONTROL,
                                "private, max-age=86400, immutable");
        return vx_resp_queue(c, r, 304, nm, 0);
    }
    struct MHD_Response *resp = MHD_create_response_from_fd64((uint64_t)st.st_size, fd);
    if (!resp) {
        close(fd);
        return MHD_NO;
    }
    vx_conns_watch_file(h->conns, r->vc, fd, (uint64_t)st.st_size);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE,
                            vx_intake_format_media(fmt ? fmt : VX_MESH_OBJ));
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
    MHD_add_response_header(resp, "Content-Disposition", disp);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL,
                            "private, max-age=86400, immutable");
    return vx_resp_queue(c, r, 200, resp, (uint64_t)st.st_size);
}

/* The name an upload gives its mesh: ?name=, else a Content-Disposition
 * filename. 0 with name set ("" for none), or -1 with err (400). */
static int upload_name(struct MHD_Connection *c, req *r, char *name, size_t n, vx_err *err)
{
    name[0] = 0;
    if (r->q.has_name) {
        snprintf(name, n, "%s", r->q.name);
        return 0;
    }
    int rc = vx_req_disposition_name(vx_resp_header(c, "Content-Disposition"), name, n);
    if (rc < 0)
        return vx_err_set(err, VX_EINVAL, "invalid_request",
                          "the Content-Disposition filename must be 1 to %d bytes of UTF-8 "
                          "without control or invisible format characters, '\\' or '\"', and "
                          "not . or ..",
                          VX_NAME_MAX);
    return 0;
}

/* The worst-case memory of the upload parses running now (--max-parse-memory). */

/* Parses upload r (stored as id, in format fmt) under the parse-memory
 * budget and checks it: its Mesh JSON (owned), or NULL with err. */
static cJSON *parse_upload(vx_http *h, req *r, const char *id, vx_mesh_format fmt, vx_err *err)
{
    vx_mesh_limits lim = {.max_triangles = h->d.cfg->max_triangles};
    const char *fname = vx_intake_format_name(fmt);
    uint64_t bytes = vx_upload_bytes(r->up);
    /* Reserve the parse's worst-case memory first; the upload was not
     * acknowledged, so a busy answer loses nothing. */
    uint64_t cost = vx_mesh_parse_cost(vx_upload_path(r->up), fmt, bytes, &lim);
    uint64_t budget = h->d.cfg->max_parse_memory;
    vx_budget_result br = vx_budget_reserve(&h->parse_budget, cost, budget);
    if (br != VX_BUDGET_OK) {
        VX_INFO("mesh.parse_budget", "format=%s bytes=%llu cost=%llu used=%llu limit=%llu", fname,
                (unsigned long long)bytes, (unsigned long long)cost,
                (unsigned long long)vx_budget_used(&h->parse_budget), (unsigned long long)budget);
        if (br == VX_BUDGET_TOO_BIG)
            vx_err_set(err, VX_ETOOBIG, "parse_too_big",
                       "parsing this %s upload may take up to %llu bytes of memory, more than the "
                       "max-parse-memory limit of %llu bytes",
                       fname, (unsigned long long)cost, (unsigned long long)budget);
        else
            vx_err_set(err, VX_EOVERLOAD, "busy_parsing",
                       "other uploads being parsed hold the memory this %s upload may need (%llu "
                       "of max-parse-memory's %llu bytes); retry later",
                       fname, (unsigned long long)cost, (unsigned long long)budget);
        return NULL;
    }
    double t = vx_mono();
    vx_mesh *m = vx_mesh_read_as(vx_upload_path(r->up), fmt, &lim, err);
    double parse_ms = (vx_mono() - t) * 1e3;
    cJSON *meta = NULL;
    if (!m) {
        char q[600];
        VX_INFO("mesh.rejected", "code=%s message=%s", err->code,
                vx_log_quote(q, sizeof q, err->message));
    } else if (vx_intake_check(m, err) == 0) {
        meta = vx_intake_meta(id, fmt, bytes, m);
        VX_INFO("mesh.uploaded",
                "mesh=%s new=1 format=%s bytes=%llu vertices=%zu triangles=%zu parse_ms=%.1f", id,
                fname, (unsigned long long)bytes, m->nverts, m->ntris, parse_ms);
    }
    vx_mesh_free(m);
    vx_budget_release(&h->parse_budget, cost);
    return meta;
}

int vx_route_upload(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    vx_err_clear(&err);
    if (r->too_big)
        return vx_resp_fail(c, r, VX_ETOOBIG, "too_large",
                            "the body is larger than the %llu-byte upload limit",
                            (unsigned long long)h->d.cfg->max_upload_bytes);
    if (r->body_err.kind != VX_EOK) return vx_resp_err(c, r, &r->body_err);
    if (vx_upload_bytes(r->up) == 0)
        return vx_resp_fail(c, r, VX_EUNPROC, "obj_no_faces", "the body is empty: no faces");
    char id[65], name[VX_NAME_MAX + 1];
    if (upload_name(c, r, name, sizeof name, &err)) return vx_resp_err(c, r, &err);
    if (vx_upload_finish(r->up, id, &err)) return vx_resp_err(c, r, &err);
    size_t nhead;
    const unsigned char *head = vx_upload_head(r->up, &nhead);
    vx_mesh_format fmt;
    if (vx_intake_resolve(r->declared, head, nhead, vx_upload_bytes(r->up), &fmt, &err))
        return vx_resp_err(c, r, &err);
    cJSON *meta = vx_store_mesh_meta(h->d.store, id, NULL);
    if (meta && !vx_store_mesh_stored(h->d.store, id)) { /* the catalog's, not here */
        cJSON_Delete(meta);
        meta = NULL;
    }
    if (meta && vx_store_mesh_repair(h->d.store, r->up, id, vx_intake_format_ext(fmt), &err)) {
        cJSON_Delete(meta);
        return vx_resp_err(c, r, &err);
    }
    if (meta) {
        VX_INFO("mesh.uploaded", "mesh=%s new=0", id);
        return vx_resp_json(c, r, 200, meta, NULL, NULL);
    }
    if (!(meta = parse_upload(h, r, id, fmt, &err))) return vx_resp_err(c, r, &err);
    if (name[0]) cJSON_AddStringToObject(meta, "name", name);
    int existed = 0;
    vx_upload *up = r->up;
    r->up = NULL; /* commit frees it */
    if (vx_store_mesh_commit(h->d.store, up, id, vx_intake_format_ext(fmt), meta, &existed, &err)) {
        cJSON_Delete(meta);
        return vx_resp_err(c, r, &err);
    }
    char loc[128];
    snprintf(loc, sizeof loc, "/v1/meshes/%s", id);
    if (existed) { /* a concurrent upload of the same bytes won */
        cJSON_Delete(meta);
        meta = vx_store_mesh_meta(h->d.store, id, NULL);
        return vx_resp_json(c, r, 200, meta, NULL, NULL);
    }
    return vx_resp_json(c, r, 201, meta, MHD_HTTP_HEADER_LOCATION, loc);
}
