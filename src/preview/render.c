/* The preview renderer (preview.h): MSAA draws of the mesh, band by band. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "preview/preview.h"
#include "util/clock.h"
#include "util/log.h"
#include "util/vec3.h"

/* Every GL object one render creates, so that every exit path deletes the
 * same set (names of 0 are ignored by glDelete*). */
typedef struct objs {
    GLuint vbo, ibo, vao;
    GLuint fbo, rb_color, rb_depth;          /* single-sample: resolve target */
    GLuint fbo_ms, rb_ms_color, rb_ms_depth; /* multisample draw target */
} objs;

static void objs_free(objs *o)
{
    GLuint bufs[2] = {o->vbo, o->ibo};
    glDeleteBuffers(2, bufs);
    glDeleteVertexArrays(1, &o->vao);
    GLuint fbos[2] = {o->fbo, o->fbo_ms};
    glDeleteFramebuffers(2, fbos);
    GLuint rbs[4] = {o->rb_color, o->rb_depth, o->rb_ms_color, o->rb_ms_depth};
    glDeleteRenderbuffers(4, rbs);
    memset(o, 0, sizeof *o);
}

/* Column-major view and projection for the orbit camera around the origin
 * (where the normalised mesh's bbox centre is). The view only turns: its
 * space is centred on the mesh (z towards the eye), and the eye's distance
 * is in the projection, so no vertex is a small difference of two large
 * numbers. Else a tiny field of view (the eye 1e5 radii away) left the
 * depth a few hundred levels over the mesh and its shading noise. */
static void camera(const vx_preview_params *p, float view[16], float proj[16])
{
    const double deg = M_PI / 180.0;
    double az = p->azimuth_deg * deg, el = p->elevation_deg * deg;
    double aspect = (double)p->width / (double)p->height;
    /* Unit vector from the centre to the eye: azimuth 0 is +Z, positive
     * azimuth swings towards +X, elevation lifts towards +Y. */
    double e[3] = {cos(el) * sin(az), sin(el), cos(el) * cos(az)};

    memset(proj, 0, 16 * sizeof *proj);
    if (p->fov_deg > 0) {
        double fov = p->fov_deg < VX_PREVIEW_MIN_FOV ? VX_PREVIEW_MIN_FOV : p->fov_deg;
        double tv = tan(0.5 * fov * deg), th = aspect * tv;
        /* The narrower of the two half-angles decides: the sphere must fit
         * both ways, whatever the aspect ratio. */
        double half = atan(tv < th ? tv : th);
        double dist = VX_PREVIEW_MARGIN / sin(half);
        double near = dist - 1.1, far = dist + 1.1;
        if (near < 0.01 * dist) near = 0.01 * dist;
        /* w = dist - z (z: the view space's, towards the eye); the usual
         * depth a w + b with a + b / near = -1 and a + b / far = 1, written
         * in z: (a dist + b) - a z, its constant taken in double. */
        double f = 1.0 / tv, a = (far + near) / (far - near), b = -2.0 * far * near / (far - near);
        proj[0] = (float)(f / aspect);
        proj[5] = (float)f;
        proj[10] = (float)-a;
        proj[11] = -1.0f;
        proj[14] = (float)(a * dist + b);
        proj[15] = (float)dist;
    } else {
        /* A sphere VX_PREVIEW_MARGIN times the unit one fills the smaller
         * image dimension, as in the narrowest perspective (the limit of
         * its picture); depth -1 at z = 1.1 (nearest), 1 at z = -1.1. */
        double hx = aspect >= 1 ? aspect : 1, hy = aspect >= 1 ? 1 : 1 / aspect;
        hx *= VX_PREVIEW_MARGIN;
        hy *= VX_PREVIEW_MARGIN;
        proj[0] = (float)(1.0 / hx);
        proj[5] = (float)(1.0 / hy);
        proj[10] = (float)(-1.0 / 1.1);
        proj[15] = 1.0f;
    }

    double f[3] = {-e[0], -e[1], -e[2]}, up[3] = {0, 1, 0}, s[3], u[3];
    vx_v3_cross(f, up, s);
    vx_v3_unit(s);
    vx_v3_cross(s, f, u);
    memset(view, 0, 16 * sizeof *view);
    for (int i = 0; i < 3; i++) {
        view[4 * i + 0] = (float)s[i];
        view[4 * i + 1] = (float)u[i];
        view[4 * i + 2] = (float)-f[i];
    }
    view[15] = 1.0f;
}

