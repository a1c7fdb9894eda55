/* The GL layer: device list, context, programs, errors, rebuild. One context
 * for the whole file (the daemon has one too), made in the group setup. */
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cmocka.h>

#include "gl/gl.h"
#include "gl/internal.h"

static vx_gl *g_gl;

static int setup(void **state)
{
    vx_err err = {0};
    vx_gl_desc d = {.debug = 1, .robust = 1};
    g_gl = vx_gl_new(&d, &err);
    if (!g_gl) fprintf(stderr, "vx_gl_new: %s: %s\n", err.code, err.message);
    return g_gl ? 0 : -1;
}

static int teardown(void **state)
{
    vx_gl_free(g_gl);
    g_gl = NULL;
    return 0;
}

static void test_list_devices(void **state)
{
    vx_gl_device d[16];
    vx_err err = {0};
    int n = vx_gl_list_devices(d, 16, &err);
    assert_true(n >= 1);
    const char *order[] = {"nvidia", "hardware", "other", "software"};
    int last = 0;
    for (int i = 0; i < n; i++) {
        printf("device %d: index=%d kind=%s name=%s\n", i, d[i].index, d[i].kind, d[i].name);
        int rank = -1;
        for (int k = 0; k < 4; k++)
            if (strcmp(d[i].kind, order[k]) == 0) rank = k;
        assert_true(rank >= 0);
        assert_true(rank >= last); /* listed in try order */
        last = rank;
        assert_true(d[i].index >= 0 && d[i].index < n);
    }
    /* max smaller than the count truncates. */
    assert_int_equal(vx_gl_list_devices(d, 0, &err), 0);
}

static void test_info(void **state)
{
    const vx_gl_info *in = vx_gl_get_info(g_gl);
    printf("renderer=%s version=%s glsl=%s vendor=%s kind=%s index=%d egl=%s %s robust=%d\n",
           in->renderer, in->version, in->glsl, in->vendor, in->device_kind, in->device_index,
           in->egl_vendor, in->egl_version, in->robust);
    printf("max groups %ld %ld %ld invocations %ld ssbo %ld tex %ld tex3d %ld samples %ld\n",
           in->max_compute_groups[0], in->max_compute_groups[1], in->max_compute_groups[2],
           in->max_compute_invocations, in->max_ssbo_bytes, in->max_texture_size,
           in->max_3d_texture_size, in->max_samples);
    GLint major = 0, minor = 0;
    glGetIntegerv(GL_MAJOR_VERSION, &major);
    glGetIntegerv(GL_MINOR_VERSION, &minor);
    assert_true(major > 4 || (major == 4 && minor >= 5));
    assert_true(strlen(in->renderer) > 0);
    assert_true(strlen(in->version) > 0);
    assert_true(in->max_compute_groups[0] >= 65535);
    assert_true(in->max_compute_invocations >= 1024);
    assert_true(in->max_ssbo_bytes >= (1 << 27));
    GLint profile = 0;
    glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &profile);
    assert_true(profile & GL_CONTEXT_CORE_PROFILE_BIT);
    assert_int_equal(vx_gl_lost(g_gl), 0);
}

/* --require-gpu's test: Mesa's software rasterizers by name (any case) or
 * the software EGL device; GPU renderers and the surfaceless platform on
 * a GPU are not software. */
static void test_info_software(void **state)
{
    static const struct {
        const char *kind, *renderer;
        int soft;
    } cases[] = {
        {"software", "llvmpipe (LLVM 15.0.6, 256 bits)", 1},
        {"software", "", 1},
        {"surfaceless", "llvmpipe (LLVM 15.0.6, 256 bits)", 1},
        {"", "Gallium 0.4 on softpipe", 1},
        {"hardware", "Mesa X11 SWRAST", 1},
        {"other", "LLVMPIPE", 1},
        {"nvidia", "NVIDIA H100 80GB HBM3/PCIe/SSE2", 0},
        {"hardware", "AMD Radeon RX 7900 XTX (radeonsi, navi31, LLVM 15.0.6)", 0},
        {"surfaceless", "Mesa Intel(R) UHD Graphics 630 (CFL GT2)", 0},
        {"", "", 0},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        vx_gl_info in;
        memset(&in, 0, sizeof in);
        snprintf(in.device_kind, sizeof in.device_kind, "%s", cases[i].kind);
        snprintf(in.renderer, sizeof in.renderer, "%s", cases[i].renderer);
        assert_int_equal(vx_gl_info_software(&in), cases[i].soft);
    }
    /* The context this file made: software exactly when its device is
     * Mesa's software one or its renderer is llvmpipe. */
    const vx_gl_info *cur = vx_gl_get_info(g_gl);
    int expect = !strcmp(cur->device_kind, "software") || strstr(cur->renderer, "llvmpipe");
    assert_int_equal(vx_gl_info_software(cur), expect);
}

