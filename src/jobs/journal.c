#include "jobs/journal.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "util/fsutil.h"
#include "util/log.h"
#include "util/json.h"

struct vx_journal {
    char path[VX_PATH_MAX];
    int fd;
    off_t size;       /* bytes of complete records: where the next one starts */
    off_t reserved;   /* blocks allocated up to here (fallocate, past the size) */
    int no_fallocate; /* the file system has none: nothing is reserved */
    int short_said;   /* a failed top-up or a refusal was logged: once until one works */
    pthread_mutex_t lock;
};

/* Space kept allocated past the journal's end, so that the records of jobs
 * already running (their start and end) still go in on a full disk: a job
 * whose end could not be written was told succeeded, and ran again after
 * a restart. About 4,000 records; topped up when half is used. */
#define RESERVE ((off_t)1 << 20)
/* What a new job's first record must leave of the reserve at least, for
 * the records owed to the jobs accepted before it (each record is about a
 * job's snapshot, 1.2 KB for a voxelize job: 512 KiB is some 200 jobs'
 * start and end). On a full disk new jobs are refused (507) from there on. */
#define RESERVE_FLOOR (RESERVE / 2)

/* Makes at least need bytes past j->size reserved, topping up to RESERVE
 * or need (lock held, or before the journal is shared). A file system
 * without fallocate, or without room, keeps what it has: appends then take
 * their chance as before. */
static void reserve_tail(vx_journal *j, off_t need)
{
    if (j->no_fallocate || j->reserved - j->size >= need) return;
    off_t len = need > RESERVE ? need : RESERVE;
    int rc = fallocate(j->fd, FALLOC_FL_KEEP_SIZE, j->size, len);
    if (rc == 0) {
        j->reserved = j->size + len;
        j->short_said = 0;
    } else if (errno == EOPNOTSUPP || errno == ENOSYS) {
        j->no_fallocate = 1;
    } else {
        const int e = errno;
        /* What the file holds already counts: the reserve a run before this
         * one left (a restart on a full disk), or part of this top-up. It
         * is found by halving (to 4 KiB) between what failed and what is
         * known: a range already allocated costs nothing (the file's block
         * count would also count metadata, and space a file system may
         * take back). */
        if (j->reserved < j->size) j->reserved = j->size;
        off_t ok = j->reserved - j->size, bad = len;
        while (bad - ok > 4096) {
            const off_t mid = (ok + (bad - ok) / 2) & ~(off_t)4095;
            if (mid <= ok) break;
            if (fallocate(j->fd, FALLOC_FL_KEEP_SIZE, j->size, mid) == 0)
                ok = mid;
            else
                bad = mid;
        }
        j->reserved = j->size + ok;
        if (!j->short_said) { /* not once a request while the disk stays full */
            j->short_said = 1;
            VX_WARN("journal.reserve_failed", "path=%s error=%d reserved=%lld", VX_Q(j->path), e,
                    (long long)(j->reserved - j->size));
        }
    }
}

/* A record is one line: '#', the CRC-32 of the JSON as 8 hex digits, a
 * space, the JSON, '\n'. Lines of journals written before the framing (bare
 * JSON) are still read. */
#define FRAME_HEAD 10 /* "#xxxxxxxx " */

static uint32_t crc_of(const char *p, size_t n)
{
    return (uint32_t)crc32(0L, (const Bytef *)p, (uInt)n);
}

