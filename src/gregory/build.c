/* The interpolate construction and the Bézier input (gregory.h).
 *
 * Seed 001 §2.1.4: every patch edge is a cubic curve through its end nodes
 * with end tangents in the nodes' tangent planes; the two interior points
 * next to an edge make the cross-boundary derivative
 *   X(t) = k(t) G(t) + h(t) C(t)
 * with C(t) the curve's derivative (quadratic, C0..C2), k and h linear and
 * G(t) linear between G0 = n0 x C0 and G3 = n3 x C2 (the formulas 2.10-2.12
 * with the seed's A replaced by G). k0, h0 solve X0 = k0 G0 + h0 C0 in least
 * squares (exact: X0 lies in the tangent plane) and likewise k1, h1 at the
 * far end. Every patch on the edge gets the same G, so any two of them
 * have normals parallel to C x G along the whole edge: G1, whichever side
 * is "first" (the seed's A side is the special case k = 1, h = 0). */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "gregory/gregory.h"

enum { NONE = UINT32_MAX };

/* Curve kinds: how a patch edge's curve is made from the input. */
enum { C_EDGE = 0, C_HALF0, C_HALF1, C_INNER };

struct vx_gregory_topo {
    size_t nverts, nfaces, nedges, nnodes, ncurves, npatches;
    int split;
    uint32_t *fstart, *fidx;    /* face offsets and indices (copied) */
    uint32_t *edge_v;           /* 2 per input edge, a < b */
    uint32_t *edge_nf;          /* faces on the edge */
    uint32_t *fedge;            /* per face corner i: edge of (v_i, v_i+1) */
    uint32_t *bnb;              /* 2 per vertex: boundary neighbours, NONE */
    uint32_t *curve_node;       /* 2 per curve: its direction */
    uint8_t *curve_kind;
    uint32_t *curve_ref; /* input edge (C_EDGE, C_HALF*) or face (C_INNER) */
    uint32_t *curve_np;  /* patches on the curve */
    uint32_t *curve_off; /* ncurves + 1 offsets into curve_pe */
    uint32_t *curve_pe;  /* 4 * patch + patch edge, per incidence */
    uint32_t *pnode;     /* 4 per patch */
    uint32_t *pcurve;    /* 4 per patch: curve of edge e (corner e -> e+1) */
    uint8_t *pdir;       /* 1: the curve runs corner e -> e+1 */
    uint32_t *pface;
};

size_t vx_gregory_topo_npatches(const vx_gregory_topo *t) { return t->npatches; }
size_t vx_gregory_topo_nverts(const vx_gregory_topo *t) { return t->nverts; }

void vx_gregory_topo_free(vx_gregory_topo *t)
{
    if (!t) return;
    free(t->fstart);
    free(t->fidx);
    free(t->edge_v);
    free(t->edge_nf);
    free(t->fedge);
    free(t->bnb);
    free(t->curve_node);
    free(t->curve_kind);
    free(t->curve_ref);
    free(t->curve_np);
    free(t->curve_off);
    free(t->curve_pe);
    free(t->pnode);
    free(t->pcurve);
    free(t->pdir);
    free(t->pface);
    free(t);
}

typedef struct half {
    uint64_t key; /* min * nverts + max */
    uint32_t corner;
} half;

static int half_cmp(const void *a, const void *b)
{
    const half *x = a, *y = b;
    if (x->key != y->key) return x->key < y->key ? -1 : 1;
    return x->corner < y->corner ? -1 : x->corner > y->corner;
}

/* Slots along patch edge e from corner e to corner e+1: the boundary row
 * and the row inside it (gregory.h layout). */
static const int bnd_slot[4][4] = {{0, 1, 2, 3}, {3, 7, 11, 15}, {15, 14, 13, 12}, {12, 8, 4, 0}};
static const int inn_slot[4][4] = {{4, 5, 6, 7}, {2, 17, 19, 14}, {11, 10, 9, 8}, {13, 18, 16, 1}};