/* Runs shaders/test_fill.comp with a 2-D dispatch and checks every value. */
static void run_fill(GLuint prog)
{
    enum { GX = 4, GY = 3, N = 700, TOTAL = GX * GY * 64 };
    uint32_t init[TOTAL];
    for (int i = 0; i < TOTAL; i++)
        init[i] = 0xdeadbeef;
    GLuint buf;
    glCreateBuffers(1, &buf);
    glNamedBufferStorage(buf, sizeof init, init, 0);
    glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, buf);
    glUseProgram(prog);
    glProgramUniform1ui(prog, 0, N);
    glDispatchCompute(GX, GY, 1);
    glMemoryBarrier(GL_BUFFER_UPDATE_BARRIER_BIT);
    uint32_t out[TOTAL];
    glGetNamedBufferSubData(buf, 0, sizeof out, out);
    glUseProgram(0);
    glDeleteBuffers(1, &buf);
    vx_err err = {0};
    assert_int_equal(vx_gl_check(g_gl, "test.fill", &err), 0);
    for (int i = 0; i < N; i++)
        assert_int_equal(out[i], 3u * (uint32_t)i);
    for (int i = N; i < TOTAL; i++)
        assert_int_equal(out[i], 0xdeadbeef);
}

static void test_compute(void **state)
{
    vx_err err = {0};
    GLuint p = vx_gl_compute_program(g_gl, "test_fill.comp", &err);
    assert_true(p != 0);
    /* Cached: the same name comes back. */
    assert_int_equal(vx_gl_compute_program(g_gl, "test_fill.comp", &err), p);
    run_fill(p);
}

static void test_preview_program_builds(void **state)
{
    vx_err err = {0};
    GLuint p = vx_gl_program(g_gl, "preview.vert", "preview.frag", &err);
    if (!p) fprintf(stderr, "%s: %s\n", err.code, err.message);
    assert_true(p != 0);
    assert_int_equal(vx_gl_program(g_gl, "preview.vert", "preview.frag", &err), p);
}

static void test_missing_shader(void **state)
{
    vx_err err = {0};
    assert_int_equal(vx_gl_compute_program(g_gl, "no_such_shader.comp", &err), 0);
    assert_int_equal(err.kind, VX_EGPU);
    assert_string_equal(err.code, "shader_missing");
    assert_non_null(strstr(err.message, "no_such_shader.comp"));
    vx_err_clear(&err);
    assert_int_equal(vx_gl_program(g_gl, "preview.vert", "nope.frag", &err), 0);
    assert_string_equal(err.code, "shader_missing");
    assert_non_null(strstr(err.message, "nope.frag"));
}

static void test_build_error(void **state)
{
    vx_err err = {0};
    const char *bad =
        "#version 450 core\nlayout(local_size_x = 1) in;\nvoid main() { int x = ; }\n";
    assert_int_equal(vx_gl_program_from_source("test.bad", NULL, NULL, bad, &err), 0);
    printf("build error: %s\n", err.message);
    assert_int_equal(err.kind, VX_EGPU);
    assert_string_equal(err.code, "shader_build");
    assert_non_null(strstr(err.message, "test.bad"));
    /* The GLSL log names the line (Mesa "0:3(...)", NVIDIA "0(3)"). */
    assert_non_null(strstr(err.message, "3"));
    assert_true(strstr(err.message, "error") || strstr(err.message, "ERROR"));

    /* Link errors too: a fragment shader reading an input nobody writes. */
    const char *vs = "#version 450 core\nvoid main() { gl_Position = vec4(0); }\n";
    const char *fs = "#version 450 core\nin vec4 v_missing; out vec4 o;\n"
                     "void main() { o = v_missing; }\n";
    vx_err_clear(&err);
    GLuint p = vx_gl_program_from_source("test.link", vs, fs, NULL, &err);
    if (p) {
        /* Some drivers accept an unwritten input (it reads undefined). */
        glDeleteProgram(p);
    } else {
        assert_string_equal(err.code, "shader_build");
    }

    /* A good source builds, uncached and owned by the caller. */
    const char *good = "#version 450 core\nlayout(local_size_x = 1) in;\nvoid main() {}\n";
    p = vx_gl_program_from_source("test.good", NULL, NULL, good, &err);
    assert_true(p != 0);
    glDeleteProgram(p);
}

