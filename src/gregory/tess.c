/* Tessellation of a Gregory patch set (tess.h): shaders/
 * gregory_tess.comp.glsl evaluates every grid vertex in one compute pass,
 * or tess_cpu.c the same formulas on the CPU threads. */
#include <stdlib.h>

#include "gregory/tess_int.h"
#include "util/stop.h"

/* llvmpipe's SSBO limit (ARCHITECTURE.md); the driver's own value when lower. */
#define SSBO_CAP ((uint64_t)128 << 20)

#define CP_FLOATS VX_GTESS_CP_FLOATS
/* The shader's local size. */
#define GROUP 64
/* Bytes per output vertex: position and normal. */
#define VBYTES (6 * sizeof(float))
/* Grid vertices per chunk: one dispatch, the piece of work between two
 * polls of the stop hook (util/stop.h): ~0.05 s on a loaded llvmpipe. */
#define CHUNK_VERTS ((uint64_t)1 << 19)

typedef struct chunk {
    size_t p0, p1;   /* patches [p0, p1) */
    GLuint buf[3];   /* control points, info, output */
    uint64_t v0, nv; /* grid vertices */
} chunk;

struct vx_gtess {
    int cpu; /* the CPU engine: no GL objects */
    vx_gl *gl;
    const vx_gtess_layout *l;
    GLuint prog;
    size_t nchunks, maxp;
    chunk *ch;
    uint32_t *rows, *same; /* per chunk: grid rows, common N (0: mixed) */
    float *cpf;            /* upload staging, maxp patches */
};

void vx_gtess_free(vx_gtess *t)
{
    if (!t) return;
    for (size_t c = 0; c < t->nchunks; c++)
        glDeleteBuffers(3, t->ch[c].buf);
    free(t->ch);
    free(t->rows);
    free(t->same);
    free(t->cpf);
    free(t);
}

static vx_gtess *oom_free(vx_gtess *t, vx_err *err)
{
    vx_gtess_free(t);
    vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the tessellator");
    return NULL;
}

void vx_gtess_pack(const vx_gpatch_set *s, size_t p, const double origin[3], float *f)
{
    const double *src = s->cp + p * VX_GPATCH_POINTS * 3;
    for (int j = 0; j < VX_GPATCH_POINTS; j++)
        for (int a = 0; a < 3; a++)
            f[3 * j + a] = (float)(src[3 * j + a] - src[a]);
    for (int a = 0; a < 3; a++)
        f[60 + a] = (float)(src[a] - origin[a]);
    f[63] = 0;
}

vx_gtess *vx_gtess_new(vx_gl *gl, const vx_gtess_layout *l, vx_err *err)
{
    return vx_gtess_new_on(gl, l, VX_GTESS_AUTO, err);
}

const char *vx_gtess_engine_name(const vx_gtess *t)
{
    return t->cpu ? "cpu" : "gpu";
}

vx_gtess *vx_gtess_new_on(vx_gl *gl, const vx_gtess_layout *l, vx_gtess_engine engine, vx_err *err)
{
    vx_gtess *t = calloc(1, sizeof *t);
    if (!t) return oom_free(t, err);
    t->gl = gl;
    t->l = l;
    t->cpu = engine == VX_GTESS_CPU ||
             (engine == VX_GTESS_AUTO && (!gl || vx_gl_info_software(vx_gl_get_info(gl))));
    if (t->cpu) return t;
    t->prog = vx_gl_compute_program(gl, "gregory_tess.comp", err);
    if (!t->prog) {
        vx_gtess_free(t);
        return NULL;
    }
    uint64_t cap = SSBO_CAP;
    const vx_gl_info *info = vx_gl_get_info(gl);
    if (info->max_ssbo_bytes > 0 && (uint64_t)info->max_ssbo_bytes < cap)
        cap = (uint64_t)info->max_ssbo_bytes;
    /* Chunks: outputs under cap (and at most 65535 patches, which keeps the
     * patch search short). */
    size_t cap_chunks = 16;
    t->ch = calloc(cap_chunks, sizeof *t->ch);
    if (!t->ch) return oom_free(t, err);
    for (size_t p = 0; p < l->npatches;) {
        size_t q = p;
        while (q < l->npatches && q - p < 65535 && (l->voff[q + 1] - l->voff[p]) * VBYTES <= cap &&
               l->voff[q + 1] - l->voff[p] <= CHUNK_VERTS)
            q++;
        if (q == p) q = p + 1; /* one patch is at most 257^2 vertices: far under any cap */
        if (t->nchunks == cap_chunks) {
            chunk *n = realloc(t->ch, 2 * cap_chunks * sizeof *t->ch);
            if (!n) return oom_free(t, err);
            t->ch = n;
            cap_chunks *= 2;
        }
        t->ch[t->nchunks++] =
            (chunk){.p0 = p, .p1 = q, .v0 = l->voff[p], .nv = l->voff[q] - l->voff[p]};
        if (q - p > t->maxp) t->maxp = q - p;
        p = q;
    }
    t->rows = calloc(t->nchunks + 1, sizeof *t->rows);
    t->same = calloc(t->nchunks + 1, sizeof *t->same);
    t->cpf = malloc((t->maxp * CP_FLOATS + 1) * sizeof *t->cpf);
    uint32_t *inf = malloc((t->maxp * 4 + 1) * sizeof *inf);
    if (!t->rows || !t->same || !t->cpf || !inf) {
        free(inf);
        return oom_free(t, err);
    }
    /* Buffers made once: per-patch info (N, first row, first vertex), the
     * control points (rewritten every run), the output. */
    for (size_t c = 0; c < t->nchunks; c++) {
        chunk *k = &t->ch[c];
        size_t np = k->p1 - k->p0;
        uint32_t rows = 0, same = l->ndiv[k->p0];
        for (size_t i = 0; i < np; i++) {
            size_t p = k->p0 + i;
            inf[4 * i] = l->ndiv[p];
            inf[4 * i + 1] = rows;
            inf[4 * i + 2] = (uint32_t)(l->voff[p] - k->v0);
            inf[4 * i + 3] = 0;
            rows += l->ndiv[p] + 1;
            if (l->ndiv[p] != same) same = 0;
        }
        t->rows[c] = rows;
        t->same[c] = same;
        if (vx_stop_poll(err)) {
            free(inf);
            vx_gtess_free(t);
            return NULL;
        }
        glCreateBuffers(3, k->buf);
        glNamedBufferStorage(k->buf[0], (GLsizeiptr)(np * CP_FLOATS * sizeof(float)), NULL,
                             GL_DYNAMIC_STORAGE_BIT);
        glNamedBufferStorage(k->buf[1], (GLsizeiptr)(np * 4 * sizeof *inf), inf, 0);
        glNamedBufferStorage(k->buf[2], (GLsizeiptr)(k->nv * VBYTES), NULL, 0);
    }
    free(inf);
    if (vx_gl_check(gl, "gregory.buffers", err)) {
        vx_gtess_free(t);
        return NULL;
    }
    return t;
}

