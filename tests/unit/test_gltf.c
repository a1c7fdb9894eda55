/* The glTF 2.0 reader (mesh/import.cc, tinygltf and the scene walk):
 * files built here, as glTF with a data: URI and as glb with a BIN chunk,
 * read back to the geometry they hold: node transforms (matrix, T * R * S,
 * nested), mirrored nodes keeping outward winding, strips and fans,
 * quantized and sparse positions (sparse ones found by binary search for
 * the vertices a primitive indexes), images ignored, many primitives over one
 * shared accessor (only the vertices they index are kept); refusals (indices out
 * of range, external buffers, NaNs, limits, no scene); and mutated files,
 * which must fail with an error or give a consistent mesh. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "mesh/mesh.h"
#include "text_buf.h"

static uint64_t rnd_state = 0x243F6A8885A308D3ull;

/* ---- building files ------------------------------------------------- */

typedef struct part {
    const void *data;
    size_t bytes;
} part;

/* The one buffer: parts one after another, each at a 4-byte boundary;
 * off[i] is where part i starts. */
static tbuf pack(const part *parts, int n, size_t *off)
{
    tbuf b = {0};
    static const char zero[4] = {0};
    for (int i = 0; i < n; i++) {
        off[i] = b.n;
        tbuf_put(&b, parts[i].data, parts[i].bytes);
        tbuf_put(&b, zero, (4 - b.n % 4) % 4);
    }
    return b;
}

static void base64(tbuf *out, const unsigned char *p, size_t n)
{
    static const char a[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for (size_t i = 0; i < n; i += 3) {
        uint32_t v = (uint32_t)p[i] << 16 | (i + 1 < n ? (uint32_t)p[i + 1] << 8 : 0) |
                     (i + 2 < n ? p[i + 2] : 0);
        char q[4] = {a[v >> 18], a[(v >> 12) & 63], i + 1 < n ? a[(v >> 6) & 63] : '=',
                     i + 2 < n ? a[v & 63] : '='};
        tbuf_put(out, q, 4);
    }
}

/* A file from its JSON body (everything but asset and buffers, which are
 * added: buffer 0 holds bin) as glTF (data: URI) or glb (BIN chunk). */
static tbuf make_file(const char *body, const tbuf *bin, int glb)
{
    tbuf j = {0};
    tbuf_printf(&j, "{\"asset\":{\"version\":\"2.0\"},");
    tbuf_put(&j, body, strlen(body));
    tbuf_printf(&j, ",\"buffers\":[{\"byteLength\":%zu", bin->n);
    if (!glb) {
        tbuf_printf(&j, ",\"uri\":\"data:application/octet-stream;base64,");
        base64(&j, (const unsigned char *)bin->p, bin->n);
        tbuf_printf(&j, "\"");
    }
    tbuf_printf(&j, "}]}");
    if (!glb) return j;
    while (j.n % 4)
        tbuf_put(&j, " ", 1);
    tbuf f = {0};
    uint32_t h[5] = {0x46546C67u, 2, (uint32_t)(12 + 8 + j.n + 8 + bin->n), (uint32_t)j.n,
                     0x4E4F534Au};
    tbuf_put(&f, h, sizeof h);
    tbuf_put(&f, j.p, j.n);
    uint32_t c[2] = {(uint32_t)bin->n, 0x004E4942u};
    tbuf_put(&f, c, sizeof c);
    tbuf_put(&f, bin->p, bin->n);
    free(j.p);
    return f;
}

static vx_mesh *read_file(const tbuf *f, int glb, const vx_mesh_limits *lim, vx_err *err)
{
    vx_err_clear(err);
    return vx_import_read_mem((const unsigned char *)f->p, f->n, glb ? VX_MESH_GLB : VX_MESH_GLTF,
                              lim, err);
}

/* The unit cube, outward winding. */
static const float cube_pos[24] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0,
                                   0, 0, 1, 1, 0, 1, 1, 1, 1, 0, 1, 1};
static const uint16_t cube_idx[36] = {0, 2, 1, 0, 3, 2, 4, 5, 6, 4, 6, 7, 0, 1, 5, 0, 5, 4,
                                      1, 2, 6, 1, 6, 5, 2, 3, 7, 2, 7, 6, 3, 0, 4, 3, 4, 7};

