/* Hostile mesh files (issue #10, defects 2 and 8): declared counts that
 * libdraco or the .bpt reader would have allocated for before reading any
 * data. Each reproducer must fail with its error code, and the process's
 * peak memory must stay within 100 MB of where it was (the reproducers made
 * 240 MB to 96 GB before the fix). The hostile cases run first, in a fresh
 * process, so that the peak (ru_maxrss) is theirs. The Draco reproducers
 * are checked in under tests/fuzz/corpus/fuzz_draco/ (repro-*.drc) beside
 * the real encodings, which must still decode. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "mesh/mesh.h"

#define BOUND_MB 100

static char corpus[1024];

static long peak_mb(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_maxrss / 1024;
}

static long base_mb;

static void check_bounded(const char *what)
{
    long grew = peak_mb() - base_mb;
    if (grew >= BOUND_MB) print_error("%s: peak memory grew by %ld MB\n", what, grew);
    assert_true(grew < BOUND_MB);
}

static const char *corpus_file(const char *name)
{
    static char path[2048];
    snprintf(path, sizeof path, "%s/%s", corpus, name);
    return path;
}

static void expect_draco(const char *name, const vx_mesh_limits *lim, vx_err_kind kind,
                         const char *code)
{
    vx_err err = {0};
    vx_mesh *m = vx_mesh_read_path(corpus_file(name), lim, &err);
    if (m) print_error("%s: accepted\n", name);
    assert_null(m);
    if (strcmp(err.code, code)) print_error("%s: %s (%s)\n", name, err.code, err.message);
    assert_string_equal(err.code, code);
    assert_int_equal(err.kind, kind);
    check_bounded(name);
}

static void test_draco_reproducers(void **state)
{
    (void)state;
    /* 2.2 edgebreaker, 10^8 faces (and symbols) in 53 bytes: 2.3 GB before */
    expect_draco("repro-eb-faces-1e8.drc", NULL, VX_EINVAL, "draco_corrupt");
    /* 2.2 valence edgebreaker, 10^7 faces in 55 bytes: 240 MB before */
    expect_draco("repro-valence-faces-1e7.drc", NULL, VX_EINVAL, "draco_corrupt");
    /* 1.2 bitstream (uint32 counts), 10^8 faces in 45 bytes: 2.3 GB before */
    expect_draco("repro-v12-faces-1e8.drc", NULL, VX_EINVAL, "draco_corrupt");
    /* sequential, 2^32-1 points for 4 faces */
    expect_draco("repro-seq-points-4e9.drc", NULL, VX_EINVAL, "draco_corrupt");
    /* metadata whose entry claims 4 GB */
    expect_draco("repro-metadata-4g.drc", NULL, VX_EINVAL, "draco_corrupt");
    /* found by fuzz_draco: a texture-coordinate predictor's orientation
     * count deep in the data (2^31 bits, then a loop of as many steps): 27 s
     * and 200 MB before the decode was held to vx_draco_decode_bound */
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    expect_draco("repro-texcoord-orientations.drc", NULL, VX_EINVAL, "draco_corrupt");
    clock_gettime(CLOCK_MONOTONIC, &t1);
    double secs = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
    if (secs > 2) print_error("texcoord reproducer took %.1f s\n", secs);
    assert_true(secs < 2);
    /* found by fuzz_draco: a POSITION attribute of bools (reading its bytes
     * as bool was undefined behaviour) */
    expect_draco("repro-bool-positions.drc", NULL, VX_EUNPROC, "draco_no_positions");
    /* with the daemon's limit too: the impossible count is named first */
    vx_mesh_limits lim = {.max_triangles = 20000000};
    expect_draco("repro-eb-faces-1e8.drc", &lim, VX_EINVAL, "draco_corrupt");
    /* a real file over the limit is refused from its header */
    lim.max_triangles = 3;
    expect_draco("tet.cl7.drc", &lim, VX_ETOOBIG, "mesh_too_big");
    expect_draco("tet.cl0.drc", &lim, VX_ETOOBIG, "mesh_too_big");
}

/* A header with the given version, method and 8 bytes of counts after it. */
static size_t header(unsigned char *b, int major, int minor, int type, int method)
{
    memcpy(b, "DRACO", 5);
    b[5] = (unsigned char)major;
    b[6] = (unsigned char)minor;
    b[7] = (unsigned char)type;
    b[8] = (unsigned char)method;
    b[9] = b[10] = 0;
    memset(b + 11, 0, 32);
    return 43;
}

