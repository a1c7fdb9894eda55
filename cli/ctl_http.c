/* HTTP for voxelctl, through libcurl (ctl.h). */
#include <curl/curl.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

#include "ctl.h"

int ctl_http_init(void)
{
    if (curl_global_init(CURL_GLOBAL_DEFAULT) != CURLE_OK) {
        fprintf(stderr, "voxelctl: cannot initialise libcurl\n");
        return -1;
    }
    return 0;
}

static int buf_add(ctl_buf *b, const char *p, size_t n)
{
    if (b->n + n + 1 > b->cap) {
        size_t cap = (b->n + n + 1) * 2;
        char *q = realloc(b->p, cap);
        if (!q) return -1;
        b->p = q;
        b->cap = cap;
    }
    memcpy(b->p + b->n, p, n);
    b->n += n;
    b->p[b->n] = 0;
    return 0;
}

typedef struct sink {
    CURL *curl;
    ctl_buf *buf;
    FILE *out;
    char *disp;
    size_t dispn;
} sink;

static size_t on_body(char *p, size_t size, size_t n, void *ud)
{
    sink *s = ud;
    long status = 0;
    curl_easy_getinfo(s->curl, CURLINFO_RESPONSE_CODE, &status);
    if (s->out && status >= 200 && status < 300)
        return fwrite(p, size, n, s->out) == n ? n * size : 0;
    return buf_add(s->buf, p, size * n) ? 0 : size * n;
}

/* Content-Disposition: attachment; filename="NAME" → NAME (no path parts). */
static size_t on_header(char *p, size_t size, size_t n, void *ud)
{
    sink *s = ud;
    size_t len = size * n;
    static const char key[] = "content-disposition:";
    if (s->disp && len > sizeof key && !strncasecmp(p, key, sizeof key - 1)) {
        char line[512];
        snprintf(line, sizeof line, "%.*s", (int)len, p);
        char *f = strstr(line, "filename=");
        if (f) {
            f += 9;
            if (*f == '"') f++;
            size_t k = strcspn(f, "\"\r\n;");
            f[k] = 0;
            char *slash = strrchr(f, '/');
            snprintf(s->disp, s->dispn, "%s", slash ? slash + 1 : f);
        }
    }
    return len;
}

/* A handle for c->server + path with the token; headers into *hl. */
static CURL *open_handle(const ctl *c, const char *path, const char *ctype, struct curl_slist **hl)
{
    CURL *h = curl_easy_init();
    if (!h) return NULL;
    char url[2048], auth[600], ct[200];
    snprintf(url, sizeof url, "%s%s", c->server, path);
    curl_easy_setopt(h, CURLOPT_URL, url);
    curl_easy_setopt(h, CURLOPT_USERAGENT, "voxelctl/" VX_VERSION);
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    *hl = NULL;
    if (c->token[0]) {
        snprintf(auth, sizeof auth, "Authorization: Bearer %s", c->token);
        *hl = curl_slist_append(*hl, auth);
    }
    if (ctype) {
        snprintf(ct, sizeof ct, "Content-Type: %s", ctype);
        *hl = curl_slist_append(*hl, ct);
    }
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, *hl);
    return h;
}

long ctl_http(const ctl *c, const char *method, const char *path, const char *ctype,
              const char *data, const char *upload, ctl_buf *resp, FILE *out, char *disp,
              size_t dispn)
{
    struct curl_slist *hl;
    CURL *h = open_handle(c, path, ctype, &hl);
    if (!h) return -1;
    sink s = {.curl = h, .buf = resp, .out = out, .disp = disp, .dispn = dispn};
    if (disp) disp[0] = 0;
    FILE *in = NULL;
    if (upload) {
        in = fopen(upload, "rb");
        struct stat st;
        if (!in || fstat(fileno(in), &st) != 0) {
            fprintf(stderr, "voxelctl: cannot read %s\n", upload);
            if (in) fclose(in);
            curl_slist_free_all(hl);
            curl_easy_cleanup(h);
            return -1;
        }
        curl_easy_setopt(h, CURLOPT_POST, 1L);
        curl_easy_setopt(h, CURLOPT_READDATA, in);
        curl_easy_setopt(h, CURLOPT_POSTFIELDSIZE_LARGE, (curl_off_t)st.st_size);
    } else if (data) {
        curl_easy_setopt(h, CURLOPT_POSTFIELDS, data);
    }
    if (strcmp(method, "POST") != 0 && strcmp(method, "GET") != 0)
        curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, method);
    curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, on_body);
    curl_easy_setopt(h, CURLOPT_WRITEDATA, &s);
    curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(h, CURLOPT_HEADERDATA, &s);
    if (resp->p) resp->p[0] = 0;
    resp->n = 0;
    CURLcode rc = curl_easy_perform(h);
    long status = -1;
    if (rc == CURLE_OK)
        curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    else
        fprintf(stderr, "voxelctl: %s%s: %s\n", c->server, path, curl_easy_strerror(rc));
    if (in) fclose(in);
    curl_slist_free_all(hl);
    curl_easy_cleanup(h);
    if (!resp->p) buf_add(resp, "", 0);
    return status;
}

