/* The STL reader (mesh/import.cc, voxeld's own: assimp's STL importer
 * leaked on every malformed ASCII file): random triangle soups written binary
 * (headers that start with "solid" too) and ASCII (tabs, CRLF, several
 * solids, names with blanks, no endsolid) read back welded, corner by
 * corner, binary files with bytes after the last triangle too; every truncation of a binary file
 * and a set of malformed ASCII files fail with stl_corrupt; the limits hold. The sanitized build's
 * leak check covers the failures. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "text_buf.h"

static uint64_t rnd_state = 0x9E3779B97F4A7C15ull;
static uint64_t rnd(void)
{
    return test_rand(&rnd_state);
}

/* ntri triangles over a pool of npool positions (so corners repeat and
 * the reader must weld them); binary files hold floats, so the pool is
 * made of floats. */
static float *random_soup(size_t ntri, size_t npool, float **pool_out)
{
    float *pool = malloc(3 * npool * sizeof *pool), *c = malloc(9 * ntri * sizeof *c);
    for (size_t i = 0; i < 3 * npool; i++)
        pool[i] = (float)((double)(rnd() % 200001) / 1024.0 - 97.0);
    for (size_t t = 0; t < ntri; t++) {
        size_t a = rnd() % npool, b = rnd() % npool, d = rnd() % npool;
        while (b == a)
            b = (b + 1) % npool;
        while (d == a || d == b)
            d = (d + 1) % npool;
        memcpy(c + 9 * t, pool + 3 * a, 12);
        memcpy(c + 9 * t + 3, pool + 3 * b, 12);
        memcpy(c + 9 * t + 6, pool + 3 * d, 12);
    }
    *pool_out = pool;
    return c;
}

static void put_le32(tbuf *b, uint32_t u)
{
    unsigned char o[4] = {(unsigned char)u, (unsigned char)(u >> 8), (unsigned char)(u >> 16),
                          (unsigned char)(u >> 24)};
    tbuf_put(b, o, 4);
}

static tbuf write_binary(const float *c, size_t ntri, int solid_header)
{
    tbuf b = {0};
    char head[80];
    memset(head, ' ', sizeof head);
    if (solid_header) memcpy(head, "solid exported by a CAD tool", 28);
    tbuf_put(&b, head, 80);
    put_le32(&b, (uint32_t)ntri);
    for (size_t t = 0; t < ntri; t++) {
        for (int k = 0; k < 3; k++)
            put_le32(&b, 0); /* the normal */
        for (int k = 0; k < 9; k++) {
            uint32_t u;
            memcpy(&u, &c[9 * t + k], 4);
            put_le32(&b, u);
        }
        tbuf_put(&b, "\0\0", 2);
    }
    return b;
}

static tbuf write_ascii(const float *c, size_t ntri, int style)
{
    const char *nl = style & 1 ? "\r\n" : "\n", *in = style & 2 ? "\t" : "  ";
    tbuf b = {0};
    size_t split = style & 4 ? ntri / 2 : ntri; /* two solids */
    for (int s = 0; s < 2; s++) {
        size_t t0 = s ? split : 0, t1 = s ? ntri : split;
        if (s && t0 == t1) break;
        tbuf_printf(&b, "solid part %d of a model%s", s, nl);
        for (size_t t = t0; t < t1; t++) {
            tbuf_printf(&b, "%sfacet normal 0 0 1%s%s%souter loop%s", in, nl, in, in, nl);
            for (int v = 0; v < 3; v++)
                tbuf_printf(&b, "%s%s%svertex %.17g %.17g %.17g%s", in, in, in,
                            (double)c[9 * t + 3 * v], (double)c[9 * t + 3 * v + 1],
                            (double)c[9 * t + 3 * v + 2], nl);
            tbuf_printf(&b, "%s%sendloop%s%sendfacet%s", in, in, nl, in, nl);
        }
        if (!(style & 8) || s == 0) tbuf_printf(&b, "endsolid part %d%s", s, nl);
    }
    return b;
}

