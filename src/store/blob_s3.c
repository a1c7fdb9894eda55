/* The s3:// byte store (blob.h): objects in an S3-compatible bucket under a
 * key prefix, path-style against the endpoint, each request signed with AWS
 * Signature V4 by libcurl (CURLOPT_AWS_SIGV4). Bodies stream between files
 * and the network (read and write callbacks), never whole in memory; files
 * over the part size go up as multipart uploads. A cache dir under the data
 * dir (DATA/blobcache, the keys' layout) holds local copies for path(), in
 * a byte budget (least recently used copies go first). A result prefix is
 * written locally by the engines and uploaded by its sync: until then it is
 * the only copy and never evicted. */
#include "store/blob.h"

#include <curl/curl.h>
#include <dirent.h>
#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "util/fsutil.h"
#include "util/log.h"
#include "util/path.h"

#define S3_MIN_PART (5ull << 20) /* S3's smallest part but the last */

struct vx_blob {
    char cache[VX_PATH_MAX / 2]; /* DATA/blobcache */
    char base[1024];             /* ENDPOINT/BUCKET */
    char bucket[64];
    char prefix[256]; /* "" or ending in '/' */
    char sigv4[96];   /* aws:amz:REGION:s3 */
    char userpwd[512];
    char token_hdr[4096]; /* "x-amz-security-token: …", or "" */
    uint64_t cache_max, part_size;
    long timeout_ms;
    int retries;
    atomic_ulong seq;
    atomic_ullong cache_bytes; /* about: recounted by each eviction pass */
    pthread_mutex_t lock;      /* dirty and evictions */
    char (*dirty)[128];        /* result prefixes written but not yet synced */
    size_t ndirty, capdirty;
};

/* ---- configuration ---- */

static int safe_name(const char *s, size_t n)
{
    for (size_t i = 0; i < n; i++)
        if (!((s[i] >= 'a' && s[i] <= 'z') || (s[i] >= 'A' && s[i] <= 'Z') ||
              (s[i] >= '0' && s[i] <= '9') || strchr("-_./", s[i])))
            return 0;
    return 1;
}

/* The value of query parameter name in q ("a=1&b=2"), into out. */
static int query_param(const char *q, const char *name, char *out, size_t n)
{
    size_t ln = strlen(name);
    while (q && *q) {
        const char *amp = strchr(q, '&');
        size_t len = amp ? (size_t)(amp - q) : strlen(q);
        if (len > ln && strncmp(q, name, ln) == 0 && q[ln] == '=') {
            if (len - ln - 1 >= n) return -1;
            memcpy(out, q + ln + 1, len - ln - 1);
            out[len - ln - 1] = 0;
            return 0;
        }
        q = amp ? amp + 1 : NULL;
    }
    return 1;
}

/* Credentials from FILE: "name = value" lines (aws_access_key_id,
 * aws_secret_access_key, aws_session_token: the names of the AWS CLI's
 * credentials file); "#"/";" comments and "[profile]" lines are skipped, the
 * first value of each name counts. */
static int read_credentials(const char *file, char *ak, char *sk, char *tok, size_t n, size_t tokn,
                            vx_err *err)
{
    FILE *f = fopen(file, "re");
    if (!f)
        return vx_err_set(err, VX_EINVAL, "bad_blob_credentials", "cannot read %s: %s", file,
                          strerror(errno));
    char line[4096];
    while (fgets(line, sizeof line, f)) {
        char *p = line + strspn(line, " \t");
        if (*p == '#' || *p == ';' || *p == '[' || *p == '\n' || !*p) continue;
        char *eq = strchr(p, '=');
        if (!eq) continue;
        char *ke = eq;
        while (ke > p && (ke[-1] == ' ' || ke[-1] == '\t'))
            ke--;
        *ke = 0;
        char *v = eq + 1 + strspn(eq + 1, " \t");
        v[strcspn(v, "\r\n")] = 0;
        for (char *e = v + strlen(v); e > v && (e[-1] == ' ' || e[-1] == '\t');)
            *--e = 0;
        char *dst = !strcmp(p, "aws_access_key_id")       ? ak
                    : !strcmp(p, "aws_secret_access_key") ? sk
                    : !strcmp(p, "aws_session_token")     ? tok
                                                          : NULL;
        if (dst && !dst[0]) snprintf(dst, dst == tok ? tokn : n, "%s", v);
    }
    fclose(f);
    return 0;
}

