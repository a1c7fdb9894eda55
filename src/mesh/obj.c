/* Streaming Wavefront OBJ reader, format sniffing and the read-by-path
 * dispatcher.
 *
 * The reader never holds more than one chunk of the file plus one line: an
 * upload may be several hundred MB and the limits must trip before the
 * memory for a too-big mesh has been spent. Numbers are parsed by hand
 * (strtod costs about as much as everything else together, and follows the
 * process locale); strtod_l in the "C" locale is only the fallback for the
 * digits the fast path cannot round exactly. */
#include "mesh/mesh.h"

#include <errno.h>
#include <locale.h>
#include <math.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/intake.h"
#include "mesh/text.h"
#include "util/log.h"

/* A line longer than this is an error, so one hostile line cannot make the
 * reader buffer an unbounded amount of the file. */
#define OBJ_MAX_LINE (64 * 1024)
#define OBJ_CHUNK (256 * 1024)
/* +1: room for the NUL written after a last line that has no newline. */
#define OBJ_BUF (OBJ_CHUNK + OBJ_MAX_LINE + 1)

#define OBJ_SNIFF_BYTES 512

typedef struct obj_reader {
    const vx_mesh_limits *lim;
    vx_err *err;
    vx_mesh *m;
    size_t lineno;                      /* line the statement being parsed starts on */
    size_t cap_pos, cap_idx, cap_start; /* capacities, in elements */
    size_t nidx;                        /* entries used in face_idx */
    size_t ntris;                       /* fan triangles so far, for the limit */
    uint32_t *face;                     /* the face being parsed */
    size_t cap_face;
} obj_reader;

static int obj_fail(obj_reader *r, vx_err_kind kind, const char *code, const char *fmt, ...)
    __attribute__((format(printf, 4, 5)));

static int obj_fail(obj_reader *r, vx_err_kind kind, const char *code, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vx_mesh_line_fail(r->err, r->lineno, "mesh.obj_reject", kind, code, fmt, ap);
    va_end(ap);
    return -1;
}

static inline int is_ws(char c)
{
    return vx_mesh_is_blank(c);
}
static inline int is_end(char c)
{
    return c == 0 || is_ws(c);
}
static inline int is_digit(char c)
{
    return (unsigned)(c - '0') < 10;
}

static inline char *skip_ws(char *p)
{
    while (is_ws(*p))
        p++;
    return p;
}

/* Length of the token at p (up to whitespace), for quoting it in messages. */
static int tok_len(const char *p)
{
    int n = 0;
    while (!is_end(p[n]) && n < 40)
        n++;
    return n;
}

static pthread_once_t c_locale_once = PTHREAD_ONCE_INIT;
static locale_t c_locale;
static void c_locale_init(void)
{
    c_locale = newlocale(LC_ALL_MASK, "C", (locale_t)0);
}

/* Correctly rounded conversion of a token the fast path cannot do exactly. */
static double slow_strtod(const char *s, const char *end, int *ok)
{
    pthread_once(&c_locale_once, c_locale_init);
    char *e;
    double v = c_locale ? strtod_l(s, &e, c_locale) : strtod(s, &e);
    *ok = e == end;
    return v;
}

static int match_word(const char *p, const char *w)
{
    while (*w)
        if ((*p++ | 0x20) != *w++) return 0;
    return 1;
}

static const double pow10_exact[] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,
                                     1e8,  1e9,  1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
                                     1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

/* Parses one decimal number token ([+-] digits [. digits] [e [+-] digits],
 * or inf/infinity/nan, which the caller rejects as obj_nan). Returns the end
 * of the token, which must be followed by whitespace or the end of the line,
 * or NULL when the token is not a number.
 *
 * Fast path (Clinger): a mantissa below 2^53 and a power of ten up to 22 are
 * both exact doubles, so one multiplication or division rounds correctly.
 * Everything else (17+ significant digits, large exponents) goes to strtod_l. */