int ctl_http_fail(const char *what, long status, const ctl_buf *resp)
{
    if (status < 0) return 1;
    cJSON *doc = resp->p ? cJSON_Parse(resp->p) : NULL;
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(doc, "error");
    const char *msg = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "message"));
    const char *code = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "code"));
    if (msg)
        fprintf(stderr, "voxelctl: %s: %s (%s, HTTP %ld)\n", what, msg, code ? code : "?", status);
    else
        fprintf(stderr, "voxelctl: %s: HTTP %ld\n", what, status);
    cJSON_Delete(doc);
    return 1;
}

/* ---- the event stream ------------------------------------------------ */

typedef struct stream {
    CURL *curl;
    ctl_buf line, data;
    cJSON *last;
    void (*on_job)(void *, const cJSON *);
    void *ud;
    ctl_buf err; /* the body of a non-200 answer */
} stream;

/* One line of the stream, without its end: data lines gather, a blank
 * line ends the event. */
static void stream_line(stream *s, const char *l)
{
    if (!*l) {
        if (s->data.n) {
            cJSON *job = cJSON_Parse(s->data.p);
            if (job) {
                if (s->on_job) s->on_job(s->ud, job);
                cJSON_Delete(s->last);
                s->last = job;
            }
        }
        s->data.n = 0;
        if (s->data.p) s->data.p[0] = 0;
        return;
    }
    if (!strncmp(l, "data:", 5)) {
        l += 5;
        if (*l == ' ') l++;
        if (s->data.n) buf_add(&s->data, "\n", 1);
        buf_add(&s->data, l, strlen(l));
    }
}

static size_t on_stream(char *p, size_t size, size_t n, void *ud)
{
    stream *s = ud;
    long status = 0;
    curl_easy_getinfo(s->curl, CURLINFO_RESPONSE_CODE, &status);
    size_t len = size * n;
    if (status != 200) return buf_add(&s->err, p, len) ? 0 : len;
    for (size_t i = 0; i < len; i++) {
        if (p[i] == '\n') {
            if (s->line.n && s->line.p[s->line.n - 1] == '\r') s->line.p[--s->line.n] = 0;
            stream_line(s, s->line.p ? s->line.p : "");
            s->line.n = 0;
            if (s->line.p) s->line.p[0] = 0;
        } else if (buf_add(&s->line, p + i, 1)) {
            return 0;
        }
    }
    return len;
}

cJSON *ctl_http_events(const ctl *c, const char *jid, void (*on_job)(void *, const cJSON *),
                       void *ud, long *status)
{
    char path[128];
    snprintf(path, sizeof path, "/v1/jobs/%s/events", jid);
    struct curl_slist *hl;
    CURL *h = open_handle(c, path, NULL, &hl);
    *status = 0;
    if (!h) return NULL;
    hl = curl_slist_append(hl, "Accept: text/event-stream");
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, hl);
    stream s = {.curl = h, .on_job = on_job, .ud = ud};
    curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, on_stream);
    curl_easy_setopt(h, CURLOPT_WRITEDATA, &s);
    /* No byte for a minute (keepalives come every 15 s): the server is gone. */
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_TIME, 60L);
    CURLcode rc = curl_easy_perform(h);
    if (rc == CURLE_OK) curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, status);
    curl_slist_free_all(hl);
    curl_easy_cleanup(h);
    free(s.line.p);
    free(s.data.p);
    free(s.err.p);
    if (rc != CURLE_OK || *status != 200) {
        cJSON_Delete(s.last);
        return NULL;
    }
    return s.last;
}
