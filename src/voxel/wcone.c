/* The cones that close a mesh's boundary for the winding rule
 * (winding_int.h): over the edges whose uses do not cancel, vertices welded
 * (vx_mesh_net_edges), one apex per connected part of that boundary. */
#include <stdlib.h>
#include <string.h>

#include "voxel/winding_int.h"

/* Union-find root of v (paths halved). */
static uint32_t root(uint32_t *up, uint32_t v)
{
    while (up[v] != v) {
        up[v] = up[up[v]];
        v = up[v];
    }
    return v;
}

int vx_wcone_build(const vx_mesh *m, double **cone, size_t *ncone, vx_err *err)
{
    *cone = NULL;
    *ncone = 0;
    vx_mesh_edge *e;
    size_t nb = 0, w;
    if (vx_mesh_net_edges(m, &e, &w, err)) return -1;
    for (size_t i = 0; i < w; i++)
        nb += (size_t)abs(e[i].net);
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
        for (int r = 0; r < abs(e[i].net); r++) {
            /* edge a -> b is closed by (b, a, apex) */
            uint32_t a = e[i].net > 0 ? e[i].lo : e[i].hi, b = e[i].net > 0 ? e[i].hi : e[i].lo;
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
    free(e);
    return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the mesh's boundary");
}
