/* The PLY reader (mesh/ply.c): random meshes written in ASCII, binary
 * little and big endian, with every value type for coordinates, counts and
 * indices, extra properties and elements around the two it reads, must
 * read back exactly; every truncation of a file and a set of hostile ones
 * must fail with ply_corrupt (fuzz_ply's crash in assimp was a mutated
 * body under a valid header); the header parser must ask for more bytes
 * only while the header is unfinished. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "mesh/mesh.h"
#include "text_buf.h"
#include "mesh/ply.h"

static const char *type_name[] = {"",    "char", "uchar", "short", "ushort",
                                  "int", "uint", "float", "double"};

static uint64_t rnd_state = 88172645463325252ull;
static uint64_t rnd(void)
{
    return test_rand(&rnd_state);
}

/* Writes value v as type t in format f (ASCII: followed by a blank). */
static void put_value(tbuf *b, vx_ply_format f, vx_ply_type t, double v)
{
    if (f == VX_PLY_ASCII) {
        if (t >= VX_PLY_F32)
            tbuf_printf(b, "%.17g ", v);
        else
            tbuf_printf(b, "%lld ", (long long)v);
        return;
    }
    uint64_t u = 0;
    int size = vx_ply_type_size(t);
    if (t == VX_PLY_F32) {
        float x = (float)v;
        uint32_t w;
        memcpy(&w, &x, 4);
        u = w;
    } else if (t == VX_PLY_F64) {
        memcpy(&u, &v, 8);
    } else {
        u = (uint64_t)(int64_t)v;
    }
    unsigned char o[8];
    for (int i = 0; i < size; i++)
        o[f == VX_PLY_BE ? size - 1 - i : i] = (unsigned char)(u >> (8 * i));
    tbuf_put(b, o, (size_t)size);
}

/* What a value of type t holds of v. */
static double as_type(vx_ply_type t, double v)
{
    return t == VX_PLY_F32 ? (double)(float)v : v;
}

typedef struct spec {
    vx_ply_format format;
    vx_ply_type coord, count, index;
    int extra;          /* extra scalar and list properties on both elements */
    int vertex_last;    /* the face element before the vertex element */
    int other_elements; /* an "edge" element before and a "material" after */
    int crlf;           /* header lines end in \r\n */
} spec;

typedef struct mesh_in {
    size_t nv, nf;
    double *pos;
    uint32_t *start, *idx; /* nf + 1 offsets, corners */
} mesh_in;

static mesh_in random_mesh(size_t nv, size_t nf, vx_ply_type index)
{
    mesh_in m = {nv, nf, malloc(3 * nv * sizeof(double)), malloc((nf + 1) * sizeof(uint32_t)),
                 malloc(6 * nf * sizeof(uint32_t) + 4)};
    size_t most = index == VX_PLY_I8 ? 127 : index == VX_PLY_U8 ? 255 : nv;
    if (most > nv) most = nv;
    for (size_t i = 0; i < 3 * nv; i++)
        m.pos[i] = ((double)(rnd() % 2000001) - 1000000.0) / 4096.0 + (double)(rnd() % 7) * 1e-9;
    size_t used = 0;
    for (size_t f = 0; f < nf; f++) {
        m.start[f] = (uint32_t)used;
        /* 3..6 corners, no vertex twice (readers refuse that) */
        size_t k = 3 + rnd() % (most < 6 ? most - 2 : 4);
        for (size_t j = 0; j < k; j++) {
            uint32_t v;
            int again;
            do {
                v = (uint32_t)(rnd() % most);
                again = 0;
                for (size_t i = m.start[f]; i < used; i++)
                    again |= m.idx[i] == v;
            } while (again);
            m.idx[used++] = v;
        }
    }
    m.start[nf] = (uint32_t)used;
    return m;
}

static void free_mesh(mesh_in *m)
{
    free(m->pos);
    free(m->start);
    free(m->idx);
}

