/* Big zeroed buffers (bigmem.h). */
#include "util/bigmem.h"

#include <limits.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>

#include "util/par.h"

#define BIGMEM_MAP_MIN ((size_t)4 << 20)
#define BIGMEM_ROUND ((size_t)2 << 20) /* mappings in whole huge pages, to fit again */
#define KEPT_MAX 16

/* The kept mappings, unordered. */
static pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
static struct {
    void *p;
    size_t len;
} kept[KEPT_MAX];
static int nkept;
static size_t kept_bytes, keep_limit;

void vx_bigmem_keep(size_t bytes)
{
    pthread_mutex_lock(&mu);
    keep_limit = bytes;
    while (nkept && kept_bytes > keep_limit) {
        nkept--;
        kept_bytes -= kept[nkept].len;
        munmap(kept[nkept].p, kept[nkept].len);
    }
    pthread_mutex_unlock(&mu);
}

size_t vx_bigmem_kept(void)
{
    pthread_mutex_lock(&mu);
    size_t n = kept_bytes;
    pthread_mutex_unlock(&mu);
    return n;
}

/* Takes kept mapping i out of the list (mu held). */
static void drop(int i)
{
    kept_bytes -= kept[i].len;
    kept[i] = kept[--nkept];
}

/* The smallest kept mapping that holds len, taken out of the list; of one
 * BIGMEM_MAP_MIN or more longer only the head is taken, the tail stays
 * kept (a 4 MiB scratch does not hold a whole grid's mapping). */
static void *take(size_t len, size_t *got)
{
    pthread_mutex_lock(&mu);
    int best = -1;
    for (int i = 0; i < nkept; i++)
        if (kept[i].len >= len && (best < 0 || kept[i].len < kept[best].len)) best = i;
    void *p = NULL;
    if (best >= 0) {
        p = kept[best].p;
        if (kept[best].len - len >= BIGMEM_MAP_MIN) {
            kept[best].p = (unsigned char *)p + len;
            kept[best].len -= len;
            kept_bytes -= len;
            *got = len;
        } else {
            *got = kept[best].len;
            drop(best);
        }
    }
    pthread_mutex_unlock(&mu);
    return p;
}

/* A kept mapping is cleared on all CPUs, 8 MiB a piece (a fresh one's
 * pages are cleared by the kernel as the threads that fill them first
 * touch them, on all of them): a 72 MB grid's memset on one took 7 ms of
 * a 40 ms spot job at 1024^3. */
#define CLEAR_PIECE ((size_t)8 << 20)

typedef struct clear_job {
    unsigned char *p;
    size_t n;
} clear_job;

static int clear_piece(int i, int t, void *ud)
{
    (void)t;
    const clear_job *c = ud;
    const size_t at = (size_t)i * CLEAR_PIECE;
    memset(c->p + at, 0, c->n - at < CLEAR_PIECE ? c->n - at : CLEAR_PIECE);
    return 0;
}

static void clear(void *p, size_t n)
{
    clear_job c = {p, n};
    const size_t pieces = (n + CLEAR_PIECE - 1) / CLEAR_PIECE;
    if (pieces < 2 || pieces > INT_MAX)
        memset(p, 0, n);
    else
        vx_par_for((int)pieces, vx_par_cpus(), clear_piece, &c);
}

/* A fresh mapping of len bytes (zero, not yet faulted in), huge pages
 * asked for; NULL if none. */
static void *map_fresh(size_t len)
{
    void *p = mmap(NULL, len, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) return NULL;
#ifdef MADV_HUGEPAGE
    madvise(p, len, MADV_HUGEPAGE); /* a hint: without THP, small pages */
#endif
    return p;
}

static void *bigmem(size_t bytes, size_t *mapped, int zero)
{
    *mapped = 0;
    if (bytes < BIGMEM_MAP_MIN)
        return zero ? calloc(bytes ? bytes : 1, 1) : malloc(bytes ? bytes : 1);
    if (bytes > SIZE_MAX - BIGMEM_ROUND) return NULL; /* no such mapping */
    size_t len = (bytes + BIGMEM_ROUND - 1) / BIGMEM_ROUND * BIGMEM_ROUND;
    size_t got = 0;
    void *p = take(len, &got);
    if (p) {
        if (zero) clear(p, bytes);
        *mapped = got;
        return p;
    }
    p = map_fresh(len);
    if (p) *mapped = len;
    return p;
}

void *vx_bigmem_alloc(size_t bytes, size_t *mapped)
{
    return bigmem(bytes, mapped, 1);
}

void *vx_bigmem_scratch(size_t bytes, size_t *mapped)
{
    return bigmem(bytes, mapped, 0);
}

void vx_bigmem_free(void *p, size_t mapped)
{
    if (!mapped) {
        free(p);
        return;
    }
    pthread_mutex_lock(&mu);
    if (mapped <= keep_limit) {
        /* joined to the kept pieces beside it (the rest of a mapping it
         * was taken from), within the limit: whole again for a buffer as
         * big as before */
        for (int i = 0; i < nkept;) {
            unsigned char *q = kept[i].p;
            if (mapped + kept[i].len > keep_limit) {
                i++;
            } else if (q + kept[i].len == (unsigned char *)p) {
                p = q;
                mapped += kept[i].len;
                drop(i);
            } else if ((unsigned char *)p + mapped == q) {
                mapped += kept[i].len;
                drop(i);
            } else {
                i++;
            }
        }
        /* room for it: the smallest kept ones go first (a big one fits
         * more of what comes) */
        while (nkept && (kept_bytes + mapped > keep_limit || nkept == KEPT_MAX)) {
            int s = 0;
            for (int i = 1; i < nkept; i++)
                if (kept[i].len < kept[s].len) s = i;
            munmap(kept[s].p, kept[s].len);
            drop(s);
        }
        kept[nkept].p = p;
        kept[nkept].len = mapped;
        nkept++;
        kept_bytes += mapped;
        p = NULL;
    }
    pthread_mutex_unlock(&mu);
    if (p) munmap(p, mapped);
}

size_t vx_bigmem_pretouch(size_t bytes)
{
    pthread_mutex_lock(&mu);
    size_t room = keep_limit > kept_bytes ? keep_limit - kept_bytes : 0;
    pthread_mutex_unlock(&mu);
    const size_t len = (bytes < room ? bytes : room) / BIGMEM_ROUND * BIGMEM_ROUND;
    if (len < BIGMEM_MAP_MIN) return 0;
    void *p = map_fresh(len);
    if (!p) return 0;
    clear(p, len); /* every page written: faulted in now */
    vx_bigmem_free(p, len);
    return len;
}
