/* The fast writers (voxel/io.h: word-at-a-time raw8, raw1 and binvox, the
 * leaf-at-a-time OpenVDB tree) against simple references on random grids:
 * raw8, raw1 and binvox byte for byte against voxel-by-voxel encoders
 * written here; .vdb (every grid class) through the vdbcheck tool, which
 * builds its reference tree voxel by voxel through OpenVDB's accessor. */
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

#include "util/bigmem.h"
#include "voxel/io.h"
#include "voxel/voxel.h"

static char dir[] = "/tmp/vx-voxel-enc-XXXXXX";
static uint64_t rng = 88172645463325252ull;

static uint32_t rnd(void)
{
    rng ^= rng << 13;
    rng ^= rng >> 7;
    rng ^= rng << 17;
    return (uint32_t)(rng >> 16);
}

/* kind 0 empty, 1 full, 2 noise, 3 a few balls with noise on their rims
 * (full leaves, runs over 255 and partial leaves together). */
static void random_grid(vx_bitgrid *g, int nx, int ny, int nz, int kind, int counts)
{
    vx_grid gr = {{0.25, -3.0, 1.5}, 0.125, {nx, ny, nz}, {0, 0, 0}};
    assert_int_equal(vx_bitgrid_alloc(g, &gr, counts, NULL), 0);
    double c[3][4];
    for (int b = 0; b < 3; b++) {
        c[b][0] = rnd() % (unsigned)nx, c[b][1] = rnd() % (unsigned)ny;
        c[b][2] = rnd() % (unsigned)nz;
        c[b][3] = 2 + rnd() % (unsigned)(nx / 2 + 2);
    }
    g->nsamples = 8;
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                int v = kind == 1 || (kind == 2 && (rnd() & 1));
                for (int b = 0; kind == 3 && b < 3; b++) {
                    double dx = i - c[b][0], dy = j - c[b][1], dz = k - c[b][2];
                    double r2 = dx * dx + dy * dy + dz * dz, r = c[b][3];
                    v |= r2 < (r - 1) * (r - 1) || (r2 < (r + 1) * (r + 1) && (rnd() & 1));
                }
                if (v) g->bits[((size_t)k * ny + j) * g->wx + (size_t)(i >> 5)] |= 1u << (i & 31);
                if (counts) {
                    size_t L = ((size_t)k * ny + j) * nx + i;
                    g->counts[L] =
                        (uint8_t)(v ? (kind == 3 && (rnd() & 1) ? 8 : 1 + rnd() % 8) : 0);
                }
            }
}

/* ---- the references: one voxel at a time ---- */

static void ref_raw8(const vx_bitgrid *g, const char *p)
{
    FILE *f = fopen(p, "wb");
    const int *n = g->grid.dims;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++)
                putc(vx_bitgrid_get(g, i, j, k), f);
    fclose(f);
}

static void ref_raw1(const vx_bitgrid *g, const char *p)
{
    FILE *f = fopen(p, "wb");
    const int *n = g->grid.dims;
    unsigned acc = 0, nacc = 0;
    for (int k = 0; k < n[2]; k++)
        for (int j = 0; j < n[1]; j++)
            for (int i = 0; i < n[0]; i++) {
                acc |= (unsigned)vx_bitgrid_get(g, i, j, k) << nacc;
                if (++nacc == 8) putc((int)acc, f), acc = 0, nacc = 0;
            }
    if (nacc) putc((int)acc, f);
    fclose(f);
}

static void ref_binvox(const vx_bitgrid *g, const char *p)
{
    FILE *f = fopen(p, "wb");
    const int *n = g->grid.dims;
    int d = n[0] > n[1] ? n[0] : n[1];
    if (n[2] > d) d = n[2];
    fprintf(f, "#binvox 1\ndim %d %d %d\ntranslate %.17g %.17g %.17g\nscale %.17g\ndata\n", d, d, d,
            g->grid.origin[0], g->grid.origin[1], g->grid.origin[2], d * g->grid.h);
    int cur = -1, run = 0;
    for (int i = 0; i < d; i++)
        for (int k = 0; k < d; k++)
            for (int j = 0; j < d; j++) {
                int v = i < n[0] && j < n[1] && k < n[2] ? vx_bitgrid_get(g, i, j, k) : 0;
                if (v == cur && run < 255) {
                    run++;
                    continue;
                }
                if (run) putc(cur, f), putc(run, f);
                cur = v;
                run = 1;
            }
    if (run) putc(cur, f), putc(run, f);
    fclose(f);
}

