/* The binvox writer (io.h). binvox stores the cube d^3 (d the grid's
 * largest side, the rest zeros) x slice by x slice, z then y fastest, as
 * (value, count 1..255) pairs. Two coders make the same bytes:
 * - from y-transitions (the fast path): the rows' words xor'ed with the
 *   previous row's give, for 32 x at once, where the voxel differs from its
 *   -y neighbour; those (x, z, y) events, gathered per x on all threads,
 *   are the runs' ends in binvox order. Their memory grows with the
 *   surface, so it is capped (io->binvox_event_bytes);
 * - from transposed 32 x 32 blocks (the bounded path, when the cap is
 *   reached): memory fixed by io->binvox_group_bytes. */
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#if defined(__x86_64__)
#include <immintrin.h>
#elif defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "util/bigmem.h"
#include "util/cpu.h"
#include "util/par.h"
#include "voxel/io.h"
#include "voxel/io_int.h"

/* In place: a[r] bit c <-> a[c] bit r (bits least significant first). */
static void transpose32(uint32_t a[32])
{
    uint32_t m = 0x0000ffffu;
    for (int j = 16; j != 0; j >>= 1, m ^= m << j)
        for (int k = 0; k < 32; k = ((k | j) + 1) & ~j) {
            uint32_t t = ((a[k] >> j) ^ a[k | j]) & m;
            a[k] ^= t << j;
            a[k | j] ^= t;
        }
}

/* binvox's run-length coder: (value, count 1..255) pairs, a run longer
 * than 255 as several pairs. */
typedef struct rle {
    vx_out *o;
    unsigned cur;
    uint64_t run;
} rle;

/* One (value, count) pair into the buffer. */
static inline int rle_pair(vx_out *o, unsigned value, unsigned count)
{
    if (o->n + 2 > VX_OUT_BUF && vx_out_flush(o)) return -1;
    o->buf[o->n] = (uint8_t)value;
    o->buf[o->n + 1] = (uint8_t)count;
    o->n += 2;
    return 0;
}

/* q pairs (v, 255) at p, four at a store; returns p past them. */
static inline uint8_t *full_pairs(uint8_t *p, unsigned v, size_t q)
{
    const uint8_t b[8] = {(uint8_t)v, 255, (uint8_t)v, 255, (uint8_t)v, 255, (uint8_t)v, 255};
    uint64_t four;
    memcpy(&four, b, 8);
    size_t i = 0;
    for (; i + 4 <= q; i += 4)
        memcpy(p + 2 * i, &four, 8);
    for (; i < q; i++)
        memcpy(p + 2 * i, b, 2);
    return p + 2 * q;
}

static int rle_flush(rle *r)
{
    vx_out *o = r->o;
    while (r->run >= 255) { /* whole pairs of 255 straight into the buffer */
        if (o->n + 2 > VX_OUT_BUF && vx_out_flush(o)) return -1;
        uint64_t c = (VX_OUT_BUF - o->n) / 2;
        if (c > r->run / 255) c = r->run / 255;
        o->n = (size_t)(full_pairs(o->buf + o->n, r->cur, (size_t)c) - o->buf);
        r->run -= 255 * c;
    }
    unsigned last = (unsigned)r->run;
    r->run = 0;
    return last ? rle_pair(o, r->cur, last) : 0;
}

/* Appends the n (1..32) low bits of w, least significant first. */
static int rle_bits(rle *r, uint32_t w, unsigned n)
{
    while (n) {
        uint32_t x = r->cur ? ~w : w; /* bits equal to cur are 0 in x */
        unsigned c = x ? (unsigned)__builtin_ctz(x) : 32;
        if (c > n) c = n;
        r->run += c;
        n -= c;
        w = c < 32 ? w >> c : 0;
        if (n) {
            if (rle_flush(r)) return -1;
            r->cur ^= 1u;
        }
    }
    return 0;
}

static int rle_zeros(rle *r, uint64_t n)
{
    if (!n) return 0;
    if (r->cur && rle_flush(r)) return -1;
    r->cur = 0;
    r->run += n;
    return 0;
}

/* binvox's pipeline works on groups of x blocks (32 x columns each): a
 * group's columns transposed so that y runs along the bits, read from the
 * grid a few words per row at a time (one word per row per pass would read
 * a whole cache line for each word used). cols[((b * 32 + ii) * nz + k) *
 * wy + jw]: bit jj = voxel (32 (x0 + b) + ii, 32 jw + jj, k). A group's
 * columns take at most BINVOX_GROUP_BYTES (or io->binvox_group_bytes; one
 * block at least). */
