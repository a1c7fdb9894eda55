/* Results: per-job output dirs under a byte/idle-age budget (store.h). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

#include "store/store_int.h"
#include "util/fsutil.h"
#include "util/log.h"

/* A result id: a job id (hex), or in cluster mode a job id and its attempt
 * ("<hex>/<digits>": results/JOB/ATTEMPT, so that a stale attempt never
 * writes over the winner's). */
static int valid_jid(const char *s)
{
    size_t n = strlen(s), i = 0;
    if (n == 0 || n >= sizeof(((result_entry *)0)->jid)) return 0;
    while (i < n && ((s[i] >= '0' && s[i] <= '9') || (s[i] >= 'a' && s[i] <= 'f')))
        i++;
    if (i == 0) return 0;
    if (i == n) return 1;
    if (s[i++] != '/' || i == n) return 0;
    for (; i < n; i++)
        if (s[i] < '0' || s[i] > '9') return 0;
    return 1;
}

/* The key of job jid's result prefix. */
static void result_key(const char *jid, char *buf, size_t n)
{
    snprintf(buf, n, "results/%s", jid);
}

static int result_add_locked(vx_store *s, const char *jid, uint64_t bytes, double t)
{
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results_bytes -= s->results[i].bytes;
            s->results[i].bytes = bytes;
            s->results[i].last_access = t;
            s->results_bytes += bytes;
            return 0;
        }
    if (s->nresults == s->capresults) {
        size_t cap = s->capresults ? 2 * s->capresults : 64;
        result_entry *n = realloc(s->results, cap * sizeof *n);
        if (!n) return -1;
        s->results = n;
        s->capresults = cap;
    }
    result_entry *e = &s->results[s->nresults++];
    snprintf(e->jid, sizeof e->jid, "%s", jid);
    e->bytes = bytes;
    e->last_access = t;
    s->results_bytes += bytes;
    return 0;
}

static int load_result(const char *name, void *ud)
{
    vx_store *s = ud;
    if (name[0] == '.' || !valid_jid(name)) return 0;
    char key[128];
    result_key(name, key, sizeof key);
    uint64_t bytes;
    double t;
    if (s->ops->stat(s->blob, key, &bytes, &t) == 1) result_add_locked(s, name, bytes, t);
    return 0;
}

int vx_store_load_results(vx_store *s)
{
    return s->ops->list(s->blob, "results", load_result, s);
}

/* Drops jid's entry from the budget; caller holds the lock. */
/* Forgets the results of jid and of everything under it ("jid/attempt":
 * removing a key removes its whole prefix). */
static void result_forget_locked(vx_store *s, const char *jid)
{
    size_t n = strlen(jid);
    for (size_t i = 0; i < s->nresults;) {
        const char *k = s->results[i].jid;
        if (!strncmp(k, jid, n) && (k[n] == 0 || k[n] == '/')) {
            s->results_bytes -= s->results[i].bytes;
            s->results[i] = s->results[--s->nresults];
        } else {
            i++;
        }
    }
}

int vx_store_result_dir(vx_store *s, const char *jid, char *buf, size_t n, vx_err *err)
{
    if (!valid_jid(jid)) return vx_err_set(err, VX_EINTERNAL, "bad_job_id", "bad job id");
    char key[128];
    result_key(jid, key, sizeof key);
    s->ops->path(s->blob, key, buf, n);
    s->ops->remove_prefix(s->blob, key); /* left over from an interrupted earlier attempt */
    pthread_mutex_lock(&s->lock);
    result_forget_locked(s, jid);
    pthread_mutex_unlock(&s->lock);
    return s->ops->make_prefix(s->blob, key, err);
}

