/* OBJ reader: syntax coverage, every error code with its line number,
 * limits, sniffing, and the real meshes of VX_MESH_DIR. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <fcntl.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "mesh/mesh.h"

/* Reads an OBJ held in memory (n bytes, may contain NULs). */
static vx_mesh *read_mem(const char *text, size_t n, const vx_mesh_limits *lim, vx_err *err)
{
    /* fmemopen of 0 bytes is refused by some libcs: go through a file. */
    char path[] = "/tmp/vx_test_obj_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    assert_int_equal(write(fd, text, n), (ssize_t)n);
    close(fd);
    vx_mesh *m = vx_obj_read_path(path, lim, err);
    unlink(path);
    return m;
}

static vx_mesh *read_str(const char *text, vx_err *err)
{
    return read_mem(text, strlen(text), NULL, err);
}

/* Same through fmemopen and vx_obj_read_file. */
static vx_mesh *read_fmem(const char *text, vx_err *err)
{
    FILE *f = fmemopen((void *)text, strlen(text), "r");
    assert_non_null(f);
    vx_mesh *m = vx_obj_read_file(f, NULL, err);
    fclose(f);
    return m;
}

/* Asserts that text fails with the kind and code, and that the message
 * starts with "line <line>: " (line 0: no line prefix expected). */
static void expect_fail(const char *text, size_t n, vx_err_kind kind, const char *code, int line)
{
    vx_err err = {0};
    vx_mesh *m = read_mem(text, n, NULL, &err);
    if (m) print_error("accepted: %.60s\n", text);
    assert_null(m);
    if (strcmp(err.code, code) != 0 || err.kind != kind)
        print_error("text %.60s: got %s (%s) kind %d\n", text, err.code, err.message, err.kind);
    assert_string_equal(err.code, code);
    assert_int_equal(err.kind, kind);
    if (line > 0) {
        char prefix[32];
        snprintf(prefix, sizeof prefix, "line %d: ", line);
        if (strncmp(err.message, prefix, strlen(prefix)) != 0)
            print_error("message '%s' does not start with '%s'\n", err.message, prefix);
        assert_true(strncmp(err.message, prefix, strlen(prefix)) == 0);
    }
}

static void expect_fail_str(const char *text, const char *code, int line)
{
    expect_fail(text, strlen(text), VX_EINVAL, code, line);
}

static void assert_faces(const vx_mesh *m, const uint32_t *want, const uint32_t *sizes, size_t nf)
{
    assert_int_equal(m->nfaces, nf);
    size_t k = 0;
    for (size_t f = 0; f < nf; f++) {
        assert_int_equal(vx_mesh_face_size(m, f), sizes[f]);
        const uint32_t *v = vx_mesh_face(m, f);
        for (uint32_t i = 0; i < sizes[f]; i++)
            assert_int_equal(v[i], want[k++]);
    }
}

static const char *square =
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\n";

static void test_triangle(void **state)
{
    vx_err err = {0};
    vx_mesh *m = read_str("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", &err);
    assert_non_null(m);
    assert_int_equal(m->nverts, 3);
    assert_int_equal(m->nfaces, 1);
    assert_int_equal(m->ntris, 1);
    assert_null(m->face_start);
    assert_ptr_equal(m->tri, m->face_idx);
    assert_true(m->pos[3] == 1.0 && m->pos[7] == 1.0);
    assert_int_equal(m->boundary_edges, 3);
    assert_int_equal(m->faces_by_size[0], 1);
    vx_mesh_free(m);
}

/* Every index form, absolute and relative, names the same two triangles. */
static void test_index_forms(void **state)
{
    static const char *faces[] = {
        "f 1 2 3\nf 1 3 4\n",
        "f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n",
        "f 1//1 2//2 3//3\nf 1//1 3//3 4//4\n",
        "f 1/1/1 2/2/2 3/3/3\nf 1/1/1 3/3/3 4/4/4\n",
        "f -4 -3 -2\nf -4 -2 -1\n",
        "f -4/-4 -3/-3 -2/-2\nf -4/-4/-4 -2/-2/-2 -1/-1/-1\n",
        "f -4//-1 -3//-2 -2//-3\nf 1/-1 -2/2 4/1/-4\n",
        "f +1 +2 +3\nf\t1\t3\t4  \n",
        /* empty slots, as some exporters leave them (other readers take them) */
        "f 1/ 2/ 3/\nf 1// 3// 4//\n",
        "f 1/1/ 2/2/ 3/3/\nf 1//\t3/ 4//4\n",
    };
    static const uint32_t want[] = {0, 1, 2, 0, 2, 3}, sizes[] = {3, 3};
    for (size_t i = 0; i < sizeof faces / sizeof faces[0]; i++) {
        char text[1024];
        snprintf(text, sizeof text, "%s%s", square, faces[i]);
        vx_err err = {0};
        vx_mesh *m = read_str(text, &err);
        if (!m) print_error("form %zu: %s\n", i, err.message);
        assert_non_null(m);
        assert_faces(m, want, sizes, 2);
        assert_int_equal(m->ntexcoords, 4);
        assert_int_equal(m->nnormals, 4);
        assert_null(m->face_start);
        assert_int_equal(m->ntris, 2);
        vx_mesh_free(m);
    }
}