static int s3_config(vx_blob *b, const vx_blob_conf *conf, vx_err *err)
{
    const char *url = conf->url + 5; /* after s3:// */
    const char *q = strchr(url, '?');
    size_t plen = q ? (size_t)(q - url) : strlen(url);
    const char *slash = memchr(url, '/', plen);
    size_t blen = slash ? (size_t)(slash - url) : plen;
    if (blen < 3 || blen >= sizeof b->bucket || !safe_name(url, plen) ||
        memchr(url, '.', blen) != NULL)
        return vx_err_set(err, VX_EINVAL, "bad_blob_store",
                          "s3:// needs a bucket name of 3 to %zu letters, digits, - and _",
                          sizeof b->bucket - 1);
    memcpy(b->bucket, url, blen);
    b->bucket[blen] = 0;
    if (slash && plen > blen + 1) {
        size_t n = plen - blen - 1;
        while (n && slash[n] == '/')
            n--;
        if (n + 2 >= sizeof b->prefix || strstr(slash + 1, "..") || memmem(slash, n + 1, "//", 2))
            return vx_err_set(err, VX_EINVAL, "bad_blob_store", "s3:// prefix too long or bad");
        if (n) snprintf(b->prefix, sizeof b->prefix, "%.*s/", (int)n, slash + 1);
    }
    char endpoint[512] = "", region[64] = "";
    if (query_param(q ? q + 1 : NULL, "endpoint", endpoint, sizeof endpoint) < 0 ||
        query_param(q ? q + 1 : NULL, "region", region, sizeof region) < 0)
        return vx_err_set(err, VX_EINVAL, "bad_blob_store", "s3:// query value too long");
    if (!region[0]) snprintf(region, sizeof region, "us-east-1");
    if (!safe_name(region, strlen(region)))
        return vx_err_set(err, VX_EINVAL, "bad_blob_store", "bad s3:// region");
    if (!endpoint[0]) snprintf(endpoint, sizeof endpoint, "https://s3.%s.amazonaws.com", region);
    if (strncmp(endpoint, "http://", 7) && strncmp(endpoint, "https://", 8))
        return vx_err_set(err, VX_EINVAL, "bad_blob_store",
                          "the s3:// endpoint must be an http:// or https:// URL");
    size_t el = strlen(endpoint);
    while (el && endpoint[el - 1] == '/')
        endpoint[--el] = 0;
    snprintf(b->base, sizeof b->base, "%s/%s", endpoint, b->bucket);
    snprintf(b->sigv4, sizeof b->sigv4, "aws:amz:%s:s3", region);

    char ak[240] = "", sk[240] = "", tok[3900] = "";
    if (conf->credentials_file && conf->credentials_file[0]) {
        if (read_credentials(conf->credentials_file, ak, sk, tok, sizeof ak, sizeof tok, err))
            return -1;
    } else {
        const char *e;
        if ((e = getenv("AWS_ACCESS_KEY_ID"))) snprintf(ak, sizeof ak, "%s", e);
        if ((e = getenv("AWS_SECRET_ACCESS_KEY"))) snprintf(sk, sizeof sk, "%s", e);
        if ((e = getenv("AWS_SESSION_TOKEN"))) snprintf(tok, sizeof tok, "%s", e);
    }
    if (!ak[0] || !sk[0] || strchr(ak, ':'))
        return vx_err_set(err, VX_EINVAL, "bad_blob_credentials",
                          "s3:// needs an access key and a secret (AWS_ACCESS_KEY_ID and "
                          "AWS_SECRET_ACCESS_KEY, or --blob-credentials)");
    snprintf(b->userpwd, sizeof b->userpwd, "%s:%s", ak, sk);
    if (tok[0]) snprintf(b->token_hdr, sizeof b->token_hdr, "x-amz-security-token: %s", tok);
    b->part_size = conf->part_size ? conf->part_size : 64ull << 20;
    if (b->part_size < S3_MIN_PART)
        return vx_err_set(err, VX_EINVAL, "bad_blob_store", "--blob-part-size is at least 5M");
    b->cache_max = conf->cache_max_bytes;
    b->timeout_ms = (long)((conf->timeout_s > 0 ? conf->timeout_s : 30) * 1000);
    b->retries = conf->retries == 0 ? 3 : conf->retries < 0 ? 0 : conf->retries;
    return 0;
}

/* ---- one request ---- */

typedef struct s3_req {
    const char *method; /* GET, HEAD, PUT, POST, DELETE */
    const char *key;    /* under the prefix; NULL = the bucket */
    const char *query;  /* canonical: sorted, encoded, every name with '=' */
    int in_fd;          /* PUT body: in_len bytes of in_fd from in_off; -1 = none */
    off_t in_off;
    uint64_t in_len, in_pos;
    const char *post; /* POST body */
    int out_fd;       /* response body to this file; -1 = to memory (capped) */
    char *mem;
    size_t memn, memcap;
    const char *hdr; /* one more request header, or NULL */
    int once;        /* no retries (ping) */
    /* answers */
    long status;
    char etag[128];
    curl_off_t length, filetime; /* HEAD: Content-Length, Last-Modified (-1: none) */
} s3_req;

static size_t on_read(char *buf, size_t size, size_t nitems, void *ud)
{
    s3_req *r = ud;
    size_t want = size * nitems;
    if (r->in_pos + want > r->in_len) want = (size_t)(r->in_len - r->in_pos);
    if (!want) return 0;
    ssize_t n;
    do
        n = pread(r->in_fd, buf, want, r->in_off + (off_t)r->in_pos);
    while (n < 0 && errno == EINTR);
    if (n <= 0) return CURL_READFUNC_ABORT;
    r->in_pos += (uint64_t)n;
    return (size_t)n;
}

static int on_seek(void *ud, curl_off_t off, int origin)
{
    s3_req *r = ud;
    if (origin != SEEK_SET || off < 0 || (uint64_t)off > r->in_len) return CURL_SEEKFUNC_FAIL;
    r->in_pos = (uint64_t)off;
    return CURL_SEEKFUNC_OK;
}

static size_t on_write(char *data, size_t size, size_t nmemb, void *ud)
{
    s3_req *r = ud;
    size_t n = size * nmemb;
    if (r->out_fd >= 0 && r->status == 0) return vx_write_all(r->out_fd, data, n) ? 0 : n;
    /* Listings, upload ids and error documents: small, capped. */
    if (r->memn + n + 1 > r->memcap) {
        size_t cap = r->memcap ? r->memcap * 2 : 8192;
        while (cap < r->memn + n + 1)
            cap *= 2;
        if (cap > (16u << 20)) return 0;
        char *m = realloc(r->mem, cap);
        if (!m) return 0;
        r->mem = m;
        r->memcap = cap;
    }
    memcpy(r->mem + r->memn, data, n);
    r->memn += n;
    r->mem[r->memn] = 0;
    return n;
}

static size_t on_header(char *line, size_t size, size_t n, void *ud)
{
    s3_req *r = ud;
    size_t len = size * n;
    if (len > 5 && strncasecmp(line, "HTTP/", 5) == 0) {
        /* A status line: a body that is not 2xx goes to memory (an error
         * document), not into the caller's file. */
        const char *sp = memchr(line, ' ', len);
        if (sp) r->status = strtol(sp + 1, NULL, 10) / 100 == 2 ? 0 : 1;
    } else if (len > 5 && strncasecmp(line, "ETag:", 5) == 0) {
        const char *v = line + 5;
        while (*v == ' ')
            v++;
        size_t vl = strcspn(v, "\r\n");
        if (vl < sizeof r->etag) {
            memcpy(r->etag, v, vl);
            r->etag[vl] = 0;
        }
    }
    return len;
}