static int poll_render(const vx_preview_params *p, double fraction, vx_err *err)
{
    return p->poll ? p->poll(p->poll_ud, fraction, err) : 0;
}

/* Centre the bbox at the origin and scale the bounding sphere to radius 1,
 * in double (coordinates far from the origin, like +1e6, would lose the
 * mesh's detail if shifted after conversion), then upload as floats. */
static int upload(vx_gl *gl, const vx_mesh *m, const vx_preview_params *p, objs *o, vx_err *err)
{
    double c[3], r2 = 0;
    for (int a = 0; a < 3; a++)
        c[a] = 0.5 * (m->bbox_min[a] + m->bbox_max[a]);
    /* the vertices the triangles use, as the bbox (a vertex no face uses
     * left the picture empty) */
    for (size_t i = 0; i < 3 * m->ntris; i++) {
        const double *v = m->pos + 3 * (size_t)m->tri[i];
        double dx = v[0] - c[0], dy = v[1] - c[1], dz = v[2] - c[2];
        double d2 = dx * dx + dy * dy + dz * dz;
        if (d2 > r2) r2 = d2;
    }
    double inv = r2 > 0 ? 1.0 / sqrt(r2) : 1.0;

    GLsizeiptr vbytes = (GLsizeiptr)(m->nverts * 3 * sizeof(float));
    GLsizeiptr ibytes = (GLsizeiptr)(m->ntris * 3 * sizeof(uint32_t));
    glCreateBuffers(1, &o->vbo);
    glNamedBufferStorage(o->vbo, vbytes, NULL, GL_DYNAMIC_STORAGE_BIT);
    if (vx_gl_check(gl, "preview.vertex_buffer", err)) return -1;
    /* Converted in slices: bounded extra memory whatever the mesh size. */
    enum { CHUNK = 65536 };
    float *tmp = malloc(CHUNK * 3 * sizeof *tmp);
    if (!tmp) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for upload");
    for (size_t i0 = 0; i0 < m->nverts; i0 += CHUNK) {
        size_t n = m->nverts - i0 < CHUNK ? m->nverts - i0 : CHUNK;
        for (size_t k = 0; k < n; k++)
            for (int a = 0; a < 3; a++)
                tmp[3 * k + a] = (float)((m->pos[3 * (i0 + k) + a] - c[a]) * inv);
        glNamedBufferSubData(o->vbo, (GLintptr)(i0 * 3 * sizeof(float)),
                             (GLsizeiptr)(n * 3 * sizeof(float)), tmp);
        if (((i0 / CHUNK) & 15) == 15 && poll_render(p, 0, err)) {
            free(tmp);
            return -1;
        }
    }
    free(tmp);
    if (vx_gl_check(gl, "preview.vertex_upload", err)) return -1;

    glCreateBuffers(1, &o->ibo);
    glNamedBufferStorage(o->ibo, ibytes, m->tri, 0);
    if (vx_gl_check(gl, "preview.index_buffer", err)) return -1;

    o->vao = vx_gl_position_vao(o->vbo, o->ibo);
    return vx_gl_check(gl, "preview.vertex_array", err);
}

/* samples: asked for; set to what the implementation gave (it may round
 * up: llvmpipe gives 4 for 2). */
