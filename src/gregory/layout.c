/* The tessellation layout (tess.h): divisions, welding by corner keys,
 * triangles. CPU only; built once per topology. */
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>

#include "gregory/tess.h"
#include "util/stop.h"

enum { NONE = UINT32_MAX };

typedef struct pedge {
    uint32_t lo, hi; /* corner keys, lo <= hi */
    uint32_t curve;  /* which boundary curve between lo and hi (curve_classes) */
    uint32_t pe;     /* 4 * patch + edge */
} pedge;

static int pedge_cmp(const void *a, const void *b)
{
    const pedge *x = a, *y = b;
    if (x->lo != y->lo) return x->lo < y->lo ? -1 : 1;
    if (x->hi != y->hi) return x->hi < y->hi ? -1 : 1;
    if (x->curve != y->curve) return x->curve < y->curve ? -1 : 1;
    return x->pe < y->pe ? -1 : x->pe > y->pe;
}

/* Sorts e, whose pe are 0..n-1 in any order, into pedge_cmp's order:
 * placed by pe, then stable radix passes of 16 bits over curve, hi and lo
 * (a pass whose digit is one value everywhere is skipped). qsort took
 * ~0.5 s on ogre's 1.5M patch edges, with no stop check inside. */
static void sort_edges(pedge *e, size_t n)
{
    pedge *t = malloc(n * sizeof *t + 1);
    uint32_t *cnt = malloc(65537 * sizeof *cnt);
    if (!t || !cnt) {
        free(t);
        free(cnt);
        qsort(e, n, sizeof *e, pedge_cmp);
        return;
    }
    for (size_t q = 0; q < n; q++)
        t[e[q].pe] = e[q];
    pedge *a = t, *b = e;
    for (int pass = 0; pass < 6; pass++) {
        int shift = (pass % 2) * 16;
        size_t off = pass < 2   ? offsetof(pedge, curve)
                     : pass < 4 ? offsetof(pedge, hi)
                                : offsetof(pedge, lo);
#define DIGIT(x) ((*(const uint32_t *)((const char *)(x) + off) >> shift) & 0xffffu)
        memset(cnt, 0, 65537 * sizeof *cnt);
        for (size_t q = 0; q < n; q++)
            cnt[DIGIT(&a[q]) + 1]++;
        if (n == 0 || cnt[DIGIT(&a[0]) + 1] == n) continue;
        for (int d = 0; d < 65536; d++)
            cnt[d + 1] += cnt[d];
        for (size_t q = 0; q < n; q++)
            b[cnt[DIGIT(&a[q])]++] = a[q];
#undef DIGIT
        pedge *x = a;
        a = b;
        b = x;
    }
    if (a != e) memcpy(e, a, n * sizeof *e);
    free(t);
    free(cnt);
}

/* Control point slots of patch edge e, from corner e to corner e + 1. */
static const int edge_slots[4][4] = {{0, 1, 2, 3}, {3, 7, 11, 15}, {15, 14, 13, 12}, {12, 8, 4, 0}};

/* The two inner control points of patch edge pe, run from its lo corner to
 * its hi corner, and the length of its control polygon. */
static double edge_inner(const vx_gpatch_set *s, const pedge *e, double in[6])
{
    const double *cp = s->cp + (size_t)(e->pe / 4) * VX_GPATCH_POINTS * 3;
    const int *sl = edge_slots[e->pe % 4];
    int fwd = s->corner_key[e->pe] == e->lo;
    memcpy(in, cp + 3 * sl[fwd ? 1 : 2], 3 * sizeof *in);
    memcpy(in + 3, cp + 3 * sl[fwd ? 2 : 1], 3 * sizeof *in);
    double len = 0;
    for (int i = 0; i < 3; i++) {
        const double *a = cp + 3 * sl[i], *b = cp + 3 * sl[i + 1];
        len += sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                    (a[2] - b[2]) * (a[2] - b[2]));
    }
    return len;
}