int vx_gtess_run(vx_gtess *t, const vx_gpatch_set *s, const double origin[3], float *grid,
                 double *gpu_ms, vx_err *err)
{
    *gpu_ms = 0;
    if (s->npatches != t->l->npatches)
        return vx_err_set(err, VX_EINTERNAL, "gregory_layout", "%zu patches for a layout of %zu",
                          s->npatches, t->l->npatches);
    if (t->cpu) return vx_gtess_cpu_run(t->l, s, origin, grid, 0, gpu_ms, err);
    for (size_t c = 0; c < t->nchunks; c++) {
        chunk *k = &t->ch[c];
        size_t np = k->p1 - k->p0;
        for (size_t i = 0; i < np; i++)
            vx_gtess_pack(s, k->p0 + i, origin, t->cpf + i * CP_FLOATS);
        glNamedBufferSubData(k->buf[0], 0, (GLsizeiptr)(np * CP_FLOATS * sizeof(float)), t->cpf);
        if (vx_stop_poll(err)) return -1;
    }
    if (vx_gl_check(t->gl, "gregory.upload", err)) return -1;
    /* The timer sees the pass only (the buffers are made and filled). */
    glFinish();
    glUseProgram(t->prog);
    vx_gl_timer tm;
    vx_gl_timer_begin(&tm);
    for (size_t c = 0; c < t->nchunks; c++) {
        chunk *k = &t->ch[c];
        if (c > 0) { /* a stop waits for the dispatch in flight only */
            glFinish();
            if (vx_stop_poll(err)) {
                vx_gl_timer_end_ms(&tm);
                glUseProgram(0);
                return -1;
            }
        }
        for (GLuint b = 0; b < 3; b++)
            glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, k->buf[b]);
        glUniform1ui(0, t->rows[c]);
        glUniform1ui(1, (GLuint)(k->p1 - k->p0));
        glUniform1ui(2, t->same[c]);
        uint64_t groups = (t->rows[c] + GROUP - 1) / GROUP;
        uint64_t gx = groups < 65535 ? groups : 65535, gy = (groups + gx - 1) / gx;
        glDispatchCompute((GLuint)gx, (GLuint)gy, 1);
    }
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    *gpu_ms = vx_gl_timer_end_compute_ms(&tm);
    if (vx_gl_check(t->gl, "gregory.dispatch", err)) return -1;
    for (size_t c = 0; c < t->nchunks; c++) {
        if (vx_stop_poll(err)) return -1;
        glGetNamedBufferSubData(t->ch[c].buf[2], 0, (GLsizeiptr)(t->ch[c].nv * VBYTES),
                                grid + 6 * t->ch[c].v0);
    }
    return vx_gl_check(t->gl, "gregory.readback", err);
}

int vx_gregory_tessellate(vx_gl *gl, const vx_gpatch_set *s, const vx_gtess_layout *l,
                          const double origin[3], float *grid, double *gpu_ms, vx_err *err)
{
    *gpu_ms = 0;
    if (s->npatches == 0) return 0;
    vx_gtess *t = vx_gtess_new(gl, l, err);
    if (!t) return -1;
    int rc = vx_gtess_run(t, s, origin, grid, gpu_ms, err);
    vx_gtess_free(t);
    return rc;
}
