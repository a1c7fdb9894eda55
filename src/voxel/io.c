/* raw8 and raw1 writers (io.h), and the buffered output file every writer
 * shares (io_int.h). Each works a word of the bit grid at a time (32
 * voxels) and writes through a buffer of about 1 MiB (raw8, and raw1 with
 * rows that start mid-byte: chunks of about 4 MiB instead, one per thread,
 * each written at its place), so the only memory beyond the grid is that.
 * binvox is binvox.c. */
#include <errno.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "util/par.h"
#include "voxel/io.h"
#include "voxel/io_int.h"

int vx_out_open(vx_out *o, const char *path, vx_err *err)
{
    memset(o, 0, sizeof *o);
    o->path = path;
    snprintf(o->tmp, sizeof o->tmp, "%s.tmp", path);
    o->buf = malloc(VX_OUT_BUF);
    if (!o->buf) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a buffer");
    o->f = fopen(o->tmp, "wb");
    if (!o->f) {
        free(o->buf);
        o->buf = NULL;
        int e = errno;
        const char *base = strrchr(o->tmp, '/') ? strrchr(o->tmp, '/') + 1 : o->tmp;
        return vx_err_set(err, VX_EIO, "io_error", "creating %s failed: %s", base, strerror(e));
    }
    setvbuf(o->f, NULL, _IONBF, 0); /* the buffer is ours */
    return 0;
}

int vx_out_flush(vx_out *o)
{
    if (o->failed) return -1;
    if (o->n && fwrite(o->buf, 1, o->n, o->f) != o->n) o->failed = errno ? errno : EIO;
    o->n = 0;
    return o->failed ? -1 : 0;
}

int vx_out_write(vx_out *o, const void *p, size_t n)
{
    const uint8_t *s = p;
    if (n >= VX_OUT_BUF) { /* a block as large as the buffer goes as it is */
        if (vx_out_flush(o)) return -1;
        if (fwrite(s, 1, n, o->f) != n) o->failed = errno ? errno : EIO;
        return o->failed ? -1 : 0;
    }
    while (n) {
        if (o->n == VX_OUT_BUF && vx_out_flush(o)) return -1;
        size_t c = VX_OUT_BUF - o->n < n ? VX_OUT_BUF - o->n : n;
        memcpy(o->buf + o->n, s, c);
        o->n += c;
        s += c;
        n -= c;
    }
    return 0;
}

int vx_out_close(vx_out *o, int ok, vx_err *err)
{
    if (!o->f) return ok ? 0 : -1;
    if (ok && vx_out_flush(o)) ok = 0;
    int e = o->failed;
    int c = fclose(o->f);
    o->f = NULL;
    free(o->buf);
    o->buf = NULL;
    /* Messages name the file, never its server path. */
    const char *base = strrchr(o->tmp, '/') ? strrchr(o->tmp, '/') + 1 : o->tmp;
    if (e || (ok && c))
        ok = 0,
        vx_err_set(err, VX_EIO, "io_error", "writing %s failed: %s", base, strerror(e ? e : errno));
    if (ok && rename(o->tmp, o->path))
        ok = 0,
        vx_err_set(err, VX_EIO, "io_error", "renaming %s failed: %s", base, strerror(errno));
    if (!ok) remove(o->tmp);
    return ok ? 0 : -1;
}

int vx_out_progress(const vx_voxel_io *io, int k, int nz, vx_err *err)
{
    if (!io || !io->progress || (k & 7)) return 0;
    return io->progress(io->ud, (double)k / nz, err) ? -1 : 0;
}

/* Chunks go out on a few threads, each filling its own buffer and writing
 * it at its place in the file (pwrite): the page cache's copy runs on all
 * of them. Of T threads, thread t makes chunks t, t + T, t + 2 T, ...; the
 * calling thread is thread 0 and reports progress (c / n) before each of
 * its chunks c, so the bar moves in steps of T chunks whatever the
 * scheduler does, and its hook stops the others within a chunk. */
#define OUT_THREADS 4

typedef struct out_par {
    int fd;
    off_t base;        /* the file offset of chunk 0 */
    const size_t *off; /* off[c]: chunk c's place from base; off[n]: the total */
    size_t n;
    int nthreads; /* T */
    uint8_t *buf[OUT_THREADS];
    vx_out_fill_fn fill;
    void *ud;
    const vx_voxel_io *io;
    vx_err *err;         /* set by the calling thread only */
    atomic_int tidx;     /* the next new thread's index, from 1 */
    atomic_int stop;     /* the hook said stop or a chunk failed */
    atomic_int werr;     /* errno of the first failed write */
    atomic_int bad;      /* a fill that gave another size than size() said */
    pthread_mutex_t *go; /* held until nthreads is known */
} out_par;

/* Fills chunk c into buf and writes it at its place: 0, or -1 with bad or
 * werr set. */