vx_journal *vx_journal_open(const char *path, vx_err *err)
{
    vx_journal *j = calloc(1, sizeof *j);
    if (!j) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        return NULL;
    }
    snprintf(j->path, sizeof j->path, "%s", path);
    j->fd = open(path, O_RDWR | O_CREAT | O_APPEND | O_CLOEXEC, 0640);
    if (j->fd < 0) {
        int e = errno;
        VX_ERROR("journal.open_failed", "path=%s error=%d", VX_Q(path), e);
        vx_err_set(err, vx_err_io_kind(e), "journal_failed", "cannot open the journal: %s",
                   strerror(e));
        free(j);
        return NULL;
    }
    struct stat st;
    if (fstat(j->fd, &st) != 0 || !S_ISREG(st.st_mode)) { /* a FIFO's reads would block */
        VX_ERROR("journal.open_failed", "path=%s error=not_a_regular_file", VX_Q(path));
        vx_err_set(err, VX_EIO, "journal_failed", "the journal is not a regular file");
        close(j->fd);
        free(j);
        return NULL;
    }
    j->size = st.st_size;
    reserve_tail(j, RESERVE / 2);
    pthread_mutex_init(&j->lock, NULL);
    return j;
}

void vx_journal_close(vx_journal *j)
{
    if (!j) return;
    if (j->fd >= 0) {
        fdatasync(j->fd);
        close(j->fd);
    }
    pthread_mutex_destroy(&j->lock);
    free(j);
}

/* A framed record at p (n bytes, no newline): the JSON, or NULL. */
static cJSON *parse_framed(const char *p, size_t n)
{
    if (n < FRAME_HEAD + 2 || p[0] != '#' || p[FRAME_HEAD - 1] != ' ' || p[FRAME_HEAD] != '{')
        return NULL;
    char hex[9];
    memcpy(hex, p + 1, 8);
    hex[8] = 0;
    char *end;
    unsigned long want = strtoul(hex, &end, 16);
    if (*end || crc_of(p + FRAME_HEAD, n - FRAME_HEAD) != (uint32_t)want) return NULL;
    return cJSON_ParseWithLength(p + FRAME_HEAD, n - FRAME_HEAD);
}

/* Whether a frame's head ("#" and 8 hex digits and a space) ends just
 * before p (line <= p). */
static int after_frame_head(const char *line, const char *p)
{
    if (p - line < FRAME_HEAD || p[-FRAME_HEAD] != '#' || p[-1] != ' ') return 0;
    for (const char *h = p - FRAME_HEAD + 1; h < p - 1; h++)
        if (!((*h >= '0' && *h <= '9') || (*h >= 'a' && *h <= 'f') || (*h >= 'A' && *h <= 'F')))
            return 0;
    return 1;
}

/* A line that is not one good record may be a fragment that a failed write
 * left behind with a good record glued on after it (journals written before
 * failed appends were truncated): the last frame (or, unframed, the first
 * JSON suffix) that checks out is that record. The unframed search is for
 * journals of versions that wrote no frames: it never reads a frame's own
 * payload, whose CRC failed (a bit flipped on disk is not a record). */
static cJSON *salvage(const char *line, size_t n)
{
    for (size_t i = n; i-- > 1;)
        if (line[i] == '#') {
            cJSON *rec = parse_framed(line + i, n - i);
            if (rec) return rec;
        }
    if (line[0] == '#') return NULL; /* a framed record: its CRC decides */
    static const char key[] = "{\"job\":";
    for (const char *p = line + 1; (p = memmem(p, n - (size_t)(p - line), key, sizeof key - 1));
         p++) {
        if (after_frame_head(line, p)) continue;
        cJSON *rec = cJSON_ParseWithLength(p, n - (size_t)(p - line));
        if (rec) return rec;
    }
    return NULL;
}

/* The journal read in pieces (replay): lines are kept up to MAX_LINE bytes;
 * a longer one is no record this daemon wrote (damage: zeros, garbage) and
 * is counted through, not held. */
#define MAX_LINE (VX_JOURNAL_MAX_RECORD + FRAME_HEAD + 1)

typedef struct reader {
    int fd;
    size_t at, end;
    char buf[1 << 16];
} reader;

/* The next line of r into *line (grown as needed, up to MAX_LINE + 1
 * bytes): 1 with *n its bytes, the '\n' included when there is one
 * (*ended), and *over set when it is longer than MAX_LINE (its bytes not
 * kept); 0 at the end of the file; -1 on a read or allocation error
 * (errno). */