/* Relative indices count from the vertices read so far, not the file's. */
static void test_relative_interleaved(void **state)
{
    vx_err err = {0};
    vx_mesh *m = read_str("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n"
                          "v 0 0 1\nv 1 0 1\nv 0 1 1\nf -3 -2 -1\n",
                          &err);
    assert_non_null(m);
    static const uint32_t want[] = {0, 1, 2, 3, 4, 5}, sizes[] = {3, 3};
    assert_faces(m, want, sizes, 2);
    vx_mesh_free(m);
}

static void test_ngons(void **state)
{
    vx_err err = {0};
    /* A hexagon split into a triangle, a quad and ... as separate faces. */
    vx_mesh *m = read_str("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 0 1 0\nv 1 2 0\n"
                          "f 1 2 5 6\n"
                          "f 2 3 4 5\n"
                          "f 6 5 4 7 \n"
                          "f 1 2 3 4 5 6\n"
                          "f 1 2 3\n",
                          &err);
    assert_non_null(m);
    assert_non_null(m->face_start);
    static const uint32_t want[] = {0, 1, 4, 5, 1, 2, 3, 4, 5, 4, 3, 6, 0, 1, 2, 3, 4, 5, 0, 1, 2};
    static const uint32_t sizes[] = {4, 4, 4, 6, 3};
    assert_faces(m, want, sizes, 5);
    assert_int_equal(m->ntris, 2 + 2 + 2 + 4 + 1);
    assert_int_equal(m->faces_by_size[0], 1);
    assert_int_equal(m->faces_by_size[1], 3);
    assert_int_equal(m->faces_by_size[2], 1);
    assert_int_equal(m->face_start[5], 21);
    /* The fan of the hexagon: (0,1,2) (0,2,3) (0,3,4) (0,4,5) */
    const uint32_t *t = m->tri + 3 * 6;
    static const uint32_t fan[] = {0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5};
    for (int i = 0; i < 12; i++)
        assert_int_equal(t[i], fan[i]);
    vx_mesh_free(m);
}

/* Face f's triangles (m->tri from 3 t0) against the face: their areas,
 * each facing the face's way, add up to the face's own (a fan of a
 * concave face covers what lies outside it twice, and backwards). */
static void check_cover(const vx_mesh *m, size_t f, size_t t0)
{
    const uint32_t *v = vx_mesh_face(m, f);
    uint32_t n = vx_mesh_face_size(m, f);
    double N[3] = {0, 0, 0}; /* 2 x the vector area (Newell) */
    for (uint32_t i = 0; i < n; i++) {
        const double *a = m->pos + 3 * v[i], *b = m->pos + 3 * v[(i + 1) % n];
        N[0] += a[1] * b[2] - a[2] * b[1];
        N[1] += a[2] * b[0] - a[0] * b[2];
        N[2] += a[0] * b[1] - a[1] * b[0];
    }
    double area = sqrt(N[0] * N[0] + N[1] * N[1] + N[2] * N[2]), sum = 0;
    for (uint32_t k = 0; k + 2 < n; k++) {
        const uint32_t *t = m->tri + 3 * (t0 + k);
        const double *a = m->pos + 3 * t[0], *b = m->pos + 3 * t[1], *c = m->pos + 3 * t[2];
        double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]},
               w[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
        double x[3] = {u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2],
                       u[0] * w[1] - u[1] * w[0]};
        double along = (x[0] * N[0] + x[1] * N[1] + x[2] * N[2]) / area;
        if (along < -1e-9 * area) print_error("face %zu triangle %u faces backwards\n", f, k);
        assert_true(along >= -1e-9 * area);
        sum += sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2]);
        for (int i = 0; i < 3; i++) { /* a triangle of the face's own vertices */
            int found = 0;
            for (uint32_t j = 0; j < n; j++)
                found |= t[i] == v[j];
            assert_true(found);
        }
    }
    if (fabs(sum - area) > 1e-9 * area)
        print_error("face %zu (%u vertices): triangles cover %.17g, the face %.17g\n", f, n, sum,
                    area);
    assert_true(fabs(sum - area) <= 1e-9 * area);
}

/* Concave faces are ear-clipped in their plane, convex ones stay fans: an
 * L, a dart (a quad whose fan diagonal lies outside), and random
 * star-shaped faces of 4 to VX_MESH_EAR_MAX vertices in random planes. */