static void test_check(void **state)
{
    vx_err err = {0};
    assert_int_equal(vx_gl_check(g_gl, "test.clean", &err), 0);
    glBindBuffer(0x1234, 0); /* not a buffer target: GL_INVALID_ENUM */
    assert_int_equal(vx_gl_check(g_gl, "test.provoked", &err), -1);
    assert_int_equal(err.kind, VX_EGPU);
    assert_string_equal(err.code, "gl_error");
    assert_non_null(strstr(err.message, "GL_INVALID_ENUM"));
    assert_non_null(strstr(err.message, "test.provoked"));
    /* Drained: the next check is clean. */
    assert_int_equal(vx_gl_check(g_gl, "test.after", &err), 0);
}

static void test_out_of_memory(void **state)
{
    vx_err err = {0};
    GLuint buf;
    glCreateBuffers(1, &buf);
    /* 2^50 bytes: no device has that much memory. */
    glNamedBufferData(buf, (GLsizeiptr)1 << 50, NULL, GL_STATIC_DRAW);
    assert_int_equal(vx_gl_check(g_gl, "test.huge_buffer", &err), -1);
    glDeleteBuffers(1, &buf);
    printf("huge buffer: %s: %s\n", err.code, err.message);
    assert_string_equal(err.code, "gpu_out_of_memory");
    assert_int_equal(vx_gl_check(g_gl, "test.after", &err), 0);
}

static void test_timer(void **state)
{
    vx_gl_timer t;
    vx_gl_timer_begin(&t);
    GLuint p = vx_gl_compute_program(g_gl, "test_fill.comp", NULL);
    assert_true(p != 0);
    run_fill(p);
    double ms = vx_gl_timer_end_ms(&t);
    printf("timer: %.3f ms\n", ms);
    assert_true(ms >= 0 && ms < 10000);
    vx_err err = {0};
    assert_int_equal(vx_gl_check(g_gl, "test.timer", &err), 0);
}

static void test_rebuild(void **state)
{
    vx_err err = {0};
    GLuint before = vx_gl_compute_program(g_gl, "test_fill.comp", &err);
    assert_true(before != 0);
    assert_int_equal(vx_gl_rebuild(g_gl, &err), 0);
    assert_int_equal(vx_gl_lost(g_gl), 0);
    /* The cache was emptied with the old context: a fresh build works. */
    GLuint p = vx_gl_compute_program(g_gl, "test_fill.comp", &err);
    assert_true(p != 0);
    assert_true(glIsProgram(p));
    run_fill(p);
    assert_true(vx_gl_program(g_gl, "preview.vert", "preview.frag", &err) != 0);
}

static void test_device_out_of_range(void **state)
{
    vx_gl_device d[16];
    vx_err err = {0};
    int n = vx_gl_list_devices(d, 16, &err);
    assert_true(n >= 1);
    vx_gl_desc desc = {.pick_device = 1, .device = n + 5};
    assert_null(vx_gl_new(&desc, &err));
    printf("out of range: %s: %s\n", err.code, err.message);
    assert_int_equal(err.kind, VX_EGPU);
    assert_string_equal(err.code, "bad_egl_device");
    char want[64];
    snprintf(want, sizeof want, "%d EGL device", n);
    assert_non_null(strstr(err.message, want));
    /* The live context is untouched. */
    assert_int_equal(vx_gl_lost(g_gl), 0);
    assert_int_equal(vx_gl_check(g_gl, "test.after_bad_device", &err), 0);
}

/* Runs with no other context alive: EGL displays are per device and
 * process, so two vx_gl on one device would share (and terminate) one. */
static void test_explicit_device(void **state)
{
    vx_gl_device d[16];
    vx_err err = {0};
    int n = vx_gl_list_devices(d, 16, &err);
    assert_true(n >= 1);
    vx_gl_desc desc = {.pick_device = 1, .device = d[0].index};
    vx_gl *gl = vx_gl_new(&desc, &err);
    if (!gl) fprintf(stderr, "%s: %s\n", err.code, err.message);
    assert_non_null(gl);
    const vx_gl_info *in = vx_gl_get_info(gl);
    assert_int_equal(in->device_index, d[0].index);
    assert_string_equal(in->device_kind, d[0].kind);
    assert_int_equal(in->robust, 0);
    GLuint p = vx_gl_compute_program(gl, "test_fill.comp", &err);
    assert_true(p != 0);
    vx_gl_free(gl);
    vx_gl_free(NULL);
}