char *vx_mesh_parse_double(char *p, double *out)
{
    char *s = p;
    int neg = 0;
    if (*p == '-' || *p == '+') neg = *p++ == '-';
    uint64_t mant = 0;
    int nd = 0, exp10 = 0, any = 0, dropped = 0;
    while (*p == '0') {
        p++;
        any = 1;
    }
    for (; is_digit(*p); p++) {
        any = 1;
        if (nd < 19) {
            mant = mant * 10 + (uint64_t)(*p - '0');
            nd++;
        } else {
            exp10++;
            dropped |= *p != '0';
        }
    }
    if (*p == '.') {
        p++;
        if (nd == 0)
            for (; *p == '0'; p++) {
                exp10--;
                any = 1;
            }
        for (; is_digit(*p); p++) {
            any = 1;
            if (nd < 19) {
                mant = mant * 10 + (uint64_t)(*p - '0');
                nd++;
                exp10--;
            } else {
                dropped |= *p != '0';
            }
        }
    }
    if (!any) {
        double v;
        if (match_word(p, "infinity")) {
            p += 8;
            v = INFINITY;
        } else if (match_word(p, "inf")) {
            p += 3;
            v = INFINITY;
        } else if (match_word(p, "nan")) {
            p += 3;
            v = NAN;
        } else {
            return NULL;
        }
        if (!is_end(*p)) return NULL;
        *out = neg ? -v : v;
        return p;
    }
    if (*p == 'e' || *p == 'E') {
        p++;
        int eneg = 0;
        if (*p == '-' || *p == '+') eneg = *p++ == '-';
        if (!is_digit(*p)) return NULL;
        int ev = 0;
        for (; is_digit(*p); p++)
            if (ev < 100000) ev = ev * 10 + (*p - '0');
        exp10 += eneg ? -ev : ev;
    }
    if (!is_end(*p)) return NULL;
    double v;
    if (mant == 0) {
        v = 0;
    } else if (!dropped && mant <= (UINT64_C(1) << 53) && exp10 >= -22 && exp10 <= 22) {
        v = exp10 < 0 ? (double)mant / pow10_exact[-exp10] : (double)mant * pow10_exact[exp10];
    } else {
        int ok;
        v = slow_strtod(s, p, &ok);
        if (!ok) return NULL;
        *out = v; /* strtod saw the sign */
        return p;
    }
    *out = neg ? -v : v;
    return p;
}

/* Parses an integer index token part; stops at '/', whitespace or the end.
 * Values too large for any mesh saturate: they are out of range anyway and
 * the message quotes the token as written. */
static char *parse_index(char *p, int64_t *out)
{
    int neg = 0;
    if (*p == '-' || *p == '+') neg = *p++ == '-';
    if (!is_digit(*p)) return NULL;
    int64_t v = 0;
    for (; is_digit(*p); p++)
        if (v < INT64_C(1) << 40) v = v * 10 + (*p - '0');
    *out = neg ? -v : v;
    return p;
}

/* Grows *p to hold at least `need` elements, geometrically so that the
 * copies add up to O(n). */
static int grow(void **p, size_t *cap, size_t need, size_t elsize)
{
    if (need <= *cap) return 0;
    size_t ncap = *cap + *cap / 2 + 1024;
    if (ncap < need) ncap = need;
    if (ncap > SIZE_MAX / elsize) return -1;
    void *q = realloc(*p, ncap * elsize);
    if (!q) return -1;
    *p = q;
    *cap = ncap;
    return 0;
}

static int obj_oom(obj_reader *r, const char *what)
{
    return obj_fail(r, VX_EINTERNAL, "out_of_memory", "no memory for the %s", what);
}

static int junk(obj_reader *r, const char *stmt, const char *tok)
{
    if (!*tok) return obj_fail(r, VX_EINVAL, "obj_junk", "NUL byte in the line");
    return obj_fail(r, VX_EINVAL, "obj_junk", "'%s' statement: unexpected '%.*s'", stmt,
                    tok_len(tok), tok);
}

