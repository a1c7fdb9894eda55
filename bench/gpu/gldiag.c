/* GPU bring-up diagnostics for the voxelizers (bench/gpu/run.sh): on the
 * machine's GL device, with a debug context (every KHR_debug message to
 * the log), prints the rasterizer limits the brick-exact crossings rely on,
 * what the rasterizer covers for squares (two triangles each) drawn the
 * way the voxelizers draw them, then each GPU method on shapes with known answers
 * against the CPU reference, with a map of the z slices that differ.
 *
 *   gldiag [--robust] [--case probe|cube0|cube2|box|sphere|robust|surface|mesh] [MESH.obj]
 *
 * --robust asks for a robust context (as voxeld does); --case runs one
 * case (each in its own process, a fault in one cannot spoil the next);
 * VX_GL_TRACE=1 logs every stage's GPU time (gl.h). MESH is voxelized at
 * 64 beside the built-in shapes.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gl/gl.h"
#include "gl/internal.h"
#include "mesh/mesh.h"
#include "shapes.h"
#include "util/clock.h"
#include "util/log.h"
#include "voxel/voxel.h"
#include "voxel/xing.h"

static void limits(void)
{
    GLint sub = 0, vsub = 0, dims[2] = {0, 0}, tbo = 0, tboal = 0, fbw = 0, fbh = 0;
    GLfloat range[2] = {0, 0};
    glGetIntegerv(GL_SUBPIXEL_BITS, &sub);
    glGetIntegerv(GL_VIEWPORT_SUBPIXEL_BITS, &vsub);
    glGetIntegerv(GL_MAX_VIEWPORT_DIMS, dims);
    glGetFloatv(GL_VIEWPORT_BOUNDS_RANGE, range);
    glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &tbo);
    glGetIntegerv(GL_TEXTURE_BUFFER_OFFSET_ALIGNMENT, &tboal);
    glGetIntegerv(GL_MAX_FRAMEBUFFER_WIDTH, &fbw);
    glGetIntegerv(GL_MAX_FRAMEBUFFER_HEIGHT, &fbh);
    printf("GL_SUBPIXEL_BITS %d, GL_VIEWPORT_SUBPIXEL_BITS %d, GL_MAX_VIEWPORT_DIMS %dx%d, "
           "GL_VIEWPORT_BOUNDS_RANGE [%g, %g]\n",
           sub, vsub, dims[0], dims[1], range[0], range[1]);
    printf("GL_MAX_TEXTURE_BUFFER_SIZE %d, GL_TEXTURE_BUFFER_OFFSET_ALIGNMENT %d, "
           "GL_MAX_FRAMEBUFFER %dx%d\n",
           tbo, tboal, fbw, fbh);
}

/* Two triangles (a unit square split on its diagonal, and a thin sliver),
 * drawn into an attachment-less w x h framebuffer through
 * vx_xing_viewport: each pixel's fragment count and last primitive id. */
static const char *probe_vs =
    "#version 450 core\n"
    "layout(location = 0) in vec3 a_pos;\n"
    "layout(location = 1) uniform vec4 u_ndc;\n"
    "void main() { gl_Position = vec4(a_pos.x * u_ndc.x + u_ndc.y, a_pos.y * u_ndc.z + "
    "u_ndc.w, 0.0, 1.0); }\n";
static const char *probe_fs =
    "#version 450 core\n"
    "layout(binding = 0, r32ui) uniform coherent uimage2D u_count;\n"
    "layout(binding = 1, r32ui) uniform coherent uimage2D u_prim;\n"
    "void main() {\n"
    "  ivec2 p = ivec2(gl_FragCoord.xy);\n"
    "  imageAtomicAdd(u_count, p, 1u);\n"
    "  imageAtomicMax(u_prim, p, uint(gl_PrimitiveID + 1) | (gl_FrontFacing ? 16u : 0u));\n"
    "}\n";

