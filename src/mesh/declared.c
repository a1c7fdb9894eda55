/* What STL, PLY, OFF and glTF headers declare, checked against the bytes
 * that follow before any library decodes the file, and the sniffing of
 * these formats (mesh.h: vx_declared_check, vx_mesh_sniff_sized).
 *
 * Readers size arrays from declared counts (PLY's element counts, OFF's
 * vertex and face counts, glTF accessor counts) before reading the data;
 * a count is accepted here only when the rest of the file can hold it at
 * the format's densest encoding. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>

#include <cjson/cJSON.h>

#include "mesh/mesh.h"
#include "mesh/ply.h"

static int corrupt(vx_err *err, vx_mesh_format fmt, const char *fmtstr, ...)
    __attribute__((format(printf, 3, 4)));

static const char *fmt_name(vx_mesh_format fmt)
{
    switch (fmt) {
    case VX_MESH_STL:
        return "STL";
    case VX_MESH_PLY:
        return "PLY";
    case VX_MESH_OFF:
        return "OFF";
    default:
        return "glTF";
    }
}

static const char *fmt_code(vx_mesh_format fmt)
{
    switch (fmt) {
    case VX_MESH_STL:
        return "stl_corrupt";
    case VX_MESH_PLY:
        return "ply_corrupt";
    case VX_MESH_OFF:
        return "off_corrupt";
    default:
        return "gltf_corrupt";
    }
}

static int vcorrupt(vx_err *err, vx_mesh_format fmt, const char *fmtstr, va_list ap)
{
    char msg[200];
    vsnprintf(msg, sizeof msg, fmtstr, ap);
    return vx_err_set(err, VX_EINVAL, fmt_code(fmt), "not a valid %s file: %s", fmt_name(fmt), msg);
}

static int corrupt(vx_err *err, vx_mesh_format fmt, const char *fmtstr, ...)
{
    va_list ap;
    va_start(ap, fmtstr);
    int rc = vcorrupt(err, fmt, fmtstr, ap);
    va_end(ap);
    return rc;
}

static int over_limits(const vx_mesh_declared *d, const vx_mesh_limits *lim, vx_mesh_format fmt,
                       vx_err *err)
{
    /* An ASCII STL declares nothing: its counts are the size's bound (a
     * facet of 32 bytes, where exporters write about 250), for the parse's
     * memory only; its reader counts the triangles against the limits. */
    if (fmt == VX_MESH_STL && !d->exact) return 0;
    /* Every face makes a triangle at least. */
    uint64_t tris = d->exact ? d->triangles : d->faces;
    if (lim && lim->max_triangles && tris > lim->max_triangles)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the %s file declares %llu triangles, more than %zu (the limit)",
                          fmt_name(fmt), (unsigned long long)tris, lim->max_triangles);
    if (lim && lim->max_vertices && d->vertices > lim->max_vertices)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the %s file declares %llu vertices, more than %zu (the limit)",
                          fmt_name(fmt), (unsigned long long)d->vertices, lim->max_vertices);
    return 0;
}

static uint32_t le32(const unsigned char *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}

static int blank(unsigned char c)
{
    return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\f' || c == '\v';
}

/* ---- STL ------------------------------------------------------------- */

/* Bytes after a binary STL's last triangle that the sniff takes (a
 * declared STL may have any number). */
#define STL_SNIFF_TRAILING 512

/* The shortest ASCII facet the STL reader takes ("facet vertex 0 0 0 ..."). */
#define STL_ASCII_MIN_FACET 32

/* "solid" first, in any case, after a UTF-8 byte order mark and blanks
 * (binary headers often start so too). */
static int solid_first(const unsigned char *p, size_t n)
{
    size_t i = n >= 3 && !memcmp(p, "\xef\xbb\xbf", 3) ? 3 : 0;
    while (i < n && blank(p[i]))
        i++;
    return n - i >= 5 && !strncasecmp((const char *)p + i, "solid", 5);
}

/* ASCII STL: "solid" first and no NUL in the first 512 bytes (binary
 * triangle data holds zero bytes: the attribute word, zero coordinates). */
static int ascii_stl(const unsigned char *p, size_t n)
{
    return solid_first(p, n) && !memchr(p, 0, n < 512 ? n : 512);
}