/* Reads the numbers of a v/vt/vn statement into v[0..max). */
static int parse_numbers(obj_reader *r, const char *stmt, char *p, const char *end, double *v,
                         int max, int *n)
{
    *n = 0;
    for (;;) {
        p = skip_ws(p);
        if (!*p) break;
        if (*n == max)
            return obj_fail(r, VX_EINVAL, "obj_junk", "too many numbers in a '%s' statement", stmt);
        char *q = vx_mesh_parse_double(p, &v[*n]);
        if (!q) return junk(r, stmt, p);
        (*n)++;
        p = q;
    }
    if (p != end) return junk(r, stmt, p);
    for (int i = 0; i < *n; i++)
        if (!isfinite(v[i]))
            return obj_fail(r, VX_EINVAL, "obj_nan", "NaN or infinite number in a '%s' statement",
                            stmt);
    return 0;
}

static int stmt_v(obj_reader *r, char *p, const char *end)
{
    double v[7];
    int n;
    if (parse_numbers(r, "v", p, end, v, 7, &n)) return -1;
    /* x y z, x y z w, or x y z r g b (a common extension: vertex colours),
     * or x y z r g b a (the same with alpha) */
    if (n != 3 && n != 4 && n != 6 && n != 7)
        return obj_fail(r, VX_EINVAL, "obj_junk", "'v' needs 3, 4, 6 or 7 numbers, got %d", n);
    vx_mesh *m = r->m;
    if (r->lim && r->lim->max_vertices && m->nverts >= r->lim->max_vertices)
        return obj_fail(r, VX_ETOOBIG, "mesh_too_big", "more than %zu vertices (the limit)",
                        r->lim->max_vertices);
    if (m->nverts >= UINT32_MAX)
        return obj_fail(r, VX_ETOOBIG, "mesh_too_big", "more than %u vertices", UINT32_MAX);
    if (grow((void **)&m->pos, &r->cap_pos, 3 * (m->nverts + 1), sizeof(double)))
        return obj_oom(r, "vertices");
    double *d = m->pos + 3 * m->nverts++;
    d[0] = v[0];
    d[1] = v[1];
    d[2] = v[2];
    return 0;
}

/* Turns a one-based or negative (relative) OBJ index into a zero-based one. */
static int resolve(obj_reader *r, const char *tok, int len, int64_t idx, size_t count,
                   const char *what, const char *whats, uint32_t *out)
{
    if (idx == 0)
        return obj_fail(r, VX_EINVAL, "obj_index", "%s index 0 is invalid (indices start at 1)",
                        what);
    if (idx > 0 && (uint64_t)idx <= count) {
        *out = (uint32_t)(idx - 1);
        return 0;
    }
    if (idx < 0 && (uint64_t)-idx <= count) {
        *out = (uint32_t)(count - (uint64_t)-idx);
        return 0;
    }
    return obj_fail(r, VX_EINVAL, "obj_index", "%s index %.*s out of range: %zu %s defined", what,
                    len, tok, count, whats);
}