/* The cube's buffer, views and accessors (0: positions, 1: indices) and
 * the mesh, in front of the caller's nodes and scenes. */
static tbuf cube_file(const char *nodes, int glb)
{
    size_t off[2];
    part parts[2] = {{cube_pos, sizeof cube_pos}, {cube_idx, sizeof cube_idx}};
    tbuf bin = pack(parts, 2, off);
    tbuf body = {0};
    tbuf_printf(&body,
                "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu},"
                "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu}],",
                off[0], sizeof cube_pos, off[1], sizeof cube_idx);
    tbuf_printf(&body, "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":8,"
                       "\"type\":\"VEC3\"},{\"bufferView\":1,\"componentType\":5123,"
                       "\"count\":36,\"type\":\"SCALAR\"}],");
    tbuf_printf(&body, "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                       "\"indices\":1}]}],");
    tbuf_put(&body, nodes, strlen(nodes));
    tbuf f = make_file(body.p, &bin, glb);
    free(body.p);
    free(bin.p);
    return f;
}

/* ---- checks ---------------------------------------------------------- */

static double signed_volume(const vx_mesh *m)
{
    double v = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                     *c = m->pos + 3 * m->tri[3 * t + 2];
        v += (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
              a[2] * (b[0] * c[1] - b[1] * c[0])) /
             6;
    }
    return v;
}

static void expect_box(const vx_mesh *m, const double lo[3], const double hi[3])
{
    for (int i = 0; i < 3; i++) {
        if (fabs(m->bbox_min[i] - lo[i]) > 1e-6 || fabs(m->bbox_max[i] - hi[i]) > 1e-6)
            fail_msg("axis %d: [%g, %g], expected [%g, %g]", i, m->bbox_min[i], m->bbox_max[i],
                     lo[i], hi[i]);
    }
}

static vx_mesh *must_read(const tbuf *f, int glb)
{
    vx_err err;
    vx_mesh *m = read_file(f, glb, NULL, &err);
    if (!m) fail_msg("%s: %s", err.code, err.message);
    return m;
}

static void expect_error(const tbuf *f, int glb, const vx_mesh_limits *lim, const char *code,
                         const char *words)
{
    vx_err err;
    vx_mesh *m = read_file(f, glb, lim, &err);
    if (m) fail_msg("read, expected %s", code);
    if (strcmp(err.code, code) || (words && !strstr(err.message, words)))
        fail_msg("got %s: %s; expected %s (%s)", err.code, err.message, code, words ? words : "");
}

/* ---- tests ----------------------------------------------------------- */

static void test_gltf_cube(void **state)
{
    (void)state;
    for (int glb = 0; glb < 2; glb++) {
        tbuf f =
            cube_file("\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]", glb);
        vx_mesh *m = must_read(&f, glb);
        assert_int_equal(m->nverts, 8);
        assert_int_equal(m->ntris, 12);
        assert_int_equal(m->boundary_edges, 0);
        assert_int_equal(m->nonmanifold_edges, 0);
        assert_true(fabs(signed_volume(m) - 1) < 1e-9);
        expect_box(m, (double[]){0, 0, 0}, (double[]){1, 1, 1});
        vx_mesh_free(m);
        free(f.p);
    }
}

/* No scenes (a library, which the spec allows): the root nodes, each
 * child once through its parent; with no nodes, the meshes as they are. It
 * had been no faces (422 gltf_no_faces). */
static void test_gltf_no_scenes(void **state)
{
    (void)state;
    for (int glb = 0; glb < 2; glb++) {
        tbuf f = cube_file("\"nodes\":[{\"mesh\":0,\"translation\":[5,0,0]},"
                           "{\"mesh\":0,\"children\":[2]},{\"mesh\":0,\"translation\":[0,0,3]}]",
                           glb);
        vx_mesh *m = must_read(&f, glb);
        assert_int_equal(m->ntris, 36);
        assert_true(fabs(signed_volume(m) - 3) < 1e-9);
        expect_box(m, (double[]){0, 0, 0}, (double[]){6, 1, 4});
        vx_mesh_free(m);
        free(f.p);
        f = cube_file("\"extras\":{}", glb);
        m = must_read(&f, glb);
        assert_int_equal(m->ntris, 12);
        expect_box(m, (double[]){0, 0, 0}, (double[]){1, 1, 1});
        vx_mesh_free(m);
        free(f.p);
    }
}

