/* GPU tessellation of a Gregory patch set (tess.h): shaders/
 * gregory_tess.comp.glsl evaluates every grid vertex in one compute pass. */
#include <stdlib.h>

#include "gregory/tess.h"

/* llvmpipe's SSBO limit (ARCHITECTURE.md); the driver's own value when lower. */
#define SSBO_CAP ((uint64_t)128 << 20)

/* Floats per patch in the shader's buffer: 20 points relative to the
 * first, the first relative to the origin, a pad. */
#define CP_FLOATS 64
/* The shader's local size. */
#define GROUP 64

typedef struct chunk {
    size_t p0, p1;    /* patches [p0, p1) */
    GLuint buf[3];    /* control points, info, output */
    uint64_t v0, nv;  /* grid vertices */
} chunk;

int vx_gregory_tessellate(vx_gl *gl, const vx_gpatch_set *s, const vx_gtess_layout *l,
                          const double origin[3], float *grid, double *gpu_ms, vx_err *err)
{
    *gpu_ms = 0;
    if (s->npatches == 0) return 0;
    GLuint prog = vx_gl_compute_program(gl, "gregory_tess.comp", err);
    if (!prog) return -1;
    uint64_t cap = SSBO_CAP;
    const vx_gl_info *info = vx_gl_get_info(gl);
    if (info->max_ssbo_bytes > 0 && (uint64_t)info->max_ssbo_bytes < cap)
        cap = (uint64_t)info->max_ssbo_bytes;
    const uint64_t vbytes = 6 * sizeof(float);

    /* Chunks: outputs under cap (and at most 65535 patches, which keeps the
     * patch search short). */
    size_t nchunks = 0, cap_chunks = 16;
    chunk *ch = calloc(cap_chunks, sizeof *ch);
    if (!ch) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for chunks");
    for (size_t p = 0; p < s->npatches;) {
        size_t q = p;
        while (q < s->npatches && q - p < 65535 &&
               (l->voff[q + 1] - l->voff[p]) * vbytes <= cap)
            q++;
        if (nchunks == cap_chunks) {
            chunk *n = realloc(ch, 2 * cap_chunks * sizeof *ch);
            if (!n) {
                free(ch);
                return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for chunks");
            }
            ch = n;
            cap_chunks *= 2;
        }
        ch[nchunks++] = (chunk){.p0 = p, .p1 = q, .v0 = l->voff[p], .nv = l->voff[q] - l->voff[p]};
        p = q;
    }

    int rc = -1;
    float *cpf = NULL;
    uint32_t *inf = NULL;
    size_t maxp = 0;
    for (size_t c = 0; c < nchunks; c++)
        if (ch[c].p1 - ch[c].p0 > maxp) maxp = ch[c].p1 - ch[c].p0;
    cpf = malloc(maxp * CP_FLOATS * sizeof *cpf);
    inf = malloc(maxp * 4 * sizeof *inf);
    if (!cpf || !inf) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patch upload");
        goto done;
    }
    glUseProgram(prog);
    for (size_t c = 0; c < nchunks; c++) {
        chunk *k = &ch[c];
        size_t np = k->p1 - k->p0;
        uint32_t rows = 0;
        for (size_t i = 0; i < np; i++) {
            size_t p = k->p0 + i;
            const double *src = s->cp + p * VX_GPATCH_POINTS * 3;
            float *dst = cpf + i * CP_FLOATS;
            for (int j = 0; j < VX_GPATCH_POINTS; j++)
                for (int a = 0; a < 3; a++)
                    dst[3 * j + a] = (float)(src[3 * j + a] - src[a]);
            for (int a = 0; a < 3; a++)
                dst[60 + a] = (float)(src[a] - origin[a]);
            dst[63] = 0;
            inf[4 * i] = l->ndiv[p];
            inf[4 * i + 1] = rows;
            inf[4 * i + 2] = (uint32_t)(l->voff[p] - k->v0);
            inf[4 * i + 3] = 0;
            rows += l->ndiv[p] + 1;
        }
        glCreateBuffers(3, k->buf);
        glNamedBufferStorage(k->buf[0], (GLsizeiptr)(np * CP_FLOATS * sizeof *cpf), cpf, 0);
        glNamedBufferStorage(k->buf[1], (GLsizeiptr)(np * 4 * sizeof *inf), inf, 0);
        glNamedBufferStorage(k->buf[2], (GLsizeiptr)(k->nv * vbytes), NULL, 0);
        if (vx_gl_check(gl, "gregory.buffers", err)) goto done;
    }
    /* Every buffer is made and filled first: the timer sees the pass only. */
    glFinish();
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    for (size_t c = 0; c < nchunks; c++) {
        chunk *k = &ch[c];
        size_t np = k->p1 - k->p0;
        uint32_t rows = 0;
        for (size_t p = k->p0; p < k->p1; p++)
            rows += l->ndiv[p] + 1;
        for (GLuint b = 0; b < 3; b++)
            glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, k->buf[b]);
        uint32_t same = l->ndiv[k->p0];
        for (size_t i = k->p0; i < k->p1 && same; i++)
            if (l->ndiv[i] != same) same = 0;
        glUniform1ui(0, rows);
        glUniform1ui(1, (GLuint)np);
        glUniform1ui(2, same);
        uint64_t groups = (rows + GROUP - 1) / GROUP;
        uint64_t gx = groups < 65535 ? groups : 65535, gy = (groups + gx - 1) / gx;
        glDispatchCompute((GLuint)gx, (GLuint)gy, 1);
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    *gpu_ms = vx_gl_timer_end_compute_ms(&t);
    if (vx_gl_check(gl, "gregory.dispatch", err)) goto done;
    for (size_t c = 0; c < nchunks; c++)
        glGetNamedBufferSubData(ch[c].buf[2], 0, (GLsizeiptr)(ch[c].nv * vbytes),
                                grid + 6 * ch[c].v0);
    if (vx_gl_check(gl, "gregory.readback", err)) goto done;
    rc = 0;
done:
    for (size_t c = 0; c < nchunks; c++)
        glDeleteBuffers(3, ch[c].buf);
    free(ch);
    free(cpf);
    free(inf);
    return rc;
}