static int check_stl(const unsigned char *p, size_t n, uint64_t size, vx_mesh_declared *d,
                     vx_err *err)
{
    if (n >= 84) {
        uint64_t count = le32(p + 80);
        /* A count of 0 before whole triangles: a writer that streamed them
         * and never filled the count in (the size tells it). */
        if (count == 0 && size > 84 && (size - 84) % 50 == 0 && !ascii_stl(p, n))
            count = (size - 84) / 50;
        /* An exact size is binary whatever the header says; bytes after
         * the last triangle (some exporters pad or append) are ignored
         * unless the file reads as ASCII. */
        if (84 + 50 * count == size || (84 + 50 * count < size && !ascii_stl(p, n))) {
            d->triangles = d->faces = count;
            d->vertices = d->indices = 3 * count;
            d->exact = 1;
            return 0;
        }
        if (!ascii_stl(p, n))
            return corrupt(err, VX_MESH_STL,
                           "the binary header declares %llu triangles (%llu bytes) but the file "
                           "has only %llu bytes",
                           (unsigned long long)count, (unsigned long long)(84 + 50 * count),
                           (unsigned long long)size);
    } else if (!ascii_stl(p, n)) {
        return corrupt(err, VX_MESH_STL,
                       "%llu bytes, shorter than a binary header, and no ASCII \"solid\"",
                       (unsigned long long)size);
    }
    d->triangles = d->faces = size / STL_ASCII_MIN_FACET;
    d->vertices = d->indices = 3 * d->triangles;
    return 0;
}

/* ---- PLY ------------------------------------------------------------- */

static int check_ply(const unsigned char *p, size_t n, uint64_t size, vx_mesh_declared *d,
                     vx_err *err)
{
    vx_ply_header *h = malloc(sizeof *h);
    if (!h) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a PLY header");
    int rc = vx_ply_header_parse(p, n, size, h, err);
    if (rc) {
        free(h);
        return rc;
    }
    const int ascii = h->format == VX_PLY_ASCII;
    uint64_t left = size - (uint64_t)h->body, need = 0;
    /* ASCII: the last number may end the file without a separator. */
    if (ascii) left += 1;
    int isz = 0;
    for (int i = 0; i < h->nelems; i++) {
        const vx_ply_elem *e = &h->elems[i];
        /* An entry's shortest encoding, lists empty: a digit and a blank
         * per ASCII value or count, the type's size in binary. */
        uint64_t minb = 0;
        for (int j = e->first_prop; j < e->first_prop + e->nprops; j++) {
            const vx_ply_prop *pr = &h->props[j];
            minb += ascii ? 2
                          : (uint64_t)vx_ply_type_size(pr->count_type ? (vx_ply_type)pr->count_type
                                                                      : (vx_ply_type)pr->type);
            /* a face's corner, or a strip's index (a triangle at most) */
            if (pr->count_type && (!strcmp(e->name, "face") || !strcmp(e->name, "tristrips"))) {
                int s = ascii ? 2 : vx_ply_type_size((vx_ply_type)pr->type);
                isz = s < isz || isz == 0 ? s : isz;
            }
        }
        if (!minb) minb = 1;
        if (e->count > left / minb || need + e->count * minb > left) {
            rc = corrupt(err, VX_MESH_PLY,
                         "element '%s' declares %llu entries, more than the %llu bytes after "
                         "the header can hold",
                         e->name, (unsigned long long)e->count, (unsigned long long)left);
            break;
        }
        need += e->count * minb;
        if (!strcmp(e->name, "vertex")) d->vertices = e->count;
        if (!strcmp(e->name, "face")) d->faces = e->count;
    }
    free(h);
    if (rc) return rc;
    d->indices = (left - need) / (uint64_t)(isz ? isz : 1);
    d->triangles = d->indices;
    return 0;
}

/* ---- OFF ------------------------------------------------------------- */

static int parse_u64(const char *s, size_t len, uint64_t *out)
{
    if (!len || len > 12) return -1;
    uint64_t v = 0;
    for (size_t i = 0; i < len; i++) {
        if (s[i] < '0' || s[i] > '9') return -1;
        v = v * 10 + (uint64_t)(s[i] - '0');
    }
    *out = v;
    return 0;
}

/* Skips blanks and # comments. */
static size_t off_skip(const unsigned char *p, size_t n, size_t i)
{
    for (;;) {
        while (i < n && blank(p[i]))
            i++;
        if (i < n && p[i] == '#') {
            while (i < n && p[i] != '\n')
                i++;
            continue;
        }
        return i;
    }
}