static int targets(vx_gl *gl, int w, int h, int *samples_io, objs *o, vx_err *err)
{
    const int samples = *samples_io;
    glCreateFramebuffers(1, &o->fbo);
    glCreateRenderbuffers(1, &o->rb_color);
    glNamedRenderbufferStorage(o->rb_color, GL_RGBA8, w, h);
    glNamedFramebufferRenderbuffer(o->fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, o->rb_color);
    GLuint draw = o->fbo;
    if (samples > 1) {
        glCreateFramebuffers(1, &o->fbo_ms);
        glCreateRenderbuffers(1, &o->rb_ms_color);
        glCreateRenderbuffers(1, &o->rb_ms_depth);
        glNamedRenderbufferStorageMultisample(o->rb_ms_color, samples, GL_RGBA8, w, h);
        glNamedRenderbufferStorageMultisample(o->rb_ms_depth, samples, GL_DEPTH_COMPONENT24, w, h);
        glNamedFramebufferRenderbuffer(o->fbo_ms, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER,
                                       o->rb_ms_color);
        glNamedFramebufferRenderbuffer(o->fbo_ms, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER,
                                       o->rb_ms_depth);
        draw = o->fbo_ms;
        GLint got = 0;
        glGetNamedRenderbufferParameteriv(o->rb_ms_color, GL_RENDERBUFFER_SAMPLES, &got);
        if (got > 0) *samples_io = got;
    } else {
        glCreateRenderbuffers(1, &o->rb_depth);
        glNamedRenderbufferStorage(o->rb_depth, GL_DEPTH_COMPONENT24, w, h);
        glNamedFramebufferRenderbuffer(o->fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, o->rb_depth);
    }
    if (vx_gl_check(gl, "preview.framebuffer", err)) return -1;
    GLenum st = glCheckNamedFramebufferStatus(draw, GL_FRAMEBUFFER);
    if (st != GL_FRAMEBUFFER_COMPLETE) {
        VX_ERROR("preview.fbo_incomplete", "status=0x%x samples=%d", st, samples);
        return vx_err_set(err, VX_EGPU, "gl_error",
                          "preview framebuffer %dx%d with %d samples is incomplete (0x%x)", w, h,
                          samples, st);
    }
    return 0;
}

/* Turns one band of the resolved premultiplied coverage image (rows y0..
 * y0+n-1 counted from the bottom, as glReadPixels gives them) into the
 * final picture: composite over the background (which may be
 * translucent), count covered pixels, and store the rows top row first. */
static uint64_t finish_band(uint8_t *band, int w, int h, int y0, int n, const float bg[4],
                            uint8_t *rgba)
{
    uint8_t bg8[4];
    for (int i = 0; i < 4; i++)
        bg8[i] = (uint8_t)lrint(255.0 * bg[i]);
    uint64_t covered = 0;
    const size_t npx = (size_t)w * (size_t)n;
    for (size_t i = 0; i < npx; i++) {
        uint8_t *px = band + 4 * i;
        if (px[3] == 0) {
            memcpy(px, bg8, 4);
            continue;
        }
        covered++;
        if (px[3] == 255) continue; /* fully covered: already the shaded colour */
        /* Edge pixel: px holds coverage-weighted colour, px[3] the coverage. */
        double cov = px[3] / 255.0, ba = bg[3] * (1.0 - cov), oa = cov + ba;
        for (int k = 0; k < 3; k++) {
            double v = (px[k] / 255.0 + bg[k] * ba) / oa;
            px[k] = (uint8_t)lrint(255.0 * (v > 1 ? 1 : v));
        }
        px[3] = (uint8_t)lrint(255.0 * oa);
    }
    const size_t stride = (size_t)w * 4;
    for (int k = 0; k < n; k++)
        memcpy(rgba + (size_t)(h - 1 - (y0 + k)) * stride, band + (size_t)k * stride, stride);
    return covered;
}

/* Checks the image size against the GPU and every triangle index against
 * the vertex count. */
static int check_inputs(const vx_mesh *m, const vx_preview_params *p, vx_err *err)
{
    const int w = p->width, h = p->height;
    if (w <= 0 || h <= 0)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "preview size %dx%d is not positive",
                          w, h);
    GLint max_rb = 0;
    glGetIntegerv(GL_MAX_RENDERBUFFER_SIZE, &max_rb);
    if (w > max_rb || h > max_rb)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "preview size %dx%d exceeds this GPU's limit of %d pixels per side", w, h,
                          max_rb);
    /* A bad index would make the GPU read outside the vertex buffer: a
     * hand-built or corrupted mesh must fail here, not fault there. */
    return vx_mesh_check_indices(m, err);
}

/* The sample count asked for, clamped to 1..the GPU's maximum. */
static int pick_samples(vx_gl *gl, const vx_preview_params *p)
{
    int samples = p->samples < 1 ? 1 : p->samples;
    long max_samples = vx_gl_get_info(gl)->max_samples;
    if (samples > max_samples) {
        VX_INFO("preview.samples_clamped", "asked=%d max=%ld", samples, max_samples);
        samples = max_samples < 1 ? 1 : (int)max_samples;
    }
    return samples;
}

