/* Solid voxelization by depth peeling (seed 000, Harada & Koshizuka), and
 * the conservative surface fill, on the GL thread (voxel.h).
 *
 * Pipeline per slab of z rows (rows k0..k0+rows-1):
 *   1. peel (seed 000 §2.1): the mesh, in grid units, is drawn orthographically
 *      along the ray axis into an image whose pixel centres are the voxel
 *      centres, until an occlusion query says no sample passed. The seed
 *      keeps one layer per pass (the nearest crossing beyond the last one,
 *      by a depth test); here a pass keeps the next k layers per pixel in an
 *      R32UI array, sorted by an atomic-min cascade over k slots
 *      (voxel_peel.frag.glsl), and only a crossing that finds all k slots
 *      taken passes the query. k is 16 in the first pass and then the
 *      number of slots so far (16, 16, 32, ...): llvmpipe pays a whole
 *      vertex pass per pass, and one grazing ray can need 40 layers where
 *      the rest of the mesh needs 10 (fandisk at 256^3). A layer's key is
 *      the first voxel centre beyond the crossing, then where it lies
 *      between centres, then its facing (voxel_peel.frag.glsl); coincident
 *      crossings (the same key twice) are flagged, and then one more pass
 *      counts every key's fragments into a second R32UI array, so faces
 *      that coincide along a ray are all counted.
 *   2. fill (seed 000 §2.2): a compute shader walks each pixel's layers and
 *      writes the bits straight into an SSBO in the voxel.h layout (x rays:
 *      whole 32-bit words per invocation, no atomics). No GPU->CPU transfer
 *      happens between the two stages, as in the seed.
 *   3. the slab's words are read back into out->bits.
 * The seed stored one voxel per colour channel, so 256^3 was its limit
 * (§3); here a voxel is one bit (the encoding the seed names as the way to
 * higher resolutions) and the grid is cut into slabs so that each SSBO
 * binding stays under GL_MAX_SHADER_STORAGE_BLOCK_SIZE (128 MiB on
 * llvmpipe) and the layer arrays stay within texture limits and memory.
 *
 * Inside rules: nonzero (signed crossings), parity (the seed's entry/exit
 * pairing), robust (majority of parity along x, y and z; see below).
 *
 * Robust mode and where it fails: a hole in an open mesh spoils the parity
 * of the rays that pass through it, along one axis at a time (crossings are
 * counted from the centre towards +ray, as the reference does). A voxel is
 * still right when the rays along the other two axes are clean. It fails
 * where the rays along two of the three axes through a voxel meet holes: a
 * box-like part missing two faces with different normals (top and +x side:
 * inside it, the z and the x rays both miss their exit, so 2 of 3 say
 * outside); a large missing region that rays of two axes pass through (a
 * sphere with a big cap cut off at 45 degrees to two axes); several
 * overlapping open shells. Self-intersecting meshes make parity differ from
 * the intended union along every axis (use nonzero for those).
 *
 * With several slabs, x and y rays draw only the triangles that reach the
 * slab (slab_buckets); z rays (robust) cross every slab: they are peeled
 * once over the whole grid and their layers kept for the fill of each
 * slab.
 *
 * Crossings are decided by xing() (shaders/voxel_xing.glsl, xing.h) from
 * the lattice's own numbers: every brick and slab height of a lattice
 * gives the same voxels, bit for bit, and scan (the same x rays) agrees.
 *
 * Known limits: parts thinner than the voxel spacing between two centres
 * vanish (seed 000 §3; use fill=surface to catch them). */
#include <limits.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "util/clock.h"
#include "util/log.h"
#include "util/vec3.h"
#include "voxel/peel_int.h"
#include "voxel/voxel.h"

#define PEEL_EMPTY 0xffffffffu    /* cleared key slot: no crossing there */
#define PEEL_PIXEL_CAP (4u << 20) /* pixels per peel image: bounds one layer to 32 MiB */
#define PEEL_FIRST_CAP 16         /* layer slots of the first pass (allocated up front) */
#define SURF_GPU_WORK 16384       /* voxel tests one GPU invocation may take */
#define SURF_MARGIN 1e-4          /* grid units the boxes grow by: float rounding */

static void layers_free(layer_set *o)
{
    GLuint t[2] = {o->keys, o->counts};
    glDeleteTextures(2, t);
    glDeleteFramebuffers(1, &o->fbo);
    o->keys = o->counts = o->fbo = 0;
    o->w = o->h = o->cap = 0;
}

void vx_peel_objs_free(peel_objs *o)
{
    layers_free(&o->ls[0]);
    layers_free(&o->ls[1]);
    GLuint b[12] = {o->vbo,         o->ibo,         o->ssbo[0],     o->ssbo[1],
                    o->ssbo[2],     o->list,        o->ibo_slab,    o->scan_buf[0],
                    o->scan_buf[1], o->scan_buf[2], o->scan_buf[3], o->peel_stat};
    glDeleteBuffers(12, b);
    vx_xing_free(&o->xing);
    glDeleteFramebuffers(1, &o->scan_fbo);
    glDeleteVertexArrays(1, &o->vao);
    glDeleteQueries(1, &o->query);
    memset(o, 0, sizeof *o);
}

int vx_peel_too_big(peel_ctx *c, uint64_t need)
{
    return vx_err_set(c->err, VX_ETOOBIG, "job_memory_limit",
                      "voxelizing %dx%dx%d needs %llu bytes of memory, the job may use %llu",
                      c->dims[0], c->dims[1], c->dims[2], (unsigned long long)need,
                      (unsigned long long)c->limit);
}

/* Calls the caller's progress hook; a nonzero answer stops the job.
 * Progress follows the work: a slab's x and y rays are one unit each; with
 * three axes (robust) the z rays cross every slab and are peeled once, in
 * slab 0, which weighs as much as all the slabs' x rays (issue 14: the bar
 * sat at 0.0675 for most of a robust job), and later slabs' z fills weigh
 * nothing. */
