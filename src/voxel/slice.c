/* Slicing solid voxelizer (seed 003, Nakamura et al.): vx_voxelize_slice.
 *
 * The seed (§3.1-3.3): viewport resolution = voxel resolution, front faces
 * pure red, back faces pure blue, an orthographic view whose near clip plane
 * steps through the volume one slice at a time; a pixel is inside when the
 * nearest surface beyond the plane is a back face (blue). Here the plane
 * steps along z through the voxel centres (w = k + 1/2), so each slice is an
 * x-by-y image and its rows are the rows of voxel.h's x-fastest bit layout.
 * The near plane is the fragment shader's test "w beyond the plane" rather
 * than the GL near clip plane: clipping the triangles that cross the plane
 * and interpolating across the clipped vertices misjudges some centres next
 * to the plane, the fragment test does not (and gives the tie rule below).
 *
 * Instead of reading every slice back as the seed did, a batch of slices
 * goes to the layers of an array texture, a pixel pack copies them into a
 * buffer, and a compute pass (shaders/voxel_slice_pack.comp) packs them into
 * bits (and counts) in an SSBO, read back once per chunk of z-layers (chunks
 * keep each SSBO under the 128 MiB binding limit of llvmpipe,
 * ARCHITECTURE.md).
 *
 * Inside rules (vx_inside):
 *   parity  - the number of surfaces beyond the plane, counted like nonzero
 *             below (+1 for every face), inside when odd: entry/exit
 *             parity, the symmetric difference of overlapping parts, as
 *             peel and scan. (The seed's nearest-surface test, with the
 *             depth test, was used until issue 14: it set streaks down a
 *             column where the column grazes a fold, since the depth order
 *             of two nearly coincident crossings is rounding, and it
 *             differed from peel and scan on overlapping parts.)
 *   nonzero - the signed-count form: no depth test, additive blending of +1
 *             per back face and -1 per front face beyond the plane into an
 *             R32F target; the sum is the winding number of the ray from the
 *             centre, inside when nonzero (the union of overlapping parts).
 *             Computed incrementally: the first plane of a run sums every
 *             surface beyond it, each later plane starts from a copy of the
 *             previous plane's sum and subtracts the surfaces in the slab
 *             between the two planes (triangles bucketed by slab). Each
 *             triangle is drawn about once per slab it spans instead of
 *             once per slice: O(T + slices x pixels), not O(T x slices).
 *             The sums are small integers in R32F, exact; no clipping, so a
 *             fragment falls in exactly one slab and nothing drifts.
 *   robust  - the parity count stepped along x, y and z (only z runs
 *             incrementally: the slab lists are along z); a voxel is inside
 *             when at least two of the three agree (with supersampling: the
 *             median of the three counts). It repairs a hole that only one
 *             axis's rays pass through; it fails where a hole (or an open
 *             part) is seen by two axes, e.g. an open box missing two faces
 *             perpendicular to different axes, or a missing face that rays
 *             along two axes cross after leaving the solid. Slower: three
 *             passes, and the x and y passes set bits with atomics.
 *
 * Tie rule: a centre exactly on a face counts as inside when the face is an
 * entry and outside when it is an exit, i.e. half-open [entry, exit) along
 * the stepping direction, like tests/support/ref_voxel (which uses +x): only
 * surfaces strictly beyond the plane count (w - plane > 0, with the
 * fragment's w clamped to its triangle's w range, so a face on the plane
 * keeps exactly the plane's w; see shaders/voxel_slice.frag). Centres on
 * faces parallel to the stepping axis lie on triangle edges in the image:
 * the rasterizer's edge rule decides; on llvmpipe it is the same half-open
 * rule (measured in test_slice), other drivers may differ. Grids whose cell
 * boundaries carry the faces have no centre ties at all.
 *
 * Accuracy improvement (seed 003 §3.4, supersample 2): the images are drawn
 * at twice the resolution and two planes per voxel (w = k + 1/4, k + 3/4) go
 * to two layers, so each voxel sees 2 x 2 x 2 = 8 samples; the voxel is set
 * when at least `threshold` are inside, and the count goes to out->counts. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "util/clock.h"
#include "util/log.h"
#include "voxel/voxel.h"
#include "voxel/xing.h"

/* One SSBO binding may not exceed this (llvmpipe's limit; NVIDIA allows
 * more, but chunks of 128 MiB cost nothing measurable). */
#define SLICE_SSBO_MAX ((uint64_t)128 << 20)
/* Colour + depth layers of one batch stay under this. */
#define SLICE_BATCH_BYTES ((uint64_t)32 << 20)
#define SLICE_BATCH_MAX 64
/* Voxels by which a triangle's w range is widened when choosing which
 * triangles a draw needs (far above float interpolation error). */
#define SLAB_MARGIN 0.01f

/* Every GL object one run creates, so that every exit path deletes the same
 * set (names of 0 are ignored by glDelete*). */
typedef struct objs {
    GLuint vbo, ibo[3], vao;
    GLuint fbo, tex_color;
    GLuint ssbo_bits, ssbo_counts, pbo;
    GLuint slab_ibo; /* nonzero: triangles per slab between consecutive planes */
    vx_xing xing;    /* the triangles as the fragment shader reads them */
} objs;

static void objs_free(objs *o)
{
    GLuint bufs[7] = {o->vbo,       o->ibo[0],      o->ibo[1], o->ibo[2],
                      o->ssbo_bits, o->ssbo_counts, o->pbo};
    glDeleteBuffers(7, bufs);
    glDeleteBuffers(1, &o->slab_ibo);
    vx_xing_free(&o->xing);
    glDeleteVertexArrays(1, &o->vao);
    glDeleteFramebuffers(1, &o->fbo);
    glDeleteTextures(1, &o->tex_color);
    memset(o, 0, sizeof *o);
}

