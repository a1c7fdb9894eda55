/* Mesh writers and the Draco reader: OBJ and Draco round trips, the binary
 * PLY parsed back byte by byte, and Draco inputs that must be refused. */
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <setjmp.h>
#include <cmocka.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "mesh/mesh.h"

#define DRACO_ENCODER "/usr/bin/draco_encoder"
#define DRACO_DECODER "/usr/bin/draco_decoder"

static char tmpdir[64];

static int setup_dir(void **state)
{
    strcpy(tmpdir, "/tmp/vx_test_mesh_io_XXXXXX");
    return mkdtemp(tmpdir) ? 0 : -1;
}

static int remove_dir(void **state)
{
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    return system(cmd) == 0 ? 0 : -1;
}

static const char *tmp(const char *name)
{
    static char path[8][256];
    static int next;
    char *p = path[next++ % 8];
    snprintf(p, 256, "%s/%s", tmpdir, name);
    return p;
}

static unsigned char *slurp(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    assert_non_null(f);
    fseek(f, 0, SEEK_END);
    long len = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *d = malloc((size_t)len + 1);
    assert_int_equal(fread(d, 1, (size_t)len, f), (size_t)len);
    fclose(f);
    d[len] = 0;
    *n = (size_t)len;
    return d;
}

static void spill(const char *path, const void *d, size_t n)
{
    FILE *f = fopen(path, "wb");
    assert_non_null(f);
    assert_int_equal(fwrite(d, 1, n, f), n);
    assert_int_equal(fclose(f), 0);
}

/* Builds and analyses a mesh from face sizes and flat indices. */
static vx_mesh *make_mesh(size_t nv, const double *pos, size_t nf, const uint32_t *sizes,
                          const uint32_t *idx)
{
    vx_mesh *m = vx_mesh_new();
    m->nverts = nv;
    m->pos = malloc(3 * nv * sizeof(double));
    memcpy(m->pos, pos, 3 * nv * sizeof(double));
    size_t total = 0;
    int all_tris = 1;
    for (size_t f = 0; f < nf; f++) {
        total += sizes[f];
        all_tris &= sizes[f] == 3;
    }
    m->nfaces = nf;
    m->face_idx = malloc(total * sizeof(uint32_t));
    memcpy(m->face_idx, idx, total * sizeof(uint32_t));
    if (!all_tris) {
        m->face_start = malloc((nf + 1) * sizeof(uint32_t));
        m->face_start[0] = 0;
        for (size_t f = 0; f < nf; f++)
            m->face_start[f + 1] = m->face_start[f] + sizes[f];
    }
    vx_err err = {0};
    assert_int_equal(vx_mesh_analyze(m, &err), 0);
    return m;
}

/* A cube with one face split into two triangles, a pentagon on a tower,
 * and coordinates of very different magnitudes. */
static vx_mesh *mixed_mesh(void)
{
    static const double pos[] = {
        -1, -1, -1,     1, -1,         -1,      1,    1,       -1,      -1,  1,
        -1, -1, -1,     1, 1,          -1,      1,    1,       1,       1,   -1,
        1,  1,  0.0001, 3, 123456.789, -2.5e-7, 3.25, -9876.5, 1.0 / 3, 3.5, 2.0 / 3};
    static const uint32_t sizes[] = {4, 4, 4, 4, 4, 3, 3, 5};
    static const uint32_t idx[] = {0, 3, 2, 1, 4, 5, 6, 7, 0, 1, 5, 4, 1,  2, 6, 5,
                                   2, 3, 7, 6, 3, 0, 4, 3, 4, 7, 8, 9, 10, 1, 0};
    return make_mesh(11, pos, 8, sizes, idx);
}

static void assert_same_mesh(const vx_mesh *a, const vx_mesh *b, double rel)
{
    assert_int_equal(a->nverts, b->nverts);
    for (size_t i = 0; i < 3 * a->nverts; i++) {
        double x = a->pos[i], y = b->pos[i];
        if (fabs(x - y) > rel * fmax(fabs(x), 1e-30))
            print_error("pos %zu: %.17g vs %.17g\n", i, x, y);
        assert_true(fabs(x - y) <= rel * fmax(fabs(x), 1e-30));
    }
    assert_int_equal(a->nfaces, b->nfaces);
    for (size_t f = 0; f < a->nfaces; f++) {
        assert_int_equal(vx_mesh_face_size(a, f), vx_mesh_face_size(b, f));
        assert_memory_equal(vx_mesh_face(a, f), vx_mesh_face(b, f),
                            vx_mesh_face_size(a, f) * sizeof(uint32_t));
    }
    assert_int_equal(a->ntris, b->ntris);
}

