/* The tessellation layout (tess.h): divisions, welding by corner keys,
 * triangles. CPU only; built once per topology. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gregory/tess.h"

enum { NONE = UINT32_MAX };

typedef struct pedge {
    uint32_t lo, hi; /* corner keys, lo <= hi */
    uint32_t pe;     /* 4 * patch + edge */
} pedge;

static int pedge_cmp(const void *a, const void *b)
{
    const pedge *x = a, *y = b;
    if (x->lo != y->lo) return x->lo < y->lo ? -1 : 1;
    if (x->hi != y->hi) return x->hi < y->hi ? -1 : 1;
    return x->pe < y->pe ? -1 : x->pe > y->pe;
}

/* Patch edges sorted by their corner keys: equal neighbours share an edge. */
static pedge *sorted_edges(const vx_gpatch_set *s)
{
    pedge *e = malloc((4 * s->npatches + 1) * sizeof *e);
    if (!e) return NULL;
    for (size_t q = 0; q < 4 * s->npatches; q++) {
        uint32_t a = s->corner_key[q], b = s->corner_key[4 * (q / 4) + (q % 4 + 1) % 4];
        e[q].lo = a < b ? a : b;
        e[q].hi = a < b ? b : a;
        e[q].pe = (uint32_t)q;
    }
    qsort(e, 4 * s->npatches, sizeof *e, pedge_cmp);
    return e;
}