static size_t off_word(const unsigned char *p, size_t n, size_t i)
{
    while (i < n && !blank(p[i]) && p[i] != '#')
        i++;
    return i;
}

/* Where the header word [i, j) ends: past its "OFF" when it is a prefix
 * of at most 6 letters ([ST][C][N][4][n]) and OFF, or that followed by
 * digits: the first count with no blank before it, as ModelNet's files
 * write it ("OFF490 518 0"); 0 when it is no OFF word. off.c reads it so. */
static size_t off_magic(const unsigned char *p, size_t i, size_t j)
{
    for (size_t k = i; k + 3 <= j && k <= i + 6; k++) {
        if (memcmp(p + k, "OFF", 3)) continue;
        for (size_t m = k + 3; m < j; m++)
            if (p[m] < '0' || p[m] > '9') return 0;
        return k + 3;
    }
    return 0;
}

static int check_off(const unsigned char *p, size_t n, uint64_t size, vx_mesh_declared *d,
                     vx_err *err)
{
    const vx_mesh_format F = VX_MESH_OFF;
    size_t i = off_skip(p, n, 0), j = off_word(p, n, i), w = off_magic(p, i, j);
    if (!w) {
        if (j == n && n < size) return 1;
        return corrupt(err, F, "the first word is not OFF");
    }
    uint64_t c[2];
    j = w;
    if (memchr(p + i, 'n', w - i - 3)) { /* nOFF: the dimension first (off.c reads it) */
        i = off_skip(p, n, j);
        j = off_word(p, n, i);
        if (j == n && n < size) return 1;
    }
    for (int k = 0; k < 2; k++) {
        i = off_skip(p, n, j);
        j = off_word(p, n, i);
        if (j == n && n < size) return 1;
        if (parse_u64((const char *)p + i, j - i, &c[k]))
            return corrupt(err, F, "the header has no vertex and face counts");
    }
    /* The edge count is optional: not read here. */
    uint64_t left = size - j + 1;
    /* A vertex takes three numbers and their separators; a face at least
     * its size and a separator. */
    if (c[0] > left / 6 || c[1] > (left - 6 * c[0]) / 2)
        return corrupt(err, F,
                       "the header declares %llu vertices and %llu faces, more than the %llu "
                       "bytes after it can hold",
                       (unsigned long long)c[0], (unsigned long long)c[1],
                       (unsigned long long)left);
    d->vertices = c[0];
    d->faces = c[1];
    d->indices = (left - 6 * c[0]) / 2;
    d->triangles = d->indices;
    return 0;
}

/* ---- glTF ------------------------------------------------------------ */

#define GLTF_MAX_DEPTH 256 /* nodes nested in nodes (import.cc walks as deep) */

typedef struct gltf_ctx {
    cJSON *root;
    uint64_t bin_len; /* glb BIN chunk, or UINT64_MAX: none */
    uint64_t *buf_len, *view_len;
    int nbuf, nview;
    /* the top-level arrays' items by index (cJSON's arrays are lists:
     * indexing one item by item is quadratic in a file of many nodes) */
    cJSON **views, **accs, **meshes, **nodes;
    int nacc, nmesh;
    unsigned char *seen; /* nodes visited */
    int nnodes;
    uint64_t tris, verts;
    vx_err *err;
} gltf_ctx;

/* The items of root's array member key into *at (NULL and 0 when it has
 * none); their number, or -1 without memory. */
static int index_array(const cJSON *root, const char *key, cJSON ***at)
{
    cJSON *a = cJSON_GetObjectItemCaseSensitive(root, key), *e;
    int n = 0;
    *at = NULL;
    if (!cJSON_IsArray(a)) return 0;
    cJSON_ArrayForEach(e, a) n++;
    *at = malloc(((size_t)n + 1) * sizeof **at);
    if (!*at) return -1;
    n = 0;
    cJSON_ArrayForEach(e, a)
    {
        (*at)[n++] = e;
    }
    return n;
}

static int gl_fail(gltf_ctx *g, const char *fmtstr, ...) __attribute__((format(printf, 2, 3)));
static int gl_fail(gltf_ctx *g, const char *fmtstr, ...)
{
    va_list ap;
    va_start(ap, fmtstr);
    int rc = vcorrupt(g->err, VX_MESH_GLTF, fmtstr, ap);
    va_end(ap);
    return rc;
}

