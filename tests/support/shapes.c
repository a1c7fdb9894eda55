/* Test meshes built in code or loaded from the shared data (shapes.h). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "shapes.h"

vx_mesh *shape_mesh_from(size_t nv, const double *pos, size_t nt, const uint32_t *idx)
{
    vx_mesh *m = vx_mesh_new();
    m->nverts = nv;
    m->pos = malloc(nv * 3 * sizeof(double));
    memcpy(m->pos, pos, nv * 3 * sizeof(double));
    m->nfaces = nt;
    m->face_idx = malloc(nt * 3 * sizeof(uint32_t));
    memcpy(m->face_idx, idx, nt * 3 * sizeof(uint32_t));
    if (vx_mesh_analyze(m, NULL) != 0) abort();
    return m;
}

/* Axis-aligned box [lo, hi] as 12 outward-facing triangles. */
vx_mesh *shape_box(const double lo[3], const double hi[3])
{
    double p[24];
    for (int v = 0; v < 8; v++)
        for (int a = 0; a < 3; a++)
            p[3 * v + a] = (v >> a) & 1 ? hi[a] : lo[a];
    static const uint32_t f[36] = {0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4,
                                   2, 6, 7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5};
    return shape_mesh_from(8, p, 12, f);
}

double shape_signed_volume(const vx_mesh *m)
{
    double v = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                     *c = m->pos + 3 * m->tri[3 * t + 2];
        v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
             a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    return v / 6;
}

void shape_flip(vx_mesh *m)
{
    for (size_t t = 0; t < m->ntris; t++) {
        uint32_t x = m->tri[3 * t + 1];
        m->tri[3 * t + 1] = m->tri[3 * t + 2];
        m->tri[3 * t + 2] = x;
    }
}

/* Closed surface from an (nu x nv) parameter grid, periodic in u; with
 * poles (sphere) v runs pole to pole, else (torus) periodic in v too.
 * Oriented outward (inward when `inward`). */
vx_mesh *shape_param_mesh(int nu, int nv, int poles, int inward, double cx, double cy, double cz,
                          double r1, double r2)
{
    size_t nvert = poles ? (size_t)nu * (nv - 1) + 2 : (size_t)nu * nv;
    double *p = malloc(nvert * 3 * sizeof *p);
    uint32_t *f = malloc((size_t)nu * nv * 6 * sizeof *f);
    size_t q = 0, t = 0;
#define VID(i, j)                                                                                  \
    (poles ? 2 + (uint32_t)(((j)-1) * nu + ((i) % nu)) : (uint32_t)(((j) % nv) * nu + ((i) % nu)))
    if (poles) {
        double s[6] = {cx, cy, cz - r1, cx, cy, cz + r1};
        memcpy(p, s, sizeof s);
        q = 2;
        for (int j = 1; j < nv; j++)
            for (int i = 0; i < nu; i++) {
                double th = M_PI * j / nv, ph = 2 * M_PI * i / nu;
                p[3 * q] = cx + r1 * sin(th) * cos(ph);
                p[3 * q + 1] = cy + r1 * sin(th) * sin(ph);
                p[3 * q + 2] = cz - r1 * cos(th);
                q++;
            }
        for (int i = 0; i < nu; i++) {
            f[t++] = 0, f[t++] = VID(i + 1, 1), f[t++] = VID(i, 1);
            f[t++] = 1, f[t++] = VID(i, nv - 1), f[t++] = VID(i + 1, nv - 1);
        }
        for (int j = 1; j < nv - 1; j++)
            for (int i = 0; i < nu; i++) {
                f[t++] = VID(i, j), f[t++] = VID(i + 1, j), f[t++] = VID(i + 1, j + 1);
                f[t++] = VID(i, j), f[t++] = VID(i + 1, j + 1), f[t++] = VID(i, j + 1);
            }
    } else {
        for (int j = 0; j < nv; j++)
            for (int i = 0; i < nu; i++) {
                double u = 2 * M_PI * i / nu, v = 2 * M_PI * j / nv;
                p[3 * q] = cx + (r1 + r2 * cos(v)) * cos(u);
                p[3 * q + 1] = cy + (r1 + r2 * cos(v)) * sin(u);
                p[3 * q + 2] = cz + r2 * sin(v);
                q++;
            }
        for (int j = 0; j < nv; j++)
            for (int i = 0; i < nu; i++) {
                f[t++] = VID(i, j), f[t++] = VID(i + 1, j), f[t++] = VID(i + 1, j + 1);
                f[t++] = VID(i, j), f[t++] = VID(i + 1, j + 1), f[t++] = VID(i, j + 1);
            }
    }
#undef VID
    vx_mesh *m = shape_mesh_from(q, p, t / 3, f);
    free(p);
    free(f);
    if (m->boundary_edges != 0) abort();
    if ((shape_signed_volume(m) < 0) != inward) shape_flip(m);
    return m;
}

