/* OFF reader (vx_off_read_mem, mesh.h), from memory.
 *
 * assimp 5.2's OFF importer crashed (SEGV) on files that fuzz_off made of
 * a valid header and garbage face lines, so OFF is read here: line by
 * line, '#' comments dropped, the header word (OFF, COFF, NOFF, CNOFF,
 * STOFF, 4OFF: homogeneous x y z w; nOFF: a dimension, 3 only, before the
 * counts; the first count may follow the word without a blank, as in
 * ModelNet's "OFF490 518 0"), the vertex and face counts (checked against the size first,
 * vx_declared_check), then per vertex line its first three numbers (4OFF:
 * four, divided by w) and per face line its size and indices
 * (colours after them are ignored), and nothing but comments after the
 * last face (a face count that is too small). Lines of any length.
 * Polygons are kept. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "mesh/text.h"

typedef struct off_in {
    const char *p, *end;
    char *line; /* cap bytes, grown to the longest line */
    size_t cap, lineno;
} off_in;

/* The next line with something on it but comments, NUL-terminated in
 * in->line; 0 at the end, -1 for a NUL byte or without memory. */
static int next_line(off_in *in)
{
    while (in->p < in->end) {
        /* lines end at LF, CRLF or a lone CR (old Mac files) */
        const char *nl = memchr(in->p, '\n', (size_t)(in->end - in->p));
        const char *cr = memchr(in->p, '\r', (size_t)((nl ? nl : in->end) - in->p));
        if (cr && cr + 1 != nl) nl = cr;
        const char *e = nl ? nl : in->end;
        size_t len = (size_t)(e - in->p);
        in->lineno++;
        if (len >= in->cap) {
            size_t cap = len + 1 > 2 * in->cap ? len + 1 : 2 * in->cap;
            char *l = realloc(in->line, cap);
            if (!l) return -1;
            in->line = l;
            in->cap = cap;
        }
        memcpy(in->line, in->p, len);
        in->line[len] = 0;
        in->p = nl ? nl + 1 : in->end;
        char *hash = strchr(in->line, '#');
        if (hash) *hash = 0;
        if (strlen(in->line) != len && !hash) return -1; /* a NUL byte */
        for (char *c = in->line; *c; c++)
            if (*c != ' ' && *c != '\t' && *c != '\r' && *c != '\f' && *c != '\v') return 1;
    }
    return 0;
}

static int fail(vx_err *err, off_in *in, const char *what)
{
    return vx_err_set(err, VX_EINVAL, "off_corrupt", "not a valid OFF file: line %zu: %s",
                      in->lineno, what);
}

/* The separators of the header's words, as vx_declared_check reads them. */
static int blank(char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}

/* Reads an unsigned integer token at *s (a whole token: "6.5" is not 6). */
static int read_uint(char **s, unsigned long long *v)
{
    char *e;
    while (blank(**s))
        (*s)++;
    if (**s < '0' || **s > '9') return -1;
    *v = strtoull(*s, &e, 10);
    if (*e && !blank(*e)) return -1;
    *s = e;
    return 0;
}

/* The next unsigned integer of the header, on this line or the next. */
static int header_uint(off_in *in, char **s, unsigned long long *v)
{
    while (blank(**s))
        (*s)++;
    if (!**s) {
        if (next_line(in) <= 0) return -1;
        *s = in->line;
    }
    return read_uint(s, v);
}

/* The header: its word ([ST][C][N][4][n]OFF), nOFF's dimension (3 only) and
 * the vertex and face counts into c. *hom: 1 for 4OFF (x y z w vertices). */
static int read_header(off_in *in, unsigned long long c[2], int *hom, vx_err *err)
{
    if (next_line(in) <= 0) return fail(err, in, "no header");
    char *s = in->line;
    while (blank(*s))
        s++;
    char *w = s;
    while (*s && !blank(*s))
        s++;
    /* [prefix]OFF, or that with the first count glued to it (ModelNet's
     * "OFF490 518 0"), as vx_declared_check reads it */
    char *off = NULL;
    for (char *k = w; !off && k + 3 <= s && k <= w + 6; k++)
        if (!strncmp(k, "OFF", 3)) off = k;
    for (char *k = off ? off + 3 : s; k < s; k++)
        if (*k < '0' || *k > '9') off = NULL;
    if (!off) return fail(err, in, "the first word is not OFF");
    size_t wl = (size_t)(off - w); /* the prefix */
    s = off + 3;
    *hom = memchr(w, '4', wl) != NULL;
    if (memchr(w, 'n', wl)) {
        unsigned long long dim;
        if (header_uint(in, &s, &dim)) return fail(err, in, "nOFF without its dimension");
        if (dim != 3) {
            char what[96];
            snprintf(what, sizeof what, "nOFF of dimension %llu (only 3 is read)", dim);
            return fail(err, in, what);
        }
    }
    for (int k = 0; k < 2; k++)
        if (header_uint(in, &s, &c[k])) return fail(err, in, "bad vertex or face count");
    return 0;
}