#define BINVOX_GROUP_BYTES ((size_t)16 << 20)

/* Slices k0..k1-1 of nb blocks from x block x0. kinds[(b * nz + k) * wy +
 * jw]: the 32 x 32 block's voxels all 0 (BLOCK_ZEROS), all 1 (BLOCK_ONES),
 * or mixed (BLOCK_MIXED): only a mixed block's words are stored in cols
 * (most blocks of a solid are uniform: their words are neither written nor
 * read again). */
enum { BLOCK_ZEROS = 0, BLOCK_ONES = 1, BLOCK_MIXED = 2 };

static void binvox_transpose(const vx_bitgrid *g, size_t x0, size_t nb, int k0, int k1,
                             uint32_t *cols, uint8_t *kinds)
{
    const int ny = g->grid.dims[1], nz = g->grid.dims[2];
    const size_t wy = ((size_t)ny + 31) / 32, ncols = 32 * (size_t)nz * wy;
    uint32_t a[32][32];
    for (int k = k0; k < k1; k++)
        for (size_t jw = 0; jw < wy; jw++) {
            for (int jj = 0; jj < 32; jj++) {
                size_t j = 32 * jw + (size_t)jj;
                const uint32_t *row = g->bits + ((size_t)k * ny + j) * g->wx;
                for (size_t b = 0; b < nb; b++)
                    a[b][jj] = j < (size_t)ny ? vx_row_word(g, row, x0 + b) : 0;
            }
            for (size_t b = 0; b < nb; b++) {
                uint32_t any = 0, all = ~0u;
                for (int ii = 0; ii < 32; ii++) {
                    any |= a[b][ii];
                    all &= a[b][ii];
                }
                uint8_t *kind = kinds + (b * (size_t)nz + (size_t)k) * wy + jw;
                if (!any || !~all) {
                    *kind = any ? BLOCK_ONES : BLOCK_ZEROS;
                    continue;
                }
                *kind = BLOCK_MIXED;
                transpose32(a[b]);
                uint32_t *c = cols + b * ncols + (size_t)k * wy + jw;
                for (int ii = 0; ii < 32; ii++)
                    c[(size_t)ii * nz * wy] = a[b][ii];
            }
        }
}

/* Word e of a transposed column c whose blocks' kinds are kind[]. */
static inline uint32_t col_word(const uint8_t *kind, const uint32_t *c, size_t e)
{
    return kind[e] == BLOCK_MIXED ? c[e] : kind[e] == BLOCK_ONES ? 0xffffffffu : 0u;
}

/* The run-length code of x block x (from its transposed columns), in
 * binvox order: x, then z, then y fastest, each y column padded to the
 * cube's side d with zeros, each x slice to d x d. */
static int binvox_rle(const vx_bitgrid *g, size_t x, int d, const uint32_t *cols,
                      const uint8_t *kinds, rle *r)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    const size_t wy = ((size_t)ny + 31) / 32;
    const unsigned ylast = (unsigned)(ny - 32 * (int)(wy - 1));
    for (int ii = 0; ii < 32 && 32 * (int)x + ii < nx; ii++) {
        for (int k = 0; k < nz; k++) {
            const uint32_t *c = cols + ((size_t)ii * nz + k) * wy;
            const uint8_t *kind = kinds + (size_t)k * wy;
            for (size_t jw = 0; jw < wy;) {
                /* most words continue the current run whole (counted here,
                 * not in r, so that the count stays in a register) */
                const uint32_t same = r->cur ? 0xffffffffu : 0u;
                size_t e = jw;
                while (e + 1 < wy && col_word(kind, c, e) == same)
                    e++;
                r->run += 32 * (uint64_t)(e - jw);
                if (rle_bits(r, col_word(kind, c, e), e + 1 < wy ? 32 : ylast)) return -1;
                jw = e + 1;
            }
            if (rle_zeros(r, (uint64_t)(d - ny))) return -1;
        }
        if (rle_zeros(r, (uint64_t)(d - nz) * d)) return -1;
    }
    return 0;
}

