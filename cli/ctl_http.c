/* HTTP for voxelctl, through libcurl (ctl.h). */
#include <curl/curl.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "ctl.h"

char ctl_http_error[256];
int ctl_http_write_errno;

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
    long retry_after; /* seconds; -1: no Retry-After header */
    int werr;         /* errno of a write to out that failed */
    char coded[32];   /* a Content-Encoding voxelctl did not ask for ("": none) */
} sink;

static size_t on_body(char *p, size_t size, size_t n, void *ud)
{
    sink *s = ud;
    long status = 0;
    curl_easy_getinfo(s->curl, CURLINFO_RESPONSE_CODE, &status);
    if (s->out && status >= 200 && status < 300) {
        if (s->coded[0]) return 0; /* its bytes are not the result's (http_once says so) */
        errno = 0;
        if (fwrite(p, size, n, s->out) == n) return n * size;
        s->werr = errno ? errno : EIO;
        return 0;
    }
    return buf_add(s->buf, p, size * n) ? 0 : size * n;
}

static int hexval(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* A file name from a Content-Disposition parameter value v (quoted, or
 * RFC 8187 UTF-8''%-encoded when ext): its last path part, into out; 0 when
 * nothing safe is left (empty, a leading dot, control bytes, a NUL). */
static int disp_name(const char *v, int ext, char *out, size_t n)
{
    char raw[512];
    size_t o = 0;
    if (ext) {
        if (strncasecmp(v, "UTF-8''", 7)) return 0;
        for (v += 7; *v && !strchr(" \t\r\n;", *v) && o + 1 < sizeof raw; v++) {
            int h1, h2;
            if (*v == '%' && (h1 = hexval(v[1])) >= 0 && (h2 = hexval(v[2])) >= 0) {
                raw[o++] = (char)(h1 * 16 + h2);
                v += 2;
            } else {
                raw[o++] = *v;
            }
        }
    } else {
        if (*v == '"') v++;
        for (; *v && !strchr("\"\r\n;", *v) && o + 1 < sizeof raw; v++)
            raw[o++] = *v;
    }
    raw[o] = 0;
    if (strlen(raw) != o) return 0; /* a %00 */
    char *base = raw;
    for (char *p = raw; *p; p++) {
        if ((unsigned char)*p < 0x20 || *p == 0x7f) return 0;
        if (*p == '/' || *p == '\\') base = p + 1;
    }
    /* (a dot file: the server would name .profile or .bashrc in the
     * user's directory) */
    if (!*base || base[0] == '.') return 0;
    snprintf(out, n, "%s", base);
    return 1;
}

/* Content-Disposition: attachment; filename="NAME"; filename*=UTF-8''NAME
 * → NAME (no path parts), filename* first (RFC 6266 4.3). */
static size_t on_header(char *p, size_t size, size_t n, void *ud)
{
    sink *s = ud;
    size_t len = size * n;
    static const char key[] = "content-disposition:", ra[] = "retry-after:",
                      ce[] = "content-encoding:";
    if (!strncmp(p, "HTTP/", 5)) { /* a new answer's head */
        s->retry_after = -1;
        s->coded[0] = 0;
    }
    if (len > sizeof ce && !strncasecmp(p, ce, sizeof ce - 1)) {
        /* voxelctl asks for none (no Accept-Encoding): the bytes as they are */
        char v[32];
        const char *q = p + sizeof ce - 1;
        size_t k = len - (sizeof ce - 1);
        while (k && (*q == ' ' || *q == '\t'))
            q++, k--;
        while (k && strchr(" \t\r\n", q[k - 1]))
            k--;
        snprintf(v, sizeof v, "%.*s", (int)k, q);
        if (v[0] && strcasecmp(v, "identity")) snprintf(s->coded, sizeof s->coded, "%s", v);
    }
    if (len > sizeof ra && !strncasecmp(p, ra, sizeof ra - 1)) {
        /* delta-seconds, or an HTTP-date */
        char v[128];
        snprintf(v, sizeof v, "%.*s", (int)(len - (sizeof ra - 1)), p + sizeof ra - 1);
        char *end;
        long secs = strtol(v, &end, 10);
        if (end == v) {
            time_t at = curl_getdate(v, NULL);
            secs = at < 0 ? 2 : (long)(at - time(NULL));
        }
        s->retry_after = secs < 0 ? 0 : secs;
    }
    if (s->disp && len > sizeof key && !strncasecmp(p, key, sizeof key - 1)) {
        char line[1024];
        snprintf(line, sizeof line, "%.*s", (int)len, p);
        char *fx = strcasestr(line, "filename*="), *f = strcasestr(line, "filename=");
        if (!(fx && disp_name(fx + 10, 1, s->disp, s->dispn)) && f)
            disp_name(f + 9, 0, s->disp, s->dispn);
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
    /* a server that stopped answering (paused, or gone without a reset)
     * is an error in a minute, not a wait forever: nothing arrived for
     * 60 s (longer than the 30 s ?wait polls) */
    curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT, 10L);
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_TIME, 60L);
    *hl = NULL;
    if (c->token[0]) {
        snprintf(auth, sizeof auth, "Authorization: Bearer %s", c->token);
        *hl = curl_slist_append(*hl, auth);
    }
    if (ctype) {
        snprintf(ct, sizeof ct, "Content-Type: %s", ctype);
        *hl = curl_slist_append(*hl, ct);
    }
    if (c->idem_key[0]) {
        char k[64];
        snprintf(k, sizeof k, "Idempotency-Key: %s", c->idem_key);
        *hl = curl_slist_append(*hl, k);
    }
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, *hl);
    return h;
}