static int same_file(const char *a, const char *b)
{
    char cmd[600];
    snprintf(cmd, sizeof cmd, "cmp -s %s %s", a, b);
    return system(cmd) == 0;
}

/* Widths on and off word and byte boundaries; 40 and 72: rows of whole
 * bytes that start mid-word in raw1; 65, 127 and 191: raw1's 64-bit
 * pieces with a tail of 1, 63 and 63 bits. */
static const int sizes[][3] = {{1, 1, 1},     {13, 5, 3},  {32, 32, 32}, {33, 70, 9}, {64, 8, 129},
                               {100, 37, 61}, {7, 300, 2}, {260, 3, 40}, {40, 9, 7},  {72, 130, 3},
                               {65, 17, 5},   {127, 9, 4}, {191, 5, 3}};

static void test_raw_binvox(void **st)
{
    char a[256], b[256];
    for (size_t s = 0; s < sizeof sizes / sizeof *sizes; s++)
        for (int kind = 0; kind < 4; kind++) {
            vx_bitgrid g;
            random_grid(&g, sizes[s][0], sizes[s][1], sizes[s][2], kind, 0);
            vx_err err;
            struct {
                const char *name;
                int (*fast)(const vx_bitgrid *, const char *, const vx_voxel_io *, vx_err *);
                void (*ref)(const vx_bitgrid *, const char *);
            } enc[] = {{"raw8", vx_voxel_write_raw8, ref_raw8},
                       {"raw1", vx_voxel_write_raw1, ref_raw1},
                       {"binvox", vx_voxel_write_binvox, ref_binvox}};
            for (int e = 0; e < 3; e++) {
                snprintf(a, sizeof a, "%s/fast.%s", dir, enc[e].name);
                snprintf(b, sizeof b, "%s/ref.%s", dir, enc[e].name);
                assert_int_equal(enc[e].fast(&g, a, NULL, &err), 0);
                enc[e].ref(&g, b);
                if (!same_file(a, b))
                    fail_msg("%s differs from the reference on %dx%dx%d kind %d", enc[e].name,
                             sizes[s][0], sizes[s][1], sizes[s][2], kind);
            }
            /* binvox's bounded coder (an event budget of 1 byte forces it)
             * in groups of 1, 2 and 3 blocks (the last group short), not
             * only the whole grid in one group */
            const size_t block = 32u * (size_t)sizes[s][2] * ((sizes[s][1] + 31u) / 32u) * 4u;
            for (size_t per = 1; per <= 3; per++) {
                vx_voxel_io io = {.binvox_group_bytes = per * block, .binvox_event_bytes = 1};
                snprintf(a, sizeof a, "%s/fast.binvox", dir);
                assert_int_equal(vx_voxel_write_binvox(&g, a, &io, &err), 0);
                if (!same_file(a, b))
                    fail_msg("binvox in groups of %zu blocks differs on %dx%dx%d kind %d", per,
                             sizes[s][0], sizes[s][1], sizes[s][2], kind);
            }
            /* the event coder's budget running out part way: the bounded
             * coder starts again from the header */
            vx_voxel_io part = {.binvox_event_bytes = 2048};
            assert_int_equal(vx_voxel_write_binvox(&g, a, &part, &err), 0);
            if (!same_file(a, b))
                fail_msg("binvox past a 2 KiB event budget differs on %dx%dx%d kind %d",
                         sizes[s][0], sizes[s][1], sizes[s][2], kind);
            vx_bitgrid_free(&g);
        }
}

/* raw1 on rows wider than its 16 KiB buffer, byte aligned
 * and not (binvox's cube would be 131080^3). */