/* Two threads: group q is coded on the calling thread (the coder is
 * sequential: a run crosses block boundaries) while group q + 1 is
 * transposed, a few slices at a time, by the other thread and then by the
 * coder too once it is done. The calling thread alone reports progress
 * (and so polls the job's stop hook, util/par.h). */
#define BINVOX_SLICES 16 /* slices per piece of a group's transposition */

typedef struct binvox_pipe {
    const vx_bitgrid *g;
    size_t q, per, ncols; /* the group being coded, blocks per group, words per block */
    int d, coding;        /* coding: group q is coded (else only transposed) */
    uint32_t *cols[2];
    uint8_t *kinds[2]; /* nz * wy bytes a block */
    atomic_int piece;  /* the next piece of group q + 1 to transpose */
    rle *r;
    const vx_voxel_io *io;
    vx_err *err;
    pthread_t caller;
    int rc; /* the coder's */
} binvox_pipe;

static size_t group_blocks(const binvox_pipe *p, size_t q)
{
    size_t x0 = q * p->per;
    return x0 >= p->g->wx ? 0 : (p->g->wx - x0 < p->per ? p->g->wx - x0 : p->per);
}

/* Pieces of group q's transposition until none is left. */
static void transpose_pieces(binvox_pipe *p, size_t q)
{
    const int nz = p->g->grid.dims[2];
    size_t nb = group_blocks(p, q);
    for (int k0; nb && (k0 = BINVOX_SLICES * atomic_fetch_add(&p->piece, 1)) < nz;)
        binvox_transpose(p->g, q * p->per, nb, k0,
                         k0 + BINVOX_SLICES < nz ? k0 + BINVOX_SLICES : nz, p->cols[q & 1],
                         p->kinds[q & 1]);
}

static void *binvox_stage(void *ud)
{
    binvox_pipe *p = ud;
    if (!p->coding) {
        transpose_pieces(p, p->q);
        return NULL;
    }
    if (pthread_equal(pthread_self(), p->caller))
        for (size_t b = 0; b < group_blocks(p, p->q) && !p->rc; b++) {
            size_t x = p->q * p->per + b;
            if (p->io && p->io->progress &&
                p->io->progress(p->io->ud, (double)(32 * x) / p->d, p->err))
                p->rc = -1;
            else if (binvox_rle(p->g, x, p->d, p->cols[p->q & 1] + b * p->ncols,
                                p->kinds[p->q & 1] + b * (p->ncols / 32), p->r))
                p->rc = -1;
        }
    transpose_pieces(p, p->q + 1);
    return NULL;
}

/* The bounded coder: the header is written; the body from transposed
 * blocks. */
static int binvox_blocks(const vx_bitgrid *g, vx_out *o, int d, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    const size_t wy = ((size_t)ny + 31) / 32; /* words of a transposed y column */
    const size_t ncols = 32 * (size_t)nz * wy;
    size_t per = (io && io->binvox_group_bytes ? io->binvox_group_bytes : BINVOX_GROUP_BYTES) /
                 (ncols * sizeof(uint32_t));
    if (per < 1) per = 1;
    if (per > 32) per = 32;
    if (per > g->wx) per = g->wx;
    /* written once a group, sparsely: in huge pages (util/bigmem.h) */
    size_t cols_mapped, kinds_mapped;
    uint32_t *cols = vx_bigmem_alloc(2 * per * ncols * sizeof *cols, &cols_mapped);
    uint8_t *kinds = vx_bigmem_alloc(2 * per * (ncols / 32), &kinds_mapped);
    if (!cols || !kinds) {
        vx_bigmem_free(cols, cols_mapped);
        vx_bigmem_free(kinds, kinds_mapped);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for binvox columns");
        return -1;
    }
    rle r = {o, 0, 0};
    binvox_pipe p = {.g = g,
                     .per = per,
                     .ncols = ncols,
                     .d = d,
                     .cols = {cols, cols + per * ncols},
                     .kinds = {kinds, kinds + per * (ncols / 32)},
                     .r = &r,
                     .io = io,
                     .err = err,
                     .caller = pthread_self()};
    /* group 0 transposed, then each group coded while the next is (with
     * one thread only, when none could be made, in turn) */
    int ok = 1;
    vx_par_run(2, binvox_stage, &p);
    for (size_t q = 0; ok && q * per < g->wx; q++) {
        p.q = q;
        p.coding = 1;
        atomic_store(&p.piece, 0);
        vx_par_run(2, binvox_stage, &p);
        if (p.rc) ok = 0;
    }
    if (ok && rle_zeros(&r, (uint64_t)(d - nx) * d * d)) ok = 0;
    if (ok && r.run && rle_flush(&r)) ok = 0;
    vx_bigmem_free(cols, cols_mapped);
    vx_bigmem_free(kinds, kinds_mapped);
    return ok ? 0 : -1;
}

