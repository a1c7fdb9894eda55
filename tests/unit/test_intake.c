/* Mesh intake (src/mesh/intake.c): the format table both ways, declared
 * media types, declared against sniffed types, the degenerate-mesh rule
 * and the Mesh JSON. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <math.h>
#include <setjmp.h>
#include <cmocka.h>

#include <stdlib.h>
#include <string.h>

#include "mesh/intake.h"

static const unsigned char OBJ_HEAD[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
static const unsigned char BPT_HEAD[] = "1\n1,2,3,4\n";
static const unsigned char DRACO_HEAD[] = "DRACO\x02\x02\x01\x01";
static const unsigned char JUNK_HEAD[] = "\x89PNG\r\n\x1a\n";

static void test_format_table(void **state)
{
    (void)state;
    const vx_mesh_format all[] = {VX_MESH_OBJ, VX_MESH_DRACO, VX_MESH_BPT, VX_MESH_STL,
                                  VX_MESH_PLY, VX_MESH_GLTF,  VX_MESH_GLB, VX_MESH_OFF};
    const char *names[] = {"obj", "draco", "bpt", "stl", "ply", "gltf", "glb", "off"};
    const char *exts[] = {"obj", "drc", "bpt", "stl", "ply", "gltf", "glb", "off"};
    for (int i = 0; i < 8; i++) {
        assert_string_equal(vx_intake_format_name(all[i]), names[i]);
        assert_string_equal(vx_intake_format_ext(all[i]), exts[i]);
        /* Both directions agree: name -> format -> name, name -> extension. */
        assert_int_equal(vx_intake_format_by_name(names[i]), all[i]);
        assert_string_equal(vx_intake_ext_of_name(names[i]), exts[i]);
    }
    /* Metadata naming no known format is stored as OBJ (the store's rule). */
    assert_int_equal(vx_intake_format_by_name("fbx"), 0);
    assert_int_equal(vx_intake_format_by_name("drc"), 0);
    assert_int_equal(vx_intake_format_by_name(NULL), 0);
    assert_string_equal(vx_intake_ext_of_name("fbx"), "obj");
    assert_string_equal(vx_intake_format_media(VX_MESH_GLB), "model/gltf-binary");
    assert_string_equal(vx_intake_format_name(0), "obj");
}

static void test_media_types(void **state)
{
    (void)state;
    static const struct {
        const char *mt;
        vx_intake_media m;
    } ok[] = {
        {"model/obj", VX_INTAKE_OBJ},
        {"text/plain", VX_INTAKE_TEXT},
        {"model/x-bpt", VX_INTAKE_BPT},
        {"model/x-draco", VX_INTAKE_DRACO},
        {"application/x-draco", VX_INTAKE_DRACO},
        {"", VX_INTAKE_SNIFF},
        {"application/octet-stream", VX_INTAKE_SNIFF},
        {"application/x-www-form-urlencoded", VX_INTAKE_SNIFF},
        {"model/stl", VX_INTAKE_STL},
        {"model/x-ply", VX_INTAKE_PLY},
        {"application/ply", VX_INTAKE_PLY},
        {"model/gltf+json", VX_INTAKE_GLTF},
        {"model/gltf-binary", VX_INTAKE_GLB},
        {"model/x-off", VX_INTAKE_OFF},
    };
    for (size_t i = 0; i < sizeof ok / sizeof ok[0]; i++) {
        vx_intake_media m = (vx_intake_media)-1;
        vx_err err;
        assert_int_equal(vx_intake_media_of(ok[i].mt, &m, &err), 0);
        assert_int_equal(m, ok[i].m);
    }
    vx_err err;
    vx_intake_media m;
    assert_int_equal(vx_intake_media_of("image/png", &m, &err), -1);
    assert_int_equal(err.kind, VX_EMEDIA);
    assert_string_equal(err.code, "unsupported_media_type");
    assert_string_equal(err.message, "cannot take 'image/png': send model/obj, model/stl, "
                                     "model/x-ply, model/gltf+json, model/gltf-binary, "
                                     "model/x-off, model/x-bpt, model/x-draco or "
                                     "application/octet-stream");
    /* The quoted type is cut at 100 bytes. */
    char big[300];
    memset(big, 'a', sizeof big - 1);
    big[sizeof big - 1] = 0;
    assert_int_equal(vx_intake_media_of(big, &m, &err), -1);
    assert_non_null(strstr(err.message, "'aaaa"));
    assert_true(strlen(err.message) < 300);
    /* Matching is exact: callers lower-case and drop parameters first. */
    assert_int_equal(vx_intake_media_of("Model/OBJ", &m, &err), -1);
}

