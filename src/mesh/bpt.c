/* Streaming reader for Newell's Bézier patch text format (.bpt), and the
 * tessellation that gives such an upload faces the rasterizing engines can
 * draw (mesh.h documents the layout and the index order). */
#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "mesh/mesh.h"
#include "mesh/text.h"
#include "util/log.h"

#define BPT_MAX_LINE 4096
/* The shortest lines the format allows: 16 one-digit indices with 15
 * separators, and "x,y,z" with one-digit numbers, each with its newline. */
#define BPT_MIN_PATCH_LINE 32
#define BPT_MIN_POINT_LINE 6

typedef struct bpt_reader {
    FILE *f;
    vx_err *err;
    size_t lineno;
    char line[BPT_MAX_LINE + 2];
} bpt_reader;

static int bpt_fail(bpt_reader *r, vx_err_kind kind, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

static int bpt_fail(bpt_reader *r, vx_err_kind kind, const char *code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vx_mesh_line_fail(r->err, r->lineno, "mesh.bpt_reject", kind, code, fmt, ap);
    va_end(ap);
    return -1;
}

/* Reads the next non-blank line into r->line (NUL-terminated, without the
 * newline). Returns 1 at the end of the file, 0 for a line, -1 on error. */
static int next_line(bpt_reader *r)
{
    int c = 0;
    while (c != EOF) {
        size_t len = 0;
        r->lineno++;
        while ((c = getc(r->f)) != EOF && c != '\n') {
            if (c == 0) return bpt_fail(r, VX_EINVAL, "bpt_junk", "NUL byte in the line");
            if (len == BPT_MAX_LINE)
                return bpt_fail(r, VX_EINVAL, "bpt_line_too_long", "line longer than %d bytes",
                                BPT_MAX_LINE);
            r->line[len++] = (char)c;
        }
        if (c == EOF && ferror(r->f))
            return bpt_fail(r, VX_EIO, "mesh_io", "read error: %s", strerror(errno));
        r->line[len] = 0;
        char *p = r->line;
        if (r->lineno == 1 && len >= 3 && memcmp(p, "\xef\xbb\xbf", 3) == 0) p += 3;
        while (vx_mesh_is_blank(*p))
            p++;
        if (*p) {
            memmove(r->line, p, strlen(p) + 1);
            return 0;
        }
    }
    return 1;
}

/* Splits the current line into exactly n fields separated by one comma
 * and/or blanks; fields[i] point into r->line, NUL-terminated. */
static int split(bpt_reader *r, char **fields, int n, const char *what)
{
    char *p = r->line;
    int k = 0;
    for (;;) {
        while (vx_mesh_is_blank(*p))
            p++;
        if (!*p) break;
        if (*p == ',') return bpt_fail(r, VX_EINVAL, "bpt_junk", "empty field in %s", what);
        if (k == n) return bpt_fail(r, VX_EINVAL, "bpt_junk", "more than %d fields in %s", n, what);
        fields[k++] = p;
        while (*p && *p != ',' && !vx_mesh_is_blank(*p))
            p++;
        char *end = p;
        while (vx_mesh_is_blank(*p))
            p++;
        int comma = *p == ',';
        if (comma) p++;
        *end = 0;
        if (comma) {
            while (vx_mesh_is_blank(*p))
                p++;
            if (!*p) return bpt_fail(r, VX_EINVAL, "bpt_junk", "trailing comma in %s", what);
        }
    }
    if (k != n) return bpt_fail(r, VX_EINVAL, "bpt_junk", "%s needs %d fields, got %d", what, n, k);
    return 0;
}

/* Unsigned decimal integer field; past 2^40 (far above any valid count)
 * it is UINT64_MAX, which messages call "over 2^40" (count_text). */
static int parse_uint(bpt_reader *r, const char *s, const char *what, uint64_t *out)
{
    uint64_t v = 0;
    const char *p = s;
    if (*p == '+') p++;
    if (!*p) return bpt_fail(r, VX_EINVAL, "bpt_junk", "%s: empty number", what);
    for (; *p; p++) {
        if (*p < '0' || *p > '9')
            return bpt_fail(r, VX_EINVAL, "bpt_junk", "%s: '%.40s' is not an unsigned integer",
                            what, s);
        v = v < UINT64_C(1) << 40 ? v * 10 + (uint64_t)(*p - '0') : UINT64_MAX;
    }
    *out = v;
    return 0;
}

/* A count for a message: its digits, or "over 2^40" when it was past that. */
static const char *count_text(uint64_t v, char buf[24])
{
    if (v == UINT64_MAX) return "over 2^40";
    snprintf(buf, 24, "%llu", (unsigned long long)v);
    return buf;
}

/* Bytes of the file after the current position, or UINT64_MAX when the
 * file's size is not known (a pipe, a memory stream). */
static uint64_t bytes_left(bpt_reader *r)
{
    struct stat st;
    off_t here = ftello(r->f);
    int fd = fileno(r->f);
    if (fd < 0 || here < 0 || fstat(fd, &st) || !S_ISREG(st.st_mode) || st.st_size < here)
        return UINT64_MAX;
    return (uint64_t)(st.st_size - here);
}

/* Room for `count` records of which `have` are stored: grows *p (elsize
 * bytes a record) by half again, so that memory follows the data read and
 * never a declared count; capped at `declared`. */
static int grow_to(void **p, size_t *cap, size_t need, size_t declared, size_t elsize)
{
    if (need <= *cap) return 0;
    size_t n = *cap + *cap / 2 + 1024;
    if (n > declared) n = declared;
    if (n < need) n = need;
    void *q = realloc(*p, n * elsize);
    if (!q) return -1;
    *p = q;
    *cap = n;
    return 0;
}

/* A line holding one count (patches, points). */
static int read_count(bpt_reader *r, const char *what, uint64_t *out)
{
    int e = next_line(r);
    if (e < 0) return -1;
    if (e) return bpt_fail(r, VX_EINVAL, "bpt_truncated", "the file ends before the %s", what);
    char *f;
    if (split(r, &f, 1, what) || parse_uint(r, f, what, out)) return -1;
    return 0;
}

static void bernstein(double t, double b[4])
{
    double s = 1 - t;
    b[0] = s * s * s;
    b[1] = 3 * t * s * s;
    b[2] = 3 * t * t * s;
    b[3] = t * t * t;
}

/* One patch edge: its four control-point indices in the patch's order. */
typedef struct bpt_edge {
    uint32_t key[4]; /* canonical order (the smaller of it and its reverse) */
    uint32_t patch, side;
    int reversed;  /* key is the patch's order reversed */
    uint32_t base; /* first of its VX_BPT_TESS - 1 vertices */
} bpt_edge;

static int cmp4(const uint32_t *x, const uint32_t *y)
{
    for (int i = 0; i < 4; i++)
        if (x[i] != y[i]) return x[i] < y[i] ? -1 : 1;
    return 0;
}

static int cmp_edge(const void *a, const void *b)
{
    return cmp4(((const bpt_edge *)a)->key, ((const bpt_edge *)b)->key);
}

/* Slots of each side's control points, from corner to corner in the
 * direction of increasing u (sides 0, 2) or v (sides 1, 3). */
static const int side_slots[4][4] = {{0, 1, 2, 3}, {3, 7, 11, 15}, {12, 13, 14, 15}, {0, 4, 8, 12}};

static void eval_patch(const vx_mesh *m, const uint32_t *idx, double u, double v, double *out)
{
    double bu[4], bv[4];
    bernstein(u, bu);
    bernstein(v, bv);
    out[0] = out[1] = out[2] = 0;
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            const double *p = m->pos + 3 * (size_t)idx[4 * j + i];
            double w = bu[i] * bv[j];
            out[0] += w * p[0];
            out[1] += w * p[1];
            out[2] += w * p[2];
        }
}

