/* PLY header parser (mesh/ply.h) and reader (vx_ply_read_mem, mesh.h),
 * from memory.
 *
 * assimp 5.2's PLY importer read past the end of its buffer (SEGV) on a
 * file that fuzz_ply made of a valid header and a mutated body, so PLY is
 * read here: the header's elements and properties (any of the eight value
 * types, lists with any integer count type), then the body in ASCII,
 * binary little or big endian, every read checked against the bytes left.
 * The vertex element's x, y and z, the face element's vertex_indices
 * (or vertex_index) list and the tristrips element's vertex_indices list
 * (strips of triangles, -1 between strips, as Stanford's scanning tools
 * wrote them) are kept; every other element and property is skipped;
 * nothing but blanks may follow the last element (a count too small
 * otherwise reads out of step). Polygons are kept. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "mesh/ply.h"
#include "mesh/text.h"

static int fail(vx_err *err, const char *fmt, ...) __attribute__((format(printf, 2, 3)));

static int fail(vx_err *err, const char *fmt, ...)
{
    char msg[200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return vx_err_set(err, VX_EINVAL, "ply_corrupt", "not a valid PLY file: %s", msg);
}

static const struct {
    const char *name;
    vx_ply_type type;
} ply_types[] = {
    {"char", VX_PLY_I8},   {"int8", VX_PLY_I8},     {"uchar", VX_PLY_U8},   {"uint8", VX_PLY_U8},
    {"short", VX_PLY_I16}, {"int16", VX_PLY_I16},   {"ushort", VX_PLY_U16}, {"uint16", VX_PLY_U16},
    {"int", VX_PLY_I32},   {"int32", VX_PLY_I32},   {"uint", VX_PLY_U32},   {"uint32", VX_PLY_U32},
    {"float", VX_PLY_F32}, {"float32", VX_PLY_F32}, {"double", VX_PLY_F64}, {"float64", VX_PLY_F64},
};

int vx_ply_type_size(vx_ply_type t)
{
    static const int size[] = {0, 1, 1, 2, 2, 4, 4, 4, 8};
    return t <= VX_PLY_F64 ? size[t] : 0;
}

static vx_ply_type type_of(const char *w, size_t len)
{
    for (size_t i = 0; i < sizeof ply_types / sizeof ply_types[0]; i++)
        if (strlen(ply_types[i].name) == len && !memcmp(ply_types[i].name, w, len))
            return ply_types[i].type;
    return VX_PLY_NONE;
}

/* The first name of t, for messages. */
static const char *type_name(vx_ply_type t)
{
    for (size_t i = 0; i < sizeof ply_types / sizeof ply_types[0]; i++)
        if (ply_types[i].type == t) return ply_types[i].name;
    return "value";
}