static size_t count_lines(const char *text, const char *prefix)
{
    size_t n = 0, k = strlen(prefix);
    for (const char *p = text; p && *p; p = strchr(p, '\n'), p = p ? p + 1 : p)
        if (strncmp(p, prefix, k) == 0) n++;
    return n;
}

/* Checks vx_mesh_net_edges on m against want (n edges as lo, hi, net):
 * as the analysis kept them, and found again without it. */
static void expect_net(vx_mesh *m, const int32_t (*want)[3], size_t n)
{
    for (int again = 0; again < 2; again++) {
        if (again) m->net_known = 0; /* as for a list over VX_MESH_NET_KEEP */
        vx_mesh_edge *e;
        size_t got;
        vx_err err = {0};
        assert_int_equal(vx_mesh_net_edges(m, &e, &got, &err), 0);
        assert_int_equal(got, n);
        for (size_t i = 0; i < n; i++) {
            assert_int_equal(e[i].lo, want[i][0]);
            assert_int_equal(e[i].hi, want[i][1]);
            assert_int_equal(e[i].net, want[i][2]);
        }
        free(e);
    }
}

/* Misoriented edges: none on a consistently wound tetrahedron (closed or
 * open), the three edges of a face turned round, and a seam of split
 * vertices counted once welded. With them the edges whose uses do not
 * cancel (vx_mesh_net_edges): none on the closed tetrahedron; the rim of
 * a missing face, each its way round; the turned face's three, used twice
 * the same way (and so welded across the seam); a quad's fan diagonal
 * cancels. */
static void test_orientation(void **state)
{
    (void)state;
    static const double pos[] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0};
    static const uint32_t sizes[] = {3, 3, 3, 3};
    static const uint32_t good[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3};
    static const uint32_t flip[] = {0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 3, 2};
    static const uint32_t seam[] = {4, 2, 1, 0, 1, 3, 0, 3, 2, 1, 3, 2}; /* vertex 4 = 0 */
    static const int32_t rim[][3] = {{1, 2, -1}, {1, 3, 1}, {2, 3, -1}};
    static const int32_t twice[][3] = {{1, 2, -2}, {1, 3, 2}, {2, 3, -2}};
    vx_mesh *m = make_mesh(4, pos, 4, sizes, good);
    assert_int_equal(m->boundary_edges, 0);
    assert_int_equal(m->misoriented_edges, 0);
    assert_true(m->net_known);
    expect_net(m, NULL, 0);
    vx_mesh_free(m);
    m = make_mesh(4, pos, 3, sizes, good); /* open: one face missing */
    assert_int_equal(m->boundary_edges, 3);
    assert_int_equal(m->misoriented_edges, 0);
    expect_net(m, rim, 3);
    vx_mesh_free(m);
    m = make_mesh(4, pos, 4, sizes, flip);
    assert_int_equal(m->boundary_edges, 0); /* no edge used once, yet three do not cancel */
    assert_int_equal(m->misoriented_edges, 3);
    expect_net(m, twice, 3);
    vx_mesh_free(m);
    m = make_mesh(5, pos, 4, sizes, seam);
    assert_int_equal(m->boundary_edges, 4);
    assert_int_equal(m->boundary_edges_welded, 0);
    assert_int_equal(m->misoriented_edges, 3);
    expect_net(m, twice, 3);
    vx_mesh_free(m);
    static const double quad_pos[] = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
    static const uint32_t quad_size[] = {4}, quad[] = {0, 1, 2, 3};
    static const int32_t quad_rim[][3] = {{0, 1, 1}, {0, 3, -1}, {1, 2, 1}, {2, 3, 1}};
    m = make_mesh(4, quad_pos, 1, quad_size, quad);
    assert_int_equal(m->ntris, 2);
    expect_net(m, quad_rim, 4);
    vx_mesh_free(m);
}