static int cmp_point(const void *a, const void *b, void *pos)
{
    const double *x = (const double *)pos + 3 * (size_t) * (const uint32_t *)a,
                 *y = (const double *)pos + 3 * (size_t) * (const uint32_t *)b;
    for (int k = 0; k < 3; k++)
        if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return *(const uint32_t *)a < *(const uint32_t *)b ? -1 : 1;
}

/* Points written twice in the file (the teapot has some on patch seams)
 * are one point: patch_idx is remapped to the first of equal coordinates,
 * so that the patches sharing them share edges and corner keys. */
static int dedupe_points(vx_mesh *m, vx_err *err)
{
    uint32_t *order = malloc(m->nverts * sizeof *order + 1),
             *canon = malloc(m->nverts * sizeof *canon + 1);
    if (!order || !canon) {
        free(order);
        free(canon);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the points");
    }
    for (size_t i = 0; i < m->nverts; i++)
        order[i] = (uint32_t)i;
    qsort_r(order, m->nverts, sizeof *order, cmp_point, m->pos);
    for (size_t i = 0; i < m->nverts; i++) {
        const double *a = m->pos + 3 * (size_t)order[i];
        const double *b = i ? m->pos + 3 * (size_t)order[i - 1] : NULL;
        canon[order[i]] =
            b && a[0] == b[0] && a[1] == b[1] && a[2] == b[2] ? canon[order[i - 1]] : order[i];
    }
    for (size_t k = 0; k < 16 * m->npatches; k++)
        m->patch_idx[k] = canon[m->patch_idx[k]];
    free(order);
    free(canon);
    return 0;
}

