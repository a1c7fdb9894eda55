/* GET /v1/jobs/{id}/result[/{name}]: result files, sent with sendfile(2)
 * as they are, or compressed on the fly (compress.h), or one byte range.
 *
 * How Range and Content-Encoding go together: a range always applies to
 * the identity (uncompressed) bytes, and a request that gets a range (206)
 * is never compressed, so that a resumed download can be appended to the
 * part already written. Only a whole-file answer (200) is compressed, and
 * only when Accept-Encoding allows zstd or gzip. Each coding is its own
 * representation with its own strong ETag ("<file>", "<file>+zstd",
 * "<file>+gzip"), and every answer says Vary: Accept-Encoding. If-Range
 * compares against the identity ETag. */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "compress.h"
#include "http_int.h"

#define RESULT_CACHE "private, max-age=86400, immutable"

/* The headers every answer about a result carries. */
static void result_headers(struct MHD_Response *resp, const char *etag)
{
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ETAG, etag);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CACHE_CONTROL, RESULT_CACHE);
    MHD_add_response_header(resp, MHD_HTTP_HEADER_VARY, "Accept-Encoding");
    MHD_add_response_header(resp, MHD_HTTP_HEADER_ACCEPT_RANGES, "bytes");
}

/* 304: the validators and Cache-Control of the 200, no body and no
 * Content-Length (RFC 9110 15.4.5). */
static int not_modified(struct MHD_Connection *c, req *r, const char *etag)
{
    struct MHD_Response *resp = vx_resp_headers_only();
    if (!resp) return MHD_NO;
    result_headers(resp, etag);
    return vx_resp_queue(c, r, 304, resp, 0);
}

/* Whether a result of this content type is worth compressing (PNG and
 * other images are compressed already). */
static int compressible(const char *ctype)
{
    return strncmp(ctype, "image/", 6) != 0;
}

/* The Content-Disposition of a result: named after the job's mesh too when
 * its upload gave it a name. */
static void result_disposition(vx_http *h, const char *jid, const char *fname, char *disp, size_t n)
{
    cJSON *job = vx_jobs_get(h->d.jobs, jid, NULL, NULL), *meta = NULL;
    const cJSON *mj = cJSON_GetObjectItemCaseSensitive(job, "mesh");
    if (cJSON_IsString(mj)) meta = vx_store_mesh_meta(h->d.store, mj->valuestring, NULL);
    const cJSON *nj = cJSON_GetObjectItemCaseSensitive(meta, "name");
    vx_resp_disposition(disp, n, cJSON_IsString(nj) ? nj->valuestring : NULL, fname, fname, NULL);
    cJSON_Delete(meta);
    cJSON_Delete(job);
}