/* Patch edges with the same two corner keys are one edge only when they are
 * one boundary curve: their inner control points agree to 1e-6 of the
 * curve's control polygon (one curve computed twice agrees to rounding;
 * the two halves of a tube's cross-section through the same two points do
 * not). Numbers the curves of each run of equal corner keys in e[lo..hi).
 * A run of more than 64 different curves (no real surface has one) gives
 * the rest a curve each, so the time stays linear. */
enum { MAX_CURVES = 64 };
static void curve_classes(const vx_gpatch_set *s, pedge *e, size_t lo, size_t hi)
{
    double rep[MAX_CURVES][6], tol[MAX_CURVES];
    uint32_t ncurves = 0;
    for (size_t k = lo; k < hi; k++) {
        double in[6], len = edge_inner(s, &e[k], in);
        uint32_t c = 0;
        for (; c < ncurves; c++) {
            double d = 0;
            for (int i = 0; i < 6; i++)
                d = fmax(d, fabs(in[i] - rep[c][i]));
            if (d <= fmax(tol[c], 1e-6 * len)) break;
        }
        if (c == ncurves && ncurves < MAX_CURVES) {
            memcpy(rep[c], in, sizeof in);
            tol[c] = 1e-6 * len;
            ncurves++;
        }
        e[k].curve = c < MAX_CURVES ? c : (uint32_t)(MAX_CURVES + (k - lo));
    }
}

/* Patch edges sorted by their corner keys and curves: equal neighbours
 * share an edge. Depends on the control points as well as the keys: a
 * layout is made from the first frame's patches. NULL with err when out
 * of memory or the thread's stop hook says stop. */
static pedge *sorted_edges(const vx_gpatch_set *s, vx_err *err)
{
    pedge *e = malloc((4 * s->npatches + 1) * sizeof *e);
    if (!e) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the tessellation layout");
        return NULL;
    }
    size_t n = 4 * s->npatches;
    for (size_t q = 0; q < n; q++) {
        uint32_t a = s->corner_key[q], b = s->corner_key[4 * (q / 4) + (q % 4 + 1) % 4];
        e[q].lo = a < b ? a : b;
        e[q].hi = a < b ? b : a;
        e[q].curve = 0;
        e[q].pe = (uint32_t)q;
    }
    sort_edges(e, n);
    int split = 0;
    for (size_t q = 0, polled = 0; q < n;) {
        if (q - polled >= 65536) {
            polled = q;
            if (vx_stop_poll(err)) {
                free(e);
                return NULL;
            }
        }
        size_t r = q + 1;
        while (r < n && e[r].lo == e[q].lo && e[r].hi == e[q].hi)
            r++;
        if (r - q > 1 && e[q].lo != e[q].hi) {
            curve_classes(s, e, q, r);
            for (size_t k = q; k < r; k++)
                split |= e[k].curve != 0;
        }
        q = r;
    }
    if (split) sort_edges(e, n);
    if (vx_stop_poll(err)) {
        free(e);
        return NULL;
    }
    return e;
}

static int same_edge(const pedge *a, const pedge *b)
{
    return a->lo == b->lo && a->hi == b->hi && a->curve == b->curve;
}

static int oom(vx_err *err)
{
    return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the tessellation layout");
}

static uint32_t uf_find(uint32_t *par, uint32_t x)
{
    while (par[x] != x) {
        par[x] = par[par[x]];
        x = par[x];
    }
    return x;
}