static int stmt_f(obj_reader *r, char *p, const char *end)
{
    vx_mesh *m = r->m;
    size_t n = 0;
    for (;;) {
        p = skip_ws(p);
        if (!*p) break;
        char *tok = p;
        int64_t vi, ti, ni;
        uint32_t v, unused;
        char *q = parse_index(p, &vi);
        if (!q) return junk(r, "f", tok);
        int vlen = (int)(q - p);
        if (resolve(r, p, vlen, vi, m->nverts, "vertex", "vertices", &v)) return -1;
        p = q;
        /* empty slots ("1/", "1//", "1/2/") are taken, as other readers do */
        if (*p == '/') {
            p++;
            if (*p != '/' && !is_end(*p)) {
                char *t = p;
                if (!(q = parse_index(p, &ti))) return junk(r, "f", tok);
                if (resolve(r, t, (int)(q - t), ti, m->ntexcoords, "texture coordinate",
                            "texture coordinates", &unused))
                    return -1;
                p = q;
            }
            if (*p == '/' && !is_end(p[1])) {
                char *t = ++p;
                if (!(q = parse_index(p, &ni))) return junk(r, "f", tok);
                if (resolve(r, t, (int)(q - t), ni, m->nnormals, "normal", "normals", &unused))
                    return -1;
                p = q;
            } else if (*p == '/') {
                p++;
            }
        }
        if (!is_end(*p)) return junk(r, "f", tok);
        /* Twice the face: the second half is vx_mesh_face_repeat's sort scratch. */
        if (grow((void **)&r->face, &r->cap_face, 2 * (n + 1), sizeof(uint32_t)))
            return obj_oom(r, "face");
        r->face[n++] = v;
    }
    if (p != end) return junk(r, "f", p);
    if (n < 3) return obj_fail(r, VX_EINVAL, "obj_face_short", "face has %zu vertices, needs 3", n);
    uint32_t rep;
    if (vx_mesh_face_repeat(r->face, n, r->face + n, &rep))
        return obj_fail(r, VX_EINVAL, "obj_face_repeat", "face uses vertex %u twice", rep + 1);

    r->ntris += n - 2;
    if (r->lim && r->lim->max_triangles && r->ntris > r->lim->max_triangles)
        return obj_fail(r, VX_ETOOBIG, "mesh_too_big", "more than %zu triangles (the limit)",
                        r->lim->max_triangles);
    /* face_start holds uint32 offsets. */
    if (r->nidx + n > UINT32_MAX)
        return obj_fail(r, VX_ETOOBIG, "mesh_too_big", "more than %u face corners", UINT32_MAX);

    if (n != 3 && !m->face_start) {
        /* First non-triangle: every face so far was a triangle, so the
         * offsets are known without having been stored. Meshes that are
         * all triangles never pay for face_start. */
        if (grow((void **)&m->face_start, &r->cap_start, m->nfaces + 2, sizeof(uint32_t)))
            return obj_oom(r, "faces");
        for (size_t i = 0; i <= m->nfaces; i++)
            m->face_start[i] = (uint32_t)(3 * i);
    }
    if (m->face_start) {
        if (grow((void **)&m->face_start, &r->cap_start, m->nfaces + 2, sizeof(uint32_t)))
            return obj_oom(r, "faces");
        m->face_start[m->nfaces + 1] = (uint32_t)(r->nidx + n);
    }
    if (grow((void **)&m->face_idx, &r->cap_idx, r->nidx + n, sizeof(uint32_t)))
        return obj_oom(r, "faces");
    memcpy(m->face_idx + r->nidx, r->face, n * sizeof(uint32_t));
    r->nidx += n;
    m->nfaces++;
    return 0;
}

/* Statements that are valid OBJ but carry nothing the renderer uses:
 * grouping, materials and texture maps, free-form geometry (and the
 * superseded Bezier and Cardinal patch statements of the 2.x spec),
 * display attributes, the shell command `csh` (never run). */
static const char *const obj_ignored[] = {
    "o",     "g",     "s",        "usemtl",   "mtllib", "maplib",     "usemap",    "l",
    "p",     "vp",    "cstype",   "deg",      "bmat",   "step",       "curv",      "curv2",
    "surf",  "parm",  "trim",     "hole",     "scrv",   "sp",         "end",       "con",
    "mg",    "bevel", "c_interp", "d_interp", "lod",    "shadow_obj", "trace_obj", "ctech",
    "stech", "csh",   "bsp",      "bzp",      "cdc",    "cdp",        "res",       NULL};