/* A zero-initialised desc means the automatic order (issue #11: it used to
 * force device 0); device 0 itself stays reachable explicitly. */
static void test_zero_desc_is_automatic(void **state)
{
    vx_gl_desc zero = {0};
    assert_int_equal(vx_gl_desc_device(&zero), -1);
    assert_int_equal(vx_gl_desc_device(NULL), -1);
    vx_gl_desc dev0 = {.pick_device = 1, .device = 0};
    assert_int_equal(vx_gl_desc_device(&dev0), 0);
    vx_gl_desc dev3 = {.pick_device = 1, .device = 3};
    assert_int_equal(vx_gl_desc_device(&dev3), 3);
    /* A device index alone, without pick_device, does not choose. */
    vx_gl_desc idx_only = {.device = 3};
    assert_int_equal(vx_gl_desc_device(&idx_only), -1);
    vx_gl_device d[16];
    vx_err err = {0};
    assert_true(vx_gl_list_devices(d, 16, &err) >= 1);
    vx_gl *gl = vx_gl_new(&zero, &err);
    if (!gl) fprintf(stderr, "%s: %s\n", err.code, err.message);
    assert_non_null(gl);
    /* The first device of the automatic order that works: here the first. */
    assert_int_equal(vx_gl_get_info(gl)->device_index, d[0].index);
    vx_gl_free(gl);
}

/* Counts lines of stderr holding `needle` while fn runs. */
static int count_logged(const char *needle, void (*fn)(void))
{
    char path[] = "/tmp/vx_test_gl_log.XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    fflush(stderr);
    int saved = dup(2);
    dup2(fd, 2);
    fn();
    fflush(stderr);
    dup2(saved, 2);
    close(saved);
    FILE *f = fdopen(fd, "r");
    rewind(f);
    char line[1024];
    int n = 0;
    while (fgets(line, sizeof line, f))
        n += strstr(line, needle) != NULL;
    fclose(f);
    unlink(path);
    return n;
}

static void bad_device(void)
{
    vx_err err = {0};
    vx_gl_desc desc = {.pick_device = 1, .device = 1000};
    assert_null(vx_gl_new(&desc, &err));
}

/* A failed init is logged once, by the GL layer. */
static void test_init_failed_logged_once(void **state)
{
    assert_int_equal(count_logged("event=gl.init_failed", bad_device), 1);
}

/* A driver that says the same thing at every draw: 1000 messages in a burst
 * log at most 20 gl.debug lines, and the next message after the second is
 * out says how many were left out. */
static void debug_flood(void)
{
    for (int i = 0; i < 1000; i++)
        glDebugMessageInsert(GL_DEBUG_SOURCE_APPLICATION, GL_DEBUG_TYPE_PERFORMANCE, 7,
                             GL_DEBUG_SEVERITY_MEDIUM, -1, "vx-test-flood");
    usleep(1100 * 1000);
    glDebugMessageInsert(GL_DEBUG_SOURCE_APPLICATION, GL_DEBUG_TYPE_PERFORMANCE, 7,
                         GL_DEBUG_SEVERITY_MEDIUM, -1, "vx-test-flood");
}

static void test_debug_flood_limited(void **state)
{
    int n = count_logged("vx-test-flood", debug_flood);
    assert_true(n >= 2);  /* the messages reach the log */
    assert_true(n <= 21); /* a burst of 20, then the one after the second */
    assert_int_equal(count_logged("event=gl.debug_suppressed lines=", debug_flood), 1);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_list_devices),
        cmocka_unit_test(test_info),
        cmocka_unit_test(test_info_software),
        cmocka_unit_test(test_compute),
        cmocka_unit_test(test_preview_program_builds),
        cmocka_unit_test(test_missing_shader),
        cmocka_unit_test(test_build_error),
        cmocka_unit_test(test_check),
        cmocka_unit_test(test_out_of_memory),
        cmocka_unit_test(test_timer),
        cmocka_unit_test(test_rebuild),
        cmocka_unit_test(test_device_out_of_range),
        cmocka_unit_test(test_init_failed_logged_once),
        cmocka_unit_test(test_debug_flood_limited),
    };
    const struct CMUnitTest alone[] = {
        cmocka_unit_test(test_explicit_device),
        cmocka_unit_test(test_zero_desc_is_automatic),
    };
    int failed = cmocka_run_group_tests(tests, setup, teardown);
    failed += cmocka_run_group_tests(alone, NULL, NULL);
    return failed;
}