static void test_concave_faces(void **state)
{
    (void)state;
    vx_err err = {0};
    vx_mesh *m = read_str("v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\n"
                          "v 0 0 0\nv 1 3 0\nv 0 1 0\nv -1 3 0\n"
                          "f 3 4 5 6 1 2\n" /* the L: its fan would span the notch */
                          "f 8 9 10 7\n",   /* the dart from a wing tip: the same */
                          &err);
    assert_non_null(m);
    assert_int_equal(m->ntris, 4 + 2);
    check_cover(m, 0, 0);
    check_cover(m, 1, 4);
    vx_mesh_free(m);
    /* a square with a square hole, joined by a bridge of no width (its two
     * ends repeat positions), from every corner; and a spike of no width
     * into a square (a turn straight back is not convex) */
    static const double hole[10][2] = {{0, 0}, {4, 0}, {4, 4}, {0, 4}, {0, 0},
                                       {1, 1}, {1, 3}, {3, 3}, {3, 1}, {1, 1}};
    static const double spike[7][2] = {{0, 0}, {4, 0}, {4, 4}, {0, 4}, {0, 2}, {2, 2}, {0, 2}};
    char buf[1024];
    for (int s0 = 0; s0 < 11; s0++) {
        int n = s0 < 10 ? 10 : 7;
        const double(*p)[2] = s0 < 10 ? hole : spike;
        char *w = buf;
        for (int k = 0; k < n; k++)
            w += sprintf(w, "v %g %g 1\n", p[(k + s0) % n][0], p[(k + s0) % n][1]);
        w += sprintf(w, "f");
        for (int k = 1; k <= n; k++)
            w += sprintf(w, " %d", k);
        sprintf(w, "\n");
        m = read_str(buf, &err);
        assert_non_null(m);
        check_cover(m, 0, 0);
        vx_mesh_free(m);
    }
    /* a convex face keeps its fan, collinear vertices and all */
    m = read_str("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nf 1 2 3 4 5\n", &err);
    assert_non_null(m);
    static const uint32_t fan[] = {0, 1, 2, 0, 2, 3, 0, 3, 4};
    assert_memory_equal(m->tri, fan, sizeof fan);
    vx_mesh_free(m);

    srand48(11);
    char *text = malloc(200 * (VX_MESH_EAR_MAX + 2) + 64);
    int concave = 0;
    for (int trial = 0; trial < 300; trial++) {
        int n = 4 + (int)(drand48() * (VX_MESH_EAR_MAX - 3));
        /* a random plane: orthonormal e1, e2 from a random rotation */
        double a = drand48() * 2 * M_PI, b = acos(2 * drand48() - 1), c = drand48() * 2 * M_PI;
        double z[3] = {sin(b) * cos(a), sin(b) * sin(a), cos(b)};
        double h[3] = {fabs(z[0]) < 0.9 ? 1 : 0, fabs(z[0]) < 0.9 ? 0 : 1, 0};
        double e1[3] = {h[1] * z[2] - h[2] * z[1], h[2] * z[0] - h[0] * z[2],
                        h[0] * z[1] - h[1] * z[0]};
        double l = sqrt(e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]);
        for (int i = 0; i < 3; i++)
            e1[i] /= l;
        double e2[3] = {z[1] * e1[2] - z[2] * e1[1], z[2] * e1[0] - z[0] * e1[2],
                        z[0] * e1[1] - z[1] * e1[0]};
        char *p = text;
        int reflex = 0;
        double prev_r = 0;
        for (int i = 0; i < n; i++) {
            double t = 2 * M_PI * (i + 0.5 * drand48()) / n + c;
            double r = 0.2 + drand48();
            reflex |= i && fabs(r - prev_r) > 0.3;
            prev_r = r;
            double x = r * cos(t), y = r * sin(t);
            p += sprintf(p, "v %.17g %.17g %.17g\n", 5 + x * e1[0] + y * e2[0],
                         -3 + x * e1[1] + y * e2[1], 1 + x * e1[2] + y * e2[2]);
        }
        concave += reflex;
        p += sprintf(p, "f");
        for (int i = 0; i < n; i++)
            p += sprintf(p, " %d", trial % 2 ? n - i : i + 1); /* either way round */
        sprintf(p, "\n");
        m = read_str(text, &err);
        assert_non_null(m);
        assert_int_equal(m->ntris, (size_t)n - 2);
        check_cover(m, 0, 0);
        vx_mesh_free(m);
    }
    assert_true(concave > 200);
    free(text);
}

/* Triangles first, then a quad: the offsets of the earlier faces are
 * made up when face_start is created late. */
static void test_late_quad(void **state)
{
    vx_err err = {0};
    vx_mesh *m = read_str("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 2\n"
                          "f 1 2 3\nf 1 3 4\nf 2 3 5\nf 1 2 3 4\nf 3 4 5\n",
                          &err);
    assert_non_null(m);
    assert_non_null(m->face_start);
    static const uint32_t want[] = {0, 1, 2, 0, 2, 3, 1, 2, 4, 0, 1, 2, 3, 2, 3, 4};
    static const uint32_t sizes[] = {3, 3, 3, 4, 3};
    assert_faces(m, want, sizes, 5);
    assert_int_equal(m->ntris, 6);
    vx_mesh_free(m);
}

static const char *cube_v = "v -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\n"
                            "v -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n";
static const char *cube_f = "f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\n";
static const char *cube_lid = "f 4 1 5 8\n";

static void test_cube_closed_and_open(void **state)
{
    char text[1024];
    vx_err err = {0};
    snprintf(text, sizeof text, "%s%s%s", cube_v, cube_f, cube_lid);
    vx_mesh *m = read_str(text, &err);
    assert_non_null(m);
    assert_int_equal(m->nfaces, 6);
    assert_int_equal(m->faces_by_size[1], 6);
    assert_int_equal(m->ntris, 12);
    assert_int_equal(m->boundary_edges, 0);
    assert_int_equal(m->nonmanifold_edges, 0);
    assert_true(m->bbox_min[0] == -1 && m->bbox_max[2] == 1);
    vx_mesh_free(m);

    snprintf(text, sizeof text, "%s%s", cube_v, cube_f);
    m = read_str(text, &err);
    assert_non_null(m);
    assert_int_equal(m->nfaces, 5);
    assert_int_equal(m->boundary_edges, 4);
    assert_int_equal(m->boundary_edges_welded, 4);
    vx_mesh_free(m);
}