/* Nested nodes: a translated parent, a child rotated 90 degrees about z
 * and scaled by 2 (T * R * S: scale first), a sibling given as a matrix,
 * and a mirrored instance whose winding must come out outward. */
static void test_gltf_transforms(void **state)
{
    (void)state;
    const double s = sqrt(0.5);
    char nodes[1024];
    snprintf(nodes, sizeof nodes,
             "\"scene\":1,\"scenes\":[{\"nodes\":[3]},{\"nodes\":[0]}],\"nodes\":["
             "{\"translation\":[10,20,30],\"children\":[1,2]},"
             "{\"mesh\":0,\"rotation\":[0,0,%.17g,%.17g],\"scale\":[2,2,2]},"
             "{\"mesh\":0,\"matrix\":[1,0,0,0,0,1,0,0,0,0,1,0,-5,0,0,1]},"
             "{\"mesh\":0}]",
             s, s);
    for (int glb = 0; glb < 2; glb++) {
        tbuf f = cube_file(nodes, glb);
        vx_mesh *m = must_read(&f, glb);
        /* The rotated cube spans x in [8, 10], y in [20, 22], z in [30, 32];
         * the matrix one x in [5, 6], y in [20, 21], z in [30, 31]. Scene 0
         * (node 3 alone) is not the default one and is not read. */
        expect_box(m, (double[]){5, 20, 30}, (double[]){10, 22, 32});
        assert_int_equal(m->ntris, 24);
        assert_true(fabs(signed_volume(m) - 9) < 1e-9);
        vx_mesh_free(m);
        free(f.p);
    }
    /* Mirrored (scale -1 on x, and a matrix with a negative determinant):
     * the triangles are turned so that the volume stays positive. */
    const char *mirrors[] = {
        "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0,\"scale\":[-1,1,1]}]",
        "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"children\":[1],\"scale\":[1,-3,1]},"
        "{\"mesh\":0,\"matrix\":[1,0,0,0,0,1,0,0,0,0,-1,0,0,0,0,1]}]"};
    const double vol[] = {1, 3};
    for (int k = 0; k < 2; k++) {
        tbuf f = cube_file(mirrors[k], k);
        vx_mesh *m = must_read(&f, k);
        if (fabs(signed_volume(m) - vol[k]) > 1e-9)
            fail_msg("mirror %d: volume %g, expected %g", k, signed_volume(m), vol[k]);
        vx_mesh_free(m);
        free(f.p);
    }
}

/* A strip and a fan over the same hexagon ring: every triangle faces +z
 * (the strip alternates its corners as glTF says). */
static void test_gltf_strip_fan(void **state)
{
    (void)state;
    float ring[18];
    for (int i = 0; i < 6; i++) {
        ring[3 * i] = (float)cos(i * M_PI / 3);
        ring[3 * i + 1] = (float)sin(i * M_PI / 3);
        ring[3 * i + 2] = 0;
    }
    /* Strip order zigzags across the hexagon: 0 1 5 2 4 3. */
    const uint8_t strip[6] = {0, 1, 5, 2, 4, 3}, fan[6] = {0, 1, 2, 3, 4, 5};
    size_t off[3];
    part parts[3] = {{ring, sizeof ring}, {strip, 6}, {fan, 6}};
    tbuf bin = pack(parts, 3, off);
    for (int mode = 5; mode <= 6; mode++) {
        tbuf body = {0};
        tbuf_printf(&body,
                    "\"bufferViews\":[{\"buffer\":0,\"byteLength\":72},"
                    "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":6}],",
                    off[mode - 4]);
        tbuf_printf(&body, "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":6,"
                           "\"type\":\"VEC3\"},{\"bufferView\":1,\"componentType\":5121,"
                           "\"count\":6,\"type\":\"SCALAR\"}],");
        tbuf_printf(&body,
                    "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                    "\"indices\":1,\"mode\":%d},{\"attributes\":{\"POSITION\":0},\"mode\":1}]}],"
                    "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]",
                    mode);
        tbuf f = make_file(body.p, &bin, mode == 6);
        vx_mesh *m = must_read(&f, mode == 6);
        assert_int_equal(m->ntris, 4); /* the line primitive adds nothing */
        assert_int_equal(m->nverts, 6);
        for (size_t t = 0; t < m->ntris; t++) {
            const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                         *c = m->pos + 3 * m->tri[3 * t + 2];
            double nz = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
            if (!(nz > 0)) fail_msg("mode %d: triangle %zu faces -z (%g)", mode, t, nz);
        }
        assert_int_equal(m->boundary_edges, 6);
        vx_mesh_free(m);
        free(f.p);
        free(body.p);
    }
    free(bin.p);
}