/* errno for a finished transfer: 0 on 2xx. A failure to reach the server
 * says which (refused, timed out, no host), for the messages; each of
 * those and EAGAIN (5xx, 429) is tried again. */
static int s3_errno(CURLcode rc, long status)
{
    if (rc == CURLE_COULDNT_CONNECT) return ECONNREFUSED;
    if (rc == CURLE_COULDNT_RESOLVE_HOST) return EHOSTUNREACH;
    if (rc == CURLE_OPERATION_TIMEDOUT) return ETIMEDOUT;
    if (rc == CURLE_SEND_ERROR || rc == CURLE_RECV_ERROR || rc == CURLE_GOT_NOTHING)
        return ECONNRESET;
    if (rc != CURLE_OK) return EAGAIN;
    if (status / 100 == 2) return 0;
    if (status == 404) return ENOENT;
    if (status >= 500 || status == 429) return EAGAIN;
    if (status == 403 || status == 401) return EACCES;
    return EIO;
}

/* Runs r, retrying connection errors and 5xx with backoff; 0 on 2xx, or -1
 * with errno (ENOENT: 404; ECONNREFUSED, EHOSTUNREACH, ETIMEDOUT,
 * ECONNRESET, EAGAIN: unreachable for now; EIO, EACCES). */
static int s3_do(vx_blob *b, s3_req *r)
{
    char url[2048];
    int n = r->key ? snprintf(url, sizeof url, "%s/%s%s", b->base, b->prefix, r->key)
                   : snprintf(url, sizeof url, "%s", b->base);
    if (n >= 0 && n < (int)sizeof url && r->query)
        n += snprintf(url + n, sizeof url - (size_t)n, "?%s", r->query);
    if (n < 0 || n >= (int)sizeof url) {
        errno = ENAMETOOLONG;
        return -1;
    }
    CURL *h = curl_easy_init();
    if (!h) {
        errno = ENOMEM;
        return -1;
    }
    struct curl_slist *hd = NULL;
    hd = curl_slist_append(hd, "x-amz-content-sha256: UNSIGNED-PAYLOAD");
    /* No header may be blanked here ("Expect:"): curl 7.88 signs every
     * header of this list, also one that it then does not send. */
    if (b->token_hdr[0]) hd = curl_slist_append(hd, b->token_hdr);
    if (r->hdr) hd = curl_slist_append(hd, r->hdr);
    if (r->post) hd = curl_slist_append(hd, "Content-Type: application/xml");
    curl_easy_setopt(h, CURLOPT_URL, url);
    curl_easy_setopt(h, CURLOPT_HTTPHEADER, hd);
    curl_easy_setopt(h, CURLOPT_AWS_SIGV4, b->sigv4);
    curl_easy_setopt(h, CURLOPT_USERPWD, b->userpwd);
    curl_easy_setopt(h, CURLOPT_NOSIGNAL, 1L);
    curl_easy_setopt(h, CURLOPT_CONNECTTIMEOUT_MS,
                     r->once && b->timeout_ms > 2000 ? 2000L : b->timeout_ms);
    /* No overall limit (a big object takes its time), but no stall longer
     * than the timeout. */
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_LIMIT, 1L);
    curl_easy_setopt(h, CURLOPT_LOW_SPEED_TIME, (b->timeout_ms + 999) / 1000);
    if (r->once) curl_easy_setopt(h, CURLOPT_TIMEOUT_MS, 3000L); /* a probe answers quickly */
    curl_easy_setopt(h, CURLOPT_WRITEFUNCTION, on_write);
    curl_easy_setopt(h, CURLOPT_WRITEDATA, r);
    curl_easy_setopt(h, CURLOPT_HEADERFUNCTION, on_header);
    curl_easy_setopt(h, CURLOPT_HEADERDATA, r);
    if (!strcmp(r->method, "HEAD")) {
        curl_easy_setopt(h, CURLOPT_NOBODY, 1L);
        curl_easy_setopt(h, CURLOPT_FILETIME, 1L);
    } else if (!strcmp(r->method, "PUT")) {
        curl_easy_setopt(h, CURLOPT_UPLOAD, 1L);
        curl_easy_setopt(h, CURLOPT_READFUNCTION, on_read);
        curl_easy_setopt(h, CURLOPT_READDATA, r);
        curl_easy_setopt(h, CURLOPT_SEEKFUNCTION, on_seek);
        curl_easy_setopt(h, CURLOPT_SEEKDATA, r);
        curl_easy_setopt(h, CURLOPT_INFILESIZE_LARGE, (curl_off_t)r->in_len);
    } else if (!strcmp(r->method, "POST")) {
        curl_easy_setopt(h, CURLOPT_POSTFIELDS, r->post ? r->post : "");
        curl_easy_setopt(h, CURLOPT_POSTFIELDSIZE_LARGE,
                         (curl_off_t)(r->post ? strlen(r->post) : 0));
    } else if (strcmp(r->method, "GET")) {
        curl_easy_setopt(h, CURLOPT_CUSTOMREQUEST, r->method);
    }
    int tries = r->once ? 0 : b->retries, e = 0;
    long status = 0;
    for (int attempt = 0;; attempt++) {
        r->in_pos = 0;
        r->memn = 0;
        r->status = 0;
        r->etag[0] = 0;
        if (r->out_fd >= 0 && (ftruncate(r->out_fd, 0) || lseek(r->out_fd, 0, SEEK_SET))) {
            e = errno;
            break;
        }
        CURLcode rc = curl_easy_perform(h);
        status = 0;
        curl_easy_getinfo(h, CURLINFO_RESPONSE_CODE, &status);
        e = s3_errno(rc, status);
        if (vx_err_io_kind(e) != VX_EUNAVAIL || attempt >= tries) {
            /* A 404 is an answer (stat of a missing key), not a failure. */
            if (e == ENOENT)
                VX_DEBUG("blob.s3_not_found", "method=%s key=%s", r->method, r->key ? r->key : "");
            else if (e)
                VX_WARN("blob.s3_failed", "method=%s key=%s status=%ld curl=%d tries=%d", r->method,
                        r->key ? r->key : "", status, (int)rc, attempt + 1);
            break;
        }
        long ms = 100L << (attempt < 5 ? attempt : 5);
        struct timespec ts = {ms / 1000, (ms % 1000) * 1000000L};
        nanosleep(&ts, NULL);
    }
    r->status = status;
    r->length = r->filetime = -1;
    curl_easy_getinfo(h, CURLINFO_CONTENT_LENGTH_DOWNLOAD_T, &r->length);
    curl_easy_getinfo(h, CURLINFO_FILETIME_T, &r->filetime);
    curl_slist_free_all(hd);
    curl_easy_cleanup(h);
    if (e) {
        errno = e;
        return -1;
    }
    return 0;
}

