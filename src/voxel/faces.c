/* Face-centre supersampling: supersample 2 with samples "faces".
 *
 * Seed 003's accuracy improvement samples a voxel at 2 x 2 x 2 points, a
 * quarter voxel from its centre along each axis, and sets it when at least
 * `threshold` are inside. Measured by the seed's own figure (the mean
 * distance from the centres of surface voxels to the surface), that pattern
 * has a floor: on a face parallel to a grid plane the lowest threshold sets
 * a voxel when the face lies less than 3/4 voxel above its centre and more
 * than 1/4 below, so over the face's offsets the distance is uniform on
 * [0, 3/4) and its mean 0.3125 (bench/RESULTS.md).
 *
 * This pattern samples the centre and the centres of the six faces. With
 * threshold 1 a voxel is set when the surface lies less than half a voxel
 * beyond its centre along some axis: on a plane with unit normal n the
 * surface voxels are those whose signed distance lies within
 * [-m/2, m/2), m = max |n_a|, and their mean distance is m/4 -- at most
 * 0.25 (faces parallel to grid planes) and 0.14 on a plane at equal angles
 * to the axes. That is the least any binary voxelization can reach on a
 * plane parallel to a grid plane (exactly one voxel per column is the last
 * inside, and the nearest centre is on average 1/4 away). Higher
 * thresholds shrink the solid back towards centre sampling (4 of 7: the
 * centre's own answer wherever the surface is flat within the voxel).
 *
 * The samples are the centres of seven grids: the voxel grid itself, and
 * for each axis the grid moved half a voxel less FACES_INSET against it
 * and along it, whose voxel i is centred FACES_INSET inside voxel i's
 * lower (upper) face. Inside the face, not on it: a face of the mesh lying
 * on voxel faces (grid-aligned parts) is then never on a sample, and each
 * voxel sees it from its own side. (Samples on the faces, shared by the
 * voxels either side, met such a face in a tie, and the tie rule counted
 * it for the voxel on one side only: a box filling voxels 1..3 exactly
 * gave 8 voxels at threshold 7, and a layer on its low sides at 1.) Each
 * is voxelized at its centres by the requested method (auto: cpu), with
 * the same inside rule and tie rule; a voxel's count is its centre plus
 * its two faces along each axis, added on the GPU (vx_faces_count,
 * shaders/voxel_faces_count.comp) a z slab at a time: the seven sample slabs
 * go up, the bits and the per-voxel counts come back. */
#include <stdlib.h>
#include <string.h>

#include "util/clock.h"
#include "voxel/faces_int.h"
#include "voxel/peel_int.h"
#include "voxel/voxel.h"

typedef struct sub_progress {
    const vx_voxelize_desc *d;
    int part; /* 0..6 the sample grids, 7 the count */
} sub_progress;

/* The face samples' distance inside the face, voxels: one snapping step.
 * The moved grids' lattices are the voxel grid's shifted by a whole number
 * of steps, so every grid snaps a position to the same point, and a face
 * of the mesh meets a sample only when it lies exactly one step off a
 * voxel face (never when it lies on one). */
#define FACES_INSET (1.0 / VX_GRID_SNAP)

/* The seven runs take the first 90 % of the bar, the count the rest. */
static int progress(void *ud, double f, vx_err *err)
{
    sub_progress *p = ud;
    double at = p->part < VX_FACES_SAMPLES ? 0.9 * (p->part + f) / VX_FACES_SAMPLES : 0.9 + 0.1 * f;
    return p->d->progress(p->d->ud, at, err);
}

static void add_stats(vx_voxelize_stats *st, const vx_voxelize_stats *s)
{
    st->method = s->method;
    if (s->layers > st->layers) st->layers = s->layers;
    st->passes += s->passes;
    st->slices += s->slices;
    st->chunks += s->chunks;
    st->upload_ms += s->upload_ms;
    st->gpu_peel_ms += s->gpu_peel_ms;
    st->gpu_fill_ms += s->gpu_fill_ms;
    st->gpu_slice_ms += s->gpu_slice_ms;
    st->readback_ms += s->readback_ms;
}

