/* EGL device choice and the one headless OpenGL 4.5 core context (gl.h).
 *
 * Everything goes through EGL_EXT_platform_device so that the same code
 * picks an NVIDIA GPU on a server and Mesa's software device (llvmpipe) on a
 * machine without one; EGL_PLATFORM_SURFACELESS_MESA is the last resort for
 * Mesa builds whose device enumeration finds nothing usable. */
#include "gl/internal.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "util/clock.h"
#include "util/log.h"

struct vx_gl {
    vx_gl_desc desc;
    EGLDisplay dpy;
    EGLConfig cfg;   /* EGL_NO_CONFIG_KHR when the display is configless */
    EGLSurface surf; /* 1x1 pbuffer, or EGL_NO_SURFACE (surfaceless) */
    EGLContext ctx;
    int egl15;       /* EGL >= 1.5: core context attributes are understood */
    int khr_create;  /* EGL_KHR_create_context, for EGL 1.4 displays */
    int surfaceless; /* EGL_KHR_surfaceless_context */
    char where[160]; /* "EGL device 0 (software, ...)", for messages */
    vx_gl_info info;
    vx_gl_prog_entry *progs;
    size_t nprogs, capprogs;
};

vx_gl_prog_entry **vx_gl_prog_slots(vx_gl *gl, size_t **n, size_t **cap)
{
    *n = &gl->nprogs;
    *cap = &gl->capprogs;
    return &gl->progs;
}

/* ---- small helpers ------------------------------------------------------ */

/* Whole-token search in a space-separated extension list (a plain strstr
 * would let EGL_EXT_device_drm match EGL_EXT_device_drm_render_node). */
static int has_ext(const char *list, const char *name)
{
    if (!list) return 0;
    size_t n = strlen(name);
    for (const char *p = list; (p = strstr(p, name)) != NULL; p += n)
        if ((p == list || p[-1] == ' ') && (p[n] == ' ' || p[n] == 0)) return 1;
    return 0;
}

static const char *egl_error_name(EGLint e)
{
    switch (e) {
    case EGL_SUCCESS:
        return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED:
        return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS:
        return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC:
        return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE:
        return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG:
        return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT:
        return "EGL_BAD_CONTEXT";
    case EGL_BAD_CURRENT_SURFACE:
        return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY:
        return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH:
        return "EGL_BAD_MATCH";
    case EGL_BAD_NATIVE_PIXMAP:
        return "EGL_BAD_NATIVE_PIXMAP";
    case EGL_BAD_NATIVE_WINDOW:
        return "EGL_BAD_NATIVE_WINDOW";
    case EGL_BAD_PARAMETER:
        return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE:
        return "EGL_BAD_SURFACE";
    case EGL_CONTEXT_LOST:
        return "EGL_CONTEXT_LOST";
    default:
        return "EGL_UNKNOWN_ERROR";
    }
}

static int egl_fail(vx_err *err, const char *code, const char *call, const char *where)
{
    EGLint e = eglGetError();
    return vx_err_set(err, VX_EGPU, code, "%s failed on %s: %s (0x%x)", call, where,
                      egl_error_name(e), (unsigned)e);
}

static const char *gl_error_name(GLenum e)
{
    switch (e) {
    case GL_INVALID_ENUM:
        return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE:
        return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION:
        return "GL_INVALID_OPERATION";
    case GL_STACK_OVERFLOW:
        return "GL_STACK_OVERFLOW";
    case GL_STACK_UNDERFLOW:
        return "GL_STACK_UNDERFLOW";
    case GL_OUT_OF_MEMORY:
        return "GL_OUT_OF_MEMORY";
    case GL_INVALID_FRAMEBUFFER_OPERATION:
        return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_CONTEXT_LOST:
        return "GL_CONTEXT_LOST";
    default:
        return "GL_UNKNOWN_ERROR";
    }
}

static void copy_str(char *dst, size_t size, const void *src)
{
    snprintf(dst, size, "%s", src ? (const char *)src : "");
}

/* ---- device discovery --------------------------------------------------- */