/* AWS's URI encoding of a query value: all but A-Za-z0-9-_.~ as %XX. */
static void uri_encode(const char *in, char *out, size_t n)
{
    size_t o = 0;
    for (; *in && o + 4 < n; in++) {
        unsigned char c = (unsigned char)*in;
        if ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
            strchr("-_.~", c))
            out[o++] = (char)c;
        else
            o += (size_t)snprintf(out + o, n - o, "%%%02X", c);
    }
    out[o] = 0;
}

/* The text of the next <tag>…</tag> at or after p (before end), into out;
 * returns the position after it, or NULL. */
static const char *xml_next(const char *p, const char *end, const char *tag, char *out, size_t n)
{
    char open[64], close[64];
    snprintf(open, sizeof open, "<%s>", tag);
    snprintf(close, sizeof close, "</%s>", tag);
    const char *a = p ? strstr(p, open) : NULL;
    if (!a || (end && a >= end)) return NULL;
    a += strlen(open);
    const char *z = strstr(a, close);
    if (!z) return NULL;
    size_t len = (size_t)(z - a);
    if (len >= n) len = n - 1;
    memcpy(out, a, len);
    out[len] = 0;
    return z + strlen(close);
}

/* ---- the cache ---- */

static int cache_path(vx_blob *b, const char *key, char *buf, size_t n)
{
    if (snprintf(buf, n, "%s/%s", b->cache, key) >= (int)n) {
        errno = ENAMETOOLONG;
        return -1;
    }
    return 0;
}

/* mkdir -p of path's parent. */
static int mkparent(const char *path)
{
    char dir[VX_PATH_MAX];
    snprintf(dir, sizeof dir, "%s", path);
    char *slash = strrchr(dir, '/');
    if (!slash) return 0;
    *slash = 0;
    if (vx_mkdirs(dir, NULL)) {
        errno = EIO;
        return -1;
    }
    return 0;
}

static int dirty_find_locked(vx_blob *b, const char *prefix)
{
    for (size_t i = 0; i < b->ndirty; i++)
        if (strcmp(b->dirty[i], prefix) == 0) return (int)i;
    return -1;
}

static int is_dirty(vx_blob *b, const char *prefix)
{
    pthread_mutex_lock(&b->lock);
    int i = dirty_find_locked(b, prefix);
    pthread_mutex_unlock(&b->lock);
    return i >= 0;
}

static void set_dirty(vx_blob *b, const char *prefix, int on)
{
    pthread_mutex_lock(&b->lock);
    int i = dirty_find_locked(b, prefix);
    if (on && i < 0 && strlen(prefix) < sizeof b->dirty[0]) {
        if (b->ndirty == b->capdirty) {
            size_t cap = b->capdirty ? 2 * b->capdirty : 16;
            void *m = realloc(b->dirty, cap * sizeof *b->dirty);
            if (m) {
                b->dirty = m;
                b->capdirty = cap;
            }
        }
        if (b->ndirty < b->capdirty)
            snprintf(b->dirty[b->ndirty++], sizeof b->dirty[0], "%s", prefix);
    } else if (!on && i >= 0) {
        memcpy(b->dirty[i], b->dirty[--b->ndirty], sizeof b->dirty[0]);
    }
    pthread_mutex_unlock(&b->lock);
}

typedef struct cached {
    char *path;
    double mtime;
    uint64_t bytes;
} cached;

typedef struct walk {
    vx_blob *b;
    cached *v;
    size_t n, cap;
    uint64_t total;
} walk;

/* Copies used this recently stay (path() has just handed them out). */
#define S3_CACHE_GRACE_S 5.0

/* Collects the evictable copies under dir (rel: its key): not staged
 * objects, not dirty result prefixes, not copies used in the grace time. */
static void walk_dir(walk *w, const char *dir, const char *rel)
{
    if (rel[0] && dirty_find_locked(w->b, rel) >= 0) return;
    DIR *d = opendir(dir);
    if (!d) return;
    struct dirent *e;
    while ((e = readdir(d))) {
        if (e->d_name[0] == '.') continue;
        char p[VX_PATH_MAX], r[VX_PATH_MAX];
        snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
        snprintf(r, sizeof r, "%s%s%s", rel, rel[0] ? "/" : "", e->d_name);
        struct stat st;
        if (lstat(p, &st) != 0) continue;
        if (S_ISDIR(st.st_mode)) {
            walk_dir(w, p, r);
            continue;
        }
        if (!S_ISREG(st.st_mode) || strncmp(e->d_name, "tmp-", 4) == 0) continue;
        if (w->n == w->cap) {
            size_t cap = w->cap ? 2 * w->cap : 256;
            cached *m = realloc(w->v, cap * sizeof *m);
            if (!m) break;
            w->v = m;
            w->cap = cap;
        }
        double mt = (double)st.st_mtim.tv_sec + st.st_mtim.tv_nsec * 1e-9;
        w->total += (uint64_t)st.st_size;
        if (vx_now() - mt < S3_CACHE_GRACE_S) continue;
        cached *c = &w->v[w->n];
        if (!(c->path = strdup(p))) break;
        c->mtime = mt;
        c->bytes = (uint64_t)st.st_size;
        w->n++;
    }
    closedir(d);
}