/* The OBJ text's boundary edges: as its indices say, and welded. */
static void expect_edges(const char *text, size_t boundary, size_t welded)
{
    vx_err err = {0};
    vx_mesh *m = read_str(text, &err);
    assert_non_null(m);
    assert_int_equal(m->boundary_edges, boundary);
    assert_int_equal(m->boundary_edges_welded, welded);
    vx_mesh_free(m);
}

/* The cube written face by face (24 vertices, none shared, as a glTF
 * with hard edges or an OBJ exported per face): every edge is a seam,
 * used once, and none is a hole once the vertices are welded by position.
 * Without its lid, the lid's 4 edges stay open; a sliver whose two
 * vertices weld into one has no edge there. */
static void test_split_vertices_weld(void **state)
{
    (void)state;
    static const int quad[6][4] = {{0, 3, 2, 1}, {4, 5, 6, 7}, {0, 1, 5, 4},
                                   {1, 2, 6, 5}, {2, 3, 7, 6}, {3, 0, 4, 7}};
    static const int c[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                                {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};
    for (int faces = 6; faces >= 5; faces--) {
        char text[2048];
        size_t n = 0;
        for (int f = 0; f < faces; f++)
            for (int k = 0; k < 4; k++) {
                const int *p = c[quad[f][k]];
                n += (size_t)snprintf(text + n, sizeof text - n, "v %d %d %d\n", p[0], p[1], p[2]);
            }
        for (int f = 0; f < faces; f++)
            n += (size_t)snprintf(text + n, sizeof text - n, "f %d %d %d %d\n", 4 * f + 1,
                                  4 * f + 2, 4 * f + 3, 4 * f + 4);
        vx_err err = {0};
        vx_mesh *m = read_str(text, &err);
        assert_non_null(m);
        assert_int_equal(m->nverts, 4 * (size_t)faces);
        assert_int_equal(m->boundary_edges, 4 * (size_t)faces);
        assert_int_equal(m->boundary_edges_welded, faces == 6 ? 0 : 4);
        assert_int_equal(m->nonmanifold_edges, 0);
        vx_mesh_free(m);
    }
    /* the closed cube with a ninth vertex -0 -0 -0 where vertex 1 (0 0 0)
     * is, used by one face: one place, closed once welded (the weld once
     * compared the bits: 4 open edges and a default `winding`) */
    expect_edges("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\n"
                 "v 1 1 1\nv 0 1 1\nv -0 -0 -0\n"
                 "f 9 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n",
                 4, 0);
    /* two triangles on one edge, plus a sliver 4 5 6 whose vertices 5 and
     * 6 sit at one place: welded, its edge 5-6 is no edge, 4-5 and 6-4 are
     * one edge used twice, and the pair's outline stays open (4 edges) */
    expect_edges("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 0\nv 2 2 0\n"
                 "f 1 2 3\nf 1 3 4\nf 4 5 6\n",
                 7, 4);
}

/* Writes text to path (replacing it: a new file renamed over it). */
static void replace_file(const char *path, const char *text)
{
    char tmp[256];
    snprintf(tmp, sizeof tmp, "%s.new", path);
    FILE *f = fopen(tmp, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(text, 1, strlen(text), f), strlen(text));
    assert_int_equal(fclose(f), 0);
    assert_int_equal(rename(tmp, path), 0);
}

/* vx_mesh_read_fd reads the file its fd names, not what the path holds by
 * then (a job reads the mesh file the store checked; one swapped in after
 * the check is not read), its format told by the name's extension (OFF,
 * through the importer) or by its bytes (OBJ). */
static void test_read_fd_not_path(void **state)
{
    (void)state;
    static const char *tet_obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n"
                                 "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    static const char *tri_obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    static const char *tet_off = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
                                 "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    static const char *tri_off = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    const char *names[] = {"/tmp/vx_test_fd_%d.obj", "/tmp/vx_test_fd_%d.off"};
    for (int k = 0; k < 2; k++) {
        char path[128];
        snprintf(path, sizeof path, names[k], (int)getpid());
        replace_file(path, k ? tet_off : tet_obj);
        int fd = open(path, O_RDONLY);
        assert_true(fd >= 0);
        replace_file(path, k ? tri_off : tri_obj); /* swapped after the open */
        vx_err err = {0};
        vx_mesh_limits lim = {0};
        vx_mesh *m = vx_mesh_read_fd(fd, path, &lim, &err);
        assert_non_null(m);
        assert_int_equal(m->ntris, 4); /* the file opened */
        vx_mesh_free(m);
        m = vx_mesh_read_fd(fd, path, &lim, &err); /* fd unchanged: again */
        assert_non_null(m);
        assert_int_equal(m->ntris, 4);
        vx_mesh_free(m);
        close(fd);
        m = vx_mesh_read_path(path, &lim, &err);
        assert_non_null(m);
        assert_int_equal(m->ntris, 1); /* the path's file now */
        vx_mesh_free(m);
        unlink(path);
    }
}

/* CRLF, CR alone (classic Mac OS), no final newline, comments, blank lines,
 * tabs, continuation, BOM, vertex colours (with alpha),
 * and the statements that are accepted and ignored all give one mesh. */
static void test_syntax_variants(void **state)
{
    static const char *texts[] = {
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",
        "v 0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3",
        "v 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 2 3\r",
        "# Mac\r\rv 0 0 0\rv 1 0 0\rv 0 1 0\rf 1 \\\r2 3",
        "v 0 0 0\rv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n",
        "v 0 0 0 1 0 0 1\nv 1 0 0 0 1 0 0.5\nv 0 1 0 0 0 1 0\nf 1 2 3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3",
        "# header\n\n   \n\t\nv 0 0 0 # origin\nv 1 0 0#x\n  v\t0   1 0   \n\nf 1 2 3 # tri\n#end",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\\n 2 \\\n3\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 \\\r\n3",
        "\xef\xbb\xbfv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "v 0 0 0 1\nv 1 0 0 1.0\nv 0 1 0 0.5 0.5 0.5\nf 1 2 3\n",
        "mtllib a.mtl\no obj\ng grp a b\ns 1\ns off\nusemtl red\n"
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvp 0.5 0.5\nl 1 2\np 1\nf 1 2 3\n"
        "cstype bezier\ndeg 3\nbmat u 1 0\nstep 1\ncurv 0 1 1 2\ncurv2 1 2\nsurf 0 1 0 1 1 2\n"
        "parm u 0 1\ntrim 0 1 1\nhole 0 1 1\nscrv 0 1 1\nsp 1\nend\ncon 1 0 1 1 2 0 1 1\n"
        "mg 1 0.5\nbevel off\nc_interp on\nd_interp off\nlod 1\nshadow_obj s.obj\n"
        "trace_obj t.obj\nctech cparm 1\nstech cparma 1 1\n",
        /* the spec's texture map library, shell command and superseded
         * patch statements (each had been obj_junk) */
        "maplib a.map b.map\nusemap wood\ncsh -echo hi\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
        "bzp 1 2 3 4\nbsp 1 2 3 4\ncdc 1 2 3 4\ncdp 1 2 3 4\nres 4 4\nf 1 2 3\n",
        "v 0e0 0.0 -0\nv 1e0 .0 +0\nv 0. 1.000 0E+00\nf 1 2 3\n",
    };
    for (size_t i = 0; i < sizeof texts / sizeof texts[0]; i++) {
        vx_err err = {0};
        vx_mesh *m = read_str(texts[i], &err);
        if (!m) print_error("variant %zu: %s: %s\n", i, err.code, err.message);
        assert_non_null(m);
        assert_int_equal(m->nverts, 3);
        assert_int_equal(m->nfaces, 1);
        static const uint32_t want[] = {0, 1, 2}, sizes[] = {3};
        assert_faces(m, want, sizes, 1);
        static const double pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
        for (int k = 0; k < 9; k++)
            assert_true(m->pos[k] == pos[k]);
        vx_mesh_free(m);

        m = read_fmem(texts[i], &err);
        assert_non_null(m);
        assert_int_equal(m->nfaces, 1);
        vx_mesh_free(m);
    }
}

/* The hand-written number parser agrees with strtod to the last bit. */
static void test_number_parsing(void **state)
{
    static const char *nums[] = {"0.1",
                                 "-0.1",
                                 "1e-5",
                                 "123456789.123456789",
                                 "3.14159265358979323846",
                                 "1e22",
                                 "1e23",
                                 "9007199254740993",
                                 "0.08156099999999999",
                                 "-2.5e-300",
                                 "4.9e-324",
                                 "2.2250738585072014e-308",
                                 "1.7976931348623157e308",
                                 ".5",
                                 "5.",
                                 "+3",
                                 "1E3",
                                 "0.000000000000000000000000000001",
                                 "1234567890123456789012345",
                                 "7.038531e-26",
                                 "0.30000000000000004",
                                 "00000000000000000000000000012.5e-1",
                                 "-1e-400"};
    for (size_t i = 0; i < sizeof nums / sizeof nums[0]; i++) {
        char text[256];
        snprintf(text, sizeof text, "v %s 0 0\nv 0 0 0\nv 0 1 0\nf 1 2 3\n", nums[i]);
        vx_err err = {0};
        vx_mesh *m = read_str(text, &err);
        if (!m) print_error("%s: %s\n", nums[i], err.message);
        assert_non_null(m);
        double want = strtod(nums[i], NULL);
        if (m->pos[0] != want) print_error("%s: got %.17g want %.17g\n", nums[i], m->pos[0], want);
        assert_true(m->pos[0] == want);
        assert_true(signbit(m->pos[0]) == signbit(want));
        vx_mesh_free(m);
    }
}

static void test_errors(void **state)
{
    const char *v3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    char t[512];
#define WITH_V3(s) (snprintf(t, sizeof t, "%s%s", v3, s), t)
    /* junk tokens */
    expect_fail_str("v 0 0 0\nv 1 2 abc\n", "obj_junk", 2);
    expect_fail_str("v 0 0 0\nv 1 2 3abc\n", "obj_junk", 2);
    expect_fail_str("v 1 2\n", "obj_junk", 1);
    expect_fail_str("v 1 2 3 4 5\n", "obj_junk", 1);
    expect_fail_str("v 1 2 3 4 5 6 7 8\n", "obj_junk", 1);
    expect_fail_str("v 1.2.3 0 0\n", "obj_junk", 1);
    expect_fail_str("v 1e 0 0\n", "obj_junk", 1);
    expect_fail_str("v - 0 0\n", "obj_junk", 1);
    expect_fail_str("v 0x10 0 0\n", "obj_junk", 1);
    expect_fail_str("v 1,5 0 0\n", "obj_junk", 1);
    expect_fail_str("vt 0 0 0 0\n", "obj_junk", 1);
    expect_fail_str("vt\n", "obj_junk", 1);
    expect_fail_str("\n\nvn 0 0\n", "obj_junk", 3);
    expect_fail_str("vn 0 0 1 x\n", "obj_junk", 1);
    expect_fail_str(WITH_V3("f 1 2 x\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("f 1 2 3 junk\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("f 1 2 3x\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("f 1/// 2/// 3///\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("f 1/x 2/ 3/\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("f 1.0 2 3\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("vt 0 0\nvn 0 0 1\nf 1/1/1/1 2 3\n"), "obj_junk", 6);
    expect_fail_str(WITH_V3("\nfoo 1 2 3\n"), "obj_junk", 5);
    expect_fail_str(WITH_V3("F 1 2 3\n"), "obj_junk", 4);
    expect_fail_str(WITH_V3("vx 1 2 3\n"), "obj_junk", 4);
    expect_fail_str("\xef\xbb\xbf\xef\xbb\xbfv 0 0 0\n", "obj_junk", 1);
    /* a NUL byte inside a statement */
    static const char nul[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\0 3\n";
    expect_fail(nul, sizeof nul - 1, VX_EINVAL, "obj_junk", 4);
    static const char nul2[] = "v 0 0 0\n\0\n";
    expect_fail(nul2, sizeof nul2 - 1, VX_EINVAL, "obj_junk", 2);

    /* NaN / Inf */
    expect_fail_str("v 0 0 0\nv nan 0 0\n", "obj_nan", 2);
    expect_fail_str("v 0 NaN 0\n", "obj_nan", 1);
    expect_fail_str("v 0 0 inf\n", "obj_nan", 1);
    expect_fail_str("v 0 0 -Infinity\n", "obj_nan", 1);
    expect_fail_str("v 1e999 0 0\n", "obj_nan", 1);
    expect_fail_str("v -1e400 0 0\n", "obj_nan", 1);
    expect_fail_str("vn 0 0 nan\n", "obj_nan", 1);
    expect_fail_str("vt inf 0\n", "obj_nan", 1);

    /* indices */
    expect_fail_str(WITH_V3("f 0 1 2\n"), "obj_index", 4);
    expect_fail_str(WITH_V3("f 1 2 4\n"), "obj_index", 4);
    expect_fail_str(WITH_V3("f -4 -2 -1\n"), "obj_index", 4);
    expect_fail_str(WITH_V3("f 1 2 99999999999999999999999\n"), "obj_index", 4);
    expect_fail_str(WITH_V3("f 1/1 2/1 3/1\n"), "obj_index", 4);
    expect_fail_str(WITH_V3("vt 0 0\nf 1/1 2/2 3/1\n"), "obj_index", 5);
    expect_fail_str(WITH_V3("vt 0 0\nf 1/0 2/1 3/1\n"), "obj_index", 5);
    expect_fail_str(WITH_V3("vt 0 0\nf 1/-2 2/1 3/1\n"), "obj_index", 5);
    expect_fail_str(WITH_V3("vn 0 0 1\nf 1//1 2//1 3//2\n"), "obj_index", 5);
    expect_fail_str(WITH_V3("vn 0 0 1\nf 1//1 2//1 3//-2\n"), "obj_index", 5);
    expect_fail_str(WITH_V3("vn 0 0 1\nf 1/1/1 2/1/1 3/1/1\n"), "obj_index", 5);
    /* a forward reference: the vertex comes later */
    expect_fail_str("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", "obj_index", 3);

    /* short and degenerate faces */
    expect_fail_str(WITH_V3("f 1 2\n"), "obj_face_short", 4);
    expect_fail_str(WITH_V3("f\n"), "obj_face_short", 4);
    expect_fail_str(WITH_V3("f 1 # 2 3\n"), "obj_face_short", 4);
    expect_fail_str(WITH_V3("f 1 2 1\n"), "obj_face_repeat", 4);
    expect_fail_str(WITH_V3("f 1 2 3\nf 1 2 3 -3\n"), "obj_face_repeat", 5);
    expect_fail_str(WITH_V3("f 1 1/1 2\n") + 0, "obj_index", 4); /* vt 1 missing first */

    /* no faces */
    expect_fail("", 0, VX_EUNPROC, "obj_no_faces", 0);
    expect_fail("# only a comment\n", 17, VX_EUNPROC, "obj_no_faces", 0);
    expect_fail(v3, strlen(v3), VX_EUNPROC, "obj_no_faces", 0);
#undef WITH_V3
}

/* Long n-gons take the sorting path of the repeat check. */
static void test_long_ngon(void **state)
{
    size_t n = 1000;
    char *text = malloc(n * 100 + 64), *p = text;
    for (size_t i = 0; i < n; i++) {
        double a = 2 * M_PI * (double)i / (double)n;
        p += sprintf(p, "v %.17g %.17g 0\n", cos(a), sin(a));
    }
    p += sprintf(p, "f");
    for (size_t i = 0; i < n; i++)
        p += sprintf(p, " %zu", i + 1);
    p += sprintf(p, "\n");
    vx_err err = {0};
    vx_mesh *m = read_str(text, &err);
    assert_non_null(m);
    assert_int_equal(m->nfaces, 1);
    assert_int_equal(m->ntris, n - 2);
    assert_int_equal(m->faces_by_size[2], 1);
    assert_int_equal(m->boundary_edges, n);
    vx_mesh_free(m);
    /* the same with one vertex used twice, far apart */
    sprintf(p - 1, " 500\n");
    expect_fail_str(text, "obj_face_repeat", (int)n + 1);
    free(text);
}

static void test_line_too_long(void **state)
{
    size_t n = 70 * 1024;
    char *text = malloc(n + 256);
    strcpy(text, "v 0 0 0\nv 1 0 0\nv 0 1 0\n# ");
    size_t k = strlen(text);
    memset(text + k, 'x', n);
    strcpy(text + k + n, "\nf 1 2 3\n");
    expect_fail_str(text, "obj_line_too_long", 4);
    /* the same as the last line, without a newline */
    text[k + n] = 0;
    expect_fail_str(text, "obj_line_too_long", 4);
    /* a long line through continuations */
    char *c = malloc(n * 3 + 64), *p = c;
    p += sprintf(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\\n");
    for (size_t i = 0; i < n / 2; i++)
        p += sprintf(p, " \\\n");
    sprintf(p, "2 3\n");
    expect_fail_str(c, "obj_line_too_long", 4);
    free(c);
    /* just under the limit is fine */
    strcpy(text, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 # ");
    k = strlen(text);
    memset(text + k, 'y', 60 * 1024);
    strcpy(text + k + 60 * 1024, "\n");
    vx_err err = {0};
    vx_mesh *m = read_str(text, &err);
    assert_non_null(m);
    vx_mesh_free(m);
    free(text);
}

/* Many lines: the chunked line splitter at buffer boundaries. */
/* Lines across the reader's buffer refills, with LF and CRLF mixed, and
 * with CR alone. */
static void test_many_lines(void **state)
{
    size_t nv = 50000;
    size_t cap = nv * 64 + 1024;
    char *text = malloc(cap);
    for (int cr = 0; cr < 2; cr++) {
        char *p = text;
        for (size_t i = 0; i < nv; i++)
            p += sprintf(p, "v %zu.5 %zu -%zu.25%s", i, i % 7, i % 13,
                         cr      ? "\r"
                         : i % 2 ? "\r\n"
                                 : "\n");
        for (size_t i = 0; i + 2 < nv; i += 2)
            p += sprintf(p, "f %zu %zu %zu%s", i + 1, i + 2, i + 3, cr ? "\r" : "\n");
        vx_err err = {0};
        vx_mesh *m = read_str(text, &err);
        if (!m) print_error("cr %d: %s: %s\n", cr, err.code, err.message);
        assert_non_null(m);
        assert_int_equal(m->nverts, nv);
        assert_int_equal(m->nfaces, nv / 2 - 1);
        for (size_t i = 0; i < nv; i++) {
            assert_true(m->pos[3 * i] == (double)i + 0.5);
            assert_true(m->pos[3 * i + 1] == (double)(i % 7));
            assert_true(m->pos[3 * i + 2] == -(double)(i % 13) - 0.25);
        }
        vx_mesh_free(m);
    }
    free(text);
}

static void test_limits(void **state)
{
    char text[1024];
    snprintf(text, sizeof text, "%s%s%s", cube_v, cube_f, cube_lid);
    vx_err err = {0};
    vx_mesh_limits lim = {.max_vertices = 8, .max_triangles = 12};
    vx_mesh *m = read_mem(text, strlen(text), &lim, &err);
    assert_non_null(m); /* exactly at the limits */
    vx_mesh_free(m);

    lim = (vx_mesh_limits){.max_vertices = 7};
    assert_null(read_mem(text, strlen(text), &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_true(strncmp(err.message, "line 8: ", 8) == 0);

    /* triangles are counted on the fan: the 6th quad makes 12 */
    lim = (vx_mesh_limits){.max_triangles = 11};
    assert_null(read_mem(text, strlen(text), &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_true(strncmp(err.message, "line 14: ", 9) == 0);
}

/* A real file over max_triangles fails early, at the face over the limit. */
static void test_limits_real(void **state)
{
    vx_err err = {0};
    vx_mesh_limits lim = {.max_triangles = 1000};
    assert_null(vx_obj_read_path(VX_MESH_DIR "/ogre.obj", &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_int_equal(err.kind, VX_ETOOBIG);
    /* ogre.obj has 62194 v lines before its faces */
    assert_true(strncmp(err.message, "line 63195: ", 12) == 0);
    lim = (vx_mesh_limits){.max_vertices = 10000};
    assert_null(vx_obj_read_path(VX_MESH_DIR "/ogre.obj", &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    assert_true(strncmp(err.message, "line 10001: ", 12) == 0);
}

typedef struct real_mesh {
    const char *file;
    size_t nfaces, ntris, tris, quads, ngons, boundary;
} real_mesh;

/* What the files contain, counted independently (awk over the f lines; the
 * boundary edges with a separate edge count), and matching the README. */
static const real_mesh real_meshes[] = {
    {"stanford-bunny.obj", 69451, 69451, 69451, 0, 0, 223},
    {"spot_triangulated.obj", 5856, 5856, 5856, 0, 0, 0},
    {"fandisk.obj", 12946, 12946, 12946, 0, 0, 0},
    {"rocker-arm.obj", 20088, 20088, 20088, 0, 0, 0},
    {"ogre.obj", 124008, 124008, 124008, 0, 0, 236},
    {"suzanne.obj", 500, 968, 32, 468, 0, 42},
    {"spot_quadrangulated.obj", 2928, 5856, 0, 2928, 0, 0},
    {"spot_control_mesh.obj", 180, 4 + 2 * 160 + 3 * 16, 4, 160, 16, 0},
};

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void test_real_meshes(void **state)
{
    for (size_t i = 0; i < sizeof real_meshes / sizeof real_meshes[0]; i++) {
        const real_mesh *r = &real_meshes[i];
        char path[512];
        snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, r->file);
        vx_err err = {0};
        double t0 = now();
        vx_mesh *m = vx_mesh_read_path(path, NULL, &err);
        double dt = now() - t0;
        if (!m) print_error("%s: %s: %s\n", r->file, err.code, err.message);
        assert_non_null(m);
        print_message("%-24s %7zu faces %7zu tris %4zu boundary %3zu non-manifold  %.1f ms\n",
                      r->file, m->nfaces, m->ntris, m->boundary_edges, m->nonmanifold_edges,
                      dt * 1e3);
        assert_int_equal(m->nfaces, r->nfaces);
        assert_int_equal(m->ntris, r->ntris);
        assert_int_equal(m->faces_by_size[0], r->tris);
        assert_int_equal(m->faces_by_size[1], r->quads);
        assert_int_equal(m->faces_by_size[2], r->ngons);
        assert_int_equal(m->boundary_edges, r->boundary);
        if (r->quads || r->ngons)
            assert_non_null(m->face_start);
        else
            assert_null(m->face_start);
        for (int a = 0; a < 3; a++)
            assert_true(m->bbox_min[a] < m->bbox_max[a]);
        vx_mesh_free(m);
    }
}

static void test_sniff(void **state)
{
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"DRACO\x02\x02", 7), VX_MESH_DRACO);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"DRAC", 4), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"v 1 2 3\r\n\tf 1 2 3\n", 18),
                     VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"# caf\xc3\xa9 \xe2\x82\xac\n", 12),
                     VX_MESH_OBJ);
    /* a multi-byte character cut by the end of the sniffed bytes */
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"# \xe2\x82", 4), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"", 0), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"v 1\0", 4), 0);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"\x89PNG\r\n", 6), 0);
    /* names in Latin-1 (not UTF-8): text, while such bytes are few */
    const char *latin1 = "# caf\xe9 au lait \xc3\x28\nv 1 2 3\n";
    assert_int_equal(vx_mesh_sniff((const unsigned char *)latin1, strlen(latin1)), VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"# M\xe4x W\xfcrfel\nv 1 2 3\n", 20),
                     VX_MESH_OBJ);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"# \xff", 3), 0);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"\xfe\xfa\xe0 x", 5), 0);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"ply\x1b", 4), 0);
    assert_int_equal(vx_mesh_sniff((const unsigned char *)"drACO", 5), VX_MESH_OBJ);
}