int vx_peel_progress(peel_ctx *c, double within_slab)
{
    if (!c->d->progress) return 0;
    double f;
    if (c->naxes == 3) {
        double ns = c->nslabs, a = c->axis_i, s = c->slab;
        double before = 2 * s + (s > 0 ? ns : 0) + (a < 2 ? a : 2);
        double weight = a < 2 ? 1 : c->slab == 0 ? ns : 0;
        f = (before + within_slab * weight) / (3 * ns);
    } else {
        f = ((double)c->slab + ((double)c->axis_i + within_slab) / c->naxes) / c->nslabs;
    }
    if (f > 1) f = 1;
    if (c->d->progress(c->d->ud, f, c->err) == 0) return 0;
    if (c->err && c->err->kind == VX_EOK)
        vx_err_set(c->err, VX_ECANCELED, "canceled", "voxelization stopped by its caller");
    return -1;
}

/* GPU time of a compute region. llvmpipe runs compute dispatches outside
 * the rasterizer that its timer queries measure and reports ~20 ns for a
 * dispatch of milliseconds; when the query says less than a thousandth of
 * the wall-clock time to glFinish, the wall-clock time (the dispatch ran on
 * the CPU) is the honest figure. */
double vx_peel_timer_end_compute(vx_gl_timer *t)
{
    return vx_gl_timer_end_compute_ms(t);
}

void vx_peel_dispatch_2d(uint64_t invocations)
{
    uint64_t groups = (invocations + 63) / 64;
    if (groups == 0) return;
    /* llvmpipe allows 65535 groups per dimension (ARCHITECTURE.md). */
    uint64_t gx = groups < 65535 ? groups : 65535, gy = (groups + gx - 1) / gx;
    glDispatchCompute((GLuint)gx, (GLuint)gy, 1);
}

/* Positions in grid units, snapped (vx_grid_unit): a face on a cell
 * boundary lands exactly on an integer (an axis-aligned cube filling the
 * grid gives exactly the full grid), and every brick of a lattice sees the
 * same exact floats shifted by integers (xing.h). Uploaded once. */
int vx_peel_upload(peel_ctx *c)
{
    const vx_mesh *m = c->m;
    const vx_grid *g = &c->d->grid;
    peel_objs *o = &c->o;
    glCreateBuffers(1, &o->vbo);
    glNamedBufferStorage(o->vbo, (GLsizeiptr)(m->nverts * 3 * sizeof(float) + 16), NULL,
                         GL_DYNAMIC_STORAGE_BIT);
    if (vx_gl_check(c->gl, "peel.vertex_buffer", c->err)) return -1;
    enum { CHUNK = 65536 };
    float *tmp = malloc(CHUNK * 3 * sizeof *tmp);
    if (!tmp) return vx_err_set(c->err, VX_EINTERNAL, "out_of_memory", "no memory for upload");
    for (int a = 0; a < 3; a++) {
        c->tlo[a] = INFINITY;
        c->thi[a] = -INFINITY;
    }
    for (size_t i0 = 0; i0 < m->nverts; i0 += CHUNK) {
        size_t n = m->nverts - i0 < CHUNK ? m->nverts - i0 : CHUNK;
        for (size_t k = 0; k < n; k++)
            for (int a = 0; a < 3; a++) {
                float t = vx_grid_unit(g, a, m->pos[3 * (i0 + k) + a]);
                tmp[3 * k + a] = t;
                if (t < c->tlo[a]) c->tlo[a] = t;
                if (t > c->thi[a]) c->thi[a] = t;
            }
        glNamedBufferSubData(o->vbo, (GLintptr)(i0 * 3 * sizeof(float)),
                             (GLsizeiptr)(n * 3 * sizeof(float)), tmp);
    }
    free(tmp);
    if (vx_gl_check(c->gl, "peel.vertex_upload", c->err)) return -1;
    glCreateBuffers(1, &o->ibo);
    glNamedBufferStorage(o->ibo, (GLsizeiptr)(m->ntris * 3 * sizeof(uint32_t) + 16), NULL,
                         GL_DYNAMIC_STORAGE_BIT);
    if (m->ntris)
        glNamedBufferSubData(o->ibo, 0, (GLsizeiptr)(m->ntris * 3 * sizeof(uint32_t)), m->tri);
    o->vao = vx_gl_position_vao(o->vbo, o->ibo);
    if (vx_xing_init(&o->xing, c->gl, m, g, c->err)) return -1;
    glCreateQueries(GL_ANY_SAMPLES_PASSED, 1, &o->query);
    return vx_gl_check(c->gl, "peel.index_buffer", c->err);
}