/* The plane steps along grid axis w; the image is (u, v) = the next two axes
 * cyclically, so (u, v, w) keeps the handedness of (x, y, z). Axis 2 (z)
 * first: it is the only one a non-robust run needs. */
static const int k_perm[3][3] = {{1, 2, 0}, {2, 0, 1}, {0, 1, 2}};

/* Sort keys: triangles ascending by their largest w, so that the ones a
 * slice needs (largest w beyond the plane) are a suffix of the index buffer. */
typedef struct tri_key {
    float wmax;
    uint32_t t; /* triangle index */
} tri_key;

static int cmp_key(const void *a, const void *b)
{
    float x = ((const tri_key *)a)->wmax, y = ((const tri_key *)b)->wmax;
    if (x != y) return x < y ? -1 : 1;
    uint32_t s = ((const tri_key *)a)->t, t = ((const tri_key *)b)->t;
    return (s > t) - (s < t);
}

typedef struct plan {
    int dims[3];
    size_t wx;
    int ss;                            /* 1 or 2 */
    int threshold;                     /* samples inside to set a voxel */
    int naxes;                         /* 1, or 3 for robust */
    int axes[3];                       /* grid axes the plane steps along */
    int count;                         /* parity, robust: count surfaces, inside when odd */
    int tile;                          /* largest tile side in voxels (multiple of 32) */
    int tex_w, tex_h;                  /* target size in pixels (largest tile over the axes) */
    int batch;                         /* slices per batch (each has ss layers) */
    int nk;                            /* z-layers per chunk */
    uint64_t bits_layer, counts_layer; /* bytes of one z-layer in the SSBOs */
    uint64_t slab_refs;                /* nonzero: triangle references over all slabs */
    int incremental;                   /* nonzero: slab updates (else every slice sums afresh) */
} plan;

static uint64_t u64min(uint64_t a, uint64_t b)
{
    return a < b ? a : b;
}

/* Colour (R32F sums) of `batch` slices. */
static uint64_t target_color_bytes(const plan *p, int batch)
{
    /* rows padded to 4 bytes in the pixel-pack copy */
    uint64_t px = ((uint64_t)p->tex_w + 3) / 4 * 4 * (uint64_t)p->tex_h;
    return px * 4 * (uint64_t)batch * (uint64_t)p->ss;
}

/* Colour + the pixel-pack copy of it. */
static uint64_t target_bytes(const plan *p, int batch)
{
    return 2 * target_color_bytes(p, batch);
}

/* Grid-frame coordinate of vertex v along axis a, as uploaded (snapped,
 * xing.h). */
static float grid_coord(const vx_mesh *m, const vx_grid *g, size_t v, int a)
{
    return vx_grid_unit(g, a, m->pos[3 * v + a]);
}

/* Incremental signed count (nonzero): plane j sits at w = (j + 1/2) / ss.
 * Slab j >= 1 is (plane j-1, plane j]; a triangle goes into every slab its
 * w range may reach. The margin only adds triangles (the fragment shader
 * decides exactly), so interpolation rounding cannot drop a fragment. */
static int slab_range(float wmin, float wmax, int ss, int nplanes, int *j0, int *j1)
{
    double lo = ceil(ss * ((double)wmin - SLAB_MARGIN) - 0.5);
    double hi = ceil(ss * ((double)wmax + SLAB_MARGIN) + 0.5) - 1;
    if (lo < 1) lo = 1;
    if (hi > nplanes - 1) hi = nplanes - 1;
    if (lo > hi) return 0;
    *j0 = (int)lo;
    *j1 = (int)hi;
    return 1;
}

static void tri_wrange(const vx_mesh *m, const vx_grid *g, size_t t, int a, float *lo, float *hi)
{
    *lo = INFINITY;
    *hi = -INFINITY;
    for (int v = 0; v < 3; v++) {
        float w = grid_coord(m, g, m->tri[3 * t + v], a);
        if (w < *lo) *lo = w;
        if (w > *hi) *hi = w;
    }
}

/* Fills the sizes of the run and checks them against the GL limits and
 * desc->max_memory before anything is allocated. */