static int by_mtime(const void *a, const void *b)
{
    double x = ((const cached *)a)->mtime, y = ((const cached *)b)->mtime;
    return x < y ? -1 : x > y;
}

/* Removes the least recently used copies until the cache is in budget. */
static void cache_evict(vx_blob *b)
{
    if (!b->cache_max || atomic_load(&b->cache_bytes) <= b->cache_max) return;
    pthread_mutex_lock(&b->lock);
    walk w = {b, NULL, 0, 0, 0};
    walk_dir(&w, b->cache, "");
    qsort(w.v, w.n, sizeof *w.v, by_mtime);
    size_t gone = 0;
    for (size_t i = 0; i < w.n; i++) {
        if (w.total > b->cache_max && unlink(w.v[i].path) == 0) {
            w.total -= w.v[i].bytes;
            gone++;
        }
        free(w.v[i].path);
    }
    free(w.v);
    atomic_store(&b->cache_bytes, w.total);
    pthread_mutex_unlock(&b->lock);
    if (gone) VX_INFO("blob.cache_evicted", "files=%zu", gone);
}

static void cache_added(vx_blob *b, uint64_t bytes)
{
    atomic_fetch_add(&b->cache_bytes, bytes);
    cache_evict(b);
}

/* A staged name beside path: DIR/tmp-<pid>-<seq>. */
static void tmp_beside(vx_blob *b, const char *path, char *tmp, size_t n)
{
    const char *slash = strrchr(path, '/');
    unsigned long seq = atomic_fetch_add(&b->seq, 1) + 1;
    snprintf(tmp, n, "%.*s/tmp-%lu-%lu", (int)(slash - path), path, (unsigned long)getpid(), seq);
}

/* GET key into the cache file path (through a temp file). */
static int fetch(vx_blob *b, const char *key, const char *path)
{
    char tmp[VX_PATH_MAX];
    if (mkparent(path)) return -1;
    tmp_beside(b, path, tmp, sizeof tmp);
    int fd = open(tmp, O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0) return -1;
    s3_req r = {.method = "GET", .key = key, .in_fd = -1, .out_fd = fd};
    int rc = s3_do(b, &r);
    int e = errno;
    struct stat st;
    if (rc == 0 && (fstat(fd, &st) != 0 || rename(tmp, path) != 0)) rc = -1, e = errno;
    close(fd);
    free(r.mem);
    if (rc) {
        unlink(tmp);
        errno = e;
        return -1;
    }
    cache_added(b, (uint64_t)st.st_size);
    return 0;
}

/* Calls fn with each object under P/prefix (key relative to the store's
 * prefix, size, mtime) or, with delim, each name directly under it. */
typedef int (*list_fn)(const char *name, uint64_t bytes, double mtime, void *ud);

static double iso_time(const char *s)
{
    struct tm tm = {0};
    double frac = 0;
    if (sscanf(s, "%d-%d-%dT%d:%d:%d", &tm.tm_year, &tm.tm_mon, &tm.tm_mday, &tm.tm_hour,
               &tm.tm_min, &tm.tm_sec) != 6)
        return 0;
    const char *dot = strchr(s, '.');
    if (dot) frac = strtod(dot, NULL);
    tm.tm_year -= 1900;
    tm.tm_mon -= 1;
    return (double)timegm(&tm) + frac;
}

static int s3_list(vx_blob *b, const char *prefix, int delim, list_fn fn, void *ud)
{
    char full[512], enc[1600], token[1024] = "", tenc[3100], q[5000];
    snprintf(full, sizeof full, "%s%s", b->prefix, prefix);
    uri_encode(full, enc, sizeof enc);
    size_t skip = strlen(b->prefix), plen = strlen(full);
    for (;;) {
        uri_encode(token, tenc, sizeof tenc);
        snprintf(q, sizeof q, "%s%s%s%slist-type=2&prefix=%s",
                 token[0] ? "continuation-token=" : "", token[0] ? tenc : "", token[0] ? "&" : "",
                 delim ? "delimiter=%2F&" : "", enc);
        s3_req r = {.method = "GET", .key = NULL, .query = q, .in_fd = -1, .out_fd = -1};
        if (s3_do(b, &r)) {
            free(r.mem);
            return -1;
        }
        const char *p = r.mem ? r.mem : "";
        int stop = 0;
        const char *c;
        while (!stop && (c = strstr(p, "<Contents>"))) {
            const char *end = strstr(c, "</Contents>");
            char key[1024] = "", size[32] = "0", lm[64] = "";
            xml_next(c, end, "Key", key, sizeof key);
            xml_next(c, end, "Size", size, sizeof size);
            xml_next(c, end, "LastModified", lm, sizeof lm);
            if (strlen(key) > plen)
                stop = fn(key + (delim ? plen : skip), strtoull(size, NULL, 10), iso_time(lm), ud);
            p = end ? end : c + 10;
        }
        p = r.mem ? r.mem : "";
        while (!stop && delim && (c = strstr(p, "<CommonPrefixes>"))) {
            char pre[1024] = "";
            xml_next(c, NULL, "Prefix", pre, sizeof pre);
            size_t l = strlen(pre);
            if (l > plen + 1 && pre[l - 1] == '/') {
                pre[l - 1] = 0;
                stop = fn(pre + plen, 0, 0, ud);
            }
            p = c + 16;
        }
        char trunc[16] = "";
        xml_next(r.mem, NULL, "IsTruncated", trunc, sizeof trunc);
        token[0] = 0;
        if (!stop && !strcmp(trunc, "true"))
            xml_next(r.mem, NULL, "NextContinuationToken", token, sizeof token);
        free(r.mem);
        if (!token[0]) return 0;
    }
}