static int next_line(reader *r, char **line, size_t *cap, off_t *n, int *over, int *ended)
{
    size_t kept = 0;
    *n = 0;
    *over = 0;
    *ended = 0;
    for (;;) {
        if (r->at == r->end) {
            ssize_t got = read(r->fd, r->buf, sizeof r->buf);
            if (got < 0 && errno == EINTR) continue;
            if (got < 0) return -1;
            if (got == 0) return *n > 0;
            r->at = 0;
            r->end = (size_t)got;
        }
        char *p = r->buf + r->at, *nl = memchr(p, '\n', r->end - r->at);
        size_t take = nl ? (size_t)(nl - p) + 1 : r->end - r->at;
        if (!*over && kept + take > MAX_LINE) *over = 1;
        if (!*over) {
            if (kept + take + 1 > *cap) {
                size_t want = 2 * *cap > kept + take + 1 ? 2 * *cap : kept + take + 1;
                if (want > MAX_LINE + 1) want = MAX_LINE + 1;
                char *g = realloc(*line, want);
                if (!g) return -1;
                *line = g;
                *cap = want;
            }
            memcpy(*line + kept, p, take);
            kept += take;
        }
        *n += (off_t)take;
        r->at += take;
        if (nl) return *ended = 1;
    }
}

long vx_journal_replay(vx_journal *j, void (*fn)(const cJSON *rec, void *ud), void *ud, vx_err *err)
{
    reader *r = malloc(sizeof *r);
    int fd = r ? open(j->path, O_RDONLY | O_CLOEXEC) : -1;
    if (fd < 0) {
        int e = r ? errno : ENOMEM;
        free(r);
        VX_ERROR("journal.open_failed", "path=%s error=%d", VX_Q(j->path), e);
        return vx_err_set(err, VX_EIO, "journal_failed", "cannot read the journal: %s",
                          strerror(e));
    }
    r->fd = fd;
    r->at = r->end = 0;
    char *line = NULL;
    size_t cap = 0;
    off_t n;
    int over, ended, got;
    long count = 0, lineno = 0;
    off_t good = 0; /* end of the last complete line */
    int torn = 0;
    long damaged = 0; /* records that do not check out, past what a crash tears */
    while ((got = next_line(r, &line, &cap, &n, &over, &ended)) > 0) {
        lineno++;
        if (!ended) {
            /* Torn tail: written partly before a crash, never acknowledged:
             * the start of one record, no NUL in it. Anything else there
             * (zeros, garbage, more than a record) is damage to acknowledged
             * records. */
            int record = !over && (line[0] == '#' || line[0] == '{') && !memchr(line, 0, (size_t)n);
            if (record) {
                VX_WARN("journal.torn_tail", "path=%s line=%ld bytes=%lld", VX_Q(j->path), lineno,
                        (long long)n);
            } else {
                VX_ERROR("journal.damaged_tail", "path=%s line=%ld bytes=%lld", VX_Q(j->path),
                         lineno, (long long)n);
                damaged++;
            }
            torn = 1;
            break;
        }
        good += n;
        if (over) {
            VX_ERROR("journal.bad_record", "path=%s line=%ld bytes=%lld reason=too_long",
                     VX_Q(j->path), lineno, (long long)n);
            damaged++;
            continue;
        }
        size_t len = (size_t)n - 1;
        cJSON *rec = line[0] == '#' ? parse_framed(line, len) : cJSON_ParseWithLength(line, len);
        if (!rec && (rec = salvage(line, len)))
            VX_WARN("journal.salvaged", "path=%s line=%ld", VX_Q(j->path), lineno);
        if (!rec) {
            VX_ERROR("journal.bad_record", "path=%s line=%ld", VX_Q(j->path), lineno);
            damaged++;
            continue;
        }
        fn(rec, ud);
        cJSON_Delete(rec);
        count++;
    }
    int e = errno;
    free(line);
    close(fd);
    free(r);
    if (got < 0) {
        VX_ERROR("journal.read_failed", "path=%s line=%ld error=%d", VX_Q(j->path), lineno, e);
        return vx_err_set(err, vx_err_io_kind(e), "journal_failed", "cannot read the journal: %s",
                          strerror(e));
    }
    if (damaged) {
        /* the evidence, before the cut and the compaction rewrite it */
        char copy[4200];
        int kept = 0;
        long long now = (long long)time(NULL);
        for (int k = 0; k < 10 && !kept; k++) { /* a name no copy has (two in one second) */
            if (k)
                snprintf(copy, sizeof copy, "%s.damaged-%lld.%d", j->path, now, k);
            else
                snprintf(copy, sizeof copy, "%s.damaged-%lld", j->path, now);
            kept = vx_copy_file(j->path, copy) == 0;
        }
        VX_ERROR("journal.damaged", "path=%s records=%ld copy=%s", VX_Q(j->path), damaged,
                 kept ? VX_Q(copy) : "-");
    }
    pthread_mutex_lock(&j->lock);
    if (torn) {
        /* Cut the torn tail so the next record starts on a line of its own
         * (compaction may not run: the disk can be full). */
        if (ftruncate(j->fd, good) != 0 || fdatasync(j->fd) != 0)
            VX_ERROR("journal.truncate_failed", "path=%s error=%d", VX_Q(j->path), errno);
        j->reserved = good; /* a truncate frees the blocks past the end too */
    }
    j->size = good;
    if (torn) reserve_tail(j, RESERVE / 2);
    pthread_mutex_unlock(&j->lock);
    return count;
}