/* KHR_mesh_quantization: positions as normalized shorts, in a view with a
 * stride of 8, one vertex replaced by a sparse accessor, no index
 * accessor (the corners in order); 32-bit integer positions refused. */
static void test_gltf_quantized_sparse(void **state)
{
    (void)state;
    const int16_t q[12] = {0, 0, 0, 0, 32767, 0, 0, 0, 0, 32767, 0, 0};
    const uint8_t sp_idx[1] = {2};
    const int16_t sp_val[3] = {-32767, 32767, 16384};
    size_t off[3];
    part parts[3] = {{q, sizeof q}, {sp_idx, 1}, {sp_val, 6}};
    tbuf bin = pack(parts, 3, off);
    tbuf body = {0};
    tbuf_printf(&body,
                "\"extensionsUsed\":[\"KHR_mesh_quantization\"],\"bufferViews\":[{\"buffer\":0,"
                "\"byteLength\":24,\"byteStride\":8},{\"buffer\":0,\"byteOffset\":%zu,"
                "\"byteLength\":1},{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":6}],",
                off[1], off[2]);
    tbuf_printf(&body, "\"accessors\":[{\"bufferView\":0,\"componentType\":5122,"
                       "\"normalized\":true,\"count\":3,\"type\":\"VEC3\",\"sparse\":{"
                       "\"count\":1,\"indices\":{\"bufferView\":1,\"componentType\":5121},"
                       "\"values\":{\"bufferView\":2}}}],");
    tbuf_printf(&body, "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                       "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]");
    for (int glb = 0; glb < 2; glb++) {
        tbuf f = make_file(body.p, &bin, glb);
        vx_mesh *m = must_read(&f, glb);
        assert_int_equal(m->ntris, 1);
        /* (0,0,0), (1,0,0) and the sparse (-1, 1, 16384/32767). */
        expect_box(m, (double[]){-1, 0, 0}, (double[]){1, 1, 16384 / 32767.0});
        vx_mesh_free(m);
        free(f.p);
    }
    free(body.p);
    free(bin.p);
    /* Positions of 32-bit integers, unsigned or signed: neither glTF nor
     * KHR_mesh_quantization has them (unsigned ones were read as
     * coordinates, a float's bits as an integer). */
    const uint32_t u[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    part upart = {u, sizeof u};
    bin = pack(&upart, 1, off);
    for (int ct = 5124; ct <= 5125; ct++) {
        body = (tbuf){0};
        tbuf_printf(&body,
                    "\"extensionsUsed\":[\"KHR_mesh_quantization\"],\"bufferViews\":[{"
                    "\"buffer\":0,\"byteLength\":36}],\"accessors\":[{\"bufferView\":0,"
                    "\"componentType\":%d,\"count\":3,\"type\":\"VEC3\"}],",
                    ct);
        tbuf_printf(&body, "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0}}]}],"
                           "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]");
        for (int glb = 0; glb < 2; glb++) {
            tbuf f = make_file(body.p, &bin, glb);
            expect_error(&f, glb, NULL, "gltf_corrupt", "accessor 0");
            free(f.p);
        }
        free(body.p);
    }
    free(bin.p);
}

