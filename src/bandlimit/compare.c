/* The older normal estimators seed 002 §2 compares against (its figure of
 * stripes): they work on the same band-limited voxels as the spectral
 * method, but only through neighbouring values — the voxel grid's
 * central differences (interpolated trilinearly: Phong-style) and 3-D
 * Sobel operator, or the screen-space neighbours of each hit (cross mask
 * and 2-D Sobel on the depth/position buffer), or depth alone. Also the
 * small bitmap font that labels the comparison panels. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "bandlimit/bandlimit.h"
#include "util/stop.h"
#include "util/vec3.h"

const char *const vx_bl_normals_names[VX_BL_NORMALS_COUNT + 1] = {
    "spectral", "depth-only", "central-difference", "cross-mask", "sobel2d", "sobel3d", NULL};

static inline size_t wrap_idx(int x, int y, int z, int M)
{
    x = (x + M) % M;
    y = (y + M) % M;
    z = (z + M) % M;
    return ((size_t)z * M + y) * M + x;
}

int vx_bl_voxel_gradient(vx_bl_volume *v, vx_bl_normals method, vx_err *err)
{
    const int M = v->M;
    size_t m3 = (size_t)M * M * M;
    for (int a = 0; a < 3; a++) {
        free(v->g[a]);
        v->g[a] = malloc(sizeof(float) * m3);
    }
    if (!v->g[0] || !v->g[1] || !v->g[2])
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for voxel gradients");
    static const int sm[3] = {1, 2, 1};
    for (int z = 0; z < M; z++) {
        if (vx_stop_poll(err)) return -1;
        for (int y = 0; y < M; y++)
            for (int x = 0; x < M; x++) {
                size_t i = ((size_t)z * M + y) * M + x;
                const int p[3] = {x, y, z};
                for (int a = 0; a < 3; a++) {
                    double s = 0;
                    int b = (a + 1) % 3, c = (a + 2) % 3;
                    if (method == VX_BL_SOBEL3D) {
                        for (int db = -1; db <= 1; db++)
                            for (int dc = -1; dc <= 1; dc++) {
                                int q1[3], q0[3];
                                for (int e = 0; e < 3; e++)
                                    q1[e] = q0[e] = p[e];
                                q1[a] += 1;
                                q0[a] -= 1;
                                q1[b] += db;
                                q0[b] += db;
                                q1[c] += dc;
                                q0[c] += dc;
                                double w = sm[db + 1] * sm[dc + 1];
                                s += w * (v->f[wrap_idx(q1[0], q1[1], q1[2], M)] -
                                          v->f[wrap_idx(q0[0], q0[1], q0[2], M)]);
                            }
                        s /= 16 * 2 * v->h;
                    } else {
                        int q1[3] = {x, y, z}, q0[3] = {x, y, z};
                        q1[a] += 1;
                        q0[a] -= 1;
                        s = (v->f[wrap_idx(q1[0], q1[1], q1[2], M)] -
                             v->f[wrap_idx(q0[0], q0[1], q0[2], M)]) /
                            (2 * v->h);
                    }
                    v->g[a][i] = (float)s;
                }
            }
    }
    return 0;
}

/* Position of pixel (x, y), or of the centre pixel c when it missed or is
 * outside the image. */
static void pos_or(const vx_bl_hits *h, int x, int y, size_t c, double p[3])
{
    size_t i = c;
    if (x >= 0 && y >= 0 && x < h->width && y < h->height) {
        size_t j = (size_t)y * h->width + x;
        if (!isnan(h->depth[j])) i = j;
    }
    for (int a = 0; a < 3; a++)
        p[a] = h->pos[3 * i + a];
}