static void test_draco_header(void **state)
{
    (void)state;
    unsigned char b[64];
    vx_draco_header h;
    vx_err err = {0};
    size_t n = header(b, 3, 0, 1, 1);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    assert_string_equal(err.code, "draco_corrupt");
    assert_non_null(strstr(err.message, "version 3.0"));
    n = header(b, 2, 3, 1, 1);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    n = header(b, 2, 2, 1, 2);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    assert_non_null(strstr(err.message, "method 2"));
    n = header(b, 2, 2, 0, 0);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    assert_string_equal(err.code, "draco_point_cloud");
    assert_int_equal(err.kind, VX_EUNPROC);
    n = header(b, 2, 2, 1, 1);
    b[11] = 3; /* no such traversal */
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    assert_non_null(strstr(err.message, "traversal 3"));
    /* a varint longer than five bytes */
    b[11] = 0;
    memset(b + 12, 0xff, 8);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), -1);
    /* a window that ends inside the counts asks for more */
    n = header(b, 2, 2, 1, 1);
    assert_int_equal(vx_draco_check_header(b, 13, 1000, NULL, &h, &err), 1);
    assert_int_equal(vx_draco_check_header(b, 13, 13, NULL, &h, &err), -1);
    assert_string_equal(err.code, "draco_corrupt");
    /* 1.2: uint32 counts, read as such: 10 faces, 10 symbols fit */
    n = header(b, 1, 2, 1, 1);
    uint32_t c[] = {3, 6, 10};
    memcpy(b + 12, c, sizeof c);
    b[24] = 0;
    memcpy(b + 25, &c[2], 4);
    memset(b + 29, 0, 4);
    assert_int_equal(vx_draco_check_header(b, n, n, NULL, &h, &err), 0);
    assert_int_equal(h.faces, 10);
    assert_int_equal(h.points, 6);
    assert_int_equal(h.extra_points, 3);
}

/* Every real encoding in the corpus still decodes: both methods, the
 * standard and valence traversals, compression levels 0 to 10, metadata. */
static void test_draco_real_files(void **state)
{
    (void)state;
    DIR *d = opendir(corpus);
    assert_non_null(d);
    struct dirent *e;
    int n = 0;
    while ((e = readdir(d))) {
        size_t len = strlen(e->d_name);
        if (len < 4 || strcmp(e->d_name + len - 4, ".drc") || !strncmp(e->d_name, "repro-", 6))
            continue;
        vx_err err = {0};
        vx_mesh *m = vx_mesh_read_path(corpus_file(e->d_name), NULL, &err);
        if (!m) print_error("%s: %s (%s)\n", e->d_name, err.code, err.message);
        assert_non_null(m);
        assert_true(m->ntris > 0);
        vx_mesh_free(m);
        n++;
    }
    closedir(d);
    assert_true(n >= 6);
}

static vx_mesh *read_text(const char *text, int as_file, vx_err *err)
{
    FILE *f = as_file ? tmpfile() : fmemopen((void *)text, strlen(text), "rb");
    assert_non_null(f);
    if (as_file) {
        fputs(text, f);
        rewind(f);
    }
    vx_mesh *m = vx_bpt_read_file(f, NULL, err);
    fclose(f);
    return m;
}

static const char patch[] = "1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n";

static void expect_bpt(const char *text, const char *code, const char *what)
{
    /* from a file (the size is known) and from a stream (it is not) */
    for (int as_file = 1; as_file >= 0; as_file--) {
        vx_err err = {0};
        vx_mesh *m = read_text(text, as_file, &err);
        if (m) print_error("%s: accepted\n", what);
        assert_null(m);
        if (strcmp(err.code, code)) print_error("%s: %s (%s)\n", what, err.code, err.message);
        assert_string_equal(err.code, code);
        check_bounded(what);
    }
}

static void test_bpt_reproducers(void **state)
{
    (void)state;
    char text[4096];
    /* defect 8: 4294967294 points declared, one given: 96 GB before */
    snprintf(text, sizeof text, "1\n%s4294967294\n0,0,0\n", patch);
    expect_bpt(text, "bpt_truncated", "bpt 4294967294 points");
    /* the largest patch count the uint32 offsets allow, without limits */
    snprintf(text, sizeof text, "4194303\n%s%s", patch, patch);
    expect_bpt(text, "bpt_truncated", "bpt 4194303 patches");
    /* counts that fit but points that do not follow */
    snprintf(text, sizeof text, "1\n%s300000000\n", patch);
    expect_bpt(text, "bpt_truncated", "bpt 3e8 points, none given");
}