static int make_plan(const vx_mesh *m, const vx_voxelize_desc *d, plan *p, vx_err *err)
{
    memset(p, 0, sizeof *p);
    memcpy(p->dims, d->grid.dims, sizeof p->dims);
    p->wx = ((size_t)p->dims[0] + 31) / 32;
    p->ss = d->supersample == 2 ? 2 : 1;
    p->threshold = p->ss == 2 ? (d->threshold ? d->threshold : 4) : 1;
    p->count = d->inside != VX_INSIDE_NONZERO;
    p->naxes = d->inside == VX_INSIDE_ROBUST ? 3 : 1;
    for (int a = 0; a < p->naxes; a++)
        p->axes[a] = p->naxes == 1 ? 2 : (a + 2) % 3;

    GLint max_tex = 0, max_rb = 0, max_vp[2] = {0, 0}, max_layers = 0, max_ssbo = 0;
    glGetIntegerv(GL_MAX_TEXTURE_SIZE, &max_tex);
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_rb);
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, max_vp);
    glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &max_layers);
    glGetIntegerv(GL_MAX_SHADER_STORAGE_BLOCK_SIZE, &max_ssbo);
    int lim = max_tex;
    if (max_rb < lim) lim = max_rb;
    if (max_vp[0] < lim) lim = max_vp[0];
    if (max_vp[1] < lim) lim = max_vp[1];
    /* power-of-two viewports (xing.h) */
    while (vx_xing_pow2(lim) > lim)
        lim = vx_xing_pow2(lim) / 2;
    /* Tiles start on word boundaries so the z pass owns whole words. */
    p->tile = (lim / p->ss) / 32 * 32;
    if (p->tile < 32)
        return vx_err_set(err, VX_EGPU, "gl_unsupported", "texture limit %d is too small", lim);
    for (int a = 0; a < p->naxes; a++) {
        const int *pm = k_perm[p->axes[a]];
        int tw = p->dims[pm[0]] < p->tile ? p->dims[pm[0]] : p->tile;
        int th = p->dims[pm[1]] < p->tile ? p->dims[pm[1]] : p->tile;
        if (tw * p->ss > p->tex_w) p->tex_w = tw * p->ss;
        if (th * p->ss > p->tex_h) p->tex_h = th * p->ss;
    }

    uint64_t ssbo_max = SLICE_SSBO_MAX;
    if (max_ssbo > 0 && (uint64_t)max_ssbo < ssbo_max) ssbo_max = (uint64_t)max_ssbo;
    p->bits_layer = (uint64_t)p->dims[1] * p->wx * 4;
    p->counts_layer = p->ss == 2 ? (uint64_t)p->dims[1] * (uint64_t)p->dims[0] : 0;
    uint64_t layer_max = p->bits_layer > p->counts_layer ? p->bits_layer : p->counts_layer;
    if (layer_max + 4 > ssbo_max)
        return vx_err_set(err, VX_ETOOBIG, "gpu_limit",
                          "one z-layer of a %dx%d grid needs %llu bytes, over the GPU's %llu "
                          "bytes per storage buffer",
                          p->dims[0], p->dims[1], (unsigned long long)layer_max,
                          (unsigned long long)ssbo_max);
    uint64_t nk = (ssbo_max - 4) / layer_max;
    if (nk > (uint64_t)p->dims[2]) nk = (uint64_t)p->dims[2];

    int batch = (int)u64min(SLICE_BATCH_MAX, SLICE_BATCH_BYTES / target_bytes(p, 1));
    if (batch < 1) batch = 1;
    if (batch * p->ss > max_layers) batch = max_layers / p->ss;
    if (batch > p->dims[2] && p->naxes == 1) batch = p->dims[2];

    {
        int nplanes = p->dims[2] * p->ss, j0, j1;
        for (size_t t = 0; t < m->ntris; t++) {
            float lo, hi;
            tri_wrange(m, &d->grid, t, 2, &lo, &hi);
            if (slab_range(lo, hi, p->ss, nplanes, &j0, &j1))
                p->slab_refs += (uint64_t)(j1 - j0 + 1);
        }
        /* Triangles that span many slabs (few large ones are fine, many
         * are not) would make the slab lists huge: sum every slice afresh
         * then, as the seed does. */
        uint64_t cap = (uint64_t)m->ntris * 8 + ((uint64_t)64 << 20) / 12;
        p->incremental = p->slab_refs <= cap;
        if (!p->incremental) p->slab_refs = 0;
    }

    if (d->max_memory) {
        /* What does not shrink with the chunk: the output, the mesh on the
         * GPU (vertices, one sorted index buffer per axis), the sort keys,
         * one batch of one slice. */
        uint64_t fixed = vx_bitgrid_bytes(p->dims, p->ss) + (uint64_t)m->nverts * 12 +
                         vx_xing_bytes(m) + (uint64_t)m->ntris * 20 * (uint64_t)p->naxes +
                         (uint64_t)m->ntris * sizeof(tri_key) + target_bytes(p, 1) +
                         p->slab_refs * 20 * 2 + ((uint64_t)p->dims[2] * p->ss + 1) * 8;
        /* Per z-layer of a chunk: the SSBOs, and for robust the CPU copies
         * of the three axes' answers. */
        uint64_t per_k = (p->bits_layer + p->counts_layer) * (p->naxes == 3 ? 4 : 1);
        if (fixed + per_k > d->max_memory)
            return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                              "a %dx%dx%d grid needs at least %llu bytes, the limit is %llu",
                              p->dims[0], p->dims[1], p->dims[2],
                              (unsigned long long)(fixed + per_k),
                              (unsigned long long)d->max_memory);
        uint64_t left = d->max_memory - fixed;
        /* Give the chunk what it needs (fewer chunks redraw less), then
         * whatever is left to the batch. */
        if (left / per_k < nk) nk = left / per_k;
        left -= nk * per_k;
        uint64_t extra = left / target_bytes(p, 1);
        if ((uint64_t)batch > extra + 1) batch = (int)(extra + 1);
    }
    p->nk = (int)nk;
    p->batch = batch;
    return 0;
}

/* Bucket the triangles by slab (CSR: slab j's triangles are entries
 * slab_start[j] .. slab_start[j+1] of the slab index buffer). */