/* Node ids: input vertices, then edge midpoints, then face centres. */
static uint32_t mid_node(const vx_gregory_topo *t, uint32_t e) { return (uint32_t)(t->nverts + e); }
static uint32_t centre_node(const vx_gregory_topo *t, uint32_t f)
{
    return (uint32_t)(t->nverts + t->nedges + f);
}

static int oom(vx_err *err)
{
    return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the Gregory patch tables");
}

/* Curves: one per input edge (quad mode) or two halves per input edge plus
 * one midpoint -> centre curve per face corner (split mode). Patches find
 * their curves through these numbering rules, so no search is needed. */
static int make_layout(vx_gregory_topo *t, vx_err *err)
{
    size_t ncorners = t->fstart[t->nfaces];
    t->ncurves = t->split ? 2 * t->nedges + ncorners : t->nedges;
    t->npatches = t->split ? ncorners : t->nfaces;
    t->curve_node = malloc(2 * t->ncurves * sizeof *t->curve_node);
    t->curve_kind = malloc(t->ncurves + 1);
    t->curve_ref = malloc(t->ncurves * sizeof *t->curve_ref);
    t->curve_np = calloc(t->ncurves + 1, sizeof *t->curve_np);
    t->curve_off = calloc(t->ncurves + 1, sizeof *t->curve_off);
    t->curve_pe = malloc(4 * t->npatches * sizeof *t->curve_pe);
    t->pnode = malloc(4 * t->npatches * sizeof *t->pnode);
    t->pcurve = malloc(4 * t->npatches * sizeof *t->pcurve);
    t->pdir = malloc(4 * t->npatches + 1);
    t->pface = malloc(t->npatches * sizeof *t->pface + 1);
    if (!t->curve_node || !t->curve_kind || !t->curve_ref || !t->curve_np || !t->curve_off ||
        !t->curve_pe || !t->pnode || !t->pcurve || !t->pdir || !t->pface)
        return oom(err);
    for (uint32_t e = 0; e < t->nedges; e++) {
        uint32_t a = t->edge_v[2 * e], b = t->edge_v[2 * e + 1];
        if (!t->split) {
            t->curve_node[2 * e] = a;
            t->curve_node[2 * e + 1] = b;
            t->curve_kind[e] = C_EDGE;
            t->curve_ref[e] = e;
            continue;
        }
        /* Half 0 runs a -> mid, half 1 mid -> b. */
        t->curve_node[4 * e] = a;
        t->curve_node[4 * e + 1] = mid_node(t, e);
        t->curve_node[4 * e + 2] = mid_node(t, e);
        t->curve_node[4 * e + 3] = b;
        t->curve_kind[2 * e] = C_HALF0;
        t->curve_kind[2 * e + 1] = C_HALF1;
        t->curve_ref[2 * e] = t->curve_ref[2 * e + 1] = e;
    }
    if (t->split)
        for (uint32_t f = 0; f < t->nfaces; f++)
            for (uint32_t c = t->fstart[f]; c < t->fstart[f + 1]; c++) {
                size_t id = 2 * t->nedges + c; /* midpoint of corner c's edge -> centre */
                t->curve_node[2 * id] = mid_node(t, t->fedge[c]);
                t->curve_node[2 * id + 1] = centre_node(t, f);
                t->curve_kind[id] = C_INNER;
                t->curve_ref[id] = f;
            }

    size_t p = 0;
    for (uint32_t f = 0; f < t->nfaces; f++) {
        uint32_t s = t->fstart[f], n = t->fstart[f + 1] - s;
        if (!t->split) {
            for (int k = 0; k < 4; k++) {
                t->pnode[4 * p + k] = t->fidx[s + k];
                uint32_t e = t->fedge[s + k];
                t->pcurve[4 * p + k] = e;
                t->pdir[4 * p + k] = t->curve_node[2 * e] == t->fidx[s + k];
            }
            t->pface[p++] = f;
            continue;
        }
        for (uint32_t i = 0; i < n; i++) {
            uint32_t c = s + i, cprev = s + (i + n - 1) % n;
            uint32_t v = t->fidx[c], e = t->fedge[c], eprev = t->fedge[cprev];
            uint32_t *pn = t->pnode + 4 * p, *pc = t->pcurve + 4 * p;
            uint8_t *pd = t->pdir + 4 * p;
            pn[0] = v;
            pn[1] = mid_node(t, e);
            pn[2] = centre_node(t, f);
            pn[3] = mid_node(t, eprev);
            /* v -> mid(e): the half of e at v */
            pc[0] = 2 * e + (t->edge_v[2 * e] == v ? 0 : 1);
            pd[0] = t->curve_node[2 * pc[0]] == v;
            pc[1] = (uint32_t)(2 * t->nedges + c);
            pd[1] = 1;
            pc[2] = (uint32_t)(2 * t->nedges + cprev);
            pd[2] = 0;
            pc[3] = 2 * eprev + (t->edge_v[2 * eprev] == v ? 0 : 1);
            pd[3] = t->curve_node[2 * pc[3]] == pn[3];
            t->pface[p++] = f;
        }
    }
    for (size_t q = 0; q < 4 * t->npatches; q++)
        t->curve_np[t->pcurve[q]]++;
    for (size_t c = 0; c < t->ncurves; c++)
        t->curve_off[c + 1] = t->curve_off[c] + t->curve_np[c];
    uint32_t *fill = calloc(t->ncurves + 1, sizeof *fill);
    if (!fill) return oom(err);
    for (size_t q = 0; q < 4 * t->npatches; q++) {
        uint32_t c = t->pcurve[q];
        t->curve_pe[t->curve_off[c] + fill[c]++] = (uint32_t)q;
    }
    free(fill);
    return 0;
}