/* ---- the fast coder: y-transitions, gathered per x ----
 *
 * Voxel (x, j, k) starts a run in binvox order exactly where it differs
 * from (x, j - 1, k), rows -1 and ny counted as zeros (row ny: the cube's
 * padding in y). Row j xor row j - 1 gives those events for 32 x at once;
 * most words are 0. Each z slab (an item of vx_par_for) appends its events
 * (k << ybits | j) to a list per x, in chunks of 64 taken from the slab's
 * arena: slab s's events of slice x, in binvox order (k, then j). The runs
 * are the gaps between events, coded in x ranges on all threads; a range's
 * first and last runs are left open and the ranges joined in order, so the
 * bytes are those of one pass (a run goes on across a range's edges). The
 * arenas and the ranges' pairs are written once each, in huge pages
 * (util/bigmem.h): on a virtual machine first-touch faults in small pages
 * cost more than the coding. */

/* The fast coder's event chunks may take io->binvox_event_bytes, or by
 * default a quarter of the bit grid's bytes and at least this. */
#define BINVOX_EVENT_MIN ((size_t)4 << 20)

/* The progress bar: gathering to EV_GATHERED, measuring the runs to
 * EV_MEASURED, writing them to 1. */
#define EV_GATHERED 0.6
#define EV_MEASURED 0.7
#define EV_CHUNK 64 /* events a chunk */

/* A slab's events: slice x's n[x] events in chunks head[x], next[head[x]],
 * ... (chunk c: ev + EV_CHUNK * c; chunk 0 is none), the last tail[x]. */
typedef struct ev_slab_t {
    uint32_t *ev, *next; /* the arena: chunks, and each chunk's next */
    size_t ev_mapped, next_mapped;
    uint32_t nchunks, cap; /* chunks taken (from 1), chunks the arena holds */
    uint32_t *n, *head, *tail;
} ev_slab_t;

typedef struct ev_job {
    const vx_bitgrid *g;
    int d, nslabs, slab; /* the cube's side, slabs, slices per slab */
    int ybits;
    const uint32_t *zeros; /* a row of zeros */
    ev_slab_t *s;
    size_t budget; /* bytes of event chunks, all slabs together */
    atomic_size_t used;
    atomic_int over; /* the budget (or memory) ran out */
    const vx_voxel_io *io;
    vx_err *err;
    int stopped; /* the hook said stop (set by the calling thread) */
} ev_job;

/* Event ev of slice x: its place in binvox order. */
static inline uint64_t ev_pos(const ev_job *j, int x, uint32_t ev)
{
    return ((uint64_t)x * j->d + (ev >> j->ybits)) * j->d + (ev & ((1u << j->ybits) - 1u));
}

/* Bit w set where a[w] != b[w], w < n <= 64 (SSE2: four words a compare;
 * diff_words_avx2, eight). */
static inline uint64_t diff_words(const uint32_t *a, const uint32_t *b, size_t n)
{
    uint64_t m = 0;
    size_t w = 0;
#if defined(__SSE2__)
    const __m128i zero = _mm_setzero_si128();
    for (; w + 4 <= n; w += 4) {
        __m128i x = _mm_xor_si128(_mm_loadu_si128((const __m128i *)(a + w)),
                                  _mm_loadu_si128((const __m128i *)(b + w)));
        unsigned same = (unsigned)_mm_movemask_ps(_mm_castsi128_ps(_mm_cmpeq_epi32(x, zero)));
        m |= (uint64_t)(same ^ 0xfu) << w;
    }
#endif
    for (; w < n; w++)
        m |= (uint64_t)(a[w] != b[w]) << w;
    return m;
}

