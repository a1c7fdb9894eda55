/* Encoder benchmark (issue 14 item 10): voxelizes a mesh once per
 * resolution (engine time, the best of --runs after a warm-up), then times
 * every writer of voxel/io.h on that grid (ms, the best of --runs writes
 * and the worst, bytes, MB/s and the ratio to the engine time; for a .vdb
 * the time its tree then took to free, after the write as a job frees it
 * (vx_voxel_io.vdb_keep), in the best run), beside the
 * disk's sequential write speed measured in the same run (the raw8 size of
 * zeros through write(2), then with fsync).
 *
 *   voxel_encode_bench DIR MESH.obj RES... [--runs N] [--formats raw8,binvox,vdb:fog,...]
 *                      [--no-disk]
 * ("binvox:blocks" is binvox's bounded coder, forced; --no-disk leaves the
 * disk's speed out).
 * DIR receives the files (removed after each is measured). */
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "gl/gl.h"
#include "mesh/mesh.h"
#include "voxel/io.h"
#include "voxel/voxel.h"

static double now_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static double cpu_ms(void)
{
    struct timespec t;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
    return t.tv_sec * 1e3 + t.tv_nsec / 1e6;
}

static long long file_bytes(const char *p)
{
    struct stat s;
    return stat(p, &s) ? -1 : (long long)s.st_size;
}

/* MB/s writing n bytes of zeros to path (fsync: to the disk, else the page
 * cache). */