vx_gregory_topo *vx_gregory_topo_new(const vx_mesh *m, vx_err *err)
{
    if (m->nverts >= UINT32_MAX / 4 || m->nfaces == 0) {
        vx_err_set(err, VX_EUNPROC, "mesh_unusable", "the mesh has no faces or too many vertices");
        return NULL;
    }
    vx_gregory_topo *t = calloc(1, sizeof *t);
    if (!t) {
        oom(err);
        return NULL;
    }
    t->nverts = m->nverts;
    t->nfaces = m->nfaces;
    t->fstart = malloc((m->nfaces + 1) * sizeof *t->fstart);
    if (!t->fstart) goto fail_oom;
    t->fstart[0] = 0;
    int all_quads = 1;
    for (size_t f = 0; f < m->nfaces; f++) {
        uint32_t n = vx_mesh_face_size(m, f);
        all_quads &= n == 4;
        t->fstart[f + 1] = t->fstart[f] + n;
    }
    t->split = !all_quads;
    size_t nc = t->fstart[m->nfaces];
    t->fidx = malloc(nc * sizeof *t->fidx);
    t->fedge = malloc(nc * sizeof *t->fedge);
    half *h = malloc(nc * sizeof *h);
    if (!t->fidx || !t->fedge || !h) {
        free(h);
        goto fail_oom;
    }
    for (size_t f = 0; f < m->nfaces; f++)
        memcpy(t->fidx + t->fstart[f], vx_mesh_face(m, f),
               (t->fstart[f + 1] - t->fstart[f]) * sizeof *t->fidx);
    for (size_t f = 0; f < m->nfaces; f++) {
        uint32_t s = t->fstart[f], n = t->fstart[f + 1] - s;
        for (uint32_t i = 0; i < n; i++) {
            uint64_t a = t->fidx[s + i], b = t->fidx[s + (i + 1) % n];
            if (a > b) {
                uint64_t x = a;
                a = b;
                b = x;
            }
            h[s + i].key = a * m->nverts + b;
            h[s + i].corner = s + i;
        }
    }
    qsort(h, nc, sizeof *h, half_cmp);
    size_t ne = 0;
    for (size_t i = 0; i < nc; i++)
        ne += i == 0 || h[i].key != h[i - 1].key;
    t->nedges = ne;
    t->edge_v = malloc(2 * ne * sizeof *t->edge_v);
    t->edge_nf = calloc(ne + 1, sizeof *t->edge_nf);
    t->bnb = malloc(2 * m->nverts * sizeof *t->bnb + 1);
    if (!t->edge_v || !t->edge_nf || !t->bnb) {
        free(h);
        goto fail_oom;
    }
    size_t e = (size_t)-1;
    for (size_t i = 0; i < nc; i++) {
        if (i == 0 || h[i].key != h[i - 1].key) {
            e++;
            t->edge_v[2 * e] = (uint32_t)(h[i].key / m->nverts);
            t->edge_v[2 * e + 1] = (uint32_t)(h[i].key % m->nverts);
        }
        t->edge_nf[e]++;
        t->fedge[h[i].corner] = (uint32_t)e;
    }
    free(h);
    /* Boundary neighbours: the tangent of a boundary curve at a vertex with
     * exactly two boundary edges runs from one neighbour to the other. */
    uint32_t *bcount = calloc(m->nverts + 1, sizeof *bcount);
    if (!bcount) goto fail_oom;
    for (size_t v = 0; v < 2 * m->nverts; v++)
        t->bnb[v] = NONE;
    for (size_t k = 0; k < ne; k++) {
        if (t->edge_nf[k] != 1) continue;
        for (int s = 0; s < 2; s++) {
            uint32_t v = t->edge_v[2 * k + s], o = t->edge_v[2 * k + 1 - s];
            if (bcount[v] < 2) t->bnb[2 * v + bcount[v]] = o;
            bcount[v]++;
        }
    }
    for (size_t v = 0; v < m->nverts; v++)
        if (bcount[v] != 2) t->bnb[2 * v] = t->bnb[2 * v + 1] = NONE;
    free(bcount);
    t->nnodes = t->split ? m->nverts + ne + m->nfaces : m->nverts;
    if (t->nnodes >= UINT32_MAX) {
        vx_gregory_topo_free(t);
        vx_err_set(err, VX_EUNPROC, "mesh_unusable", "the mesh is too large for patch corner keys");
        return NULL;
    }
    if (make_layout(t, err)) {
        vx_gregory_topo_free(t);
        return NULL;
    }
    return t;
fail_oom:
    vx_gregory_topo_free(t);
    oom(err);
    return NULL;
}