#if defined(__x86_64__)
__attribute__((target("avx2"))) static inline uint64_t diff_words_avx2(const uint32_t *a,
                                                                       const uint32_t *b, size_t n)
{
    uint64_t m = 0;
    size_t w = 0;
    const __m256i zero = _mm256_setzero_si256();
    for (; w + 8 <= n; w += 8) {
        __m256i x = _mm256_xor_si256(_mm256_loadu_si256((const __m256i *)(a + w)),
                                     _mm256_loadu_si256((const __m256i *)(b + w)));
        unsigned same =
            (unsigned)_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(x, zero)));
        m |= (uint64_t)(same ^ 0xffu) << w;
    }
    for (; w < n; w++)
        m |= (uint64_t)(a[w] != b[w]) << w;
    return m;
}
#endif

typedef uint64_t (*diff_fn)(const uint32_t *a, const uint32_t *b, size_t n);

/* Slab s's events into its lists (chunks charged to the budget a slice at
 * a time). Inlined with diff. */
static inline __attribute__((always_inline)) int ev_rows_with(ev_job *j, int si, int t,
                                                              diff_fn diff)
{
    const vx_bitgrid *g = j->g;
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    const size_t wx = g->wx;
    const uint32_t tailmask = nx & 31 ? (1u << (nx & 31)) - 1u : ~0u;
    ev_slab_t *s = j->s + si;
    uint32_t *const ev = s->ev, *const next = s->next, *const n = s->n, *const head = s->head,
                    *const tail = s->tail;
    uint32_t nchunks = s->nchunks;
    const int k1 = (si + 1) * j->slab < nz ? (si + 1) * j->slab : nz;
    for (int k = si * j->slab; k < k1; k++) {
        if (atomic_load_explicit(&j->over, memory_order_relaxed)) return -1;
        if (t == 0 && j->io && j->io->progress && !(k & 7) &&
            j->io->progress(j->io->ud, EV_GATHERED * k / nz, j->err)) {
            j->stopped = 1;
            return -1;
        }
        const uint32_t c0 = nchunks;
        const uint32_t *prev = j->zeros;
        for (int y = 0; y <= ny; y++) {
            const uint32_t *cur = y < ny ? g->bits + ((size_t)k * ny + y) * wx : j->zeros;
            const uint32_t key = (uint32_t)k << j->ybits | (uint32_t)y;
            for (size_t w0 = 0; w0 < wx; w0 += 64)
                for (uint64_t m = diff(cur + w0, prev + w0, wx - w0 < 64 ? wx - w0 : 64); m;
                     m &= m - 1) {
                    /* a word's events take at most 32 new chunks */
                    if (nchunks + 32 > s->cap) {
                        atomic_store(&j->over, 1);
                        return -1;
                    }
                    const size_t w = w0 + (size_t)__builtin_ctzll(m);
                    uint32_t dw = cur[w] ^ prev[w];
                    if (w == wx - 1) dw &= tailmask; /* row padding: never set */
                    for (; dw; dw &= dw - 1) {
                        const size_t x = 32 * w + (unsigned)__builtin_ctz(dw);
                        const uint32_t i = n[x]++;
                        if (!(i % EV_CHUNK)) { /* a new chunk */
                            if (i)
                                next[tail[x]] = nchunks;
                            else
                                head[x] = nchunks;
                            tail[x] = nchunks++;
                        }
                        ev[(size_t)tail[x] * EV_CHUNK + i % EV_CHUNK] = key;
                    }
                }
            prev = cur;
        }
        const size_t bytes = (size_t)(nchunks - c0) * (EV_CHUNK + 1) * sizeof *ev;
        if (atomic_fetch_add(&j->used, bytes) + bytes > j->budget) {
            atomic_store(&j->over, 1);
            return -1;
        }
    }
    s->nchunks = nchunks;
    return 0;
}

static int ev_rows_sse2(ev_job *j, int si, int t)
{
    return ev_rows_with(j, si, t, diff_words);
}

#if defined(__x86_64__)
__attribute__((target("avx2"))) static int ev_rows_avx2(ev_job *j, int si, int t)
{
    return ev_rows_with(j, si, t, diff_words_avx2);
}
#endif

static int ev_rows(ev_job *j, int si, int t)
{
#if defined(__x86_64__)
    if (vx_cpu_avx2()) return ev_rows_avx2(j, si, t);
#endif
    return ev_rows_sse2(j, si, t);
}

/* Slab s's arena (reserved at the whole budget, touched as used) and its
 * events. */