/* The record as one framed line; owned, its length in *n. */
static char *frame(const cJSON *rec, size_t *n)
{
    char *json = vx_json_print(rec, 0);
    if (!json) return NULL;
    size_t len = strlen(json);
    char *line = malloc(len + FRAME_HEAD + 2);
    if (line) {
        snprintf(line, FRAME_HEAD + 1, "#%08x ", crc_of(json, len));
        memcpy(line + FRAME_HEAD, json, len);
        line[FRAME_HEAD + len] = '\n';
        *n = FRAME_HEAD + len + 1;
    }
    free(json);
    return line;
}

int vx_journal_append(vx_journal *j, const cJSON *rec, size_t owed, vx_err *err)
{
    size_t n;
    char *text = frame(rec, &n);
    if (!text) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
    if (n > MAX_LINE) { /* replay would take it for damage */
        free(text);
        return vx_err_set(err, VX_ETOOBIG, "too_large",
                          "the job's record is %zu bytes, over the journal's %d MiB a record", n,
                          VX_JOURNAL_MAX_RECORD >> 20);
    }
    pthread_mutex_lock(&j->lock);
    if (owed) { /* records of this one's size, and some room for their stats */
        off_t floor =
            (off_t)(owed > ((size_t)1 << 30) / (n + 1024) ? ((size_t)1 << 30) : owed * (n + 1024));
        if (floor < RESERVE_FLOOR) floor = RESERVE_FLOOR;
        reserve_tail(j, floor + (off_t)n);
        if (!j->no_fallocate && j->reserved - j->size < floor + (off_t)n) {
            const long long kept = (long long)(j->reserved - j->size);
            pthread_mutex_unlock(&j->lock);
            free(text);
            VX_DEBUG("journal.reserve_kept", "path=%s reserved=%lld", VX_Q(j->path), kept);
            return vx_err_set(err, VX_ENOSPC, "insufficient_storage",
                              "the disk is full: the job journal's last space is kept for the "
                              "jobs already accepted");
        }
    }
    int rc = vx_write_all(j->fd, text, n);
    if (rc == 0) rc = fdatasync(j->fd);
    int e = errno;
    /* A journal removed under the daemon (rm -rf of the data dir) still
     * takes appends, into a file no restart will read: not durable. */
    struct stat st;
    if (rc == 0 && fstat(j->fd, &st) == 0 && st.st_nlink == 0) rc = -1, e = ENOENT;
    if (rc == 0) {
        j->size += (off_t)n;
        reserve_tail(j, RESERVE / 2);
    } else {
        /* A torn write (ENOSPC after part of the line) must not stay in the
         * file: the next record would be glued onto it. Shrinking needs no
         * space; if even that fails, replay salvages the glued record. The
         * truncate frees the reserve past the end too. */
        if (ftruncate(j->fd, j->size) != 0 || fdatasync(j->fd) != 0)
            VX_ERROR("journal.truncate_failed", "path=%s error=%d", VX_Q(j->path), errno);
        j->reserved = j->size;
    }
    pthread_mutex_unlock(&j->lock);
    free(text);
    if (rc != 0) {
        VX_ERROR("journal.append_failed", "path=%s error=%d", VX_Q(j->path), e);
        if (e == ENOENT)
            return vx_err_set(err, VX_EIO, "journal_failed",
                              "the job journal was removed from the data directory");
        return vx_err_set(err, vx_err_io_kind(e),
                          e == ENOSPC || e == EDQUOT ? "insufficient_storage" : "journal_failed",
                          "the job journal could not be written: %s", strerror(e));
    }
    return 0;
}

