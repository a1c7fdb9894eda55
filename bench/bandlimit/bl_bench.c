/* bl_bench: the band-limit module against its peers, in one run.
 *
 *   bl_bench lowpass MESH R N [--runs K]
 *       The mesh's solid at R^3 from the voxel engine (GPU), then the
 *       filtered N^3 spectrum two ways on the same bit grid: Algorithm I
 *       (slab by slab, partial transforms) and one full R^3 FFT (the peer).
 *       Each runs in a forked child so that its peak resident memory
 *       (VmHWM growth) is its own; prints times, peaks and ratios, and
 *       checks that both spectra agree.
 *   bl_bench render MESH N L WIDTH [--runs K]
 *       Algorithm I at R = 8N, interpolation to M = L N, then WIDTH^2
 *       renders from an orbit camera (perspective): spectral vs the same
 *       caster with central-difference normals on the N voxels.
 * Timings are the best of K runs. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#include "bandlimit/bandlimit.h"
#include "bandlimit/fft_int.h"
#include "gl/gl.h"
#include "util/clock.h"
#include "voxel/voxel.h"

static long status_kb(const char *key)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    long kb = -1;
    size_t n = strlen(key);
    while (f && fgets(line, sizeof line, f))
        if (strncmp(line, key, n) == 0) kb = atol(line + n + 1);
    if (f) fclose(f);
    return kb;
}

static void die(const char *what, const vx_err *e)
{
    fprintf(stderr, "%s: %s: %s\n", what, e->code, e->message);
    exit(1);
}

/* The solid of m in the cube around its bbox padded by 20% (as render). */
static void solid(const char *path, int R, vx_bitgrid *g, double *P, double *ms)
{
    vx_err err = {0};
    vx_mesh *m = vx_mesh_read_path(path, NULL, &err);
    if (!m) die(path, &err);
    vx_gl_desc gd = {0};
    vx_gl *gl = vx_gl_new(&gd, &err);
    if (!gl) die("gl", &err);
    double ext = 0;
    for (int a = 0; a < 3; a++)
        ext = fmax(ext, m->bbox_max[a] - m->bbox_min[a]);
    *P = ext * 1.4;
    vx_voxelize_desc d = {0};
    for (int a = 0; a < 3; a++) {
        d.grid.origin[a] = 0.5 * (m->bbox_min[a] + m->bbox_max[a]) - *P / 2;
        d.grid.dims[a] = R;
    }
    d.grid.h = *P / R;
    vx_voxelize_stats st;
    double t0 = vx_mono_ms();
    if (vx_voxelize(gl, m, &d, g, &st, &err)) die("voxelize", &err);
    *ms = vx_mono_ms() - t0;
    vx_gl_free(gl);
    vx_mesh_free(m);
}

typedef struct result {
    double ms, sample_ms;
    long peak_kb;
    double checksum[4];
} result;

/* Runs one low-pass in a child; its result through a pipe. */
static result run_child(int full, const vx_bitgrid *g, int R, int N)
{
    int fd[2];
    result res = {0};
    if (pipe(fd)) exit(1);
    pid_t pid = fork();
    if (pid == 0) {
        close(fd[0]);
        long base = status_kb("VmRSS:");
        vx_bl_bits bits = {g, 1, NULL, NULL};
        vx_bl_filter flt = {N / 4.0, 2};
        vx_bl_lowpass_stats st;
        vx_err err = {0};
        float *s = (full ? vx_bl_lowpass_full : vx_bl_lowpass)(R, N, &flt, vx_bl_sample_bits, &bits,
                                                               2, &st, &err);
        if (!s) die("lowpass", &err);
        result r = {st.ms, st.sample_ms, status_kb("VmHWM:") - base, {0}};
        /* a few coefficients to compare the two */
        size_t len = vx_bl_spectrum_len(N);
        size_t idx[4] = {0, 1, len / 3, len - 1};
        for (int i = 0; i < 4; i++)
            r.checksum[i] = s[2 * idx[i]];
        if (write(fd[1], &r, sizeof r) != sizeof r) _exit(1);
        _exit(0);
    }
    close(fd[1]);
    if (read(fd[0], &res, sizeof res) != sizeof res) {
        fprintf(stderr, "child failed\n");
        exit(1);
    }
    close(fd[0]);
    waitpid(pid, NULL, 0);
    return res;
}