/* Resolves head (n bytes) declared as d: the format, or 0 with the error. */
static vx_mesh_format resolve(vx_intake_media d, const unsigned char *head, size_t n, vx_err *err)
{
    vx_mesh_format f = (vx_mesh_format)-1;
    vx_err_clear(err);
    if (vx_intake_resolve(d, head, n, n, &f, err)) {
        assert_int_equal(err->kind, VX_EMEDIA);
        assert_string_equal(err->code, "unsupported_media_type");
        return 0;
    }
    return f;
}

#define HEAD(x) (const unsigned char *)(x), sizeof(x) - 1

static void test_resolve(void **state)
{
    (void)state;
    vx_err e;
    /* Told by content. */
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD(OBJ_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD(BPT_HEAD), &e), VX_MESH_BPT);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD(DRACO_HEAD), &e), VX_MESH_DRACO);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD(JUNK_HEAD), &e), 0);
    assert_string_equal(e.message, "the body is no mesh format that voxeld reads (OBJ, STL, PLY, "
                                   "glTF, glb, OFF, Draco, .bpt)");
    /* model/obj is OBJ whatever the text (a bad one fails in the parser). */
    assert_int_equal(resolve(VX_INTAKE_OBJ, HEAD(OBJ_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_OBJ, HEAD(BPT_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_OBJ, HEAD(JUNK_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_OBJ, HEAD(DRACO_HEAD), &e), 0);
    assert_string_equal(e.message,
                        "Content-Type says text (OBJ or .bpt) but the body is a Draco file");
    /* text/plain is .bpt when it sniffs so, else OBJ. */
    assert_int_equal(resolve(VX_INTAKE_TEXT, HEAD(OBJ_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_TEXT, HEAD(BPT_HEAD), &e), VX_MESH_BPT);
    assert_int_equal(resolve(VX_INTAKE_TEXT, HEAD(JUNK_HEAD), &e), VX_MESH_OBJ);
    assert_int_equal(resolve(VX_INTAKE_TEXT, HEAD(DRACO_HEAD), &e), 0);
    /* The Draco and .bpt types must match the bytes. */
    assert_int_equal(resolve(VX_INTAKE_DRACO, HEAD(DRACO_HEAD), &e), VX_MESH_DRACO);
    assert_int_equal(resolve(VX_INTAKE_DRACO, HEAD(OBJ_HEAD), &e), 0);
    assert_string_equal(e.message,
                        "Content-Type says Draco but the body does not start with DRACO");
    assert_int_equal(resolve(VX_INTAKE_BPT, HEAD(BPT_HEAD), &e), VX_MESH_BPT);
    assert_int_equal(resolve(VX_INTAKE_BPT, HEAD(OBJ_HEAD), &e), 0);
    assert_string_equal(e.message,
                        "Content-Type says .bpt but the first line is not a patch count");
    assert_int_equal(resolve(VX_INTAKE_BPT, HEAD(DRACO_HEAD), &e), 0);
    /* The new formats, told by content... */
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("ply\nformat ascii 1.0\n"), &e), VX_MESH_PLY);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("glTF\x02\0\0\0\x10\0\0\0"), &e), VX_MESH_GLB);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD(" {\"asset\":{}}"), &e), VX_MESH_GLTF);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("{\r\n  \"asset\""), &e), VX_MESH_GLTF);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("{"), &e), VX_MESH_GLTF); /* cut */
    /* ...but not binary bytes that start with a brace */
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("{\x93\x07\"\xfe"), &e), 0);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("{\"a\x01\x02"), &e), 0);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("OFF\n3 1 0\n"), &e), VX_MESH_OFF);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("solid x\n facet normal 0 0 1\n"), &e),
                     VX_MESH_STL);
    /* ...a binary STL by its count and size, "solid" header or not... */
    unsigned char stl[134] = "solid but binary";
    stl[80] = 1;
    vx_mesh_format f = 0;
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, sizeof stl, 134, &f, &e), 0);
    assert_int_equal(f, VX_MESH_STL);
    memcpy(stl, "\x01\x02", 2);
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, sizeof stl, 134, &f, &e), 0);
    assert_int_equal(f, VX_MESH_STL);
    /* bytes after the last triangle (the reader ignores them), up to 511
     * of them by content alone (other binary files hold small numbers at
     * offset 80 too); too few is no STL */
    f = 0;
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, sizeof stl, 184, &f, &e), 0);
    assert_int_equal(f, VX_MESH_STL);
    f = 0;
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, sizeof stl, 134 + 511, &f, &e), 0);
    assert_int_equal(f, VX_MESH_STL);
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, sizeof stl, 134 + 512, &f, &e), -1);
    assert_int_equal(resolve(VX_INTAKE_STL, stl, sizeof stl, &e), VX_MESH_STL);
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, stl, 100, 133, &f, &e), -1);
    /* an ASCII STL whose solid name runs past the sniffed bytes */
    char longname[512];
    memset(longname, 'x', sizeof longname);
    memcpy(longname, "solid ", 6);
    f = 0;
    assert_int_equal(vx_intake_resolve(VX_INTAKE_SNIFF, (const unsigned char *)longname,
                                       sizeof longname, 4096, &f, &e),
                     0);
    assert_int_equal(f, VX_MESH_STL);
    /* OFF with the first count glued to the word, as ModelNet writes it */
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("OFF3 1 0\n"), &e), VX_MESH_OFF);
    assert_int_equal(resolve(VX_INTAKE_SNIFF, HEAD("COFF12 1 0\n"), &e), VX_MESH_OFF);
    /* ...and by Content-Type: trusted unless the bytes are another format. */
    assert_int_equal(resolve(VX_INTAKE_STL, HEAD(JUNK_HEAD), &e), VX_MESH_STL);
    assert_int_equal(resolve(VX_INTAKE_PLY, HEAD(OBJ_HEAD), &e), VX_MESH_PLY);
    assert_int_equal(resolve(VX_INTAKE_GLTF, HEAD("glTF\x02\0\0\0\x10\0\0\0"), &e), VX_MESH_GLTF);
    assert_int_equal(resolve(VX_INTAKE_STL, HEAD(DRACO_HEAD), &e), 0);
    assert_string_equal(e.message, "Content-Type says STL but the body is a Draco file");
    assert_int_equal(resolve(VX_INTAKE_OFF, HEAD("ply\nformat ascii 1.0\n"), &e), 0);
    assert_string_equal(e.message, "Content-Type says OFF but the body is a PLY file");
    /* text/plain holding an ASCII STL is an STL. */
    assert_int_equal(resolve(VX_INTAKE_TEXT, HEAD("solid x\n facet normal 0 0 1\n"), &e),
                     VX_MESH_STL);
}