/* Fills e[4 * p + s] with side s of patch p, keyed canonically. */
static void patch_edges(const vx_mesh *m, bpt_edge *e)
{
    for (size_t p = 0; p < m->npatches; p++)
        for (int s = 0; s < 4; s++) {
            bpt_edge *x = &e[4 * p + (size_t)s];
            uint32_t fw[4], bw[4];
            for (int k = 0; k < 4; k++) {
                fw[k] = m->patch_idx[16 * p + (size_t)side_slots[s][k]];
                bw[3 - k] = fw[k];
            }
            x->reversed = cmp4(bw, fw) < 0;
            memcpy(x->key, x->reversed ? bw : fw, sizeof fw);
            x->patch = (uint32_t)p;
            x->side = (uint32_t)s;
        }
}

/* Gives each distinct edge of the sorted edges its vertex block (numbered
 * from nv on) and points byp[4 * patch + side] at it; returns the vertex
 * count after the blocks. */
static uint64_t edge_blocks(bpt_edge *sorted, size_t ne, bpt_edge **byp, uint64_t nv)
{
    const uint32_t T = VX_BPT_TESS;
    for (size_t i = 0; i < ne; i++) {
        int collapsed = sorted[i].key[0] == sorted[i].key[1] &&
                        sorted[i].key[1] == sorted[i].key[2] &&
                        sorted[i].key[2] == sorted[i].key[3];
        if (i > 0 && cmp_edge(&sorted[i], &sorted[i - 1]) == 0) {
            sorted[i].base = sorted[i - 1].base;
        } else if (collapsed) {
            sorted[i].base = UINT32_MAX;
        } else {
            sorted[i].base = (uint32_t)nv;
            nv += T - 1;
        }
        byp[4 * sorted[i].patch + sorted[i].side] = &sorted[i];
    }
    return nv;
}

/* Fills grid[(T+1)*b + a] with the vertex of patch p at (u, v) = (a/T, b/T),
 * evaluating new interior vertices from *next on and shared edge vertices. */