static int blank(unsigned char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

/* Splits line [p, end) into at most max words; returns the count. */
static int words(const char *p, const char *end, const char **w, size_t *wl, int max)
{
    int k = 0;
    while (p < end && k < max) {
        while (p < end && blank((unsigned char)*p))
            p++;
        if (p == end) break;
        w[k] = p;
        while (p < end && !blank((unsigned char)*p))
            p++;
        wl[k] = (size_t)(p - w[k]);
        k++;
    }
    return k;
}

static void copy_name(char dst[32], const char *w, size_t len)
{
    snprintf(dst, 32, "%.*s", (int)(len < 31 ? len : 31), w);
}

int vx_ply_header_parse(const unsigned char *p, size_t n, uint64_t size, vx_ply_header *h,
                        vx_err *err)
{
    const char *s = (const char *)p, *end = s + (n < VX_PLY_MAX_HEADER ? n : VX_PLY_MAX_HEADER);
    memset(h, 0, sizeof *h);
    int format = -1, line = 0;
    /* a UTF-8 byte order mark before "ply", as the text readers take it */
    const char *at = end - s >= 3 && !memcmp(s, "\xef\xbb\xbf", 3) ? s + 3 : s;
    for (;;) {
        const char *nl = memchr(at, '\n', (size_t)(end - at));
        if (!nl) {
            if (n < size && n < VX_PLY_MAX_HEADER) return 1;
            return fail(err, "no end_header in the first %d bytes", VX_PLY_MAX_HEADER);
        }
        const char *w[6];
        size_t wl[6];
        int k = words(at, nl, w, wl, 6);
        at = nl + 1;
        line++;
#define IS(i, lit) (wl[i] == strlen(lit) && !memcmp(w[i], lit, wl[i]))
        if (line == 1) {
            if (k != 1 || !IS(0, "ply")) return fail(err, "the first line is not \"ply\"");
            continue;
        }
        if (!k || IS(0, "comment") || IS(0, "obj_info")) continue;
        if (IS(0, "end_header")) break;
        if (IS(0, "format")) {
            if (k != 3 || !IS(2, "1.0")) return fail(err, "line %d: bad format line", line);
            if (IS(1, "ascii"))
                format = VX_PLY_ASCII;
            else if (IS(1, "binary_little_endian"))
                format = VX_PLY_LE;
            else if (IS(1, "binary_big_endian"))
                format = VX_PLY_BE;
            else
                return fail(err, "line %d: unknown format", line);
        } else if (IS(0, "element")) {
            if (k != 3 || h->nelems == VX_PLY_MAX_ELEMENTS)
                return fail(err, "line %d: bad element line (or more than %d elements)", line,
                            VX_PLY_MAX_ELEMENTS);
            vx_ply_elem *e = &h->elems[h->nelems++];
            copy_name(e->name, w[1], wl[1]);
            e->first_prop = h->nprops;
            if (!wl[2] || wl[2] > 12) return fail(err, "line %d: bad element count", line);
            for (size_t i = 0; i < wl[2]; i++) {
                if (w[2][i] < '0' || w[2][i] > '9')
                    return fail(err, "line %d: bad element count", line);
                e->count = e->count * 10 + (uint64_t)(w[2][i] - '0');
            }
        } else if (IS(0, "property")) {
            if (!h->nelems) return fail(err, "line %d: a property before any element", line);
            if (h->nprops == VX_PLY_MAX_PROPS)
                return fail(err, "line %d: more than %d properties", line, VX_PLY_MAX_PROPS);
            vx_ply_prop *pr = &h->props[h->nprops];
            if (k >= 2 && IS(1, "list")) {
                pr->count_type = k == 5 ? type_of(w[2], wl[2]) : VX_PLY_NONE;
                pr->type = k == 5 ? type_of(w[3], wl[3]) : VX_PLY_NONE;
                if (pr->count_type == VX_PLY_NONE || pr->type == VX_PLY_NONE ||
                    pr->count_type >= VX_PLY_F32)
                    return fail(err, "line %d: bad list property", line);
                copy_name(pr->name, w[4], wl[4]);
            } else {
                pr->type = k == 3 ? type_of(w[1], wl[1]) : VX_PLY_NONE;
                if (pr->type == VX_PLY_NONE) return fail(err, "line %d: bad property", line);
                copy_name(pr->name, w[2], wl[2]);
            }
            h->nprops++;
            h->elems[h->nelems - 1].nprops++;
        } else {
            return fail(err, "line %d: unknown header keyword", line);
        }
#undef IS
    }
    if (format < 0) return fail(err, "no format line");
    h->format = (vx_ply_format)format;
    h->body = (size_t)(at - s);
    return 0;
}

/* ---- the body ---------------------------------------------------------- */

typedef struct ply_in {
    const unsigned char *p, *end;
    vx_ply_format format;
    const char *elem; /* for messages */
    uint64_t entry;
    vx_err *err;
} ply_in;

static int short_body(ply_in *in)
{
    return fail(in->err, "element '%s' entry %llu: the file ends (or a value is malformed) there",
                in->elem, (unsigned long long)in->entry);
}

static uint64_t load(const unsigned char *p, int size, int big)
{
    uint64_t v = 0;
    for (int i = 0; i < size; i++)
        v |= (uint64_t)p[big ? size - 1 - i : i] << (8 * i);
    return v;
}

/* Reads one value of type t into *v. */
static int read_value(ply_in *in, vx_ply_type t, double *v)
{
    if (in->format == VX_PLY_ASCII) {
        while (in->p < in->end && blank(*in->p))
            in->p++;
        const unsigned char *w = in->p;
        while (in->p < in->end && !blank(*in->p))
            in->p++;
        size_t len = (size_t)(in->p - w);
        char tok[64];
        if (!len || len >= sizeof tok) return short_body(in);
        memcpy(tok, w, len);
        tok[len] = 0;
        /* (the OBJ reader's numbers: decimal, no hex, the "C" locale) */
        char *e = vx_mesh_parse_double(tok, v);
        if (!e || *e) return short_body(in);
        static const double
            lo[VX_PLY_F64 +
               1] = {[VX_PLY_I8] = INT8_MIN, [VX_PLY_I16] = INT16_MIN, [VX_PLY_I32] = INT32_MIN},
               hi[VX_PLY_F64 + 1] = {
                   [VX_PLY_I8] = INT8_MAX,    [VX_PLY_U8] = UINT8_MAX,  [VX_PLY_I16] = INT16_MAX,
                   [VX_PLY_U16] = UINT16_MAX, [VX_PLY_I32] = INT32_MAX, [VX_PLY_U32] = UINT32_MAX};
        if (t != VX_PLY_F32 && t != VX_PLY_F64 &&
            (!(*v >= lo[t] && *v <= hi[t]) || *v != floor(*v)))
            return fail(in->err, "element '%s' entry %llu: %s is not of type %s", in->elem,
                        (unsigned long long)in->entry, tok, type_name(t));
        return 0;
    }
    int size = vx_ply_type_size(t);
    if (in->end - in->p < size) return short_body(in);
    uint64_t u = load(in->p, size, in->format == VX_PLY_BE);
    in->p += size;
    switch (t) {
    case VX_PLY_I8:
        *v = (int8_t)u;
        break;
    case VX_PLY_U8:
    case VX_PLY_U16:
    case VX_PLY_U32:
        *v = (double)u;
        break;
    case VX_PLY_I16:
        *v = (int16_t)u;
        break;
    case VX_PLY_I32:
        *v = (int32_t)u;
        break;
    case VX_PLY_F32: {
        uint32_t b = (uint32_t)u;
        float f;
        memcpy(&f, &b, sizeof f);
        *v = f;
        break;
    }
    default: {
        memcpy(v, &u, sizeof *v);
        break;
    }
    }
    return 0;
}

/* Reads a list's count: a whole number the bytes left can hold. */
static int read_count(ply_in *in, vx_ply_type ct, vx_ply_type t, uint64_t *k)
{
    double c;
    if (read_value(in, ct, &c)) return -1;
    /* The shortest item: one byte of binary, a digit and a blank of ASCII. */
    double most = in->format == VX_PLY_ASCII ? (double)(in->end - in->p) / 2 + 1
                                             : (double)(in->end - in->p) / vx_ply_type_size(t);
    if (!(c >= 0) || c != floor(c) || c > most)
        return fail(in->err,
                    "element '%s' entry %llu: a list of %g items, more than the file holds",
                    in->elem, (unsigned long long)in->entry, c);
    *k = (uint64_t)c;
    return 0;
}

static int skip_values(ply_in *in, vx_ply_type t, uint64_t k)
{
    if (in->format != VX_PLY_ASCII) {
        in->p += k * (uint64_t)vx_ply_type_size(t); /* read_count checked it fits */
        return 0;
    }
    double v;
    for (uint64_t i = 0; i < k; i++)
        if (read_value(in, t, &v)) return -1;
    return 0;
}

static int find_prop(const vx_ply_header *h, const vx_ply_elem *e, const char *name)
{
    for (int i = 0; i < e->nprops; i++)
        if (!strcmp(h->props[e->first_prop + i].name, name)) return e->first_prop + i;
    return -1;
}

typedef struct ply_out {
    vx_mesh *m;
    size_t cap, used, kept, ntris;
    size_t fcap; /* face_start's room, less its closing entry */
    const vx_mesh_limits *lim;
} ply_out;

/* Room for k more corners in face_idx; a face's corner takes a byte of
 * the file at least, a strip's triangle (three corners) one of its own
 * indices: at most 3 n + 16 in all. */
static int room(ply_in *in, ply_out *o, uint64_t k, size_t n)
{
    if (o->used + k <= o->cap) return 0;
    size_t cap = 2 * o->cap + (size_t)k;
    if (cap > 3 * n + 16) cap = 3 * n + 16;
    if (o->used + k > cap) return short_body(in);
    uint32_t *g = realloc(o->m->face_idx, cap * sizeof(uint32_t));
    if (!g)
        return vx_err_set(in->err, VX_EINTERNAL, "out_of_memory", "no memory to read the PLY file");
    o->m->face_idx = g;
    o->cap = cap;
    return 0;
}

/* Closes the face of the corners face_idx[used..used + k) (k >= 3). */
static int keep_face(ply_in *in, ply_out *o, uint64_t k, size_t n)
{
    if (o->kept == o->fcap) {
        size_t fcap = 2 * o->fcap + 16;
        if (fcap > n + 16) fcap = n + 16; /* a face or strip triangle per byte at most */
        if (o->kept == fcap) return short_body(in);
        uint32_t *f = realloc(o->m->face_start, (fcap + 1) * sizeof(uint32_t));
        if (!f)
            return vx_err_set(in->err, VX_EINTERNAL, "out_of_memory",
                              "no memory to read the PLY file");
        o->m->face_start = f;
        o->fcap = fcap;
    }
    o->m->face_start[o->kept++] = (uint32_t)o->used;
    o->used += k;
    o->ntris += k - 2;
    if (o->lim && o->lim->max_triangles && o->ntris > o->lim->max_triangles)
        return vx_err_set(in->err, VX_ETOOBIG, "mesh_too_big",
                          "the PLY file has more than %zu triangles (the limit)",
                          o->lim->max_triangles);
    return 0;
}

/* A vertex index read as v: a whole number in 0..UINT32_MAX - 1. */
static int vertex_index(ply_in *in, double v, uint32_t *out)
{
    if (!(v >= 0) || v != floor(v) || v >= UINT32_MAX)
        return fail(in->err, "element '%s' entry %llu: a bad vertex index", in->elem,
                    (unsigned long long)in->entry);
    *out = (uint32_t)v;
    return 0;
}

/* A tristrips entry of k indices: each index after a strip's first two
 * makes a triangle with the two before it, every second one turned so
 * that the strip keeps one orientation; -1 starts a new strip. A
 * triangle that repeats a vertex (strips are stitched with them) is
 * dropped. */
static int read_strip(ply_in *in, ply_out *o, vx_ply_type t, uint64_t k, size_t n)
{
    uint32_t a = 0, b = 0;
    uint64_t have = 0; /* indices of the current strip so far */
    for (uint64_t i = 0; i < k; i++) {
        double v;
        uint32_t c = 0;
        if (read_value(in, t, &v)) return -1;
        if (v == -1) {
            have = 0;
            continue;
        }
        if (vertex_index(in, v, &c)) return -1;
        if (have >= 2 && a != b && b != c && a != c) {
            if (room(in, o, 3, n)) return -1;
            uint32_t *f = o->m->face_idx + o->used;
            f[0] = have % 2 ? b : a;
            f[1] = have % 2 ? a : b;
            f[2] = c;
            if (keep_face(in, o, 3, n)) return -1;
        }
        a = b;
        b = c;
        have++;
    }
    return 0;
}

static int read_face(ply_in *in, ply_out *o, vx_ply_type t, uint64_t k, size_t n)
{
    if (room(in, o, k, n)) return -1;
    for (uint64_t i = 0; i < k; i++) {
        double v;
        if (read_value(in, t, &v) || vertex_index(in, v, &o->m->face_idx[o->used + i])) return -1;
    }
    if (k < 3) return 0; /* points and edges */
    uint32_t rep, small[16], *scr = k > 16 ? malloc((size_t)k * sizeof *scr) : small;
    if (!scr)
        return vx_err_set(in->err, VX_EINTERNAL, "out_of_memory", "no memory to read the PLY file");
    int twice = vx_mesh_face_repeat(o->m->face_idx + o->used, (size_t)k, scr, &rep);
    if (scr != small) free(scr);
    if (twice)
        return fail(in->err, "element '%s' entry %llu uses vertex %u twice", in->elem,
                    (unsigned long long)in->entry, rep);
    return keep_face(in, o, k, n);
}

vx_mesh *vx_ply_read_mem(const unsigned char *data, size_t n, const vx_mesh_limits *lim,
                         vx_err *err)
{
    vx_mesh_declared d;
    if (vx_declared_check(VX_MESH_PLY, data, n, n, lim, &d, err)) return NULL;
    vx_ply_header *h = malloc(sizeof *h);
    vx_mesh *m = vx_mesh_new();
    if (!h || !m) goto oom;
    if (vx_ply_header_parse(data, n, n, h, err)) goto out;
    const vx_ply_elem *ve = NULL, *fe = NULL, *te = NULL;
    for (int i = 0; i < h->nelems; i++) {
        if (!ve && !strcmp(h->elems[i].name, "vertex")) ve = &h->elems[i];
        if (!fe && !strcmp(h->elems[i].name, "face")) fe = &h->elems[i];
        if (!te && !strcmp(h->elems[i].name, "tristrips")) te = &h->elems[i];
    }
    int xyz[3] = {-1, -1, -1}, fi = -1, ti = -1;
    if (ve)
        for (int a = 0; a < 3; a++) {
            xyz[a] = find_prop(h, ve, (const char *[]){"x", "y", "z"}[a]);
            if (xyz[a] < 0 || h->props[xyz[a]].count_type != VX_PLY_NONE) {
                fail(err, "the vertex element has no scalar property %c", "xyz"[a]);
                goto out;
            }
        }
    if (fe) {
        fi = find_prop(h, fe, "vertex_indices");
        if (fi < 0) fi = find_prop(h, fe, "vertex_index");
        if (fi < 0 || h->props[fi].count_type == VX_PLY_NONE) {
            fail(err, "the face element has no vertex_indices list");
            goto out;
        }
    }
    if (te) {
        ti = find_prop(h, te, "vertex_indices");
        if (ti < 0 || h->props[ti].count_type == VX_PLY_NONE) {
            fail(err, "the tristrips element has no vertex_indices list");
            goto out;
        }
    }
    if (!ve && ((fe && fe->count) || (te && te->count))) {
        fail(err, "faces but no vertex element");
        goto out;
    }
    if (!ve || !((fe && fe->count) || (te && te->count))) {
        vx_err_set(err, VX_EUNPROC, "ply_no_faces", "the PLY file has no faces");
        goto out;
    }
    /* vx_declared_check held the counts to the bytes after the header. */
    size_t nv = (size_t)ve->count, nf = fe ? (size_t)fe->count : 0;
    ply_out o = {.m = m, .cap = 3 * nf + 16, .fcap = nf, .lim = lim};
    if (o.cap > n + 16) o.cap = n + 16;
    m->pos = malloc(3 * nv * sizeof(double) + 1);
    m->face_start = malloc((nf + 1) * sizeof(uint32_t));
    m->face_idx = malloc(o.cap * sizeof(uint32_t));
    if (!m->pos || !m->face_start || !m->face_idx) goto oom;
    ply_in in = {.p = data + h->body, .end = data + n, .format = h->format, .err = err};
    for (int i = 0; i < h->nelems; i++) {
        const vx_ply_elem *e = &h->elems[i];
        in.elem = e->name;
        for (in.entry = 0; in.entry < e->count; in.entry++) {
            for (int j = e->first_prop; j < e->first_prop + e->nprops; j++) {
                const vx_ply_prop *pr = &h->props[j];
                double v;
                uint64_t k = 0;
                if (pr->count_type == VX_PLY_NONE) {
                    if (read_value(&in, pr->type, &v)) goto out;
                    if (e != ve) continue;
                    for (int a = 0; a < 3; a++) {
                        if (j != xyz[a]) continue;
                        if (!isfinite(v)) {
                            fail(err, "vertex %llu has a NaN or infinite coordinate",
                                 (unsigned long long)in.entry);
                            goto out;
                        }
                        m->pos[3 * in.entry + a] = v;
                    }
                    continue;
                }
                if (read_count(&in, pr->count_type, pr->type, &k)) goto out;
                if (e == fe && j == fi   ? read_face(&in, &o, pr->type, k, n)
                    : e == te && j == ti ? read_strip(&in, &o, pr->type, k, n)
                                         : skip_values(&in, pr->type, k))
                    goto out;
            }
        }
    }
    /* What the header declares is the whole body: bytes after it (past
     * blanks) mean a count that is too small or data out of step */
    while (in.p < in.end && blank(*in.p))
        in.p++;
    if (in.p < in.end) {
        fail(err,
             "%llu bytes after the last element that the header declares (a count that is "
             "too small, or entries out of step with the header)",
             (unsigned long long)(in.end - in.p));
        goto out;
    }
    for (size_t i = 0; i < o.used; i++)
        if (m->face_idx[i] >= nv) {
            fail(err, "a face index (%u) out of range (%zu vertices)", m->face_idx[i], nv);
            goto out;
        }
    if (!o.kept) {
        vx_err_set(err, VX_EUNPROC, "ply_no_faces",
                   "the PLY file has no faces of three or more vertices (each of its %zu face "
                   "entries is a point or an edge, and its strips make no triangle that uses "
                   "three vertices)",
                   nf);
        goto out;
    }
    m->face_start[o.kept] = (uint32_t)o.used;
    m->nverts = nv;
    m->nfaces = o.kept;
    if (vx_mesh_analyze(m, err)) goto out;
    free(h);
    return m;
oom:
    vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to read the PLY file");
out:
    free(h);
    vx_mesh_free(m);
    return NULL;
}