typedef struct fetch_all {
    vx_blob *b;
    int rc, e, n;
} fetch_all;

static int fetch_one(const char *key, uint64_t bytes, double mtime, void *ud)
{
    (void)mtime;
    fetch_all *f = ud;
    char path[VX_PATH_MAX];
    struct stat st;
    f->n++;
    if (cache_path(f->b, key, path, sizeof path)) return 0;
    if (stat(path, &st) == 0 && (uint64_t)st.st_size == bytes) return 0;
    if (fetch(f->b, key, path)) {
        f->rc = -1;
        f->e = errno;
        return 1;
    }
    return 0;
}

/* ---- ops ---- */

static void curl_once(void)
{
    curl_global_init(CURL_GLOBAL_DEFAULT);
}

static void s3_close(vx_blob *b)
{
    if (!b) return;
    pthread_mutex_destroy(&b->lock);
    free(b->dirty);
    free(b);
}

static vx_blob *s3_open(const char *data_dir, const vx_blob_conf *conf, vx_err *err)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, curl_once);
    vx_blob *b = calloc(1, sizeof *b);
    if (!b) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    pthread_mutex_init(&b->lock, NULL);
    if (!conf || !conf->url || strncmp(conf->url, "s3://", 5)) {
        vx_err_set(err, VX_EINVAL, "bad_blob_store", "--blob-store s3:// needs a bucket");
        s3_close(b);
        return NULL;
    }
    if (s3_config(b, conf, err)) {
        s3_close(b);
        return NULL;
    }
    char results[VX_PATH_MAX];
    if (snprintf(b->cache, sizeof b->cache, "%s/blobcache", data_dir) >= (int)sizeof b->cache ||
        vx_mkdirs(b->cache, err)) {
        s3_close(b);
        return NULL;
    }
    /* Cached results may be unsynced leftovers of a crash: they come back
     * from the bucket when asked for. */
    snprintf(results, sizeof results, "%s/results", b->cache);
    vx_remove_tree(results);
    atomic_store(&b->cache_bytes, vx_tree_bytes(b->cache));
    VX_INFO("blob.s3_open", "endpoint=%s prefix=%s cache=%s", b->base, b->prefix, b->cache);
    return b;
}

static int s3_stage(vx_blob *b, const char *ns, const void *data, size_t n, char *tmp, size_t tmpn)
{
    char dir[VX_PATH_MAX];
    if (cache_path(b, ns, dir, sizeof dir) || vx_mkdirs(dir, NULL)) return -1;
    unsigned long seq = atomic_fetch_add(&b->seq, 1) + 1;
    snprintf(tmp, tmpn, "%s/tmp-%lu-%lu", dir, (unsigned long)getpid(), seq);
    return vx_write_new(tmp, data, n);
}

static void s3_discard(vx_blob *b, const char *tmp)
{
    (void)b;
    unlink(tmp);
}

/* Uploads fd (size bytes) to key: one PUT, or a multipart upload. */
static int upload_fd(vx_blob *b, const char *key, int fd, uint64_t size)
{
    if (size <= b->part_size) {
        s3_req r = {.method = "PUT", .key = key, .in_fd = fd, .in_len = size, .out_fd = -1};
        int rc = s3_do(b, &r);
        free(r.mem);
        return rc;
    }
    s3_req init = {.method = "POST", .key = key, .query = "uploads=", .in_fd = -1, .out_fd = -1};
    char id[1024] = "", enc[3100];
    if (s3_do(b, &init) || !xml_next(init.mem, NULL, "UploadId", id, sizeof id)) {
        int e = init.mem && !id[0] ? EIO : errno;
        free(init.mem);
        errno = e;
        return -1;
    }
    free(init.mem);
    uri_encode(id, enc, sizeof enc);
    uint64_t parts = (size + b->part_size - 1) / b->part_size;
    size_t cap = (size_t)parts * 160 + 128;
    char *doc = malloc(cap);
    int rc = doc ? 0 : -1, e = ENOMEM;
    size_t o = doc ? (size_t)snprintf(doc, cap, "<CompleteMultipartUpload>") : 0;
    for (uint64_t i = 0; i < parts && rc == 0; i++) {
        char q[3200];
        snprintf(q, sizeof q, "partNumber=%llu&uploadId=%s", (unsigned long long)i + 1, enc);
        uint64_t off = i * b->part_size;
        s3_req r = {.method = "PUT",
                    .key = key,
                    .query = q,
                    .in_fd = fd,
                    .in_off = (off_t)off,
                    .in_len = size - off < b->part_size ? size - off : b->part_size,
                    .out_fd = -1};
        rc = s3_do(b, &r);
        e = errno;
        if (rc == 0 && !r.etag[0]) rc = -1, e = EIO;
        if (rc == 0)
            o += (size_t)snprintf(doc + o, cap - o,
                                  "<Part><PartNumber>%llu</PartNumber><ETag>%s</ETag></Part>",
                                  (unsigned long long)i + 1, r.etag);
        free(r.mem);
    }
    if (rc == 0) {
        snprintf(doc + o, cap - o, "</CompleteMultipartUpload>");
        char q[3200];
        snprintf(q, sizeof q, "uploadId=%s", enc);
        s3_req r = {
            .method = "POST", .key = key, .query = q, .post = doc, .in_fd = -1, .out_fd = -1};
        rc = s3_do(b, &r);
        e = errno;
        /* S3 may answer 200 with an error document. */
        if (rc == 0 && r.mem && strstr(r.mem, "<Error>")) rc = -1, e = EAGAIN;
        free(r.mem);
    }
    free(doc);
    if (rc) {
        char q[3200];
        snprintf(q, sizeof q, "uploadId=%s", enc);
        s3_req r = {
            .method = "DELETE", .key = key, .query = q, .in_fd = -1, .out_fd = -1, .once = 1};
        s3_do(b, &r);
        free(r.mem);
        errno = e;
        return -1;
    }
    VX_INFO("blob.s3_multipart", "key=%s parts=%llu", key, (unsigned long long)parts);
    return 0;
}

