/* inside "winding" against "nonzero" (auto: scan) on the same mesh and
 * grid, in one run, the two rules taking turns (so that both see the
 * machine's same minutes: its speed moves by a quarter from one minute to
 * the next): engine time of each (median, min and max of N runs), the
 * ratio of the medians and of the bests, and the voxels each sets.
 *
 *   winding_bench [--runs N] [--padding P] MESH... RES...
 *
 * The target (issue 14): winding at most 3x nonzero's time. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl/gl.h"
#include "mesh/mesh.h"
#include "util/clock.h"
#include "voxel/voxel.h"

static int dcmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* FNV-1a of a grid's bits: the same voxels from two builds (--hash). */
static unsigned long long grid_hash(const vx_bitgrid *b)
{
    const unsigned char *p = (const unsigned char *)b->bits;
    size_t bytes = b->wx * (size_t)b->grid.dims[1] * (size_t)b->grid.dims[2] * sizeof *b->bits;
    unsigned long long h = 14695981039346656037ull;
    for (size_t i = 0; i < bytes; i++)
        h = (h ^ p[i]) * 1099511628211ull;
    return h;
}

/* One run of rule on m over g: its engine time in ms; *n its voxels, and
 * the grid's hash into *hash when it is not NULL. */
static double time_once(vx_gl *gl, const vx_mesh *m, const vx_grid *g, vx_inside rule,
                        unsigned long long *n, unsigned long long *hash)
{
    vx_voxelize_desc d = {.grid = *g, .inside = rule};
    d.max_slab_rows = vx_voxelize_slab_rows(g->dims);
    vx_bitgrid b;
    vx_voxelize_stats st;
    vx_err err = {0};
    double t0 = vx_mono();
    if (vx_voxelize(gl, m, &d, &b, &st, &err)) {
        fprintf(stderr, "voxelize: %s\n", err.message);
        exit(1);
    }
    double t = (vx_mono() - t0) * 1e3;
    *n = (unsigned long long)st.voxels_inside;
    if (hash) *hash = grid_hash(&b);
    vx_bitgrid_free(&b);
    return t;
}

int main(int argc, char **argv)
{
    int runs = 5, padding = 0, nm = 0, nr = 0, res[16], hash = 0;
    const char *mesh[16];
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--hash"))
            hash = 1;
        else if (!strcmp(argv[i], "--padding") && i + 1 < argc)
            padding = atoi(argv[++i]);
        else if (argv[i][0] >= '0' && argv[i][0] <= '9' && nr < 16)
            res[nr++] = atoi(argv[i]);
        else if (nm < 16)
            mesh[nm++] = argv[i];
    }
    if (!nm || !nr || runs < 1 || runs > 64) {
        fprintf(stderr, "usage: winding_bench [--runs N] [--padding P] [--hash] MESH... RES...\n");
        return 2;
    }
    vx_err err = {0};
    vx_gl_desc gd = {0};
    vx_gl *gl = vx_gl_new(&gd, &err);
    if (!gl) {
        fprintf(stderr, "gl: %s\n", err.message);
        return 1;
    }
    printf("| mesh | grid | boundary edges | nonzero ms (min-max) | winding ms (min-max) | ratio "
           "| ratio of bests | voxels nonzero | voxels winding |\n"
           "|---|---|---|---|---|---|---|---|---|\n");
    for (int i = 0; i < nm; i++) {
        vx_mesh *m = vx_mesh_read_path(mesh[i], NULL, &err);
        if (!m) {
            fprintf(stderr, "%s: %s\n", mesh[i], err.message);
            return 1;
        }
        const char *name = strrchr(mesh[i], '/') ? strrchr(mesh[i], '/') + 1 : mesh[i];
        for (int r = 0; r < nr; r++) {
            vx_grid g;
            if (vx_grid_from_resolution(m, res[r], padding, &g, &err)) return 1;
            double tn[64], tw[64];
            unsigned long long nn = 0, nw = 0, hw = 0;
            for (int k = 0; k < runs; k++) {
                tn[k] = time_once(gl, m, &g, VX_INSIDE_NONZERO, &nn, NULL);
                tw[k] = time_once(gl, m, &g, VX_INSIDE_WINDING, &nw, hash && !k ? &hw : NULL);
            }
            if (hash)
                fprintf(stderr, "winding grid %s %dx%dx%d: hash %016llx\n", name, g.dims[0],
                        g.dims[1], g.dims[2], hw);
            qsort(tn, (size_t)runs, sizeof *tn, dcmp);
            qsort(tw, (size_t)runs, sizeof *tw, dcmp);
            double mn = tn[runs / 2], mw = tw[runs / 2];
            printf(
                "| %s | %dx%dx%d | %zu | %.0f (%.0f-%.0f) | %.0f (%.0f-%.0f) | %.2f | %.2f | %llu "
                "| %llu |\n",
                name, g.dims[0], g.dims[1], g.dims[2], m->boundary_edges, mn, tn[0], tn[runs - 1],
                mw, tw[0], tw[runs - 1], mw / mn, tw[0] / tn[0], nn, nw);
            fflush(stdout);
        }
        vx_mesh_free(m);
    }
    vx_gl_free(gl);
    return 0;
}