static CURLcode g_last_rc; /* of the last request */

static void say_no_answer(const ctl *c, const char *path, CURLcode rc)
{
    fprintf(stderr, "voxelctl: %s%s: %s%s\n", c->server, path, curl_easy_strerror(rc),
            rc == CURLE_COULDNT_CONNECT || rc == CURLE_COULDNT_RESOLVE_HOST
                ? " (is voxeld running there? --server URL or VOXELD_URL names another; "
                  "--local runs the job without one)"
                : "");
}

static long http_once(const ctl *c, const char *method, const char *path, const char *ctype,
                      const char *data, const char *upload, ctl_buf *resp, FILE *out, char *disp,
                      size_t dispn, long *retry_after)
{
    struct curl_slist *hl;
    *retry_after = -1;
    ctl_http_error[0] = 0;
    ctl_http_write_errno = 0;
    g_last_rc = CURLE_FAILED_INIT;
    CURL *h = open_handle(c, path, ctype, &hl);
    if (!h) return -1;
    sink s = {.curl = h, .buf = resp, .out = out, .disp = disp, .dispn = dispn, .retry_after = -1};
    if (disp) disp[0] = 0;
    FILE *in = NULL;
    if (upload) {
        in = fopen(upload, "rb");
        struct stat st;
        int e = in ? 0 : errno;
        if (in && fstat(fileno(in), &st) != 0) e = errno;
        if (!e && !S_ISREG(st.st_mode)) e = S_ISDIR(st.st_mode) ? EISDIR : EINVAL;
        if (e) {
            fprintf(stderr, "voxelctl: cannot read %s: %s\n", upload,
                    e == EINVAL ? "not a regular file" : strerror(e));
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
    if (rc != CURLE_OK)
        snprintf(ctl_http_error, sizeof ctl_http_error, "%s", curl_easy_strerror(rc));
    if (rc == CURLE_WRITE_ERROR && s.coded[0])
        fprintf(stderr,
                "voxelctl: %s: the server sent the answer with Content-Encoding %s, which "
                "voxelctl did not ask for: nothing written\n",
                path, s.coded);
    else if (rc == CURLE_WRITE_ERROR && s.werr)
        ctl_http_write_errno = s.werr; /* the caller names the file */
    else if (rc == CURLE_OK)
        curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
    else if (!c->quiet_transport)
        say_no_answer(c, path, rc);
    g_last_rc = rc;
    if (in) fclose(in);
    curl_slist_free_all(hl);
    curl_easy_cleanup(h);
    if (!resp->p) buf_add(resp, "", 0);
    *retry_after = s.retry_after;
    return status;
}

/* Whether rc can be a request that reached the server whose answer was
 * lost on the way back. */
static int answer_lost(CURLcode rc)
{
    return rc == CURLE_RECV_ERROR || rc == CURLE_GOT_NOTHING || rc == CURLE_SEND_ERROR ||
           rc == CURLE_PARTIAL_FILE || rc == CURLE_OPERATION_TIMEDOUT;
}

long ctl_http(const ctl *c, const char *method, const char *path, const char *ctype,
              const char *data, const char *upload, ctl_buf *resp, FILE *out, char *disp,
              size_t dispn)
{
    time_t first = 0; /* when the first 429, 503 or lost answer came */
    ctl quiet = *c;   /* the tries after it */
    quiet.quiet_transport = 1;
    for (;;) {
        long ra, st = http_once(first || c->idem_key[0] ? &quiet : c, method, path, ctype, data,
                                upload, resp, out, disp, dispn, &ra);
        /* after a 503 (nothing was done) or a lost answer, no connection
         * at all is the server restarting: tried again too; so is a lost
         * answer to a request with an Idempotency-Key (its job answers) */
        int lost = st < 0 && c->idem_key[0] && answer_lost(g_last_rc);
        int refused = first && st < 0 && g_last_rc == CURLE_COULDNT_CONNECT;
        if (lost) ra = 2;
        if (!lost && !refused && ((st != 429 && st != 503) || ra < 0 || c->no_retry)) {
            if ((first || c->idem_key[0]) && st < 0 && !c->quiet_transport)
                say_no_answer(c, path, g_last_rc);
            return st;
        }
        long wait = refused ? 2 : ra < 1 ? 1 : ra > 30 ? 30 : ra;
        time_t now = time(NULL);
        if (!first) {
            first = now;
            if (lost && !c->quiet)
                fprintf(stderr,
                        "voxelctl: %s %s: the answer was lost (%s): sending it again with its "
                        "Idempotency-Key every %ld s for up to %d s\n",
                        method, path, curl_easy_strerror(g_last_rc), wait, CTL_RETRY_FOR);
            else if (!c->quiet) {
                cJSON *doc = cJSON_Parse(resp->p);
                const cJSON *e = cJSON_GetObjectItemCaseSensitive(doc, "error");
                const char *code =
                    cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "code"));
                const char *msg =
                    cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "message"));
                fprintf(stderr,
                        "voxelctl: %s %s: %s (%s, HTTP %ld): trying again every %ld s for up "
                        "to %d s\n",
                        method, path, msg ? msg : "busy", code ? code : "?", st, wait,
                        CTL_RETRY_FOR);
                cJSON_Delete(doc);
            }
        }
        if (now + wait - first > CTL_RETRY_FOR) {
            if ((refused || lost) && !c->quiet_transport) say_no_answer(c, path, g_last_rc);
            return st;
        }
        sleep((unsigned)wait);
    }
}