static GLuint new_array(GLenum fmt, int w, int h, int layers)
{
    GLuint t = 0;
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &t);
    glTextureStorage3D(t, 1, fmt, w, h, layers);
    /* texelFetch needs a complete texture: one level, no filtering. */
    glTextureParameteri(t, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(t, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    return t;
}

static int first_cap(const peel_ctx *c)
{
    return c->max_layers < PEEL_FIRST_CAP ? c->max_layers : PEEL_FIRST_CAP;
}

static uint64_t layer_bytes(uint64_t pixels, int cap)
{
    return pixels * 8u * (uint64_t)cap;
}

/* Grows the layer arrays to hold at least `need` layers (doubling), keeping
 * the first `keep` keys (the counts are written after the last pass).
 * Checks max_memory first: old and new live together while the old layers
 * are copied. */
static int grow(peel_ctx *c, layer_set *o, int need, int keep)
{
    int cap = o->cap ? o->cap : first_cap(c);
    while (cap < need)
        cap *= 2;
    if (cap > c->max_layers) cap = c->max_layers;
    /* the GL's limit before the memory's: a doubling past it is not what
     * the job would need, and too_many_layers is what auto slices on */
    GLint max_layers = 0;
    glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
    if (cap > max_layers) cap = max_layers;
    if (cap < need)
        return vx_err_set(c->err, VX_EUNPROC, "too_many_layers",
                          "the mesh needs more than %d depth layers (GL_MAX_ARRAY_TEXTURE_LAYERS)",
                          max_layers);
    uint64_t px = (uint64_t)o->w * (uint64_t)o->h;
    uint64_t total = c->fixed_bytes + c->layers_now + layer_bytes(px, cap);
    if (total > c->limit) return vx_peel_too_big(c, total);
    const GLuint empty = PEEL_EMPTY;
    GLuint nk = new_array(GL_R32UI, o->w, o->h, cap);
    glClearTexImage(nk, 0, GL_RED_INTEGER, GL_UNSIGNED_INT, &empty);
    if (keep > 0) {
        /* The last pass's image atomics must land before the copy. */
        glMemoryBarrier(GL_ALL_BARRIER_BITS);
        glCopyImageSubData(o->keys, GL_TEXTURE_2D_ARRAY, 0, 0, 0, 0, nk, GL_TEXTURE_2D_ARRAY, 0, 0,
                           0, 0, o->w, o->h, keep);
    }
    /* The counts are made by the count pass, at the cap it needs: on
     * llvmpipe making a 1024^2 x 32 array takes half a second. */
    GLuint old[2] = {o->keys, o->counts};
    glDeleteTextures(2, old);
    o->keys = nk;
    o->counts = 0;
    c->layers_now += layer_bytes(px, cap) - layer_bytes(px, o->cap);
    o->cap = cap;
    return vx_gl_check(c->gl, "peel.layers", c->err);
}

/* The pass target and the layer arrays for a w x h image (kept while the
 * size stays the same: slabs of one size share them). */
static int targets(peel_ctx *c, layer_set *o, int w, int h)
{
    if (o->fbo && o->w == w && o->h == h) return 0;
    c->layers_now -= layer_bytes((uint64_t)o->w * (uint64_t)o->h, o->cap);
    layers_free(o);
    o->w = w;
    o->h = h;
    /* The passes write no colour and no depth: only image atomics. */
    glCreateFramebuffers(1, &o->fbo);
    glNamedFramebufferParameteri(o->fbo, GL_FRAMEBUFFER_DEFAULT_WIDTH, w);
    glNamedFramebufferParameteri(o->fbo, GL_FRAMEBUFFER_DEFAULT_HEIGHT, h);
    if (vx_gl_check(c->gl, "peel.framebuffer", c->err)) return -1;
    GLenum stt = glCheckNamedFramebufferStatus(o->fbo, GL_FRAMEBUFFER);
    if (stt != GL_FRAMEBUFFER_COMPLETE)
        return vx_err_set(c->err, VX_EGPU, "gl_error",
                          "peel framebuffer %dx%d is incomplete (0x%x)", w, h, stt);
    return grow(c, o, 1, 0);
}

void vx_peel_draw_slab(peel_ctx *c, GLuint prog, int bucketed)
{
    size_t first = 0, ntri = c->m->ntris;
    GLuint ibo = c->o.ibo;
    if (c->slab_first && bucketed) {
        first = c->slab_first[c->slab];
        ntri = c->slab_first[c->slab + 1] - first;
        ibo = c->o.ibo_slab;
    }
    glVertexArrayElementBuffer(c->o.vao, ibo);
    vx_xing_bind(&c->o.xing, prog, ibo);
    if (ntri) vx_xing_draw(prog, first, ntri);
}

/* Triangle t's voxel rows along z in grid units, widened by one. */
static void tri_zrange(const peel_ctx *c, size_t t, double *lo, double *hi)
{
    const vx_grid *g = &c->d->grid;
    *lo = INFINITY;
    *hi = -INFINITY;
    for (int v = 0; v < 3; v++) {
        double z = vx_grid_coord(g, 2, c->m->pos[3 * (size_t)c->m->tri[3 * t + v] + 2]);
        *lo = fmin(*lo, z);
        *hi = fmax(*hi, z);
    }
    *lo = floor(*lo) - 1;
    *hi = ceil(*hi) + 1;
}

/* With several slabs, x and y rays need only the triangles that reach the
 * slab's rows: an element buffer with the triangles grouped by slab (one
 * reaching several slabs is repeated) saves drawing the whole mesh in every
 * pass of every slab. Skipped (whole mesh per slab) when the copies would
 * not fit max_memory. */
int vx_peel_slab_buckets(peel_ctx *c)
{
    if (c->nslabs < 2 || c->m->ntris == 0) return 0;
    size_t *first = calloc((size_t)c->nslabs + 1, sizeof *first);
    if (!first) return vx_err_set(c->err, VX_EINTERNAL, "out_of_memory", "no memory for slabs");
    for (size_t t = 0; t < c->m->ntris; t++) {
        double lo, hi;
        tri_zrange(c, t, &lo, &hi);
        for (int s = 0; s < c->nslabs; s++) {
            double k0 = (double)s * c->rows, k1 = k0 + c->rows;
            if (hi >= k0 && lo <= k1) first[s + 1]++;
        }
    }
    for (int s = 0; s < c->nslabs; s++)
        first[s + 1] += first[s];
    uint64_t bytes = (uint64_t)first[c->nslabs] * 12u;
    if (c->fixed_bytes + bytes + c->first_layers > c->limit) {
        free(first);
        return 0;
    }
    uint32_t *idx = malloc(bytes + 4);
    size_t *fill = malloc(((size_t)c->nslabs + 1) * sizeof *fill);
    if (!idx || !fill) {
        free(first), free(idx), free(fill);
        return vx_err_set(c->err, VX_EINTERNAL, "out_of_memory", "no memory for slabs");
    }
    memcpy(fill, first, ((size_t)c->nslabs + 1) * sizeof *fill);
    for (size_t t = 0; t < c->m->ntris; t++) {
        double lo, hi;
        tri_zrange(c, t, &lo, &hi);
        for (int s = 0; s < c->nslabs; s++) {
            double k0 = (double)s * c->rows, k1 = k0 + c->rows;
            if (hi >= k0 && lo <= k1) memcpy(idx + 3 * fill[s]++, c->m->tri + 3 * t, 12);
        }
    }
    free(fill);
    glCreateBuffers(1, &c->o.ibo_slab);
    glNamedBufferStorage(c->o.ibo_slab, (GLsizeiptr)(bytes + 4), idx, 0);
    free(idx);
    c->fixed_bytes += bytes;
    c->slab_first = first;
    return vx_gl_check(c->gl, "peel.slab_index", c->err);
}

/* Extent and first index of grid axis a in the slab's image. */
static int slab_ext(const peel_ctx *c, int a, int k0, int rows, int *off)
{
    *off = a == 2 ? k0 : 0;
    return a == 2 ? rows : c->dims[a];
}

/* Draws the slab's triangles once with the peel program bound; z rays
 * cross every slab and need the whole mesh. */
static void draw_slab(peel_ctx *c, int axis)
{
    vx_peel_draw_slab(c, c->prog_peel, axis != 2);
}

/* Draws the slab in `bands` bands of its h rows (the scissor keeps a
 * band's fragments; every ray is independent), with a stop check between
 * bands; *passed (if not NULL) is whether any fragment passed. The scissor
 * is on with one band too: the framebuffer has no attachments, and a
 * driver's bounds for those are its default size, which the scissor makes
 * explicit. */
static int draw_banded(peel_ctx *c, int axis, int w, int h, int bands, double within,
                       GLuint *passed)
{
    peel_objs *po = &c->o;
    int rc = 0;
    glEnable(GL_SCISSOR_TEST);
    for (int b = 0; b < bands && !rc; b++) {
        int y0 = (int)((long long)h * b / bands), y1 = (int)((long long)h * (b + 1) / bands);
        glScissor(0, y0, w, y1 - y0);
        GLuint any = 0;
        if (passed) glBeginQuery(GL_ANY_SAMPLES_PASSED, po->query);
        draw_slab(c, axis);
        if (passed) {
            glEndQuery(GL_ANY_SAMPLES_PASSED);
            glGetQueryObjectuiv(po->query, GL_QUERY_RESULT, &any);
            *passed |= any;
        } else if (bands > 1) {
            glFinish();
        }
        if (b + 1 < bands) rc = vx_peel_progress(c, within);
    }
    glDisable(GL_SCISSOR_TEST);
    return rc;
}

/* Bands of about PEEL_BAND_MS for a w x h pass at the slowest rate per
 * ray the job has shown (peel below). */
static int pass_bands(const peel_ctx *c, int w, int h)
{
    enum { PEEL_BAND_MS = 100, PEEL_MAX_BANDS = 64 };
    int bands = (int)ceil(c->pass_ms_ray * w * h / PEEL_BAND_MS);
    if (bands > PEEL_MAX_BANDS) bands = PEEL_MAX_BANDS;
    if (bands > h) bands = h;
    return bands < 1 ? 1 : bands;
}

/* Peels the mesh along `axis` for the slab, several layers per pass (see
 * the top of this file); sets *nslots to the key slots the fill walks. */
static int peel(peel_ctx *c, layer_set *o, int axis, int k0, int rows, int *nslots)
{
    peel_objs *po = &c->o;
    int ua = (axis + 1) % 3, va = (axis + 2) % 3, uoff, voff;
    int w = slab_ext(c, ua, k0, rows, &uoff), h = slab_ext(c, va, k0, rows, &voff);
    *nslots = 0;
    if (targets(c, o, w, h)) return -1;
    const GLuint empty = PEEL_EMPTY, zero = 0;
    glClearTexImage(o->keys, 0, GL_RED_INTEGER, GL_UNSIGNED_INT, &empty);
    o->counted = 0;
    if (c->m->ntris == 0) return vx_gl_check(c->gl, "peel.clear", c->err);

    /* Keys (voxel_peel.frag): ib in [0, n] from bit o->shift, n < 2^(32 -
     * shift) - 1 so that no key is PEEL_EMPTY. */
    int n = c->dims[axis], ibbits = 1;
    while (((int64_t)1 << ibbits) - 2 < n)
        ibbits++;
    o->shift = 32 - ibbits;
    /* the w x h image's targets bound the fragments, the viewport holds
     * the mesh (xing.h) */
    const int off[2] = {uoff, voff};
    const double lo[2] = {c->tlo[ua], c->tlo[va]}, hi[2] = {c->thi[ua], c->thi[va]};
    float ndc[4];
    vx_xing_viewport(w, h, off, 1, lo, hi, ndc);
    GLuint p = c->prog_peel;
    glProgramUniform3i(p, 0, axis, ua, va);
    glProgramUniform4f(p, 1, ndc[0], ndc[1], ndc[2], ndc[3]);
    glProgramUniform2i(p, 3, o->shift, n);
    glProgramUniform1i(p, 4, 0);
    glProgramUniform2i(p, 6, uoff, voff);

    glBindFramebuffer(GL_FRAMEBUFFER, o->fbo);
    /* State other code may have left behind; cull nothing, both faces are
     * crossings; no depth test (the cascade orders the crossings). */
    vx_peel_raster_state();
    glDisable(GL_DEPTH_TEST);
    glUseProgram(p);
    glBindVertexArray(po->vao);
    glClearNamedBufferSubData(po->peel_stat, GL_R32UI, 0, 4, GL_RED_INTEGER, GL_UNSIGNED_INT,
                              &zero);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, po->peel_stat);

    /* A pass over a whole robust z slab (1024^2 rays of the whole mesh)
     * takes about a second on llvmpipe, and over two beside other work: a
     * pass is drawn in bands of about 100 ms each (pass_bands), from the
     * slowest rate per ray the job's passes have shown so far (the first z
     * pass follows x's and y's; a slower pass makes the later ones and the
     * count pass use more), so a job's timeout or cancel is seen within
     * about 100 ms. */
    int rc = -1, base = 0, bands = pass_bands(c, w, h);
    for (int pass = 0;; pass++) {
        /* 16 slots, then as many as so far: passes grow geometrically. */
        int k = pass == 0 ? first_cap(c) : base;
        if (k > c->max_layers - base) k = c->max_layers - base;
        if (base + k > o->cap && grow(c, o, base + k, base)) goto done;
        const double within = 0.9 * (pass + 1) / (pass + 4.0);
        const double t0 = vx_mono_ms();
        vx_gl_timer t;
        vx_gl_timer_begin(&t);
        glBindImageTexture(0, o->keys, 0, GL_TRUE, 0, GL_READ_WRITE, GL_R32UI);
        glProgramUniform2i(p, 2, base, k);
        GLuint passed = 0;
        int stopped = draw_banded(c, axis, w, h, bands, within, &passed);
        /* The next pass reads this one's last slot. */
        glMemoryBarrier(GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
        c->st->gpu_peel_ms += vx_gl_timer_end_ms(&t); /* ended even when stopped */
        if (stopped) goto done;
        double ms_ray = (vx_mono_ms() - t0) / ((double)w * h);
        if (ms_ray > c->pass_ms_ray) c->pass_ms_ray = ms_ray;
        bands = pass_bands(c, w, h);
        c->st->passes++;
        if (vx_gl_check(c->gl, "peel.pass", c->err)) goto done;
        base += k;
        if (!passed) break;
        if (base >= c->max_layers) {
            vx_err_set(c->err, VX_EUNPROC, "too_many_layers",
                       "the mesh has more than %d depth layers along %c (max_layers)",
                       c->max_layers, "xyz"[axis]);
            goto done;
        }
        if (vx_peel_progress(c, within)) goto done;
    }
    *nslots = base;

    /* Coincident crossings were dropped from the slots: one more pass
     * counts every key's fragments. The flag is the only value read back
     * between peeling and filling, besides the occlusion queries. */
    GLuint coincident = 0;
    /* written by the fragment shader: without the barrier a GPU may hand
     * back the buffer as cleared (llvmpipe does not) */
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    glGetNamedBufferSubData(po->peel_stat, 0, 4, &coincident);
    if (coincident) {
        vx_gl_timer t;
        vx_gl_timer_begin(&t);
        if (!o->counts) o->counts = new_array(GL_R32UI, o->w, o->h, o->cap);
        glClearTexImage(o->counts, 0, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
        glBindImageTexture(1, o->counts, 0, GL_TRUE, 0, GL_READ_WRITE, GL_R32UI);
        glProgramUniform1i(p, 4, 1);
        glProgramUniform1i(p, 5, base);
        int stopped = draw_banded(c, axis, w, h, bands, 0.9, NULL);
        c->st->gpu_peel_ms += vx_gl_timer_end_ms(&t);
        if (stopped) goto done;
        c->st->passes++;
        o->counted = 1;
    }
    rc = vx_gl_check(c->gl, "peel.count", c->err);
done:
    vx_xing_unbind();
    glBindVertexArray(0);
    glUseProgram(0);
    glBindImageTexture(0, 0, 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32UI);
    glBindImageTexture(1, 0, 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32UI);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    return rc;
}

/* Fills the slab's bits for the layers peeled along `axis` into ssbo[slot]. */
static int fill(peel_ctx *c, const layer_set *o, int axis, int slot, int mode, int k0, int rows,
                int nslots)
{
    GLuint p = c->prog_fill;
    glProgramUniform2i(p, 0, o->w, o->h);
    glProgramUniform1i(p, 1, nslots);
    glProgramUniform1i(p, 2, mode == VX_INSIDE_PARITY ? 1 : 0);
    glProgramUniform1i(p, 3, axis);
    glProgramUniform4i(p, 4, c->dims[0], c->dims[1], (int)c->wx, rows);
    glProgramUniform2i(p, 5, c->dims[axis], k0);
    glProgramUniform1i(p, 6, o->shift);
    glProgramUniform1i(p, 7, o->counted);
    /* The keys and counts were written by image atomics in the passes. */
    glMemoryBarrier(GL_TEXTURE_FETCH_BARRIER_BIT | GL_SHADER_IMAGE_ACCESS_BARRIER_BIT);
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    glUseProgram(p);
    glBindTextureUnit(0, o->keys);
    glBindTextureUnit(1, o->counts);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, c->o.ssbo[slot]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, c->o.peel_stat);
    vx_peel_dispatch_2d((uint64_t)o->w * (uint64_t)o->h);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    c->st->gpu_fill_ms += vx_peel_timer_end_compute(&t);
    glUseProgram(0);
    glBindTextureUnit(0, 0);
    glBindTextureUnit(1, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, 0);
    return vx_gl_check(c->gl, "peel.fill", c->err);
}

/* ---- surface fill ---------------------------------------------------- */

static int axis_test(const double a[3], const double v[3][3], double hs)
{
    double p0 = a[0] * v[0][0] + a[1] * v[0][1] + a[2] * v[0][2];
    double p1 = a[0] * v[1][0] + a[1] * v[1][1] + a[2] * v[1][2];
    double p2 = a[0] * v[2][0] + a[1] * v[2][1] + a[2] * v[2][2];
    double r = hs * (fabs(a[0]) + fabs(a[1]) + fabs(a[2]));
    double mn = fmin(p0, fmin(p1, p2)), mx = fmax(p0, fmax(p1, p2));
    return !(mn > r || mx < -r);
}

/* Separating-axis triangle/box test (Akenine-Moller 2001), box centre c. */
static int tri_box(const double c[3], const double tv[3][3], const double n[3], double hs)
{
    double v[3][3], e[3][3];
    for (int i = 0; i < 3; i++)
        for (int a = 0; a < 3; a++)
            v[i][a] = tv[i][a] - c[a];
    for (int i = 0; i < 3; i++)
        for (int a = 0; a < 3; a++)
            e[i][a] = v[(i + 1) % 3][a] - v[i][a];
    for (int i = 0; i < 3; i++) {
        double ax[3][3] = {{0, -e[i][2], e[i][1]}, {e[i][2], 0, -e[i][0]}, {-e[i][1], e[i][0], 0}};
        for (int j = 0; j < 3; j++)
            if (!axis_test(ax[j], v, hs)) return 0;
    }
    for (int a = 0; a < 3; a++) {
        double mn = fmin(v[0][a], fmin(v[1][a], v[2][a])),
               mx = fmax(v[0][a], fmax(v[1][a], v[2][a]));
        if (mn > hs || mx < -hs) return 0;
    }
    return axis_test(n, v, hs);
}

/* Triangle t in grid units, its normal, and its voxel bbox clipped to the
 * grid; 0 when the bbox misses the grid. */
static int tri_setup(const peel_ctx *c, size_t t, double v[3][3], double n[3], int lo[3], int hi[3])
{
    const vx_grid *g = &c->d->grid;
    for (int i = 0; i < 3; i++)
        for (int a = 0; a < 3; a++)
            v[i][a] = vx_grid_unit(g, a, c->m->pos[3 * (size_t)c->m->tri[3 * t + i] + a]);
    double e0[3], e1[3];
    vx_v3_sub(v[1], v[0], e0);
    vx_v3_sub(v[2], v[1], e1);
    vx_v3_cross(e0, e1, n);
    for (int a = 0; a < 3; a++) {
        double mn = fmin(v[0][a], fmin(v[1][a], v[2][a])) - SURF_MARGIN,
               mx = fmax(v[0][a], fmax(v[1][a], v[2][a])) + SURF_MARGIN;
        double l = fmax(ceil(mn) - 1, 0), h = fmin(floor(mx), c->dims[a] - 1);
        if (l > h) return 0;
        lo[a] = (int)l;
        hi[a] = (int)h;
    }
    return 1;
}

/* Axis the triangle's normal is closest to: rows are walked across the
 * other two axes and, along this one, only the few voxels near the plane
 * are tested (at most ~6 per row), so the work follows the triangle's area
 * whatever its orientation. */
static int dominant(const double n[3])
{
    int d = 0;
    for (int a = 1; a < 3; a++)
        if (fabs(n[a]) > fabs(n[d])) d = a;
    return d;
}

/* Voxel range [*t0, *t1] along axis d, in the row whose other two voxel
 * coordinates are in r (r[d] ignored), where a box can touch the plane;
 * widened by one voxel for rounding. */
static void plane_range(const double v0[3], const double n[3], double hs, int d, const int r[3],
                        int *t0, int *t1)
{
    if (n[d] == 0) return; /* degenerate triangle: the whole bbox */
    double rad = hs * (fabs(n[0]) + fabs(n[1]) + fabs(n[2]));
    double dd = n[0] * v0[0] + n[1] * v0[1] + n[2] * v0[2], rest = 0;
    for (int a = 0; a < 3; a++)
        if (a != d) rest += n[a] * (r[a] + 0.5);
    double x0 = (dd - rest - rad) / n[d], x1 = (dd - rest + rad) / n[d];
    double a = fmax(floor(fmin(x0, x1) - 0.5) - 1, *t0),
           b = fmin(ceil(fmax(x0, x1) - 0.5) + 1, *t1);
    *t0 = (int)a;
    *t1 = (int)b;
}

/* Splits the triangles: the GPU takes those whose tests fit one invocation
 * (SURF_GPU_WORK), the CPU the rest (a huge triangle on a big grid would
 * otherwise keep one invocation busy for seconds; the CPU walks the same
 * rows as the shader). The split follows the triangle's own size, not the
 * part of it in the grid, so a triangle takes the same path (and the same
 * arithmetic) in every brick of a lattice. */
static int surface_lists(peel_ctx *c, uint32_t **gpu, size_t *ngpu)
{
    const vx_mesh *m = c->m;
    *gpu = malloc(m->ntris * sizeof **gpu + 4);
    c->cpu_tris = malloc(m->ntris * sizeof *c->cpu_tris + 4);
    if (!*gpu || !c->cpu_tris)
        return vx_err_set(c->err, VX_EINTERNAL, "out_of_memory", "no memory for triangle lists");
    *ngpu = 0;
    c->ncpu_tris = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        double v[3][3], n[3];
        int lo[3], hi[3];
        if (!tri_setup(c, t, v, n, lo, hi)) continue;
        int d = dominant(n), a1 = (d + 1) % 3, a2 = (d + 2) % 3;
        double ext[3];
        for (int a = 0; a < 3; a++)
            ext[a] = ceil(fmax(v[0][a], fmax(v[1][a], v[2][a])) -
                          fmin(v[0][a], fmin(v[1][a], v[2][a]))) +
                     2;
        double rows = ext[a1] * ext[a2], along = n[d] != 0 ? fmin(ext[d], 6) : ext[d];
        if (rows * along <= SURF_GPU_WORK)
            (*gpu)[(*ngpu)++] = (uint32_t)t;
        else
            c->cpu_tris[c->ncpu_tris++] = (uint32_t)t;
    }
    return 0;
}