/* An indexed primitive over a sparse accessor: only the vertices it
 * indexes are decoded, each sparse one found among the sparse indices
 * (1 and 3 replaced, 5 replaced but not used); sparse indices that do not
 * strictly increase are refused, as the spec requires. */
static void test_gltf_sparse_indexed(void **state)
{
    (void)state;
    const float base[18] = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0, 4, 0, 0, 5, 0, 0};
    const uint16_t tri[6] = {0, 1, 3, 1, 3, 4};
    const float sp_val[9] = {1, 5, 0, 3, 0, 7, 99, 99, 99};
    for (int bad = 0; bad < 2; bad++) {
        const uint8_t sp_idx[3] = {1, bad ? 1 : 3, 5};
        size_t off[4];
        part parts[4] = {{base, sizeof base}, {tri, sizeof tri}, {sp_idx, 3}, {sp_val, 36}};
        tbuf bin = pack(parts, 4, off);
        tbuf body = {0};
        tbuf_printf(&body,
                    "\"bufferViews\":[{\"buffer\":0,\"byteLength\":72},{\"buffer\":0,"
                    "\"byteOffset\":%zu,\"byteLength\":12},{\"buffer\":0,\"byteOffset\":%zu,"
                    "\"byteLength\":3},{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":36}],",
                    off[1], off[2], off[3]);
        tbuf_printf(&body,
                    "\"accessors\":[{\"bufferView\":0,\"componentType\":5126,"
                    "\"count\":6,\"type\":\"VEC3\",\"sparse\":{\"count\":3,\"indices\":{"
                    "\"bufferView\":2,\"componentType\":5121},\"values\":{\"bufferView\":3}}},"
                    "{\"bufferView\":1,\"componentType\":5123,\"count\":6,"
                    "\"type\":\"SCALAR\"}],");
        tbuf_printf(&body,
                    "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},"
                    "\"indices\":1}]}],\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]");
        for (int glb = 0; glb < 2; glb++) {
            tbuf f = make_file(body.p, &bin, glb);
            if (bad) {
                expect_error(&f, glb, NULL, "gltf_corrupt", "strictly increasing");
            } else {
                vx_mesh *m = must_read(&f, glb);
                assert_int_equal(m->ntris, 2);
                assert_int_equal(m->nverts, 4);
                /* (0,0,0), the sparse (1,5,0) and (3,0,7), and (4,0,0) */
                expect_box(m, (double[]){0, 0, 0}, (double[]){4, 5, 7});
                vx_mesh_free(m);
            }
            free(f.p);
        }
        free(body.p);
        free(bin.p);
    }
}

/* Images are not decoded and never opened: an external URI naming a
 * server file and an embedded one that is not an image leave the mesh
 * readable. */
static void test_gltf_images_ignored(void **state)
{
    (void)state;
    tbuf f = cube_file("\"images\":[{\"uri\":\"/etc/shadow\"},{\"uri\":\"data:image/png;base64,"
                       "AAAA\"}],\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]",
                       0);
    vx_mesh *m = must_read(&f, 0);
    assert_int_equal(m->ntris, 12);
    vx_mesh_free(m);
    free(f.p);
}