static int ev_slab(int si, int t, void *ud)
{
    ev_job *j = ud;
    const int nx = j->g->grid.dims[0];
    ev_slab_t *s = j->s + si;
    s->cap = (uint32_t)(j->budget / ((EV_CHUNK + 1) * sizeof(uint32_t)));
    s->nchunks = 1;
    s->ev = vx_bigmem_scratch((size_t)s->cap * EV_CHUNK * sizeof *s->ev, &s->ev_mapped);
    s->next = vx_bigmem_scratch((size_t)s->cap * sizeof *s->next, &s->next_mapped);
    s->n = calloc(3 * (size_t)nx, sizeof *s->n);
    s->head = s->n + nx;
    s->tail = s->head + nx;
    if (!s->ev || !s->next || !s->n || ev_rows(j, si, t)) {
        atomic_store(&j->over, 1);
        return 1;
    }
    return 0;
}

/* An x range's runs: the first left open (head), those after it closed
 * (the interior: bytes of pairs, written at off), the last left open
 * (tail). */
typedef struct ev_range {
    int x0, x1;
    unsigned v0;  /* the value after the last event before x0 */
    uint64_t at0; /* that event's place (0: none) */
    unsigned head_v, tail_v;
    uint64_t head_len, tail_len;
    size_t finished; /* runs closed in the range */
    uint64_t bytes, off;
} ev_range;

/* A run the join closes (an open run merged across ranges), written at off. */
typedef struct ev_run {
    uint64_t off, len;
    unsigned v;
} ev_run;

/* Pairs made into a buffer and written at their place in the file. */
typedef struct ev_sink {
    uint8_t *buf;
    size_t n;
    int fd;
    uint64_t off;
    int err; /* errno of a failed write */
} ev_sink;

#define EV_SINK_BYTES ((size_t)256 << 10)

typedef struct ev_emit {
    ev_job *j;
    ev_range *r;
    int nr;
    ev_run *runs;
    int nruns;
    int writing; /* 0: the ranges measured, 1: written */
    int fd;
    uint8_t *bufs[VX_PAR_MAX]; /* a sink's buffer per thread */
    atomic_int werr;
} ev_emit;

static inline uint64_t pair_bytes(uint64_t len)
{
    return 2 * (len / 255 + (len % 255 != 0));
}