static void surface_cpu(peel_ctx *c)
{
    const double hs = 0.5 + SURF_MARGIN;
    uint32_t *bits = c->out->bits;
    for (size_t q = 0; q < c->ncpu_tris; q++) {
        double v[3][3], n[3], ctr[3];
        int lo[3], hi[3], r[3];
        if (!tri_setup(c, c->cpu_tris[q], v, n, lo, hi)) continue;
        int d = dominant(n), a1 = (d + 1) % 3, a2 = (d + 2) % 3;
        for (r[a2] = lo[a2]; r[a2] <= hi[a2]; r[a2]++)
            for (r[a1] = lo[a1]; r[a1] <= hi[a1]; r[a1]++) {
                int t0 = lo[d], t1 = hi[d];
                plane_range(v[0], n, hs, d, r, &t0, &t1);
                for (r[d] = t0; r[d] <= t1; r[d]++) {
                    for (int a = 0; a < 3; a++)
                        ctr[a] = r[a] + 0.5;
                    if (tri_box(ctr, v, n, hs))
                        bits[((size_t)r[2] * c->dims[1] + r[1]) * c->wx + (r[0] >> 5)] |=
                            1u << (r[0] & 31);
                }
            }
    }
}

static int surface_slab(peel_ctx *c, size_t ngpu, int k0, int rows)
{
    peel_objs *o = &c->o;
    GLuint p = c->prog_surf;
    glClearNamedBufferData(o->ssbo[0], GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
    glProgramUniform1ui(p, 0, (GLuint)ngpu);
    glProgramUniform4i(p, 1, c->dims[0], c->dims[1], (int)c->wx, rows);
    glProgramUniform1i(p, 2, k0);
    glProgramUniform1f(p, 3, (float)(0.5 + SURF_MARGIN));
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    glUseProgram(p);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, o->ssbo[0]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, o->vbo);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, o->ibo);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, o->list);
    vx_peel_dispatch_2d(ngpu);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    c->st->gpu_fill_ms += vx_peel_timer_end_compute(&t);
    glUseProgram(0);
    for (GLuint b = 0; b < 4; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
    return vx_gl_check(c->gl, "peel.surface", c->err);
}