static int out_one(out_par *p, size_t c, uint8_t *buf)
{
    size_t len = p->fill(p->ud, c, buf), at = 0;
    if (len != p->off[c + 1] - p->off[c]) {
        atomic_store(&p->bad, 1);
        return -1;
    }
    while (at < len) {
        ssize_t w = pwrite(p->fd, buf + at, len - at, p->base + (off_t)(p->off[c] + at));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
            int zero = 0;
            atomic_compare_exchange_strong(&p->werr, &zero, w < 0 && errno ? errno : EIO);
            return -1;
        }
        at += (size_t)w;
    }
    return 0;
}

/* Thread t's chunks. */
static void out_thread(out_par *p, int t)
{
    for (size_t c = (size_t)t; c < p->n && !atomic_load(&p->stop); c += (size_t)p->nthreads) {
        if (t == 0 && p->io && p->io->progress &&
            p->io->progress(p->io->ud, (double)c / p->n, p->err)) {
            atomic_store(&p->stop, 1);
        } else if (out_one(p, c, p->buf[t])) {
            atomic_store(&p->stop, 1);
        }
    }
}

static void *out_worker(void *ud)
{
    out_par *p = ud;
    pthread_mutex_lock(p->go);
    pthread_mutex_unlock(p->go);
    out_thread(p, atomic_fetch_add(&p->tidx, 1));
    return NULL;
}

int vx_out_chunks(vx_out *o, size_t n, size_t cap, vx_out_size_fn size, vx_out_fill_fn fill,
                  void *ud, const vx_voxel_io *io, vx_err *err)
{
    if (vx_out_flush(o)) return -1;
    int nt = vx_par_cpus() < OUT_THREADS ? vx_par_cpus() : OUT_THREADS;
    size_t *off = malloc((n + 1) * sizeof *off);
    uint8_t *buf = malloc((size_t)nt * cap);
    out_par p = {.fd = fileno(o->f),
                 .base = ftello(o->f),
                 .off = off,
                 .n = n,
                 .fill = fill,
                 .ud = ud,
                 .io = io,
                 .err = err};
    int rc = -1;
    if (!off || !buf) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for output chunks");
        goto out;
    }
    if (p.base < 0) {
        o->failed = errno ? errno : EIO;
        goto out;
    }
    off[0] = 0;
    for (size_t c = 0; c < n; c++)
        off[c + 1] = off[c] + size(ud, c);
    for (int t = 0; t < nt; t++)
        p.buf[t] = buf + (size_t)t * cap;
    atomic_init(&p.tidx, 1);
    atomic_init(&p.stop, 0);
    atomic_init(&p.werr, 0);
    atomic_init(&p.bad, 0);
    /* the threads that could be made share the chunks out; they start
     * only once T is known */
    pthread_t th[OUT_THREADS];
    int started = 0;
    pthread_mutex_t go = PTHREAD_MUTEX_INITIALIZER;
    p.go = &go;
    pthread_mutex_lock(&go);
    for (int t = 1; t < nt; t++)
        if (pthread_create(&th[started], NULL, out_worker, &p) == 0) started++;
    p.nthreads = 1 + started;
    pthread_mutex_unlock(&go);
    out_thread(&p, 0);
    for (int t = 0; t < started; t++)
        pthread_join(th[t], NULL);
    if (atomic_load(&p.werr)) {
        o->failed = atomic_load(&p.werr);
    } else if (atomic_load(&p.bad)) {
        vx_err_set(err, VX_EINTERNAL, "internal", "an output chunk's size was not as counted");
    } else if (!atomic_load(&p.stop)) {
        /* the file goes on after the chunks */
        if (fseeko(o->f, p.base + (off_t)off[n], SEEK_SET))
            o->failed = errno ? errno : EIO;
        else
            rc = 0;
    }
out:
    free(off);
    free(buf);
    return rc;
}

/* The row after a chunk of per rows from r0, of rows in all. */
static inline size_t chunk_end(size_t r0, size_t per, size_t rows)
{
    return r0 + per < rows ? r0 + per : rows;
}

/* Output chunks: about VX_CHUNK_BYTES, at least 16 (the progress steps). */
#define VX_CHUNK_BYTES ((size_t)4 << 20)

typedef struct raw8_job {
    const vx_bitgrid *g;
    size_t rows, per;     /* rows, rows per chunk */
    uint64_t spread[256]; /* the 8 bytes 0/1 of byte b's bits, least significant first */
} raw8_job;

static size_t raw8_size(void *ud, size_t c)
{
    const raw8_job *j = ud;
    size_t r0 = c * j->per, r1 = chunk_end(r0, j->per, j->rows);
    return (r1 - r0) * (size_t)j->g->grid.dims[0];
}

static size_t raw8_fill(void *ud, size_t c, uint8_t *out)
{
    const raw8_job *j = ud;
    const size_t nx = (size_t)j->g->grid.dims[0], nb = (nx + 7) / 8;
    size_t r0 = c * j->per, r1 = chunk_end(r0, j->per, j->rows);
    for (size_t r = r0; r < r1; r++, out += nx) { /* a row's last 8 bytes may run past nx: slack */
        const uint8_t *w = (const uint8_t *)(j->g->bits + r * j->g->wx);
        for (size_t b = 0; b < nb; b++)
            memcpy(out + 8 * b, &j->spread[w[b]], 8);
    }
    return (r1 - r0) * nx;
}