static void test_check_and_meta(void **state)
{
    (void)state;
    vx_mesh m;
    memset(&m, 0, sizeof m);
    double pos[12] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    m.pos = pos;
    m.nverts = 4;
    m.ntris = 2;
    m.nfaces = 1;
    m.faces_by_size[1] = 1;
    m.degenerate_tris = 1;
    m.bbox_max[0] = m.bbox_max[1] = 1;
    vx_err err;
    vx_err_clear(&err);
    assert_int_equal(vx_intake_check(&m, &err), 0);
    m.degenerate_tris = 2;
    assert_int_equal(vx_intake_check(&m, &err), -1);
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "degenerate_mesh");
    assert_string_equal(err.message, "every triangle of the mesh has zero area");
    /* every vertex is in the 32-bit range, used by a face or not */
    pos[7] = -2e30;
    assert_int_equal(vx_intake_check(&m, &err), -1);
    assert_string_equal(err.code, "coordinate_out_of_range");
    assert_non_null(strstr(err.message, "vertex 2 reaches -2e+30 along axis 1"));
    pos[7] = NAN;
    assert_int_equal(vx_intake_check(&m, &err), -1);
    assert_string_equal(err.code, "coordinate_out_of_range");
    pos[7] = 1;

    cJSON *o = vx_intake_meta("ab", VX_MESH_DRACO, 123, &m);
    assert_non_null(o);
    char *text = cJSON_PrintUnformatted(o);
    /* Everything but the creation time, in the order the API documents. */
    const char *want = "{\"id\":\"ab\",\"format\":\"draco\",\"bytes\":123,\"vertices\":4,"
                       "\"triangles\":2,\"faces\":{\"total\":1,\"triangles\":0,\"quads\":1,"
                       "\"ngons\":0},\"bbox\":{\"min\":[0,0,0],\"max\":[1,1,0]},"
                       "\"boundary_edges\":0,\"boundary_edges_welded\":0,\"nonmanifold_edges\":0,"
                       "\"misoriented_edges\":0,"
                       "\"degenerate_triangles\":2,"
                       "\"texcoords\":0,\"normals\":0,\"patches\":0,\"created\":\"";
    assert_memory_equal(text, want, strlen(want));
    const cJSON *created = cJSON_GetObjectItemCaseSensitive(o, "created");
    assert_true(cJSON_IsString(created));
    assert_int_equal(strlen(created->valuestring), 24); /* 2026-01-01T00:00:00.000Z */
    free(text);
    cJSON_Delete(o);
}