int vx_journal_compact(vx_journal *j, cJSON *const *recs, size_t n, vx_err *err)
{
    char tmp[2100];
    snprintf(tmp, sizeof tmp, "%s.compact", j->path);
    int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (fd < 0) {
        int e = errno;
        return vx_err_set(err, vx_err_io_kind(e), "journal_failed",
                          "cannot compact the journal: %s", strerror(e));
    }
    int rc = 0, e = 0;
    off_t size = 0;
    for (size_t i = 0; i < n && rc == 0; i++) {
        size_t len;
        char *text = frame(recs[i], &len);
        if (!text) {
            rc = -1;
            e = ENOMEM;
            break;
        }
        rc = vx_write_all(fd, text, len);
        if (rc) e = errno;
        size += (off_t)len;
        free(text);
    }
    if (rc == 0 && (rc = fsync(fd)) != 0) e = errno;
    close(fd);
    if (rc != 0) {
        unlink(tmp);
        return vx_err_set(err, vx_err_io_kind(e), "journal_failed",
                          "cannot compact the journal: %s", strerror(e));
    }
    pthread_mutex_lock(&j->lock);
    rc = rename(tmp, j->path);
    if (rc == 0) {
        int nfd = open(j->path, O_RDWR | O_APPEND | O_CLOEXEC);
        if (nfd >= 0) {
            close(j->fd);
            j->fd = nfd;
            j->size = j->reserved = size;
            reserve_tail(j, RESERVE / 2);
        } else {
            rc = -1;
        }
    }
    pthread_mutex_unlock(&j->lock);
    if (rc != 0)
        return vx_err_set(err, VX_EIO, "journal_failed", "cannot replace the journal: %s",
                          strerror(errno));
    char dir[VX_PATH_MAX];
    snprintf(dir, sizeof dir, "%s", j->path);
    char *slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    return vx_fsync_dir(slash ? dir : ".", err);
}

int vx_journal_intact(vx_journal *j)
{
    struct stat mine, named;
    pthread_mutex_lock(&j->lock);
    int ok = fstat(j->fd, &mine) == 0 && stat(j->path, &named) == 0 && mine.st_nlink > 0 &&
             mine.st_dev == named.st_dev && mine.st_ino == named.st_ino;
    pthread_mutex_unlock(&j->lock);
    return ok;
}

long vx_journal_size(vx_journal *j)
{
    struct stat st;
    pthread_mutex_lock(&j->lock);
    long n = fstat(j->fd, &st) == 0 ? (long)st.st_size : -1;
    pthread_mutex_unlock(&j->lock);
    return n;
}
