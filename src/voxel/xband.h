/* What the CPU crossing engines (cpu.c, rays along x; winding.c, along z
 * or y) share: the job's memory as they take it, triangles binned by the
 * bands of rows their columns fall in, and each thread's crossings of its
 * band, sorted by row with a counting sort. Private to src/voxel. */
#ifndef VX_VOXEL_XBAND_H
#define VX_VOXEL_XBAND_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "util/err.h"

/* The memory a job's engine takes; stop and err are the engine's own (its
 * threads stop once stop is set; the first error wins). */
typedef struct vx_xmeter {
    uint64_t limit;        /* max_memory, or 0: no limit */
    _Atomic uint64_t used; /* bytes taken so far */
    const char *who;       /* "the cpu method": names the engine in the error */
    atomic_int *stop;
    vx_err *err;
} vx_xmeter;

/* Takes `bytes` more: 0, or -1 with VX_ETOOBIG job_memory_limit set and
 * stop raised. Any thread. */
int vx_xmeter_charge(vx_xmeter *m, uint64_t bytes);
/* Out of memory: VX_EINTERNAL out_of_memory set, stop raised; -1. */
int vx_xmeter_oom(vx_xmeter *m);

/* One crossing of a band: its row in the band (columns, for winding) and
 * 2 x its first centre at or beyond it, plus 1 for a front face. */
typedef struct vx_xent {
    uint32_t row;
    int32_t at2;
} vx_xent;

/* A thread's crossings of the band it holds; zero is empty. */
typedef struct vx_xband {
    vx_xent *e, *sorted; /* as found, then by row (vx_xband_sort) */
    size_t n, cap, scap;
    uint32_t *end; /* after vx_xband_sort: end[r] is where row r ends in sorted */
    size_t nend;
} vx_xband;

/* Appends a crossing, charging the meter for it and its sorted copy as
 * the list grows: 0, or -1 (the meter says why). */
int vx_xband_push(vx_xband *b, vx_xmeter *m, uint32_t row, int32_t at2);
/* Sorts the crossings by row, rows of them (each row < rows): row r's
 * are sorted[r ? end[r - 1] : 0 .. end[r]). 0, or -1 out of memory. */
int vx_xband_sort(vx_xband *b, vx_xmeter *m, size_t rows);
void vx_xband_free(vx_xband *b);

/* Triangles 0..n-1 binned by bands of `band` rows (nbands of them): row
 * range lo..hi of triangle t from rows(ud, t, &lo, &hi), 0 for none. Into
 * *off (nbands + 1 offsets) and *bin (triangle ids band after band; the
 * meter charged for them). 0, or -1 with the meter's error. */
int vx_xband_bin(size_t n, int (*rows)(const void *ud, size_t t, int *lo, int *hi), const void *ud,
                 int band, int nbands, vx_xmeter *m, size_t **off, uint32_t **bin);

#endif