static void test_raw_wide_rows(void **st)
{
    char a[256], b[256];
    const int wide[][3] = {{131080, 2, 3}, {131075, 3, 2}};
    for (int s = 0; s < 2; s++) {
        vx_bitgrid g;
        random_grid(&g, wide[s][0], wide[s][1], wide[s][2], 1, 0);
        vx_err err;
        snprintf(a, sizeof a, "%s/fast.raw1", dir);
        snprintf(b, sizeof b, "%s/ref.raw1", dir);
        assert_int_equal(vx_voxel_write_raw1(&g, a, NULL, &err), 0);
        ref_raw1(&g, b);
        if (!same_file(a, b))
            fail_msg("raw1 differs on %dx%dx%d", wide[s][0], wide[s][1], wide[s][2]);
        vx_bitgrid_free(&g);
    }
}

static void vdbcheck(const vx_bitgrid *g, vx_vdb_class cls, int coverage)
{
    char vdb[256], raw[256], cnt[256], cmd[1200];
    snprintf(vdb, sizeof vdb, "%s/x.vdb", dir);
    snprintf(raw, sizeof raw, "%s/x.raw8", dir);
    snprintf(cnt, sizeof cnt, "%s/x.counts", dir);
    vx_err err;
    ref_raw8(g, raw);
    vx_bitgrid gg = *g;
    if (!coverage) gg.counts = NULL;
    assert_int_equal(vx_voxel_write_vdb(&gg, cls, NULL, vdb, NULL, &err), 0);
    const int *n = g->grid.dims;
    int len = snprintf(cmd, sizeof cmd, "%s/vdbcheck %s %s %d %d %d", VX_TOOLS_DIR, vdb, raw, n[0],
                       n[1], n[2]);
    if (coverage) {
        FILE *f = fopen(cnt, "wb");
        fwrite(g->counts, 1, (size_t)n[0] * n[1] * n[2], f);
        fclose(f);
        snprintf(cmd + len, sizeof cmd - (size_t)len, " %s %d", cnt, g->nsamples);
    }
    if (system(cmd) != 0)
        fail_msg("vdbcheck failed: class %d coverage %d on %dx%dx%d", cls, coverage, n[0], n[1],
                 n[2]);
}

/* And for the vdb writer, rows of more than 128 bytes of leaves: its
 * classifier's blocks of 128 bytes, then of 32, then bytes (binvox's cube
 * of these would be 2 G voxels). */
static const int wide[][3] = {{1100, 9, 10}, {1301, 17, 9}};

static void test_vdb(void **st)
{
    const size_t ns = sizeof sizes / sizeof *sizes, nw = sizeof wide / sizeof *wide;
    for (size_t s = 0; s < ns + nw; s++)
        for (int kind = 0; kind < 4; kind++) {
            const int *n = s < ns ? sizes[s] : wide[s - ns];
            vx_bitgrid g;
            random_grid(&g, n[0], n[1], n[2], kind, 1);
            vdbcheck(&g, VX_VDB_BOOL, 0);
            vdbcheck(&g, VX_VDB_FOG, 0);
            vdbcheck(&g, VX_VDB_FOG, 1);
            vdbcheck(&g, VX_VDB_LEVEL_SET, 0);
            vx_bitgrid_free(&g);
        }
}

/* A 0/1 fog grid's leaves hold their masks only, their floats made as
 * they are written: its tree takes about what the bool grid's does (float
 * leaves would take ~8 times as much), within the bytes a job counts for
 * it at submission. Noise (every leaf partial) and balls (full leaves as
 * tiles too); vdbcheck reads the fog file back. */
static void test_vdb_fog_memory(void **st)
{
    char p[256];
    snprintf(p, sizeof p, "%s/fogmem.vdb", dir);
    for (int kind = 2; kind <= 3; kind++) {
        vx_bitgrid g;
        random_grid(&g, 90, 50, 200, kind, 0);
        uint64_t bytes[2];
        for (int c = 0; c < 2; c++) {
            vx_vdb_tree *t = NULL;
            vx_voxel_io io = {.vdb_keep = &t};
            vx_err err;
            assert_int_equal(
                vx_voxel_write_vdb(&g, c ? VX_VDB_FOG : VX_VDB_BOOL, NULL, p, &io, &err), 0);
            assert_non_null(t);
            bytes[c] = vx_vdb_tree_bytes(t);
            vx_vdb_tree_free(t);
        }
        assert_true(bytes[0] > 0);
        assert_true(bytes[1] < bytes[0] * 3 / 2);
        assert_true(bytes[1] <= vx_voxel_vdb_bytes(g.grid.dims, VX_VDB_FOG, 0));
        vdbcheck(&g, VX_VDB_FOG, 0);
        vx_bitgrid_free(&g);
    }
}