/* Bytes of GPU buffers per slab: the seven sample slabs, the bits and the
 * counts. Small enough to stay in llvmpipe's caches between upload and
 * read-back, big enough that the round trips don't dominate (as scan.c's
 * SCAN_DELTA_CAP). */
#define FACES_SLAB_CAP (16u << 20)

int vx_faces_count(vx_gl *gl, const vx_bitgrid g[VX_FACES_SAMPLES], int threshold, vx_bitgrid *out,
                   const vx_faces_count_desc *fd, vx_voxelize_stats *st, vx_err *err)
{
    const int nx = out->grid.dims[0], ny = out->grid.dims[1], nz = out->grid.dims[2];
    const size_t wx = out->wx;
    /* one z row: of a sample grid (and of the bits), of the counts */
    const uint64_t rb = (uint64_t)ny * wx * 4u, rc_ = (uint64_t)ny * (uint64_t)nx;
    const uint64_t per_row = (VX_FACES_SAMPLES + 1) * rb + rc_ + 4u;
    const uint64_t widest = VX_FACES_SAMPLES * rb;
    const long max_ssbo = vx_gl_get_info(gl)->max_ssbo_bytes;
    uint64_t rows = FACES_SLAB_CAP / per_row;
    if (max_ssbo > 0 && rows > (uint64_t)max_ssbo / widest) rows = (uint64_t)max_ssbo / widest;
    if (fd && fd->max_rows > 0 && rows > (uint64_t)fd->max_rows) rows = (uint64_t)fd->max_rows;
    if (fd && fd->max_bytes > 0 && rows > fd->max_bytes / per_row) rows = fd->max_bytes / per_row;
    if (rows > (uint64_t)nz) rows = (uint64_t)nz;
    if (rows < 1) {
        if (max_ssbo > 0 && widest > (uint64_t)max_ssbo)
            return vx_err_set(err, VX_ETOOBIG, "grid_too_large",
                              "one z layer of the faces count (%llu bytes) exceeds this GPU's "
                              "storage block size (%ld bytes)",
                              (unsigned long long)widest, max_ssbo);
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                          "the faces count on a %dx%dx%d grid needs %llu bytes of GPU buffers, "
                          "more than the job has left",
                          nx, ny, nz, (unsigned long long)per_row);
    }
    GLuint prog = vx_gl_compute_program(gl, "voxel_faces_count.comp", err);
    if (!prog) return -1;
    while (glGetError() != GL_NO_ERROR) {
    }
    /* the seven sample slabs one after another, the bits, the counts */
    const uint64_t size[3] = {VX_FACES_SAMPLES * rb * rows, rb * rows, (rc_ * rows + 3u) & ~3ull};
    GLuint buf[3];
    glCreateBuffers(3, buf);
    for (int b = 0; b < 3; b++)
        glNamedBufferStorage(buf[b], (GLsizeiptr)size[b], NULL, GL_DYNAMIC_STORAGE_BIT);
    int rc = -1;
    if (vx_gl_check(gl, "faces.buffers", err)) goto done;
    glUseProgram(prog);
    for (GLuint b = 0; b < 3; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, buf[b]);
    for (int k0 = 0; k0 < nz; k0 += (int)rows) {
        const int r = nz - k0 < (int)rows ? nz - k0 : (int)rows;
        if (fd && fd->progress && fd->progress(fd->ud, (double)k0 / nz, err)) goto done;
        double t0 = vx_mono_ms();
        /* each sample slab is rows k0.. of its grid, contiguous */
        for (int s = 0; s < VX_FACES_SAMPLES; s++)
            glNamedBufferSubData(buf[0], (GLintptr)(rb * (uint64_t)r * (uint64_t)s),
                                 (GLsizeiptr)(rb * (uint64_t)r),
                                 (const char *)g[s].bits + rb * (uint64_t)k0);
        glClearNamedBufferData(buf[2], GL_R32UI, GL_RED_INTEGER, GL_UNSIGNED_INT, NULL);
        st->upload_ms += vx_mono_ms() - t0;
        vx_gl_timer t;
        vx_gl_timer_begin(&t);
        glProgramUniform4i(prog, 0, nx, ny, (int)wx, r);
        glProgramUniform1i(prog, 1, threshold);
        vx_peel_dispatch_2d((uint64_t)ny * wx * (uint64_t)r);
        glMemoryBarrier(GL_SHADER_STORAGE_BARRIER_BIT | GL_BUFFER_UPDATE_BARRIER_BIT);
        st->gpu_fill_ms += vx_gl_timer_end_compute_ms(&t);
        t0 = vx_mono_ms();
        glGetNamedBufferSubData(buf[1], 0, (GLsizeiptr)(rb * (uint64_t)r),
                                out->bits + (size_t)k0 * (size_t)ny * wx);
        glGetNamedBufferSubData(buf[2], 0, (GLsizeiptr)(rc_ * (uint64_t)r),
                                out->counts + (size_t)k0 * (size_t)ny * (size_t)nx);
        st->readback_ms += vx_mono_ms() - t0;
        if (vx_gl_check(gl, "faces.count", err)) goto done;
    }
    rc = 0;