/* A non-negative integer member, or def when absent; -1 when not one. */
static double num(const cJSON *o, const char *key, double def)
{
    const cJSON *v = cJSON_GetObjectItemCaseSensitive(o, key);
    if (!v) return def;
    if (!cJSON_IsNumber(v) || v->valuedouble < 0 || v->valuedouble > 9e15 ||
        v->valuedouble != floor(v->valuedouble))
        return -1;
    return v->valuedouble;
}

static cJSON *arr(const cJSON *root, const char *key)
{
    cJSON *a = cJSON_GetObjectItemCaseSensitive(root, key);
    return cJSON_IsArray(a) ? a : NULL;
}

/* Decoded length of a base64 data URI of a buffer, -1 when it is not a
 * data: URI, -2 when it is one the reader (tinygltf) does not decode: its
 * media type must be glTF's (application/octet-stream or
 * application/gltf-buffer) or one tinygltf takes besides, base64, the
 * prefix in lower case as tinygltf compares it. */
static double data_uri_len(const char *uri)
{
    static const char *const ok[] = {"data:application/octet-stream;base64,",
                                     "data:application/gltf-buffer;base64,",
                                     "data:text/plain;base64,",
                                     "data:image/png;base64,",
                                     "data:image/jpeg;base64,",
                                     "data:image/bmp;base64,",
                                     "data:image/gif;base64,"};
    if (strncasecmp(uri, "data:", 5)) return -1;
    const char *b = NULL;
    for (size_t k = 0; k < sizeof ok / sizeof ok[0] && !b; k++)
        if (!strncmp(uri, ok[k], strlen(ok[k]))) b = uri + strlen(ok[k]);
    if (!b) return -2;
    size_t len = strlen(b);
    while (len && b[len - 1] == '=')
        len--;
    return (double)(len / 4 * 3 + (len % 4 ? len % 4 - 1 : 0));
}

static int gltf_buffers(gltf_ctx *g)
{
    cJSON *bufs = arr(g->root, "buffers"), *b;
    g->nbuf = bufs ? cJSON_GetArraySize(bufs) : 0;
    g->buf_len = calloc((size_t)g->nbuf + 1, sizeof *g->buf_len);
    if (!g->buf_len) return vx_err_set(g->err, VX_EINTERNAL, "out_of_memory", "no memory");
    int i = 0;
    cJSON_ArrayForEach(b, bufs)
    {
        double len = num(b, "byteLength", -1), have;
        const cJSON *uri = cJSON_GetObjectItemCaseSensitive(b, "uri");
        if (len < 0) return gl_fail(g, "%s %d has no byteLength", "buffer", i);
        if (uri) {
            if (cJSON_IsString(uri) && (have = data_uri_len(uri->valuestring)) == -2)
                return gl_fail(g,
                               "%s %d's data: URI is not base64 of a media type the reader "
                               "decodes (data:application/octet-stream;base64, or "
                               "data:application/gltf-buffer;base64,)",
                               "buffer", i);
            if (!cJSON_IsString(uri) || (have = data_uri_len(uri->valuestring)) < 0)
                return gl_fail(g,
                               "%s %d refers to an external file (only data: URIs and the glb "
                               "BIN chunk are read)",
                               "buffer", i);
        } else {
            if (i != 0 || g->bin_len == UINT64_MAX)
                return gl_fail(g, "%s %d has no uri and there is no glb BIN chunk", "buffer", i);
            have = (double)g->bin_len;
        }
        if (len > have) return gl_fail(g, "%s %d is longer than its data", "buffer", i);
        g->buf_len[i++] = (uint64_t)len;
    }
    return 0;
}

static int gltf_views(gltf_ctx *g)
{
    cJSON *views = arr(g->root, "bufferViews"), *v;
    g->view_len = calloc((size_t)g->nview + 1, sizeof *g->view_len);
    if (!g->view_len) return vx_err_set(g->err, VX_EINTERNAL, "out_of_memory", "no memory");
    int i = 0;
    cJSON_ArrayForEach(v, views)
    {
        double b = num(v, "buffer", -1), off = num(v, "byteOffset", 0),
               len = num(v, "byteLength", -1);
        if (b < 0 || b >= g->nbuf || off < 0 || len < 0 || off + len > (double)g->buf_len[(int)b])
            return gl_fail(g, "%s %d is out of its buffer's bounds", "bufferView", i);
        g->view_len[i++] = (uint64_t)len;
    }
    return 0;
}

