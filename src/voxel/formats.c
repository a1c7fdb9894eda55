/* The nrrd, npy and vox writers (io.h): nrrd and npy put a header before
 * the raw8 body; vox (MagicaVoxel) splits the grid into bricks of at most
 * 256 per axis, one model each, placed by a scene graph. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/par.h"
#include "voxel/io.h"
#include "voxel/io_int.h"

int vx_voxel_write_nrrd(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const vx_grid *gr = &g->grid;
    const double h = gr->h;
    char hdr[1024];
    /* the space origin is the first sample: voxel (0,0,0)'s centre */
    int n = snprintf(hdr, sizeof hdr,
                     "NRRD0004\n# voxeld voxelize: 1 = inside, x fastest\ntype: uint8\n"
                     "dimension: 3\nspace dimension: 3\nsizes: %d %d %d\n"
                     "space directions: (%.17g,0,0) (0,%.17g,0) (0,0,%.17g)\n"
                     "space origin: (%.17g,%.17g,%.17g)\nkinds: domain domain domain\n"
                     "encoding: raw\n\n",
                     gr->dims[0], gr->dims[1], gr->dims[2], h, h, h, gr->origin[0] + 0.5 * h,
                     gr->origin[1] + 0.5 * h, gr->origin[2] + 0.5 * h);
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    int ok = vx_out_write(&o, hdr, (size_t)n) == 0 && vx_out_raw8(&o, g, io, err) == 0;
    return vx_out_close(&o, ok, err);
}

int vx_voxel_write_npy(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    /* NPY 1.0: magic, version, header length, a Python dict literal padded
     * with spaces to a multiple of 64 bytes and ended by a newline. x runs
     * fastest, so shape (nx, ny, nz) in Fortran order: a[i, j, k]. */
    char hdr[256];
    int n = snprintf(hdr + 10, sizeof hdr - 10,
                     "{'descr': '|u1', 'fortran_order': True, 'shape': (%d, %d, %d), }",
                     g->grid.dims[0], g->grid.dims[1], g->grid.dims[2]);
    int total = (10 + n + 1 + 63) / 64 * 64;
    memset(hdr + 10 + n, ' ', (size_t)(total - 10 - n - 1));
    hdr[total - 1] = '\n';
    memcpy(hdr, "\x93NUMPY\x01\x00", 8);
    hdr[8] = (char)((total - 10) & 0xff);
    hdr[9] = (char)((total - 10) >> 8);
    vx_out o;
    if (vx_out_open(&o, path, err)) return -1;
    int ok = vx_out_write(&o, hdr, (size_t)total) == 0 && vx_out_raw8(&o, g, io, err) == 0;
    return vx_out_close(&o, ok, err);
}

/* ---- vox ---- */

#define VOX_BRICK 256

typedef struct vox_brick {
    int o[3], s[3]; /* first voxel and size */
    uint64_t count;
} vox_brick;

static inline void put_le32(uint8_t *p, uint32_t v)
{
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    memcpy(p, &v, 4);
#else
    p[0] = (uint8_t)v, p[1] = (uint8_t)(v >> 8), p[2] = (uint8_t)(v >> 16),
    p[3] = (uint8_t)(v >> 24);
#endif
}

/* Writes the set voxels of slices k0..k1-1 of the brick to out as XYZI's
 * (x, y, z, colour 1) relative to the brick, z, y, x order (x fastest);
 * returns their number. */