typedef struct egl_dev {
    EGLDeviceEXT dev;
    vx_gl_device d;
    int rank; /* try order: 0 nvidia, 1 hardware, 2 other, 3 software */
} egl_dev;

static PFNEGLQUERYDEVICESEXTPROC p_query_devices;
static PFNEGLQUERYDEVICESTRINGEXTPROC p_query_device_string;
static PFNEGLQUERYDEVICEATTRIBEXTPROC p_query_device_attrib;

static void classify(egl_dev *e)
{
    const char *ext = p_query_device_string(e->dev, EGL_EXTENSIONS);
    const char *drm = NULL, *node = NULL;
    /* Only ask for strings the device advertises: asking otherwise raises
     * EGL_BAD_ATTRIBUTE. Mesa's software device advertises
     * EGL_EXT_device_drm_render_node yet answers NULL, so NULL is checked. */
    if (has_ext(ext, "EGL_EXT_device_drm"))
        drm = p_query_device_string(e->dev, EGL_DRM_DEVICE_FILE_EXT);
    if (has_ext(ext, "EGL_EXT_device_drm_render_node"))
        node = p_query_device_string(e->dev, EGL_DRM_RENDER_NODE_FILE_EXT);
    eglGetError(); /* a NULL answer leaves an error behind; it means nothing here */

    if (has_ext(ext, "EGL_NV_device_cuda")) {
        EGLAttrib cuda = -1;
        if (!p_query_device_attrib || !p_query_device_attrib(e->dev, EGL_CUDA_DEVICE_NV, &cuda))
            cuda = -1;
        e->rank = 0;
        snprintf(e->d.kind, sizeof e->d.kind, "nvidia");
        snprintf(e->d.name, sizeof e->d.name, "cuda=%ld %s", (long)cuda,
                 node  ? node
                 : drm ? drm
                       : "");
    } else if (drm || node) {
        e->rank = 1;
        snprintf(e->d.kind, sizeof e->d.kind, "hardware");
        snprintf(e->d.name, sizeof e->d.name, "%s", node ? node : drm);
    } else if (has_ext(ext, "EGL_MESA_device_software")) {
        e->rank = 3;
        snprintf(e->d.kind, sizeof e->d.kind, "software");
        snprintf(e->d.name, sizeof e->d.name, "EGL_MESA_device_software");
    } else {
        /* Neither a DRM node nor a known vendor: still worth trying before
         * the software rasterizer. */
        e->rank = 2;
        snprintf(e->d.kind, sizeof e->d.kind, "other");
        snprintf(e->d.name, sizeof e->d.name, "%s", ext ? ext : "");
    }
}

/* All EGL devices in try order; *out is owned by the caller. Returns the
 * count (0 when the client lacks device enumeration) or -1. */
static int enum_devices(egl_dev **out, vx_err *err)
{
    *out = NULL;
    const char *cext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
    if (!has_ext(cext, "EGL_EXT_device_enumeration") && !has_ext(cext, "EGL_EXT_device_base")) {
        eglGetError();
        return 0;
    }
    /* Function pointers, not link-time symbols: libglvnd's libEGL does not
     * export the EXT entry points (ARCHITECTURE.md, traps). */
    p_query_devices = (PFNEGLQUERYDEVICESEXTPROC)eglGetProcAddress("eglQueryDevicesEXT");
    p_query_device_string =
        (PFNEGLQUERYDEVICESTRINGEXTPROC)eglGetProcAddress("eglQueryDeviceStringEXT");
    p_query_device_attrib =
        (PFNEGLQUERYDEVICEATTRIBEXTPROC)eglGetProcAddress("eglQueryDeviceAttribEXT");
    if (!p_query_devices || !p_query_device_string) return 0;

    EGLint n = 0;
    if (!p_query_devices(0, NULL, &n))
        return egl_fail(err, "egl_devices", "eglQueryDevicesEXT", "the EGL client");
    if (n <= 0) return 0;
    EGLDeviceEXT *devs = calloc((size_t)n, sizeof *devs);
    egl_dev *e = calloc((size_t)n, sizeof *e);
    if (!devs || !e) {
        free(devs);
        free(e);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %d EGL devices", n);
    }
    if (!p_query_devices(n, devs, &n)) {
        free(devs);
        free(e);
        return egl_fail(err, "egl_devices", "eglQueryDevicesEXT", "the EGL client");
    }
    for (EGLint i = 0; i < n; i++) {
        e[i].dev = devs[i];
        e[i].d.index = i;
        classify(&e[i]);
    }
    free(devs);
    /* Stable insertion sort by rank: a handful of devices. */
    for (EGLint i = 1; i < n; i++) {
        egl_dev t = e[i];
        EGLint j = i;
        for (; j > 0 && e[j - 1].rank > t.rank; j--)
            e[j] = e[j - 1];
        e[j] = t;
    }
    *out = e;
    return n;
}