static void test_obj_hostile(void **state)
{
    (void)state;
    /* OBJ declares no counts; huge indices are range errors, not sizes */
    const char *cases[][2] = {
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4294967296000\n", "obj_index"},
        {"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 -99999999999999\n", "obj_index"},
        {"v 0 0 0\nvt 0 0\nf 1/99999999999 1/1 1/1\n", "obj_index"},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        FILE *f = fmemopen((void *)cases[i][0], strlen(cases[i][0]), "rb");
        vx_err err = {0};
        vx_mesh *m = vx_obj_read_file(f, NULL, &err);
        fclose(f);
        assert_null(m);
        assert_string_equal(err.code, cases[i][1]);
        check_bounded(cases[i][0]);
    }
}

/* OFF (fuzz_off): the header's words split by \v or \f. The size check
 * took them as separators and the reader did not, so the reader found
 * other counts on the next line (6937544551 faces in a 4 KB file: 27 GB
 * of arrays). Now both read the header alike. */
static void test_off_header_blanks(void **state)
{
    (void)state;
    vx_err err = {0};
    const char *ok = "OFF\v3\f1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    vx_mesh *m = vx_off_read_mem((const unsigned char *)ok, strlen(ok), NULL, &err);
    if (!m) print_error("%s\n", err.message);
    assert_non_null(m);
    assert_int_equal(m->nverts, 3);
    assert_int_equal(m->ntris, 1);
    vx_mesh_free(m);
    static unsigned char repro[8192];
    FILE *f = fopen(VX_FUZZ_CORPUS "/fuzz_off/repro-vt-header.off", "rb");
    assert_non_null(f);
    size_t n = fread(repro, 1, sizeof repro, f);
    fclose(f);
    assert_null(vx_off_read_mem(repro, n, NULL, &err));
    assert_string_equal(err.code, "off_corrupt");
    /* 0 vertices and 1 face, as the size check read them */
    if (!strstr(err.message, "face index")) print_error("%s\n", err.message);
    assert_non_null(strstr(err.message, "face index"));
    check_bounded("off \\v header");
}

/* OFF's coordinates are decimal numbers, as OBJ's: strtod took hex
 * ("0x10" was 16); blanks and CR line ends around them still pass. */
static void test_off_numbers(void **state)
{
    (void)state;
    vx_err err = {0};
    const char *ok = "OFF\r\n3 1 0\r\n\t0 0 0 \r\n 1.5e0\t0 0 255 0 0\r\n0 1 0\r\n3 0 1 2\r\n";
    vx_mesh *m = vx_off_read_mem((const unsigned char *)ok, strlen(ok), NULL, &err);
    if (!m) print_error("%s\n", err.message);
    assert_non_null(m);
    assert_true(m->pos[3] == 1.5);
    vx_mesh_free(m);
    /* lone CR line ends (old Mac files), as OBJ takes them: the whole file
     * was one line, "a vertex line without three numbers" */
    const char *mac = "OFF\r3 1 0\r0 0 0\r1 0 0 # a comment\r0 1 0\r3 0 1 2\r";
    m = vx_off_read_mem((const unsigned char *)mac, strlen(mac), NULL, &err);
    if (!m) print_error("%s\n", err.message);
    assert_non_null(m);
    assert_int_equal(m->ntris, 1);
    assert_true(m->pos[3] == 1.0);
    vx_mesh_free(m);
    /* CRLF is one line end: a bad fourth line is line 4 */
    const char *crlf = "OFF\r\n3 1 0\r\n0 0 0\r\n1 0\r\n0 1 0\r\n3 0 1 2\r\n";
    assert_null(vx_off_read_mem((const unsigned char *)crlf, strlen(crlf), NULL, &err));
    assert_non_null(strstr(err.message, "line 4:"));
    static const char *const bad[] = {"OFF\n3 1 0\n0x10 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
                                      "OFF\n3 1 0\n0 0 0\n1 0 0x1p0\n0 1 0\n3 0 1 2\n",
                                      "OFF\n3 1 0\n0 0 0\n1,0 0 0\n0 1 0\n3 0 1 2\n"};
    for (size_t i = 0; i < sizeof bad / sizeof *bad; i++) {
        assert_null(vx_off_read_mem((const unsigned char *)bad[i], strlen(bad[i]), NULL, &err));
        assert_string_equal(err.code, "off_corrupt");
    }
}

int main(void)
{
    snprintf(corpus, sizeof corpus, "%s/fuzz_draco", VX_FUZZ_CORPUS);
    base_mb = peak_mb();
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_draco_reproducers), cmocka_unit_test(test_bpt_reproducers),
        cmocka_unit_test(test_obj_hostile),       cmocka_unit_test(test_draco_header),
        cmocka_unit_test(test_draco_real_files),  cmocka_unit_test(test_off_header_blanks),
        cmocka_unit_test(test_off_numbers),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
