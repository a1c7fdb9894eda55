/* Solid voxelization by crossing counts in a single pass (voxel.h, method
 * `scan`), on the GL thread.
 *
 * Depth peeling (peel.c) draws the mesh once per depth layer and needs
 * layer arrays; here every crossing is counted in one draw:
 *   1. draw (voxel_peel.vert + voxel_scan.frag): all the triangles that
 *      reach the slab, orthographic along x exactly as peel's first pass
 *      (an ny x rows image, pixel centre = voxel centre in y, z), depth test
 *      off, no culling, no attachments. Each fragment is a crossing at x = t
 *      (grid units, xing(): the same value peel sees) and adds its sign
 *      (+1 facing +x, -1 facing -x, as peel's nonzero) to a per-voxel delta
 *      counter: the slot of the last voxel whose centre lies before t (the
 *      [entry, exit) tie rule), or the row's tail counter when t is beyond
 *      the last centre; crossings before the first centre count for no
 *      voxel and are dropped. Counting runs from each centre towards +x,
 *      like peel's fill and the CPU reference, so results match peel also
 *      on open meshes and on grids that cut the mesh.
 *   2. sum (voxel_scan_sum.comp): one invocation per x row adds the slots
 *      from the row's end down and writes whole 32-bit words of bits in the
 *      voxel.h layout; the draw also sets one "block" bit per output word
 *      that received a crossing, and words whose bit is clear are written
 *      whole without reading their counters (O(words + crossings), like
 *      peel's fill, instead of O(voxels)) (nonzero: sum != 0; parity: sum odd; a signed sum has
 *      the parity of the number of crossings, so one counter serves both),
 *      zeroing the counters behind it for the next slab.
 *   3. the slab's bits are read back into out->bits.
 *
 * Delta storage: signed 16-bit fields, two per uint (2 bytes per voxel),
 * updated with atomicAdd on the shifted value; the word is decoded as a
 * signed-digit number so carries between the halves do no harm. That is
 * exact while the net count of crossings falling into one voxel cell of one
 * ray stays within [-32768, 32767] (peel's per-layer counts have a 16-bit
 * limit too). 8-bit fields would halve the buffer but a mesh with more than
 * 127 coincident faces in one cell (duplicated shells, stacked copies) is
 * plausible; 32767 in one voxel along one ray is not. The shader still
 * detects the first atomic that would leave the range and the job fails
 * with too_many_crossings; `auto` then runs peel.
 *
 * The delta buffer (nx/2 uints per row) is the big allocation: the grid is
 * cut into z slabs so that it stays under GL_MAX_SHADER_STORAGE_BLOCK_SIZE,
 * the job's max_memory and SCAN_DELTA_CAP, and each slab draws only the
 * triangles that reach it (peel's slab buckets).
 *
 * Crossings are decided by xing() (shaders/voxel_xing.glsl, xing.h) from
 * the lattice's own numbers, so scan, peel (the same x rays) and every
 * brick or slab height of a lattice give the same voxels, bit for bit.
 *
 * robust (majority of parity along x, y, z) and fill=surface run peel
 * (vx_voxelize_peel; st->method says "peel"). supersample 2 is not
 * supported (vx_voxelize refuses it as for peel). st->layers is 0. Timers:
 * gpu_peel_ms is the draw, gpu_fill_ms the sums. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "voxel/peel_int.h"
#include "voxel/voxel.h"

/* Bytes of delta counters per slab. Well under the SSBO limit: on llvmpipe
 * a slab whose counters stay in the CPU caches between the draw and the
 * sums, and a small buffer to clear (first touch of a 128 MiB buffer costs
 * ~60 ms), are faster than few big slabs (spot 1024^3: 9 slabs of 128 MiB
 * 370 ms, 8 MiB slabs 265 ms); below ~16 MiB the per-slab round trips
 * (draw, sums, read-back) take over on wide grids (bunny 1024^3: 4 MiB
 * 520 ms, 8 MiB 334 ms, 16 and 32 MiB 281 ms; spot, ogre and the 828k-face
 * fandisk are 5-15 % faster at 16 than at 8 MiB). */