uint32_t *vx_gregory_divisions(const vx_gpatch_set *s, int n, double max_edge, vx_err *err)
{
    uint32_t *nd = malloc((s->npatches + 1) * sizeof *nd);
    if (!nd) {
        oom(err);
        return NULL;
    }
    for (size_t p = 0; p < s->npatches; p++)
        nd[p] = (uint32_t)n;
    if (!(max_edge > 0)) return nd;
    for (size_t p = 0; p < s->npatches; p++) {
        const double *cp = s->cp + p * VX_GPATCH_POINTS * 3;
        double longest = 0;
        /* A curve's length is at most its control polygon's length. */
        for (int e = 0; e < 4; e++) {
            double len = 0;
            for (int i = 0; i < 3; i++) {
                const double *a = cp + 3 * edge_slots[e][i], *b = cp + 3 * edge_slots[e][i + 1];
                len += sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                            (a[2] - b[2]) * (a[2] - b[2]));
            }
            if (len > longest) longest = len;
        }
        double need = ceil(longest / max_edge);
        nd[p] = need < 1                          ? 1
                : need > VX_GREGORY_MAX_DIVISIONS ? VX_GREGORY_MAX_DIVISIONS
                                                  : (uint32_t)need;
    }
    /* A patch of 1 division next to a finer one gets 2, so that it has an
     * interior for the transition strip: every patch of 1 in a component
     * (patches joined by shared edges) that has a finer patch. */
    uint32_t *par = malloc((s->npatches + 1) * sizeof *par), *top = NULL;
    pedge *e = sorted_edges(s, err); /* NULL: err says why */
    if (par) top = calloc(s->npatches + 1, sizeof *top);
    if (!par || !top || !e) {
        if (e) oom(err);
        free(par);
        free(top);
        free(e);
        free(nd);
        return NULL;
    }
    /* Graded: no patch under half of a neighbour's N, so that the zipper
     * strip of a transition patch never fans one inner point out to many
     * points of a much finer edge (thin triangles that turn over on a
     * strongly curved patch). N only rises, to at most the largest N, so
     * the passes end; each carries the grading across many patches. */
    for (int changed = 1; changed;) {
        changed = 0;
        for (size_t q = 1; q < 4 * s->npatches; q++) {
            if (!same_edge(&e[q], &e[q - 1]) || e[q].lo == e[q].hi) continue;
            uint32_t a = e[q].pe / 4, b = e[q - 1].pe / 4;
            if (nd[a] < (nd[b] + 1) / 2) nd[a] = (nd[b] + 1) / 2, changed = 1;
            if (nd[b] < (nd[a] + 1) / 2) nd[b] = (nd[a] + 1) / 2, changed = 1;
        }
    }
    for (size_t p = 0; p < s->npatches; p++)
        par[p] = (uint32_t)p;
    for (size_t q = 1; q < 4 * s->npatches; q++)
        if (same_edge(&e[q], &e[q - 1]) && e[q].lo != e[q].hi) {
            uint32_t a = uf_find(par, e[q].pe / 4), b = uf_find(par, e[q - 1].pe / 4);
            if (a != b) par[a] = b;
        }
    for (size_t p = 0; p < s->npatches; p++) {
        uint32_t r = uf_find(par, (uint32_t)p);
        if (nd[p] > top[r]) top[r] = nd[p];
    }
    for (size_t p = 0; p < s->npatches; p++)
        if (nd[p] == 1 && top[uf_find(par, (uint32_t)p)] > 1) nd[p] = 2;
    free(par);
    free(top);
    free(e);
    return nd;
}

void vx_gregory_layout_free(vx_gtess_layout *l)
{
    if (!l) return;
    free(l->ndiv);
    free(l->voff);
    free(l->rep);
    free(l->share);
    free(l->tri);
    free(l->tri_patch);
    free(l);
}

/* Divisions of every patch edge, ne (the most of the patches on it; a
 * collapsed edge keeps its patch's), and src, the patch edge whose grid
 * gives its points (one of the patches with that many). Both 4 * npatches. */
static int edge_divisions(const vx_gpatch_set *s, const uint32_t *ndiv, uint32_t *ne, uint32_t *src,
                          vx_err *err)
{
    pedge *e = sorted_edges(s, err); /* polls the stop hook */
    if (!e) return -1;
    size_t n = 4 * s->npatches;
    for (size_t q = 0; q < n;) {
        size_t r = q, best = q;
        while (r < n && same_edge(&e[r], &e[q])) {
            if (ndiv[e[r].pe / 4] > ndiv[e[best].pe / 4]) best = r;
            r++;
        }
        for (size_t k = q; k < r; k++) {
            int collapsed = e[k].lo == e[k].hi;
            ne[e[k].pe] = ndiv[(collapsed ? e[k] : e[best]).pe / 4];
            src[e[k].pe] = (collapsed ? e[k] : e[best]).pe;
        }
        q = r;
    }
    free(e);
    return 0;
}