int vx_gl_list_devices(vx_gl_device *out, int max, vx_err *err)
{
    egl_dev *e;
    int n = enum_devices(&e, err);
    if (n < 0) return -1;
    int k = n < max ? n : max;
    for (int i = 0; i < k; i++)
        out[i] = e[i].d;
    free(e);
    return k;
}

/* ---- context ------------------------------------------------------------ */

static const char *debug_source(GLenum s)
{
    switch (s) {
    case GL_DEBUG_SOURCE_API:
        return "api";
    case GL_DEBUG_SOURCE_WINDOW_SYSTEM:
        return "window_system";
    case GL_DEBUG_SOURCE_SHADER_COMPILER:
        return "shader_compiler";
    case GL_DEBUG_SOURCE_THIRD_PARTY:
        return "third_party";
    case GL_DEBUG_SOURCE_APPLICATION:
        return "application";
    default:
        return "other";
    }
}

static const char *debug_type(GLenum t)
{
    switch (t) {
    case GL_DEBUG_TYPE_ERROR:
        return "error";
    case GL_DEBUG_TYPE_DEPRECATED_BEHAVIOR:
        return "deprecated";
    case GL_DEBUG_TYPE_UNDEFINED_BEHAVIOR:
        return "undefined_behavior";
    case GL_DEBUG_TYPE_PORTABILITY:
        return "portability";
    case GL_DEBUG_TYPE_PERFORMANCE:
        return "performance";
    case GL_DEBUG_TYPE_MARKER:
        return "marker";
    default:
        return "other";
    }
}

/* At most GL_DEBUG_BURST gl.debug lines a second, then one line saying how
 * many were left out: a driver may say the same thing at every draw (a
 * shader recompiled for a state, a buffer's placement), thousands of lines
 * a job, and the log is every job's. */
enum { GL_DEBUG_BURST = 20 };

static int debug_rate_ok(void)
{
    static vx_log_rate rate = VX_LOG_RATE_INIT;
    unsigned dropped;
    int show = vx_log_rate_ok(&rate, GL_DEBUG_BURST, &dropped);
    if (dropped) VX_WARN("gl.debug_suppressed", "lines=%u seconds=1", dropped);
    return show;
}

static void APIENTRY debug_cb(GLenum source, GLenum type, GLuint id, GLenum severity,
                              GLsizei length, const GLchar *message, const void *user)
{
    vx_log_level lv;
    const char *sev;
    switch (severity) {
    case GL_DEBUG_SEVERITY_HIGH:
        lv = VX_LOG_ERR, sev = "high";
        break;
    case GL_DEBUG_SEVERITY_MEDIUM:
        lv = VX_LOG_WARN, sev = "medium";
        break;
    case GL_DEBUG_SEVERITY_LOW:
        lv = VX_LOG_INFO, sev = "low";
        break;
    default:
        lv = VX_LOG_DEBUG, sev = "notification";
        break;
    }
    if (lv > vx_log_get_level() || !debug_rate_ok()) return;
    char q[1024];
    vx_log(lv, "gl.debug", "source=%s type=%s id=%u severity=%s message=%s", debug_source(source),
           debug_type(type), id, sev, vx_log_quote(q, sizeof q, message));
}

/* What a plain (unversioned) context on this display offers, for the
 * message that explains why 4.5 core was refused. Best effort. */