#define SCAN_DELTA_CAP (16u << 20)

/* uints per delta row: two 16-bit slots each. */
static uint64_t delta_row_uints(const peel_ctx *c)
{
    return ((uint64_t)c->dims[0] + 1) / 2;
}

/* Delta counters + row tails of a slab of `rows` z rows. */
static uint64_t delta_bytes(const peel_ctx *c, int rows)
{
    return delta_row_uints(c) * 4u * (uint64_t)c->dims[1] * (uint64_t)rows;
}

static uint64_t tail_bytes(const peel_ctx *c, int rows)
{
    return 4u * (uint64_t)c->dims[1] * (uint64_t)rows;
}

/* Block bits: one per output word (32 voxels), uints per row. */
static uint64_t block_row_uints(const peel_ctx *c)
{
    return ((uint64_t)c->wx + 31) / 32;
}

static uint64_t block_bytes(const peel_ctx *c, int rows)
{
    return block_row_uints(c) * 4u * (uint64_t)c->dims[1] * (uint64_t)rows;
}

/* Memory a slab height needs: CPU grid, mesh buffers, bit slab, delta
 * counters and tails. */
static uint64_t estimate(const peel_ctx *c, int rows)
{
    uint64_t b = vx_bitgrid_bytes(c->dims, 1);
    b += (uint64_t)c->m->nverts * 12u + (uint64_t)c->m->ntris * 12u + vx_xing_bytes(c->m);
    return b + vx_peel_slab_bytes(c, rows) + delta_bytes(c, rows) + tail_bytes(c, rows) +
           block_bytes(c, rows) + 4u;
}

static int plan(peel_ctx *c)
{
    const vx_gl_info *in = vx_gl_get_info(c->gl);
    GLint vp[2] = {0, 0}, fw = 0, fh = 0;
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, vp);
    glGetIntegerv(GL_MAX_FRAMEBUFFER_WIDTH, &fw);
    glGetIntegerv(GL_MAX_FRAMEBUFFER_HEIGHT, &fh);
    long wmax = vp[0] < fw ? vp[0] : fw, hmax = vp[1] < fh ? vp[1] : fh;
    /* power-of-two viewports (xing.h) no larger than the GPU allows */
    while (hmax > 1 && vx_xing_pow2((int)hmax) > vp[1])
        hmax /= 2;
    if (vx_xing_pow2(c->dims[1]) > wmax || vx_xing_pow2(c->dims[1]) > vp[0])
        return vx_err_set(c->err, VX_ETOOBIG, "grid_too_large",
                          "a %dx%dx%d grid needs scan images wider than this GPU's %ld pixels",
                          c->dims[0], c->dims[1], c->dims[2], wmax);
    uint64_t row_bytes = delta_bytes(c, 1);
    uint64_t rows = (uint64_t)in->max_ssbo_bytes / row_bytes;
    if (rows == 0)
        return vx_err_set(c->err, VX_ETOOBIG, "grid_too_large",
                          "one z layer of %dx%d voxel counters (%llu bytes) exceeds this GPU's "
                          "storage block size (%ld bytes)",
                          c->dims[0], c->dims[1], (unsigned long long)row_bytes,
                          in->max_ssbo_bytes);
    uint64_t cap = SCAN_DELTA_CAP / row_bytes;
    if (rows > cap) rows = cap > 0 ? cap : 1;
    if (rows > (uint64_t)c->dims[2]) rows = (uint64_t)c->dims[2];
    if (rows > (uint64_t)hmax) rows = (uint64_t)hmax;
    if (c->d->max_slab_rows > 0 && rows > (uint64_t)c->d->max_slab_rows)
        rows = (uint64_t)c->d->max_slab_rows;
    if (rows < 1) rows = 1;
    /* Shrink slabs until the job fits its memory; the CPU grid is fixed. */
    while (rows > 1 && estimate(c, (int)rows) > c->limit)
        rows = (rows + 1) / 2;
    uint64_t need = estimate(c, (int)rows);
    if (need > c->limit) return vx_peel_too_big(c, need);
    c->rows = (int)rows;
    c->nslabs = (int)(((uint64_t)c->dims[2] + rows - 1) / rows);
    c->first_layers = 0;
    c->fixed_bytes = need;
    return 0;
}

