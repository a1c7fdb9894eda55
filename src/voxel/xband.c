/* The CPU crossing engines' shared parts (xband.h). */
#include "voxel/xband.h"

#include <stdlib.h>
#include <string.h>

int vx_xmeter_charge(vx_xmeter *m, uint64_t bytes)
{
    uint64_t now = atomic_fetch_add(&m->used, bytes) + bytes;
    if (!m->limit || now <= m->limit) return 0;
    if (!atomic_exchange(m->stop, 1))
        vx_err_set(m->err, VX_ETOOBIG, "job_memory_limit",
                   "%s needs more than %llu bytes for this grid's crossings, over the job "
                   "memory limit of %llu",
                   m->who, (unsigned long long)now, (unsigned long long)m->limit);
    return -1;
}

int vx_xmeter_oom(vx_xmeter *m)
{
    if (!atomic_exchange(m->stop, 1))
        vx_err_set(m->err, VX_EINTERNAL, "out_of_memory", "no memory for the crossings");
    return -1;
}

int vx_xband_push(vx_xband *b, vx_xmeter *m, uint32_t row, int32_t at2)
{
    if (b->n == b->cap) {
        size_t cap = b->cap ? 2 * b->cap : 1024;
        /* the sorted copy grows with it */
        if (vx_xmeter_charge(m, 2 * (cap - b->cap) * sizeof *b->e)) return -1;
        vx_xent *e = realloc(b->e, cap * sizeof *e);
        if (!e) return vx_xmeter_oom(m);
        b->e = e;
        b->cap = cap;
    }
    b->e[b->n++] = (vx_xent){row, at2};
    return 0;
}

int vx_xband_sort(vx_xband *b, vx_xmeter *m, size_t rows)
{
    if (b->nend < rows + 1) {
        free(b->end);
        b->end = malloc((rows + 1) * sizeof *b->end);
        b->nend = b->end ? rows + 1 : 0;
        if (!b->end) return vx_xmeter_oom(m);
    }
    if (b->scap < b->cap) {
        free(b->sorted);
        b->sorted = malloc(b->cap * sizeof *b->sorted);
        b->scap = b->sorted ? b->cap : 0;
        if (!b->sorted) return vx_xmeter_oom(m);
    }
    /* counts into end[r + 1], their sums into end[r]: the start of row r,
     * moved to its end as its crossings are placed */
    memset(b->end, 0, (rows + 1) * sizeof *b->end);
    for (size_t i = 0; i < b->n; i++)
        b->end[b->e[i].row + 1]++;
    for (size_t r = 0; r < rows; r++)
        b->end[r + 1] += b->end[r];
    for (size_t i = 0; i < b->n; i++)
        b->sorted[b->end[b->e[i].row]++] = b->e[i];
    return 0;
}

void vx_xband_free(vx_xband *b)
{
    free(b->e);
    free(b->sorted);
    free(b->end);
    memset(b, 0, sizeof *b);
}

int vx_xband_bin(size_t n, int (*rows)(const void *ud, size_t t, int *lo, int *hi), const void *ud,
                 int band, int nbands, vx_xmeter *m, size_t **off, uint32_t **bin)
{
    *bin = NULL;
    *off = calloc((size_t)nbands + 2, sizeof **off);
    if (!*off) return vx_xmeter_oom(m);
    size_t *o = *off;
    for (int pass = 0; pass < 2; pass++) {
        for (size_t t = 0; t < n; t++) {
            int lo, hi;
            if (!rows(ud, t, &lo, &hi)) continue;
            for (int b = lo / band; b <= hi / band; b++) {
                if (pass == 0)
                    o[b + 1]++;
                else
                    (*bin)[o[b]++] = (uint32_t)t;
            }
        }
        if (pass == 0) {
            for (int b = 0; b < nbands; b++)
                o[b + 1] += o[b];
            if (vx_xmeter_charge(m, o[nbands] * sizeof **bin + ((size_t)nbands + 2) * sizeof *o))
                return -1;
            *bin = malloc(o[nbands] * sizeof **bin + 1);
            if (!*bin) return vx_xmeter_oom(m);
        } else { /* o[b] moved to band b's end: back to its start */
            memmove(o + 1, o, (size_t)nbands * sizeof *o);
            o[0] = 0;
        }
    }
    return 0;
}