done:
    for (GLuint b = 0; b < 3; b++)
        glBindBufferBase(GL_SHADER_STORAGE_BUFFER, b, 0);
    glUseProgram(0);
    glDeleteBuffers(3, buf);
    return rc;
}

int vx_voxelize_faces(vx_gl *gl, const vx_mesh *m, const vx_voxelize_desc *d, vx_bitgrid *out,
                      vx_voxelize_stats *st, vx_err *err)
{
    vx_voxelize_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    memset(out, 0, sizeof *out);
    const vx_grid *grid = &d->grid;
    /* The result's bits and counts, then the seven sample grids, live
     * together: each run gets what the ones before it left of max_memory. */
    uint64_t held = vx_bitgrid_bytes(grid->dims, 2);
    if (d->max_memory && held > d->max_memory)
        return vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                          "the faces sample pattern on a %dx%dx%d grid needs more than %llu "
                          "bytes, the job may use %llu",
                          grid->dims[0], grid->dims[1], grid->dims[2], (unsigned long long)held,
                          (unsigned long long)d->max_memory);
    if (vx_bitgrid_alloc(out, grid, 1, err)) return -1;
    out->nsamples = 7;

    vx_bitgrid g[VX_FACES_SAMPLES];
    memset(g, 0, sizeof g);
    sub_progress sp = {d, 0};
    vx_voxelize_desc sub = *d;
    sub.supersample = 1;
    sub.samples = VX_SAMPLES_CUBE;
    sub.progress = d->progress ? progress : NULL;
    sub.ud = &sp;
    int rc = -1;
    for (int part = 0; part < VX_FACES_SAMPLES; part++) {
        /* part 2a + 1: the lower faces along axis a, 2a + 2 the upper */
        sub.grid = *grid;
        if (part > 0)
            sub.grid.origin[(part - 1) / 2] += (part % 2 ? -1 : 1) * (0.5 - FACES_INSET) * grid->h;
        if (d->max_memory) {
            if (held >= d->max_memory) {
                vx_err_set(err, VX_ETOOBIG, "job_memory_limit",
                           "the faces sample pattern on a %dx%dx%d grid needs more than the "
                           "%llu bytes the job may use",
                           grid->dims[0], grid->dims[1], grid->dims[2],
                           (unsigned long long)d->max_memory);
                goto done;
            }
            sub.max_memory = d->max_memory - held;
        }
        sp.part = part;
        vx_voxelize_stats s;
        if (vx_voxelize(gl, m, &sub, &g[part], &s, err)) goto done;
        add_stats(st, &s);
        held += vx_bitgrid_bytes(sub.grid.dims, 1);
    }
    /* What the count may take: what the seven runs left of max_memory. */
    sp.part = VX_FACES_SAMPLES;
    vx_faces_count_desc fd = {
        .max_bytes = d->max_memory ? (held < d->max_memory ? d->max_memory - held : 1) : 0,
        .progress = d->progress ? progress : NULL,
        .ud = &sp};
    if (vx_faces_count(gl, g, d->threshold, out, &fd, st, err)) goto done;
    st->voxels_inside = vx_bitgrid_count(out);
    rc = 0;
done:
    for (int part = 0; part < VX_FACES_SAMPLES; part++)
        vx_bitgrid_free(&g[part]);
    if (rc) vx_bitgrid_free(out);
    return rc;
}