static int upload_slabs(vx_gl *gl, const vx_mesh *m, const vx_grid *g, const plan *p, objs *o,
                        size_t **slab_start, vx_err *err)
{
    int nplanes = p->dims[2] * p->ss, j0, j1;
    size_t *start = calloc((size_t)nplanes + 2, sizeof *start);
    uint32_t *idx = malloc(p->slab_refs * 3 * sizeof *idx + 1);
    if (!start || !idx) {
        free(start);
        free(idx);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %llu slab entries",
                          (unsigned long long)p->slab_refs);
    }
    for (size_t t = 0; t < m->ntris; t++) {
        float lo, hi;
        tri_wrange(m, g, t, 2, &lo, &hi);
        if (slab_range(lo, hi, p->ss, nplanes, &j0, &j1))
            for (int j = j0; j <= j1; j++)
                start[j + 1]++;
    }
    for (int j = 0; j < nplanes; j++)
        start[j + 1] += start[j];
    for (size_t t = 0; t < m->ntris; t++) {
        float lo, hi;
        tri_wrange(m, g, t, 2, &lo, &hi);
        if (slab_range(lo, hi, p->ss, nplanes, &j0, &j1))
            for (int j = j0; j <= j1; j++)
                memcpy(idx + 3 * start[j]++, m->tri + 3 * t, 12);
    }
    /* the fill advanced each start to the next one's: shift back */
    for (int j = nplanes; j > 0; j--)
        start[j] = start[j - 1];
    start[0] = 0;
    *slab_start = start;
    glCreateBuffers(1, &o->slab_ibo);
    glNamedBufferStorage(o->slab_ibo, (GLsizeiptr)(p->slab_refs * 12 + 12), NULL,
                         GL_DYNAMIC_STORAGE_BIT);
    if (p->slab_refs) glNamedBufferSubData(o->slab_ibo, 0, (GLsizeiptr)(p->slab_refs * 12), idx);
    free(idx);
    return vx_gl_check(gl, "slice.slab_buffer", err);
}

/* Normalises positions into the grid frame in double (origin 0, voxel edge
 * 1, snapped: vx_grid_unit) and only then converts to float: a face on a
 * cell boundary lands on an exact integer, so no voxel centre (at +1/2) is
 * ever in doubt for it. */
static int upload(vx_gl *gl, const vx_mesh *m, const vx_grid *g, const plan *p, objs *o,
                  float wmin_all[3], float wmax_all[3], float **wmax_sorted, size_t **slab_start,
                  vx_err *err)
{
    float *pos = malloc(m->nverts * 3 * sizeof *pos + 1);
    tri_key *keys = malloc(m->ntris * sizeof *keys + 1);
    uint32_t *idx = malloc(m->ntris * 3 * sizeof *idx + 1);
    int rc = -1;
    if (!pos || !keys || !idx) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to upload %zu vertices",
                   m->nverts);
        goto done;
    }
    for (int a = 0; a < 3; a++) {
        wmin_all[a] = INFINITY;
        wmax_all[a] = -INFINITY;
    }
    for (size_t i = 0; i < m->nverts; i++)
        for (int a = 0; a < 3; a++) {
            pos[3 * i + a] = grid_coord(m, g, i, a);
            if (pos[3 * i + a] > wmax_all[a]) wmax_all[a] = pos[3 * i + a];
            if (pos[3 * i + a] < wmin_all[a]) wmin_all[a] = pos[3 * i + a];
        }
    glCreateBuffers(1, &o->vbo);
    glNamedBufferStorage(o->vbo, (GLsizeiptr)(m->nverts * 3 * sizeof *pos), pos, 0);
    if (vx_gl_check(gl, "slice.vertex_buffer", err)) goto done;

    for (int a = 0; a < p->naxes; a++) {
        int w = p->axes[a];
        for (size_t t = 0; t < m->ntris; t++) {
            const uint32_t *v = m->tri + 3 * t;
            float z = pos[3 * v[0] + w];
            if (pos[3 * v[1] + w] > z) z = pos[3 * v[1] + w];
            if (pos[3 * v[2] + w] > z) z = pos[3 * v[2] + w];
            keys[t].wmax = z;
            keys[t].t = (uint32_t)t;
        }
        qsort(keys, m->ntris, sizeof *keys, cmp_key);
        wmax_sorted[a] = malloc(m->ntris * sizeof(float) + 1);
        if (!wmax_sorted[a]) {
            vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %zu triangles", m->ntris);
            goto done;
        }
        for (size_t t = 0; t < m->ntris; t++) {
            const uint32_t *v = m->tri + 3 * (size_t)keys[t].t;
            memcpy(idx + 3 * t, v, 3 * sizeof *idx);
            wmax_sorted[a][t] = keys[t].wmax;
        }
        glCreateBuffers(1, &o->ibo[a]);
        glNamedBufferStorage(o->ibo[a], (GLsizeiptr)(m->ntris * 3 * sizeof *idx), idx, 0);
        if (vx_gl_check(gl, "slice.index_buffer", err)) goto done;
    }

    if (p->incremental && upload_slabs(gl, m, g, p, o, slab_start, err)) goto done;

    o->vao = vx_gl_position_vao(o->vbo, 0);
    if (vx_xing_init(&o->xing, gl, m, g, err)) goto done;
    rc = vx_gl_check(gl, "slice.vertex_array", err);
done:
    free(pos);
    free(keys);
    free(idx);
    return rc;
}