static void put_vertices(tbuf *b, const spec *s, const mesh_in *m)
{
    for (size_t v = 0; v < m->nv; v++) {
        if (s->extra) put_value(b, s->format, VX_PLY_U8, (double)(v % 200));
        for (int a = 0; a < 3; a++)
            put_value(b, s->format, s->coord, m->pos[3 * v + a]);
        if (s->extra) {
            put_value(b, s->format, VX_PLY_U16, 2);
            put_value(b, s->format, VX_PLY_F32, 0.5);
            put_value(b, s->format, VX_PLY_F32, -0.25);
            put_value(b, s->format, VX_PLY_F64, 1e300);
        }
        if (s->format == VX_PLY_ASCII) tbuf_printf(b, "\n");
    }
}

static void put_faces(tbuf *b, const spec *s, const mesh_in *m)
{
    for (size_t f = 0; f < m->nf; f++) {
        if (s->extra) put_value(b, s->format, VX_PLY_I32, -7);
        uint32_t k = m->start[f + 1] - m->start[f];
        put_value(b, s->format, s->count, k);
        for (uint32_t j = 0; j < k; j++)
            put_value(b, s->format, s->index, m->idx[m->start[f] + j]);
        if (s->extra) {
            put_value(b, s->format, VX_PLY_U8, 0); /* an empty list */
            put_value(b, s->format, VX_PLY_I16, 3);
        }
        if (s->format == VX_PLY_ASCII) tbuf_printf(b, "\n");
    }
}