static double disk_mbs(const char *path, uint64_t n, int do_fsync)
{
    const size_t chunk = (size_t)1 << 20;
    char *buf = calloc(1, chunk);
    int fd = open(path, O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (fd < 0 || !buf) return -1;
    double t0 = now_ms();
    for (uint64_t done = 0; done < n;) {
        size_t c = n - done < chunk ? (size_t)(n - done) : chunk;
        if (write(fd, buf, c) != (ssize_t)c) break;
        done += c;
    }
    if (do_fsync) fsync(fd);
    double ms = now_ms() - t0;
    close(fd);
    unlink(path);
    free(buf);
    return (double)n / 1e6 / (ms / 1e3);
}

/* Whether name ("vdb fog" is written vdb:fog) is in the comma list. */
static int listed(const char *list, const char *name)
{
    char want[64];
    snprintf(want, sizeof want, "%s", name);
    for (char *c = want; *c; c++)
        if (*c == ' ') *c = ':';
    size_t n = strlen(want);
    for (const char *p = list; *p;) {
        const char *e = strchr(p, ',');
        size_t len = e ? (size_t)(e - p) : strlen(p);
        if (len == n && !strncmp(p, want, n)) return 1;
        p += len + (e != NULL);
    }
    return 0;
}

typedef struct writer {
    const char *name;
    int (*fn)(const vx_bitgrid *, const char *, const vx_voxel_io *, vx_err *);
    int vdb; /* 1 + vx_vdb_class, 0 = not vdb */
    const vx_voxel_io *io;
} writer;

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: voxel_encode_bench DIR MESH.obj RES... [--runs N] [--formats a,b] "
                        "[--no-disk]\n");
        return 2;
    }
    const char *dir = argv[1], *mesh = argv[2];
    int runs = 2, res[16], nres = 0, no_disk = 0;
    const char *formats = NULL;
    for (int i = 3; i < argc; i++)
        if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--no-disk"))
            no_disk = 1;
        else if (!strcmp(argv[i], "--formats") && i + 1 < argc)
            formats = argv[++i];
        else if (nres < 16)
            res[nres++] = atoi(argv[i]);
    vx_err err;
    vx_mesh *m = vx_mesh_read_path(mesh, NULL, &err);
    if (!m) return fprintf(stderr, "%s: %s\n", mesh, err.message), 1;
    vx_gl_desc gd = {0};
    vx_gl *gl = vx_gl_new(&gd, &err);
    if (!gl) return fprintf(stderr, "GL: %s\n", err.message), 1;
    /* binvox's bounded coder, which it falls back on past its event budget */
    const vx_voxel_io blocks = {.binvox_event_bytes = 1};
    const writer ws[] = {
        {"raw8", vx_voxel_write_raw8, 0, NULL},
        {"raw1", vx_voxel_write_raw1, 0, NULL},
        {"binvox", vx_voxel_write_binvox, 0, NULL},
        {"binvox blocks", vx_voxel_write_binvox, 0, &blocks},
        {"nrrd", vx_voxel_write_nrrd, 0, NULL},
        {"npy", vx_voxel_write_npy, 0, NULL},
        {"vox", vx_voxel_write_vox, 0, NULL},
        {"vdb level_set", NULL, 1 + VX_VDB_LEVEL_SET, NULL},
        {"vdb fog", NULL, 1 + VX_VDB_FOG, NULL},
        {"vdb bool", NULL, 1 + VX_VDB_BOOL, NULL},
    };
    const char *base = strrchr(mesh, '/') ? strrchr(mesh, '/') + 1 : mesh;
    printf("| mesh | grid | engine ms | format | encode ms | encode / engine | encode CPU ms (all "
           "threads) | bytes | MB/s | vdb tree freed after, ms "
           "|\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (int r = 0; r < nres; r++) {
        vx_voxelize_desc d = {0};
        if (vx_grid_from_resolution(m, res[r], 0, &d.grid, &err)) return 1;
        d.max_slab_rows = vx_voxelize_slab_rows(d.grid.dims);
        vx_bitgrid g = {0};
        vx_voxelize_stats st;
        double best = 1e30;
        for (int k = 0; k <= runs; k++) { /* the first run warms up */
            vx_bitgrid_free(&g);
            double t0 = now_ms();
            if (vx_voxelize(gl, m, &d, &g, &st, &err))
                return fprintf(stderr, "voxelize: %s\n", err.message), 1;
            if (k && now_ms() - t0 < best) best = now_ms() - t0;
        }
        const int *n = g.grid.dims;
        char grid[64], path[4200];
        snprintf(grid, sizeof grid, "%dx%dx%d", n[0], n[1], n[2]);
        for (size_t w = 0; w < sizeof ws / sizeof *ws; w++) {
            if (formats && !listed(formats, ws[w].name)) continue;
            snprintf(path, sizeof path, "%s/enc.out", dir);
            /* best of runs (at least one); the spread is the worst */
            double ms = 1e30, cms = 0, worst = 0, fms = 0;
            long long bytes = 0;
            int rc = 0;
            for (int k = 0; k < (runs > 0 ? runs : 1) && !rc; k++) {
                /* a .vdb's tree is freed after, as a job frees it (io.h) */
                vx_vdb_tree *tree = NULL;
                vx_voxel_io io = {.vdb_keep = &tree};
                double t0 = now_ms(), c0 = cpu_ms();
                rc = ws[w].vdb ? vx_voxel_write_vdb(&g, (vx_vdb_class)(ws[w].vdb - 1), NULL, path,
                                                    &io, &err)
                               : ws[w].fn(&g, path, ws[w].io, &err);
                double t = now_ms() - t0, c = cpu_ms() - c0, f0 = now_ms();
                vx_vdb_tree_free(tree);
                if (t < ms) ms = t, cms = c, fms = now_ms() - f0;
                if (t > worst) worst = t;
                bytes = file_bytes(path);
                unlink(path);
            }
            if (rc) {
                printf("| %s | %s | %.1f | %s | failed: %s | | | | | |\n", base, grid, best,
                       ws[w].name, err.message);
                continue;
            }
            char freed[32] = "";
            if (ws[w].vdb) snprintf(freed, sizeof freed, "%.1f", fms);
            printf("| %s | %s | %.1f | %s | %.1f (worst %.1f) | %.2f | %.1f | %lld | %.0f | %s |\n",
                   base, grid, best, ws[w].name, ms, worst, ms / best, cms, bytes,
                   bytes / 1e6 / (ms / 1e3), freed);
            fflush(stdout);
        }
        uint64_t raw8 = (uint64_t)n[0] * n[1] * n[2];
        if (no_disk) {
            vx_bitgrid_free(&g);
            continue;
        }
        snprintf(path, sizeof path, "%s/disk.out", dir);
        printf("| %s | %s | | disk: %llu bytes of zeros | page cache %.0f MB/s | with fsync %.0f "
               "MB/s | | | | |\n",
               base, grid, (unsigned long long)raw8, disk_mbs(path, raw8, 0),
               disk_mbs(path, raw8, 1));
        vx_bitgrid_free(&g);
    }
    vx_gl_free(gl);
    vx_mesh_free(m);
    return 0;
}