static void test_obj_round_trip(void **state)
{
    vx_mesh *m = mixed_mesh();
    vx_err err = {0};
    const char *path = tmp("plain.obj");
    assert_int_equal(vx_obj_write_path(m, NULL, path, &err), 0);
    vx_mesh *r = vx_obj_read_path(path, NULL, &err);
    assert_non_null(r);
    assert_same_mesh(m, r, 1e-6);
    assert_int_equal(r->nnormals, 0);
    vx_mesh_free(r);

    /* normals and groups: vn per vertex, f a//a, g at every change */
    float *nrm = malloc(3 * m->nverts * sizeof(float));
    for (size_t i = 0; i < 3 * m->nverts; i++)
        nrm[i] = (float)i / 7.0f - 1.0f;
    static const uint32_t groups[] = {0, 0, 1, 1, 7, 7, 0, 3};
    vx_mesh_write_opts o = {.normals = nrm, .face_group = groups};
    path = tmp("groups.obj");
    assert_int_equal(vx_obj_write_path(m, &o, path, &err), 0);
    r = vx_obj_read_path(path, NULL, &err);
    assert_non_null(r);
    assert_same_mesh(m, r, 1e-6);
    assert_int_equal(r->nnormals, m->nverts);
    vx_mesh_free(r);
    size_t n;
    char *text = (char *)slurp(path, &n);
    assert_int_equal(count_lines(text, "g "), 5);
    assert_int_equal(count_lines(text, "vn "), m->nverts);
    assert_non_null(strstr(text, "\ng patch0\nf 1//1 4//4 3//3 2//2\n"));
    assert_non_null(strstr(text, "\ng patch7\n"));
    assert_non_null(strstr(text, "\ng patch3\nf 9//9 10//10 11//11 2//2 1//1\n"));
    /* the vn values read back to float precision */
    const char *vn = strstr(text, "\nvn ");
    float x, y, z;
    assert_int_equal(sscanf(vn, "\nvn %f %f %f", &x, &y, &z), 3);
    assert_true(x == nrm[0] && y == nrm[1] && z == nrm[2]);
    free(text);

    o.group_prefix = "part_";
    o.normals = NULL;
    path = tmp("prefix.obj");
    assert_int_equal(vx_obj_write_path(m, &o, path, &err), 0);
    text = (char *)slurp(path, &n);
    assert_non_null(strstr(text, "\ng part_1\nf 1 2 6 5\n"));
    assert_null(strstr(text, "//"));
    free(text);
    free(nrm);
    vx_mesh_free(m);
}

/* A real mesh through OBJ write / read: same faces, positions to 1e-6. */
static void test_obj_round_trip_real(void **state)
{
    vx_err err = {0};
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_control_mesh.obj", NULL, &err);
    assert_non_null(m);
    const char *path = tmp("spot_control.obj");
    assert_int_equal(vx_obj_write_path(m, NULL, path, &err), 0);
    vx_mesh *r = vx_obj_read_path(path, NULL, &err);
    assert_non_null(r);
    assert_same_mesh(m, r, 1e-6);
    assert_int_equal(r->boundary_edges, 0);
    vx_mesh_free(r);
    vx_mesh_free(m);
}