static void probe_offered(vx_gl *gl, char *ver, size_t vsz, char *ren, size_t rsz)
{
    snprintf(ver, vsz, "unknown");
    snprintf(ren, rsz, "unknown");
    EGLContext c = eglCreateContext(gl->dpy, gl->cfg, EGL_NO_CONTEXT, NULL);
    if (c == EGL_NO_CONTEXT) {
        eglGetError();
        return;
    }
    if (eglMakeCurrent(gl->dpy, gl->surf, gl->surf, c)) {
        copy_str(ver, vsz, glGetString(GL_VERSION));
        copy_str(ren, rsz, glGetString(GL_RENDERER));
        eglMakeCurrent(gl->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    }
    eglDestroyContext(gl->dpy, c);
    eglGetError();
}

static EGLContext create_ctx(vx_gl *gl, int robust)
{
    EGLint a[16], k = 0;
    a[k++] = EGL_CONTEXT_MAJOR_VERSION;
    a[k++] = 4;
    a[k++] = EGL_CONTEXT_MINOR_VERSION;
    a[k++] = 5;
    a[k++] = EGL_CONTEXT_OPENGL_PROFILE_MASK;
    a[k++] = EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT;
    if (gl->egl15) {
        if (gl->desc.debug) {
            a[k++] = EGL_CONTEXT_OPENGL_DEBUG;
            a[k++] = EGL_TRUE;
        }
        if (robust) {
            a[k++] = EGL_CONTEXT_OPENGL_ROBUST_ACCESS;
            a[k++] = EGL_TRUE;
            a[k++] = EGL_CONTEXT_OPENGL_RESET_NOTIFICATION_STRATEGY;
            a[k++] = EGL_LOSE_CONTEXT_ON_RESET;
        }
    } else {
        /* EGL 1.4 + EGL_KHR_create_context spells the same requests as flags. */
        EGLint flags = (gl->desc.debug ? EGL_CONTEXT_OPENGL_DEBUG_BIT_KHR : 0) |
                       (robust ? EGL_CONTEXT_OPENGL_ROBUST_ACCESS_BIT_KHR : 0);
        if (flags) {
            a[k++] = EGL_CONTEXT_FLAGS_KHR;
            a[k++] = flags;
        }
        if (robust) {
            a[k++] = EGL_CONTEXT_OPENGL_RESET_NOTIFICATION_STRATEGY_KHR;
            a[k++] = EGL_LOSE_CONTEXT_ON_RESET_KHR;
        }
    }
    a[k] = EGL_NONE;
    return eglCreateContext(gl->dpy, gl->cfg, EGL_NO_CONTEXT, a);
}

static void destroy_context(vx_gl *gl)
{
    if (gl->ctx != EGL_NO_CONTEXT) {
        /* Program names belong to this context: delete them while it is
         * current, and forget them so a rebuilt context starts empty. */
        vx_gl_programs_clear(gl);
        eglMakeCurrent(gl->dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
        eglDestroyContext(gl->dpy, gl->ctx);
        gl->ctx = EGL_NO_CONTEXT;
    }
    if (gl->surf != EGL_NO_SURFACE) {
        eglDestroySurface(gl->dpy, gl->surf);
        gl->surf = EGL_NO_SURFACE;
    }
}

static long get_long(GLenum pname)
{
    GLint64 v = 0;
    glGetInteger64v(pname, &v);
    return (long)v;
}

/* Creates the 4.5 core context on gl->dpy (initialised, config chosen),
 * makes it current, checks what it offers and fills gl->info. On failure
 * nothing is left behind but the display. */
static int create_context(vx_gl *gl, vx_err *err)
{
    if (!gl->egl15 && !gl->khr_create)
        return vx_err_set(err, VX_EGPU, "gl_unsupported",
                          "%s: EGL %s has neither EGL 1.5 nor EGL_KHR_create_context, so an "
                          "OpenGL 4.5 core context cannot be requested",
                          gl->where, gl->info.egl_version);

    if (!gl->surfaceless) {
        const EGLint pb[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
        gl->surf = eglCreatePbufferSurface(gl->dpy, gl->cfg, pb);
        if (gl->surf == EGL_NO_SURFACE)
            return egl_fail(err, "egl_surface", "eglCreatePbufferSurface(1x1)", gl->where);
    }

    gl->info.robust = 0;
    gl->ctx = create_ctx(gl, gl->desc.robust);
    if (gl->ctx == EGL_NO_CONTEXT && gl->desc.robust) {
        EGLint e = eglGetError();
        VX_INFO("gl.robust_refused", "device=%d egl_error=%s", gl->info.device_index,
                egl_error_name(e));
        gl->ctx = create_ctx(gl, 0);
    }
    if (gl->ctx == EGL_NO_CONTEXT) {
        EGLint e = eglGetError();
        char ver[128], ren[256];
        probe_offered(gl, ver, sizeof ver, ren, sizeof ren);
        destroy_context(gl);
        return vx_err_set(err, VX_EGPU, "gl_unsupported",
                          "%s: OpenGL 4.5 core is not available (eglCreateContext: %s); the "
                          "driver offers GL_VERSION \"%s\", GL_RENDERER \"%s\"",
                          gl->where, egl_error_name(e), ver, ren);
    }
    if (!eglMakeCurrent(gl->dpy, gl->surf, gl->surf, gl->ctx)) {
        egl_fail(err, "egl_make_current", "eglMakeCurrent", gl->where);
        destroy_context(gl);
        return -1;
    }

    vx_gl_info *in = &gl->info;
    copy_str(in->vendor, sizeof in->vendor, glGetString(GL_VENDOR));
    copy_str(in->renderer, sizeof in->renderer, glGetString(GL_RENDERER));
    copy_str(in->version, sizeof in->version, glGetString(GL_VERSION));
    copy_str(in->glsl, sizeof in->glsl, glGetString(GL_SHADING_LANGUAGE_VERSION));
    GLint major = 0, minor = 0;
    glGetIntegerv(GL_MAJOR_VERSION, &major);
    glGetIntegerv(GL_MINOR_VERSION, &minor);
    for (GLuint i = 0; i < 3; i++) {
        GLint64 v = 0;
        glGetInteger64i_v(GL_MAX_COMPUTE_WORK_GROUP_COUNT, i, &v);
        in->max_compute_groups[i] = (long)v;
    }
    in->max_compute_invocations = get_long(GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS);
    in->max_ssbo_bytes = get_long(GL_MAX_SHADER_STORAGE_BLOCK_SIZE);
    in->max_texture_size = get_long(GL_MAX_TEXTURE_SIZE);
    in->max_3d_texture_size = get_long(GL_MAX_3D_TEXTURE_SIZE);
    in->max_samples = get_long(GL_MAX_SAMPLES);
    while (glGetError() != GL_NO_ERROR) {
    }

    if (major < 4 || (major == 4 && minor < 5) || in->max_compute_groups[0] <= 0 ||
        in->max_compute_invocations <= 0) {
        vx_err_set(err, VX_EGPU, "gl_unsupported",
                   "%s: need OpenGL 4.5 core with compute shaders, found GL_VERSION \"%s\" "
                   "(%d.%d), GL_RENDERER \"%s\", max compute work groups %ld",
                   gl->where, in->version, major, minor, in->renderer, in->max_compute_groups[0]);
        destroy_context(gl);
        return -1;
    }

    if (gl->desc.robust) {
        GLint strategy = 0;
        glGetIntegerv(GL_RESET_NOTIFICATION_STRATEGY, &strategy);
        in->robust = strategy == GL_LOSE_CONTEXT_ON_RESET;
    }
    if (gl->desc.debug) {
        glEnable(GL_DEBUG_OUTPUT);
        /* Synchronous: the message is logged inside the call that caused
         * it, on the GL thread, so the log line is next to its cause. */
        glEnable(GL_DEBUG_OUTPUT_SYNCHRONOUS);
        glDebugMessageCallback(debug_cb, gl);
        /* Notifications are debug-level chatter: let the driver skip them
         * unless they would be logged. */
        glDebugMessageControl(GL_DONT_CARE, GL_DONT_CARE, GL_DEBUG_SEVERITY_NOTIFICATION, 0, NULL,
                              vx_log_get_level() >= VX_LOG_DEBUG ? GL_TRUE : GL_FALSE);
    }

    char q1[300], q2[160];
    VX_INFO("gl.context", "device=%d kind=%s renderer=%s version=%s robust=%d debug=%d",
            in->device_index, in->device_kind, vx_log_quote(q1, sizeof q1, in->renderer),
            vx_log_quote(q2, sizeof q2, in->version), in->robust, gl->desc.debug ? 1 : 0);
    return 0;
}

/* Initialises dpy, picks a config and creates the context. On failure the
 * display is terminated and gl->dpy reset. */
static int try_display(vx_gl *gl, EGLDisplay dpy, const char *kind, int index, const char *name,
                       vx_err *err)
{
    if (index >= 0)
        snprintf(gl->where, sizeof gl->where, "EGL device %d (%s, %s)", index, kind, name);
    else
        snprintf(gl->where, sizeof gl->where, "the EGL surfaceless platform");
    snprintf(gl->info.device_kind, sizeof gl->info.device_kind, "%s", kind);
    gl->info.device_index = index;
    if (dpy == EGL_NO_DISPLAY)
        return egl_fail(err, "egl_display", "eglGetPlatformDisplay", gl->where);

    EGLint major = 0, minor = 0;
    if (!eglInitialize(dpy, &major, &minor))
        return egl_fail(err, "egl_init", "eglInitialize", gl->where);
    gl->dpy = dpy;
    copy_str(gl->info.egl_vendor, sizeof gl->info.egl_vendor, eglQueryString(dpy, EGL_VENDOR));
    copy_str(gl->info.egl_version, sizeof gl->info.egl_version, eglQueryString(dpy, EGL_VERSION));
    gl->egl15 = major > 1 || (major == 1 && minor >= 5);
    const char *ext = eglQueryString(dpy, EGL_EXTENSIONS);
    gl->khr_create = has_ext(ext, "EGL_KHR_create_context");
    gl->surfaceless = has_ext(ext, "EGL_KHR_surfaceless_context");

    if (!eglBindAPI(EGL_OPENGL_API)) {
        vx_err_set(err, VX_EGPU, "gl_unsupported",
                   "%s: desktop OpenGL is not available (eglBindAPI: %s)", gl->where,
                   egl_error_name(eglGetError()));
        goto fail;
    }
    if (gl->surfaceless && has_ext(ext, "EGL_KHR_no_config_context")) {
        gl->cfg = EGL_NO_CONFIG_KHR;
    } else {
        /* All rendering goes to FBOs: the config only has to allow a
         * desktop GL context (and a pbuffer when surfaceless is missing). */
        const EGLint want[] = {EGL_SURFACE_TYPE, gl->surfaceless ? EGL_DONT_CARE : EGL_PBUFFER_BIT,
                               EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
        EGLint n = 0;
        if (!eglChooseConfig(dpy, want, &gl->cfg, 1, &n) || n < 1) {
            vx_err_set(err, VX_EGPU, "gl_unsupported", "%s: no EGL config for desktop OpenGL%s",
                       gl->where, gl->surfaceless ? "" : " with a pbuffer");
            goto fail;
        }
    }
    if (create_context(gl, err) == 0) return 0;
fail:
    eglTerminate(dpy);
    gl->dpy = EGL_NO_DISPLAY;
    return -1;
}

int vx_gl_desc_device(const vx_gl_desc *desc)
{
    return desc && desc->pick_device && desc->device >= 0 ? desc->device : -1;
}

vx_gl *vx_gl_new(const vx_gl_desc *desc, vx_err *err)
{
    vx_gl *gl = calloc(1, sizeof *gl);
    if (!gl) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the GL context");
        return NULL;
    }
    if (desc) gl->desc = *desc;
    int want = vx_gl_desc_device(desc);
    gl->dpy = EGL_NO_DISPLAY;
    gl->surf = EGL_NO_SURFACE;
    gl->ctx = EGL_NO_CONTEXT;

    egl_dev *devs = NULL;
    int n = enum_devices(&devs, err);
    if (n < 0) goto fail;

    if (want >= 0) {
        /* An explicit choice is exact: no silent fallback to another GPU. */
        egl_dev *pick = NULL;
        for (int i = 0; i < n; i++)
            if (devs[i].d.index == want) pick = &devs[i];
        if (!pick) {
            /* Its own code: the caller's configuration is wrong (voxeld
             * exits 2 for it), where gl_no_device is this machine's lack. */
            if (n > 0)
                vx_err_set(err, VX_EGPU, "bad_egl_device",
                           "EGL device %d does not exist: %d EGL device%s found (indices 0..%d)",
                           want, n, n == 1 ? "" : "s", n - 1);
            else
                vx_err_set(err, VX_EGPU, "bad_egl_device",
                           "EGL device %d does not exist: no EGL devices found", want);
            goto fail;
        }
        EGLDisplay dpy = eglGetPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, pick->dev, NULL);
        if (try_display(gl, dpy, pick->d.kind, pick->d.index, pick->d.name, err)) goto fail;
    } else {
        int ok = 0, tried = 0;
        for (int i = 0; i < n && !ok; i++) {
            EGLDisplay dpy = eglGetPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, devs[i].dev, NULL);
            tried++;
            if (try_display(gl, dpy, devs[i].d.kind, devs[i].d.index, devs[i].d.name, err) == 0)
                ok = 1;
            else if (err) {
                char q[600];
                VX_WARN("gl.device_failed", "device=%d kind=%s code=%s message=%s", devs[i].d.index,
                        devs[i].d.kind, err->code, vx_log_quote(q, sizeof q, err->message));
            }
        }
        const char *cext = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
        if (!ok && has_ext(cext, "EGL_MESA_platform_surfaceless")) {
            EGLDisplay dpy =
                eglGetPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, NULL);
            tried++;
            if (try_display(gl, dpy, "surfaceless", -1, "", err) == 0) ok = 1;
        }
        if (!ok) {
            if (tried == 0)
                vx_err_set(err, VX_EGPU, "gl_no_device",
                           "no EGL device and no surfaceless platform: is an EGL vendor library "
                           "(libEGL_mesa or libEGL_nvidia) installed?");
            goto fail;
        }
    }
    free(devs);
    return gl;
fail:
    if (err) VX_ERROR("gl.init_failed", "code=%s device=%d", err->code, want);
    free(devs);
    free(gl);
    return NULL;
}