static void test_read_path_dispatch(void **state)
{
    vx_err err = {0};
    assert_null(vx_mesh_read_path("/nonexistent/x.obj", NULL, &err));
    assert_string_equal(err.code, "mesh_io");
    assert_int_equal(err.kind, VX_EIO);
    assert_null(vx_obj_read_path("/nonexistent/x.obj", NULL, &err));
    assert_string_equal(err.code, "mesh_io");

    char path[] = "/tmp/vx_test_bin_XXXXXX";
    int fd = mkstemp(path);
    assert_true(fd >= 0);
    unsigned char junkbytes[4096];
    for (size_t i = 0; i < sizeof junkbytes; i++)
        junkbytes[i] = (unsigned char)(i * 131 + 7);
    assert_int_equal(write(fd, junkbytes, sizeof junkbytes), (ssize_t)sizeof junkbytes);
    close(fd);
    assert_null(vx_mesh_read_path(path, NULL, &err));
    assert_string_equal(err.code, "mesh_format");
    assert_int_equal(err.kind, VX_EINVAL);
    unlink(path);

    /* OBJ detected by content, errors pass through with their line */
    assert_null(read_mem("v 0 0 0\nv 1 x 0\n", 16, NULL, &err));
    assert_string_equal(err.code, "obj_junk");
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_triangle),
        cmocka_unit_test(test_index_forms),
        cmocka_unit_test(test_relative_interleaved),
        cmocka_unit_test(test_ngons),
        cmocka_unit_test(test_concave_faces),
        cmocka_unit_test(test_late_quad),
        cmocka_unit_test(test_cube_closed_and_open),
        cmocka_unit_test(test_split_vertices_weld),
        cmocka_unit_test(test_read_fd_not_path),
        cmocka_unit_test(test_syntax_variants),
        cmocka_unit_test(test_number_parsing),
        cmocka_unit_test(test_errors),
        cmocka_unit_test(test_long_ngon),
        cmocka_unit_test(test_line_too_long),
        cmocka_unit_test(test_many_lines),
        cmocka_unit_test(test_limits),
        cmocka_unit_test(test_limits_real),
        cmocka_unit_test(test_real_meshes),
        cmocka_unit_test(test_sniff),
        cmocka_unit_test(test_read_path_dispatch),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