/* A patch with an edge finer than itself is a transition patch: inner grid
 * plus a zipper strip to its outer loop. */
static int is_transition(const uint32_t *ne, const uint32_t *ndiv, size_t p)
{
    for (int ed = 0; ed < 4; ed++)
        if (ne[4 * p + ed] != ndiv[p]) return 1;
    return 0;
}

/* Output vertices of patch p on its own (interior points, then its outer
 * loop) and its triangles, before welding and before dropping collapsed
 * ones. */
static void patch_counts(const uint32_t *ne, const uint32_t *ndiv, size_t p, uint64_t *verts,
                         uint64_t *tris)
{
    uint64_t n = ndiv[p], loop = 0;
    for (int ed = 0; ed < 4; ed++)
        loop += ne[4 * p + ed];
    *verts = (n - 1) * (n - 1) + loop;
    /* inner grid of (n - 2)^2 quads, and a strip of one triangle per step
     * along the inner ring (4 (n - 2) points) and the outer loop (a patch
     * of 1 with a finer edge is refused by the layout) */
    *tris = n >= 2 && is_transition(ne, ndiv, p) ? 2 * (n - 2) * (n - 2) + 4 * (n - 2) + loop
                                                 : 2 * n * n;
}

int vx_gregory_count(const vx_gpatch_set *s, const uint32_t *ndiv, uint64_t *grid_verts,
                     uint64_t *verts, uint64_t *tris, vx_err *err)
{
    size_t np = s->npatches;
    uint32_t *ne = malloc((4 * np + 1) * sizeof *ne), *src = malloc((4 * np + 1) * sizeof *src);
    if (!ne || !src || edge_divisions(s, ndiv, ne, src, err)) {
        if (!ne || !src) oom(err);
        free(ne);
        free(src);
        return -1;
    }
    uint64_t g = 0, v = 0, t = 0;
    for (size_t p = 0; p < np; p++) {
        if ((p & 0xffff) == 0 && vx_stop_poll(err)) {
            free(ne);
            free(src);
            return -1;
        }
        uint64_t pv, pt, n = ndiv[p];
        patch_counts(ne, ndiv, p, &pv, &pt);
        g += (n + 1) * (n + 1);
        v += pv;
        t += pt;
    }
    free(ne);
    free(src);
    *grid_verts = g;
    *verts = v;
    *tris = t;
    return 0;
}

typedef struct lctx {
    const vx_gpatch_set *s;
    vx_gtess_layout *l;
    uint32_t *ne, *src;  /* edge_divisions */
    uint32_t *corner_id; /* welded: per corner key */
    uint32_t *edge_base; /* welded: first id of the inner points of an edge, at its src */
    uint64_t *pbase;     /* first own (interior, then unwelded loop) id of each patch */
    uint8_t *valence;    /* patch corners per corner key (saturating at 255) */
    uint64_t *wrep;      /* unwelded: the grid vertex that gives each shared id */
} lctx;

/* Grid index of point t (0..n) along edge ed of patch p's own grid, from
 * corner ed to corner ed + 1. */
static uint64_t edge_grid(const vx_gtess_layout *l, size_t p, int ed, uint32_t t)
{
    uint32_t n = l->ndiv[p], i, j;
    switch (ed) {
    case 0:
        i = t, j = 0;
        break;
    case 1:
        i = n, j = t;
        break;
    case 2:
        i = n - t, j = n;
        break;
    default:
        i = 0, j = n - t;
        break;
    }
    return l->voff[p] + (uint64_t)j * (n + 1) + i;
}

/* The grid vertex that gives point t (0..ne) of patch edge (p, ed): the
 * patch's own, or on an edge finer than the patch, its src neighbour's (the
 * same boundary curve, maybe run the other way). */
