/* What the writers of io.c, binvox.c and formats.c share: a buffered output file
 * written to a temporary name and renamed on success. */
#ifndef VX_VOXEL_IO_INT_H
#define VX_VOXEL_IO_INT_H

#include <stdio.h>

#include "voxel/io.h"

#define VX_OUT_BUF ((size_t)1 << 20)

typedef struct vx_out {
    FILE *f;
    uint8_t *buf;
    size_t n;
    int failed; /* errno of a failed write */
    char tmp[4200];
    const char *path;
} vx_out;

/* Opens path.tmp for writing (err set on failure). */
int vx_out_open(vx_out *o, const char *path, vx_err *err);
/* Appends n bytes; -1 once a write has failed. */
int vx_out_write(vx_out *o, const void *p, size_t n);
/* Writes out the buffer; -1 once a write has failed. */
int vx_out_flush(vx_out *o);
/* Closes and renames on success (ok); removes the temporary file otherwise
 * or when a write failed (err set). */
int vx_out_close(vx_out *o, int ok, vx_err *err);
/* The progress hook at k of n, every 8th k; -1 when it stops the write. */
int vx_out_progress(const vx_voxel_io *io, int k, int n, vx_err *err);
/* Writes n chunks: chunk c is size(ud, c) bytes (at most cap), made by
 * fill(ud, c, buf) into a buffer of cap bytes. Chunks are made and written
 * at their places by a few writer threads while the calling thread reports
 * progress (chunks done / n). 0, or -1 with err set (the hook stopped it, a
 * fill gave another size) or a write failed (o->failed; vx_out_close
 * reports it). */
typedef size_t (*vx_out_size_fn)(void *ud, size_t c);
typedef size_t (*vx_out_fill_fn)(void *ud, size_t c, uint8_t *buf);
int vx_out_chunks(vx_out *o, size_t n, size_t cap, vx_out_size_fn size, vx_out_fill_fn fill,
                  void *ud, const vx_voxel_io *io, vx_err *err);
/* The raw8 body (io.h) of g into o (err set when the hook stops it). */
int vx_out_raw8(vx_out *o, const vx_bitgrid *g, const vx_voxel_io *io, vx_err *err);
/* Word x of a row, the padding bits past nx cleared. */
static inline uint32_t vx_row_word(const vx_bitgrid *g, const uint32_t *row, size_t x)
{
    uint32_t w = row[x];
    const int tail = g->grid.dims[0] & 31;
    if (tail && x == g->wx - 1) w &= (1u << tail) - 1u; /* row padding: never set */
    return w;
}

#endif