/* ---- sizing ---------------------------------------------------------- */

uint64_t vx_peel_slab_bytes(const peel_ctx *c, int rows)
{
    return (uint64_t)c->wx * 4u * (uint64_t)c->dims[1] * (uint64_t)rows;
}

/* Largest peel image of the x and y rays (layer set 0). */
static uint64_t max_image(const peel_ctx *c, int rows)
{
    uint64_t px = (uint64_t)c->dims[1] * (uint64_t)rows;
    if (c->naxes == 3) {
        uint64_t py = (uint64_t)rows * (uint64_t)c->dims[0];
        if (py > px) px = py;
    }
    return px;
}

/* The z rays' image (robust only; layer set 1). */
static uint64_t z_image(const peel_ctx *c)
{
    return c->naxes == 3 ? (uint64_t)c->dims[0] * (uint64_t)c->dims[1] : 0;
}

/* The layer arrays as first allocated. */
static uint64_t first_layers(const peel_ctx *c, int rows)
{
    return layer_bytes(max_image(c, rows), first_cap(c)) + layer_bytes(z_image(c), first_cap(c));
}

/* Memory a slab height needs: CPU grid, mesh buffers, slab SSBOs and the
 * first layer arrays (the passes have no targets). */
static uint64_t estimate(const peel_ctx *c, int rows, int surface)
{
    uint64_t b = vx_bitgrid_bytes(c->dims, 1);
    b += (uint64_t)c->m->nverts * 12u + (uint64_t)c->m->ntris * 12u + vx_xing_bytes(c->m);
    if (surface) return b + (uint64_t)c->m->ntris * 8u + vx_peel_slab_bytes(c, rows);
    b += vx_peel_slab_bytes(c, rows) * (uint64_t)c->naxes;
    return b + first_layers(c, rows);
}