int vx_store_result_commit(vx_store *s, const char *jid, vx_err *err)
{
    char key[128];
    result_key(jid, key, sizeof key);
    uint64_t bytes = 0;
    s->ops->stat(s->blob, key, &bytes, NULL);
    /* One result over the whole byte budget would evict every other result
     * and then itself, its job said succeeded: it fails instead. */
    uint64_t max = s->desc.results_max_bytes;
    if (max && bytes > max) {
        VX_WARN("store.result_too_large", "job=%s bytes=%llu results_max_bytes=%llu", jid,
                (unsigned long long)bytes, (unsigned long long)max);
        vx_store_result_remove(s, jid);
        return vx_err_set(err, VX_ETOOBIG, "result_too_large",
                          "the job's result is %llu bytes, more than the whole results budget "
                          "(--results-max-bytes %llu): it was removed; ask for a smaller "
                          "result or raise --results-max-bytes",
                          (unsigned long long)bytes, (unsigned long long)max);
    }
    vx_err e;
    vx_err_clear(&e);
    /* the job's dir, then results/ that names it: a power loss after the
     * journal said succeeded lost the whole dir (its entry unsynced) */
    int rc = s->ops->sync(s->blob, key, &e) || s->ops->sync(s->blob, "results", &e);
    if (rc) {
        VX_ERROR("store.result_unsynced", "job=%s code=%s message=%s", jid, e.code,
                 vx_log_quote((char[600]){0}, 600, e.message));
        if (err) *err = e;
    }
    pthread_mutex_lock(&s->lock);
    result_add_locked(s, jid, bytes, vx_now());
    pthread_mutex_unlock(&s->lock);
    return rc ? -1 : 0;
}

int vx_store_result_file(vx_store *s, const char *jid, const char *file, char *buf, size_t n,
                         vx_err *err)
{
    char key[128];
    result_key(jid, key, sizeof key);
    pthread_mutex_lock(&s->lock);
    int found = 0;
    for (size_t i = 0; i < s->nresults; i++)
        if (strcmp(s->results[i].jid, jid) == 0) {
            s->results[i].last_access = vx_now();
            found = 1;
            break;
        }
    pthread_mutex_unlock(&s->lock);
    /* On a shared store another daemon may have written it (cluster mode:
     * the replica that ran the job): indexed once seen. */
    uint64_t bytes = 0;
    errno = ENOENT;
    int st = found || s->ops->shared ? s->ops->stat(s->blob, key, &bytes, NULL) : -1;
    int st_errno = errno;
    if (!found && st >= 0 && valid_jid(jid)) {
        pthread_mutex_lock(&s->lock);
        result_add_locked(s, jid, bytes, vx_now());
        pthread_mutex_unlock(&s->lock);
        found = 1;
    }
    /* a store that cannot be asked (an s3 outage) is no answer: 503, not
     * 410, also where this replica never saw the results */
    if (st < 0 && st_errno != ENOENT)
        return vx_err_set(err, vx_err_io_kind(st_errno), "store_failed",
                          "cannot reach the results of job %s: %s", jid, strerror(st_errno));
    if (st < 0 && found && !s->ops->shared) { /* removed behind the daemon: out of the budget */
        VX_WARN("store.result_missing", "job=%s", jid);
        pthread_mutex_lock(&s->lock);
        result_forget_locked(s, jid);
        pthread_mutex_unlock(&s->lock);
    }
    if (st < 0)
        return vx_err_set(err, VX_EGONE, "result_evicted",
                          "the results of job %s are gone (%s): run the job again", jid,
                          found ? "removed from the store, not by this daemon's budget"
                                : "removed by the results budget, or from the disk");
    /* The mtime of the dir carries the LRU order across restarts. */
    s->ops->touch(s->blob, key);
    char dir[VX_PATH_MAX];
    if (s->ops->path(s->blob, key, dir, sizeof dir))
        return vx_err_set(err, vx_err_io_kind(errno), "store_failed",
                          "cannot fetch the results of job %s: %s", jid, strerror(errno));
    snprintf(buf, n, "%s/%s", dir, file);
    return 0;
}

void vx_store_result_remove(vx_store *s, const char *jid)
{
    char key[128];
    result_key(jid, key, sizeof key);
    pthread_mutex_lock(&s->lock);
    result_forget_locked(s, jid);
    pthread_mutex_unlock(&s->lock);
    s->ops->remove_prefix(s->blob, key);
}

/* Moves the results of jobs jids (n of them) into a new dir
 * DATA/lost+found/results-TIME/ (TIME: UTC, to the second, a suffix when
 * taken), forgotten by the budget; said at error level. One that cannot be
 * moved stays where it is (and in the budget). */