static int targets(vx_gl *gl, const plan *p, objs *o, vx_err *err)
{
    int layers = p->batch * p->ss;
    glCreateTextures(GL_TEXTURE_2D_ARRAY, 1, &o->tex_color);
    glTextureStorage3D(o->tex_color, 1, GL_R32F, p->tex_w, p->tex_h, layers);
    glTextureParameteri(o->tex_color, GL_TEXTURE_MIN_FILTER, GL_NEAREST);
    glTextureParameteri(o->tex_color, GL_TEXTURE_MAG_FILTER, GL_NEAREST);
    glCreateFramebuffers(1, &o->fbo);
    glNamedFramebufferTextureLayer(o->fbo, GL_COLOR_ATTACHMENT0, o->tex_color, 0, 0);
    if (vx_gl_check(gl, "slice.targets", err)) return -1;
    GLenum st = glCheckNamedFramebufferStatus(o->fbo, GL_FRAMEBUFFER);
    if (st != GL_FRAMEBUFFER_COMPLETE) {
        VX_ERROR("slice.fbo_incomplete", "status=0x%x w=%d h=%d", st, p->tex_w, p->tex_h);
        return vx_err_set(err, VX_EGPU, "gl_error", "slice framebuffer %dx%d is incomplete (0x%x)",
                          p->tex_w, p->tex_h, st);
    }
    uint64_t bits = (uint64_t)p->nk * p->bits_layer, counts = (uint64_t)p->nk * p->counts_layer;
    glCreateBuffers(1, &o->ssbo_bits);
    glNamedBufferStorage(o->ssbo_bits, (GLsizeiptr)bits, NULL,
                         GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
    glCreateBuffers(1, &o->ssbo_counts);
    glNamedBufferStorage(o->ssbo_counts, (GLsizeiptr)(counts ? (counts + 3) / 4 * 4 : 4), NULL,
                         GL_DYNAMIC_STORAGE_BIT | GL_MAP_READ_BIT);
    glCreateBuffers(1, &o->pbo);
    glNamedBufferStorage(o->pbo, (GLsizeiptr)target_color_bytes(p, p->batch), NULL, 0);
    return vx_gl_check(gl, "slice.storage", err);
}

/* First triangle of the sorted list whose largest w is beyond the plane. */
static size_t first_beyond(const float *wmax, size_t n, float plane)
{
    size_t lo = 0, hi = n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (wmax[mid] > plane)
            hi = mid;
        else
            lo = mid + 1;
    }
    return lo;
}

typedef struct run {
    vx_gl *gl;
    const vx_mesh *m;
    const vx_voxelize_desc *d;
    const plan *p;
    objs *o;
    GLuint draw_prog, pack_prog;
    float wmin_all[3], wmax_all[3];
    float *wmax_sorted[3];
    size_t *slab_start; /* nonzero: CSR offsets into the slab index buffer */
    vx_voxelize_stats *st;
    double slices_total, slices_done;
} run;

/* Draws triangles [first, end) of element buffer ibo. */
static void draw_range(run *r, GLuint ibo, size_t first, size_t end)
{
    glVertexArrayElementBuffer(r->o->vao, ibo);
    vx_xing_bind(&r->o->xing, r->draw_prog, ibo);
    if (end > first) vx_xing_draw(r->draw_prog, first, end - first);
}

/* Sets the draw program's w range, for axis index a, to the whole mesh's. */
static void set_w_range(run *r, int a)
{
    const plan *p = r->p;
    /* No clipping at all: the near plane of the seed is the fragment
     * shader's test on w. A GL near plane on the slice plane would clip
     * the triangles that cross it, and the interpolation across the
     * clipped vertices then misjudges centres near the plane (56 of 2.4
     * million voxels for spot at 256^3). Unclipped, every draw
     * rasterizes a triangle identically, so in the incremental signed
     * count each fragment falls in exactly one slab. */
    float lo = r->wmin_all[p->axes[a]] - 1.0f, hi = r->wmax_all[p->axes[a]] + 1.0f;
    if (!(hi > lo)) hi = lo + 1.0f;
    glProgramUniform2f(r->draw_prog, 3, lo, 2.0f / (hi - lo));
}

/* Draws the surfaces for slice plane j (at w = (j + 1/2) / ss) of axis
 * index a: every one beyond it, or (incremental) those in the slab since
 * the previous plane. The fragment shader decides exactly (xing()); the
 * triangle lists only need to hold every triangle it could keep. */
static void draw_plane(run *r, int a, int j, int incremental)
{
    const plan *p = r->p;
    const size_t ntris = r->m->ntris;
    if (!incremental) {
        float plane = ((float)j + 0.5f) / (float)p->ss;
        glProgramUniform2i(r->draw_prog, 2, j, 0);
        glProgramUniform1i(r->draw_prog, 4, 1);
        draw_range(r, r->o->ibo[a], first_beyond(r->wmax_sorted[a], ntris, plane - SLAB_MARGIN),
                   ntris);
    } else {
        glProgramUniform2i(r->draw_prog, 2, j - 1, j);
        glProgramUniform1i(r->draw_prog, 4, 2);
        draw_range(r, r->o->slab_ibo, r->slab_start[j], r->slab_start[j + 1]);
    }
}

/* Reads the batch's nb slices from b0 into the pixel buffer and packs
 * them into the chunk's SSBOs (from z-layer k0) on the GPU. */