static uint64_t loop_grid(const lctx *c, size_t p, int ed, uint32_t t)
{
    uint32_t pe = (uint32_t)(4 * p + (size_t)ed), n = c->ne[pe], q = c->src[pe];
    if (n == c->l->ndiv[p]) return edge_grid(c->l, p, ed, t);
    int same = c->s->corner_key[pe] == c->s->corner_key[q];
    return edge_grid(c->l, q / 4, (int)(q % 4), same ? t : n - t);
}

/* Output id of point t (0..ne) of patch edge (p, ed). */
static uint32_t loop_id(const lctx *c, size_t p, int ed, uint32_t t);

/* The welded id of point t (0..ne, t < ne) of patch edge (p, ed): one per
 * corner key and per point of each shared edge (in an unwelded layout, the
 * numbering of the points that patches share). */
static uint32_t shared_id(const lctx *c, size_t p, int ed, uint32_t t)
{
    uint32_t pe = (uint32_t)(4 * p + (size_t)ed), n = c->ne[pe];
    const uint32_t *key = c->s->corner_key + 4 * p;
    uint32_t ka = key[ed], kb = key[(ed + 1) % 4];
    if (t == 0 || ka == kb) return c->corner_id[ka];
    uint32_t base = c->edge_base[c->src[pe]];
    return ka < kb ? base + t - 1 : base + n - t - 1;
}

/* Output id of point t (0..ne) of patch edge (p, ed). */
static uint32_t loop_id(const lctx *c, size_t p, int ed, uint32_t t)
{
    if (t == c->ne[4 * p + (size_t)ed]) ed = (ed + 1) % 4, t = 0; /* the next edge's corner */
    uint32_t nd = c->l->ndiv[p];
    if (c->l->weld) return shared_id(c, p, ed, t);
    uint64_t off = c->pbase[p] + (uint64_t)(nd - 1) * (nd - 1) + t;
    for (int e = 0; e < ed; e++)
        off += c->ne[4 * p + (size_t)e];
    return (uint32_t)off;
}

/* Output id of grid vertex (i, j) of patch p where its edges have its own
 * divisions (or (i, j) is interior). */
static uint32_t grid_id(const lctx *c, size_t p, uint32_t i, uint32_t j)
{
    uint32_t n = c->l->ndiv[p];
    if (i > 0 && i < n && j > 0 && j < n)
        return (uint32_t)(c->pbase[p] + (uint64_t)(j - 1) * (n - 1) + (i - 1));
    if (j == 0) return loop_id(c, p, 0, i);
    if (i == n) return loop_id(c, p, 1, j);
    if (j == n) return loop_id(c, p, 2, n - i);
    return loop_id(c, p, 3, n - j);
}

/* Output ids: corners, edge points and interiors (welded), or each patch's
 * own; the next free id. */
static uint64_t assign_ids(lctx *c, uint64_t *nshared)
{
    const vx_gpatch_set *s = c->s;
    size_t np = s->npatches;
    uint64_t next = 0;
    for (size_t q = 0; q < 4 * np; q++)
        if (c->corner_id[s->corner_key[q]] == NONE)
            c->corner_id[s->corner_key[q]] = (uint32_t)next++;
    for (size_t q = 0; q < 4 * np; q++) {
        uint32_t ka = s->corner_key[q], kb = s->corner_key[4 * (q / 4) + (q % 4 + 1) % 4];
        if (c->src[q] != q || ka == kb) continue; /* one per edge; a collapsed edge is its corner */
        c->edge_base[q] = (uint32_t)next;
        next += c->ne[q] - 1;
    }
    *nshared = next;
    if (!c->l->weld) next = 0; /* the shared ids only say which points are one */
    for (size_t p = 0; p < np; p++) {
        uint64_t pv, pt, n = c->l->ndiv[p];
        c->pbase[p] = next;
        patch_counts(c->ne, c->l->ndiv, p, &pv, &pt);
        next += c->l->weld ? (n - 1) * (n - 1) : pv;
    }
    return next;
}