void vx_bl_screen_normals(vx_bl_hits *h, const vx_bl_camera *cam, vx_bl_normals method)
{
    for (int y = 0; y < h->height; y++)
        for (int x = 0; x < h->width; x++) {
            size_t i = (size_t)y * h->width + x;
            float *n = h->nrm + 3 * i;
            if (isnan(h->depth[i])) continue;
            double tx[3] = {0, 0, 0}, ty[3] = {0, 0, 0}, p1[3], p0[3];
            if (method == VX_BL_DEPTH_ONLY) {
                for (int a = 0; a < 3; a++)
                    n[a] = (float)-cam->fwd[a];
                continue;
            }
            int r0 = method == VX_BL_SOBEL2D ? -1 : 0, r1 = -r0;
            for (int o = r0; o <= r1; o++) {
                double w = o == 0 ? 2 : 1;
                pos_or(h, x + 1, y + o, i, p1);
                pos_or(h, x - 1, y + o, i, p0);
                for (int a = 0; a < 3; a++)
                    tx[a] += w * (p1[a] - p0[a]);
                pos_or(h, x + o, y - 1, i, p1); /* y - 1 is up */
                pos_or(h, x + o, y + 1, i, p0);
                for (int a = 0; a < 3; a++)
                    ty[a] += w * (p1[a] - p0[a]);
            }
            double c[3];
            vx_v3_cross(tx, ty, c);
            double len = vx_v3_norm(c);
            if (!(len > 0)) {
                for (int a = 0; a < 3; a++)
                    n[a] = (float)-cam->fwd[a];
                continue;
            }
            double s = vx_v3_dot(c, cam->fwd) > 0 ? -1 : 1;
            for (int a = 0; a < 3; a++)
                n[a] = (float)(s * c[a] / len);
        }
}

/* 5x7 glyphs of the characters the panel labels use. */
static const struct glyph {
    char c;
    const char *rows[7];
} font[] = {
    {'a', {".....", ".....", ".###.", "....#", ".####", "#...#", ".####"}},
    {'b', {"#....", "#....", "####.", "#...#", "#...#", "#...#", "####."}},
    {'c', {".....", ".....", ".####", "#....", "#....", "#....", ".####"}},
    {'d', {"....#", "....#", ".####", "#...#", "#...#", "#...#", ".####"}},
    {'e', {".....", ".....", ".###.", "#...#", "#####", "#....", ".###."}},
    {'f', {"..##.", ".#...", "####.", ".#...", ".#...", ".#...", ".#..."}},
    {'h', {"#....", "#....", "####.", "#...#", "#...#", "#...#", "#...#"}},
    {'i', {"..#..", ".....", ".##..", "..#..", "..#..", "..#..", ".###."}},
    {'k', {"#....", "#....", "#..#.", "#.#..", "##...", "#.#..", "#..#."}},
    {'l', {".##..", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'m', {".....", ".....", "##.#.", "#.#.#", "#.#.#", "#.#.#", "#.#.#"}},
    {'n', {".....", ".....", "####.", "#...#", "#...#", "#...#", "#...#"}},
    {'o', {".....", ".....", ".###.", "#...#", "#...#", "#...#", ".###."}},
    {'p', {".....", "####.", "#...#", "#...#", "####.", "#....", "#...."}},
    {'r', {".....", ".....", "#.##.", "##..#", "#....", "#....", "#...."}},
    {'s', {".....", ".....", ".####", "#....", ".###.", "....#", "####."}},
    {'t', {".#...", ".#...", "####.", ".#...", ".#...", ".#..#", "..##."}},
    {'y', {".....", "#...#", "#...#", "#...#", ".####", "....#", ".###."}},
    {'2', {".###.", "#...#", "....#", "...#.", "..#..", ".#...", "#####"}},
    {'3', {".###.", "#...#", "....#", "..##.", "....#", "#...#", ".###."}},
    {'-', {".....", ".....", ".....", "#####", ".....", ".....", "....."}},
};

void vx_bl_label(float *rgb, int w, int h, int x, int y, int s, const char *text, const float c[3])
{
    for (; *text; text++, x += 6 * s) {
        const struct glyph *g = NULL;
        for (size_t k = 0; k < sizeof font / sizeof font[0]; k++)
            if (font[k].c == *text) g = &font[k];
        if (!g) continue;
        for (int r = 0; r < 7; r++)
            for (int q = 0; q < 5; q++) {
                if (g->rows[r][q] != '#') continue;
                for (int dy = 0; dy < s; dy++)
                    for (int dx = 0; dx < s; dx++) {
                        int px = x + q * s + dx, py = y + r * s + dy;
                        if (px < 0 || py < 0 || px >= w || py >= h) continue;
                        for (int a = 0; a < 3; a++)
                            rgb[3 * ((size_t)py * w + px) + a] = c[a];
                    }
            }
    }
}