static int lowpass(const char *mesh, int R, int N, int runs)
{
    vx_bitgrid g;
    double P, vox_ms;
    solid(mesh, R, &g, &P, &vox_ms);
    result best[2];
    for (int v = 0; v < 2; v++)
        for (int k = 0; k < runs; k++) {
            result r = run_child(v, &g, R, N);
            if (k == 0 || r.ms < best[v].ms) best[v] = r;
        }
    double maxd = 0;
    for (int i = 0; i < 4; i++)
        maxd = fmax(maxd, fabs(best[0].checksum[i] - best[1].checksum[i]));
    printf("| mesh | R | N | GPU solid ms | variant | slab sampling ms | FFT ms | peak MB |\n");
    printf("|---|---|---|---|---|---|---|---|\n");
    const char *name = strrchr(mesh, '/') ? strrchr(mesh, '/') + 1 : mesh;
    for (int v = 0; v < 2; v++)
        printf("| %s | %d | %d | %.0f | %s | %.0f | %.0f | %.1f |\n", name, R, N, vox_ms,
               v ? "full 3-D FFT (peer)" : "Algorithm I", best[v].sample_ms, best[v].ms,
               best[v].peak_kb / 1024.0);
    printf("\nratios (full / Algorithm I): FFT time %.2fx, peak memory %.1fx; "
           "max |difference| of checked coefficients %.2g\n",
           best[1].ms / best[0].ms, (double)best[1].peak_kb / best[0].peak_kb, maxd);
    printf("targets: Algorithm I FFT <= 500 ms: %s; peak <= 64 MB: %s\n",
           best[0].ms <= 500 ? "met" : "NOT met", best[0].peak_kb <= 64 * 1024 ? "met" : "NOT met");
    vx_bitgrid_free(&g);
    return 0;
}