static void emit(vx_gtess_layout *l, size_t p, uint32_t a, uint32_t b, uint32_t d)
{
    if (a == b || b == d || a == d) return; /* collapsed onto a degenerate edge */
    uint32_t *x = l->tri + 3 * l->ntris;
    x[0] = a, x[1] = b, x[2] = d;
    l->tri_patch[l->ntris++] = (uint32_t)p;
}

/* Whether the quad (i, j) of patch p is cut by its (i+1, j)-(i, j+1)
 * diagonal. A triangle of two edge points and the patch corner between them
 * (an ear) would be made twice, once in each orientation, where only two
 * patches meet at that corner: the quads at corners 1 and 3 are cut
 * through the corner, as those at 0 and 2 are. A patch of one division
 * (one quad, one diagonal) is cut through the corners 1 and 3 when one of
 * them has two patches and neither 0 nor 2 has. */
static int anti_diagonal(const lctx *c, size_t p, uint32_t i, uint32_t j)
{
    uint32_t n = c->l->ndiv[p];
    if (n >= 2) return (i == n - 1 && j == 0) || (i == 0 && j == n - 1);
    if (!c->valence) return 0;
    const uint32_t *key = c->s->corner_key + 4 * p;
    int two[4];
    for (int k = 0; k < 4; k++)
        two[k] = c->valence[key[k]] == 2;
    return (two[1] || two[3]) && !two[0] && !two[2];
}

/* Quads (i, j)..(i + 1, j + 1) for i, j in lo..hi - 1, two triangles each. */
static void grid_tris(const lctx *c, size_t p, uint32_t lo, uint32_t hi)
{
    for (uint32_t j = lo; j < hi; j++)
        for (uint32_t i = lo; i < hi; i++) {
            uint32_t a = grid_id(c, p, i, j), b = grid_id(c, p, i + 1, j),
                     cc = grid_id(c, p, i + 1, j + 1), d = grid_id(c, p, i, j + 1);
            if (lo == 0 && anti_diagonal(c, p, i, j)) {
                emit(c->l, p, a, b, d);
                emit(c->l, p, b, cc, d);
            } else {
                emit(c->l, p, a, b, cc);
                emit(c->l, p, a, cc, d);
            }
        }
}

/* Point r of the inner ring (the boundary of the grid 1..n-1, walked like
 * the outer loop: m = n - 2 points per side). */
static uint32_t ring_id(const lctx *c, size_t p, uint32_t r)
{
    uint32_t n = c->l->ndiv[p], m = n - 2;
    if (m == 0) return grid_id(c, p, 1, 1);
    r %= 4 * m;
    uint32_t k = r % m;
    switch (r / m) {
    case 0:
        return grid_id(c, p, 1 + k, 1);
    case 1:
        return grid_id(c, p, n - 1, 1 + k);
    case 2:
        return grid_id(c, p, n - 1 - k, n - 1);
    default:
        return grid_id(c, p, 1, n - 1 - k);
    }
}

/* A transition patch of 2: its centre fans to the outer loop (as the 2 x 2
 * grid does, its corner quads cut through the corners). */
static void transition_fan(const lctx *c, size_t p)
{
    const uint32_t *ne = c->ne + 4 * p;
    uint32_t loop[4 * VX_GREGORY_MAX_DIVISIONS], n = 0, centre = grid_id(c, p, 1, 1);
    for (int ed = 0; ed < 4; ed++)
        for (uint32_t t = 0; t < ne[ed]; t++)
            loop[n++] = loop_id(c, p, ed, t);
    for (uint32_t b = 0; b < n; b++)
        emit(c->l, p, loop[b], loop[(b + 1) % n], centre);
}

/* A transition patch: inner grid, then the strip between the inner ring
 * and the outer loop, both walked by the perimeter parameter in [0, 4)
 * (edge e at fraction f is e + f on either loop), always advancing the loop
 * whose next segment's midpoint comes first (so a side of the inner ring
 * shares the outer points between its two ends). Counter-clockwise in
 * (u, v), as the grid's triangles. */