static int obj_line(obj_reader *r, char *p, char *end)
{
    p = skip_ws(p);
    if (!*p) return p == end ? 0 : junk(r, "", p);
    char *k = p;
    while (!is_end(*p))
        p++;
    size_t klen = (size_t)(p - k);
    if (k[0] == 'v') {
        if (klen == 1) return stmt_v(r, p, end);
        double v[4];
        int n;
        if (klen == 2 && k[1] == 't') {
            if (parse_numbers(r, "vt", p, end, v, 3, &n)) return -1;
            if (n < 1) return obj_fail(r, VX_EINVAL, "obj_junk", "'vt' needs 1 to 3 numbers");
            r->m->ntexcoords++;
            return 0;
        }
        if (klen == 2 && k[1] == 'n') {
            if (parse_numbers(r, "vn", p, end, v, 3, &n)) return -1;
            if (n != 3)
                return obj_fail(r, VX_EINVAL, "obj_junk", "'vn' needs 3 numbers, got %d", n);
            r->m->nnormals++;
            return 0;
        }
    } else if (k[0] == 'f' && klen == 1) {
        return stmt_f(r, p, end);
    }
    for (size_t i = 0; obj_ignored[i]; i++)
        if (strlen(obj_ignored[i]) == klen && memcmp(obj_ignored[i], k, klen) == 0) return 0;
    if (klen == 4 && memcmp(k, "call", 4) == 0)
        return obj_fail(r, VX_EINVAL, "obj_junk",
                        "'call' (the statements of another file) is not read: upload one file");
    return obj_fail(r, VX_EINVAL, "obj_junk", "unknown statement '%.*s'",
                    (int)(klen > 40 ? 40 : klen), k);
}

/* Gives back what geometric growth over-allocated: the mesh outlives the
 * load by far. */
static void shrink(void **p, size_t bytes)
{
    if (!*p || !bytes) return;
    void *q = realloc(*p, bytes);
    if (q) *p = q;
}

/* The line end of a file whose first bytes are buf[0..n): '\r' where its
 * first line break is a CR alone (classic Mac OS files), else '\n' (LF or
 * CRLF). -1 while the first break is not yet in view (more = more bytes
 * to come). */
static int line_end_of(const char *buf, size_t n, int more)
{
    const char *cr = memchr(buf, '\r', n), *lf = memchr(buf, '\n', n);
    if (lf && (!cr || lf < cr)) return '\n';
    if (!cr) return more ? -1 : '\n';
    if (cr + 1 == buf + n) return more ? -1 : '\r';
    return cr[1] == '\n' ? '\n' : '\r';
}

/* Splits the stream into lines; handles LF, CRLF and CR line ends, a last
 * line without one, comments, and backslash continuation (joined into
 * `join`). */