static void test_write_errors(void **state)
{
    vx_mesh *m = mixed_mesh();
    vx_err err = {0};
    assert_int_equal(vx_obj_write_path(m, NULL, "/nonexistent/dir/x.obj", &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    assert_string_equal(err.code, "io_error");
    assert_non_null(strstr(err.message, "No such file"));
    assert_int_equal(vx_ply_write_path(m, NULL, "/nonexistent/dir/x.ply", &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    assert_int_equal(vx_draco_write_path(m, NULL, "/nonexistent/dir/x.drc", &err), -1);
    assert_int_equal(err.kind, VX_EIO);
    /* a full disk shows up when the buffer is flushed */
    if (access("/dev/full", W_OK) == 0) {
        vx_err_clear(&err);
        assert_int_equal(vx_obj_write_path(m, NULL, "/dev/full", &err), -1);
        assert_int_equal(err.kind, VX_EIO);
        assert_non_null(strstr(err.message, "No space"));
        vx_err_clear(&err);
        assert_int_equal(vx_ply_write_path(m, NULL, "/dev/full", &err), -1);
        assert_int_equal(err.kind, VX_EIO);
        assert_non_null(strstr(err.message, "No space"));
        vx_err_clear(&err);
        assert_int_equal(vx_draco_write_path(m, NULL, "/dev/full", &err), -1);
        assert_int_equal(err.kind, VX_EIO);
        assert_non_null(strstr(err.message, "No space"));
    }
    vx_mesh_write_opts o = {.draco_quantization_bits = 31};
    assert_int_equal(vx_draco_write_path(m, &o, tmp("bits.drc"), &err), -1);
    assert_string_equal(err.code, "invalid_params");
    vx_mesh_free(m);
}

/* --- PLY: a minimal binary little-endian reader for what the writer makes. */

static uint32_t rd_u32(const unsigned char **p)
{
    const unsigned char *b = *p;
    *p += 4;
    return (uint32_t)b[0] | (uint32_t)b[1] << 8 | (uint32_t)b[2] << 16 | (uint32_t)b[3] << 24;
}

static float rd_f32(const unsigned char **p)
{
    uint32_t u = rd_u32(p);
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

static void check_ply(const char *path, const vx_mesh *m, const float *nrm, const uint32_t *grp,
                      int wide)
{
    size_t n;
    unsigned char *d = slurp(path, &n);
    const char *end = strstr((const char *)d, "end_header\n");
    assert_non_null(end);
    size_t hlen = (size_t)(end - (const char *)d) + strlen("end_header\n");
    char *header = strndup((const char *)d, hlen);
    char want[1024];
    snprintf(want, sizeof want,
             "ply\nformat binary_little_endian 1.0\ncomment voxeld\nelement vertex %zu\n"
             "property float x\nproperty float y\nproperty float z\n%s"
             "element face %zu\nproperty list %s uint vertex_indices\n%send_header\n",
             m->nverts, nrm ? "property float nx\nproperty float ny\nproperty float nz\n" : "",
             m->nfaces, wide ? "uint" : "uchar", grp ? "property int patch\n" : "");
    assert_string_equal(header, want);
    free(header);

    const unsigned char *p = d + hlen;
    for (size_t i = 0; i < m->nverts; i++) {
        for (int a = 0; a < 3; a++)
            assert_true(rd_f32(&p) == (float)m->pos[3 * i + a]);
        if (nrm)
            for (int a = 0; a < 3; a++)
                assert_true(rd_f32(&p) == nrm[3 * i + a]);
    }
    for (size_t f = 0; f < m->nfaces; f++) {
        uint32_t k = wide ? rd_u32(&p) : *p++;
        assert_int_equal(k, vx_mesh_face_size(m, f));
        const uint32_t *v = vx_mesh_face(m, f);
        for (uint32_t j = 0; j < k; j++)
            assert_int_equal(rd_u32(&p), v[j]);
        if (grp) assert_int_equal((int32_t)rd_u32(&p), (int32_t)grp[f]);
    }
    assert_ptr_equal(p, d + n); /* nothing left over */
    free(d);
}

static void test_ply(void **state)
{
    vx_mesh *m = mixed_mesh();
    vx_err err = {0};
    assert_int_equal(vx_ply_write_path(m, NULL, tmp("plain.ply"), &err), 0);
    check_ply(tmp("plain.ply"), m, NULL, NULL, 0);

    float *nrm = malloc(3 * m->nverts * sizeof(float));
    for (size_t i = 0; i < 3 * m->nverts; i++)
        nrm[i] = -(float)i / 3.0f;
    static const uint32_t groups[] = {5, 5, 1, 1, 0, 2, 2, 0xffffffffu};
    vx_mesh_write_opts o = {.normals = nrm, .face_group = groups};
    assert_int_equal(vx_ply_write_path(m, &o, tmp("full.ply"), &err), 0);
    check_ply(tmp("full.ply"), m, nrm, groups, 0);
    o.normals = NULL;
    assert_int_equal(vx_ply_write_path(m, &o, tmp("groups.ply"), &err), 0);
    check_ply(tmp("groups.ply"), m, NULL, groups, 0);
    free(nrm);
    vx_mesh_free(m);

    /* faces of more than 255 vertices need the uint count */
    size_t nv = 300;
    double *pos = malloc(3 * nv * sizeof(double));
    uint32_t *idx = malloc(nv * sizeof(uint32_t)), size = (uint32_t)nv;
    for (size_t i = 0; i < nv; i++) {
        pos[3 * i] = cos(2 * M_PI * (double)i / (double)nv);
        pos[3 * i + 1] = sin(2 * M_PI * (double)i / (double)nv);
        pos[3 * i + 2] = 0;
        idx[i] = (uint32_t)i;
    }
    m = make_mesh(nv, pos, 1, &size, idx);
    assert_int_equal(vx_ply_write_path(m, NULL, tmp("wide.ply"), &err), 0);
    check_ply(tmp("wide.ply"), m, NULL, NULL, 1);
    vx_mesh_free(m);
    free(pos);
    free(idx);

    /* a real all-triangle mesh (face_start NULL) */
    m = vx_obj_read_path(VX_MESH_DIR "/fandisk.obj", NULL, &err);
    assert_non_null(m);
    assert_int_equal(vx_ply_write_path(m, NULL, tmp("fandisk.ply"), &err), 0);
    check_ply(tmp("fandisk.ply"), m, NULL, NULL, 0);
    vx_mesh_free(m);
}

/* A mesh far from the origin for its size: OBJ and PLY keep it. A unit
 * cube at 1e12 was written as eight copies of "1e+12" (OBJ's 9 digits) and
 * as floats (PLY: 1e12 rounds to 65536). Near the origin the files stay as
 * they were (9 digits, float; check_ply above). */
static void test_far_from_origin(void **state)
{
    (void)state;
    static const uint32_t sizes[] = {4, 4, 4, 4, 4, 4};
    static const uint32_t idx[] = {0, 1, 3, 2, 4, 6, 7, 5, 0, 4, 5, 1,
                                   2, 3, 7, 6, 0, 2, 6, 4, 1, 5, 7, 3};
    const double shifts[] = {10, 1e6, 1e12, -3e15};
    for (int k = 0; k < 4; k++) {
        double pos[24];
        for (int v = 0; v < 8; v++)
            for (int a = 0; a < 3; a++)
                pos[3 * v + a] = shifts[k] + ((v >> (2 - a)) & 1) + 0.1 * a;
        vx_mesh *m = make_mesh(8, pos, 6, sizes, idx);
        vx_err err = {0};
        assert_int_equal(vx_obj_write_path(m, NULL, tmp("far.obj"), &err), 0);
        assert_int_equal(vx_ply_write_path(m, NULL, tmp("far.ply"), &err), 0);
        vx_mesh *o = vx_obj_read_path(tmp("far.obj"), NULL, &err);
        vx_mesh *p = vx_mesh_read_path(tmp("far.ply"), NULL, &err);
        assert_non_null(o);
        assert_non_null(p);
        double eo = 0, ep = 0;
        for (int i = 0; i < 24; i++) {
            eo = fmax(eo, fabs(o->pos[i] - pos[i]));
            ep = fmax(ep, fabs(p->pos[i] - pos[i]));
        }
        size_t n;
        char *text = (char *)slurp(tmp("far.ply"), &n);
        int dbl = strstr(text, "property double x\n") != NULL;
        free(text);
        printf("  cube at %g: OBJ within %.3g, PLY (%s) within %.3g\n", shifts[k], eo,
               dbl ? "double" : "float", ep);
        /* a unit cube: within 1e-6 of its size, or the double's own rounding */
        double tol = fmax(1e-6, 4 * fabs(shifts[k]) * 0x1p-52);
        assert_true(eo <= tol);
        assert_true(ep <= tol);
        assert_int_equal(dbl, k > 0); /* floats only for the cube at 10 */
        vx_mesh_free(o);
        vx_mesh_free(p);
        vx_mesh_free(m);
    }
}

/* --- Draco */

static int cmp_tri(const void *a, const void *b)
{
    return memcmp(a, b, 3 * sizeof(uint32_t));
}

/* Rotates a triangle so that its smallest index comes first; keeps the
 * winding. */
static void canon(uint32_t *t)
{
    while (t[0] > t[1] || t[0] > t[2]) {
        uint32_t x = t[0];
        t[0] = t[1];
        t[1] = t[2];
        t[2] = x;
    }
}

/* Checks that d is m up to quantisation: every decoded vertex is within
 * tol (per axis) of an original vertex, and (when the quantisation is fine
 * enough for the nearest vertex to be the right one: `faces`) the
 * triangles, mapped back through those vertices, are the original ones with
 * the same winding. */
static void assert_draco_matches(const vx_mesh *m, const vx_mesh *d, double tol, int faces)
{
    assert_int_equal(d->ntris, m->ntris);
    uint32_t *map = malloc(d->nverts * sizeof(uint32_t));
    double worst = 0;
    for (size_t i = 0; i < d->nverts; i++) {
        const double *p = d->pos + 3 * i;
        double best = INFINITY;
        for (size_t j = 0; j < m->nverts; j++) {
            const double *q = m->pos + 3 * j;
            double e = fmax(fabs(p[0] - q[0]), fmax(fabs(p[1] - q[1]), fabs(p[2] - q[2])));
            if (e < best) {
                best = e;
                map[i] = (uint32_t)j;
            }
        }
        if (best > worst) worst = best;
    }
    print_message("draco: %zu -> %zu vertices, worst error %.3g (tolerance %.3g)\n", m->nverts,
                  d->nverts, worst, tol);
    assert_true(worst <= tol);
    if (!faces) {
        free(map);
        return;
    }
    /* Vertices at the same position (suzanne has two pairs) cannot be told
     * apart after decoding: compare triangles by position class, the first
     * original vertex at each position. */
    uint32_t *cls = malloc(m->nverts * sizeof(uint32_t));
    for (size_t j = 0; j < m->nverts; j++) {
        cls[j] = (uint32_t)j;
        for (size_t k = 0; k < j; k++)
            if (memcmp(m->pos + 3 * k, m->pos + 3 * j, 3 * sizeof(double)) == 0) {
                cls[j] = (uint32_t)k;
                break;
            }
    }
    uint32_t *a = malloc(3 * m->ntris * sizeof(uint32_t)),
             *b = malloc(3 * m->ntris * sizeof(uint32_t));
    for (size_t i = 0; i < 3 * m->ntris; i++)
        a[i] = cls[m->tri[i]];
    for (size_t i = 0; i < 3 * d->ntris; i++)
        b[i] = cls[map[d->tri[i]]];
    free(cls);
    for (size_t t = 0; t < m->ntris; t++) {
        canon(a + 3 * t);
        canon(b + 3 * t);
    }
    qsort(a, m->ntris, 3 * sizeof(uint32_t), cmp_tri);
    qsort(b, m->ntris, 3 * sizeof(uint32_t), cmp_tri);
    assert_memory_equal(a, b, 3 * m->ntris * sizeof(uint32_t));
    free(a);
    free(b);
    free(map);
}

/* Draco's quantisation step: the largest bbox extent over 2^bits - 1. */
static double quant_step(const vx_mesh *m, int bits)
{
    double range = 0;
    for (int a = 0; a < 3; a++)
        range = fmax(range, m->bbox_max[a] - m->bbox_min[a]);
    return range / (double)((1u << bits) - 1);
}

static void test_draco_round_trip(void **state)
{
    static const char *files[] = {"spot_triangulated.obj", "spot_quadrangulated.obj",
                                  "suzanne.obj"};
    for (size_t i = 0; i < sizeof files / sizeof files[0]; i++) {
        char path[512];
        snprintf(path, sizeof path, "%s/%s", VX_MESH_DIR, files[i]);
        vx_err err = {0};
        vx_mesh *m = vx_obj_read_path(path, NULL, &err);
        assert_non_null(m);
        for (int bits = 8; bits <= 16; bits += 4) {
            vx_mesh_write_opts o = {.draco_quantization_bits = bits == 16 ? 0 : bits};
            const char *out = tmp("rt.drc");
            assert_int_equal(vx_draco_write_path(m, &o, out, &err), 0);
            vx_mesh *d = vx_draco_read_path(out, NULL, &err);
            if (!d) print_error("%s: %s\n", err.code, err.message);
            assert_non_null(d);
            assert_null(d->face_start);
            /* half a step is the rounding error; the grid's origin and
             * float conversion add a little */
            assert_draco_matches(m, d, 0.51 * quant_step(m, bits) + 1e-6, bits >= 12);
            vx_mesh_free(d);
            /* and through the sniffing reader */
            d = vx_mesh_read_path(out, NULL, &err);
            assert_non_null(d);
            assert_int_equal(d->ntris, m->ntris);
            vx_mesh_free(d);
        }
        vx_mesh_free(m);
    }
}

static void test_draco_normals(void **state)
{
    vx_err err = {0};
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, &err);
    assert_non_null(m);
    float *nrm = calloc(3 * m->nverts, sizeof(float));
    for (size_t i = 0; i < m->nverts; i++)
        nrm[3 * i + 2] = 1; /* all +z */
    vx_mesh_write_opts o = {.normals = nrm};
    const char *out = tmp("normals.drc");
    assert_int_equal(vx_draco_write_path(m, &o, out, &err), 0);
    vx_mesh *d = vx_draco_read_path(out, NULL, &err);
    assert_non_null(d);
    assert_int_equal(d->ntris, m->ntris);
    vx_mesh_free(d);
    /* the attribute is there: the reference decoder writes it as vn */
    if (access(DRACO_DECODER, X_OK) == 0) {
        char cmd[1024];
        snprintf(cmd, sizeof cmd, "%s -i %s -o %s > /dev/null 2>&1", DRACO_DECODER, out,
                 tmp("normals.obj"));
        assert_int_equal(system(cmd), 0);
        size_t n;
        char *text = (char *)slurp(tmp("normals.obj"), &n);
        const char *vn = strstr(text, "\nvn ");
        assert_non_null(vn);
        float x, y, z;
        assert_int_equal(sscanf(vn, "\nvn %f %f %f", &x, &y, &z), 3);
        assert_true(fabsf(x) < 1e-3f && fabsf(y) < 1e-3f && fabsf(z - 1) < 1e-3f);
        free(text);
    }
    free(nrm);
    vx_mesh_free(m);
}

static void test_draco_limits(void **state)
{
    vx_err err = {0};
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, &err);
    assert_non_null(m);
    const char *out = tmp("limits.drc");
    assert_int_equal(vx_draco_write_path(m, NULL, out, &err), 0);
    vx_mesh_limits lim = {.max_triangles = 5855};
    assert_null(vx_draco_read_path(out, &lim, &err));
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "mesh_too_big");
    lim = (vx_mesh_limits){.max_vertices = 100};
    assert_null(vx_draco_read_path(out, &lim, &err));
    assert_string_equal(err.code, "mesh_too_big");
    lim = (vx_mesh_limits){.max_vertices = 2930, .max_triangles = 5856};
    vx_mesh *d = vx_draco_read_path(out, &lim, &err);
    assert_non_null(d);
    vx_mesh_free(d);
    vx_mesh_free(m);

    /* a file far larger than the limits allow is refused before decoding */
    size_t n = 4u << 20;
    unsigned char *big = calloc(n, 1);
    memcpy(big, "DRACO\x02\x02\x01", 8);
    spill(tmp("big.drc"), big, n);
    free(big);
    lim = (vx_mesh_limits){.max_vertices = 1000, .max_triangles = 1000};
    assert_null(vx_draco_read_path(tmp("big.drc"), &lim, &err));
    assert_int_equal(err.kind, VX_ETOOBIG);
    assert_string_equal(err.code, "mesh_too_big");
    /* without limits libdraco reads it as an empty mesh */
    assert_null(vx_draco_read_path(tmp("big.drc"), NULL, &err));
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "draco_no_faces");
}

static void test_draco_point_cloud(void **state)
{
    if (access(DRACO_ENCODER, X_OK) != 0) skip();
    const char *obj = tmp("cloud.obj"), *drc = tmp("cloud.drc");
    static const char text[] = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 1 1 1\n"
                               "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    spill(obj, text, sizeof text - 1);
    char cmd[1024];
    snprintf(cmd, sizeof cmd, "%s -point_cloud -i %s -o %s > /dev/null 2>&1", DRACO_ENCODER, obj,
             drc);
    int rc = system(cmd);
    if (rc) print_error("%s: status %d\n", cmd, rc);
    assert_int_equal(rc, 0);
    vx_err err = {0};
    assert_null(vx_draco_read_path(drc, NULL, &err));
    assert_int_equal(err.kind, VX_EUNPROC);
    assert_string_equal(err.code, "draco_point_cloud");
    assert_null(vx_mesh_read_path(drc, NULL, &err));
    assert_string_equal(err.code, "draco_point_cloud");

    /* and the reference encoder's mesh output reads */
    snprintf(cmd, sizeof cmd, "%s -i %s -o %s > /dev/null 2>&1", DRACO_ENCODER, obj, drc);
    assert_int_equal(system(cmd), 0);
    vx_mesh *m = vx_mesh_read_path(drc, NULL, &err);
    assert_non_null(m);
    assert_int_equal(m->ntris, 4);
    assert_int_equal(m->boundary_edges, 0);
    vx_mesh_free(m);
}

static unsigned char *real_draco(size_t *n)
{
    vx_err err = {0};
    vx_mesh *m = vx_obj_read_path(VX_MESH_DIR "/spot_triangulated.obj", NULL, &err);
    assert_non_null(m);
    assert_int_equal(vx_draco_write_path(m, NULL, tmp("real.drc"), &err), 0);
    vx_mesh_free(m);
    return slurp(tmp("real.drc"), n);
}

static void test_draco_truncated(void **state)
{
    size_t n;
    unsigned char *d = real_draco(&n);
    size_t cuts[] = {n / 2, n - 1, n / 4, 40, 12, 6, 5, 0};
    for (size_t i = 0; i < sizeof cuts / sizeof cuts[0]; i++) {
        const char *path = tmp("cut.drc");
        spill(path, d, cuts[i]);
        vx_err err = {0};
        vx_mesh *m = vx_draco_read_path(path, NULL, &err);
        if (m) print_error("accepted a cut at %zu of %zu bytes\n", cuts[i], n);
        assert_null(m);
        assert_int_equal(err.kind, VX_EINVAL);
        assert_string_equal(err.code, "draco_corrupt");
        if (cuts[i] >= 5) {
            assert_null(vx_mesh_read_path(path, NULL, &err));
            assert_string_equal(err.code, "draco_corrupt");
        }
    }
    free(d);
}

static uint64_t rng = 0x9e3779b97f4a7c15u;
static uint32_t next_rand(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (uint32_t)(rng >> 16);
}

static void test_draco_garbage(void **state)
{
    size_t n = 4096;
    unsigned char *g = malloc(n);
    for (size_t i = 0; i < n; i++)
        g[i] = (unsigned char)next_rand();
    const char *path = tmp("garbage.drc");
    spill(path, g, n);
    vx_err err = {0};
    assert_null(vx_draco_read_path(path, NULL, &err));
    assert_int_equal(err.kind, VX_EINVAL);
    assert_string_equal(err.code, "draco_corrupt");
    /* by its name (.drc, as the store names a Draco upload): the Draco
     * reader's answer; under a name without a format, the sniffer's */
    assert_null(vx_mesh_read_path(path, NULL, &err));
    assert_string_equal(err.code, "draco_corrupt");
    const char *bare = tmp("garbage");
    spill(bare, g, n);
    assert_null(vx_mesh_read_path(bare, NULL, &err));
    assert_string_equal(err.code, "mesh_format");

    /* the magic followed by garbage, for every header version byte pair */
    for (int v = 0; v < 16; v++) {
        memcpy(g, "DRACO", 5);
        g[5] = (unsigned char)(v >> 2);
        g[6] = (unsigned char)(v & 3);
        g[7] = (unsigned char)(v & 1); /* geometry type: point cloud / mesh */
        spill(path, g, n);
        vx_mesh *m = vx_mesh_read_path(path, NULL, &err);
        assert_null(m);
        assert_true(err.kind == VX_EINVAL || err.kind == VX_EUNPROC);
    }
    free(g);
}

/* Bytes flipped in a valid file: an error or a mesh, never a crash. */
static void test_draco_mutations(void **state)
{
    size_t n;
    unsigned char *d = real_draco(&n);
    unsigned char *c = malloc(n);
    const char *path = tmp("mutant.drc");
    int rejected = 0, accepted = 0;
    for (int it = 0; it < 300; it++) {
        memcpy(c, d, n);
        int flips = 1 + (int)(next_rand() % 4);
        for (int k = 0; k < flips; k++) {
            /* mostly the header and connectivity at the front */
            size_t at = it % 2 ? next_rand() % (n < 256 ? n : 256) : next_rand() % n;
            c[at] ^= (unsigned char)(1 + next_rand() % 255);
        }
        spill(path, c, n);
        vx_err err = {0};
        vx_mesh *m = vx_draco_read_path(path, NULL, &err);
        if (m) {
            accepted++;
            for (size_t i = 0; i < 3 * m->ntris; i++)
                assert_true(m->tri[i] < m->nverts);
            vx_mesh_free(m);
        } else {
            rejected++;
            assert_true(err.kind == VX_EINVAL || err.kind == VX_EUNPROC || err.kind == VX_ETOOBIG ||
                        err.kind == VX_EINTERNAL);
        }
    }
    print_message("mutated Draco files: %d rejected, %d accepted\n", rejected, accepted);
    free(c);
    free(d);
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_obj_round_trip),   cmocka_unit_test(test_obj_round_trip_real),
        cmocka_unit_test(test_write_errors),     cmocka_unit_test(test_ply),
        cmocka_unit_test(test_draco_round_trip), cmocka_unit_test(test_draco_normals),
        cmocka_unit_test(test_draco_limits),     cmocka_unit_test(test_draco_point_cloud),
        cmocka_unit_test(test_draco_truncated),  cmocka_unit_test(test_draco_garbage),
        cmocka_unit_test(test_draco_mutations),  cmocka_unit_test(test_orientation),
        cmocka_unit_test(test_far_from_origin),
    };
    return cmocka_run_group_tests(tests, setup_dir, remove_dir);
}