void vx_gl_free(vx_gl *gl)
{
    if (!gl) return;
    destroy_context(gl);
    /* The display is deliberately not terminated. EGL keeps one display per
     * device per process, shared by every vx_gl on that device: terminating
     * it here would pull it from under another live context (a second
     * vx_gl_new, or a test's). It also keeps the driver loaded until exit, so
     * its one-time global allocations stay reachable instead of showing up as
     * leaks from an unloaded module. A later vx_gl_new on the same device
     * reuses the initialised display. */
    /* Frees the per-thread state EGL keeps for the GL thread. */
    eglReleaseThread();
    free(gl->progs);
    free(gl);
}

int vx_gl_info_software(const vx_gl_info *info)
{
    static const char *const soft[] = {"llvmpipe", "softpipe", "swrast"};
    if (!strcmp(info->device_kind, "software")) return 1;
    for (size_t i = 0; i < sizeof soft / sizeof soft[0]; i++)
        if (strcasestr(info->renderer, soft[i])) return 1;
    return 0;
}

const vx_gl_info *vx_gl_get_info(const vx_gl *gl)
{
    return &gl->info;
}

int vx_gl_lost(vx_gl *gl)
{
    if (gl->ctx == EGL_NO_CONTEXT) return 1;
    return glGetGraphicsResetStatus() != GL_NO_ERROR;
}

