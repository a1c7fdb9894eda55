/* OBJ and binary PLY writers (Draco is in draco.cc).
 *
 * Both keep the face structure rather than the triangulated view: the
 * outputs feed tools that care about quads and patches. On any failure the
 * partial file is removed, so a caller never picks up half a mesh. */
#include "mesh/mesh.h"

#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "util/fsutil.h"
#include "util/log.h"

typedef struct out_file {
    FILE *f;
    const char *path;
    int regular; /* only a regular file is removed after a failure */
} out_file;

/* Reports a write error with errno's text; closes the file and removes it
 * when it is a regular file (never a device or FIFO the caller named). */
static int write_fail(out_file *o, int e, vx_err *err)
{
    if (o->f) fclose(o->f);
    o->f = NULL;
    if (o->regular) remove(o->path);
    VX_ERROR("mesh.write_failed", "path=%s errno=%d", VX_Q(o->path), e);
    return vx_err_set(err, VX_EIO, "io_error", "cannot write %s: %s", vx_path_base(o->path),
                      strerror(e));
}

static int open_out(out_file *o, const char *path, vx_err *err)
{
    o->path = path;
    o->regular = 0;
    o->f = fopen(path, "wb");
    if (!o->f) {
        int e = errno;
        VX_ERROR("mesh.write_failed", "errno=%d", e);
        return vx_err_set(err, VX_EIO, "io_error", "cannot create %s: %s", vx_path_base(path),
                          strerror(e));
    }
    struct stat st;
    o->regular = fstat(fileno(o->f), &st) == 0 && S_ISREG(st.st_mode);
    /* Large buffer: these files are written in many small pieces. */
    setvbuf(o->f, NULL, _IOFBF, 1 << 20);
    return 0;
}

static int close_out(out_file *o, vx_err *err)
{
    /* fclose flushes: a full disk often shows up only here. */
    if (ferror(o->f)) return write_fail(o, errno ? errno : EIO, err);
    FILE *f = o->f;
    o->f = NULL;
    if (fclose(f)) return write_fail(o, errno, err);
    return 0;
}

/* How far the mesh lies from the origin for its size: its largest
 * coordinate magnitude over its largest bbox extent (1 when it has no
 * extent or a coordinate is not finite). A mesh of size 1 at 1e12 printed
 * with 9 digits or stored as floats was one point. */
static double offset_ratio(const vx_mesh *m)
{
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0}, big = 0;
    for (size_t i = 0; i < m->nverts; i++)
        for (int a = 0; a < 3; a++) {
            double x = m->pos[3 * i + (size_t)a];
            if (i == 0 || x < lo[a]) lo[a] = x;
            if (i == 0 || x > hi[a]) hi[a] = x;
            if (fabs(x) > big) big = fabs(x);
        }
    double ext = 0;
    for (int a = 0; a < 3; a++)
        if (hi[a] - lo[a] > ext) ext = hi[a] - lo[a];
    double r = big / ext;
    return ext > 0 && isfinite(r) && r > 1 ? r : 1;
}

/* Past this offset_ratio a float (2^-24 of the coordinate) moves a vertex
 * by over 1e-6 of the mesh's extent: PLY positions are then doubles, and
 * OBJ coordinates get more digits than a float's 9. */
#define FAR_RATIO (1e-6 * 16777216.0)

/* Significant digits of an OBJ coordinate: 9 up to FAR_RATIO, one more
 * for each tenfold past it (so a position keeps about as much of the
 * extent as at FAR_RATIO), at most 17 (a double's). */
static int obj_digits(const vx_mesh *m)
{
    double r = offset_ratio(m);
    int d = r > FAR_RATIO ? 9 + (int)ceil(log10(r / FAR_RATIO)) : 9;
    return d > 17 ? 17 : d;
}

int vx_obj_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err)
{
    const float *nrm = o ? o->normals : NULL;
    const uint32_t *grp = o ? o->face_group : NULL;
    const char *prefix = o && o->group_prefix ? o->group_prefix : "patch";
    out_file out;
    if (open_out(&out, path, err)) return -1;
    FILE *f = out.f;
    errno = 0;
    if (fprintf(f, "# voxeld: %zu vertices, %zu faces\n", m->nverts, m->nfaces) < 0) goto io;
    int dig = obj_digits(m);
    for (size_t i = 0; i < m->nverts; i++) {
        const double *p = m->pos + 3 * i;
        if (fprintf(f, "v %.*g %.*g %.*g\n", dig, p[0], dig, p[1], dig, p[2]) < 0) goto io;
    }
    if (nrm)
        for (size_t i = 0; i < m->nverts; i++) {
            const float *n = nrm + 3 * i;
            if (fprintf(f, "vn %.9g %.9g %.9g\n", n[0], n[1], n[2]) < 0) goto io;
        }
    for (size_t fi = 0; fi < m->nfaces; fi++) {
        if (grp && (fi == 0 || grp[fi] != grp[fi - 1]))
            if (fprintf(f, "g %s%u\n", prefix, grp[fi]) < 0) goto io;
        const uint32_t *v = vx_mesh_face(m, fi);
        uint32_t n = vx_mesh_face_size(m, fi);
        if (putc('f', f) == EOF) goto io;
        for (uint32_t k = 0; k < n; k++) {
            /* v//n: the normal of a corner is its vertex's normal */
            int r = nrm ? fprintf(f, " %u//%u", v[k] + 1, v[k] + 1) : fprintf(f, " %u", v[k] + 1);
            if (r < 0) goto io;
        }
        if (putc('\n', f) == EOF) goto io;
    }
    return close_out(&out, err);
io:
    return write_fail(&out, errno ? errno : EIO, err);
}