static void test_gltf_refusals(void **state)
{
    (void)state;
    const char *one = "\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]";
    /* An index past the 8 vertices (the index data is edited in place). */
    tbuf f = cube_file(one, 1);
    char *at = memmem(f.p, f.n, cube_idx, sizeof cube_idx);
    assert_non_null(at);
    uint16_t bad = 8;
    memcpy(at + 10, &bad, 2);
    expect_error(&f, 1, NULL, "gltf_corrupt", "uses vertex 8 of 8");
    free(f.p);
    /* A NaN coordinate. */
    f = cube_file(one, 1);
    at = memmem(f.p, f.n, cube_pos, sizeof cube_pos);
    float nan = NAN;
    memcpy(at + 12, &nan, 4);
    expect_error(&f, 1, NULL, "gltf_corrupt", "NaN");
    free(f.p);
    /* A scene of nodes without meshes, or a library of nodes without
     * meshes: no faces. */
    f = cube_file("\"nodes\":[{}]", 0);
    expect_error(&f, 0, NULL, "gltf_no_faces", NULL);
    free(f.p);
    f = cube_file("\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{}]", 0);
    expect_error(&f, 0, NULL, "gltf_no_faces", NULL);
    free(f.p);
    /* A scene index that names no scene is a broken reference (it was no
     * faces); a file without scenes naming scene 0 too. */
    for (int glb = 0; glb < 2; glb++) {
        f = cube_file("\"scene\":1,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]", glb);
        expect_error(&f, glb, NULL, "gltf_corrupt", "scene 1 does not exist (the file has 1)");
        free(f.p);
        f = cube_file("\"scene\":-7,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0}]", glb);
        expect_error(&f, glb, NULL, "gltf_corrupt", "scene -7 does not exist");
        free(f.p);
        f = cube_file("\"scene\":0,\"nodes\":[{\"mesh\":0}]", glb);
        expect_error(&f, glb, NULL, "gltf_corrupt", "scene 0 does not exist (the file has 0)");
        free(f.p);
    }
    /* Limits: 12 triangles against 11, 8 vertices against 7. */
    f = cube_file(one, 0);
    expect_error(&f, 0, &(vx_mesh_limits){.max_triangles = 11}, "mesh_too_big", "triangles");
    expect_error(&f, 0, &(vx_mesh_limits){.max_vertices = 7}, "mesh_too_big", "vertices");
    free(f.p);
    /* An external buffer is never opened. */
    const char *ext = "{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":12,\"uri\":"
                      "\"/etc/passwd\"}],\"scenes\":[{\"nodes\":[]}]}";
    tbuf e = {0};
    tbuf_put(&e, ext, strlen(ext));
    expect_error(&e, 0, NULL, "gltf_corrupt", "external file");
    free(e.p);
    /* Not JSON at all, and a truncated glb. */
    tbuf j = {0};
    tbuf_printf(&j, "{\"asset\":{\"version\":\"2.0\"},\"scenes\":[");
    expect_error(&j, 0, NULL, "gltf_corrupt", NULL);
    free(j.p);
    f = cube_file(one, 1);
    f.n -= 5;
    expect_error(&f, 1, NULL, "gltf_corrupt", NULL);
    free(f.p);
}

/* 600 primitives, each a triangle of 3 of the 20000 vertices of one shared
 * POSITION accessor, each in its own node: the mesh keeps the 1800
 * vertices the indices name (its box is theirs, not the accessor's), and a
 * limit of 100000 vertices holds it (counted per instance over the whole
 * accessor it would be 12 million). */
static void test_gltf_shared_accessor(void **state)
{
    (void)state;
    enum { NV = 20000, NP = 600 };
    float *pos = malloc(sizeof(float) * 3 * NV);
    uint32_t *idx = malloc(sizeof(uint32_t) * 3 * NP);
    assert_non_null(pos);
    assert_non_null(idx);
    for (int v = 0; v < NV; v++)
        pos[3 * v] = (float)v, pos[3 * v + 1] = (float)(v % 5), pos[3 * v + 2] = (float)-v;
    for (int j = 0; j < NP; j++)
        for (int c = 0; c < 3; c++)
            idx[3 * j + c] = (uint32_t)(30 * j + c);
    size_t off[2];
    part parts[2] = {{pos, sizeof(float) * 3 * NV}, {idx, sizeof(uint32_t) * 3 * NP}};
    tbuf bin = pack(parts, 2, off);
    tbuf body = {0};
    tbuf_printf(&body,
                "\"bufferViews\":[{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu},"
                "{\"buffer\":0,\"byteOffset\":%zu,\"byteLength\":%zu}],\"accessors\":["
                "{\"bufferView\":0,\"componentType\":5126,\"count\":%d,\"type\":\"VEC3\"}",
                off[0], parts[0].bytes, off[1], parts[1].bytes, NV);
    for (int j = 0; j < NP; j++)
        tbuf_printf(&body,
                    ",{\"bufferView\":1,\"byteOffset\":%d,\"componentType\":5125,\"count\":3,"
                    "\"type\":\"SCALAR\"}",
                    12 * j);
    tbuf_printf(&body, "],\"meshes\":[");
    for (int j = 0; j < NP; j++)
        tbuf_printf(&body, "%s{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":%d}]}",
                    j ? "," : "", j + 1);
    tbuf_printf(&body, "],\"nodes\":[");
    for (int j = 0; j < NP; j++)
        tbuf_printf(&body, "%s{\"mesh\":%d}", j ? "," : "", j);
    tbuf_printf(&body, "],\"scenes\":[{\"nodes\":[");
    for (int j = 0; j < NP; j++)
        tbuf_printf(&body, "%s%d", j ? "," : "", j);
    tbuf_printf(&body, "]}]");
    for (int glb = 0; glb < 2; glb++) {
        tbuf f = make_file(body.p, &bin, glb);
        vx_err err;
        vx_mesh *m = read_file(&f, glb, &(vx_mesh_limits){.max_vertices = 100000}, &err);
        if (!m) fail_msg("%s: %s", err.code, err.message);
        assert_int_equal(m->ntris, NP);
        assert_int_equal(m->nverts, 3 * NP);
        const double last = 30.0 * (NP - 1) + 2;
        expect_box(m, (double[]){0, 0, -last}, (double[]){last, 2, 0});
        vx_mesh_free(m);
        free(f.p);
    }
    free(body.p);
    free(bin.p);
    free(pos);
    free(idx);
}