static void probe(vx_gl *gl, const char *name, const float *pos, int nv, const uint32_t *idx,
                  int ni, int w, int h, const int off[2], const double lo[2], const double hi[2])
{
    vx_err err = {0};
    GLuint prog = vx_gl_program_from_source("probe", probe_vs, probe_fs, NULL, &err);
    if (!prog) {
        printf("probe %s: program: %s\n", name, err.message);
        return;
    }
    GLuint b[2], tex[2], fbo, q;
    glCreateBuffers(2, b);
    glNamedBufferStorage(b[0], (GLsizeiptr)(nv * 3 * sizeof(float)), pos, 0);
    glNamedBufferStorage(b[1], (GLsizeiptr)(ni * sizeof(uint32_t)), idx, 0);
    GLuint vao = vx_gl_position_vao(b[0], b[1]);
    glCreateTextures(GL_TEXTURE_2D, 2, tex);
    for (int i = 0; i < 2; i++) {
        glTextureStorage2D(tex[i], 1, GL_R32UI, w, h);
        const GLuint zero = 0;
        glClearTexImage(tex[i], 0, GL_RED_INTEGER, GL_UNSIGNED_INT, &zero);
        glBindImageTexture(i, tex[i], 0, GL_FALSE, 0, GL_READ_WRITE, GL_R32UI);
    }
    glCreateFramebuffers(1, &fbo);
    glNamedFramebufferParameteri(fbo, GL_FRAMEBUFFER_DEFAULT_WIDTH, w);
    glNamedFramebufferParameteri(fbo, GL_FRAMEBUFFER_DEFAULT_HEIGHT, h);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glDisable(GL_CULL_FACE);
    glDisable(GL_DEPTH_TEST);
    glDisable(GL_SCISSOR_TEST);
    glEnable(GL_DEPTH_CLAMP);
    float ndc[4];
    vx_xing_viewport(w, h, off, 1, lo, hi, ndc);
    GLint vp[4];
    glGetIntegerv(GL_VIEWPORT, vp);
    glUseProgram(prog);
    glProgramUniform4f(prog, 1, ndc[0], ndc[1], ndc[2], ndc[3]);
    glBindVertexArray(vao);
    glGenQueries(1, &q);
    glBeginQuery(GL_SAMPLES_PASSED, q);
    glDrawElements(GL_TRIANGLES, ni, GL_UNSIGNED_INT, NULL);
    glEndQuery(GL_SAMPLES_PASSED);
    GLuint samples = 0;
    glGetQueryObjectuiv(q, GL_QUERY_RESULT, &samples);
    glMemoryBarrier(GL_ALL_BARRIER_BITS);
    uint32_t *c = calloc((size_t)w * h, 4), *p = calloc((size_t)w * h, 4);
    glGetTextureImage(tex[0], 0, GL_RED_INTEGER, GL_UNSIGNED_INT, w * h * 4, c);
    glGetTextureImage(tex[1], 0, GL_RED_INTEGER, GL_UNSIGNED_INT, w * h * 4, p);
    int e = vx_gl_check(gl, "probe", &err);
    long total = 0;
    for (int i = 0; i < w * h; i++)
        total += c[i];
    printf("probe %s: viewport (%d %d %d %d) ndc (%g %g %g %g), fragments %ld, "
           "GL_SAMPLES_PASSED %u, gl error %d\n",
           name, vp[0], vp[1], vp[2], vp[3], ndc[0], ndc[1], ndc[2], ndc[3], total, samples, e);
    printf("  count per pixel (row y = %d at the top) | primitive id + 1 (+16 front-facing)\n",
           h - 1);
    for (int y = h - 1; y >= 0; y--) {
        printf("  ");
        for (int x = 0; x < w; x++)
            printf("%u", c[y * w + x] > 9 ? 9 : c[y * w + x]);
        printf(" | ");
        for (int x = 0; x < w; x++)
            printf("%2u ", p[y * w + x]);
        printf("\n");
    }
    free(c);
    free(p);
    glBindFramebuffer(GL_FRAMEBUFFER, 0);
    glBindVertexArray(0);
    glUseProgram(0);
    glDeleteQueries(1, &q);
    glDeleteFramebuffers(1, &fbo);
    glDeleteTextures(2, tex);
    glDeleteBuffers(2, b);
    glDeleteVertexArrays(1, &vao);
    glDeleteProgram(prog);
}

typedef int (*runner)(vx_gl *, const vx_mesh *, const vx_voxelize_desc *, vx_bitgrid *,
                      vx_voxelize_stats *, vx_err *);

static const struct {
    const char *name;
    runner run;
} methods[] = {
    {"peel", vx_voxelize_peel}, {"scan", vx_voxelize_scan}, {"slice", vx_voxelize_slice}};