int vx_route_result(vx_http *h, struct MHD_Connection *c, req *r)
{
    vx_err err;
    char path[2400], ctype[64], fname[128];
    if (vx_jobs_output(h->d.jobs, r->id, r->route == VX_R_RESULT_NAME ? r->name : NULL, path,
                       sizeof path, ctype, fname, &err))
        return vx_resp_err(c, r, &err);
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    struct stat st;
    if (fd < 0 || fstat(fd, &st) != 0) {
        int e = errno;
        if (fd >= 0) close(fd);
        if (e == ENOENT || e == ENOTDIR)
            return vx_resp_fail(c, r, VX_EGONE, "result_evicted", "the result file is gone");
        /* not the client's doing, and not gone: a permission, a disk */
        VX_ERROR("result.unreadable", "job=%s path=%s error=%d", r->id, VX_Q(path), e);
        const vx_err_kind k = vx_err_io_kind(e);
        return vx_resp_fail(c, r, k, k == VX_EIO ? "io_error" : "store_failed",
                            "cannot read the result file: %s", strerror(e));
    }
    uint64_t size = (uint64_t)st.st_size;
    char id_etag[160], etag[176], disp[600];
    snprintf(id_etag, sizeof id_etag, "\"%s\"", fname);
    result_disposition(h, r->id, fname, disp, sizeof disp);

    uint64_t first = 0, last = 0;
    /* every Range and If-Range line: two Range lines are two ranges (the
     * whole body), two If-Range lines a list (no match) */
    char rbuf[512], irbuf[512];
    const char *range = vx_resp_header_list(c, MHD_HTTP_HEADER_RANGE, rbuf, sizeof rbuf);
    const char *if_range = vx_resp_header_list(c, MHD_HTTP_HEADER_IF_RANGE, irbuf, sizeof irbuf);
    if (!if_range && vx_resp_header(c, MHD_HTTP_HEADER_IF_RANGE)) if_range = ","; /* too long */
    /* If-Range holds one tag or a date: a list (or a date, which has a
     * comma and is never matched here) sends the whole result */
    int rk = range && (!if_range ||
                       (!strchr(if_range, ',') && vx_req_etag_match(if_range, id_etag, 0, 0)))
                 ? vx_req_range(range, size, &first, &last)
                 : 0;
    char ae[1024];
    vx_req_coding coding = rk == 0 && compressible(ctype)
                               ? vx_req_accept_coding(vx_resp_header_list(
                                     c, MHD_HTTP_HEADER_ACCEPT_ENCODING, ae, sizeof ae))
                               : VX_CODING_IDENTITY;
    if (coding == VX_CODING_IDENTITY)
        snprintf(etag, sizeof etag, "%s", id_etag);
    else
        snprintf(etag, sizeof etag, "\"%s+%s\"", fname, vx_compress_token(coding));

    /* If-Match may name the result in any coding: the bytes never change */
    int pre = vx_resp_preconditions(c, etag, id_etag);
    if (pre) close(fd);
    if (pre == 412) return vx_resp_precondition_failed(c, r, etag);
    if (pre == 304) return not_modified(c, r, etag);
    if (rk < 0) {
        close(fd);
        char cr[64];
        snprintf(cr, sizeof cr, "bytes */%llu", (unsigned long long)size);
        vx_err_set(&err, VX_ERANGE, "range_not_satisfiable",
                   "the range '%.80s' lies outside the %llu-byte result", range,
                   (unsigned long long)size);
        return vx_resp_err_with(c, r, &err, MHD_HTTP_HEADER_CONTENT_RANGE, cr);
    }
    struct MHD_Response *resp;
    unsigned status = 200;
    uint64_t bytes = size;
    if (rk > 0) {
        /* from_fd lets MHD use sendfile(2); it closes fd with the response. */
        bytes = last - first + 1;
        resp = MHD_create_response_from_fd_at_offset64(bytes, fd, first);
        status = 206;
    } else if (coding != VX_CODING_IDENTITY && !strcmp(r->method, "HEAD")) {
        /* The coded length is not known without coding the file: no
         * length and no body (a chunked answer's last chunk, sent to HEAD
         * too, was read as the next answer by a client reusing the
         * connection). */
        close(fd);
        fd = -1;
        resp = vx_resp_headers_only();
        bytes = 0;
    } else if (coding != VX_CODING_IDENTITY) {
        resp = vx_compress_response(fd, coding, &r->bytes_out); /* fd is its own now */
        fd = -1;
        bytes = 0; /* counted as the coder hands its bytes out */
    } else {
        resp = MHD_create_response_from_fd64(size, fd);
    }
    if (fd >= 0) vx_conns_watch_file(h->conns, r->vc, fd, rk > 0 ? last + 1 : size);
    if (!resp) {
        if (fd >= 0) close(fd);
        return MHD_NO;
    }
    MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_TYPE, ctype);
    MHD_add_response_header(resp, "Content-Disposition", disp);
    result_headers(resp, etag);
    if (coding != VX_CODING_IDENTITY)
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_ENCODING, vx_compress_token(coding));
    if (rk > 0) {
        char cr[96];
        snprintf(cr, sizeof cr, "bytes %llu-%llu/%llu", (unsigned long long)first,
                 (unsigned long long)last, (unsigned long long)size);
        MHD_add_response_header(resp, MHD_HTTP_HEADER_CONTENT_RANGE, cr);
    }
    return vx_resp_queue(c, r, status, resp, bytes);
}