/* The reader's mesh has the soup's corners, welded by position in order
 * of first appearance. */
static void check_soup(const vx_mesh *m, const float *c, size_t ntri)
{
    assert_int_equal(m->nfaces, ntri);
    size_t nuniq = 0;
    for (size_t t = 0; t < ntri; t++) {
        const uint32_t *f = vx_mesh_face(m, t);
        assert_int_equal(vx_mesh_face_size(m, t), 3);
        for (int v = 0; v < 3; v++) {
            assert_true(f[v] < m->nverts);
            for (int a = 0; a < 3; a++)
                assert_true(m->pos[3 * f[v] + a] == (double)c[9 * t + 3 * v + a]);
            if (f[v] == nuniq) nuniq++; /* first appearances number 0, 1, 2, ... */
            assert_true(f[v] < nuniq);
        }
    }
    assert_int_equal(nuniq, m->nverts);
    /* No two vertices at one position. */
    for (size_t i = 0; i < m->nverts; i++)
        for (size_t j = i + 1; j < m->nverts; j++)
            assert_false(!memcmp(m->pos + 3 * i, m->pos + 3 * j, 3 * sizeof(double)));
}

static vx_mesh *read_buf(const tbuf *b, vx_err *err)
{
    memset(err, 0, sizeof *err);
    return vx_import_read_mem((const unsigned char *)b->p, b->n, VX_MESH_STL, NULL, err);
}

static void test_round_trip(void **state)
{
    (void)state;
    for (int round = 0; round < 40; round++) {
        size_t ntri = 1 + rnd() % 300, npool = 3 + rnd() % 200;
        float *pool, *c = random_soup(ntri, npool, &pool);
        tbuf b = round % 2 ? write_ascii(c, ntri, round / 2 % 16)
                           : write_binary(c, ntri, round % 4 == 0);
        vx_err err;
        vx_mesh *m = read_buf(&b, &err);
        if (!m) fail_msg("round %d: %s", round, err.message);
        check_soup(m, c, ntri);
        vx_mesh_free(m);
        free(b.p);
        free(c);
        free(pool);
    }
}

/* A cube whose facets write one corner as -0 and the others as 0: one
 * place, one vertex (the weld once compared the bits: 9 vertices and 6
 * boundary edges, so a default voxelize ran `winding` on a closed cube). */
