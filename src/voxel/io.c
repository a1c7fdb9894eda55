/* raw8, raw1 and binvox writers (io.h). Each streams the bit grid row by
 * row through stdio, so the only memory beyond the grid is one row. */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "voxel/io.h"

typedef struct out_file {
    FILE *f;
    char tmp[4200];
    const char *path;
} out_file;

static int out_open(out_file *o, const char *path, vx_err *err)
{
    o->path = path;
    snprintf(o->tmp, sizeof o->tmp, "%s.tmp", path);
    o->f = fopen(o->tmp, "wb");
    if (!o->f) return vx_err_set(err, VX_EIO, "io_error", "open %s: %s", o->tmp, strerror(errno));
    /* big buffer: rows are written a few bytes at a time */
    setvbuf(o->f, NULL, _IOFBF, 1 << 20);
    return 0;
}

/* Closes and renames on success; removes the temporary file otherwise. */
static int out_close(out_file *o, int ok, vx_err *err)
{
    if (!o->f) return ok ? 0 : -1;
    int e = ferror(o->f);
    int c = fclose(o->f);
    o->f = NULL;
    /* a failed fwrite/putc leaves ferror set: that is the error to report */
    if (e || (ok && c))
        ok = 0, vx_err_set(err, VX_EIO, "io_error", "write %s: %s", o->tmp, strerror(errno));
    if (ok && rename(o->tmp, o->path))
        ok = 0, vx_err_set(err, VX_EIO, "io_error", "rename %s: %s", o->tmp, strerror(errno));
    if (!ok) remove(o->tmp);
    return ok ? 0 : -1;
}

static int slab_progress(const vx_voxel_io *io, int k, int nz, vx_err *err)
{
    if (!io || !io->progress || (k & 7)) return 0;
    return io->progress(io->ud, (double)k / nz, err) ? -1 : 0;
}

int vx_voxel_write_raw8(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    uint8_t *row = malloc((size_t)nx);
    if (!row) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a row");
    out_file o;
    int ok = out_open(&o, path, err) == 0;
    for (int k = 0; ok && k < nz; k++) {
        if (slab_progress(io, k, nz, err)) ok = 0;
        for (int j = 0; ok && j < ny; j++) {
            for (int i = 0; i < nx; i++)
                row[i] = (uint8_t)vx_bitgrid_get(g, i, j, k);
            if (fwrite(row, 1, (size_t)nx, o.f) != (size_t)nx) ok = 0;
        }
    }
    free(row);
    return out_close(&o, ok, err);
}

int vx_voxel_write_raw1(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    out_file o;
    int ok = out_open(&o, path, err) == 0;
    /* Rows are not byte aligned when nx % 8 != 0, so bits go through an
     * accumulator rather than copying words. */
    unsigned acc = 0, nacc = 0;
    for (int k = 0; ok && k < nz; k++) {
        if (slab_progress(io, k, nz, err)) ok = 0;
        for (int j = 0; ok && j < ny; j++) {
            for (int i = 0; i < nx; i++) {
                acc |= (unsigned)vx_bitgrid_get(g, i, j, k) << nacc;
                if (++nacc == 8) {
                    if (putc((int)acc, o.f) == EOF) ok = 0;
                    acc = 0;
                    nacc = 0;
                }
            }
        }
    }
    if (ok && nacc && putc((int)acc, o.f) == EOF) ok = 0;
    return out_close(&o, ok, err);
}

int vx_voxel_write_binvox(const vx_bitgrid *g, const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    int d = nx > ny ? nx : ny;
    if (nz > d) d = nz;
    out_file o;
    int ok = out_open(&o, path, err) == 0;
    if (ok &&
        fprintf(o.f, "#binvox 1\ndim %d %d %d\ntranslate %.17g %.17g %.17g\nscale %.17g\ndata\n", d,
                d, d, g->grid.origin[0], g->grid.origin[1], g->grid.origin[2], d * g->grid.h) < 0)
        ok = 0;
    /* binvox order: x outermost, then z, then y fastest. */
    int cur = -1, run = 0;
    for (int i = 0; ok && i < d; i++) {
        if (slab_progress(io, i, d, err)) ok = 0;
        for (int k = 0; ok && k < d; k++) {
            for (int j = 0; j < d; j++) {
                int v = i < nx && j < ny && k < nz ? vx_bitgrid_get(g, i, j, k) : 0;
                if (v == cur && run < 255) {
                    run++;
                    continue;
                }
                if (run && (putc(cur, o.f) == EOF || putc(run, o.f) == EOF)) ok = 0;
                cur = v;
                run = 1;
            }
        }
    }
    if (ok && run && (putc(cur, o.f) == EOF || putc(run, o.f) == EOF)) ok = 0;
    return out_close(&o, ok, err);
}