static int comp_size(double ct)
{
    if (!(ct >= 0 && ct < 65536)) return 0;
    switch ((int)ct) {
    case 5120:
    case 5121:
        return 1;
    case 5122:
    case 5123:
        return 2;
    case 5125:
    case 5126:
        return 4;
    default:
        return 0;
    }
}

static int type_comps(const cJSON *t)
{
    static const struct {
        const char *name;
        int n;
    } types[] = {{"SCALAR", 1}, {"VEC2", 2}, {"VEC3", 3}, {"VEC4", 4},
                 {"MAT2", 4},   {"MAT3", 9}, {"MAT4", 16}};
    if (!cJSON_IsString(t)) return 0;
    for (size_t i = 0; i < sizeof types / sizeof types[0]; i++)
        if (!strcmp(t->valuestring, types[i].name)) return types[i].n;
    return 0;
}

/* Whether count elements of elem bytes at off with stride fit view vi. */
static int fits(gltf_ctx *g, double vi, double off, double stride, double count, double elem)
{
    if (vi < 0 || vi >= g->nview || off < 0) return 0;
    if (count == 0) return 1;
    return off + stride * (count - 1) + elem <= (double)g->view_len[(int)vi];
}

/* Checks every accessor; *count of accessor i is what it declares. */
static int gltf_accessors(gltf_ctx *g)
{
    cJSON *accs = arr(g->root, "accessors"), *a;
    int i = 0;
    cJSON_ArrayForEach(a, accs)
    {
        int cs = comp_size(num(a, "componentType", -1));
        int nc = type_comps(cJSON_GetObjectItemCaseSensitive(a, "type"));
        double count = num(a, "count", -1), vi = num(a, "bufferView", -1),
               off = num(a, "byteOffset", 0);
        if (!cs || !nc || count < 1) return gl_fail(g, "%s %d is malformed", "accessor", i);
        double elem = (double)cs * nc, stride = elem;
        if (vi >= 0 && vi < g->nview) {
            double st = num(g->views[(int)vi], "byteStride", 0);
            if (st > 0) stride = st;
        }
        /* no bufferView: count zeros (glTF 2.0 3.6.2.3), with or without
         * sparse values; nothing backs the count, so the readers read
         * only the elements the limits already bound (the vertices the
         * indices name, the indices of counted triangles, a skin's joints) */
        const int has_view = cJSON_GetObjectItemCaseSensitive(a, "bufferView") != NULL;
        if (!has_view && count > UINT32_MAX)
            return gl_fail(g, "%s %d declares %.15g elements of zeros (at most 2^32 - 1)",
                           "accessor", i, count);
        if (has_view && !fits(g, vi, off, stride, count, elem))
            return gl_fail(g, "%s %d declares more elements than its bufferView holds", "accessor",
                           i);
        const cJSON *sp = cJSON_GetObjectItemCaseSensitive(a, "sparse");
        if (sp) {
            double sc = num(sp, "count", -1);
            const cJSON *ix = cJSON_GetObjectItemCaseSensitive(sp, "indices");
            const cJSON *vs = cJSON_GetObjectItemCaseSensitive(sp, "values");
            int ics = comp_size(num(ix, "componentType", -1));
            if (sc < 1 || sc > count || !ics ||
                !fits(g, num(ix, "bufferView", -1), num(ix, "byteOffset", 0), ics, sc, ics) ||
                !fits(g, num(vs, "bufferView", -1), num(vs, "byteOffset", 0), elem, sc, elem))
                return gl_fail(g, "%s %d has a malformed sparse part", "accessor", i);
        }
        i++;
    }
    return 0;
}

static double acc_count(gltf_ctx *g, double ai)
{
    if (!(ai >= 0 && ai < g->nacc)) return -1;
    return num(g->accs[(int)ai], "count", -1);
}

static uint64_t sat_add(uint64_t a, uint64_t b)
{
    return a > UINT64_MAX - b ? UINT64_MAX : a + b;
}