static void results_quarantine(vx_store *s, char (*jids)[sizeof s->results[0].jid], size_t n)
{
    char dir[VX_PATH_MAX], stamp[32];
    time_t now = time(NULL);
    struct tm tm;
    gmtime_r(&now, &tm);
    strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &tm);
    snprintf(dir, sizeof dir, "%s/lost+found", s->dir);
    int made = mkdir(dir, 0750) == 0 || errno == EEXIST;
    for (int k = 0; made && k < 100; k++) { /* a name no earlier start took */
        if (k)
            snprintf(dir, sizeof dir, "%s/lost+found/results-%s.%d", s->dir, stamp, k);
        else
            snprintf(dir, sizeof dir, "%s/lost+found/results-%s", s->dir, stamp);
        made = mkdir(dir, 0750) == 0;
        if (made || errno != EEXIST) break;
    }
    int e = errno;
    size_t moved = 0;
    for (size_t i = 0; made && i < n; i++) {
        char key[128], from[VX_PATH_MAX], to[VX_PATH_MAX];
        result_key(jids[i], key, sizeof key);
        if (strchr(jids[i], '/') || s->ops->path(s->blob, key, from, sizeof from) ||
            snprintf(to, sizeof to, "%s/%s", dir, jids[i]) >= (int)sizeof to ||
            rename(from, to) != 0) {
            e = errno;
            continue;
        }
        VX_INFO("store.result_quarantined", "job=%s", jids[i]);
        pthread_mutex_lock(&s->lock);
        result_forget_locked(s, jids[i]);
        pthread_mutex_unlock(&s->lock);
        moved++;
    }
    if (made) {
        vx_fsync_dir(dir, NULL);
        s->ops->sync(s->blob, "results", NULL);
    }
    VX_ERROR("store.results_quarantined",
             "results=%zu moved=%zu dir=%s error=%d reason=\"no job record names them: the "
             "journal was emptied, removed or damaged?\"",
             n, moved, made ? VX_Q(dir) : "-", moved == n ? 0 : e);
}

size_t vx_store_results_prune(vx_store *s, int (*keep)(void *ud, const char *jid), void *ud)
{
    if (s->ops->shared) return 0; /* other daemons' results are theirs */
    pthread_mutex_lock(&s->lock);
    size_t nv = 0, nq = 0;
    char(*victims)[sizeof s->results[0].jid] =
        s->nresults ? malloc(2 * s->nresults * sizeof *victims) : NULL;
    char(*lost)[sizeof s->results[0].jid] = victims ? victims + s->nresults : NULL;
    for (size_t i = 0; victims && i < s->nresults; i++) {
        int k = keep(ud, s->results[i].jid);
        if (k == 0) memcpy(victims[nv++], s->results[i].jid, sizeof *victims);
        if (k < 0) memcpy(lost[nq++], s->results[i].jid, sizeof *victims);
    }
    pthread_mutex_unlock(&s->lock);
    for (size_t i = 0; i < nv; i++) {
        VX_INFO("store.result_pruned", "job=%s", victims[i]);
        vx_store_result_remove(s, victims[i]);
    }
    if (nq) results_quarantine(s, lost, nq);
    free(victims);
    return nv + nq;
}

int vx_store_results_evict(vx_store *s)
{
    int removed = 0;
    for (;;) {
        char victim[48] = {0};
        double now = vx_now();
        pthread_mutex_lock(&s->lock);
        size_t oldest = (size_t)-1;
        for (size_t i = 0; i < s->nresults; i++)
            if (oldest == (size_t)-1 || s->results[i].last_access < s->results[oldest].last_access)
                oldest = i;
        if (oldest != (size_t)-1) {
            int over_bytes =
                s->desc.results_max_bytes && s->results_bytes > s->desc.results_max_bytes;
            int too_old = s->desc.results_max_age_s > 0 &&
                          now - s->results[oldest].last_access > s->desc.results_max_age_s;
            if (over_bytes || too_old)
                snprintf(victim, sizeof victim, "%s", s->results[oldest].jid);
        }
        pthread_mutex_unlock(&s->lock);
        if (!victim[0]) break;
        VX_INFO("store.evict", "job=%s", victim);
        vx_store_result_remove(s, victim);
        __atomic_add_fetch(&s->evicted, 1, __ATOMIC_RELAXED);
        removed++;
    }
    return removed;
}

uint64_t vx_store_results_evicted(vx_store *s)
{
    return __atomic_load_n(&s->evicted, __ATOMIC_RELAXED);
}

uint64_t vx_store_results_bytes(vx_store *s)
{
    pthread_mutex_lock(&s->lock);
    uint64_t b = s->results_bytes;
    pthread_mutex_unlock(&s->lock);
    return b;
}