static int render(const char *mesh, int N, int L, int W, int runs)
{
    const int R = 8 * N, M = L * N;
    vx_bitgrid g;
    double P, vox_ms;
    solid(mesh, R, &g, &P, &vox_ms);
    vx_bl_bits bits = {&g, 1, NULL, NULL};
    vx_bl_filter flt = {N / 4.0, 2};
    vx_bl_lowpass_stats lst;
    vx_err err = {0};
    float *spec = vx_bl_lowpass(R, N, &flt, vx_bl_sample_bits, &bits, 2, &lst, &err);
    if (!spec) die("lowpass", &err);
    double x0[3], c[3];
    for (int a = 0; a < 3; a++) {
        x0[a] = g.grid.origin[a] + 0.5 * g.grid.h;
        c[a] = g.grid.origin[a] + P / 2;
    }
    vx_bl_volume vm, vn;
    double t0 = vx_mono_ms();
    if (vx_bl_interp(spec, N, M, x0, P, 1, 2, &vm, &err) || vx_bl_volume_blocks(&vm, &err))
        die("interp", &err);
    double interp_ms = vx_mono_ms() - t0;
    if (vx_bl_interp(spec, N, N, x0, P, 0, 2, &vn, &err) || vx_bl_volume_blocks(&vn, &err) ||
        vx_bl_voxel_gradient(&vn, VX_BL_CENTRAL, &err))
        die("interp N", &err);
    /* orbit camera, azimuth 30, elevation 20, fov 30, fitting the box */
    vx_bl_camera cam = {.fov_deg = 30};
    double az = 30 * M_PI / 180, el = 20 * M_PI / 180,
           dir[3] = {sin(az) * cos(el), sin(el), cos(az) * cos(el)},
           dist = P / 1.4 * 0.9 / sin(M_PI / 12);
    for (int a = 0; a < 3; a++) {
        cam.fwd[a] = -dir[a];
        cam.eye[a] = c[a] + dir[a] * dist;
    }
    double up[3] = {0, 1, 0};
    cam.right[0] = cam.fwd[1] * up[2] - cam.fwd[2] * up[1];
    cam.right[1] = cam.fwd[2] * up[0] - cam.fwd[0] * up[2];
    cam.right[2] = cam.fwd[0] * up[1] - cam.fwd[1] * up[0];
    double rn = sqrt(cam.right[0] * cam.right[0] + cam.right[1] * cam.right[1] +
                     cam.right[2] * cam.right[2]);
    for (int a = 0; a < 3; a++)
        cam.right[a] /= rn;
    cam.up[0] = cam.right[1] * cam.fwd[2] - cam.right[2] * cam.fwd[1];
    cam.up[1] = cam.right[2] * cam.fwd[0] - cam.right[0] * cam.fwd[2];
    cam.up[2] = cam.right[0] * cam.fwd[1] - cam.right[1] * cam.fwd[0];
    vx_bl_hits h;
    if (vx_bl_hits_alloc(&h, W, W, &err)) die("hits", &err);
    float *rgb = malloc(sizeof(float) * 3 * W * W);
    vx_bl_light light = {{0, 0, 1}, {0.85, 0.85, 0.85}};
    for (int a = 0; a < 3; a++)
        light.dir[a] = -cam.fwd[a];
    vx_bl_shade_desc sd = {.lights = &light,
                           .nlights = 1,
                           .ambient = 0.15,
                           .color = {0.8, 0.8, 0.85},
                           .background = {1, 1, 1}};
    double best[2] = {1e30, 1e30};
    size_t hits = 0;
    for (int v = 0; v < 2; v++)
        for (int k = 0; k < runs; k++) {
            t0 = vx_mono_ms();
            if (vx_bl_cast(v ? &vn : &vm, 0.5, &cam, 2, &h, &err)) die("cast", &err);
            vx_bl_shade(&h, &sd, rgb, NULL);
            double ms = vx_mono_ms() - t0;
            if (ms < best[v]) best[v] = ms;
            if (!v) {
                hits = 0;
                for (int i = 0; i < W * W; i++)
                    hits += !isnan(h.depth[i]);
            }
        }
    const char *name = strrchr(mesh, '/') ? strrchr(mesh, '/') + 1 : mesh;
    printf("| mesh | N | M | image | interpolation ms | spectral render ms | central-difference "
           "render ms (same caster, N grid) | pixels hit |\n");
    printf("|---|---|---|---|---|---|---|---|\n");
    printf("| %s | %d | %d | %dx%d | %.0f | %.0f | %.0f | %zu |\n", name, N, M, W, W, interp_ms,
           best[0], best[1], hits);
    printf("\nspectral / central-difference render time: %.2fx; target 512x512 <= 250 ms: %s\n",
           best[0] / best[1], best[0] <= 250 ? "met" : "NOT met");
    free(rgb);
    vx_bl_hits_free(&h);
    vx_bl_volume_free(&vm);
    vx_bl_volume_free(&vn);
    vx_bl_free(spec);
    vx_bitgrid_free(&g);
    return 0;
}

int main(int argc, char **argv)
{
    int runs = 3;
    for (int i = 1; i + 1 < argc; i++)
        if (strcmp(argv[i], "--runs") == 0) {
            runs = atoi(argv[i + 1]);
            argc = i;
        }
    if (argc == 5 && strcmp(argv[1], "lowpass") == 0)
        return lowpass(argv[2], atoi(argv[3]), atoi(argv[4]), runs);
    if (argc == 6 && strcmp(argv[1], "render") == 0)
        return render(argv[2], atoi(argv[3]), atoi(argv[4]), atoi(argv[5]), runs);
    fprintf(stderr, "usage: bl_bench lowpass MESH R N | render MESH N L WIDTH [--runs K]\n");
    return 2;
}