/* Sets the camera, colour and light uniforms of the preview program. */
static void set_uniforms(GLuint prog, const vx_preview_params *p)
{
    float view[16], proj[16];
    camera(p, view, proj);
    double l[3] = {VX_PREVIEW_LIGHT_X, VX_PREVIEW_LIGHT_Y, VX_PREVIEW_LIGHT_Z};
    vx_v3_unit(l);
    glProgramUniformMatrix4fv(prog, 0, 1, GL_FALSE, view);
    glProgramUniformMatrix4fv(prog, 1, 1, GL_FALSE, proj);
    glProgramUniform3f(prog, 2, p->color[0], p->color[1], p->color[2]);
    glProgramUniform1f(prog, 3, p->ambient);
    glProgramUniform3f(prog, 4, (float)l[0], (float)l[1], (float)l[2]);
}

/* Resets the GL state other code may have left behind. */
static void reset_state(void)
{
    glDisable(GL_CULL_FACE);
    glDisable(GL_BLEND);
    glDisable(GL_SCISSOR_TEST);
    glEnable(GL_MULTISAMPLE);
    glEnable(GL_DEPTH_TEST);
    glDepthFunc(GL_LESS);
    glDepthMask(GL_TRUE);
    glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
    glBindBuffer(GL_PIXEL_PACK_BUFFER, 0);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glPixelStorei(GL_PACK_ROW_LENGTH, 0);
}

/* Draws the mesh into band b of nbands in chunks, polling between them.
 * *chunk (kept from band to band) is the triangles a draw takes: it starts
 * at VX_PREVIEW_CHUNK_MIN and follows how long the draws take, doubling
 * while a draw takes under 25 ms (up to VX_PREVIEW_CHUNK_TRIS) and shrunk
 * to about 50 ms when one takes over 100 ms: a soup of large triangles
 * (each covering the band) is a few thousand triangles a draw, not 1M. */
static int draw_chunks(GLuint prog, GLuint vao, size_t nidx, int b, int nbands,
                       const vx_preview_params *p, size_t *chunk, vx_err *err)
{
    glUseProgram(prog);
    glBindVertexArray(vao);
    for (size_t first = 0; first < nidx;) {
        if (first > 0) {
            double f = ((double)b + 0.5 * (double)first / (double)nidx) / nbands;
            if (poll_render(p, 0.05 + 0.9 * f, err)) return -1;
        }
        /* glDrawElements counts in GLsizei */
        size_t count = nidx - first < 3 * *chunk ? nidx - first : 3 * *chunk;
        double t0 = vx_mono();
        glDrawElements(GL_TRIANGLES, (GLsizei)count, GL_UNSIGNED_INT,
                       (const void *)(uintptr_t)(first * sizeof(uint32_t)));
        glFinish();
        double dt = vx_mono() - t0;
        if (dt < 0.025 && count == 3 * *chunk && *chunk < VX_PREVIEW_CHUNK_TRIS)
            *chunk *= 2;
        else if (dt > 0.1)
            *chunk = (size_t)fmax(VX_PREVIEW_CHUNK_MIN / 16, (double)*chunk * 0.05 / dt);
        first += count;
    }
    glBindVertexArray(0);
    glUseProgram(0);
    return 0;
}

/* Reads the first n rows of the resolved framebuffer into band. */
static void read_band(GLuint fbo, int w, int n, uint8_t *band)
{
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo);
    glReadBuffer(GL_COLOR_ATTACHMENT0);
    glReadPixels(0, 0, w, n, GL_RGBA, GL_UNSIGNED_BYTE, band);
    glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
}

/* Rows per band: about VX_PREVIEW_BAND_SAMPLES samples, at least 16 rows
 * (llvmpipe bins in 64x64 tiles: thinner bands waste the vertex work). */
static int band_rows(const vx_preview_params *p, int samples)
{
    if (p->band_rows > 0) return p->band_rows < p->height ? p->band_rows : p->height;
    long rows = (long)VX_PREVIEW_BAND_SAMPLES / ((long)p->width * samples);
    if (rows < 16) rows = 16;
    return rows < p->height ? (int)rows : p->height;
}