/* A level set's band leaves hold a byte a voxel, not their floats (made
 * as they are written): the tree and the file (about the buffers held at
 * the write) each fit in half the bytes a job counts for the grid. Noise
 * (every leaf partial, the band as wide as it gets) and balls. */
static void test_vdb_level_set_memory(void **st)
{
    char p[256];
    snprintf(p, sizeof p, "%s/lsmem.vdb", dir);
    for (int kind = 2; kind <= 3; kind++) {
        vx_bitgrid g;
        random_grid(&g, 90, 50, 200, kind, 0);
        vx_vdb_tree *t = NULL;
        vx_voxel_io io = {.vdb_keep = &t};
        vx_err err;
        assert_int_equal(vx_voxel_write_vdb(&g, VX_VDB_LEVEL_SET, NULL, p, &io, &err), 0);
        assert_non_null(t);
        const uint64_t tree = vx_vdb_tree_bytes(t),
                       counted = vx_voxel_vdb_grid_bytes(&g, VX_VDB_LEVEL_SET);
        vx_vdb_tree_free(t);
        struct stat sb;
        assert_int_equal(stat(p, &sb), 0);
        if (tree > counted / 2 || (uint64_t)sb.st_size > counted / 2)
            fail_msg("level set kind %d: tree %llu, file %lld bytes, counted %llu", kind,
                     (unsigned long long)tree, (long long)sb.st_size, (unsigned long long)counted);
        vdbcheck(&g, VX_VDB_LEVEL_SET, 0);
        vx_bitgrid_free(&g);
    }
}

/* vx_vdb_voxel_size_ok is OpenVDB's own bound, with a margin of 1e-6 on
 * h^3: a grid of voxel vx_vdb_min_voxel_size (at an origin off zero) writes,
 * and 1e-6 under it the check refuses and OpenVDB's writer fails too (a job
 * refuses such a grid before it runs). */
static void test_vdb_min_voxel(void **st)
{
    const double h = vx_vdb_min_voxel_size(), under = h * (1 - 1e-6);
    assert_true(h > 1.44e-5 && h < 1.45e-5);
    assert_true(vx_vdb_voxel_size_ok(h));
    assert_false(vx_vdb_voxel_size_ok(under));
    assert_false(vx_vdb_voxel_size_ok(NAN));
    /* a level set's background, 3 voxels, is a float: finite up to the max */
    const double max = vx_vdb_max_voxel_size(VX_VDB_LEVEL_SET);
    assert_true(isfinite((float)(3 * max)));
    assert_false(isfinite((float)(3 * max * (1 + 1e-6))));
    assert_true(isinf(vx_vdb_max_voxel_size(VX_VDB_FOG)));
    vx_bitgrid g;
    random_grid(&g, 16, 16, 16, 3, 0);
    char p[256];
    snprintf(p, sizeof p, "%s/minvoxel.vdb", dir);
    vx_err err;
    g.grid.h = h;
    assert_int_equal(vx_voxel_write_vdb(&g, VX_VDB_FOG, NULL, p, NULL, &err), 0);
    g.grid.h = under;
    assert_int_equal(vx_voxel_write_vdb(&g, VX_VDB_FOG, NULL, p, NULL, &err), -1);
    vx_bitgrid_free(&g);
}

/* The progress hook: fractions seen, in order. */
typedef struct seen {
    double f[4096];
    int n;
} seen;

static int record(void *ud, double f, vx_err *err)
{
    seen *s = ud;
    if (s->n < 4096) s->f[s->n++] = f;
    return 0;
}

/* Every writer moves the progress while it writes (the job's bar follows
 * it): at least two distinct fractions strictly between 0 and 1, never
 * going back, and 1 at most. (160 slices: vox reports per 16 slices of a
 * model, and one of the two models may be empty.) */