static void test_negative_zero(void **state)
{
    (void)state;
    static const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                                {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
    char text[8192];
    size_t n = (size_t)snprintf(text, sizeof text, "solid c\n");
    for (int f = 0; f < 6; f++)
        for (int t = 0; t < 2; t++) {
            int c[3] = {q[f][0], q[f][t + 1], q[f][t + 2]};
            n += (size_t)snprintf(text + n, sizeof text - n, "facet normal 0 0 0\nouter loop\n");
            for (int k = 0; k < 3; k++) {
                int v = c[k];
                /* vertex 0 as -0 -0 -0 in the first facet only */
                const char *zero = f == 0 && t == 0 && v == 0 ? "-0" : "0";
                n += (size_t)snprintf(text + n, sizeof text - n, "vertex %s %s %s\n",
                                      v & 1 ? "1" : zero, v & 2 ? "1" : zero, v & 4 ? "1" : zero);
            }
            n += (size_t)snprintf(text + n, sizeof text - n, "endloop\nendfacet\n");
        }
    n += (size_t)snprintf(text + n, sizeof text - n, "endsolid c\n");
    assert_true(n < sizeof text);
    vx_err err;
    memset(&err, 0, sizeof err);
    vx_mesh *m = vx_import_read_mem((const unsigned char *)text, n, VX_MESH_STL, NULL, &err);
    if (!m) fail_msg("%s", err.message);
    assert_int_equal(m->nverts, 8);
    assert_int_equal(m->boundary_edges, 0);
    assert_int_equal(m->boundary_edges_welded, 0);
    vx_mesh_free(m);
}

static void test_truncations(void **state)
{
    (void)state;
    float *pool, *c = random_soup(6, 5, &pool);
    tbuf b = write_binary(c, 6, 1);
    for (size_t n = 0; n < b.n; n++) {
        vx_err err = {0};
        unsigned char *copy = malloc(n + 1);
        memcpy(copy, b.p, n);
        vx_mesh *m = vx_import_read_mem(copy, n, VX_MESH_STL, NULL, &err);
        assert_null(m);
        /* Before the count's zero bytes the "solid" header reads as an
         * empty ASCII solid. */
        assert_string_equal(err.code,
                            n >= 5 && !memchr(copy, 0, n) ? "stl_no_faces" : "stl_corrupt");
        free(copy);
    }
    free(b.p);
    free(c);
    free(pool);
}

/* Bytes after the last triangle of a binary file (some exporters pad or
 * append): the header's count is read, the rest ignored; with a "solid"
 * header too (it had been 400 stl_corrupt, "the file has N bytes"). */
static void test_trailing_bytes(void **state)
{
    (void)state;
    static const size_t extra[] = {1, 2, 7, 49, 50, 51, 600};
    for (size_t k = 0; k < sizeof extra / sizeof extra[0]; k++)
        for (int solid = 0; solid < 2; solid++) {
            size_t ntri = 1 + rnd() % 40;
            float *pool, *c = random_soup(ntri, 3 + rnd() % 30, &pool);
            tbuf b = write_binary(c, ntri, solid);
            for (size_t i = 0; i < extra[k]; i++)
                tbuf_put(&b, i % 3 ? "\0" : "x", 1);
            vx_err err;
            vx_mesh *m = read_buf(&b, &err);
            if (!m) fail_msg("%zu bytes after, solid %d: %s", extra[k], solid, err.message);
            check_soup(m, c, ntri);
            vx_mesh_free(m);
            /* sniffed as STL by its size too, up to 511 bytes after */
            if (extra[k] < 512)
                assert_int_equal(
                    vx_mesh_sniff_sized((const unsigned char *)b.p, b.n < 512 ? b.n : 512, b.n),
                    VX_MESH_STL);
            free(b.p);
            free(c);
            free(pool);
        }
}

/* A count of 0 before whole triangles (a writer that streamed them and
 * never filled the count in): the size gives the count (it had been 422
 * stl_no_faces). Not when a byte is left over: then 0 is what is meant,
 * and the rest trailing bytes. */
static void test_zero_count(void **state)
{
    (void)state;
    for (int solid = 0; solid < 2; solid++) {
        size_t ntri = 1 + rnd() % 40;
        float *pool, *c = random_soup(ntri, 3 + rnd() % 30, &pool);
        tbuf b = write_binary(c, ntri, solid);
        memset(b.p + 80, 0, 4);
        vx_err err;
        vx_mesh *m = read_buf(&b, &err);
        if (!m) fail_msg("count 0, %zu triangles, solid %d: %s", ntri, solid, err.message);
        check_soup(m, c, ntri);
        vx_mesh_free(m);
        tbuf_put(&b, "x", 1);
        assert_null(read_buf(&b, &err));
        assert_string_equal(err.code, "stl_no_faces");
        free(b.p);
        free(c);
        free(pool);
    }
}

static void expect(const char *text, const char *code, const char *in_message)
{
    tbuf b = {0};
    tbuf_put(&b, text, strlen(text));
    vx_err err;
    vx_mesh *m = read_buf(&b, &err);
    if (m) fail_msg("read, expected %s: %s", code, text);
    assert_string_equal(err.code, code);
    if (in_message && !strstr(err.message, in_message))
        fail_msg("message \"%s\" lacks \"%s\"", err.message, in_message);
    free(b.p);
}

#define F1 "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\n"

static void test_hostile(void **state)
{
    (void)state;
    expect("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\n"
           "endfacet\nendsolid\n",
           "stl_corrupt", "three vertices");
    expect("solid x\n" F1 "vertex 1 1 1\nendloop\nendfacet\nendsolid\n", "stl_corrupt", "endloop");
    expect("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 nan 0\nvertex 1 0 0\n"
           "vertex 0 1 0\nendloop\nendfacet\nendsolid\n",
           "stl_corrupt", "NaN");
    expect("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 x 0\nvertex 1 0 0\n"
           "vertex 0 1 0\nendloop\nendfacet\nendsolid\n",
           "stl_corrupt", "line 2");
    /* a hex number (strtod's: 0x1 was 1), as OBJ refuses it */
    expect("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0x1 0 0\n"
           "vertex 0 1 0\nendloop\nendfacet\nendsolid\n",
           "stl_corrupt", "line 2");
    /* A number over 63 characters is said as such, on its own line (it
     * was "a facet without three vertices of three numbers", line 2). */
    expect("solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 "
           "1.0000000000000000000000000000000000000000000000000000000000000000000 0\n"
           "endloop\nendfacet\nendsolid\n",
           "stl_corrupt", "line 6: a number 69 characters long (at most 63)");
    expect("solid x\n" F1 "endfacet\nendsolid x\ngarbage\n", "stl_corrupt", "after endsolid");
    expect("solid x\nfacet 0 0 1\n", "stl_corrupt", "normal");
    expect("solid x\nfacet normal 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
           "endloop\nendfacet\nendsolid\n",
           "stl_corrupt", "normal");
    expect("solid x\nloop\n", "stl_corrupt", "facet or endsolid");
    expect("solid x\nendsolid x\n", "stl_no_faces", NULL);
    /* A missing endsolid is forgiven. */
    tbuf b = {0};
    const char *ok = "solid x\n" F1 "endfacet\n";
    tbuf_put(&b, ok, strlen(ok));
    vx_err err;
    vx_mesh *m = read_buf(&b, &err);
    assert_non_null(m);
    assert_int_equal(m->nfaces, 1);
    vx_mesh_free(m);
    free(b.p);
    /* 63 characters are still a number. */
    b = (tbuf){0};
    ok = "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 "
         "1.0000000000000000000000000000000000000000000000000000000000000 "
         "0\nendloop\nendfacet\nendsolid\n";
    tbuf_put(&b, ok, strlen(ok));
    m = read_buf(&b, &err);
    if (!m)
        fail_msg("1.0000000000000000000000000000000000000000000000000000000000000", err.message);
    assert_int_equal(m->nfaces, 1);
    vx_mesh_free(m);
    free(b.p);
    /* Normals are not read: MSVC's printf wrote NaN as -1.#IND00, and
     * such files were refused ("a facet without its normal"). */
    b = (tbuf){0};
    ok = "solid x\nfacet normal -1.#IND00 -1.#IND00 1.#QNAN0\nouter loop\nvertex 0 0 0\n"
         "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n";
    tbuf_put(&b, ok, strlen(ok));
    m = read_buf(&b, &err);
    if (!m) fail_msg("%s", err.message);
    assert_int_equal(m->nfaces, 1);
    vx_mesh_free(m);
    free(b.p);
    /* The triangle limit. */
    float *pool, *c = random_soup(10, 8, &pool);
    b = write_ascii(c, 10, 0);
    vx_mesh_limits lim = {.max_triangles = 9};
    assert_null(vx_import_read_mem((const unsigned char *)b.p, b.n, VX_MESH_STL, &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    free(b.p);
    b = write_binary(c, 10, 0);
    lim = (vx_mesh_limits){.max_vertices = 3};
    assert_null(vx_import_read_mem((const unsigned char *)b.p, b.n, VX_MESH_STL, &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    free(b.p);
    free(c);
    free(pool);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_round_trip),  cmocka_unit_test(test_negative_zero),
        cmocka_unit_test(test_truncations), cmocka_unit_test(test_trailing_bytes),
        cmocka_unit_test(test_zero_count),  cmocka_unit_test(test_hostile),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