static int same_edge(const pedge *a, const pedge *b)
{
    return a->lo == b->lo && a->hi == b->hi;
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
    static const int bnd[4][4] = {{0, 1, 2, 3}, {3, 7, 11, 15}, {15, 14, 13, 12}, {12, 8, 4, 0}};
    for (size_t p = 0; p < s->npatches; p++) {
        const double *cp = s->cp + p * VX_GPATCH_POINTS * 3;
        double longest = 0;
        /* A curve's length is at most its control polygon's length. */
        for (int e = 0; e < 4; e++) {
            double len = 0;
            for (int i = 0; i < 3; i++) {
                const double *a = cp + 3 * bnd[e][i], *b = cp + 3 * bnd[e][i + 1];
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
    /* One N per connected component: the largest need in it. */
    uint32_t *par = malloc((s->npatches + 1) * sizeof *par);
    pedge *e = sorted_edges(s);
    if (!par || !e) {
        free(par);
        free(e);
        free(nd);
        oom(err);
        return NULL;
    }
    for (size_t p = 0; p < s->npatches; p++)
        par[p] = (uint32_t)p;
    for (size_t q = 1; q < 4 * s->npatches; q++)
        if (same_edge(&e[q], &e[q - 1])) {
            uint32_t a = uf_find(par, e[q].pe / 4), b = uf_find(par, e[q - 1].pe / 4);
            if (a != b) par[a] = b;
        }
    for (size_t p = 0; p < s->npatches; p++) {
        uint32_t r = uf_find(par, (uint32_t)p);
        if (nd[p] > nd[r]) nd[r] = nd[p];
    }
    for (size_t p = 0; p < s->npatches; p++)
        nd[p] = nd[uf_find(par, (uint32_t)p)];
    free(par);
    free(e);
    return nd;
}

void vx_gregory_count(size_t npatches, const uint32_t *ndiv, uint64_t *grid_verts, uint64_t *tris)
{
    uint64_t v = 0, t = 0;
    for (size_t p = 0; p < npatches; p++) {
        uint64_t n = ndiv[p];
        v += (n + 1) * (n + 1);
        t += 2 * n * n;
    }
    *grid_verts = v;
    *tris = t;
}

void vx_gregory_layout_free(vx_gtess_layout *l)
{
    if (!l) return;
    free(l->ndiv);
    free(l->voff);
    free(l->rep);
    free(l->tri);
    free(l->tri_patch);
    free(l);
}

/* Output id of every grid vertex (welded). */
static int weld_map(const vx_gpatch_set *s, vx_gtess_layout *l, uint32_t *id, vx_err *err)
{
    size_t np = s->npatches;
    uint32_t maxkey = 0;
    for (size_t q = 0; q < 4 * np; q++)
        if (s->corner_key[q] > maxkey) maxkey = s->corner_key[q];
    uint32_t *corner_id = malloc(((size_t)maxkey + 1) * sizeof *corner_id);
    uint32_t *edge_base = malloc((4 * np + 1) * sizeof *edge_base); /* per patch edge */
    pedge *e = sorted_edges(s);
    if (!corner_id || !edge_base || !e) {
        free(corner_id);
        free(edge_base);
        free(e);
        return oom(err);
    }
    for (size_t k = 0; k <= maxkey; k++)
        corner_id[k] = NONE;
    uint64_t next = 0;
    for (size_t q = 0; q < 4 * np; q++)
        if (corner_id[s->corner_key[q]] == NONE) corner_id[s->corner_key[q]] = (uint32_t)next++;
    for (size_t q = 0; q < 4 * np; q++) {
        uint32_t n = l->ndiv[e[q].pe / 4];
        if (q > 0 && same_edge(&e[q], &e[q - 1])) {
            if (n != l->ndiv[e[q - 1].pe / 4]) {
                uint32_t pa = e[q].pe / 4, pb = e[q - 1].pe / 4;
                free(corner_id);
                free(edge_base);
                free(e);
                return vx_err_set(err, VX_EUNPROC, "gregory_divisions",
                                  "patches %u and %u share an edge but have %u and %u divisions",
                                  pa, pb, n, l->ndiv[pb]);
            }
            edge_base[e[q].pe] = edge_base[e[q - 1].pe];
            continue;
        }
        edge_base[e[q].pe] = (uint32_t)next;
        if (e[q].lo != e[q].hi) next += n - 1; /* a collapsed edge is its corner */
    }
    free(e);
    for (size_t p = 0; p < np; p++) {
        uint32_t n = l->ndiv[p], w = n + 1;
        const uint32_t *key = s->corner_key + 4 * p;
        uint32_t *g = id + l->voff[p];
        for (uint32_t j = 1; j < n; j++)
            for (uint32_t i = 1; i < n; i++)
                g[j * w + i] = (uint32_t)next++;
        g[0] = corner_id[key[0]];
        g[n] = corner_id[key[1]];
        g[n * w + n] = corner_id[key[2]];
        g[n * w] = corner_id[key[3]];
        for (int ed = 0; ed < 4; ed++) {
            uint32_t ka = key[ed], kb = key[(ed + 1) % 4], base = edge_base[4 * p + ed];
            for (uint32_t t = 1; t < n; t++) {
                uint32_t i, j;
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
                g[j * w + i] = ka == kb ? corner_id[ka] : ka < kb ? base + t - 1 : base + n - t - 1;
            }
        }
    }
    free(corner_id);
    free(edge_base);
    if (next >= UINT32_MAX)
        return vx_err_set(err, VX_ETOOBIG, "too_many_vertices", "over 2^32 vertices");
    l->nverts = (size_t)next;
    return 0;
}

vx_gtess_layout *vx_gregory_layout_new(const vx_gpatch_set *s, const uint32_t *ndiv, int weld,
                                       vx_err *err)
{
    size_t np = s->npatches;
    vx_gtess_layout *l = calloc(1, sizeof *l);
    if (!l) {
        oom(err);
        return NULL;
    }
    l->npatches = np;
    l->weld = weld;
    l->ndiv = malloc((np + 1) * sizeof *l->ndiv);
    l->voff = malloc((np + 1) * sizeof *l->voff);
    if (!l->ndiv || !l->voff) goto fail_oom;
    memcpy(l->ndiv, ndiv, np * sizeof *ndiv);
    uint64_t gv, nt;
    vx_gregory_count(np, ndiv, &gv, &nt);
    if (gv >= UINT32_MAX) {
        vx_gregory_layout_free(l);
        vx_err_set(err, VX_ETOOBIG, "too_many_vertices", "over 2^32 vertices");
        return NULL;
    }
    l->voff[0] = 0;
    for (size_t p = 0; p < np; p++)
        l->voff[p + 1] = l->voff[p] + (uint64_t)(ndiv[p] + 1) * (ndiv[p] + 1);
    uint32_t *id = malloc((gv + 1) * sizeof *id);
    if (!id) goto fail_oom;
    if (weld) {
        if (weld_map(s, l, id, err)) {
            free(id);
            vx_gregory_layout_free(l);
            return NULL;
        }
    } else {
        for (uint64_t g = 0; g < gv; g++)
            id[g] = (uint32_t)g;
        l->nverts = (size_t)gv;
    }
    l->rep = malloc((l->nverts + 1) * sizeof *l->rep);
    l->tri = malloc((3 * nt + 1) * sizeof *l->tri);
    l->tri_patch = malloc((nt + 1) * sizeof *l->tri_patch);
    if (!l->rep || !l->tri || !l->tri_patch) {
        free(id);
        goto fail_oom;
    }
    for (size_t v = 0; v < l->nverts; v++)
        l->rep[v] = UINT64_MAX;
    for (uint64_t g = gv; g-- > 0;) /* the first patch that has a vertex gives it */
        l->rep[id[g]] = g;
    size_t t = 0;
    for (size_t p = 0; p < np; p++) {
        uint32_t n = ndiv[p], w = n + 1;
        const uint32_t *g = id + l->voff[p];
        for (uint32_t j = 0; j < n; j++)
            for (uint32_t i = 0; i < n; i++) {
                uint32_t a = g[j * w + i], b = g[j * w + i + 1], c = g[(j + 1) * w + i + 1],
                         d = g[(j + 1) * w + i];
                const uint32_t tr[2][3] = {{a, b, c}, {a, c, d}};
                for (int k = 0; k < 2; k++) {
                    const uint32_t *x = tr[k];
                    if (x[0] == x[1] || x[1] == x[2] || x[0] == x[2]) continue;
                    memcpy(l->tri + 3 * t, x, 3 * sizeof *x);
                    l->tri_patch[t++] = (uint32_t)p;
                }
            }
    }
    l->ntris = t;
    free(id);
    return l;
fail_oom:
    vx_gregory_layout_free(l);
    oom(err);
    return NULL;
}

void vx_gregory_gather(const vx_gtess_layout *l, const float *grid, const double origin[3],
                       double *pos, float *nrm)
{
    for (size_t v = 0; v < l->nverts; v++) {
        const float *g = grid + 6 * l->rep[v];
        for (int c = 0; c < 3; c++) {
            pos[3 * v + c] = origin[c] + (double)g[c];
            if (nrm) nrm[3 * v + c] = g[3 + c];
        }
    }
}
