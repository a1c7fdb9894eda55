/* The cones that close a mesh's boundary for the winding rule
 * (winding_int.h): welded vertices, the directed edges whose uses do not
 * cancel, one apex per connected part of that boundary. */
#include <stdlib.h>
#include <string.h>

#include "voxel/winding_int.h"

typedef struct dedge {
    uint32_t lo, hi;
    int s;
} dedge;

/* Union-find root of v (paths halved). */
static uint32_t root(uint32_t *up, uint32_t v)
{
    while (up[v] != v) {
        up[v] = up[up[v]];
        v = up[v];
    }
    return v;
}

/* Occurrences of b in list[0..n). */
static uint32_t occurs(const uint32_t *list, uint32_t n, uint32_t b)
{
    uint32_t c = 0;
    for (uint32_t k = 0; k < n; k++)
        c += list[k] == b;
    return c;
}

/* The directed edges a -> b of vertex a's out-list `to[off[a]..off[a+1])`
 * that b's list does not cancel, written into e (when not NULL); returns
 * their number. Each is written once, from the side that has more. */
static size_t emit_net(const uint32_t *off, const uint32_t *to, size_t nv, dedge *e)
{
    size_t w = 0;
    for (uint32_t a = 0; a < nv; a++) {
        const uint32_t *la = to + off[a], na = off[a + 1] - off[a];
        for (uint32_t k = 0; k < na; k++) {
            uint32_t b = la[k];
            if (occurs(la, k, b)) continue; /* counted at its first occurrence */
            uint32_t nab = occurs(la + k, na - k, b),
                     nba = occurs(to + off[b], off[b + 1] - off[b], a);
            if (nab <= nba) continue;
            int n = (int)(nab - nba);
            if (e) e[w] = a < b ? (dedge){a, b, n} : (dedge){b, a, -n};
            w++;
        }
    }
    return w;
}

/* The directed edges that do not cancel (net use s != 0, lo -> hi when
 * positive) into *out, from per-vertex out-lists (counting sort by the
 * welded start vertex); returns their number, or (size_t)-1 without
 * memory. */
static size_t net_edges(const vx_mesh *m, const uint32_t *canon, dedge **out)
{
    size_t nv = m->nverts, w = (size_t)-1;
    *out = NULL;
    if (3 * m->ntris >= UINT32_MAX) return w;
    uint32_t *off = calloc(nv + 2, sizeof *off), *to = malloc(3 * m->ntris * sizeof *to + 1);
    if (!off || !to) goto done;
    for (size_t t = 0; t < m->ntris; t++)
        for (int q = 0; q < 3; q++) {
            uint32_t a = canon[m->tri[3 * t + q]], b = canon[m->tri[3 * t + (q + 1) % 3]];
            if (a != b) off[a + 2]++;
        }
    for (size_t v = 2; v < nv + 2; v++)
        off[v] += off[v - 1];
    for (size_t t = 0; t < m->ntris; t++) /* off[a + 1] is a's cursor */
        for (int q = 0; q < 3; q++) {
            uint32_t a = canon[m->tri[3 * t + q]], b = canon[m->tri[3 * t + (q + 1) % 3]];
            if (a != b) to[off[a + 1]++] = b;
        }
    w = emit_net(off, to, nv, NULL);
    *out = malloc(w * sizeof **out + 1);
    if (!*out) {
        w = (size_t)-1;
        goto done;
    }
    emit_net(off, to, nv, *out);
done:
    free(off);
    free(to);
    return w;
}

int vx_wcone_build(const vx_mesh *m, double **cone, size_t *ncone, vx_err *err)
{
    *cone = NULL;
    *ncone = 0;
    uint32_t *canon = vx_mesh_weld(m);
    dedge *e = NULL;
    size_t nb = 0, w = canon ? net_edges(m, canon, &e) : (size_t)-1;
    if (w == (size_t)-1) goto oom;
    for (size_t i = 0; i < w; i++)
        nb += (size_t)abs(e[i].s);
    free(canon);
    canon = NULL;
    if (!nb) {
        free(e);
        return 0;
    }
    /* one apex per connected part of the boundary (a hole): the mean of
     * its edges' end points */
    uint32_t *up = malloc(m->nverts * sizeof *up + 1);
    double *apex = calloc(4 * m->nverts + 1, sizeof *apex);
    if (!up || !apex) {
        free(up);
        free(apex);
        goto oom;
    }
    for (size_t i = 0; i < w; i++)
        up[e[i].lo] = e[i].lo, up[e[i].hi] = e[i].hi;
    for (size_t i = 0; i < w; i++) {
        uint32_t a = root(up, e[i].lo), b = root(up, e[i].hi);
        if (a != b) up[a] = b;
    }
    for (size_t i = 0; i < w; i++) {
        double *x = apex + 4 * (size_t)root(up, e[i].lo);
        for (int k = 0; k < 3; k++)
            x[k] += m->pos[3 * (size_t)e[i].lo + k] + m->pos[3 * (size_t)e[i].hi + k];
        x[3] += 2;
    }
    *cone = malloc(9 * nb * sizeof **cone);
    if (!*cone) {
        free(up);
        free(apex);
        goto oom;
    }
    for (size_t i = 0; i < w; i++)
        for (int r = 0; r < abs(e[i].s); r++) {
            /* edge a -> b is closed by (b, a, apex) */
            uint32_t a = e[i].s > 0 ? e[i].lo : e[i].hi, b = e[i].s > 0 ? e[i].hi : e[i].lo;
            const double *x = apex + 4 * (size_t)root(up, a);
            double *v = *cone + 9 * (*ncone)++;
            memcpy(v, m->pos + 3 * (size_t)b, 3 * sizeof *v);
            memcpy(v + 3, m->pos + 3 * (size_t)a, 3 * sizeof *v);
            for (int k = 0; k < 3; k++)
                v[6 + k] = x[k] / x[3];
        }
    free(up);
    free(apex);
    free(e);
    return 0;
oom:
    free(canon);
    free(e);
    return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the mesh's boundary");
}
