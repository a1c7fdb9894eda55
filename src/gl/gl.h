/* The one headless OpenGL 4.5 core context, through EGL.
 *
 * Device order (ARCHITECTURE.md): EGL_EXT_platform_device devices that are
 * NVIDIA (EGL_NV_device_cuda) first, then other hardware devices, then
 * Mesa's software device, then the surfaceless platform. Every function here
 * must be called from the thread that created the context (the GL thread),
 * except vx_gl_list_devices, which creates no context. */
#ifndef VX_GL_H
#define VX_GL_H

#define GL_GLEXT_PROTOTYPES 1
#include <GL/glcorearb.h>

#include <stddef.h>

#include "util/err.h"

typedef struct vx_gl vx_gl;

/* Zero-initialised = the defaults: automatic device order, no debug
 * output, no robustness. */
typedef struct vx_gl_desc {
    int pick_device; /* nonzero: exactly EGL device `device`; 0 = automatic order */
    int device;      /* EGL device index (0 included), used when pick_device */
    int debug;       /* nonzero: KHR_debug messages go to the log */
    int robust;      /* nonzero: ask for a robust context (reset notification) */
} vx_gl_desc;

typedef struct vx_gl_info {
    char vendor[128], renderer[256], version[128], glsl[64];
    char device_kind[16]; /* "nvidia", "hardware", "other", "software", "surfaceless" */
    int device_index;     /* EGL device index, -1 for surfaceless */
    char egl_vendor[64], egl_version[64];
    int robust; /* the context has reset notification */
    long max_compute_groups[3], max_compute_invocations, max_ssbo_bytes, max_texture_size,
        max_3d_texture_size, max_samples;
} vx_gl_info;

typedef struct vx_gl_device {
    int index;
    char kind[16];  /* as in vx_gl_info; "other" = an EGL device that is neither
                       NVIDIA, nor has a DRM node, nor is Mesa's software one */
    char name[128]; /* DRM node ("cuda=N node" for NVIDIA) or extension summary */
} vx_gl_device;

/* Lists EGL devices in the order automatic choice tries them; returns count
 * (at most max), or -1. Any thread; creates no context. */
int vx_gl_list_devices(vx_gl_device *out, int max, vx_err *err);

/* Creates the context and makes it current on the calling thread, which
 * becomes the GL thread. Fails (VX_EGPU, code gl_unsupported) with a clear
 * message when GL 4.5 core with compute shaders is not available, and with
 * code bad_egl_device when desc picks a device index that does not exist.
 * Owned. */
vx_gl *vx_gl_new(const vx_gl_desc *desc, vx_err *err);
/* Destroys the context; NULL is a no-op. The EGL display stays initialised
 * (it is shared per device and process; a later vx_gl_new reuses it). */
void vx_gl_free(vx_gl *gl);
const vx_gl_info *vx_gl_get_info(const vx_gl *gl);
/* Nonzero when the context renders on the CPU: Mesa's software EGL device,
 * or a GL_RENDERER naming a software rasterizer (llvmpipe, softpipe,
 * swrast; the surfaceless platform falls back to them). Any thread. */
int vx_gl_info_software(const vx_gl_info *info);

/* 1 when the context was lost (glGetGraphicsResetStatus), else 0. */
int vx_gl_lost(vx_gl *gl);
/* Destroys and recreates the context on the same device (programs too). */
int vx_gl_rebuild(vx_gl *gl, vx_err *err);

/* Drains glGetError; GL_OUT_OF_MEMORY -> VX_EGPU "gpu_out_of_memory", any
 * other error -> VX_EGPU "gl_error", naming `where`. Returns 0 or -1.
 * With VX_GL_TRACE in the environment it first waits for the GPU and logs
 * gl.trace (the wait, the time since the last check, the reset status). */
int vx_gl_check(vx_gl *gl, const char *where, vx_err *err);

/* Program built from embedded shaders/NAME files (e.g. "preview.vert",
 * "preview.frag"; cs = compute, others NULL). Cached per context: the
 * returned name is owned by gl and stays valid until vx_gl_free/rebuild.
 * Compile/link failures are VX_EGPU "shader_build" with the GLSL log. */
GLuint vx_gl_program(vx_gl *gl, const char *vs, const char *fs, vx_err *err);
GLuint vx_gl_compute_program(vx_gl *gl, const char *cs, vx_err *err);

/* A new vertex array whose attribute 0 is the vec3 float positions of vbo
 * (tightly packed), with ibo as its element buffer (0 = none). GL thread. */
GLuint vx_gl_position_vao(GLuint vbo, GLuint ibo);

/* The embedded text of shaders/NAME, or NULL. Any thread. */
const char *vx_shader_source(const char *name);

/* GPU time of a region: begin/end a GL_TIME_ELAPSED query. Not nestable
 * (GL allows one active GL_TIME_ELAPSED query). GL thread. */
typedef struct vx_gl_timer {
    GLuint q;
    double cpu_start_ms; /* wall clock at begin: an upper bound for the GPU time */
} vx_gl_timer;
void vx_gl_timer_begin(vx_gl_timer *t);
/* Ends the query and waits for its result, in milliseconds. A result longer
 * than the wall-clock time since begin is a driver bug (llvmpipe can report
 * the time since boot): the wall-clock time is returned instead. With
 * VX_GL_NO_TIMERS in the environment there are no queries: the wall-clock
 * time (GPU bring-up). */
double vx_gl_timer_end_ms(vx_gl_timer *t);
/* The same for compute dispatches: llvmpipe runs them outside what its
 * timer queries measure (~20 ns for milliseconds of work), so when the query
 * says less than a thousandth of the wall-clock time to glFinish, the wall
 * clock (the dispatch ran on the CPU) is returned. GL thread. */
double vx_gl_timer_end_compute_ms(vx_gl_timer *t);

#endif
