/* Brick-exact crossings: texture buffers and draws for
 * shaders/voxel_xing.glsl (xing.h). */
#include "voxel/xing.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

uint64_t vx_xing_bytes(const vx_mesh *m)
{
    return (uint64_t)m->nverts * 24u;
}

int vx_xing_init(vx_xing *x, vx_gl *gl, const vx_mesh *m, const vx_grid *g, vx_err *err)
{
    memset(x, 0, sizeof *x);
    GLint max = 0;
    glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &max);
    /* 3 RG32UI texels (doubles) a vertex, 1 RGB32UI texel a triangle */
    if ((uint64_t)m->nverts * 3 > (uint64_t)max || (uint64_t)m->ntris > (uint64_t)max)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_large",
                          "the mesh has %zu vertices and %zu triangles; this GPU's texture "
                          "buffers hold %d vertices and %d triangles",
                          m->nverts, m->ntris, (int)(max / 3), (int)max);
    for (int a = 0; a < 3; a++)
        x->index[a] = (double)g->index[a];
    glCreateBuffers(1, &x->pos_buf);
    glNamedBufferStorage(x->pos_buf, (GLsizeiptr)(vx_xing_bytes(m) + 24), NULL,
                         GL_DYNAMIC_STORAGE_BIT);
    enum { CHUNK = 65536 };
    double *tmp = malloc(CHUNK * 3 * sizeof *tmp);
    if (!tmp) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for positions");
    for (size_t i0 = 0; i0 < m->nverts; i0 += CHUNK) {
        size_t n = m->nverts - i0 < CHUNK ? m->nverts - i0 : CHUNK;
        /* the lattice's units: the same numbers in every brick */
        for (size_t k = 0; k < 3 * n; k++)
            tmp[k] = (m->pos[3 * i0 + k] - g->origin[k % 3]) / g->h;
        glNamedBufferSubData(x->pos_buf, (GLintptr)(i0 * 24), (GLsizeiptr)(n * 24), tmp);
    }
    free(tmp);
    glCreateTextures(GL_TEXTURE_BUFFER, 1, &x->pos_tex);
    glTextureBuffer(x->pos_tex, GL_RG32UI, x->pos_buf);
    glCreateTextures(GL_TEXTURE_BUFFER, 1, &x->tri_tex);
    return vx_gl_check(gl, "xing.positions", err);
}

void vx_xing_bind(vx_xing *x, GLuint prog, GLuint ibo)
{
    if (x->tri_buf != ibo) {
        glTextureBuffer(x->tri_tex, GL_RGB32UI, ibo);
        x->tri_buf = ibo;
    }
    glProgramUniform3d(prog, 14, x->index[0], x->index[1], x->index[2]);
    glBindTextureUnit(6, x->pos_tex);
    glBindTextureUnit(7, x->tri_tex);
}

void vx_xing_unbind(void)
{
    glBindTextureUnit(6, 0);
    glBindTextureUnit(7, 0);
}

void vx_xing_free(vx_xing *x)
{
    GLuint t[2] = {x->pos_tex, x->tri_tex};
    glDeleteTextures(2, t);
    glDeleteBuffers(1, &x->pos_buf);
    memset(x, 0, sizeof *x);
}

void vx_xing_draw(GLuint prog, size_t first, size_t n)
{
    /* glDrawElements counts in GLsizei, u_xing_base is an int: split
     * beyond 2^28 triangles. */
    const size_t step = (size_t)1 << 28;
    for (size_t t = 0; t < n; t += step) {
        size_t count = n - t < step ? n - t : step;
        glProgramUniform1i(prog, 15, (GLint)(first + t));
        glDrawElements(GL_TRIANGLES, (GLsizei)(3 * count), GL_UNSIGNED_INT,
                       (const void *)(uintptr_t)((first + t) * 3 * sizeof(uint32_t)));
    }
}

int vx_xing_pow2(int n)
{
    int p = 1;
    while (p < n)
        p *= 2;
    return p;
}

/* One axis of vx_xing_viewport: origin and size in window pixels. */
static void view_axis(int n, int off, int ss, double lo, double hi, int maxdim, double bound,
                      int *origin, int *size)
{
    *origin = 0;
    *size = vx_xing_pow2(n);
    if (!(lo <= hi)) return; /* no vertices */
    /* the vertices' window range, a pixel wider (positions are exact) */
    double a = floor((lo - off) * ss) - 1, b = ceil((hi - off) * ss) + 1;
    if (a > 0) a = 0;
    if (b < n) b = n;
    if (a < -bound || b - a > maxdim) return;
    *origin = (int)a;
    *size = vx_xing_pow2((int)(b - a));
    if (*size > maxdim) *origin = 0, *size = vx_xing_pow2(n);
}

void vx_xing_viewport(int w, int h, const int off[2], int ss, const double lo[2],
                      const double hi[2], float ndc[4])
{
    GLint dims[2] = {0, 0};
    GLfloat range[2] = {0, 0};
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, dims);
    glGetFloatv(GL_VIEWPORT_BOUNDS_RANGE, range);
    const double bound = fmin(-(double)range[0], (double)range[1]);
    int o[2], sz[2];
    view_axis(w, off[0], ss, lo[0], hi[0], dims[0], bound, &o[0], &sz[0]);
    view_axis(h, off[1], ss, lo[1], hi[1], dims[1], bound, &o[1], &sz[1]);
    glViewport(o[0], o[1], sz[0], sz[1]);
    /* window = (NDC + 1) size / 2 + origin = (p - off) ss: exact in float,
     * the scale a power of two and NDC within [-1, 1] */
    for (int a = 0; a < 2; a++) {
        ndc[2 * a] = (float)(2.0 * ss / sz[a]);
        ndc[2 * a + 1] = (float)(-1.0 - 2.0 * ((double)off[a] * ss + o[a]) / sz[a]);
    }
}