/* Adds mesh mi's triangles and vertices (one instance) to g. */
static int gltf_mesh(gltf_ctx *g, double mi)
{
    if (!(mi >= 0 && mi < g->nmesh)) return gl_fail(g, "%s %.15g names no mesh", "node mesh", mi);
    cJSON *prims = arr(g->meshes[(int)mi], "primitives"), *p;
    cJSON_ArrayForEach(p, prims)
    {
        const cJSON *at = cJSON_GetObjectItemCaseSensitive(p, "attributes");
        double pc = acc_count(g, num(at, "POSITION", -1));
        if (pc < 0) return gl_fail(g, "%s %.15g has a primitive without POSITION", "mesh", mi);
        double ic = cJSON_GetObjectItemCaseSensitive(p, "indices")
                        ? acc_count(g, num(p, "indices", -1))
                        : pc;
        if (ic < 0) return gl_fail(g, "%s %.15g has a primitive with bad indices", "mesh", mi);
        double mode = num(p, "mode", 4);
        if (!(mode >= 0 && mode <= 6)) /* points, lines (3 kinds), triangles (3) */
            return gl_fail(g, "%s %.15g has a primitive of mode %.15g (glTF's are 0 to 6)", "mesh",
                           mi, mode);
        double t = mode == 4 ? floor(ic / 3) : (mode == 5 || mode == 6) && ic >= 3 ? ic - 2 : 0;
        /* (saturated: counts of zeros, which nothing backs, may be 2^32
         * each, and a file of 10^4 instances of them wrapped the sums to 0) */
        g->tris = sat_add(g->tris, (uint64_t)t);
        /* the reader keeps only the vertices the indices name */
        g->verts = sat_add(g->verts, (uint64_t)(ic < pc ? ic : pc));
    }
    return 0;
}

/* Node member key: absent, or n finite numbers (*len: their length). */
static int vec_ok(const cJSON *node, const char *key, int n, double *len)
{
    const cJSON *a = cJSON_GetObjectItemCaseSensitive(node, key), *e;
    double l2 = 0;
    int k = 0;
    *len = 1;
    if (!a) return 1;
    if (!cJSON_IsArray(a)) return 0;
    cJSON_ArrayForEach(e, a)
    {
        if (!cJSON_IsNumber(e) || !isfinite(e->valuedouble) || ++k > n) return 0;
        l2 += e->valuedouble * e->valuedouble;
    }
    *len = sqrt(l2);
    return k == n;
}

/* A node's transform: a matrix of 16 numbers, or a translation (3), a
 * rotation (a quaternion of 4, not zero: it is normalized) and a scale (3). */
static int gltf_transform(gltf_ctx *g, const cJSON *n, double ni)
{
    double len;
    if (!vec_ok(n, "matrix", 16, &len))
        return gl_fail(g, "node %.15g's matrix is not 16 finite numbers", ni);
    if (!vec_ok(n, "translation", 3, &len) || !vec_ok(n, "scale", 3, &len))
        return gl_fail(g, "node %.15g's translation or scale is not 3 finite numbers", ni);
    if (!vec_ok(n, "rotation", 4, &len) || !(len > 0 && len < HUGE_VAL))
        return gl_fail(
            g, "node %.15g's rotation is not a quaternion of 4 finite numbers, not all 0", ni);
    return 0;
}

static int gltf_node(gltf_ctx *g, double ni, int depth)
{
    /* ni may be any number a file holds (found by fuzz_gltf): printed, not cast. */
    if (!(ni >= 0 && ni < g->nnodes)) return gl_fail(g, "%s %.15g does not exist", "node", ni);
    if (g->seen[(int)ni])
        return gl_fail(g, "node %.15g is reached twice (a cycle, or two parents)", ni);
    if (depth > GLTF_MAX_DEPTH)
        return gl_fail(g, "node %.15g is nested more than %d deep", ni, GLTF_MAX_DEPTH);
    g->seen[(int)ni] = 1;
    cJSON *n = g->nodes[(int)ni], *c;
    if (gltf_transform(g, n, ni)) return -1;
    if (cJSON_GetObjectItemCaseSensitive(n, "mesh") && gltf_mesh(g, num(n, "mesh", -1))) return -1;
    cJSON_ArrayForEach(c, arr(n, "children"))
    {
        if (gltf_node(g, cJSON_IsNumber(c) ? c->valuedouble : -1, depth + 1)) return -1;
    }
    return 0;
}

static int gltf_scene(gltf_ctx *g)
{
    cJSON *scenes = arr(g->root, "scenes"), *r;
    g->seen = calloc((size_t)g->nnodes + 1, 1);
    if (!g->seen) return vx_err_set(g->err, VX_EINTERNAL, "out_of_memory", "no memory");
    double si = num(g->root, "scene", 0);
    if (!scenes || si < 0 || si >= cJSON_GetArraySize(scenes)) return 0;
    cJSON_ArrayForEach(r, arr(cJSON_GetArrayItem(scenes, (int)si), "nodes"))
    {
        if (gltf_node(g, cJSON_IsNumber(r) ? r->valuedouble : -1, 0)) return -1;
    }
    return 0;
}