static void patch_grid(vx_mesh *m, size_t p, bpt_edge *const *byp, uint32_t *grid, size_t *next)
{
    const uint32_t T = VX_BPT_TESS;
    const uint32_t *idx = m->patch_idx + 16 * p;
    for (uint32_t b = 0; b <= T; b++)
        for (uint32_t a = 0; a <= T; a++) {
            int s = -1;
            uint32_t t = 0; /* step along side s, in the side's own direction */
            if (b == 0)
                s = 0, t = a;
            else if (b == T)
                s = 2, t = a;
            else if (a == 0)
                s = 3, t = b;
            else if (a == T)
                s = 1, t = b;
            uint32_t vid;
            if (s < 0) {
                vid = (uint32_t)(*next)++;
                eval_patch(m, idx, (double)a / T, (double)b / T, m->pos + 3 * (size_t)vid);
            } else if (t == 0 || t == T) {
                vid = idx[side_slots[s][t ? 3 : 0]]; /* a corner is its control point */
            } else {
                const bpt_edge *x = byp[4 * p + (size_t)s];
                if (x->base == UINT32_MAX) {
                    vid = x->key[0];
                } else {
                    vid = x->base + (x->reversed ? T - t : t) - 1;
                    /* The first patch to reach a shared vertex computes it;
                     * the reverse evaluation is the same point. */
                    eval_patch(m, idx, (double)a / T, (double)b / T, m->pos + 3 * (size_t)vid);
                }
            }
            grid[(T + 1) * b + a] = vid;
        }
}

/* Appends the faces of one patch's vertex grid to m, dropping the quads
 * that collapse to an edge or a point; *nidx counts the face corners. */
static void grid_faces(vx_mesh *m, const uint32_t *grid, size_t *nidx)
{
    const uint32_t T = VX_BPT_TESS;
    for (uint32_t b = 0; b < T; b++)
        for (uint32_t a = 0; a < T; a++) {
            uint32_t q[4] = {grid[(T + 1) * b + a], grid[(T + 1) * b + a + 1],
                             grid[(T + 1) * (b + 1) + a + 1], grid[(T + 1) * (b + 1) + a]};
            uint32_t f[4];
            int n = 0;
            for (int k = 0; k < 4; k++)
                if (q[k] != q[(k + 3) % 4]) f[n++] = q[k];
            if (n < 3) continue; /* collapsed to an edge or a point */
            memcpy(m->face_idx + *nidx, f, (size_t)n * sizeof *f);
            *nidx += (size_t)n;
            m->face_start[++m->nfaces] = (uint32_t)*nidx;
        }
}

/* Builds the tessellation (faces and new vertices) of m's patches. */
static int tessellate(vx_mesh *m, const vx_mesh_limits *lim, vx_err *err)
{
    const uint32_t T = VX_BPT_TESS;
    size_t ne = 4 * m->npatches;
    bpt_edge *e = malloc(ne * sizeof *e + 1);
    if (!e) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for patch edges");
    patch_edges(m, e);
    /* A unique vertex block per distinct edge; collapsed edges (one point
     * four times) need none. */
    bpt_edge **byp = malloc(ne * sizeof *byp + 1);
    bpt_edge *sorted = malloc(ne * sizeof *sorted + 1);
    if (!byp || !sorted) {
        free(e);
        free(byp);
        free(sorted);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for patch edges");
    }
    memcpy(sorted, e, ne * sizeof *e);
    qsort(sorted, ne, sizeof *sorted, cmp_edge);
    uint64_t nv = edge_blocks(sorted, ne, byp, m->nverts);
    free(e);
    uint64_t interior = (uint64_t)m->npatches * (T - 1) * (T - 1);
    uint64_t total = nv + interior;
    if (total >= UINT32_MAX || (lim && lim->max_vertices && total > lim->max_vertices)) {
        free(byp);
        free(sorted);
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the tessellation of %zu patches needs %llu vertices, over the limit",
                          m->npatches, (unsigned long long)total);
    }
    size_t nq = m->npatches * T * T;
    double *pos = realloc(m->pos, (size_t)total * 3 * sizeof(double));
    uint32_t *grid = malloc((T + 1) * (T + 1) * sizeof *grid);
    m->face_start = malloc((nq + 1) * sizeof(uint32_t));
    m->face_idx = malloc(4 * nq * sizeof(uint32_t));
    if (pos) m->pos = pos;
    if (!pos || !grid || !m->face_start || !m->face_idx) {
        free(byp);
        free(sorted);
        free(grid);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the tessellation");
    }
    size_t next = (size_t)nv, nidx = 0;
    m->nfaces = 0;
    m->face_start[0] = 0;
    for (size_t p = 0; p < m->npatches; p++) {
        patch_grid(m, p, byp, grid, &next);
        grid_faces(m, grid, &nidx);
    }
    free(grid);
    free(byp);
    free(sorted);
    m->nverts = next;
    size_t ntri = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        ntri += vx_mesh_face_size(m, f) - 2;
    if (lim && lim->max_triangles && ntri > lim->max_triangles)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the tessellation has %zu triangles, more than the limit of %zu", ntri,
                          lim->max_triangles);
    return 0;
}