static int obj_stream(obj_reader *r, FILE *f, char *buf, char **join)
{
    size_t beg = 0, end = 0, line = 0, jlen = 0, jline = 0;
    int eof = 0, eol = -1;
    for (;;) {
        if (eol < 0) eol = line_end_of(buf + beg, end - beg, !eof);
        char *nl = eol < 0 ? NULL : memchr(buf + beg, eol, end - beg);
        if (!nl) {
            if (!eof) {
                size_t rest = end - beg;
                if (rest > OBJ_MAX_LINE) {
                    r->lineno = line + 1;
                    return obj_fail(r, VX_EINVAL, "obj_line_too_long", "line longer than %d bytes",
                                    OBJ_MAX_LINE);
                }
                memmove(buf, buf + beg, rest);
                beg = 0;
                end = rest;
                size_t got = fread(buf + end, 1, OBJ_BUF - 1 - end, f);
                if (got == 0) {
                    if (ferror(f)) {
                        r->lineno = line + 1;
                        return obj_fail(r, VX_EIO, "mesh_io", "read error: %s", strerror(errno));
                    }
                    eof = 1;
                }
                end += got;
                continue;
            }
            if (beg == end) break;
            nl = buf + end; /* last line, no newline: the spare byte takes the NUL */
        }
        char *p = buf + beg;
        size_t len = (size_t)(nl - p);
        beg = (size_t)(nl - buf) + 1;
        if (beg > end) beg = end;
        line++;
        r->lineno = line;
        if (len > OBJ_MAX_LINE)
            return obj_fail(r, VX_EINVAL, "obj_line_too_long", "line longer than %d bytes",
                            OBJ_MAX_LINE);
        if (eol == '\r' && len && *p == '\n') { /* CRLF after a first lone CR */
            p++;
            len--;
        }
        if (line == 1 && len >= 3 && memcmp(p, "\xef\xbb\xbf", 3) == 0) {
            p += 3; /* UTF-8 byte order mark, written by some Windows tools */
            len -= 3;
        }
        char *hash = memchr(p, '#', len);
        if (hash) len = (size_t)(hash - p);
        while (len && is_ws(p[len - 1]))
            len--;

        if (len && p[len - 1] == '\\') {
            /* Continuation: collect into `join`; errors name the first line. */
            if (!*join && !(*join = malloc(OBJ_MAX_LINE + 2)))
                return obj_oom(r, "line continuation");
            if (!jlen) jline = line;
            if (jlen + len > OBJ_MAX_LINE) {
                r->lineno = jline;
                return obj_fail(r, VX_EINVAL, "obj_line_too_long",
                                "continued line longer than %d bytes", OBJ_MAX_LINE);
            }
            memcpy(*join + jlen, p, len - 1);
            jlen += len - 1;
            (*join)[jlen++] = ' ';
            continue;
        }
        if (jlen) {
            r->lineno = jline;
            if (jlen + len > OBJ_MAX_LINE)
                return obj_fail(r, VX_EINVAL, "obj_line_too_long",
                                "continued line longer than %d bytes", OBJ_MAX_LINE);
            memcpy(*join + jlen, p, len);
            jlen += len;
            (*join)[jlen] = 0;
            if (obj_line(r, *join, *join + jlen)) return -1;
            jlen = 0;
            continue;
        }
        p[len] = 0;
        if (obj_line(r, p, p + len)) return -1;
    }
    if (jlen) { /* the file ended on a backslash */
        r->lineno = jline;
        (*join)[jlen] = 0;
        if (obj_line(r, *join, *join + jlen)) return -1;
    }
    return 0;
}

vx_mesh *vx_obj_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err)
{
    obj_reader r = {.lim = lim, .err = err};
    char *buf = malloc(OBJ_BUF), *join = NULL;
    r.m = vx_mesh_new();
    if (!buf || !r.m) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the OBJ reader");
        goto fail;
    }
    if (obj_stream(&r, f, buf, &join)) goto fail;
    vx_mesh *m = r.m;
    if (m->nfaces == 0) {
        vx_err_set(err, VX_EUNPROC, "obj_no_faces", "no faces ('f' statements) in the OBJ file");
        goto fail;
    }
    shrink((void **)&m->pos, 3 * m->nverts * sizeof(double));
    shrink((void **)&m->face_idx, r.nidx * sizeof(uint32_t));
    if (m->face_start) shrink((void **)&m->face_start, (m->nfaces + 1) * sizeof(uint32_t));
    if (vx_mesh_analyze(m, err)) goto fail;
    free(buf);
    free(join);
    free(r.face);
    return m;
fail:
    free(buf);
    free(join);
    free(r.face);
    vx_mesh_free(r.m);
    return NULL;
}

vx_mesh *vx_obj_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err)
{
    FILE *f = vx_mesh_open(path, err);
    if (!f) return NULL;
    vx_mesh *m = vx_obj_read_file(f, lim, err);
    fclose(f);
    return m;
}

/* Whether the first non-blank line is one unsigned integer (a .bpt patch
 * count). A line the window cuts after digits counts. */
static int first_line_is_count(const unsigned char *head, size_t n)
{
    size_t i = 0;
    if (n >= 3 && memcmp(head, "\xef\xbb\xbf", 3) == 0) i = 3;
    while (i < n && (is_ws((char)head[i]) || head[i] == '\n'))
        i++;
    if (i == n || !is_digit((char)head[i])) return 0;
    while (i < n && is_digit((char)head[i]))
        i++;
    while (i < n && is_ws((char)head[i]))
        i++;
    return i == n || head[i] == '\n';
}