/* Step 1 for slab rows k0..k0+rows-1: every crossing into the counters. */
static int draw(peel_ctx *c, int k0, int rows)
{
    peel_objs *o = &c->o;
    const int w = c->dims[1], h = rows;
    glNamedFramebufferParameteri(o->scan_fbo, GL_FRAMEBUFFER_DEFAULT_WIDTH, w);
    glNamedFramebufferParameteri(o->scan_fbo, GL_FRAMEBUFFER_DEFAULT_HEIGHT, h);
    GLuint p = c->prog_scan;
    /* voxel_peel.vert: ray x, window (y, z - k0); the framebuffer's w x h
     * bounds the fragments, the viewport holds the mesh (xing.h) */
    const int off[2] = {0, k0};
    const double lo[2] = {c->tlo[1], c->tlo[2]}, hi[2] = {c->thi[1], c->thi[2]};
    float ndc[4];
    vx_xing_viewport(w, h, off, 1, lo, hi, ndc);
    glProgramUniform3i(p, 0, 0, 1, 2);
    glProgramUniform4f(p, 1, ndc[0], ndc[1], ndc[2], ndc[3]);
    glProgramUniform4i(p, 2, c->dims[0], w, (int)delta_row_uints(c), (int)block_row_uints(c));
    glProgramUniform1i(p, 3, k0);
    glBindFramebuffer(GL_FRAMEBUFFER, o->scan_fbo);
    /* State other code may have left behind: no tests, no culling (both
     * faces are crossings), every covered pixel centre one fragment. */
    glDisable(GL_DEPTH_TEST);
    vx_peel_raster_state();
    /* the framebuffer has no attachments: its bounds made explicit, so no
     * fragment can index past the counters' rows */
    glEnable(GL_SCISSOR_TEST);
    glScissor(0, 0, w, h);
    glUseProgram(p);
    glBindVertexArray(o->vao);
    for (GLuint b = 0; b < 4; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, o->scan_buf[b]);
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    vx_peel_draw_slab(c, p, 1);
    c->st->gpu_peel_ms += vx_gl_timer_end_ms(&t);
    glDisable(GL_SCISSOR_TEST);
    vx_xing_unbind();
    glBindVertexArray(0);
    glUseProgram(0);
    for (GLuint b = 0; b < 4; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    return vx_gl_check(c->gl, "scan.draw", c->err);
}

/* Step 2: prefix sums along x into the slab's bits (ssbo[0]). */
static int sum(peel_ctx *c, int rows, int mode)
{
    peel_objs *o = &c->o;
    GLuint p = c->prog_sum;
    glProgramUniform4i(p, 0, c->dims[0], c->dims[1], (int)c->wx, rows);
    glProgramUniform3i(p, 1, (int)delta_row_uints(c), mode == VX_INSIDE_PARITY ? 1 : 0,
                       (int)block_row_uints(c));
    /* The counters were written by fragment shader atomics. */
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT);
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    glUseProgram(p);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, o->scan_buf[0]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 1, o->scan_buf[1]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 2, o->ssbo[0]);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 3, o->scan_buf[3]);
    vx_peel_dispatch_2d((uint64_t)c->dims[1] * (uint64_t)rows);
    glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
    c->st->gpu_fill_ms += vx_peel_timer_end_compute(&t);
    glUseProgram(0);
    for (GLuint b = 0; b < 4; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
    return vx_gl_check(c->gl, "scan.sum", c->err);
}