static tbuf write_ply(const spec *s, const mesh_in *m)
{
    static const char *fmt[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    const char *nl = s->crlf ? "\r\n" : "\n";
    tbuf b = {0};
    tbuf_printf(&b, "ply%sformat %s 1.0%scomment generated by test_ply%s", nl, fmt[s->format], nl,
                nl);
    if (s->other_elements)
        tbuf_printf(&b, "element edge 2%sproperty int vertex1%sproperty list uchar float w%s", nl,
                    nl, nl);
    for (int pass = 0; pass < 2; pass++) {
        if ((pass == 0) == !s->vertex_last) {
            tbuf_printf(&b, "element vertex %zu%s", m->nv, nl);
            if (s->extra) tbuf_printf(&b, "property uchar flag%s", nl);
            for (int a = 0; a < 3; a++)
                tbuf_printf(&b, "property %s %c%s", type_name[s->coord], "xyz"[a], nl);
            if (s->extra)
                tbuf_printf(&b, "property list ushort float uv%sproperty double q%s", nl, nl);
        } else {
            tbuf_printf(&b, "element face %zu%s", m->nf, nl);
            if (s->extra) tbuf_printf(&b, "property int material%s", nl);
            tbuf_printf(&b, "property list %s %s vertex_indices%s", type_name[s->count],
                        type_name[s->index], nl);
            if (s->extra)
                tbuf_printf(&b, "property list uchar int tags%sproperty short w%s", nl, nl);
        }
    }
    if (s->other_elements) tbuf_printf(&b, "element material 1%sproperty float shine%s", nl, nl);
    tbuf_printf(&b, "end_header%s", nl);
    if (s->other_elements)
        for (int e = 0; e < 2; e++) {
            put_value(&b, s->format, VX_PLY_I32, e);
            put_value(&b, s->format, VX_PLY_U8, 1);
            put_value(&b, s->format, VX_PLY_F32, 2.5);
        }
    if (s->vertex_last) {
        put_faces(&b, s, m);
        put_vertices(&b, s, m);
    } else {
        put_vertices(&b, s, m);
        put_faces(&b, s, m);
    }
    if (s->other_elements) put_value(&b, s->format, VX_PLY_F32, 0.75);
    return b;
}

/* ASCII coordinates are read as written, whatever their declared type. */
static void check_same(const vx_mesh *r, const mesh_in *m, vx_ply_type coord)
{
    assert_int_equal(r->nverts, m->nv);
    assert_int_equal(r->nfaces, m->nf);
    for (size_t i = 0; i < 3 * m->nv; i++)
        assert_true(r->pos[i] == as_type(coord, m->pos[i]));
    for (size_t f = 0; f < m->nf; f++) {
        uint32_t k = m->start[f + 1] - m->start[f];
        assert_int_equal(vx_mesh_face_size(r, f), k);
        const uint32_t *v = vx_mesh_face(r, f);
        for (uint32_t j = 0; j < k; j++)
            assert_int_equal(v[j], m->idx[m->start[f] + j]);
    }
}

/* Random meshes in every encoding read back exactly. */
static void test_round_trip(void **state)
{
    (void)state;
    static const vx_ply_type coords[] = {VX_PLY_F32, VX_PLY_F64};
    static const vx_ply_type counts[] = {VX_PLY_U8,  VX_PLY_I8,  VX_PLY_U16,
                                         VX_PLY_I16, VX_PLY_I32, VX_PLY_U32};
    static const vx_ply_type indices[] = {VX_PLY_I32, VX_PLY_U32, VX_PLY_U16,
                                          VX_PLY_I16, VX_PLY_U8,  VX_PLY_I8};
    int runs = 0;
    for (int f = 0; f < 3; f++)
        for (int round = 0; round < 24; round++) {
            spec s = {.format = (vx_ply_format)f,
                      .coord = coords[round % 2],
                      .count = counts[round % 6],
                      .index = indices[(round / 2) % 6],
                      .extra = (round / 3) % 2,
                      .vertex_last = (round / 5) % 2,
                      .other_elements = (round / 7) % 2,
                      .crlf = round % 4 == 3};
            size_t nv = 3 + rnd() % 300, nf = 1 + rnd() % 400;
            mesh_in m = random_mesh(nv, nf, s.index);
            tbuf b = write_ply(&s, &m);
            vx_err err = {0};
            vx_mesh *r = vx_ply_read_mem((const unsigned char *)b.p, b.n, NULL, &err);
            if (!r) fail_msg("format %d round %d: %s", f, round, err.message);
            check_same(r, &m, s.format == VX_PLY_ASCII ? VX_PLY_F64 : s.coord);
            vx_mesh_free(r);
            /* The same through the public entry the daemon's intake uses. */
            r = vx_import_read_mem((const unsigned char *)b.p, b.n, VX_MESH_PLY, NULL, &err);
            assert_non_null(r);
            vx_mesh_free(r);
            free(b.p);
            free_mesh(&m);
            runs++;
        }
    assert_int_equal(runs, 72);
}

/* Every prefix of a file fails cleanly (or, past the last face, reads). */
static void test_truncations(void **state)
{
    (void)state;
    for (int f = 0; f < 3; f++) {
        spec s = {.format = (vx_ply_format)f,
                  .coord = VX_PLY_F32,
                  .count = VX_PLY_U8,
                  .index = VX_PLY_I32,
                  .extra = 1};
        mesh_in m = random_mesh(12, 9, s.index);
        tbuf b = write_ply(&s, &m);
        size_t ok = 0;
        for (size_t n = 0; n < b.n; n++) {
            vx_err err = {0};
            unsigned char *copy = malloc(n + 1); /* exactly n bytes for ASan */
            memcpy(copy, b.p, n);
            vx_mesh *r = vx_ply_read_mem(copy, n, NULL, &err);
            if (r) {
                ok++;
                vx_mesh_free(r);
            } else {
                assert_true(!strcmp(err.code, "ply_corrupt") || !strcmp(err.code, "ply_no_faces"));
            }
            free(copy);
        }
        /* ASCII: the last face's trailing blank and newline may go. */
        assert_true(ok <= (f == VX_PLY_ASCII ? 2u : 0u));
        free(b.p);
        free_mesh(&m);
    }
}

static vx_mesh *read_str(const char *s, vx_err *err)
{
    memset(err, 0, sizeof *err);
    return vx_ply_read_mem((const unsigned char *)s, strlen(s), NULL, err);
}

#define HEAD_V "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
#define TRI "0 0 0\n1 0 0\n0 1 0\n"

static void expect_n(const char *file, size_t n, const char *code, const char *in_message)
{
    vx_err err = {0};
    vx_mesh *r = vx_ply_read_mem((const unsigned char *)file, n, NULL, &err);
    if (r) fail_msg("read, expected %s: %s", code, file);
    assert_string_equal(err.code, code);
    if (in_message && !strstr(err.message, in_message))
        fail_msg("message \"%s\" lacks \"%s\"", err.message, in_message);
}

static void expect(const char *file, const char *code, const char *in_message)
{
    expect_n(file, strlen(file), code, in_message);
}

static void test_hostile(void **state)
{
    (void)state;
    vx_err err;
    vx_mesh *r = read_str(HEAD_V "property float z\nelement face 1\nproperty list uchar int "
                                 "vertex_indices\nend_header\n" TRI "3 0 1 2\n",
                          &err);
    assert_non_null(r);
    assert_int_equal(r->nfaces, 1);
    vx_mesh_free(r);
    /* vertex_index is the other name files use. */
    r = read_str(HEAD_V "property float z\nelement face 1\nproperty list uchar int "
                        "vertex_index\nend_header\n" TRI "3 0 1 2\n",
                 &err);
    assert_non_null(r);
    vx_mesh_free(r);
    const char *face = "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                       "end_header\n" TRI;
    char f[1024];
    snprintf(f, sizeof f, HEAD_V "%s3 0 1 7\n", face);
    expect(f, "ply_corrupt", "out of range");
    snprintf(f, sizeof f, HEAD_V "%s3 0 1 -1\n", face);
    expect(f, "ply_corrupt", "bad vertex index");
    snprintf(f, sizeof f, HEAD_V "%s3 0 1 1.5\n", face);
    expect(f, "ply_corrupt", "1.5 is not of type int");
    snprintf(f, sizeof f, HEAD_V "%s200 0 1 2\n", face);
    expect(f, "ply_corrupt", "more than the file holds");
    snprintf(f, sizeof f, HEAD_V "%s-3 0 1 2\n", face);
    expect(f, "ply_corrupt", "-3 is not of type uchar");
    /* An ASCII value outside its declared type (a uchar of 300, taken as
     * it was), and hex numbers (strtod's: 0x10 was 16), as rply and the
     * OBJ reader refuse them. */
    snprintf(f, sizeof f, HEAD_V "%s300 0 1 2\n", face);
    expect(f, "ply_corrupt", "300 is not of type uchar");
    expect(HEAD_V "property float z\nproperty uchar red\nelement face 1\nproperty list uchar "
                  "int vertex_indices\nend_header\n0 0 0 300\n1 0 0 0\n0 1 0 0\n3 0 1 2\n",
           "ply_corrupt", "300 is not of type uchar");
    expect(HEAD_V "property float z\nproperty short s\nelement face 1\nproperty list uchar "
                  "int vertex_indices\nend_header\n0 0 0 -32769\n1 0 0 0\n0 1 0 0\n3 0 1 2\n",
           "ply_corrupt", "-32769 is not of type short");
    expect(HEAD_V "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\n0x10 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
           "ply_corrupt", "entry 0");
    /* Faces but no vertex element: said so (it was ply_no_faces, "no
     * faces") */
    expect("ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n"
           "end_header\n3 0 1 2\n",
           "ply_corrupt", "no vertex element");
    snprintf(f, sizeof f, HEAD_V "%s3 0 1 x\n", face);
    expect(f, "ply_corrupt", "entry 0");
    expect(HEAD_V "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\n0 nan 0\n1 0 0\n0 1 0\n3 0 1 2\n",
           "ply_corrupt", "NaN");
    expect(HEAD_V "element face 1\nproperty list uchar int vertex_indices\nend_header\n" TRI
                  "3 0 1 2\n",
           "ply_corrupt", "no scalar property z");
    expect(HEAD_V "property list uchar float z\nelement face 1\nproperty list uchar int "
                  "vertex_indices\nend_header\n" TRI "3 0 1 2\n",
           "ply_corrupt", "no scalar property z");
    expect(HEAD_V "property float z\nelement face 1\nproperty list uchar int corners\n"
                  "end_header\n" TRI "3 0 1 2\n",
           "ply_corrupt", "no vertex_indices");
    expect(HEAD_V "property float z\nelement face 1\nproperty list float int vertex_indices\n"
                  "end_header\n" TRI "3 0 1 2\n",
           "ply_corrupt", "bad list property");
    expect(HEAD_V "property float z\nend_header\n" TRI, "ply_no_faces", NULL);
    expect(HEAD_V "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                  "end_header\n" TRI "2 0 1\n",
           "ply_no_faces", NULL);
    /* A binary list count past the end of the file. */
    static const char big[] = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
                              "property float x\nproperty float y\nproperty float z\nelement "
                              "face 1\nproperty list uint int vertex_indices\nend_header\n"
                              "\0\0\0\0\0\0\0\0\0\0\0\0\xff\xff\xff\x7f";
    expect_n(big, sizeof big - 1, "ply_corrupt", "more than the file holds");
    expect("ply\nformat ascii 2.0\nend_header\n", "ply_corrupt", "format");
    expect("ply\nelement vertex 1\nproperty float x\nend_header\n0\n", "ply_corrupt", "format");
    expect("plyx\nformat ascii 1.0\nend_header\n", "ply_corrupt", "first line");
    /* A declared count the bytes cannot hold: refused before reading. */
    expect(HEAD_V "property float z\nelement face 4000000000\nproperty list uchar int "
                  "vertex_indices\nend_header\n" TRI "3 0 1 2\n",
           "ply_corrupt", "declares");
    /* A face naming one vertex twice, as OBJ's obj_face_repeat. */
    expect(HEAD_V "property float z\nelement face 1\nproperty list uchar int "
                  "vertex_indices\nend_header\n" TRI "4 0 1 2 1\n",
           "ply_corrupt", "uses vertex 1 twice");
    /* The face limit counts triangles of the polygons read. */
    vx_mesh_limits lim = {.max_triangles = 1};
    const char *quad = HEAD_V "property float z\nelement face 2\nproperty list uchar int "
                              "vertex_indices\nend_header\n" TRI "3 0 1 2\n3 0 2 1\n";
    r = vx_ply_read_mem((const unsigned char *)quad, strlen(quad), &lim, &err);
    assert_null(r);
    assert_string_equal(err.code, "mesh_too_big");
}

static void test_header_prefix(void **state)
{
    (void)state;
    const char *s = HEAD_V "property float z\nelement face 1\nproperty list uchar int "
                           "vertex_indices\nend_header\n" TRI "3 0 1 2\n";
    size_t n = strlen(s), body = (size_t)(strstr(s, "end_header\n") - s) + 11;
    vx_ply_header *h = malloc(sizeof *h);
    vx_err err = {0};
    for (size_t k = 1; k < body; k++) {
        int rc = vx_ply_header_parse((const unsigned char *)s, k, n, h, &err);
        assert_int_equal(rc, 1);
    }
    assert_int_equal(vx_ply_header_parse((const unsigned char *)s, body, n, h, &err), 0);
    assert_int_equal(h->body, body);
    assert_int_equal(h->nelems, 2);
    assert_int_equal(h->elems[0].nprops, 3);
    assert_int_equal(h->elems[1].count, 1);
    assert_int_equal(h->props[h->elems[1].first_prop].count_type, VX_PLY_U8);
    assert_int_equal(h->props[h->elems[1].first_prop].type, VX_PLY_I32);
    /* After a UTF-8 byte order mark (as OBJ, OFF and ASCII STL take one):
     * sniffed and read as PLY, the body after the mark's 3 bytes too */
    char *bom = malloc(n + 4);
    memcpy(bom, "\xef\xbb\xbf", 3);
    memcpy(bom + 3, s, n + 1);
    assert_int_equal(vx_mesh_sniff_sized((const unsigned char *)bom, n + 3, n + 3), VX_MESH_PLY);
    assert_int_equal(vx_ply_header_parse((const unsigned char *)bom, n + 3, n + 3, h, &err), 0);
    assert_int_equal(h->body, body + 3);
    vx_mesh *m = vx_ply_read_mem((const unsigned char *)bom, n + 3, NULL, &err);
    if (!m) print_error("%s\n", err.message);
    assert_non_null(m);
    assert_int_equal(m->ntris, 1);
    vx_mesh_free(m);
    free(bom);
    /* The whole file without an end_header line is refused, not retried. */
    const char *cut = "ply\nformat ascii 1.0\nelement vertex 0\n";
    assert_int_equal(
        vx_ply_header_parse((const unsigned char *)cut, strlen(cut), strlen(cut), h, &err), -1);
    assert_string_equal(err.code, "ply_corrupt");
    free(h);
}

/* The unit cube's six faces, each counter-clockwise seen from outside
 * (vertex x + 2 y + 4 z), as a strip a b d c of quad a b c d. */
static const int cube_strip[6][4] = {{0, 2, 1, 3}, {4, 5, 6, 7}, {0, 1, 4, 5},
                                     {2, 6, 3, 7}, {0, 4, 2, 6}, {1, 3, 5, 7}};

/* A tristrips file of the cube in format f, index type t (signed: -1
 * ends a strip): layout 0 one entry of six strips split by -1, 1 six
 * entries, 2 one strip stitched through repeated indices (triangles that
 * use a vertex twice, to be dropped). With a face element of the cube's
 * top face too when face is set (read as well: 14 triangles). */
static tbuf cube_strips(vx_ply_format f, vx_ply_type t, int layout, int face)
{
    static const char *fmt_name[] = {"ascii", "binary_little_endian", "binary_big_endian"};
    tbuf b = {0};
    int entries = layout == 1 ? 6 : 1;
    tbuf_printf(&b,
                "ply\nformat %s 1.0\nelement vertex 8\nproperty double x\nproperty double "
                "y\nproperty double z\n",
                fmt_name[f]);
    if (face) tbuf_printf(&b, "element face 1\nproperty list uchar int vertex_indices\n");
    tbuf_printf(&b, "element tristrips %d\nproperty list int %s vertex_indices\nend_header\n",
                entries, type_name[t]);
    for (int v = 0; v < 8; v++) {
        for (int a = 0; a < 3; a++)
            put_value(&b, f, VX_PLY_F64, v >> a & 1);
        if (f == VX_PLY_ASCII) tbuf_printf(&b, "\n");
    }
    if (face) {
        put_value(&b, f, VX_PLY_U8, 4);
        static const int top[4] = {4, 5, 7, 6};
        for (int k = 0; k < 4; k++)
            put_value(&b, f, VX_PLY_I32, top[k]);
    }
    int list[64], n = 0;
    for (int s = 0; s < 6; s++) {
        if (layout == 1) {
            put_value(&b, f, VX_PLY_I32, 4);
            for (int k = 0; k < 4; k++)
                put_value(&b, f, t, cube_strip[s][k]);
            continue;
        }
        if (s && layout == 0) list[n++] = -1;
        if (s && layout == 2) { /* the last index and the next strip's first, again */
            list[n++] = cube_strip[s - 1][3];
            list[n++] = cube_strip[s][0];
        }
        for (int k = 0; k < 4; k++)
            list[n++] = cube_strip[s][k];
    }
    if (layout != 1) {
        put_value(&b, f, VX_PLY_I32, n);
        for (int k = 0; k < n; k++)
            put_value(&b, f, t, list[k]);
    }
    return b;
}

/* Six times the signed volume of m's triangles. */
static double volume6(const vx_mesh *m)
{
    double v = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                     *c = m->pos + 3 * m->tri[3 * t + 2];
        v += a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
             a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    return v;
}

/* Triangle strips (element tristrips): every second triangle turned, -1
 * between strips, stitching triangles dropped; a closed cube of one
 * orientation whatever the layout, format and index type. */
static void test_tristrips(void **state)
{
    (void)state;
    static const vx_ply_type types[] = {VX_PLY_I8, VX_PLY_I16, VX_PLY_I32};
    for (int f = 0; f < 3; f++)
        for (int ti = 0; ti < 3; ti++)
            for (int layout = 0; layout < 3; layout++)
                for (int face = 0; face < 2; face++) {
                    tbuf b = cube_strips((vx_ply_format)f, types[ti], layout, face);
                    vx_err err = {0};
                    vx_mesh *m = vx_ply_read_mem((const unsigned char *)b.p, b.n, NULL, &err);
                    if (!m) fail_msg("format %d type %d layout %d: %s", f, ti, layout, err.message);
                    assert_int_equal(m->ntris, face ? 14 : 12);
                    assert_int_equal(m->nfaces, face ? 13 : 12);
                    if (!face) {
                        assert_int_equal(m->boundary_edges, 0);
                        assert_int_equal(m->misoriented_edges, 0);
                        assert_true(fabs(volume6(m) - 6) < 1e-12);
                    }
                    vx_mesh_free(m);
                    free(b.p);
                }
    /* A limit on triangles counts the strips' triangles. */
    tbuf b = cube_strips(VX_PLY_LE, VX_PLY_I32, 0, 0);
    vx_mesh_limits lim = {.max_triangles = 11};
    vx_err err = {0};
    assert_null(vx_ply_read_mem((const unsigned char *)b.p, b.n, &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    free(b.p);
    /* Hostile strips: an index past the vertices, one below -1, and
     * strips that make no triangle of three vertices. */
    static const struct {
        const char *list, *code, *words;
    } bad[] = {{"4 0 1 2 7", "ply_corrupt", "out of range"},
               {"4 0 1 2 -2", "ply_corrupt", "bad vertex index"},
               {"5 0 1 -1 2 0", "ply_no_faces", "strips"},
               {"4 0 1 1 2", "ply_no_faces", NULL}};
    for (size_t k = 0; k < sizeof bad / sizeof bad[0]; k++) {
        char f[1024];
        snprintf(f, sizeof f,
                 HEAD_V "property float z\nelement tristrips 1\nproperty list int int "
                        "vertex_indices\nend_header\n" TRI "%s\n",
                 bad[k].list);
        expect(f, bad[k].code, bad[k].words);
    }
    expect(HEAD_V "property float z\nelement tristrips 1\nproperty list int int corners\n"
                  "end_header\n" TRI "3 0 1 2\n",
           "ply_corrupt", "tristrips element has no vertex_indices");
    /* A strip of a quad: (0 1 2), then (2 1 3) */
    vx_mesh *r = read_str("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty "
                          "float y\nproperty float z\nelement tristrips 1\nproperty list int int "
                          "vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n4 0 1 2 3\n",
                          &err);
    if (!r) fail_msg("%s", err.message);
    static const uint32_t want[6] = {0, 1, 2, 2, 1, 3};
    assert_int_equal(r->nfaces, 2);
    assert_memory_equal(r->face_idx, want, sizeof want);
    vx_mesh_free(r);
}

/* What voxeld writes (vx_ply_write_path) reads back. */
static void test_own_writer(void **state)
{
    (void)state;
    mesh_in m = random_mesh(50, 40, VX_PLY_U32);
    vx_mesh *w = vx_mesh_new();
    w->nverts = m.nv;
    w->pos = m.pos;
    w->nfaces = m.nf;
    w->face_start = m.start;
    w->face_idx = m.idx;
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(w, &err), 0);
    char path[] = "/tmp/test_ply_XXXXXX.ply";
    int fd = mkstemps(path, 4);
    assert_true(fd >= 0);
    close(fd);
    assert_int_equal(vx_ply_write_path(w, NULL, path, &err), 0);
    vx_mesh *r = vx_mesh_read_path(path, NULL, &err);
    if (!r) fail_msg("%s", err.message);
    check_same(r, &m, VX_PLY_F32);
    vx_mesh_free(r);
    unlink(path);
    vx_mesh_free(w); /* owns m's arrays now */
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip), cmocka_unit_test(test_truncations),
        cmocka_unit_test(test_hostile),    cmocka_unit_test(test_header_prefix),
        cmocka_unit_test(test_own_writer), cmocka_unit_test(test_tristrips),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