int vx_gl_rebuild(vx_gl *gl, vx_err *err)
{
    destroy_context(gl);
    if (gl->dpy == EGL_NO_DISPLAY)
        vx_err_set(err, VX_EGPU, "gl_no_device", "no EGL display to rebuild on");
    if (gl->dpy == EGL_NO_DISPLAY || create_context(gl, err)) {
        /* The one log line of a failed rebuild: callers do not log it. */
        VX_ERROR("gl.rebuild_failed", "device=%d code=%s", gl->info.device_index,
                 err ? err->code : "?");
        return -1;
    }
    VX_INFO("gl.rebuilt", "device=%d", gl->info.device_index);
    return 0;
}

/* VX_GL_TRACE set: each check waits for the GPU and logs how long that
 * took, the time since the last check and the reset status (GPU bring-up:
 * which stage stalls or faults). GL thread only. */
static void trace_check(const char *where)
{
    static int on = -1;
    static double last;
    if (on < 0) on = getenv("VX_GL_TRACE") != NULL;
    if (!on) return;
    double t0 = vx_mono_ms();
    glFinish();
    double t1 = vx_mono_ms();
    GLenum reset = glGetGraphicsResetStatus();
    VX_INFO("gl.trace", "where=%s finish_ms=%.2f since_last_ms=%.2f reset=0x%x", where, t1 - t0,
            last > 0 ? t0 - last : 0.0, reset);
    last = t1;
}