static void transition_tris(const lctx *c, size_t p)
{
    uint32_t n = c->l->ndiv[p], m = n - 2, ring = 4 * m;
    const uint32_t *ne = c->ne + 4 * p;
    if (m == 0) return transition_fan(c, p);
    grid_tris(c, p, 1, n - 1);
    uint32_t a = 0, ed = 0, t = 0; /* inner steps; outer position */
    while (a < ring || ed < 4) {
        double ti = a < ring ? (a + 0.5) / m : INFINITY;
        double to = ed < 4 ? ed + (t + 0.5) / ne[ed] : INFINITY;
        uint32_t o = loop_id(c, p, (int)(ed % 4), t);
        if (to <= ti) {
            emit(c->l, p, o, loop_id(c, p, (int)ed, t + 1), ring_id(c, p, a));
            if (++t == ne[ed]) ed++, t = 0;
        } else {
            emit(c->l, p, o, ring_id(c, p, a + 1), ring_id(c, p, a));
            a++;
        }
    }
}

/* Per corner key: its welded id (NONE until assign_ids) and its valence;
 * the edge bases. -1 on allocation failure. */
static int key_tables(lctx *c)
{
    const vx_gpatch_set *s = c->s;
    size_t np = s->npatches;
    uint32_t maxkey = 0;
    for (size_t q = 0; q < 4 * np; q++)
        if (s->corner_key[q] > maxkey) maxkey = s->corner_key[q];
    c->corner_id = malloc(((size_t)maxkey + 1) * sizeof *c->corner_id);
    c->edge_base = malloc((4 * np + 1) * sizeof *c->edge_base);
    c->valence = calloc((size_t)maxkey + 1, 1);
    if (!c->corner_id || !c->edge_base || !c->valence) return -1;
    for (size_t k = 0; k <= maxkey; k++)
        c->corner_id[k] = NONE;
    for (size_t q = 0; q < 4 * np; q++)
        if (c->valence[s->corner_key[q]] < 255) c->valence[s->corner_key[q]]++;
    return 0;
}

/* The grid vertex of every output vertex (the first patch that has it
 * gives it) and, unwelded, of every shared point. -1 with the stop hook's
 * err. */
static int fill_reps(lctx *c, vx_err *err)
{
    vx_gtess_layout *l = c->l;
    for (size_t p = 0; p < l->npatches; p++) {
        uint32_t n = l->ndiv[p];
        if (vx_stop_poll(err)) return -1;
        for (uint32_t j = 1; j < n; j++)
            for (uint32_t i = 1; i < n; i++)
                l->rep[grid_id(c, p, i, j)] = l->voff[p] + (uint64_t)j * (n + 1) + i;
        for (int ed = 0; ed < 4; ed++)
            for (uint32_t t = 0; t < c->ne[4 * p + (size_t)ed]; t++) {
                uint32_t v = loop_id(c, p, ed, t);
                if (l->rep[v] == UINT64_MAX) l->rep[v] = loop_grid(c, p, ed, t);
                if (l->weld) continue;
                uint32_t w = shared_id(c, p, ed, t);
                if (c->wrep[w] == UINT64_MAX) c->wrep[w] = l->rep[v];
                l->share[v] = c->wrep[w];
            }
    }
    return 0;
}