int vx_out_raw8(vx_out *o, const vx_bitgrid *g, const vx_voxel_io *io, vx_err *err)
{
    const size_t nx = (size_t)g->grid.dims[0], rows = (size_t)g->grid.dims[1] * g->grid.dims[2];
    raw8_job *j = malloc(sizeof *j);
    if (!j) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for raw8");
    j->g = g;
    j->rows = rows;
    for (int b = 0; b < 256; b++) {
        uint64_t v = 0;
        for (int i = 0; i < 8; i++)
            v |= (uint64_t)((b >> i) & 1) << (8 * i);
        j->spread[b] = v;
    }
    j->per = VX_CHUNK_BYTES / nx;
    if (j->per > rows / 16) j->per = rows / 16;
    if (j->per < 1) j->per = 1;
    int rc = vx_out_chunks(o, (rows + j->per - 1) / j->per, j->per * nx + 8, raw8_size, raw8_fill,
                           j, io, err);
    free(j);
    return rc;
}

int vx_voxel_write_raw8(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    return vx_out_close(&o, vx_out_raw8(&o, g, io, err) == 0, err);
}

/* raw1 rows are packed continuously: when nx % 8 != 0 they start mid-byte
 * and go through a 64-bit accumulator, in chunks of a multiple of 8 rows
 * (each starting on a byte). */
typedef struct raw1_job {
    const vx_bitgrid *g;
    size_t rows, per; /* rows, rows per chunk */
} raw1_job;

/* A chunk starts on a byte: its rows' bits, the last byte padded. */
static size_t raw1_size(void *ud, size_t c)
{
    const raw1_job *j = ud;
    size_t r0 = c * j->per, r1 = chunk_end(r0, j->per, j->rows);
    return ((r1 - r0) * (size_t)j->g->grid.dims[0] + 7) / 8;
}

static size_t raw1_fill(void *ud, size_t c, uint8_t *out)
{
    const raw1_job *j = ud;
    const vx_bitgrid *g = j->g;
    const unsigned nx = (unsigned)g->grid.dims[0], tail = nx & 63;
    const size_t full = nx / 64; /* whole 64-bit pieces of a row */
    size_t r0 = c * j->per, r1 = chunk_end(r0, j->per, j->rows);
    /* acc holds nacc (< 64) bits not yet stored; a row's whole pieces
     * leave nacc as it is, 64 bits stored per piece */
    uint64_t acc = 0;
    unsigned nacc = 0;
    size_t n = 0;
    for (size_t r = r0; r < r1; r++) {
        const uint8_t *row = (const uint8_t *)(g->bits + r * g->wx);
        for (size_t q = 0; q < full; q++) {
            uint64_t v;
            memcpy(&v, row + 8 * q, 8); /* two grid words, little-endian: bits in order */
            uint64_t w = acc | v << nacc;
            memcpy(out + n, &w, 8);
            n += 8;
            acc = nacc ? v >> (64 - nacc) : 0;
        }
        if (tail) {
            uint64_t v = 0;
            memcpy(&v, row + 8 * full, tail > 32 ? 8 : 4);
            v &= ((uint64_t)1 << tail) - 1; /* row padding: never set */
            acc |= v << nacc;
            if (nacc + tail >= 64) {
                memcpy(out + n, &acc, 8);
                n += 8;
                acc = nacc ? v >> (64 - nacc) : 0;
                nacc = nacc + tail - 64;
            } else {
                nacc += tail;
            }
        }
    }
    for (; nacc; nacc = nacc > 8 ? nacc - 8 : 0, acc >>= 8)
        out[n++] = (uint8_t)acc;
    return n;
}

int vx_voxel_write_raw1(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    int ok = 1;
    const size_t rows = (size_t)ny * nz;
    if (!(nx & 7)) { /* rows of whole bytes: written as they are */
        for (size_t r = 0; ok && r < rows; r++) {
            if (r % (size_t)ny == 0 && vx_out_progress(io, (int)(r / ny), nz, err)) ok = 0;
            if (ok && vx_out_write(&o, g->bits + r * g->wx, (size_t)nx / 8)) ok = 0;
        }
        return vx_out_close(&o, ok, err);
    }
    raw1_job j = {g, rows, VX_CHUNK_BYTES * 8 / (size_t)nx};
    if (j.per > rows / 16) j.per = rows / 16;
    j.per = j.per < 8 ? 8 : j.per / 8 * 8;
    ok = vx_out_chunks(&o, (rows + j.per - 1) / j.per, (j.per * (size_t)nx + 7) / 8 + 8, raw1_size,
                       raw1_fill, &j, io, err) == 0;
    return vx_out_close(&o, ok, err);
}