static uint64_t brick_scan(const vx_bitgrid *g, const vox_brick *b, int k0, int k1, uint8_t *out)
{
    const int ny = g->grid.dims[1];
    uint64_t n = 0;
    const int i0 = b->o[0], i1 = b->o[0] + b->s[0];
    const size_t x0 = (size_t)i0 / 32, x1 = ((size_t)i1 + 31) / 32;
    uint8_t *p = out;
    for (int k = k0; k < k1; k++)
        for (int j = b->o[1]; j < b->o[1] + b->s[1]; j++) {
            const uint32_t *row = g->bits + ((size_t)k * ny + j) * g->wx;
            for (size_t x = x0; x < x1; x++) {
                uint32_t w = vx_row_word(g, row, x);
                /* bricks start on multiples of 256: only the grid's end cuts a word */
                if (32 * x + 32 > (size_t)i1) w &= (1u << (i1 - 32 * (int)x)) - 1u;
                /* (x, y, z, 1) as one little-endian word: y, z and the
                 * colour are the row's, x the bit's */
                const uint32_t row_yz = (uint32_t)(uint8_t)(j - b->o[1]) << 8 |
                                        (uint32_t)(uint8_t)(k - b->o[2]) << 16 | 1u << 24;
                const uint32_t x_at = (uint32_t)(32 * x - (size_t)i0);
                if (w == 0xffffffffu) { /* inside a solid: 32 in a row */
                    /* x_at is a multiple of 32 (bricks start on multiples
                     * of 256): the records are base + 0..31, in vectors */
                    const uint32_t base = row_yz | x_at;
                    for (uint32_t q = 0; q < 32; q++)
                        put_le32(p + 4 * q, base + q);
                    p += 128;
                    n += 32;
                } else {
                    for (; w; w &= w - 1, n++, p += 4)
                        put_le32(p, row_yz | (uint8_t)(x_at + (uint32_t)__builtin_ctz(w)));
                }
            }
        }
    return n;
}

/* The models' SIZE and XYZI chunks as output chunks of VOX_SLICES slices
 * of a brick (at most 4 MiB of XYZI), the first of each brick with its
 * headers. The set voxels of each VOX_SLICES slices of each brick column
 * are counted first (a pass over the grid's rows on all threads), so each
 * chunk's size and place are known before it is made. */
#define VOX_SLICES 16

typedef struct vox_job {
    const vx_bitgrid *g;
    int nb[3];        /* bricks along each axis */
    uint64_t *counts; /* [slice group][brick row y][brick x]: set voxels */
    const vox_brick *b;
    const size_t *first; /* first[m]: model m's first output chunk */
    int nm;
} vox_job;

static int vox_count(int kg, int t, void *ud)
{
    (void)t;
    const vox_job *j = ud;
    const vx_bitgrid *g = j->g;
    const int ny = g->grid.dims[1], nz = g->grid.dims[2];
    uint64_t *n = j->counts + (size_t)kg * j->nb[1] * j->nb[0];
    const size_t per = VOX_BRICK / 32; /* words of a brick's row */
    for (int k = kg * VOX_SLICES; k < nz && k < (kg + 1) * VOX_SLICES; k++)
        for (int y = 0; y < ny; y++) {
            const uint32_t *row = g->bits + ((size_t)k * ny + y) * g->wx;
            uint64_t *nr = n + (size_t)(y / VOX_BRICK) * j->nb[0];
            /* padding bits past nx are never set */
            for (int bx = 0; bx < j->nb[0]; bx++) {
                size_t x0 = bx * per, x1 = x0 + per < g->wx ? x0 + per : g->wx;
                nr[bx] += vx_bits_count(row + x0, x1 - x0);
            }
        }
    return 0;
}

/* Chunk c: model m, its slices k0..k1-1 (slice group k0 / VOX_SLICES). */
static const vox_brick *vox_chunk(const vox_job *j, size_t c, int *k0, int *k1, int *head)
{
    int m = 0;
    while (m + 1 < j->nm && j->first[m + 1] <= c)
        m++;
    const vox_brick *b = &j->b[m];
    *k0 = b->o[2] + VOX_SLICES * (int)(c - j->first[m]);
    *k1 = *k0 + VOX_SLICES < b->o[2] + b->s[2] ? *k0 + VOX_SLICES : b->o[2] + b->s[2];
    *head = c == j->first[m];
    return b;
}

static size_t vox_size(void *ud, size_t c)
{
    const vox_job *j = ud;
    int k0, k1, head;
    const vox_brick *b = vox_chunk(j, c, &k0, &k1, &head);
    size_t at = ((size_t)k0 / VOX_SLICES * j->nb[1] + (size_t)b->o[1] / VOX_BRICK) * j->nb[0] +
                (size_t)b->o[0] / VOX_BRICK;
    return (head ? 40 : 0) + 4 * (size_t)j->counts[at];
}