int vx_preview_render(vx_gl *gl, const vx_mesh *m, const vx_preview_params *p, uint8_t *rgba,
                      vx_preview_stats *st, vx_err *err)
{
    vx_preview_stats dummy;
    if (!st) st = &dummy;
    memset(st, 0, sizeof *st);
    const int w = p->width, h = p->height;
    if (check_inputs(m, p, err)) return -1;
    const size_t nidx = 3 * m->ntris;
    int samples = pick_samples(gl, p);
    st->samples = samples;

    GLuint prog = vx_gl_program(gl, "preview.vert", "preview.frag", err);
    if (!prog) return -1;
    /* Errors left by earlier work must not be blamed on this render. */
    if (glGetError() != GL_NO_ERROR) {
        VX_WARN("preview.stale_gl_error", "where=before_render");
        while (glGetError() != GL_NO_ERROR) {
        }
    }

    objs o = {0};
    int rc = -1, timing = 0;
    vx_gl_timer timer;
    uint8_t *band = NULL;
    const int draw = m->ntris > 0 && m->nverts > 0;
    double t0 = vx_mono_ms();
    if (draw && upload(gl, m, p, &o, err)) goto done;
    glFinish(); /* so upload_ms is the upload, not just its queueing */
    st->upload_ms = vx_mono_ms() - t0;
    if (poll_render(p, 0.05, err)) goto done;
    /* The image is drawn in bands of rows into band-sized targets: the
     * viewport puts image row y0 at the band's row 0 (a whole-pixel shift,
     * so every band rasterises as the whole image would), and a band is a
     * piece of work the time limit can stop between. */
    const int rows = band_rows(p, samples);
    if (targets(gl, w, rows, &samples, &o, err)) goto done;
    st->samples = samples;
    band = malloc((size_t)w * (size_t)rows * 4);
    if (!band) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a %dx%d band", w, rows);
        goto done;
    }

    set_uniforms(prog, p);
    GLuint target = samples > 1 ? o.fbo_ms : o.fbo;
    reset_state();
    const int nbands = (h + rows - 1) / rows;
    size_t chunk = VX_PREVIEW_CHUNK_MIN; /* triangles a draw takes (draw_chunks) */
    for (int b = 0; b < nbands; b++) {
        const int y0 = b * rows, n = h - y0 < rows ? h - y0 : rows;
        glBindFramebuffer(GL_FRAMEBUFFER, target);
        glViewport(0, -y0, w, h);
        const float clear[4] = {0, 0, 0, 0}, one = 1.0f;
        glClearNamedFramebufferfv(target, GL_COLOR, 0, clear);
        glClearNamedFramebufferfv(target, GL_DEPTH, 0, &one);
        /* Begun after the clear: llvmpipe (Mesa 22.3) loses the start of a
         * time query begun before the first command on a newly bound
         * framebuffer and then reports the time since boot. */
        vx_gl_timer_begin(&timer);
        timing = 1;
        if (draw && draw_chunks(prog, o.vao, nidx, b, nbands, p, &chunk, err)) goto done;
        if (samples > 1) {
            glFinish(); /* the draw and the resolve are two pieces */
            if (poll_render(p, 0.05 + 0.9 * (b + 0.5) / nbands, err)) goto done;
            glBlitNamedFramebuffer(o.fbo_ms, o.fbo, 0, 0, w, n, 0, 0, w, n, GL_COLOR_BUFFER_BIT,
                                   GL_NEAREST);
        }
        st->gpu_ms += vx_gl_timer_end_ms(&timer); /* waits for the band */
        timing = 0;
        read_band(o.fbo, w, n, band);
        if (vx_gl_check(gl, "preview.draw", err)) goto done;
        st->pixels_covered += finish_band(band, w, h, y0, n, p->background, rgba);
        if (poll_render(p, 0.05 + 0.9 * (b + 1) / nbands, err)) goto done;
    }
    rc = 0;
done:
    if (timing) vx_gl_timer_end_ms(&timer); /* stopped inside a band */
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glBindVertexArray(0);
    glUseProgram(0);
    objs_free(&o);
    free(band);
    return rc;
}