static int plan(peel_ctx *c, int surface)
{
    const vx_gl_info *in = vx_gl_get_info(c->gl);
    GLint vp[2] = {0, 0};
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, vp);
    long side = in->max_texture_size;
    if (vp[0] < side) side = vp[0];
    if (vp[1] < side) side = vp[1];
    /* images fit power-of-two viewports (xing.h) */
    while (vx_xing_pow2((int)side) > side)
        side = vx_xing_pow2((int)side) / 2;
    uint64_t row_bytes = vx_peel_slab_bytes(c, 1);
    uint64_t rows = (uint64_t)in->max_ssbo_bytes / row_bytes;
    if (rows == 0)
        return vx_err_set(c->err, VX_ETOOBIG, "grid_too_large",
                          "one z layer of %dx%d voxels (%llu bytes) exceeds this GPU's storage "
                          "block size (%ld bytes)",
                          c->dims[0], c->dims[1], (unsigned long long)row_bytes,
                          in->max_ssbo_bytes);
    if (rows > (uint64_t)c->dims[2]) rows = (uint64_t)c->dims[2];
    if (!surface) {
        /* Peel images: x rays are dims[1] x rows, y rays rows x dims[0],
         * z rays dims[0] x dims[1]. */
        int need[2] = {c->dims[1], c->naxes == 3 ? c->dims[0] : 1};
        if (need[0] > side || need[1] > side || (c->naxes == 3 && c->dims[1] > side))
            return vx_err_set(c->err, VX_ETOOBIG, "grid_too_large",
                              "a %dx%dx%d grid needs peel images wider than this GPU's %ld "
                              "pixels",
                              c->dims[0], c->dims[1], c->dims[2], side);
        if (rows > (uint64_t)side) rows = (uint64_t)side;
        uint64_t wide = (uint64_t)c->dims[1];
        if (c->naxes == 3 && (uint64_t)c->dims[0] > wide) wide = (uint64_t)c->dims[0];
        uint64_t cap = PEEL_PIXEL_CAP / wide;
        if (cap < 1) cap = 1;
        if (rows > cap) rows = cap;
    }
    if (c->d->max_slab_rows > 0 && rows > (uint64_t)c->d->max_slab_rows)
        rows = (uint64_t)c->d->max_slab_rows;
    if (rows < 1) rows = 1;
    /* Shrink slabs until the job fits its memory; the CPU grid is fixed. */
    while (rows > 1 && estimate(c, (int)rows, surface) > c->limit)
        rows = (rows + 1) / 2;
    uint64_t need = estimate(c, (int)rows, surface);
    if (need > c->limit) return vx_peel_too_big(c, need);
    c->rows = (int)rows;
    c->nslabs = (int)(((uint64_t)c->dims[2] + rows - 1) / rows);
    c->first_layers = surface ? 0 : first_layers(c, c->rows);
    c->fixed_bytes = need - c->first_layers;
    return 0;
}