vx_mesh_format vx_mesh_sniff(const unsigned char *head, size_t n)
{
    if (n >= 5 && memcmp(head, "DRACO", 5) == 0) return VX_MESH_DRACO;
    /* Text: printable ASCII and whitespace controls, with UTF-8 names in
     * comments and groups, or names in a single-byte code page (Latin-1,
     * Windows-1252: bytes over 0x7f that are not UTF-8), as long as those
     * are at most 1 in 8 bytes. An empty file counts as text, so that the
     * OBJ reader reports it as having no faces. */
    size_t i = 0, single = 0;
    while (i < n) {
        unsigned c = head[i];
        if (c < 0x80) {
            if ((c < 0x20 && c != '\t' && c != '\n' && c != '\r' && c != '\f' && c != '\v') ||
                c == 0x7f)
                return 0;
            i++;
            continue;
        }
        size_t len = c >= 0xc2 && c <= 0xdf   ? 2
                     : c >= 0xe0 && c <= 0xef ? 3
                     : c >= 0xf0 && c <= 0xf4 ? 4
                                              : 0;
        size_t k = 1;
        while (len && k < len && i + k < n && (head[i + k] & 0xc0) == 0x80)
            k++;
        if (len && (k == len || i + k == n)) { /* UTF-8, or cut by the window */
            i += k;
            continue;
        }
        single++;
        i++;
    }
    if (single > n / 8) return 0;
    return first_line_is_count(head, n) ? VX_MESH_BPT : VX_MESH_OBJ;
}

vx_mesh *vx_mesh_read_as(const char *path, vx_mesh_format fmt, const vx_mesh_limits *lim,
                         vx_err *err)
{
    FILE *f = vx_mesh_open(path, err);
    if (!f) return NULL;
    vx_mesh *m = NULL;
    switch (fmt) {
    case VX_MESH_OBJ:
        m = vx_obj_read_file(f, lim, err);
        break;
    case VX_MESH_DRACO:
        m = vx_draco_read_file(f, lim, err);
        break;
    case VX_MESH_BPT:
        m = vx_bpt_read_file(f, lim, err);
        break;
    case VX_MESH_STL:
    case VX_MESH_PLY:
    case VX_MESH_GLTF:
    case VX_MESH_GLB:
    case VX_MESH_OFF:
        fclose(f);
        return vx_import_read_path(path, fmt, lim, err);
    default:
        vx_err_set(err, VX_EINVAL, "mesh_format",
                   "not an OBJ, .bpt, Draco, STL, PLY, glTF or OFF file");
    }
    fclose(f);
    return m;
}

/* Reads the file at path, its format told by name's extension or else by
 * its first bytes. */
static vx_mesh *read_named(const char *path, const char *name, const vx_mesh_limits *lim,
                           vx_err *err)
{
    /* the format the upload was taken as (the store's extension for it),
     * which the first bytes cannot always tell again: an OBJ declared
     * model/obj may name its groups in Latin-1, which the sniff takes for
     * binary */
    vx_mesh_format by_ext = vx_intake_format_of_path(name);
    if (by_ext) return vx_mesh_read_as(path, by_ext, lim, err);
    FILE *f = vx_mesh_open(path, err);
    if (!f) return NULL;
    unsigned char head[OBJ_SNIFF_BYTES];
    size_t n = fread(head, 1, sizeof head, f);
    int bad = ferror(f);
    fclose(f);
    if (bad) {
        vx_err_set(err, VX_EIO, "mesh_io", "cannot read %s: %s", path, strerror(errno));
        return NULL;
    }
    return vx_mesh_read_as(path, vx_mesh_sniff(head, n), lim, err);
}

vx_mesh *vx_mesh_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err)
{
    return read_named(path, path, lim, err);
}

vx_mesh *vx_mesh_read_fd(int fd, const char *name, const vx_mesh_limits *lim, vx_err *err)
{
    char path[64];
    snprintf(path, sizeof path, "/proc/self/fd/%d", fd);
    return read_named(path, name, lim, err);
}