/* Little-endian output independent of the host byte order. */
typedef struct le_out {
    FILE *f;
    unsigned char buf[1 << 16];
    size_t n;
    int failed;
} le_out;

static void le_flush(le_out *w)
{
    if (w->n && !w->failed && fwrite(w->buf, 1, w->n, w->f) != w->n) w->failed = 1;
    w->n = 0;
}

static inline void le_u32(le_out *w, uint32_t x)
{
    if (w->n + 4 > sizeof w->buf) le_flush(w);
    w->buf[w->n++] = (unsigned char)x;
    w->buf[w->n++] = (unsigned char)(x >> 8);
    w->buf[w->n++] = (unsigned char)(x >> 16);
    w->buf[w->n++] = (unsigned char)(x >> 24);
}

static inline void le_u8(le_out *w, uint8_t x)
{
    if (w->n + 1 > sizeof w->buf) le_flush(w);
    w->buf[w->n++] = x;
}

static inline void le_f32(le_out *w, float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    le_u32(w, u);
}

static inline void le_f64(le_out *w, double x)
{
    uint64_t u;
    memcpy(&u, &x, sizeof u);
    le_u32(w, (uint32_t)u);
    le_u32(w, (uint32_t)(u >> 32));
}

int vx_ply_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err)
{
    const float *nrm = o ? o->normals : NULL;
    const uint32_t *grp = o ? o->face_group : NULL;
    uint32_t maxn = 0;
    for (size_t fi = 0; fi < m->nfaces; fi++)
        if (vx_mesh_face_size(m, fi) > maxn) maxn = vx_mesh_face_size(m, fi);
    /* uchar counts are what every PLY reader expects; a face of more than
     * 255 vertices needs the wider count type. */
    int wide = maxn > 255;
    int dbl = offset_ratio(m) > FAR_RATIO;
    const char *ptype = dbl ? "double" : "float";

    le_out *w = malloc(sizeof *w);
    if (!w) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the PLY writer");
    out_file out;
    if (open_out(&out, path, err)) {
        free(w);
        return -1;
    }
    FILE *f = out.f;
    w->f = f;
    w->n = 0;
    w->failed = 0;
    errno = 0;
    if (fprintf(f,
                "ply\nformat binary_little_endian 1.0\ncomment voxeld\n"
                "element vertex %zu\nproperty %s x\nproperty %s y\nproperty %s z\n",
                m->nverts, ptype, ptype, ptype) < 0 ||
        (nrm && fputs("property float nx\nproperty float ny\nproperty float nz\n", f) < 0) ||
        fprintf(f, "element face %zu\nproperty list %s uint vertex_indices\n", m->nfaces,
                wide ? "uint" : "uchar") < 0 ||
        (grp && fputs("property int patch\n", f) < 0) || fputs("end_header\n", f) < 0)
        goto io;
    for (size_t i = 0; i < m->nverts && !w->failed; i++) {
        for (int a = 0; a < 3; a++)
            if (dbl)
                le_f64(w, m->pos[3 * i + a]);
            else
                le_f32(w, (float)m->pos[3 * i + a]);
        if (nrm)
            for (int a = 0; a < 3; a++)
                le_f32(w, nrm[3 * i + a]);
    }
    for (size_t fi = 0; fi < m->nfaces && !w->failed; fi++) {
        const uint32_t *v = vx_mesh_face(m, fi);
        uint32_t n = vx_mesh_face_size(m, fi);
        if (wide)
            le_u32(w, n);
        else
            le_u8(w, (uint8_t)n);
        for (uint32_t k = 0; k < n; k++)
            le_u32(w, v[k]);
        if (grp) le_u32(w, grp[fi]); /* int patch: ids above INT32_MAX wrap */
    }
    le_flush(w);
    if (w->failed) goto io;
    free(w);
    return close_out(&out, err);
io:
    free(w);
    return write_fail(&out, errno ? errno : EIO, err);
}