vx_mesh *shape_sphere(double cx, double cy, double cz, double r, int inward)
{
    return shape_param_mesh(128, 64, 1, inward, cx, cy, cz, r, 0);
}

/* Concatenation of meshes. */
vx_mesh *shape_merge(vx_mesh **parts, int n)
{
    size_t nv = 0, nt = 0;
    for (int i = 0; i < n; i++)
        nv += parts[i]->nverts, nt += parts[i]->ntris;
    double *p = malloc(nv * 3 * sizeof *p);
    uint32_t *f = malloc(nt * 3 * sizeof *f);
    size_t v0 = 0, t0 = 0;
    for (int i = 0; i < n; i++) {
        memcpy(p + 3 * v0, parts[i]->pos, parts[i]->nverts * 3 * sizeof *p);
        for (size_t k = 0; k < 3 * parts[i]->ntris; k++)
            f[3 * t0 + k] = parts[i]->tri[k] + (uint32_t)v0;
        v0 += parts[i]->nverts;
        t0 += parts[i]->ntris;
    }
    vx_mesh *m = shape_mesh_from(nv, p, nt, f);
    free(p);
    free(f);
    return m;
}

vx_mesh *shape_poly_mesh(size_t nv, const double *pos, size_t nf, const uint32_t *sizes,
                         const uint32_t *idx)
{
    vx_mesh *m = vx_mesh_new();
    if (!m) abort();
    m->nverts = nv;
    m->pos = malloc(3 * nv * sizeof *m->pos + 1);
    m->nfaces = nf;
    m->face_start = malloc((nf + 1) * sizeof *m->face_start);
    if (!m->pos || !m->face_start) abort();
    memcpy(m->pos, pos, 3 * nv * sizeof *m->pos);
    m->face_start[0] = 0;
    for (size_t f = 0; f < nf; f++)
        m->face_start[f + 1] = m->face_start[f] + (sizes ? sizes[f] : 4);
    m->face_idx = malloc(m->face_start[nf] * sizeof *m->face_idx + 1);
    if (!m->face_idx) abort();
    memcpy(m->face_idx, idx, m->face_start[nf] * sizeof *m->face_idx);
    if (vx_mesh_analyze(m, NULL)) abort();
    return m;
}

vx_mesh *shape_load(const char *name)
{
    char path[1024];
    snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, name);
    vx_err err = {0};
    vx_mesh *m = vx_mesh_read_path(path, NULL, &err);
    if (!m) fprintf(stderr, "%s: %s: %s\n", path, err.code, err.message);
    return m;
}

void shape_bezier_eval(const vx_mesh *m, size_t p, double u, double v, double out[3])
{
    double bu[4] = {(1 - u) * (1 - u) * (1 - u), 3 * u * (1 - u) * (1 - u), 3 * u * u * (1 - u),
                    u * u * u};
    double bv[4] = {(1 - v) * (1 - v) * (1 - v), 3 * v * (1 - v) * (1 - v), 3 * v * v * (1 - v),
                    v * v * v};
    out[0] = out[1] = out[2] = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++)
            for (int c = 0; c < 3; c++)
                out[c] += bu[i] * bv[j] * m->pos[3 * m->patch_idx[16 * p + 4 * j + i] + c];
}