/* Random byte changes, insertions and truncations of good files: each
 * either fails with a reader error or reads a mesh whose every index is
 * in range (the sanitized build checks the memory on the way). */
static void test_gltf_mutations(void **state)
{
    (void)state;
    tbuf good[2] = {cube_file("\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0,"
                              "\"children\":[1]},{\"mesh\":0,\"translation\":[2,0,0]}]",
                              0),
                    cube_file("\"scene\":0,\"scenes\":[{\"nodes\":[0]}],\"nodes\":[{\"mesh\":0,"
                              "\"rotation\":[0,0.6,0,0.8]}]",
                              1)};
    int accepted = 0, rejected = 0;
    for (int it = 0; it < 4000; it++) {
        int glb = it % 2;
        const tbuf *g = &good[glb];
        tbuf f = {0};
        tbuf_put(&f, g->p, g->n);
        int edits = 1 + (int)(test_rand(&rnd_state) % 4);
        for (int e = 0; e < edits; e++) {
            size_t at = (size_t)(test_rand(&rnd_state) % f.n);
            switch (test_rand(&rnd_state) % 4) {
            case 0:
                f.p[at] = (char)test_rand(&rnd_state);
                break;
            case 1:
                f.p[at] = "0123456789[]{}\",:-e."[test_rand(&rnd_state) % 20];
                break;
            case 2:
                f.n = at + 1;
                break;
            default:
                f.p[at] ^= (char)(1 << (test_rand(&rnd_state) % 8));
            }
        }
        vx_err err;
        vx_mesh *m = read_file(&f, glb, &(vx_mesh_limits){.max_triangles = 1000}, &err);
        if (m) {
            accepted++;
            assert_true(m->ntris > 0 && m->ntris <= 1000);
            for (size_t t = 0; t < 3 * m->ntris; t++)
                assert_true(m->tri[t] < m->nverts);
            vx_mesh_free(m);
        } else {
            rejected++;
            assert_true(err.kind == VX_EINVAL || err.kind == VX_EUNPROC || err.kind == VX_ETOOBIG);
            assert_true(err.code[0] && err.message[0]);
        }
        free(f.p);
    }
    print_message("mutated glTF files: %d rejected, %d accepted\n", rejected, accepted);
    assert_true(accepted > 0 && rejected > 0);
    free(good[0].p);
    free(good[1].p);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_gltf_cube),
        cmocka_unit_test(test_gltf_no_scenes),
        cmocka_unit_test(test_gltf_transforms),
        cmocka_unit_test(test_gltf_strip_fan),
        cmocka_unit_test(test_gltf_quantized_sparse),
        cmocka_unit_test(test_gltf_sparse_indexed),
        cmocka_unit_test(test_gltf_images_ignored),
        cmocka_unit_test(test_gltf_refusals),
        cmocka_unit_test(test_gltf_mutations),
        cmocka_unit_test(test_gltf_shared_accessor),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