/* Refuses a patch count of 0, over the triangle limit, or too big for the
 * rest of the file. */
static int check_patch_count(bpt_reader *r, uint64_t np, const vx_mesh_limits *lim)
{
    if (np == 0) return bpt_fail(r, VX_EINVAL, "bpt_count", "the patch count is 0");
    /* Every patch becomes 2 * VX_BPT_TESS^2 triangles at most: refuse a
     * count over the limit before allocating for it (and any count whose
     * face corners would not fit the uint32 offsets). */
    uint64_t tris = np * 2 * VX_BPT_TESS * VX_BPT_TESS;
    if ((lim && lim->max_triangles && tris > lim->max_triangles) ||
        np > UINT32_MAX / (4 * VX_BPT_TESS * VX_BPT_TESS)) {
        char b[24];
        return np == UINT64_MAX ? bpt_fail(r, VX_ETOOBIG, "mesh_too_big",
                                           "a patch count %s is over the limit", count_text(np, b))
                                : bpt_fail(r, VX_ETOOBIG, "mesh_too_big",
                                           "%llu patches make %llu triangles, over the limit",
                                           (unsigned long long)np, (unsigned long long)tris);
    }
    /* The counts are untrusted: storage grows as lines arrive. Where the
     * file's size is known, a count the rest of the file cannot hold (a
     * patch line takes BPT_MIN_PATCH_LINE bytes at least) ends the read at
     * once, and the storage is sized for what can follow. */
    uint64_t left = bytes_left(r);
    if (left != UINT64_MAX && np > left / BPT_MIN_PATCH_LINE)
        return bpt_fail(r, VX_EINVAL, "bpt_truncated",
                        "%llu patches cannot fit in the %llu bytes that follow",
                        (unsigned long long)np, (unsigned long long)left);
    return 0;
}

/* Reads np patch lines into m; *maxidx gets the largest (1-based) index and
 * *maxline the line it is on. */
static int read_patches(bpt_reader *r, vx_mesh *m, uint64_t np, uint64_t *maxidx, size_t *maxline)
{
    size_t cap = 0;
    for (size_t p = 0; p < np; p++) {
        int e = next_line(r);
        if (e < 0) return -1;
        if (e)
            return bpt_fail(r, VX_EINVAL, "bpt_truncated",
                            "the file ends after %zu of %llu patches", p, (unsigned long long)np);
        if (grow_to((void **)&m->patch_idx, &cap, p + 1, (size_t)np, 16 * sizeof(uint32_t)))
            return vx_err_set(r->err, VX_EINTERNAL, "out_of_memory", "no memory for %zu patches",
                              p + 1);
        m->npatches = p + 1;
        char *fl[16];
        if (split(r, fl, 16, "a patch line")) return -1;
        for (int k = 0; k < 16; k++) {
            uint64_t v;
            if (parse_uint(r, fl[k], "patch index", &v)) return -1;
            if (v == 0)
                return bpt_fail(r, VX_EINVAL, "bpt_index",
                                "index 0 is invalid (indices start at 1)");
            if (v > UINT32_MAX) v = UINT32_MAX;
            m->patch_idx[16 * p + (size_t)k] = (uint32_t)(v - 1);
            if (v > *maxidx) {
                *maxidx = v;
                *maxline = r->lineno;
            }
        }
    }
    return 0;
}