/* Each method against cpu on the grid; a map of up to 3 differing z slices
 * ('+' set only by the method, '-' only by cpu, '#' both). */
static void compare(vx_gl *gl, const char *name, const vx_mesh *m, const vx_grid *g,
                    vx_inside inside, vx_fill fill)
{
    vx_voxelize_desc d = {.grid = *g, .inside = inside, .fill = fill};
    vx_bitgrid ref;
    vx_voxelize_stats st = {0};
    vx_err err = {0};
    if (fill == VX_FILL_SURFACE) { /* no CPU surface fill: counts only */
        vx_bitgrid b;
        if (vx_voxelize_peel(gl, m, &d, &b, &st, &err)) {
            printf("%s: peel: %s %s\n", name, err.code, err.message);
            return;
        }
        printf("%s: peel %llu voxels (llvmpipe: 4784)\n", name,
               (unsigned long long)vx_bitgrid_count(&b));
        vx_bitgrid_free(&b);
        return;
    }
    /* robust on a closed mesh is parity; cpu does not vote */
    vx_voxelize_desc dr = d;
    if (inside == VX_INSIDE_ROBUST) dr.inside = VX_INSIDE_PARITY;
    if (vx_voxelize_cpu(m, &dr, &ref, &st, &err)) {
        printf("%s: cpu: %s %s\n", name, err.code, err.message);
        return;
    }
    const int *n = g->dims;
    printf("%s: grid %dx%dx%d, inside %d, fill %d: cpu %llu voxels\n", name, n[0], n[1], n[2],
           (int)inside, (int)fill, (unsigned long long)vx_bitgrid_count(&ref));
    for (size_t k = 0; k < sizeof methods / sizeof *methods; k++) {
        vx_bitgrid b;
        vx_err e2 = {0};
        vx_voxelize_stats s2 = {0};
        double t0 = vx_mono_ms();
        int rc = methods[k].run(gl, m, &d, &b, &s2, &e2);
        double ms = vx_mono_ms() - t0;
        if (rc) {
            printf("  %-5s rc %d: %s: %s (%.1f ms)\n", methods[k].name, rc, e2.code, e2.message,
                   ms);
            continue;
        }
        long extra = 0, missing = 0;
        int shown = 0;
        for (int z = 0; z < n[2]; z++) {
            long ez = 0, mz = 0;
            for (int y = 0; y < n[1]; y++)
                for (int x = 0; x < n[0]; x++) {
                    int a = vx_bitgrid_get(&b, x, y, z), r = vx_bitgrid_get(&ref, x, y, z);
                    ez += a && !r;
                    mz += r && !a;
                }
            extra += ez;
            missing += mz;
            if ((ez || mz) && shown < 3 && n[0] <= 64 && n[1] <= 64) {
                shown++;
                printf("    z %d: %ld extra, %ld missing\n", z, ez, mz);
                for (int y = n[1] - 1; y >= 0; y--) {
                    printf("    ");
                    for (int x = 0; x < n[0]; x++) {
                        int a = vx_bitgrid_get(&b, x, y, z), r = vx_bitgrid_get(&ref, x, y, z);
                        putchar(a && r ? '#' : a ? '+' : r ? '-' : '.');
                    }
                    putchar('\n');
                }
            }
        }
        printf("  %-5s %llu voxels, %ld extra, %ld missing; layers %d passes %d slices %d "
               "chunks %d; %.1f ms; reset status 0x%x\n",
               methods[k].name, (unsigned long long)vx_bitgrid_count(&b), extra, missing, s2.layers,
               s2.passes, s2.slices, s2.chunks, ms, glGetGraphicsResetStatus());
        vx_bitgrid_free(&b);
    }
    vx_bitgrid_free(&ref);
}

static int want(const char *only, const char *name)
{
    return !only || !strcmp(only, name);
}