void vx_peel_raster_state(void)
{
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_STENCIL_TEST);
    glDisable(GL_POLYGON_OFFSET_FILL);
    glDisable(GL_MULTISAMPLE);
    glDisable(GL_RASTERIZER_DISCARD);
    glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    glFrontFace(GL_CCW);
}

int vx_peel_check_input(const vx_mesh *m, const vx_voxelize_desc *d, vx_err *err)
{
    const vx_grid *g = &d->grid;
    for (int a = 0; a < 3; a++)
        if (g->dims[a] < 1 || g->dims[a] > (1 << 20))
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "grid dims must be 1..2^20");
    if (!(g->h > 0) || !isfinite(g->h))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "voxel size must be positive");
    /* A bad index would make the GPU read outside the vertex buffer. */
    return vx_mesh_check_indices(m, err);
}

/* Compiles the programs the fill mode needs; for fill=surface also checks
 * the mesh buffers against the GPU's storage block size. */
static int load_programs(peel_ctx *c, int surface)
{
    vx_gl *gl = c->gl;
    const vx_mesh *m = c->m;
    vx_err *err = c->err;
    if (surface) {
        c->prog_surf = vx_gl_compute_program(gl, "voxel_surface.comp", err);
        if (!c->prog_surf) return -1;
        const long max_ssbo = vx_gl_get_info(gl)->max_ssbo_bytes;
        if ((uint64_t)m->nverts * 12u > (uint64_t)max_ssbo ||
            (uint64_t)m->ntris * 12u > (uint64_t)max_ssbo)
            return vx_err_set(err, VX_ETOOBIG, "mesh_too_large",
                              "the mesh's vertex or index buffer exceeds this GPU's storage "
                              "block size (%ld bytes) for fill=surface",
                              max_ssbo);
    } else {
        c->prog_peel = vx_gl_program(gl, "voxel_peel.vert", "voxel_peel.frag", err);
        if (!c->prog_peel) return -1;
        c->prog_fill = vx_gl_compute_program(gl, "voxel_peel_fill.comp", err);
        if (!c->prog_fill) return -1;
        if (c->naxes == 3 &&
            !(c->prog_major = vx_gl_compute_program(gl, "voxel_peel_major.comp", err)))
            return -1;
    }
    return 0;
}

/* Reads slab ssbo[0] (rows rows from k0) back into the output grid and
 * reports the slab's progress at axis c->axis_i. */
static int readback_slab(peel_ctx *c, int k0, int rows)
{
    double r0 = vx_mono_ms();
    glGetNamedBufferSubData(c->o.ssbo[0], 0, (GLsizeiptr)vx_peel_slab_bytes(c, rows),
                            c->out->bits + (size_t)k0 * c->dims[1] * c->wx);
    c->st->readback_ms += vx_mono_ms() - r0;
    if (vx_gl_check(c->gl, "peel.readback", c->err)) return -1;
    return vx_peel_progress(c, 1.0);
}

/* fill=surface: uploads the triangle lists, then voxelizes and reads back
 * slab by slab; t0 is when the upload began. */