const char *ctl_printable(const char *s, char *out, size_t n)
{
    size_t o = 0;
    for (; s && *s && o + 1 < n; s++) {
        unsigned char b = (unsigned char)*s, next = (unsigned char)s[1];
        int c1 = b == 0xc2 && next >= 0x80 && next <= 0x9f; /* U+0080-009F: U+009B is a CSI */
        out[o++] = b < 0x20 || b == 0x7f || c1 ? '?' : *s;
        s += c1;
    }
    out[o] = 0;
    return out;
}

int ctl_http_fail(const char *what, long status, const ctl_buf *resp)
{
    if (status < 0) return 1;
    cJSON *doc = resp->p ? cJSON_Parse(resp->p) : NULL;
    const cJSON *e = cJSON_GetObjectItemCaseSensitive(doc, "error");
    const char *msg = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "message"));
    const char *code = cJSON_GetStringValue(cJSON_GetObjectItemCaseSensitive(e, "code"));
    char m[512], k[64];
    if (msg)
        fprintf(stderr, "voxelctl: %s: %s (%s, HTTP %ld)\n", what, ctl_printable(msg, m, sizeof m),
                ctl_printable(code ? code : "?", k, sizeof k), status);
    else if (status >= 200 && status < 300) /* a success whose body is not what it should be */
        fprintf(stderr, "voxelctl: %s: HTTP %ld, but the answer is not the JSON expected: %s\n",
                what, status, ctl_printable(resp->p && resp->n ? resp->p : "(empty)", m, 120));
    else
        fprintf(stderr, "voxelctl: %s: HTTP %ld%s%s\n", what, status,
                resp->p && resp->n ? ": " : "", ctl_printable(resp->p, m, 120));
    cJSON_Delete(doc);
    return 1;
}

/* ---- the event stream ------------------------------------------------ */

#define CTL_EVENT_MAX ((size_t)1 << 20) /* an event's line or data at most */

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
        } else if (s->line.n >= CTL_EVENT_MAX || s->data.n >= CTL_EVENT_MAX ||
                   buf_add(&s->line, p + i, 1)) {
            return 0; /* (a Job is a few KB: the stream ends, ?wait polling follows) */
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
    /* (open_handle: no byte for a minute, where keepalives come every
     * 15 s, means the server is gone) */
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