int main(int argc, char **argv)
{
    const char *only = NULL, *mesh = NULL;
    int robust = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--robust"))
            robust = 1;
        else if (!strcmp(argv[i], "--case") && i + 1 < argc)
            only = argv[++i];
        else
            mesh = argv[i];
    }
    vx_log_set_level(getenv("VX_GL_TRACE") ? VX_LOG_INFO : VX_LOG_DEBUG);
    vx_err err = {0};
    vx_gl_desc gd = {.debug = 1, .robust = robust};
    vx_gl *gl = vx_gl_new(&gd, &err);
    if (!gl) {
        printf("vx_gl_new: %s: %s\n", err.code, err.message);
        return 1;
    }
    const vx_gl_info *gi = vx_gl_get_info(gl);
    printf("renderer %s | %s | %s | robust %d\n", gi->renderer, gi->version, gi->device_kind,
           gi->robust);
    limits();
    setvbuf(stdout, NULL, _IONBF, 0);

    if (want(only, "probe")) {
        /* the cube's top face as the 8^3 cube test draws it (grid units) */
        const float sq[] = {0, 0, 0, 8, 0, 0, 0, 8, 0, 8, 8, 0};
        const uint32_t sqi[] = {0, 2, 3, 0, 3, 1};
        const int off0[2] = {0, 0};
        probe(gl, "square 8x8 on pixel edges", sq, 4, sqi, 6, 8, 8, off0, (double[]){0, 0},
              (double[]){8, 8});
        const float sq2[] = {1, 1, 0, 9, 1, 0, 1, 9, 0, 9, 9, 0};
        probe(gl, "square 8x8 at (1,1) in 10x10", sq2, 4, sqi, 6, 10, 10, off0, (double[]){1, 1},
              (double[]){9, 9});
        /* a square reaching past the 6x6 framebuffer: fragments only inside */
        probe(gl, "square 8x8 past a 6x6 framebuffer", sq, 4, sqi, 6, 6, 6, off0, (double[]){0, 0},
              (double[]){8, 8});
    }
    vx_grid g;
    vx_mesh *m = shape_box((double[]){0, 0, 0}, (double[]){1, 1, 1});
    for (int pad = 0; pad <= 2; pad += 2) {
        char nm[64];
        snprintf(nm, sizeof nm, "cube%d", pad);
        if (!want(only, nm)) continue;
        vx_grid_from_resolution(m, 8, pad, &g, NULL);
        for (int rule = VX_INSIDE_NONZERO; rule <= VX_INSIDE_PARITY; rule++)
            compare(gl, nm, m, &g, (vx_inside)rule, VX_FILL_SOLID);
    }
    vx_mesh_free(m);
    if (want(only, "box")) {
        m = shape_box((double[]){0.5, 0.25, 0}, (double[]){10.25, 1.75, 1.5});
        g = (vx_grid){.origin = {0, 0, 0}, .h = 0.25, .dims = {45, 11, 9}};
        compare(gl, "box on cell boundaries", m, &g, VX_INSIDE_NONZERO, VX_FILL_SOLID);
        g.dims[0] = 1; /* the narrow grid of test_solid, one voxel inside the box */
        g.origin[0] = 2.5;
        compare(gl, "box, a 1-voxel-wide grid", m, &g, VX_INSIDE_NONZERO, VX_FILL_SOLID);
        vx_mesh_free(m);
    }
    m = shape_sphere(0, 0, 0, 1, 0);
    vx_grid_from_resolution(m, 32, 1, &g, NULL);
    if (want(only, "sphere")) {
        compare(gl, "sphere 32", m, &g, VX_INSIDE_NONZERO, VX_FILL_SOLID);
        compare(gl, "sphere 32 parity", m, &g, VX_INSIDE_PARITY, VX_FILL_SOLID);
    }
    if (want(only, "robust"))
        compare(gl, "sphere 32 robust", m, &g, VX_INSIDE_ROBUST, VX_FILL_SOLID);
    if (want(only, "surface"))
        compare(gl, "sphere 32 surface", m, &g, VX_INSIDE_NONZERO, VX_FILL_SURFACE);
    vx_mesh_free(m);
    if (mesh && want(only, "mesh")) {
        m = vx_obj_read_path(mesh, NULL, &err);
        if (m) {
            vx_grid_from_resolution(m, 64, 1, &g, NULL);
            compare(gl, mesh, m, &g, VX_INSIDE_NONZERO, VX_FILL_SOLID);
            vx_mesh_free(m);
        }
    }
    printf("reset status at the end: 0x%x\n", glGetGraphicsResetStatus());
    vx_gl_free(gl);
    return 0;
}