static int run_surface(peel_ctx *c, double t0)
{
    uint32_t *gpu_list = NULL;
    size_t ngpu = 0;
    if (surface_lists(c, &gpu_list, &ngpu)) {
        free(gpu_list);
        return -1;
    }
    glCreateBuffers(1, &c->o.list);
    glNamedBufferStorage(c->o.list, (GLsizeiptr)(ngpu * 4 + 4), gpu_list, 0);
    VX_FREE(gpu_list);
    if (vx_gl_check(c->gl, "peel.list", c->err)) return -1;
    glFinish();
    c->st->upload_ms = vx_mono_ms() - t0;
    glCreateBuffers(1, &c->o.ssbo[0]);
    glNamedBufferStorage(c->o.ssbo[0], (GLsizeiptr)vx_peel_slab_bytes(c, c->rows), NULL, 0);
    if (vx_gl_check(c->gl, "peel.ssbo", c->err)) return -1;
    for (c->slab = 0; c->slab < c->nslabs; c->slab++) {
        int k0 = c->slab * c->rows, rows = c->dims[2] - k0 < c->rows ? c->dims[2] - k0 : c->rows;
        if (surface_slab(c, ngpu, k0, rows)) return -1;
        c->axis_i = 0;
        if (readback_slab(c, k0, rows)) return -1;
    }
    surface_cpu(c);
    return 0;
}

/* Robust inside test: combines the three axes' slabs (rows words) into
 * ssbo[0] by majority. */
static void major_pass(peel_ctx *c, int rows)
{
    uint64_t words = vx_peel_slab_bytes(c, rows) / 4;
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    glUseProgram(c->prog_major);
    glProgramUniform1ui(c->prog_major, 0, (GLuint)words);
    for (GLuint b = 0; b < 3; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, c->o.ssbo[b]);
    vx_peel_dispatch_2d(words);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    c->st->gpu_fill_ms += vx_peel_timer_end_compute(&t);
    glUseProgram(0);
    for (GLuint b = 0; b < 3; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
}

/* Solid fills: peels and fills each slab along every axis, then reads it
 * back; t0 is when the upload began. */
static int run_solid(peel_ctx *c, double t0)
{
    if (vx_peel_slab_buckets(c)) return -1;
    glFinish(); /* so upload_ms is the upload, not just its queueing */
    c->st->upload_ms = vx_mono_ms() - t0;
    for (int s = 0; s < c->naxes; s++) {
        glCreateBuffers(1, &c->o.ssbo[s]);
        glNamedBufferStorage(c->o.ssbo[s], (GLsizeiptr)vx_peel_slab_bytes(c, c->rows), NULL,
                             GL_DYNAMIC_STORAGE_BIT);
    }
    /* [0] coincident crossings seen (per peel), [1] most layers of a pixel */
    glCreateBuffers(1, &c->o.peel_stat);
    glNamedBufferStorage(c->o.peel_stat, 8, (GLuint[2]){0, 0}, GL_DYNAMIC_STORAGE_BIT);
    if (vx_gl_check(c->gl, "peel.ssbo", c->err)) return -1;
    const int mode = c->naxes == 3 ? VX_INSIDE_PARITY : (int)c->d->inside;
    int nl[3] = {0, 0, 0};
    for (c->slab = 0; c->slab < c->nslabs; c->slab++) {
        int k0 = c->slab * c->rows, rows = c->dims[2] - k0 < c->rows ? c->dims[2] - k0 : c->rows;
        for (c->axis_i = 0; c->axis_i < c->naxes; c->axis_i++) {
            int axis = c->axis_i;
            /* x rays write whole words; y and z rays OR single bits. */
            if (axis > 0)
                glClearNamedBufferData(c->o.ssbo[axis], GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT,
                                       NULL);
            /* z rays cross every slab: peeled once, their layers kept
             * (set 1) and filled slab by slab. */
            layer_set *ls = &c->o.ls[axis == 2];
            if (axis < 2 || c->slab == 0) {
                if (peel(c, ls, axis, k0, rows, &nl[axis])) return -1;
            }
            if (fill(c, ls, axis, axis, mode, k0, rows, nl[axis])) return -1;
            if (c->naxes == 3 && c->axis_i < 2 && vx_peel_progress(c, 1.0)) return -1;
        }
        if (c->naxes == 3) major_pass(c, rows);
        c->axis_i = c->naxes - 1;
        if (readback_slab(c, k0, rows)) return -1;
    }
    GLuint most = 0;
    glGetNamedBufferSubData(c->o.peel_stat, 4, 4, &most);
    c->st->layers = (int)most;
    return 0;
}

int vx_voxelize_peel(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                     vx_voxelize_stats *st, vx_err *err)
{
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    st->method = "peel";
    memset(out, 0, sizeof *out);
    if (vx_peel_check_input(m, d, err)) return -1;
    const vx_grid *g = &d->grid;

    peel_ctx c = {.gl = gl, .m = m, .d = d, .st = st, .err = err, .out = out};
    for (int a = 0; a < 3; a++)
        c.dims[a] = g->dims[a];
    c.wx = ((size_t)c.dims[0] + 31) / 32;
    /* by default as many as the GL's array textures hold (grow() says so
     * when a ray needs more) and the job's memory allows */
    c.max_layers = d->max_layers > 0 ? d->max_layers : INT_MAX / 4;
    c.limit = d->max_memory ? d->max_memory : UINT64_MAX;
    const int surface = d->fill == VX_FILL_SURFACE;
    c.naxes = !surface && d->inside == VX_INSIDE_ROBUST ? 3 : 1;
    if (plan(&c, surface)) return -1;
    st->chunks = c.nslabs;
    if (load_programs(&c, surface)) return -1;
    /* Errors left by earlier work must not be blamed on this job. */
    while (glGetError() != GL_NO_ERROR) {
    }

    int rc = -1;
    if (vx_bitgrid_alloc(out, g, 0, err)) return -1;
    double t0 = vx_mono_ms();
    if (vx_peel_upload(&c)) goto done;
    if (surface ? run_surface(&c, t0) : run_solid(&c, t0)) goto done;
    st->voxels_inside = vx_bitgrid_count(out);
    rc = 0;
done:
    free(c.cpu_tris);
    free(c.slab_first);
    vx_peel_objs_free(&c.o);
    if (rc) vx_bitgrid_free(out);
    return rc;
}