static void pack_batch(run *r, const int *pm, int k0, const int rect[4], int b0, int nb)
{
    const plan *p = r->p;
    /* The pack reads the images as plain memory (see the shader). */
    int iw = rect[2] * p->ss, ih = rect[3] * p->ss, nl = nb * p->ss;
    /* R8 rows padded to 4 bytes: the pack reads four pixels per load */
    int stride = iw;
    uint64_t img_bytes = (uint64_t)stride * (uint64_t)ih * (uint64_t)nl * 4;
    glBindBuffer(GL_PIXEL_PACK_BUFFER, r->o->pbo);
    glPixelStorei(GL_PACK_ALIGNMENT, 4);
    glPixelStorei(GL_PACK_ROW_LENGTH, 0);
    glPixelStorei(GL_PACK_IMAGE_HEIGHT, 0);
    glPixelStorei(GL_PACK_SKIP_PIXELS, 0);
    glPixelStorei(GL_PACK_SKIP_ROWS, 0);
    glPixelStorei(GL_PACK_SKIP_IMAGES, 0);
    glGetTextureSubImage(r->o->tex_color, 0, 0, 0, 0, iw, ih, nl, GL_RED, GL_FLOAT,
                         (GLsizei)img_bytes, NULL);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);

    glUseProgram(r->pack_prog);
    glBindBufferRange(GL_SHADER_STORAGE_BUFFER, 2, r->o->pbo, 0,
                      (GLsizeiptr)((img_bytes + 3) / 4 * 4));
    glProgramUniform2i(r->pack_prog, 10, stride, ih);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, r->o->ssbo_bits);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, r->o->ssbo_counts);
    int packx = pm[0] == 0;
    glProgramUniform3i(r->pack_prog, 0, pm[0], pm[1], pm[2]);
    glProgramUniform4i(r->pack_prog, 1, rect[0], rect[1], rect[2], rect[3]);
    glProgramUniform2i(r->pack_prog, 2, b0, nb);
    glProgramUniform3i(r->pack_prog, 3, p->dims[0], p->dims[1], p->dims[2]);
    glProgramUniform2i(r->pack_prog, 4, k0, (int)p->wx);
    glProgramUniform1i(r->pack_prog, 5, p->ss);
    glProgramUniform1i(r->pack_prog, 6, p->count ? 2 : 1);
    glProgramUniform1i(r->pack_prog, 7, p->threshold);
    glProgramUniform1i(r->pack_prog, 8, p->ss == 2);
    glProgramUniform1i(r->pack_prog, 9, packx);
    uint64_t n;
    if (packx) {
        n = (uint64_t)(rect[2] + 31) / 32 * (uint64_t)rect[3] * (uint64_t)nb;
    } else {
        /* one invocation per output word: grid x runs along the slices
         * (stepping along x) or the image rows (along y) */
        int dx = pm[1] == 0 ? 1 : 2, ext[3] = {rect[2], rect[3], nb};
        int x_lo = dx == 1 ? rect[1] : b0, x_hi = x_lo + ext[dx];
        uint64_t nruns = (uint64_t)(((x_hi - 1) >> 5) - (x_lo >> 5) + 1);
        n = nruns * (uint64_t)ext[0] * (uint64_t)ext[1] * (uint64_t)ext[2] / (uint64_t)ext[dx];
    }
    uint64_t groups = (n + 63) / 64;
    /* 65535 groups per dimension (llvmpipe): 2-D dispatch. */
    uint64_t gx = groups < 65535 ? groups : 65535, gy = (groups + gx - 1) / gx;
    glDispatchCompute((GLuint)gx, (GLuint)gy, 1);
    glUseProgram(0);
}

/* Counts nb more slices done and reports the progress; nonzero when the
 * caller's hook stops the run. */
static int slices_done(run *r, int nb, vx_err *err)
{
    r->st->slices += nb;
    r->slices_done += nb;
    if (r->d->progress) {
        vx_err_clear(err);
        if (r->d->progress(r->d->ud, r->slices_done / r->slices_total, err)) {
            if (err && err->kind == VX_EOK)
                vx_err_set(err, VX_ECANCELED, "canceled", "voxelization stopped");
            return -1;
        }
    }
    return 0;
}

/* Draws and packs the slices w in [w0, w1) of one image tile along axis
 * index a into the chunk's SSBOs. */
static int do_tile(run *r, int a, int k0, const int rect[4], int w0, int w1, vx_err *err)
{
    const plan *p = r->p;
    const int *pm = k_perm[p->axes[a]];
    /* nonzero: the first plane of the run sums every surface beyond it;
     * each later one updates the previous plane's sum by one slab. */
    const int jfirst = w0 * p->ss;
    int prev_layer = -1;
    set_w_range(r, a);
    for (int b0 = w0; b0 < w1; b0 += p->batch) {
        int nb = w1 - b0 < p->batch ? w1 - b0 : p->batch;
        glBindFramebuffer(GL_FRAMEBUFFER, r->o->fbo);
        /* A viewport that holds the mesh (xing.h), scissored to the
         * tile's image: window = (grid units - tile corner) * ss, exactly. */
        int iw = rect[2] * p->ss, ih = rect[3] * p->ss;
        const int off[2] = {rect[0], rect[1]};
        const double lo[2] = {r->wmin_all[pm[0]], r->wmin_all[pm[1]]},
                     hi[2] = {r->wmax_all[pm[0]], r->wmax_all[pm[1]]};
        float ndc[4];
        vx_xing_viewport(iw, ih, off, p->ss, lo, hi, ndc);
        glEnable(GL_SCISSOR_TEST);
        glScissor(0, 0, iw, ih);
        glUseProgram(r->draw_prog);
        glBindVertexArray(r->o->vao);
        glProgramUniform3i(r->draw_prog, 0, pm[0], pm[1], pm[2]);
        glProgramUniform4f(r->draw_prog, 1, ndc[0], ndc[1], ndc[2], ndc[3]);
        glProgramUniform2i(r->draw_prog, 7, rect[0] * p->ss, rect[1] * p->ss);
        vx_gl_timer timer = {0};
        int timing = 0;
        for (int s = 0; s < nb; s++)
            for (int l = 0; l < p->ss; l++) {
                /* Plane through the voxel centres, or (seed 003 §3.4) the
                 * two planes a quarter voxel either side of them. */
                int layer = s * p->ss + l, j = (b0 + s) * p->ss + l;
                glNamedFramebufferTextureLayer(r->o->fbo, GL_COLOR_ATTACHMENT0, r->o->tex_color, 0,
                                               layer);
                /* the slab lists are along z */
                int incremental = p->incremental && p->axes[a] == 2 && j > jfirst;
                const float zero[4] = {0, 0, 0, 0};
                if (incremental) {
                    /* The sum beyond the previous plane, less the surfaces
                     * in the slab between the two planes. */
                    if (prev_layer != layer)
                        glCopyImageSubData(r->o->tex_color, GL_TEXTURE_2D_ARRAY, 0, 0, 0,
                                           prev_layer, r->o->tex_color, GL_TEXTURE_2D_ARRAY, 0, 0,
                                           0, layer, rect[2] * p->ss, rect[3] * p->ss, 1);
                } else {
                    glClearNamedFramebufferfv(r->o->fbo, GL_COLOR, 0, zero);
                }
                if (!timing) {
                    /* Begun after the first clear: llvmpipe loses the start
                     * of a query begun before the first command on a newly
                     * bound framebuffer (see preview/render.c). */
                    vx_gl_timer_begin(&timer);
                    timing = 1;
                }
                draw_plane(r, a, j, incremental);
                prev_layer = layer;
            }
        glBindVertexArray(0);
        glDisable(GL_SCISSOR_TEST);
        vx_xing_unbind();
        glBindFramebuffer(GL_FRAMEBUFFER, 0);

        pack_batch(r, pm, k0, rect, b0, nb);
        if (timing) r->st->gpu_slice_ms += vx_gl_timer_end_ms(&timer);
        if (vx_gl_check(r->gl, "slice.draw", err)) return -1;
        if (slices_done(r, nb, err)) return -1;
    }
    return 0;
}