/* glTF indices a file may hold but no array has: named in the message
 * (fuzz_gltf found the huge ones cast to int, undefined behaviour that
 * UBSan reports in the sanitized build of this test). */
static void test_gltf_huge_indices(void **state)
{
    (void)state;
    static const struct {
        const char *json, *message;
    } cases[] = {
        {"{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[900000000000]}],"
         "\"nodes\":[{}]}",
         "node 900000000000 does not exist"},
        {"{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[0]}],"
         "\"nodes\":[{\"mesh\":4000000000}]}",
         "node mesh 4000000000 names no mesh"},
        {"{\"asset\":{\"version\":\"2.0\"},\"scenes\":[{\"nodes\":[0]}],"
         "\"nodes\":[{\"children\":[1e300]}]}",
         "node 1e+300 does not exist"},
        {"{\"asset\":{\"version\":\"2.0\"},\"buffers\":[{\"byteLength\":4,\"uri\":"
         "\"data:application/octet-stream;base64,AAAAAA==\"}],\"bufferViews\":[{\"buffer\":0,"
         "\"byteLength\":4}],\"accessors\":[{\"bufferView\":0,\"componentType\":"
         "9000000000000000,\"count\":1,\"type\":\"SCALAR\"}]}",
         "accessor 0 is malformed"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        vx_mesh_declared d;
        vx_err err;
        vx_err_clear(&err);
        size_t n = strlen(cases[i].json);
        assert_int_equal(vx_declared_check(VX_MESH_GLTF, (const unsigned char *)cases[i].json, n, n,
                                           NULL, &d, &err),
                         -1);
        assert_string_equal(err.code, "gltf_corrupt");
        if (!strstr(err.message, cases[i].message))
            fail_msg("case %zu: \"%s\" lacks \"%s\"", i, err.message, cases[i].message);
    }
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_format_table),      cmocka_unit_test(test_media_types),
        cmocka_unit_test(test_resolve),           cmocka_unit_test(test_check_and_meta),
        cmocka_unit_test(test_gltf_huge_indices),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