/* The extensions a file requires that change where its triangles are
 * (compressed or instanced geometry) and that are not read; the others
 * (materials, textures, lights) change nothing voxeld reads. */
static int gltf_extensions(gltf_ctx *g)
{
    static const char *const unread[] = {"KHR_draco_mesh_compression", "EXT_meshopt_compression",
                                         "KHR_meshopt_compression", "EXT_mesh_gpu_instancing"};
    const cJSON *e;
    cJSON_ArrayForEach(e, arr(g->root, "extensionsRequired"))
    {
        if (!cJSON_IsString(e)) continue;
        for (size_t k = 0; k < sizeof unread / sizeof unread[0]; k++)
            if (!strcmp(e->valuestring, unread[k]))
                return gl_fail(g,
                               "it requires %s, which is not read (decompress it first, e.g. "
                               "with gltf-transform; a Draco mesh can be uploaded as .drc)",
                               unread[k]);
    }
    return 0;
}

static int check_gltf(vx_mesh_format fmt, const unsigned char *p, size_t n, uint64_t size,
                      vx_mesh_declared *d, vx_err *err)
{
    const char *json = (const char *)p;
    size_t jlen = n;
    gltf_ctx g = {.bin_len = UINT64_MAX, .err = err};
    if (fmt == VX_MESH_GLB) {
        if (n < 20) return n < size ? 1 : corrupt(err, VX_MESH_GLTF, "a glb shorter than 20 bytes");
        if (memcmp(p, "glTF", 4) || le32(p + 4) != 2)
            return corrupt(err, VX_MESH_GLTF, "no glb version 2 header");
        uint64_t total = le32(p + 8), clen = le32(p + 12);
        if (total != size || le32(p + 16) != 0x4E4F534Au || 20 + clen > size)
            return corrupt(err, VX_MESH_GLTF,
                           "the glb header and chunk lengths do not match the "
                           "file");
        if (20 + clen > n) return 1;
        json = (const char *)p + 20;
        jlen = clen;
        uint64_t at = (20 + clen + 3) & ~UINT64_C(3);
        if (at + 8 <= size) {
            if (at + 8 > n) return 1;
            uint64_t blen = le32(p + at);
            if (le32(p + at + 4) != 0x004E4942u || at + 8 + blen > size)
                return corrupt(err, VX_MESH_GLTF, "the glb BIN chunk is out of the file's bounds");
            g.bin_len = blen;
        }
    } else if (n < size) {
        return 1;
    }
    g.root = cJSON_ParseWithLength(json, jlen);
    int rc = -1;
    if (!g.root || !cJSON_IsObject(g.root)) {
        corrupt(err, VX_MESH_GLTF, "the JSON does not parse");
        goto out;
    }
    const cJSON *asset = cJSON_GetObjectItemCaseSensitive(g.root, "asset");
    const cJSON *ver = cJSON_GetObjectItemCaseSensitive(asset, "version");
    if (!cJSON_IsString(ver) || strncmp(ver->valuestring, "2.", 2)) {
        corrupt(err, VX_MESH_GLTF, "asset.version is not 2.x (glTF 2.0 is read)");
        goto out;
    }
    if ((g.nview = index_array(g.root, "bufferViews", &g.views)) < 0 ||
        (g.nacc = index_array(g.root, "accessors", &g.accs)) < 0 ||
        (g.nmesh = index_array(g.root, "meshes", &g.meshes)) < 0 ||
        (g.nnodes = index_array(g.root, "nodes", &g.nodes)) < 0) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory");
        goto out;
    }
    if (gltf_extensions(&g) || gltf_buffers(&g) || gltf_views(&g) || gltf_accessors(&g) ||
        gltf_scene(&g))
        goto out;
    d->triangles = d->faces = g.tris;
    d->indices = 3 * g.tris;
    d->vertices = g.verts;
    d->exact = 1;
    rc = 0;
out:
    cJSON_Delete(g.root);
    free(g.buf_len);
    free(g.view_len);
    free(g.views);
    free(g.accs);
    free(g.meshes);
    free(g.nodes);
    free(g.seen);
    return rc;
}

/* ---- entry points ----------------------------------------------------- */