static size_t vox_fill(void *ud, size_t c, uint8_t *out)
{
    const vox_job *j = ud;
    int k0, k1, head;
    const vox_brick *b = vox_chunk(j, c, &k0, &k1, &head);
    uint8_t *p = out;
    if (head) { /* SIZE (x, y, z), then XYZI's header and count */
        uint32_t h[] = {0,
                        12,
                        0,
                        (uint32_t)b->s[0],
                        (uint32_t)b->s[1],
                        (uint32_t)b->s[2],
                        0,
                        (uint32_t)(4 + 4 * b->count),
                        0,
                        (uint32_t)b->count};
        for (int q = 0; q < 10; q++)
            put_le32(p + 4 * q, h[q]);
        memcpy(p, "SIZE", 4);
        memcpy(p + 24, "XYZI", 4);
        p += 40;
    }
    return (size_t)(p - out) + 4 * (size_t)brick_scan(j->g, b, k0, k1, p);
}

static int put32(vx_out *o, int32_t v)
{
    uint8_t b[4] = {(uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
    return vx_out_write(o, b, 4);
}

static int chunk(vx_out *o, const char *id, int32_t content, int32_t children)
{
    return vx_out_write(o, id, 4) || put32(o, content) || put32(o, children) ? -1 : 0;
}

static int put_str(vx_out *o, const char *s)
{
    return put32(o, (int32_t)strlen(s)) || vx_out_write(o, s, strlen(s)) ? -1 : 0;
}

/* A node's chunk: nTRN (child, translation t or none), nGRP (children
 * first .. first + n - 1) or nSHP (model). sizes only: o NULL. */
static int32_t node_trn(vx_out *o, int id, int child, const char *t)
{
    int32_t len = 4 + 4 + 4 + 4 + 4 + 4 + 4 + (t ? 4 + 2 + 4 + (int32_t)strlen(t) : 0);
    if (!o) return 12 + len;
    return chunk(o, "nTRN", len, 0) || put32(o, id) || put32(o, 0) || put32(o, child) ||
                   put32(o, -1) || put32(o, t ? 0 : -1) || put32(o, 1) || put32(o, t ? 1 : 0) ||
                   (t && (put_str(o, "_t") || put_str(o, t)))
               ? -1
               : 0;
}

static int32_t node_grp(vx_out *o, int id, int first, int n)
{
    int32_t len = 4 + 4 + 4 + 4 * n;
    if (!o) return 12 + len;
    if (chunk(o, "nGRP", len, 0) || put32(o, id) || put32(o, 0) || put32(o, n)) return -1;
    for (int c = 0; c < n; c++)
        if (put32(o, first + 2 * c)) return -1;
    return 0;
}

static int32_t node_shp(vx_out *o, int id, int model)
{
    int32_t len = 4 + 4 + 4 + 4 + 4;
    if (!o) return 12 + len;
    return chunk(o, "nSHP", len, 0) || put32(o, id) || put32(o, 0) || put32(o, 1) ||
                   put32(o, model) || put32(o, 0)
               ? -1
               : 0;
}

/* Model m's translation: MagicaVoxel places a model's voxel v at
 * t + v - floor(size / 2), so t = brick origin + floor(size / 2). */
static void brick_t(const vox_brick *b, char *t, size_t n)
{
    snprintf(t, n, "%d %d %d", b->o[0] + b->s[0] / 2, b->o[1] + b->s[1] / 2, b->o[2] + b->s[2] / 2);
}

int vx_voxel_write_vox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int *d = g->grid.dims;
    vox_job j = {.g = g};
    int *nb = j.nb, total = 1;
    for (int a = 0; a < 3; a++)
        nb[a] = (d[a] + VOX_BRICK - 1) / VOX_BRICK, total *= nb[a];
    const int groups = (d[2] + VOX_SLICES - 1) / VOX_SLICES;
    vox_brick *b = calloc((size_t)total, sizeof *b);
    j.counts = calloc((size_t)groups * nb[1] * nb[0], sizeof *j.counts);
    if (!b || !j.counts) {
        free(b);
        free(j.counts);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for vox bricks");
    }
    /* pass 1: the set voxels of each slice group of each brick; the bricks
     * that hold voxels */
    vx_par_for(groups, vx_par_cpus(), vox_count, &j);
    int nm = 0;
    for (int bz = 0; bz < nb[2]; bz++)
        for (int by = 0; by < nb[1]; by++)
            for (int bx = 0; bx < nb[0]; bx++) {
                vox_brick *m = &b[nm];
                int at[3] = {bx, by, bz};
                for (int a = 0; a < 3; a++) {
                    m->o[a] = at[a] * VOX_BRICK;
                    m->s[a] = d[a] - m->o[a] < VOX_BRICK ? d[a] - m->o[a] : VOX_BRICK;
                }
                m->count = 0;
                for (int kg = m->o[2] / VOX_SLICES; kg * VOX_SLICES < m->o[2] + m->s[2]; kg++)
                    m->count += j.counts[((size_t)kg * nb[1] + by) * nb[0] + bx];
                /* an empty grid keeps one empty model, the last brick's */
                if (m->count || (!nm && bx + 1 == nb[0] && by + 1 == nb[1] && bz + 1 == nb[2]))
                    nm++;
            }
    /* (the count is a small part of the work: the chunks report progress) */
    if (io && io->progress && io->progress(io->ud, 0.0, err)) {
        free(b);
        free(j.counts);
        return -1;
    }
    /* children of MAIN: models, then the scene: root nTRN 0 -> nGRP 1 ->
     * per model nTRN 2 + 2m -> nSHP 3 + 2m */
    char t[64];
    int64_t children = 0;
    for (int m = 0; m < nm; m++) {
        brick_t(&b[m], t, sizeof t);
        children += 24 + 12 + 4 + 4 * (int64_t)b[m].count; /* SIZE, XYZI */
        children += node_trn(NULL, 2 + 2 * m, 3 + 2 * m, t) + node_shp(NULL, 3 + 2 * m, m);
    }
    children += node_trn(NULL, 0, 1, NULL) + node_grp(NULL, 1, 2, nm);
    if (children > INT32_MAX) {
        free(b);
        free(j.counts);
        return vx_err_set(err, VX_ETOOBIG, "vox_too_large",
                          "a .vox file holds at most 2^31 bytes; this grid needs %lld (use "
                          "another format)",
                          (long long)children);
    }
    vx_out o;
    int ok = vx_out_open(&o, path, err) == 0;
    ok = ok && !vx_out_write(&o, "VOX ", 4) && !put32(&o, 150) &&
         !chunk(&o, "MAIN", 0, (int32_t)children);
    size_t *first = malloc(((size_t)nm + 1) * sizeof *first);
    if (ok && !first)
        ok = 0, vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for vox bricks");
    if (ok) {
        first[0] = 0;
        for (int m = 0; m < nm; m++)
            first[m + 1] = first[m] + (size_t)(b[m].s[2] + VOX_SLICES - 1) / VOX_SLICES;
        j.b = b;
        j.first = first;
        j.nm = nm;
        size_t cap = 40 + 4 * (size_t)VOX_BRICK * VOX_BRICK * VOX_SLICES;
        ok = vx_out_chunks(&o, first[nm], cap, vox_size, vox_fill, &j, io, err) == 0;
    }
    free(first);
    free(j.counts);
    ok = ok && !node_trn(&o, 0, 1, NULL) && !node_grp(&o, 1, 2, nm);
    for (int m = 0; ok && m < nm; m++) {
        brick_t(&b[m], t, sizeof t);
        ok = !node_trn(&o, 2 + 2 * m, 3 + 2 * m, t) && !node_shp(&o, 3 + 2 * m, m);
    }
    free(b);
    return vx_out_close(&o, ok, err);
}