static void test_progress(void **st)
{
    vx_bitgrid g;
    random_grid(&g, 300, 70, 160, 3, 0);
    static const char *const names[] = {"raw8", "raw1",     "binvox",  "nrrd",         "npy",
                                        "vox",  "vdb bool", "vdb fog", "vdb level_set"};
    int (*const fns[])(const vx_bitgrid *, const char *, const vx_voxel_io *,
                       vx_err *) = {vx_voxel_write_raw8, vx_voxel_write_raw1, vx_voxel_write_binvox,
                                    vx_voxel_write_nrrd, vx_voxel_write_npy,  vx_voxel_write_vox};
    char p[256];
    snprintf(p, sizeof p, "%s/progress.out", dir);
    for (int w = 0; w < 9; w++) {
        static seen s;
        s.n = 0;
        vx_voxel_io io = {.progress = record, .ud = &s};
        vx_err err;
        int rc = w < 6 ? fns[w](&g, p, &io, &err)
                       : vx_voxel_write_vdb(&g,
                                            w == 6   ? VX_VDB_BOOL
                                            : w == 7 ? VX_VDB_FOG
                                                     : VX_VDB_LEVEL_SET,
                                            NULL, p, &io, &err);
        assert_int_equal(rc, 0);
        int inner = 0;
        for (int i = 0; i < s.n; i++) {
            if (i && s.f[i] < s.f[i - 1]) fail_msg("%s: progress went back", names[w]);
            if (s.f[i] > 1.0) fail_msg("%s: progress past 1", names[w]);
            inner += s.f[i] > 0 && s.f[i] < 1 && (!i || s.f[i] != s.f[i - 1]);
        }
        if (inner < 2) fail_msg("%s: %d distinct fractions inside (0, 1)", names[w], inner);
    }
    vx_bitgrid_free(&g);
}

/* A hook that stops the write once the fraction reaches at. */
typedef struct stopper {
    double at;
    int calls;
} stopper;

static int stop_at(void *ud, double f, vx_err *err)
{
    stopper *s = ud;
    s->calls++;
    if (f < s->at) return 0;
    vx_err_set(err, VX_ECANCELED, "canceled", "stopped at %.3f", f);
    return 1;
}

/* binvox stopped while it gathers its events (at its first call, below
 * 0.6), while it measures its runs (0.6 to 0.7), while it writes them (0.7
 * on), and in its bounded coder: -1 with the hook's error, and neither
 * the file nor its temporary left. */
static void test_binvox_stop(void **st)
{
    vx_bitgrid g;
    random_grid(&g, 300, 70, 64, 3, 0);
    char p[256], tmp[300];
    snprintf(p, sizeof p, "%s/stop.binvox", dir);
    snprintf(tmp, sizeof tmp, "%s.tmp", p);
    const double ats[] = {0.0, 0.3, 0.6, 0.7, 0.0, 0.5};
    for (int i = 0; i < 6; i++) {
        stopper s = {ats[i], 0};
        vx_voxel_io io = {.progress = stop_at, .ud = &s, .binvox_event_bytes = i < 4 ? 0 : 1};
        vx_err err = {0};
        assert_int_equal(vx_voxel_write_binvox(&g, p, &io, &err), -1);
        assert_int_equal(err.kind, VX_ECANCELED);
        assert_string_equal(err.code, "canceled");
        assert_true(s.calls > 0);
        assert_int_equal(access(p, F_OK), -1);
        assert_int_equal(access(tmp, F_OK), -1);
    }
    vx_bitgrid_free(&g);
}

static int setup(void **st)
{
    /* as the daemon runs them: freed scratch kept and handed out again as
     * left (binvox's event arenas), so a coder that read what it had not
     * written would read the last write's */
    vx_bigmem_keep((size_t)256 << 20);
    return mkdtemp(dir) ? 0 : -1;
}

static int teardown(void **st)
{
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf %s", dir);
    return system(cmd) == 0 ? 0 : -1;
}

int main(void)
{
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_raw_binvox),
        cmocka_unit_test(test_raw_wide_rows),
        cmocka_unit_test(test_vdb),
        cmocka_unit_test(test_vdb_fog_memory),
        cmocka_unit_test(test_vdb_level_set_memory),
        cmocka_unit_test(test_vdb_min_voxel),
        cmocka_unit_test(test_progress),
        cmocka_unit_test(test_binvox_stop),
    };
    return cmocka_run_group_tests(tests, setup, teardown);
}