/* ---- small vector helpers ---- */
static void sub3(const double *a, const double *b, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = a[c] - b[c];
}
static double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
static void cross3(const double *a, const double *b, double *o)
{
    o[0] = a[1] * b[2] - a[2] * b[1];
    o[1] = a[2] * b[0] - a[0] * b[2];
    o[2] = a[0] * b[1] - a[1] * b[0];
}
static double norm3(const double *a) { return sqrt(dot3(a, a)); }
static int unit3(double *a)
{
    double l = norm3(a);
    if (!(l > 0)) return -1;
    for (int c = 0; c < 3; c++)
        a[c] /= l;
    return 0;
}

/* Newell normal of face f (not normalised: its length is twice the area). */
static void face_normal(const vx_gregory_topo *t, const double *pos, uint32_t f, double n[3])
{
    n[0] = n[1] = n[2] = 0;
    uint32_t s = t->fstart[f], k = t->fstart[f + 1] - s;
    for (uint32_t i = 0; i < k; i++) {
        const double *a = pos + 3 * t->fidx[s + i], *b = pos + 3 * t->fidx[s + (i + 1) % k];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
}

/* Angle-weighted vertex normals (unit face normal times the corner angle). */
static void vertex_normals(const vx_gregory_topo *t, const double *pos, double *vn)
{
    memset(vn, 0, 3 * t->nverts * sizeof *vn);
    for (uint32_t f = 0; f < t->nfaces; f++) {
        double fn[3];
        face_normal(t, pos, f, fn);
        if (unit3(fn)) continue;
        uint32_t s = t->fstart[f], k = t->fstart[f + 1] - s;
        for (uint32_t i = 0; i < k; i++) {
            uint32_t v = t->fidx[s + i];
            double a[3], b[3];
            sub3(pos + 3 * t->fidx[s + (i + 1) % k], pos + 3 * v, a);
            sub3(pos + 3 * t->fidx[s + (i + k - 1) % k], pos + 3 * v, b);
            double la = norm3(a), lb = norm3(b);
            double cs = la > 0 && lb > 0 ? dot3(a, b) / (la * lb) : 1;
            double w = acos(cs < -1 ? -1 : cs > 1 ? 1 : cs);
            for (int c = 0; c < 3; c++)
                vn[3 * v + c] += w * fn[c];
        }
    }
    for (size_t v = 0; v < t->nverts; v++)
        if (unit3(vn + 3 * v)) {
            vn[3 * v] = vn[3 * v + 1] = 0;
            vn[3 * v + 2] = 1; /* an isolated or flat-degenerate vertex */
        }
}

/* End tangent at a (towards the far end b of the curve): dir projected onto
 * the tangent plane of normal n, |b - a| / 3 long. */
static void end_tangent(const double *a, const double *b, const double *dir, const double *n,
                        double *out)
{
    double d[3], ab[3];
    sub3(b, a, ab);
    double len = norm3(ab) / 3;
    double s = dot3(dir, n);
    for (int c = 0; c < 3; c++)
        d[c] = dir[c] - s * n[c];
    if (unit3(d)) {
        for (int c = 0; c < 3; c++)
            out[c] = 0;
        return;
    }
    for (int c = 0; c < 3; c++)
        out[c] = d[c] * len;
}

/* The cubic through a and b with tangents in the planes of na and nb. */
static void plane_curve(const double *a, const double *na, const double *b, const double *nb,
                        const double *dir_a, const double *dir_b, double cv[12])
{
    double ta[3], tb[3];
    end_tangent(a, b, dir_a, na, ta);
    end_tangent(b, a, dir_b, nb, tb);
    for (int c = 0; c < 3; c++) {
        cv[c] = a[c];
        cv[3 + c] = a[c] + ta[c];
        cv[6 + c] = b[c] + tb[c];
        cv[9 + c] = b[c];
    }
}

/* Curve of input edge e (a -> b, a < b): chord tangents, or along the
 * boundary from one boundary neighbour to the other. */
static void edge_curve(const vx_gregory_topo *t, const double *pos, const double *vn, uint32_t e,
                       double cv[12])
{
    uint32_t a = t->edge_v[2 * e], b = t->edge_v[2 * e + 1];
    const double *pa = pos + 3 * a, *pb = pos + 3 * b;
    double da[3], db[3];
    sub3(pb, pa, da);
    sub3(pa, pb, db);
    if (t->edge_nf[e] == 1) {
        uint32_t pa_other = t->bnb[2 * a] == b ? t->bnb[2 * a + 1] : t->bnb[2 * a];
        uint32_t pb_other = t->bnb[2 * b] == a ? t->bnb[2 * b + 1] : t->bnb[2 * b];
        if (pa_other != NONE) sub3(pb, pos + 3 * pa_other, da);
        if (pb_other != NONE) sub3(pa, pos + 3 * pb_other, db);
    }
    plane_curve(pa, vn + 3 * a, pb, vn + 3 * b, da, db, cv);
}

static void lerp3(const double *a, const double *b, double *o)
{
    for (int c = 0; c < 3; c++)
        o[c] = 0.5 * (a[c] + b[c]);
}

/* de Casteljau at 1/2: the halves and the tangent direction there. */
static void split_curve(const double cv[12], double h0[12], double h1[12])
{
    double p01[3], p12[3], p23[3], q0[3], q1[3], m[3];
    lerp3(cv, cv + 3, p01);
    lerp3(cv + 3, cv + 6, p12);
    lerp3(cv + 6, cv + 9, p23);
    lerp3(p01, p12, q0);
    lerp3(p12, p23, q1);
    lerp3(q0, q1, m);
    memcpy(h0, cv, 3 * sizeof *h0);
    memcpy(h0 + 3, p01, sizeof p01);
    memcpy(h0 + 6, q0, sizeof q0);
    memcpy(h0 + 9, m, sizeof m);
    memcpy(h1, m, sizeof m);
    memcpy(h1 + 3, q1, sizeof q1);
    memcpy(h1 + 6, p23, sizeof p23);
    memcpy(h1 + 9, cv + 9, 3 * sizeof *h1);
}

/* Least-squares k, h of x = k g + h c (2x2 normal equations). */
static void solve_kh(const double *x, const double *g, const double *c, double *k, double *h)
{
    double gg = dot3(g, g), gc = dot3(g, c), cc = dot3(c, c);
    double xg = dot3(x, g), xc = dot3(x, c), det = gg * cc - gc * gc;
    if (fabs(det) <= 1e-30 * (gg * cc + 1e-300)) {
        *k = gg > 0 ? xg / gg : 0;
        *h = 0;
        return;
    }
    *k = (xg * cc - xc * gc) / det;
    *h = (xc * gg - xg * gc) / det;
}

/* Interior points next to one curve for every patch on it (the correction). */
static void correct_curve(const vx_gregory_topo *t, uint32_t c, const double cv[12],
                          const double *na, const double *nb, vx_gpatch_set *s)
{
    double C[3][3], G0[3], G3[3];
    for (int i = 0; i < 3; i++)
        sub3(cv + 3 * (i + 1), cv + 3 * i, C[i]);
    cross3(na, C[0], G0);
    cross3(nb, C[2], G3);
    int usable = norm3(G0) > 0 && norm3(G3) > 0;
    for (uint32_t q = t->curve_off[c]; q < t->curve_off[c + 1]; q++) {
        uint32_t pe = t->curve_pe[q], p = pe / 4, e = pe % 4;
        double *cp = s->cp + (size_t)p * VX_GPATCH_POINTS * 3;
        int bs[4], is[4];
        for (int i = 0; i < 4; i++) { /* index 0 at the curve's start */
            int j = t->pdir[pe] ? i : 3 - i;
            bs[i] = bnd_slot[e][j];
            is[i] = inn_slot[e][j];
        }
        double X0[3], X3[3], X1[3], X2[3];
        sub3(cp + 3 * is[0], cp + 3 * bs[0], X0);
        sub3(cp + 3 * is[3], cp + 3 * bs[3], X3);
        if (usable) {
            double k0, h0, k1, h1;
            solve_kh(X0, G0, C[0], &k0, &h0);
            solve_kh(X3, G3, C[2], &k1, &h1);
            for (int d = 0; d < 3; d++) {
                X1[d] = ((k0 + k1) * G0[d] + k0 * G3[d] + 2 * h0 * C[1][d] + h1 * C[0][d]) / 3;
                X2[d] = (k1 * G0[d] + (k0 + k1) * G3[d] + h0 * C[2][d] + 2 * h1 * C[1][d]) / 3;
            }
        } else { /* a degenerate curve: the seed's linear cross-boundary field */
            for (int d = 0; d < 3; d++) {
                X1[d] = (2 * X0[d] + X3[d]) / 3;
                X2[d] = (X0[d] + 2 * X3[d]) / 3;
            }
        }
        for (int d = 0; d < 3; d++) {
            cp[3 * is[1] + d] = cp[3 * bs[1] + d] + X1[d];
            cp[3 * is[2] + d] = cp[3 * bs[2] + d] + X2[d];
        }
    }
}

/* Writes curve c's points into the boundary slots of every patch on it. */
static void place_curve(const vx_gregory_topo *t, uint32_t c, const double cv[12], vx_gpatch_set *s)
{
    for (uint32_t q = t->curve_off[c]; q < t->curve_off[c + 1]; q++) {
        uint32_t pe = t->curve_pe[q], p = pe / 4, e = pe % 4;
        double *cp = s->cp + (size_t)p * VX_GPATCH_POINTS * 3;
        for (int i = 0; i < 4; i++) {
            int j = t->pdir[pe] ? i : 3 - i;
            memcpy(cp + 3 * bnd_slot[e][j], cv + 3 * i, 3 * sizeof *cp);
        }
    }
}

void vx_gregory_build(const vx_gregory_topo *t, const double *pos, vx_gpatch_set *s)
{
    /* Node positions and normals (nnodes), curve control points. */
    double *np = malloc(3 * t->nnodes * sizeof *np), *nn = malloc(3 * t->nnodes * sizeof *nn);
    double *cvs = malloc(12 * t->ncurves * sizeof *cvs);
    if (!np || !nn || !cvs) { /* callers size-check first; keep the set defined */
        free(np);
        free(nn);
        free(cvs);
        memset(s->cp, 0, s->npatches * VX_GPATCH_POINTS * 3 * sizeof *s->cp);
        return;
    }
    memcpy(np, pos, 3 * t->nverts * sizeof *np);
    vertex_normals(t, pos, nn);
    for (uint32_t e = 0; e < t->nedges; e++) {
        if (!t->split) {
            edge_curve(t, pos, nn, e, cvs + 12 * e);
            continue;
        }
        double cv[12];
        edge_curve(t, pos, nn, e, cv);
        split_curve(cv, cvs + 24 * e, cvs + 24 * e + 12);
        /* Midpoint node: on the curve; its plane holds the curve's tangent
         * there and is otherwise the mean of the end planes. */
        uint32_t m = mid_node(t, e), a = t->edge_v[2 * e], b = t->edge_v[2 * e + 1];
        double tan[3], n[3];
        memcpy(np + 3 * m, cvs + 24 * e + 9, 3 * sizeof *np);
        sub3(cvs + 24 * e + 15, cvs + 24 * e + 6, tan);
        lerp3(nn + 3 * a, nn + 3 * b, n);
        if (unit3(tan) == 0) {
            double d = dot3(n, tan);
            for (int c = 0; c < 3; c++)
                n[c] -= d * tan[c];
        }
        if (unit3(n)) memcpy(n, nn + 3 * a, sizeof n);
        memcpy(nn + 3 * m, n, sizeof n);
    }
    if (t->split)
        for (uint32_t f = 0; f < t->nfaces; f++) {
            /* Centre: the PN-triangle rule M + (M - V) / 2 over the edge
             * midpoints M and the vertices V (exact for a plane, lifted
             * towards the surface otherwise); plane: mean vertex plane. */
            uint32_t s0 = t->fstart[f], k = t->fstart[f + 1] - s0, cn = centre_node(t, f);
            double M[3] = {0, 0, 0}, V[3] = {0, 0, 0}, n[3] = {0, 0, 0};
            for (uint32_t i = 0; i < k; i++) {
                const double *mp = np + 3 * mid_node(t, t->fedge[s0 + i]);
                const double *vp = pos + 3 * t->fidx[s0 + i];
                for (int c = 0; c < 3; c++) {
                    M[c] += mp[c] / k;
                    V[c] += vp[c] / k;
                    n[c] += nn[3 * t->fidx[s0 + i] + c];
                }
            }
            for (int c = 0; c < 3; c++)
                np[3 * cn + c] = M[c] + 0.5 * (M[c] - V[c]);
            if (unit3(n)) {
                face_normal(t, pos, f, n);
                if (unit3(n)) n[0] = n[1] = 0, n[2] = 1;
            }
            memcpy(nn + 3 * cn, n, sizeof n);
        }
    for (uint32_t c = t->split ? (uint32_t)(2 * t->nedges) : (uint32_t)t->ncurves; c < t->ncurves;
         c++) {
        uint32_t a = t->curve_node[2 * c], b = t->curve_node[2 * c + 1];
        double da[3], db[3];
        sub3(np + 3 * b, np + 3 * a, da);
        sub3(np + 3 * a, np + 3 * b, db);
        plane_curve(np + 3 * a, nn + 3 * a, np + 3 * b, nn + 3 * b, da, db, cvs + 12 * c);
    }
    for (uint32_t c = 0; c < t->ncurves; c++)
        place_curve(t, c, cvs + 12 * c, s);
    for (uint32_t c = 0; c < t->ncurves; c++)
        correct_curve(t, c, cvs + 12 * c, nn + 3 * t->curve_node[2 * c],
                      nn + 3 * t->curve_node[2 * c + 1], s);
    for (size_t p = 0; p < t->npatches; p++) {
        memcpy(s->corner_key + 4 * p, t->pnode + 4 * p, 4 * sizeof *s->corner_key);
        s->face[p] = t->pface[p];
    }
    free(np);
    free(nn);
    free(cvs);
}

/* ---- Bézier input ---- */

typedef struct keyed {
    const double *p;
    uint32_t idx;
} keyed;

static int keyed_cmp(const void *a, const void *b)
{
    const keyed *x = a, *y = b;
    int c = memcmp(x->p, y->p, 3 * sizeof(double));
    if (c) return c;
    return x->idx < y->idx ? -1 : x->idx > y->idx;
}

vx_gpatch_set *vx_gregory_from_bezier(const vx_mesh *m, const double *pos, vx_err *err)
{
    if (!pos) pos = m->pos;
    if (m->npatches == 0 || !m->patch_idx) {
        vx_err_set(err, VX_EUNPROC, "mesh_unusable", "the mesh has no Bezier patches");
        return NULL;
    }
    vx_gpatch_set *s = vx_gpatch_set_new(m->npatches);
    keyed *k = malloc((m->nverts + 1) * sizeof *k);
    uint32_t *canon = malloc((m->nverts + 1) * sizeof *canon);
    if (!s || !k || !canon) {
        free(k);
        free(canon);
        vx_gpatch_set_free(s);
        oom(err);
        return NULL;
    }
    /* Bitwise-equal points get the smallest index among them as their key. */
    for (size_t i = 0; i < m->nverts; i++) {
        k[i].p = pos + 3 * i;
        k[i].idx = (uint32_t)i;
    }
    qsort(k, m->nverts, sizeof *k, keyed_cmp);
    for (size_t i = 0; i < m->nverts; i++)
        canon[k[i].idx] = i > 0 && memcmp(k[i].p, k[i - 1].p, 3 * sizeof(double)) == 0
                              ? canon[k[i - 1].idx]
                              : k[i].idx;
    free(k);
    static const int interior[4] = {5, 6, 9, 10};
    static const int corner_net[4] = {0, 3, 15, 12};
    for (size_t p = 0; p < m->npatches; p++) {
        const uint32_t *idx = m->patch_idx + 16 * p;
        double *cp = s->cp + p * VX_GPATCH_POINTS * 3;
        for (int i = 0; i < 16; i++) {
            if (idx[i] >= m->nverts) {
                free(canon);
                vx_gpatch_set_free(s);
                vx_err_set(err, VX_EUNPROC, "mesh_unusable", "Bezier patch %zu: index out of range",
                           p);
                return NULL;
            }
            memcpy(cp + 3 * i, pos + 3 * idx[i], 3 * sizeof *cp);
        }
        for (int i = 0; i < 4; i++) {
            memcpy(cp + 3 * (16 + i), cp + 3 * interior[i], 3 * sizeof *cp);
            s->corner_key[4 * p + i] = canon[idx[corner_net[i]]];
        }
        s->face[p] = (uint32_t)p;
    }
    free(canon);
    return s;
}