int vx_gl_check(vx_gl *gl, const char *where, vx_err *err)
{
    trace_check(where);
    char names[256];
    size_t len = 0;
    int count = 0, oom = 0, lost = 0;
    names[0] = 0;
    GLenum e;
    /* A lost context may keep answering GL_CONTEXT_LOST: bound the loop. */
    while (count < 16 && (e = glGetError()) != GL_NO_ERROR) {
        oom |= e == GL_OUT_OF_MEMORY;
        lost |= e == GL_CONTEXT_LOST;
        int w =
            snprintf(names + len, sizeof names - len, "%s%s", count ? "," : "", gl_error_name(e));
        if (w > 0 && (size_t)w < sizeof names - len) len += (size_t)w;
        count++;
    }
    if (!count) return 0;
    VX_ERROR("gl.error", "where=%s errors=%s", where, names);
    if (lost)
        return vx_err_set(err, VX_EGPU, "gpu_context_lost", "GPU context lost at %s (%s)", where,
                          names);
    if (oom)
        return vx_err_set(err, VX_EGPU, "gpu_out_of_memory", "out of GPU memory at %s (%s)", where,
                          names);
    return vx_err_set(err, VX_EGPU, "gl_error", "OpenGL error at %s: %s", where, names);
}

void vx_gl_timer_begin(vx_gl_timer *t)
{
    /* VX_GL_NO_TIMERS: no timer queries, wall-clock time only (GPU
     * bring-up: a driver whose timer queries stall). GL thread only. */
    static int off = -1;
    if (off < 0) off = getenv("VX_GL_NO_TIMERS") != NULL;
    t->q = 0;
    t->cpu_start_ms = vx_mono_ms();
    if (off) return;
    glGenQueries(1, &t->q);
    glBeginQuery(GL_TIME_ELAPSED, t->q);
}

double vx_gl_timer_end_ms(vx_gl_timer *t)
{
    if (!t->q) { /* without timer queries; 0 once ended */
        double wall = t->cpu_start_ms < 0 ? 0 : vx_mono_ms() - t->cpu_start_ms;
        t->cpu_start_ms = -1;
        return wall;
    }
    glEndQuery(GL_TIME_ELAPSED);
    GLuint64 ns = 0;
    glGetQueryObjectui64v(t->q, GL_QUERY_RESULT, &ns);
    glDeleteQueries(1, &t->q);
    t->q = 0;
    double gpu = (double)ns / 1e6, wall = vx_mono_ms() - t->cpu_start_ms;
    if (gpu > wall + 1.0) {
        static int warned; /* GL thread only */
        if (!warned) VX_WARN("gl.timer_bogus", "gpu_ms=%.3f wall_ms=%.3f", gpu, wall);
        warned = 1;
        return wall;
    }
    return gpu;
}

double vx_gl_timer_end_compute_ms(vx_gl_timer *t)
{
    glFinish();
    double wall = vx_mono_ms() - t->cpu_start_ms, gpu = vx_gl_timer_end_ms(t);
    return gpu > wall * 1e-3 ? gpu : wall;
}