static void sink_flush(ev_sink *k)
{
    for (size_t done = 0; done < k->n && !k->err;) {
        ssize_t w = pwrite(k->fd, k->buf + done, k->n - done, (off_t)(k->off + done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0)
            k->err = w < 0 ? errno : EIO;
        else
            done += (size_t)w;
    }
    k->off += k->n;
    k->n = 0;
}

/* A run's pairs into the sink. */
static void sink_run(ev_sink *k, unsigned v, uint64_t len)
{
    while (len) {
        if (EV_SINK_BYTES - k->n < 2) sink_flush(k);
        uint64_t q = (EV_SINK_BYTES - k->n) / 2;
        if (q > len / 255) q = len / 255;
        if (q) {
            k->n = (size_t)(full_pairs(k->buf + k->n, v, (size_t)q) - k->buf);
            len -= 255 * q;
        } else { /* less than 255 left */
            k->buf[k->n] = (uint8_t)v;
            k->buf[k->n + 1] = (uint8_t)len;
            k->n += 2;
            len = 0;
        }
    }
}

/* A closed run of the range: the head, else counted (measuring) or
 * written (k). */
static inline void ev_close(ev_range *r, ev_sink *k, unsigned v, uint64_t len)
{
    if (!r->finished++) {
        r->head_v = v;
        r->head_len = len;
    } else if (!k) {
        r->bytes += pair_bytes(len);
    } else {
        sink_run(k, v, len);
    }
}

/* Range r's runs, measured or written (k): the same walk both times. */
static void ev_walk(ev_emit *e, ev_range *r, ev_sink *k)
{
    ev_job *j = e->j;
    uint64_t at = r->at0, plen = 0; /* the open run: value pv, plen voxels */
    unsigned v = r->v0, pv = v;
    const uint64_t d = (uint64_t)j->d;
    const int ybits = j->ybits;
    const uint32_t ymask = (1u << ybits) - 1u;
    r->finished = 0;
    for (int x = r->x0; x < r->x1; x++)
        for (int si = 0; si < j->nslabs; si++) {
            const ev_slab_t *s = j->s + si;
            const uint32_t n = s->n[x];
            const uint64_t base = (uint64_t)x * d * d; /* ev_pos's */
            /* chunk by chunk, the next one asked for ahead: each is
             * elsewhere in the arena (the walk waited on their loads) */
            for (uint32_t q0 = 0, c = s->head[x]; q0 < n; q0 += EV_CHUNK) {
                const uint32_t *ev = s->ev + (size_t)c * EV_CHUNK;
                const uint32_t m = n - q0 < EV_CHUNK ? n - q0 : EV_CHUNK;
                if (m == EV_CHUNK && q0 + EV_CHUNK < n) {
                    c = s->next[c];
                    const char *a = (const char *)(s->ev + (size_t)c * EV_CHUNK);
                    for (size_t b = 0; b < EV_CHUNK * sizeof *ev; b += 64)
                        __builtin_prefetch(a + b);
                }
                for (uint32_t i = 0; i < m; i++) {
                    const uint64_t pos = base + (uint64_t)(ev[i] >> ybits) * d + (ev[i] & ymask);
                    if (pos != at) { /* two events at one place (y = ny = d): no run */
                        if (v != pv) {
                            if (plen) ev_close(r, k, pv, plen);
                            pv = v;
                            plen = 0;
                        }
                        plen += pos - at;
                        at = pos;
                    }
                    v ^= 1u;
                }
            }
        }
    if (r == e->r + e->nr - 1) { /* after the last event, zeros to the cube's end */
        if (v != pv) {
            if (plen) ev_close(r, k, pv, plen);
            pv = v;
            plen = 0;
        }
        plen += (uint64_t)j->d * j->d * j->d - at;
    }
    r->tail_v = pv;
    r->tail_len = plen;
}

/* Item i: range i measured or written; when writing, items past the ranges
 * are the join's runs. */
static int ev_code(int i, int t, void *ud)
{
    ev_emit *e = ud;
    ev_job *j = e->j;
    const vx_voxel_io *io = j->io;
    if (i < e->nr && t == 0 && io && io->progress) {
        const double f = (double)e->r[i].x0 / j->g->grid.dims[0];
        const double f0 = e->writing ? EV_MEASURED : EV_GATHERED;
        const double f1 = e->writing ? 1 : EV_MEASURED;
        if (io->progress(io->ud, f0 + (f1 - f0) * f, j->err)) {
            j->stopped = 1;
            return 1;
        }
    }
    if (!e->writing) {
        ev_walk(e, e->r + i, NULL);
        return 0;
    }
    ev_sink k = {.buf = e->bufs[t], .fd = e->fd};
    if (i < e->nr) {
        ev_range *r = e->r + i;
        k.off = r->off;
        if (r->bytes) ev_walk(e, r, &k);
    } else {
        const ev_run *u = e->runs + (i - e->nr);
        k.off = u->off;
        sink_run(&k, u->v, u->len);
    }
    sink_flush(&k);
    if (k.err) atomic_store(&e->werr, k.err);
    return k.err ? 1 : 0;
}

/* The body from the events: 1 when the budget ran out (nothing written),
 * 0 when written, -1 on failure (err set, or o->failed). The ranges are
 * measured, laid out in the file by joining them as one pass would, then
 * written at their places on all threads. */
static int binvox_events(const vx_bitgrid *g, vx_out *o, int d, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    ev_job j = {.g = g, .d = d, .io = io, .err = err};
    j.ybits = 32 - __builtin_clz((unsigned)ny); /* j = 0..ny */
    if (j.ybits >= 32 || ((uint64_t)(nz - 1) << j.ybits) >> 32) return 1;
    const size_t grid_bytes = g->wx * sizeof(uint32_t) * (size_t)ny * nz;
    j.budget = io && io->binvox_event_bytes        ? io->binvox_event_bytes
               : grid_bytes / 4 > BINVOX_EVENT_MIN ? grid_bytes / 4
                                                   : BINVOX_EVENT_MIN;
    const int threads = vx_par_cpus();
    j.nslabs = 2 * threads < nz ? 2 * threads : nz;
    j.slab = (nz + j.nslabs - 1) / j.nslabs;
    j.nslabs = (nz + j.slab - 1) / j.slab;
    j.s = calloc((size_t)j.nslabs, sizeof *j.s);
    uint32_t *zeros = calloc(g->wx, sizeof *zeros);
    j.zeros = zeros;
    ev_emit e = {.j = &j};
    e.nr = 4 * threads < nx ? 4 * threads : nx;
    e.r = calloc((size_t)e.nr, sizeof *e.r);
    e.runs = calloc(2 * (size_t)e.nr + 1, sizeof *e.runs);
    atomic_init(&e.werr, 0);
    int rc = 1;
    if (j.s && zeros && e.r && e.runs && !vx_par_for(j.nslabs, threads, ev_slab, &j)) {
        /* each range starts after the events of the slices before it */
        uint64_t count = 0, at = 0;
        for (int i = 0, x = 0; i < e.nr; i++) {
            ev_range *r = e.r + i;
            r->x0 = (int)((int64_t)nx * i / e.nr);
            r->x1 = (int)((int64_t)nx * (i + 1) / e.nr);
            r->v0 = (unsigned)(count & 1);
            r->at0 = at;
            for (x = r->x0; x < r->x1; x++)
                for (int si = 0; si < j.nslabs; si++) {
                    const ev_slab_t *s = j.s + si;
                    const uint32_t n = s->n[x];
                    if (!n) continue;
                    const uint32_t last = s->ev[(size_t)s->tail[x] * EV_CHUNK + (n - 1) % EV_CHUNK];
                    count += n;
                    at = ev_pos(&j, x, last);
                }
        }
        rc = vx_par_for(e.nr, threads, ev_code, &e) ? -1 : 0;
        /* the join: an open run merges with the next range's head */
        fflush(o->f);
        uint64_t off = (uint64_t)ftello(o->f) + o->n, cl = 0;
        unsigned cv = 0;
        for (int i = 0; !rc && i < e.nr; i++) {
            ev_range *r = e.r + i;
            const unsigned v = r->finished ? r->head_v : r->tail_v;
            const uint64_t len = r->finished ? r->head_len : r->tail_len;
            if (len && v != cv) {
                if (cl) e.runs[e.nruns++] = (ev_run){off, cl, cv}, off += pair_bytes(cl);
                cv = v;
                cl = 0;
            }
            cl += len;
            if (r->finished) {
                if (cl) e.runs[e.nruns++] = (ev_run){off, cl, cv}, off += pair_bytes(cl);
                r->off = off;
                off += r->bytes;
                cv = r->tail_v;
                cl = r->tail_len;
            }
        }
        if (cl) e.runs[e.nruns++] = (ev_run){off, cl, cv};
        /* the header out first: the rest is written past it */
        if (!rc && vx_out_flush(o)) rc = -1;
        for (int t = 0; !rc && t < threads; t++)
            if (!(e.bufs[t] = malloc(EV_SINK_BYTES))) {
                rc = -1;
                vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for binvox's pairs");
            }
        if (!rc) {
            e.writing = 1;
            e.fd = fileno(o->f);
            if (vx_par_for(e.nr + e.nruns, threads, ev_code, &e)) rc = -1;
            if (atomic_load(&e.werr)) o->failed = atomic_load(&e.werr);
        }
    } else if (j.stopped) {
        rc = -1;
    }
    for (int si = 0; j.s && si < j.nslabs; si++) {
        vx_bigmem_free(j.s[si].ev, j.s[si].ev_mapped);
        vx_bigmem_free(j.s[si].next, j.s[si].next_mapped);
        free(j.s[si].n);
    }
    for (int t = 0; t < VX_PAR_MAX; t++)
        free(e.bufs[t]);
    free(j.s);
    free(e.r);
    free(e.runs);
    free(zeros);
    return rc;
}

int vx_voxel_write_binvox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    int d = nx > ny ? nx : ny;
    if (nz > d) d = nz;
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    char hdr[256];
    int hn =
        snprintf(hdr, sizeof hdr,
                 "#binvox 1\ndim %d %d %d\ntranslate %.17g %.17g %.17g\nscale %.17g\ndata\n", d, d,
                 d, g->grid.origin[0], g->grid.origin[1], g->grid.origin[2], d * g->grid.h);
    int ok = vx_out_write(&o, hdr, (size_t)hn) == 0;
    if (ok) {
        int rc = binvox_events(g, &o, d, io, err);
        if (rc == 1) rc = binvox_blocks(g, &o, d, io, err);
        ok = rc == 0;
    }
    return vx_out_close(&o, ok, err);
}