/* Runs every slice of axis index a that touches the z-layers [k0, k1) of the
 * chunk, tile by tile, into the cleared SSBOs. */
static int do_axis(run *r, int a, int k0, int k1, vx_err *err)
{
    const plan *p = r->p;
    const int *pm = k_perm[p->axes[a]];
    int lo[3] = {0, 0, k0}, hi[3] = {p->dims[0], p->dims[1], k1};
    const GLuint zero = 0;
    glClearNamedBufferData(r->o->ssbo_bits, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
    glClearNamedBufferData(r->o->ssbo_counts, GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
    for (int v0 = lo[pm[1]]; v0 < hi[pm[1]]; v0 += p->tile)
        for (int u0 = lo[pm[0]]; u0 < hi[pm[0]]; u0 += p->tile) {
            int rect[4] = {u0, v0, hi[pm[0]] - u0, hi[pm[1]] - v0};
            if (rect[2] > p->tile) rect[2] = p->tile;
            if (rect[3] > p->tile) rect[3] = p->tile;
            if (do_tile(r, a, k0, rect, lo[pm[2]], hi[pm[2]], err)) return -1;
        }
    return 0;
}

static int readback(vx_gl *gl, GLuint buf, void *dst, uint64_t bytes, vx_voxelize_stats *st,
                    vx_err *err)
{
    double t0 = vx_mono_ms();
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    glGetNamedBufferSubData(buf, 0, (GLsizeiptr)bytes, dst);
    st->readback_ms += vx_mono_ms() - t0;
    return vx_gl_check(gl, "slice.readback", err);
}

static int median3(int a, int b, int c)
{
    if (a > b) {
        int t = a;
        a = b;
        b = t;
    }
    return c < a ? a : c > b ? b : c;
}

/* Refuses what method slice cannot do and invalid params, grids or meshes. */
static int check_slice_input(const vx_mesh *m, const vx_voxelize_desc *d, vx_err *err)
{
    if (d->fill == VX_FILL_SURFACE)
        return vx_err_set(err, VX_EUNPROC, "unsupported",
                          "method slice fills solids only; fill surface is not supported");
    if (d->inside < VX_INSIDE_NONZERO || d->inside > VX_INSIDE_ROBUST)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "unknown inside rule %d", d->inside);
    if (d->supersample != 0 && d->supersample != 1 && d->supersample != 2)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "supersample must be 1 or 2, not %d",
                          d->supersample);
    if (d->supersample == 2 && (d->threshold < 0 || d->threshold > 8))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "threshold must be 1..8, not %d",
                          d->threshold);
    const vx_grid *g = &d->grid;
    for (int a = 0; a < 3; a++)
        if (g->dims[a] < 1 || g->dims[a] > 1 << 20)
            return vx_err_set(err, VX_EUNPROC, "invalid_params", "grid dims %dx%dx%d", g->dims[0],
                              g->dims[1], g->dims[2]);
    if (!(g->h > 0) || !isfinite(g->h))
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "voxel edge %g", g->h);
    /* A bad index would make the GPU read outside the vertex buffer. */
    return vx_mesh_check_indices(m, err);
}

/* Sets the GL state fixed for the whole run (other code may have left any). */
static void set_fixed_state(const plan *p, GLuint draw_prog)
{
    glDisable(GL_CULL_FACE);
    glDisable(GL_SCISSOR_TEST);
    glDisable(GL_STENCIL_TEST);
    glDisable(GL_POLYGON_OFFSET_FILL);
    glDisable(GL_DEPTH_CLAMP);
    glDisable(GL_RASTERIZER_DISCARD);
    glDisable(GL_COLOR_LOGIC_OP);
    glDisable(GL_MULTISAMPLE);
    glClipControl(GL_LOWER_LEFT, GL_NEGATIVE_ONE_TO_ONE);
    glFrontFace(GL_CCW); /* the shaders' facing rule depends on it */
    glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    glDepthRange(0.0, 1.0);
    glProgramUniform1i(draw_prog, 4, 1);
    glProgramUniform1i(draw_prog, 6, p->count);
    glProgramUniform1i(draw_prog, 8, p->ss);
    glDisable(GL_DEPTH_TEST);
    glEnable(GL_BLEND);
    glBlendEquation(GL_FUNC_ADD);
    glBlendFunc(GL_ONE, GL_ONE);
}

/* Robust inside test: combines the three axes' results of a chunk of nk
 * z-layers (tmp[a]: bits, then nbits on the counts) by majority, or by the
 * median count with supersampling. */