/* Refuses a point count of 0, over the limit, below the largest index or
 * too big for the rest of the file. */
static int check_point_count(bpt_reader *r, uint64_t npts, const vx_mesh_limits *lim,
                             uint64_t maxidx, size_t maxline)
{
    if (npts == 0 || (lim && lim->max_vertices && npts > lim->max_vertices) || npts >= UINT32_MAX) {
        char b[24];
        return bpt_fail(r, npts ? VX_ETOOBIG : VX_EINVAL, npts ? "mesh_too_big" : "bpt_count",
                        "point count %s is %s", count_text(npts, b), npts ? "over the limit" : "0");
    }
    if (maxidx > npts) {
        r->lineno = maxline;
        return bpt_fail(r, VX_EINVAL, "bpt_index",
                        "index %llu out of range: the file has %llu points",
                        (unsigned long long)maxidx, (unsigned long long)npts);
    }
    uint64_t left = bytes_left(r);
    /* (the last line may lack its newline) */
    if (left != UINT64_MAX && npts > (left + 1) / BPT_MIN_POINT_LINE)
        return bpt_fail(r, VX_EINVAL, "bpt_truncated",
                        "%llu points cannot fit in the %llu bytes that follow",
                        (unsigned long long)npts, (unsigned long long)left);
    return 0;
}

/* Reads npts point lines into m->pos. */
static int read_points(bpt_reader *r, vx_mesh *m, uint64_t npts)
{
    size_t cap = 0;
    for (size_t i = 0; i < npts; i++) {
        int e = next_line(r);
        if (e < 0) return -1;
        if (e)
            return bpt_fail(r, VX_EINVAL, "bpt_truncated", "the file ends after %zu of %llu points",
                            i, (unsigned long long)npts);
        if (grow_to((void **)&m->pos, &cap, i + 1, (size_t)npts, 3 * sizeof(double)))
            return vx_err_set(r->err, VX_EINTERNAL, "out_of_memory", "no memory for %zu points",
                              i + 1);
        m->nverts = i + 1;
        char *fl[3];
        if (split(r, fl, 3, "a point line")) return -1;
        for (int a = 0; a < 3; a++) {
            double v;
            char *end = vx_mesh_parse_double(fl[a], &v);
            if (!end || *end)
                return bpt_fail(r, VX_EINVAL, "bpt_junk", "'%.40s' is not a number", fl[a]);
            if (!isfinite(v))
                return bpt_fail(r, VX_EINVAL, "bpt_nan", "NaN or infinite coordinate");
            m->pos[3 * i + (size_t)a] = v;
        }
    }
    return 0;
}

vx_mesh *vx_bpt_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err)
{
    bpt_reader *r = calloc(1, sizeof *r);
    vx_mesh *m = vx_mesh_new();
    if (!r || !m) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the .bpt reader");
        goto fail;
    }
    r->f = f;
    r->err = err;
    uint64_t np, npts, maxidx = 0;
    size_t maxline = 0;
    if (read_count(r, "patch count", &np) || check_patch_count(r, np, lim)) goto fail;
    if (read_patches(r, m, np, &maxidx, &maxline)) goto fail;
    if (read_count(r, "point count", &npts) || check_point_count(r, npts, lim, maxidx, maxline))
        goto fail;
    if (read_points(r, m, npts)) goto fail;
    if (dedupe_points(m, err)) goto fail;
    int e = next_line(r);
    if (e < 0) goto fail;
    if (!e) {
        bpt_fail(r, VX_EINVAL, "bpt_junk", "text after the last point");
        goto fail;
    }
    if (tessellate(m, lim, err) || vx_mesh_analyze(m, err)) goto fail;
    free(r);
    return m;
fail:
    free(r);
    vx_mesh_free(m);
    return NULL;
}

vx_mesh *vx_bpt_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err)
{
    FILE *f = vx_mesh_open(path, err);
    if (!f) return NULL;
    vx_mesh *m = vx_bpt_read_file(f, lim, err);
    fclose(f);
    return m;
}