vx_mesh *vx_off_read_mem(const unsigned char *data, size_t n, const vx_mesh_limits *lim,
                         vx_err *err)
{
    vx_mesh_declared d;
    if (vx_declared_check(VX_MESH_OFF, data, n, n, lim, &d, err)) return NULL;
    off_in in = {.p = (const char *)data, .end = (const char *)data + n};
    unsigned long long c[2];
    int hom = 0;
    vx_mesh *m = NULL;
    uint32_t *scr = NULL; /* a face's indices, sorted for vx_mesh_face_repeat */
    size_t scr_cap = 0;
    if (read_header(&in, c, &hom, err)) goto out;
    /* Only counts the size check saw may size the arrays. */
    if (c[0] != d.vertices || c[1] != d.faces) {
        fail(err, &in, "the header's counts cannot be read one way");
        goto out;
    }
    m = vx_mesh_new();
    if (!m) goto oom;
    size_t nv = (size_t)c[0], nf = (size_t)c[1], cap = 3 * nf + 16, used = 0, ntris = 0;
    m->pos = malloc(3 * nv * sizeof(double) + 1);
    m->face_start = malloc((nf + 1) * sizeof(uint32_t));
    m->face_idx = malloc(cap * sizeof(uint32_t));
    if (!m->pos || !m->face_start || !m->face_idx) goto oom;
    for (size_t v = 0; v < nv; v++) {
        if (next_line(&in) <= 0) goto bad_v;
        char *s = in.line;
        double x[4];
        for (int a = 0; a < 3 + hom; a++) {
            while (vx_mesh_is_blank(*s))
                s++;
            char *e = vx_mesh_parse_double(s, &x[a]); /* decimal, as OBJ's: no hex */
            if (!e) goto bad_v;
            if (!isfinite(x[a])) {
                fail(err, &in, "a NaN or infinite coordinate");
                goto out;
            }
            s = e;
        }
        for (int a = 0; a < 3; a++) {
            m->pos[3 * v + a] = hom ? x[a] / x[3] : x[a];
            if (!isfinite(m->pos[3 * v + a])) {
                fail(err, &in, "a 4OFF vertex whose w is 0 or too small");
                goto out;
            }
        }
    }
    size_t kept = 0;
    for (size_t f = 0; f < nf; f++) {
        unsigned long long k, idx;
        if (next_line(&in) <= 0) goto bad_f;
        char *s = in.line;
        /* a corner takes 2 bytes of the file (a bound before any sum) */
        if (read_uint(&s, &k) || k > (unsigned long long)n / 2 + 1) goto bad_f;
        if (used + k > cap) {
            cap = 2 * cap + k;
            if (cap > (size_t)n) cap = (size_t)n; /* a corner takes 2 bytes of the file */
            if (used + k > cap) goto bad_f;
            uint32_t *g = realloc(m->face_idx, cap * sizeof(uint32_t));
            if (!g) goto oom;
            m->face_idx = g;
        }
        for (unsigned long long i = 0; i < k; i++) {
            if (read_uint(&s, &idx)) {
                fail(err, &in, "a face without as many whole-number indices as its size says");
                goto out;
            }
            if (idx >= nv) {
                fail(err, &in, "a face index out of range");
                goto out;
            }
            m->face_idx[used + i] = (uint32_t)idx;
        }
        if (k < 3) continue; /* points and edges */
        if (k > scr_cap) {
            uint32_t *g = realloc(scr, (size_t)k * sizeof *scr);
            if (!g) goto oom;
            scr = g;
            scr_cap = (size_t)k;
        }
        uint32_t rep;
        if (vx_mesh_face_repeat(m->face_idx + used, (size_t)k, scr, &rep)) {
            char what[64];
            snprintf(what, sizeof what, "a face uses vertex %u twice", rep);
            fail(err, &in, what);
            goto out;
        }
        m->face_start[kept++] = (uint32_t)used;
        used += k;
        ntris += k - 2;
        if (lim && lim->max_triangles && ntris > lim->max_triangles) {
            vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                       "the OFF file has more than %zu triangles (the limit)", lim->max_triangles);
            goto out;
        }
    }
    int more = next_line(&in);
    if (more) {
        fail(err, &in,
             more > 0 ? "more after the last face than the header's face count says"
                      : "a NUL byte, or no memory for a line");
        goto out;
    }
    if (!kept) {
        if (nf)
            vx_err_set(err, VX_EUNPROC, "off_no_faces",
                       "the OFF file has no faces of three or more vertices (each of its %zu is "
                       "a point or an edge)",
                       nf);
        else
            vx_err_set(err, VX_EUNPROC, "off_no_faces", "the OFF file has no faces");
        goto out;
    }
    m->face_start[kept] = (uint32_t)used;
    m->nverts = nv;
    m->nfaces = kept;
    if (vx_mesh_analyze(m, err)) goto out;
    free(in.line);
    free(scr);
    return m;
bad_v:
    fail(err, &in, "a vertex line without three numbers");
    goto out;
bad_f:
    fail(err, &in, "a face line without its size and indices");
    goto out;
oom:
    vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to read the OFF file");
out:
    vx_mesh_free(m);
    free(in.line);
    free(scr);
    return NULL;
}