static void combine_axes(const plan *p, uint8_t *const tmp[3], uint64_t nbits, int nk,
                         uint32_t *bits_dst, uint8_t *counts_dst)
{
    if (p->naxes == 3 && p->ss == 1) {
        /* Majority of the three axes, 32 voxels at a time. */
        const uint32_t *x = (const uint32_t *)tmp[0], *y = (const uint32_t *)tmp[1],
                       *z = (const uint32_t *)tmp[2];
        for (size_t i = 0; i < nbits / 4; i++)
            bits_dst[i] = (x[i] & y[i]) | (y[i] & z[i]) | (x[i] & z[i]);
    } else if (p->naxes == 3) {
        /* Median of the three counts: the majority rule generalised. */
        int nx = p->dims[0];
        for (size_t row = 0; row < (size_t)nk * (size_t)p->dims[1]; row++)
            for (int i = 0; i < nx; i++) {
                size_t q = row * (size_t)nx + (size_t)i;
                int med = median3(tmp[0][nbits + q], tmp[1][nbits + q], tmp[2][nbits + q]);
                counts_dst[q] = (uint8_t)med;
                if (med >= p->threshold) bits_dst[row * p->wx + (size_t)(i >> 5)] |= 1u << (i & 31);
            }
    }
}

/* Voxelizes chunk c (its z-layers) along every axis into out; tmp holds
 * the three axes' results for the robust inside test. */
static int do_chunk(run *r, int c, uint8_t *const tmp[3], vx_bitgrid *out, vx_err *err)
{
    const plan *p = r->p;
    int k0 = c * p->nk, k1 = k0 + p->nk < p->dims[2] ? k0 + p->nk : p->dims[2];
    uint64_t nbits = (uint64_t)(k1 - k0) * p->bits_layer;
    uint64_t ncounts = (uint64_t)(k1 - k0) * p->counts_layer;
    uint32_t *bits_dst = out->bits + (size_t)k0 * p->bits_layer / 4;
    uint8_t *counts_dst = out->counts ? out->counts + (size_t)k0 * p->counts_layer : NULL;
    for (int a = 0; a < p->naxes; a++) {
        if (do_axis(r, a, k0, k1, err)) return -1;
        void *bdst = p->naxes == 3 ? (void *)tmp[a] : (void *)bits_dst;
        uint8_t *cdst = p->naxes == 3 ? tmp[a] + nbits : counts_dst;
        if (readback(r->gl, r->o->ssbo_bits, bdst, nbits, r->st, err)) return -1;
        if (ncounts && readback(r->gl, r->o->ssbo_counts, cdst, ncounts, r->st, err)) return -1;
    }
    if (p->naxes == 3) combine_axes(p, tmp, nbits, k1 - k0, bits_dst, counts_dst);
    return 0;
}

int vx_voxelize_slice(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err)
{
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    st->method = "slice";
    memset(out, 0, sizeof *out);
    if (check_slice_input(m, d, err)) return -1;
    const vx_grid *g = &d->grid;

    plan p;
    if (make_plan(m, d, &p, err)) return -1;
    GLuint draw_prog = vx_gl_program(gl, "voxel_slice.vert", "voxel_slice.frag", err);
    if (!draw_prog) return -1;
    GLuint pack_prog = vx_gl_compute_program(gl, "voxel_slice_pack.comp", err);
    if (!pack_prog) return -1;
    if (vx_bitgrid_alloc(out, g, p.ss == 2, err)) return -1;
    /* Errors left by earlier work must not be blamed on this run. */
    if (glGetError() != GL_NO_ERROR) {
        VX_WARN("slice.stale_gl_error", "where=before_voxelize");
        while (glGetError() != GL_NO_ERROR) {
        }
    }

    objs o = {0};
    run r = {.gl = gl,
             .m = m,
             .d = d,
             .p = &p,
             .o = &o,
             .draw_prog = draw_prog,
             .pack_prog = pack_prog,
             .st = st};
    uint8_t *tmp[3] = {NULL, NULL, NULL};
    int rc = -1;
    double t0 = vx_mono_ms();
    if (m->ntris &&
        upload(gl, m, g, &p, &o, r.wmin_all, r.wmax_all, r.wmax_sorted, &r.slab_start, err))
        goto fail;
    glFinish(); /* so upload_ms is the upload, not just its queueing */
    st->upload_ms = vx_mono_ms() - t0;
    if (!m->ntris) goto done; /* nothing is inside */
    if (targets(gl, &p, &o, err)) goto fail;
    uint64_t chunk_bits = (uint64_t)p.nk * p.bits_layer,
             chunk_counts = (uint64_t)p.nk * p.counts_layer;
    if (p.naxes == 3)
        for (int a = 0; a < 3; a++)
            if (!(tmp[a] = malloc(chunk_bits + chunk_counts + 1))) {
                vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a chunk");
                goto fail;
            }

    set_fixed_state(&p, draw_prog);

    int nchunks = (p.dims[2] + p.nk - 1) / p.nk;
    st->chunks = nchunks;
    r.slices_total = 0;
    for (int a = 0; a < p.naxes; a++)
        r.slices_total += p.axes[a] == 2 ? p.dims[2] : (double)p.dims[p.axes[a]] * nchunks;
    for (int c = 0; c < nchunks; c++)
        if (do_chunk(&r, c, tmp, out, err)) goto fail;
done:
    st->voxels_inside = vx_bitgrid_count(out);
    rc = 0;
fail:
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glBindVertexArray(0);
    glUseProgram(0);
    glBindTextureUnit(0, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, 0);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    glDisable(GL_BLEND);
    glDisable(GL_DEPTH_TEST);
    for (int a = 0; a < 3; a++) {
        free(r.wmax_sorted[a]);
        free(tmp[a]);
    }
    free(r.slab_start);
    objs_free(&o);
    if (rc) vx_bitgrid_free(out);
    return rc;
}