static int upload_path(vx_blob *b, const char *key, const char *src, uint64_t *bytes)
{
    int fd = open(src, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return -1;
    struct stat st = {0};
    int rc = fstat(fd, &st) == 0 ? upload_fd(b, key, fd, (uint64_t)st.st_size) : -1;
    int e = errno;
    close(fd);
    if (bytes) *bytes = (uint64_t)st.st_size;
    errno = e;
    return rc;
}

/* Uploads src to key, then keeps it as the cached copy (or drops it). */
static int s3_put_file(vx_blob *b, const char *src, const char *key)
{
    uint64_t bytes = 0;
    if (upload_path(b, key, src, &bytes)) return -1;
    char path[VX_PATH_MAX];
    if (cache_path(b, key, path, sizeof path) == 0 && mkparent(path) == 0 && rename(src, path) == 0)
        cache_added(b, bytes);
    else
        unlink(src);
    return 0;
}

static int s3_put_bytes(vx_blob *b, const char *key, const void *data, size_t n, vx_err *err)
{
    char tmp[VX_PATH_MAX], ns[128];
    snprintf(ns, sizeof ns, "%s", key);
    char *slash = strrchr(ns, '/');
    if (slash) *slash = 0;
    if (s3_stage(b, ns, data, n, tmp, sizeof tmp) || s3_put_file(b, tmp, key)) {
        int e = errno;
        unlink(tmp);
        return vx_err_set(err, vx_err_io_kind(e), "store_failed", "cannot store %s: %s", key,
                          strerror(e));
    }
    return 0;
}

/* The cached copy of key, fetched when missing: an object, or each object
 * under the prefix key (ENOENT when neither). */
static int ensure_cached(vx_blob *b, const char *key, char *path, size_t n)
{
    if (cache_path(b, key, path, n)) return -1;
    struct stat st;
    if (stat(path, &st) == 0 && S_ISREG(st.st_mode)) {
        utimensat(AT_FDCWD, path, NULL, 0); /* the cache's LRU order */
        return 0;
    }
    if (is_dirty(b, key)) return 0;
    int have = stat(path, &st) == 0;
    if (!have || !S_ISDIR(st.st_mode)) {
        if (fetch(b, key, path) == 0) return 0;
        if (errno != ENOENT) return -1;
    }
    char pre[512];
    snprintf(pre, sizeof pre, "%s/", key);
    fetch_all f = {b, 0, 0, 0};
    if (s3_list(b, pre, 0, fetch_one, &f)) return -1;
    if (f.rc) {
        errno = f.e;
        return -1;
    }
    if (!f.n) {
        errno = ENOENT;
        return -1;
    }
    return 0;
}

static int s3_path(vx_blob *b, const char *key, char *buf, size_t n)
{
    if (ensure_cached(b, key, buf, n) == 0 || errno == ENOENT) return 0;
    return -1;
}

static char *s3_read(vx_blob *b, const char *key, size_t max, size_t *n, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (ensure_cached(b, key, path, sizeof path)) {
        int e = errno;
        vx_err_set(err, e == ENOENT ? VX_ENOTFOUND : vx_err_io_kind(e),
                   e == ENOENT ? "not_found" : "read_failed", "cannot read %s: %s", key,
                   strerror(e));
        return NULL;
    }
    return vx_read_file(path, max, n, err);
}

typedef struct sum {
    uint64_t bytes;
    double mtime;
    int n;
} sum;

static int add_up(const char *name, uint64_t bytes, double mtime, void *ud)
{
    (void)name;
    sum *s = ud;
    s->bytes += bytes;
    if (mtime > s->mtime) s->mtime = mtime;
    s->n++;
    return 0;
}

static int s3_stat(vx_blob *b, const char *key, uint64_t *bytes, double *mtime)
{
    char path[VX_PATH_MAX];
    if (is_dirty(b, key) && cache_path(b, key, path, sizeof path) == 0) {
        if (bytes) *bytes = vx_tree_bytes(path);
        if (mtime) *mtime = vx_now();
        return 1;
    }
    s3_req r = {.method = "HEAD", .key = key, .in_fd = -1, .out_fd = -1};
    if (s3_do(b, &r) == 0) {
        free(r.mem);
        if (bytes) *bytes = r.length > 0 ? (uint64_t)r.length : 0;
        if (mtime) *mtime = r.filetime > 0 ? (double)r.filetime : vx_now();
        return 0;
    }
    free(r.mem);
    if (errno != ENOENT) return -1;
    char pre[512];
    snprintf(pre, sizeof pre, "%s/", key);
    sum s = {0, 0, 0};
    if (s3_list(b, pre, 0, add_up, &s)) return -1;
    if (!s.n) {
        errno = ENOENT;
        return -1;
    }
    if (bytes) *bytes = s.bytes;
    if (mtime) *mtime = s.mtime;
    return 1;
}

static int s3_touch(vx_blob *b, const char *key)
{
    char path[VX_PATH_MAX];
    if (cache_path(b, key, path, sizeof path) == 0) utimensat(AT_FDCWD, path, NULL, 0);
    return 0;
}

static int s3_remove(vx_blob *b, const char *key)
{
    char path[VX_PATH_MAX];
    s3_req r = {.method = "DELETE", .key = key, .in_fd = -1, .out_fd = -1};
    int rc = s3_do(b, &r);
    free(r.mem);
    if (rc && errno != ENOENT) return -1;
    if (cache_path(b, key, path, sizeof path) == 0) unlink(path);
    return 0;
}

static int s3_move(vx_blob *b, const char *from, const char *to)
{
    char hdr[1024], f[VX_PATH_MAX], t[VX_PATH_MAX];
    snprintf(hdr, sizeof hdr, "x-amz-copy-source: /%s/%s%s", b->bucket, b->prefix, from);
    s3_req r = {.method = "PUT", .key = to, .in_fd = -1, .out_fd = -1, .hdr = hdr};
    int rc = s3_do(b, &r);
    /* A copy may answer 200 with an error document. */
    if (rc == 0 && r.mem && strstr(r.mem, "<Error>")) rc = -1, errno = EAGAIN;
    free(r.mem);
    if (rc) return -1;
    if (cache_path(b, from, f, sizeof f) == 0 && cache_path(b, to, t, sizeof t) == 0 &&
        rename(f, t) != 0)
        unlink(f);
    return s3_remove(b, from);
}

typedef struct del_all {
    vx_blob *b;
    int rc, e;
} del_all;

static int del_one(const char *key, uint64_t bytes, double mtime, void *ud)
{
    (void)bytes;
    (void)mtime;
    del_all *d = ud;
    if (s3_remove(d->b, key)) {
        d->rc = -1;
        d->e = errno;
    }
    return 0;
}

static int s3_remove_prefix(vx_blob *b, const char *prefix)
{
    char pre[512], path[VX_PATH_MAX];
    snprintf(pre, sizeof pre, "%s/", prefix);
    del_all d = {b, 0, 0};
    int rc = s3_list(b, pre, 0, del_one, &d);
    set_dirty(b, prefix, 0);
    if (cache_path(b, prefix, path, sizeof path) == 0) vx_remove_tree(path);
    if (rc || d.rc) {
        if (d.rc) errno = d.e;
        return -1;
    }
    return 0;
}

static int s3_make_prefix(vx_blob *b, const char *prefix, vx_err *err)
{
    char path[VX_PATH_MAX];
    if (cache_path(b, prefix, path, sizeof path))
        return vx_err_set(err, VX_EIO, "path_too_long", "a path is too long");
    /* A namespace needs nothing remote; a prefix under one (a job's results)
     * is written locally until its sync uploads it. */
    if (strchr(prefix, '/')) set_dirty(b, prefix, 1);
    return vx_mkdirs(path, err);
}

/* Uploads each file under dir (key: rel). */
static int upload_tree(vx_blob *b, const char *dir, const char *rel, uint64_t *bytes)
{
    DIR *d = opendir(dir);
    if (!d) return errno == ENOENT ? 0 : -1;
    struct dirent *e;
    int rc = 0;
    while (rc == 0 && (e = readdir(d))) {
        if (e->d_name[0] == '.') continue;
        char p[VX_PATH_MAX], k[VX_PATH_MAX];
        snprintf(p, sizeof p, "%s/%s", dir, e->d_name);
        snprintf(k, sizeof k, "%s/%s", rel, e->d_name);
        struct stat st;
        if (lstat(p, &st) != 0) continue;
        if (S_ISDIR(st.st_mode))
            rc = upload_tree(b, p, k, bytes);
        else if (S_ISREG(st.st_mode) && strncmp(e->d_name, "tmp-", 4) != 0) {
            uint64_t n = 0;
            rc = upload_path(b, k, p, &n);
            *bytes += n;
        }
    }
    int en = errno;
    closedir(d);
    errno = en;
    return rc;
}

static int s3_sync(vx_blob *b, const char *ns, vx_err *err)
{
    /* put_file, put_bytes, move and remove are durable when they return;
     * a dirty prefix goes up now. */
    if (!is_dirty(b, ns)) return 0;
    char path[VX_PATH_MAX];
    uint64_t bytes = 0;
    if (cache_path(b, ns, path, sizeof path) || upload_tree(b, path, ns, &bytes)) {
        int e = errno;
        return vx_err_set(err, vx_err_io_kind(e), "store_failed", "cannot upload %s: %s", ns,
                          strerror(e));
    }
    set_dirty(b, ns, 0);
    cache_added(b, bytes);
    return 0;
}

typedef struct names {
    int (*fn)(const char *name, void *ud);
    void *ud;
} names;

static int one_name(const char *name, uint64_t bytes, double mtime, void *ud)
{
    (void)bytes;
    (void)mtime;
    names *n = ud;
    return n->fn(name, n->ud);
}

static int s3_list_ns(vx_blob *b, const char *ns, int (*fn)(const char *name, void *ud), void *ud)
{
    char pre[512];
    snprintf(pre, sizeof pre, "%s/", ns);
    names n = {fn, ud};
    return s3_list(b, pre, 1, one_name, &n);
}

static int s3_ping(vx_blob *b)
{
    s3_req r = {.method = "HEAD", .key = NULL, .in_fd = -1, .out_fd = -1, .once = 1};
    int rc = s3_do(b, &r);
    free(r.mem);
    return rc == 0;
}

const vx_blob_ops vx_blob_s3 = {
    .name = "s3",
    .shared = 1,
    .open = s3_open,
    .close = s3_close,
    .stage = s3_stage,
    .discard = s3_discard,
    .put_file = s3_put_file,
    .put_bytes = s3_put_bytes,
    .read = s3_read,
    .stat = s3_stat,
    .touch = s3_touch,
    .move = s3_move,
    .remove = s3_remove,
    .remove_prefix = s3_remove_prefix,
    .make_prefix = s3_make_prefix,
    .sync = s3_sync,
    .list = s3_list_ns,
    .path = s3_path,
    .ping = s3_ping,
};