vx_gtess_layout *vx_gregory_layout_new(const vx_gpatch_set *s, const uint32_t *ndiv, int weld,
                                       vx_err *err)
{
    size_t np = s->npatches;
    lctx c = {.s = s};
    vx_gtess_layout *l = calloc(1, sizeof *l);
    if (!l) {
        oom(err);
        return NULL;
    }
    c.l = l;
    l->npatches = np;
    l->weld = weld;
    l->ndiv = malloc((np + 1) * sizeof *l->ndiv);
    l->voff = malloc((np + 1) * sizeof *l->voff);
    c.ne = malloc((4 * np + 1) * sizeof *c.ne);
    c.src = malloc((4 * np + 1) * sizeof *c.src);
    c.pbase = malloc((np + 1) * sizeof *c.pbase);
    if (!l->ndiv || !l->voff || !c.ne || !c.src || !c.pbase) goto fail_oom;
    memcpy(l->ndiv, ndiv, np * sizeof *ndiv);
    if (edge_divisions(s, ndiv, c.ne, c.src, err)) goto fail;
    uint64_t gv = 0, nt = 0;
    l->voff[0] = 0;
    for (size_t p = 0; p < np; p++) {
        uint64_t pv, pt;
        patch_counts(c.ne, ndiv, p, &pv, &pt);
        nt += pt;
        l->voff[p + 1] = l->voff[p] + (uint64_t)(ndiv[p] + 1) * (ndiv[p] + 1);
        if (ndiv[p] < 2 && is_transition(c.ne, ndiv, p)) {
            vx_err_set(err, VX_EUNPROC, "gregory_divisions",
                       "patch %zu has %u division next to a finer patch (a transition needs 2)", p,
                       ndiv[p]);
            goto fail;
        }
    }
    gv = l->voff[np];
    if (gv >= UINT32_MAX) goto fail_big;
    if (key_tables(&c)) goto fail_oom;
    uint64_t nshared, nv = assign_ids(&c, &nshared);
    if (nv >= UINT32_MAX || nshared >= UINT32_MAX) goto fail_big;
    l->nverts = (size_t)nv;
    l->rep = malloc((l->nverts + 1) * sizeof *l->rep);
    l->tri = malloc((3 * nt + 1) * sizeof *l->tri);
    l->tri_patch = malloc((nt + 1) * sizeof *l->tri_patch);
    if (!weld) {
        l->share = malloc((l->nverts + 1) * sizeof *l->share);
        c.wrep = malloc((nshared + 1) * sizeof *c.wrep);
        if (!l->share || !c.wrep) goto fail_oom;
        for (size_t v = 0; v < nshared; v++)
            c.wrep[v] = UINT64_MAX;
        for (size_t v = 0; v < l->nverts; v++)
            l->share[v] = UINT64_MAX;
    }
    if (!l->rep || !l->tri || !l->tri_patch) goto fail_oom;
    for (size_t v = 0; v < l->nverts; v++)
        l->rep[v] = UINT64_MAX;
    /* The loops below take about a second per 10^7 triangles on a CPU:
     * they poll the stop hook (util/stop.h) as they go. */
    if (fill_reps(&c, err)) goto fail;
    for (size_t p = 0; p < np; p++) {
        if (vx_stop_poll(err)) goto fail;
        if (is_transition(c.ne, ndiv, p))
            transition_tris(&c, p);
        else
            grid_tris(&c, p, 0, ndiv[p]);
    }
    free(c.ne);
    free(c.src);
    free(c.pbase);
    free(c.corner_id);
    free(c.edge_base);
    free(c.valence);
    free(c.wrep);
    return l;
fail_big:
    vx_err_set(err, VX_ETOOBIG, "too_many_vertices", "over 2^32 vertices");
    goto fail;
fail_oom:
    oom(err);
fail:
    free(c.ne);
    free(c.src);
    free(c.pbase);
    free(c.corner_id);
    free(c.edge_base);
    free(c.valence);
    free(c.wrep);
    vx_gregory_layout_free(l);
    return NULL;
}

int vx_gregory_gather(const vx_gtess_layout *l, const float *grid, const double origin[3],
                      double *pos, float *nrm, vx_err *err)
{
    const float crease = 0.99984769f; /* cos 1° */
    for (size_t v = 0; v < l->nverts; v++) {
        if ((v & 0xffff) == 0 && vx_stop_poll(err)) return -1;
        const float *g = grid + 6 * l->rep[v], *n = g + 3;
        if (l->share && l->share[v] != UINT64_MAX) {
            const float *h = grid + 6 * l->share[v];
            g = h;
            if (n[0] * h[3] + n[1] * h[4] + n[2] * h[5] >= crease) n = h + 3;
        }
        for (int c = 0; c < 3; c++) {
            pos[3 * v + c] = origin[c] + (double)g[c];
            if (nrm) nrm[3 * v + c] = n[c];
        }
    }
    return 0;
}