int vx_voxelize_scan(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                     vx_voxelize_stats *st, vx_err *err)
{
    /* Majority of three axes and the surface fill: peel's paths. */
    if (d->fill == VX_FILL_SURFACE || d->inside == VX_INSIDE_ROBUST)
        return vx_voxelize_peel(gl, m, d, out, st, err);
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    st->method = "scan";
    memset(out, 0, sizeof *out);
    if (vx_peel_check_input(m, d, err)) return -1;
    const vx_grid *g = &d->grid;

    peel_ctx c = {.gl = gl, .m = m, .d = d, .st = st, .err = err, .out = out, .naxes = 1};
    for (int a = 0; a < 3; a++)
        c.dims[a] = g->dims[a];
    c.wx = ((size_t)c.dims[0] + 31) / 32;
    c.limit = d->max_memory ? d->max_memory : UINT64_MAX;
    if (plan(&c)) return -1;
    st->chunks = c.nslabs;
    c.prog_scan = vx_gl_program(gl, "voxel_peel.vert", "voxel_scan.frag", err);
    if (!c.prog_scan) return -1;
    c.prog_sum = vx_gl_compute_program(gl, "voxel_scan_sum.comp", err);
    if (!c.prog_sum) return -1;
    /* Errors left by earlier work must not be blamed on this job. */
    while (glGetError() != GL_NO_ERROR) {
    }

    int rc = -1;
    if (vx_bitgrid_alloc(out, g, 0, err)) return -1;
    double t0 = vx_mono_ms();
    if (vx_peel_upload(&c)) goto done;
    if (vx_peel_slab_buckets(&c)) goto done;
    peel_objs *o = &c.o;
    glCreateBuffers(1, &o->ssbo[0]);
    glNamedBufferStorage(o->ssbo[0], (GLsizeiptr)vx_peel_slab_bytes(&c, c.rows), NULL, 0);
    glCreateBuffers(4, o->scan_buf);
    glNamedBufferStorage(o->scan_buf[0], (GLsizeiptr)delta_bytes(&c, c.rows), NULL, 0);
    glNamedBufferStorage(o->scan_buf[1], (GLsizeiptr)tail_bytes(&c, c.rows), NULL, 0);
    glNamedBufferStorage(o->scan_buf[2], 4, NULL, 0);
    glNamedBufferStorage(o->scan_buf[3], (GLsizeiptr)block_bytes(&c, c.rows), NULL, 0);
    /* Cleared once: the sum pass leaves the counters at zero behind it. */
    for (int b = 0; b < 4; b++)
        glClearNamedBufferData(o->scan_buf[b], GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
    glCreateFramebuffers(1, &o->scan_fbo);
    if (vx_gl_check(gl, "scan.buffers", err)) goto done;
    glFinish(); /* so upload_ms is the upload, not just its queueing */
    st->upload_ms = vx_mono_ms() - t0;

    for (c.slab = 0; c.slab < c.nslabs; c.slab++) {
        int k0 = c.slab * c.rows, rows = c.dims[2] - k0 < c.rows ? c.dims[2] - k0 : c.rows;
        if (draw(&c, k0, rows)) goto done;
        if (vx_peel_progress(&c, 0.5)) goto done;
        if (sum(&c, rows, (int)d->inside)) goto done;
        double r0 = vx_mono_ms();
        glGetNamedBufferSubData(o->ssbo[0], 0, (GLsizeiptr)vx_peel_slab_bytes(&c, rows),
                                out->bits + (size_t)k0 * c.dims[1] * c.wx);
        st->readback_ms += vx_mono_ms() - r0;
        if (vx_gl_check(gl, "scan.readback", err)) goto done;
        if (vx_peel_progress(&c, 1.0)) goto done;
    }
    GLuint overflow = 0;
    glGetNamedBufferSubData(o->scan_buf[2], 0, 4, &overflow);
    if (vx_gl_check(gl, "scan.flag", err)) goto done;
    if (overflow) {
        vx_err_set(err, VX_EUNPROC, "too_many_crossings",
                   "more than 32767 net crossings of one ray fall into one voxel; use method "
                   "peel or cpu");
        goto done;
    }
    st->voxels_inside = vx_bitgrid_count(out);
    rc = 0;
done:
    free(c.slab_first);
    vx_peel_objs_free(&c.o);
    if (rc) vx_bitgrid_free(out);
    return rc;
}