int vx_declared_check(vx_mesh_format fmt, const unsigned char *data, size_t n, uint64_t size,
                      const vx_mesh_limits *lim, vx_mesh_declared *d, vx_err *err)
{
    memset(d, 0, sizeof *d);
    int rc;
    switch (fmt) {
    case VX_MESH_STL:
        rc = check_stl(data, n, size, d, err);
        break;
    case VX_MESH_PLY:
        rc = check_ply(data, n, size, d, err);
        break;
    case VX_MESH_OFF:
        rc = check_off(data, n, size, d, err);
        break;
    case VX_MESH_GLTF:
    case VX_MESH_GLB:
        rc = check_gltf(fmt, data, n, size, d, err);
        break;
    default:
        return vx_err_set(err, VX_EINTERNAL, "mesh_format", "no header check for format %d",
                          (int)fmt);
    }
    return rc ? rc : over_limits(d, lim, fmt, err);
}

uint64_t vx_declared_decode_bound(vx_mesh_format fmt, uint64_t size, const vx_mesh_declared *d)
{
    /* The parser's own copy of the file and its parse state (glTF:
     * tinygltf's JSON tree, its copies of the buffers and the decoded
     * data: URIs), then per element what the reader gathers: a face and
     * its corners, a vertex and its position. */
    uint64_t per_byte = fmt == VX_MESH_GLTF || fmt == VX_MESH_GLB ? 16 : 4;
    return per_byte * size + 48 * d->faces + 8 * d->indices + 64 * d->vertices +
           (UINT64_C(16) << 20);
}

/* 1 when p[i..n), which starts with '{', can be the head of a JSON object:
 * blanks, then a key's quote or the closing brace (or the window's end),
 * and no control byte but blanks anywhere (JSON escapes them in strings).
 * Random bytes that happened to start with '{' were taken for glTF. */
static int json_object_head(const unsigned char *p, size_t n, size_t i)
{
    size_t k = i + 1;
    while (k < n && blank(p[k]))
        k++;
    if (k < n && p[k] != '"' && p[k] != '}') return 0;
    for (k = i; k < n; k++)
        if (p[k] < 0x20 && !blank(p[k])) return 0;
    return 1;
}

vx_mesh_format vx_mesh_sniff_sized(const unsigned char *p, size_t n, uint64_t size)
{
    if (n >= 12 && !memcmp(p, "glTF", 4)) return VX_MESH_GLB;
    const size_t bom = n >= 3 && !memcmp(p, "\xef\xbb\xbf", 3) ? 3 : 0;
    if (n >= bom + 4 && !memcmp(p + bom, "ply", 3) && (p[bom + 3] == '\n' || p[bom + 3] == '\r'))
        return VX_MESH_PLY;
    if (n >= 84 && 84 + 50 * (uint64_t)le32(p + 80) == size) return VX_MESH_STL;
    size_t i = bom;
    while (i < n && blank(p[i]))
        i++;
    if (i < n && p[i] == '{' && json_object_head(p, n, i)) return VX_MESH_GLTF;
    size_t j = off_word(p, n, i);
    if (j - i <= 18 && off_magic(p, i, j) && (j < n || n == size)) return VX_MESH_OFF;
    /* A binary STL whose header starts with "solid" but whose size does
     * not match its count: the reader says what is wrong. */
    if (solid_first(p, n) && n >= 84 && !ascii_stl(p, n)) return VX_MESH_STL;
    if (ascii_stl(p, n)) {
        /* "solid" alone could start other text: look for a facet, unless
         * the first line (the solid's name) runs past the window. */
        const char *s = (const char *)p;
        for (size_t k = i; k + 5 <= n; k++)
            if (!strncasecmp(s + k, "facet", 5) ||
                (k + 8 <= n && !strncasecmp(s + k, "endsolid", 8)))
                return VX_MESH_STL;
        if (n < size && !memchr(p + i, '\n', n - i)) return VX_MESH_STL;
    }
    vx_mesh_format text = vx_mesh_sniff(p, n);
    /* Binary data, not Draco: a binary STL with bytes after its last
     * triangle (vx_declared_check reads it so), fewer than a sector's
     * worth when only the bytes tell: other binary files (FBX, .blend)
     * hold small counts at offset 80 too, which any size would take. */
    uint64_t stl_end = n >= 84 ? 84 + 50 * (uint64_t)le32(p + 80) : UINT64_MAX;
    if (!text && stl_end < size && size - stl_end < STL_SNIFF_TRAILING) return VX_MESH_STL;
    return text;
}
