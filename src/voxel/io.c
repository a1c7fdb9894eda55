/* raw8, raw1 and binvox writers (io.h). Each works a word of the bit grid
 * at a time (32 voxels) and writes through a buffer of about 1 MiB, so the
 * only memory beyond the grid is that buffer (binvox: plus 32 x-columns of
 * the grid, transposed). */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

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
        return vx_err_set(err, VX_EIO, "io_error", "open %s: %s", o->tmp, strerror(errno));
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
    if (e || (ok && c))
        ok = 0,
        vx_err_set(err, VX_EIO, "io_error", "write %s: %s", o->tmp, strerror(e ? e : errno));
    if (ok && rename(o->tmp, o->path))
        ok = 0, vx_err_set(err, VX_EIO, "io_error", "rename %s: %s", o->tmp, strerror(errno));
    if (!ok) remove(o->tmp);
    return ok ? 0 : -1;
}

int vx_out_progress(const vx_voxel_io *io, int k, int nz, vx_err *err)
{
    if (!io || !io->progress || (k & 7)) return 0;
    return io->progress(io->ud, (double)k / nz, err) ? -1 : 0;
}

uint32_t vx_row_word(const vx_bitgrid *g, const uint32_t *row, size_t x)
{
    uint32_t w = row[x];
    const int tail = g->grid.dims[0] & 31;
    if (tail && x == g->wx - 1) w &= (1u << tail) - 1u; /* row padding: never set */
    return w;
}

int vx_out_raw8(vx_out *o, const vx_bitgrid *g, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    /* spread[b]: the 8 bytes 0/1 of byte b's bits, least significant first */
    uint64_t spread[256];
    for (int b = 0; b < 256; b++) {
        uint64_t v = 0;
        for (int i = 0; i < 8; i++)
            v |= (uint64_t)((b >> i) & 1) << (8 * i);
        spread[b] = v;
    }
    uint8_t *row = malloc(g->wx * 32);
    if (!row) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a row");
    int ok = 1;
    for (int k = 0; ok && k < nz; k++) {
        if (vx_out_progress(io, k, nz, err)) ok = 0;
        for (int j = 0; ok && j < ny; j++) {
            const uint8_t *w = (const uint8_t *)(g->bits + ((size_t)k * ny + j) * g->wx);
            for (size_t b = 0; b < g->wx * 4; b++)
                memcpy(row + 8 * b, &spread[w[b]], 8);
            if (vx_out_write(o, row, (size_t)nx)) ok = 0;
        }
    }
    free(row);
    return ok ? 0 : -1;
}

int vx_voxel_write_raw8(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    return vx_out_close(&o, vx_out_raw8(&o, g, io, err) == 0, err);
}

int vx_voxel_write_raw1(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    vx_out o;
    int ok = vx_out_open(&o, path, err) == 0;
    /* Rows are packed continuously: when nx % 8 != 0 they start mid-byte,
     * so words go through a 64-bit accumulator. */
    uint64_t acc = 0;
    unsigned nacc = 0;
    const unsigned last = (unsigned)(nx - 32 * (int)(g->wx - 1)); /* bits of a row's last word */
    for (int k = 0; ok && k < nz; k++) {
        if (vx_out_progress(io, k, nz, err)) ok = 0;
        for (int j = 0; ok && j < ny; j++) {
            const uint32_t *row = g->bits + ((size_t)k * ny + j) * g->wx;
            if (!nacc && !(nx & 7)) { /* byte aligned: the row as it is */
                if (vx_out_write(&o, row, (size_t)nx / 8)) ok = 0;
                continue;
            }
            for (size_t x = 0; x < g->wx; x++) {
                unsigned n = x + 1 < g->wx ? 32 : last;
                acc |= (uint64_t)vx_row_word(g, row, x) << nacc;
                nacc += n;
                if (nacc >= 32) {
                    uint32_t out = (uint32_t)acc;
                    if (vx_out_write(&o, &out, 4)) ok = 0;
                    acc >>= 32;
                    nacc -= 32;
                }
            }
        }
    }
    while (ok && nacc) {
        uint8_t b = (uint8_t)acc;
        if (vx_out_write(&o, &b, 1)) ok = 0;
        acc >>= 8;
        nacc = nacc > 8 ? nacc - 8 : 0;
    }
    return vx_out_close(&o, ok, err);
}

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

static int rle_flush(rle *r)
{
    uint8_t pair[2] = {(uint8_t)r->cur, 255};
    for (; r->run >= 255; r->run -= 255)
        if (vx_out_write(r->o, pair, 2)) return -1;
    pair[1] = (uint8_t)r->run;
    r->run = 0;
    return pair[1] ? vx_out_write(r->o, pair, 2) : 0;
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

int vx_voxel_write_binvox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    int d = nx > ny ? nx : ny;
    if (nz > d) d = nz;
    const size_t wy = ((size_t)ny + 31) / 32; /* words of a transposed y column */
    /* cols[(ii * nz + k) * wy + jw]: bit jj = voxel (32 x + ii, 32 jw + jj, k) */
    uint32_t *cols = malloc(32 * (size_t)nz * wy * sizeof *cols);
    if (!cols)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for binvox columns");
    vx_out o;
    int ok = vx_out_open(&o, path, err) == 0;
    char hdr[256];
    int hn =
        snprintf(hdr, sizeof hdr,
                 "#binvox 1\ndim %d %d %d\ntranslate %.17g %.17g %.17g\nscale %.17g\ndata\n", d, d,
                 d, g->grid.origin[0], g->grid.origin[1], g->grid.origin[2], d * g->grid.h);
    if (ok && vx_out_write(&o, hdr, (size_t)hn)) ok = 0;
    /* binvox order: x outermost, then z, then y fastest: 32 x at a time,
     * the grid's words transposed so that y runs along the bits. */
    rle r = {&o, 0, 0};
    const unsigned ylast = (unsigned)(ny - 32 * (int)(wy - 1));
    for (size_t x = 0; ok && x < g->wx; x++) {
        if (io && io->progress && io->progress(io->ud, (double)(32 * x) / d, err)) ok = 0;
        for (int k = 0; ok && k < nz; k++)
            for (size_t jw = 0; jw < wy; jw++) {
                uint32_t a[32];
                for (int jj = 0; jj < 32; jj++) {
                    size_t j = 32 * jw + (size_t)jj;
                    a[jj] = j < (size_t)ny
                                ? vx_row_word(g, g->bits + ((size_t)k * ny + j) * g->wx, x)
                                : 0;
                }
                transpose32(a);
                for (int ii = 0; ii < 32; ii++)
                    cols[((size_t)ii * nz + k) * wy + jw] = a[ii];
            }
        for (int ii = 0; ok && ii < 32 && 32 * (int)x + ii < nx; ii++) {
            for (int k = 0; ok && k < nz; k++) {
                const uint32_t *c = cols + ((size_t)ii * nz + k) * wy;
                for (size_t jw = 0; ok && jw < wy; jw++)
                    if (rle_bits(&r, c[jw], jw + 1 < wy ? 32 : ylast)) ok = 0;
                if (ok && rle_zeros(&r, (uint64_t)(d - ny))) ok = 0;
            }
            if (ok && rle_zeros(&r, (uint64_t)(d - nz) * d)) ok = 0;
        }
    }
    if (ok && rle_zeros(&r, (uint64_t)(d - nx) * d * d)) ok = 0;
    if (ok && r.run && rle_flush(&r)) ok = 0;
    free(cols);
    return vx_out_close(&o, ok, err);
}
