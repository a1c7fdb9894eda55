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
#include "util/vec3.h"

enum { NONE = UINT32_MAX };

/* Curve kinds: how a patch edge's curve is made from the input. */
enum { C_EDGE = 0, C_HALF0, C_HALF1, C_INNER };
enum { FAN_NONE = 0, FAN_CLOSED, FAN_OPEN };

struct vx_gregory_topo {
    size_t nverts, nfaces, nedges, nnodes, ncurves, npatches;
    int split;
    uint32_t *fstart, *fidx; /* face offsets and indices (copied) */
    uint32_t *edge_v;        /* 2 per input edge, a < b */
    uint32_t *edge_nf;       /* faces on the edge */
    uint32_t *fedge;         /* per face corner i: edge of (v_i, v_i+1) */
    uint32_t *fan_off;       /* nverts + 1 offsets into fan_nb */
    uint32_t *fan_nb;        /* neighbours counter-clockwise (open fans: corners + 1) */
    uint8_t *fan_kind;       /* FAN_NONE, FAN_CLOSED, FAN_OPEN */
    uint32_t *edge_slot;     /* 2 per edge: fan_nb index of the far end at a, at b */
    uint32_t *curve_node;    /* 2 per curve: its direction */
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

size_t vx_gregory_topo_npatches(const vx_gregory_topo *t)
{
    return t->npatches;
}
size_t vx_gregory_topo_nverts(const vx_gregory_topo *t)
{
    return t->nverts;
}

void vx_gregory_topo_free(vx_gregory_topo *t)
{
    if (!t) return;
    free(t->fstart);
    free(t->fidx);
    free(t->edge_v);
    free(t->edge_nf);
    free(t->fedge);
    free(t->fan_off);
    free(t->fan_nb);
    free(t->fan_kind);
    free(t->edge_slot);
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
static uint32_t mid_node(const vx_gregory_topo *t, uint32_t e)
{
    return (uint32_t)(t->nverts + e);
}
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

/* Vertex fans: the neighbours of every vertex in counter-clockwise order
 * about the outward normal (face order: at a corner the face runs from the
 * next vertex to the previous one). Open at a boundary (starting at the
 * boundary edge whose face follows it); FAN_NONE where the faces around a
 * vertex are not one fan (non-manifold), which falls back to projected
 * chords. */
static int make_fans(vx_gregory_topo *t, vx_err *err)
{
    size_t nv = t->nverts, nc = t->fstart[t->nfaces];
    uint32_t *voff = calloc(nv + 2, sizeof *voff), *vc = malloc((nc + 1) * sizeof *vc);
    uint32_t *cface = malloc((nc + 1) * sizeof *cface);
    t->fan_off = malloc((nv + 1) * sizeof *t->fan_off);
    t->fan_nb = malloc((nc + nv + 1) * sizeof *t->fan_nb);
    t->fan_kind = calloc(nv + 1, 1);
    t->edge_slot = malloc((2 * t->nedges + 1) * sizeof *t->edge_slot);
    uint8_t *seen = calloc(nc + 1, 1);
    int rc = -1;
    if (!voff || !vc || !cface || !t->fan_off || !t->fan_nb || !t->fan_kind || !t->edge_slot ||
        !seen) {
        oom(err);
        goto done;
    }
    for (uint32_t f = 0; f < t->nfaces; f++)
        for (uint32_t c = t->fstart[f]; c < t->fstart[f + 1]; c++) {
            cface[c] = f;
            voff[t->fidx[c] + 2]++;
        }
    for (size_t v = 0; v < nv; v++)
        voff[v + 2] += voff[v + 1];
    for (uint32_t c = 0; c < nc; c++)
        vc[voff[t->fidx[c] + 1]++] = c;
#define NX(c) t->fidx[(c) + 1 < t->fstart[cface[c] + 1] ? (c) + 1 : t->fstart[cface[c]]]
#define PV(c) t->fidx[(c) > t->fstart[cface[c]] ? (c)-1 : t->fstart[cface[c] + 1] - 1]
    uint32_t out = 0;
    for (size_t v = 0; v < nv; v++) {
        const uint32_t *L = vc + voff[v];
        uint32_t k = voff[v + 1] - voff[v], start = k ? L[0] : NONE;
        for (uint32_t i = 0; i < k; i++)
            if (t->edge_nf[t->fedge[L[i]]] == 1) start = L[i];
        t->fan_off[v] = out;
        if (!k) continue;
        uint32_t cur = start, n = 0, kind = FAN_NONE;
        for (;;) {
            seen[cur] = 1;
            t->fan_nb[out + n++] = NX(cur);
            uint32_t p = PV(cur), next = NONE;
            for (uint32_t i = 0; i < k; i++)
                if (NX(L[i]) == p && (L[i] == start || !seen[L[i]])) next = L[i];
            if (next == start) {
                kind = n == k ? FAN_CLOSED : FAN_NONE;
                break;
            }
            if (next == NONE) {
                t->fan_nb[out + n] = p;
                kind = n == k && t->edge_nf[t->fedge[start]] == 1 ? FAN_OPEN : FAN_NONE;
                n++;
                break;
            }
            cur = next;
        }
        for (uint32_t i = 0; i < k; i++)
            seen[L[i]] = 0;
        if (kind == FAN_NONE) continue;
        t->fan_kind[v] = (uint8_t)kind;
        out += n;
    }
    t->fan_off[nv] = out;
#undef NX
#undef PV
    for (size_t e = 0; e < t->nedges; e++)
        for (int s = 0; s < 2; s++) {
            uint32_t a = t->edge_v[2 * e + s], b = t->edge_v[2 * e + 1 - s];
            t->edge_slot[2 * e + s] = NONE;
            if (t->fan_kind[a] == FAN_NONE) continue;
            for (uint32_t i = t->fan_off[a]; i < t->fan_off[a + 1]; i++)
                if (t->fan_nb[i] == b) {
                    t->edge_slot[2 * e + s] = i;
                    break;
                }
        }
    rc = 0;
done:
    free(voff);
    free(vc);
    free(cface);
    free(seen);
    return rc;
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
    if (!t->edge_v || !t->edge_nf) {
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
    if (make_fans(t, err)) {
        vx_gregory_topo_free(t);
        return NULL;
    }
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

/* Newell normal of face f (not normalised: its length is twice the area),
 * relative to its first vertex: the sums a + b of positions far from the
 * origin for their size cancelled to noise (a unit quad at 1e15: vertex
 * normals 7 degrees off, and the surface with them). */
static void face_normal(const vx_gregory_topo *t, const double *pos, uint32_t f, double n[3])
{
    n[0] = n[1] = n[2] = 0;
    uint32_t s = t->fstart[f], k = t->fstart[f + 1] - s;
    const double *o = pos + 3 * t->fidx[s];
    for (uint32_t i = 0; i < k; i++) {
        const double *A = pos + 3 * t->fidx[s + i], *B = pos + 3 * t->fidx[s + (i + 1) % k];
        double a[3] = {A[0] - o[0], A[1] - o[1], A[2] - o[2]};
        double b[3] = {B[0] - o[0], B[1] - o[1], B[2] - o[2]};
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
        if (vx_v3_unit(fn)) continue;
        uint32_t s = t->fstart[f], k = t->fstart[f + 1] - s;
        for (uint32_t i = 0; i < k; i++) {
            uint32_t v = t->fidx[s + i];
            double a[3], b[3];
            vx_v3_sub(pos + 3 * t->fidx[s + (i + 1) % k], pos + 3 * v, a);
            vx_v3_sub(pos + 3 * t->fidx[s + (i + k - 1) % k], pos + 3 * v, b);
            double la = vx_v3_norm(a), lb = vx_v3_norm(b);
            double cs = la > 0 && lb > 0 ? vx_v3_dot(a, b) / (la * lb) : 1;
            double w = acos(cs < -1 ? -1 : cs > 1 ? 1 : cs);
            for (int c = 0; c < 3; c++)
                vn[3 * v + c] += w * fn[c];
        }
    }
    for (size_t v = 0; v < t->nverts; v++)
        if (vx_v3_unit(vn + 3 * v)) {
            vn[3 * v] = vn[3 * v + 1] = 0;
            vn[3 * v + 2] = 1; /* an isolated or flat-degenerate vertex */
        }
}

/* Unit direction of dir projected onto the plane of unit normal n; zero
 * when dir is along n. */
static void project_dir(const double *dir, const double *n, double *out)
{
    double d = vx_v3_dot(dir, n);
    for (int c = 0; c < 3; c++)
        out[c] = dir[c] - d * n[c];
    if (vx_v3_unit(out)) out[0] = out[1] = out[2] = 0;
}

/* Tangent directions at node p (unit normal n) towards its fan neighbours
 * P + 3 ids[i] (counter-clockwise): the neighbours' angles about p, scaled to
 * 2 pi (closed fan) or pi (open fan of two faces or more, the first and last
 * neighbours on the boundary; one face is a corner: its chords), laid out
 * in the tangent plane from the first neighbour's projected direction
 * (open: the direction from the last neighbour to the first, so the
 * boundary curve is smooth through p). Unlike projecting
 * every chord, this keeps the directions in the fan's cyclic order even
 * where the mesh is crumpled around p, so neighbouring patches never fold
 * over each other at p. Degenerate fans fall back to projected chords. */
static void fan_dirs(const double *p, const double *n, const double *P, const uint32_t *ids,
                     uint32_t m, int closed, double *dirs)
{
    double total = 0, d0[3], e[3];
    uint32_t nang = closed ? m : m - 1;
    for (uint32_t i = 0; i < nang; i++) {
        double a[3], b[3];
        vx_v3_sub(P + 3 * ids[i], p, a);
        vx_v3_sub(P + 3 * ids[(i + 1) % m], p, b);
        double la = vx_v3_norm(a), lb = vx_v3_norm(b);
        double cs = la > 0 && lb > 0 ? vx_v3_dot(a, b) / (la * lb) : 1;
        total += acos(cs < -1 ? -1 : cs > 1 ? 1 : cs);
    }
    double first[3];
    if (closed)
        vx_v3_sub(P + 3 * ids[0], p, first);
    else
        vx_v3_sub(P + 3 * ids[0], P + 3 * ids[m - 1], first);
    project_dir(first, n, d0);
    /* One face alone at p (an open fan of two neighbours) is a corner, as
     * Catmull-Clark's boundary rules take it: its angle spread to pi made
     * the boundary smooth through p and the face's corner flat, 180
     * degrees, where its patch folded (a lone quad bulged past its edges,
     * normals reversed). */
    if (!(total > 1e-12) || vx_v3_norm(d0) == 0 || m < 2 || (!closed && m == 2)) {
        for (uint32_t i = 0; i < m; i++) {
            double a[3];
            vx_v3_sub(P + 3 * ids[i], p, a);
            project_dir(a, n, dirs + 3 * i);
        }
        return;
    }
    vx_v3_cross(n, d0, e);
    double scale = (closed ? 2 * M_PI : M_PI) / total, phi = 0;
    for (uint32_t i = 0; i < m; i++) {
        for (int c = 0; c < 3; c++)
            dirs[3 * i + c] = cos(phi) * d0[c] + sin(phi) * e[c];
        if (i < nang) {
            double a[3], b[3];
            vx_v3_sub(P + 3 * ids[i], p, a);
            vx_v3_sub(P + 3 * ids[(i + 1) % m], p, b);
            double la = vx_v3_norm(a), lb = vx_v3_norm(b);
            double cs = la > 0 && lb > 0 ? vx_v3_dot(a, b) / (la * lb) : 1;
            phi += scale * acos(cs < -1 ? -1 : cs > 1 ? 1 : cs);
        }
    }
}

/* The cubic from a to b with unit end directions ta (at a, towards b) and
 * tb (at b, towards a), each a third of the chord long. */
static void dir_curve(const double *a, const double *ta, const double *b, const double *tb,
                      double cv[12])
{
    double ab[3];
    vx_v3_sub(b, a, ab);
    double len = vx_v3_norm(ab) / 3;
    for (int c = 0; c < 3; c++) {
        cv[c] = a[c];
        cv[3 + c] = a[c] + len * ta[c];
        cv[6 + c] = b[c] + len * tb[c];
        cv[9 + c] = b[c];
    }
}

/* Direction at end s (0: a, 1: b) of input edge e: its fan direction, or
 * the projected chord where the vertex has no fan. */
static void edge_end_dir(const vx_gregory_topo *t, const double *pos, const double *vn,
                         const double *vdir, uint32_t e, int s, double *out)
{
    uint32_t slot = t->edge_slot[2 * e + s];
    if (slot != NONE) {
        memcpy(out, vdir + 3 * slot, 3 * sizeof *out);
        return;
    }
    uint32_t a = t->edge_v[2 * e + s], b = t->edge_v[2 * e + 1 - s];
    double d[3];
    vx_v3_sub(pos + 3 * b, pos + 3 * a, d);
    project_dir(d, vn + 3 * a, out);
}

/* Curve of input edge e (a -> b, a < b). */
static void edge_curve(const vx_gregory_topo *t, const double *pos, const double *vn,
                       const double *vdir, uint32_t e, double cv[12])
{
    double ta[3], tb[3];
    edge_end_dir(t, pos, vn, vdir, e, 0, ta);
    edge_end_dir(t, pos, vn, vdir, e, 1, tb);
    dir_curve(pos + 3 * t->edge_v[2 * e], ta, pos + 3 * t->edge_v[2 * e + 1], tb, cv);
}

/* de Casteljau at 1/2: the halves and the tangent direction there. */
static void split_curve(const double cv[12], double h0[12], double h1[12])
{
    double p01[3], p12[3], p23[3], q0[3], q1[3], m[3];
    vx_v3_mid(cv, cv + 3, p01);
    vx_v3_mid(cv + 3, cv + 6, p12);
    vx_v3_mid(cv + 6, cv + 9, p23);
    vx_v3_mid(p01, p12, q0);
    vx_v3_mid(p12, p23, q1);
    vx_v3_mid(q0, q1, m);
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
    double gg = vx_v3_dot(g, g), gc = vx_v3_dot(g, c), cc = vx_v3_dot(c, c);
    double xg = vx_v3_dot(x, g), xc = vx_v3_dot(x, c), det = gg * cc - gc * gc;
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
        vx_v3_sub(cv + 3 * (i + 1), cv + 3 * i, C[i]);
    vx_v3_cross(na, C[0], G0);
    vx_v3_cross(nb, C[2], G3);
    int usable = vx_v3_norm(G0) > 0 && vx_v3_norm(G3) > 0;
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
        vx_v3_sub(cp + 3 * is[0], cp + 3 * bs[0], X0);
        vx_v3_sub(cp + 3 * is[3], cp + 3 * bs[3], X3);
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

/* Places edge e's midpoint node on its split curve (cvs + 24 * e), with
 * its plane in nn and the curve's tangent there in mt. */
static void mid_node_frame(const vx_gregory_topo *t, uint32_t e, const double *cvs, double *np,
                           double *nn, double *mt)
{
    /* Midpoint node: on the curve; its plane holds the curve's tangent
     * there and is otherwise the mean of the end planes. */
    uint32_t m = mid_node(t, e), a = t->edge_v[2 * e], b = t->edge_v[2 * e + 1];
    double *tan = mt + 3 * e, n[3];
    memcpy(np + 3 * m, cvs + 24 * e + 9, 3 * sizeof *np);
    vx_v3_sub(cvs + 24 * e + 15, cvs + 24 * e + 6, tan);
    vx_v3_mid(nn + 3 * a, nn + 3 * b, n);
    if (vx_v3_unit(tan) == 0) {
        double d = vx_v3_dot(n, tan);
        for (int c = 0; c < 3; c++)
            n[c] -= d * tan[c];
    }
    if (vx_v3_unit(n)) memcpy(n, nn + 3 * a, sizeof n);
    memcpy(nn + 3 * m, n, sizeof n);
}

/* Places face f's centre node and plane and builds its midpoint -> centre
 * curves into cvs; cdir and ids are scratch for the face's corners. */
static void face_centre(const vx_gregory_topo *t, const double *pos, uint32_t f, double *np,
                        double *nn, const double *mt, double *cdir, uint32_t *ids, double *cvs)
{
    /* Centre: the PN-triangle rule M + (M - V) / 2 over the edge
     * midpoints M and the vertices V (exact for a plane, lifted
     * towards the surface otherwise); plane: mean vertex plane. */
    uint32_t s0 = t->fstart[f], k = t->fstart[f + 1] - s0, cn = centre_node(t, f);
    double M[3] = {0, 0, 0}, V[3] = {0, 0, 0}, n[3] = {0, 0, 0};
    for (uint32_t i = 0; i < k; i++) {
        ids[i] = mid_node(t, t->fedge[s0 + i]);
        const double *vp = pos + 3 * t->fidx[s0 + i];
        for (int c = 0; c < 3; c++) {
            M[c] += np[3 * ids[i] + c] / k;
            V[c] += vp[c] / k;
            n[c] += nn[3 * t->fidx[s0 + i] + c];
        }
    }
    double *cp = np + 3 * cn;
    for (int c = 0; c < 3; c++)
        cp[c] = M[c] + 0.5 * (M[c] - V[c]);
    if (vx_v3_unit(n)) {
        face_normal(t, pos, f, n);
        if (vx_v3_unit(n)) n[0] = n[1] = 0, n[2] = 1;
    }
    memcpy(nn + 3 * cn, n, sizeof n);
    /* Midpoint -> centre curves: at the midpoint towards the centre in
     * the midpoint's plane (square to the edge in a regular face; in a
     * thin one, leaving square would cross the curve from the next
     * midpoint, two sides of a 9 degree sector 0.08 apart, and fold the
     * patch), square to the edge where that direction runs along the edge
     * or away from the face (a degenerate face), towards the face's side (left of the face's
     * direction along the edge); at the centre from the centre's fan. */
    fan_dirs(cp, n, np, ids, k, 1, cdir);
    for (uint32_t i = 0; i < k; i++) {
        uint32_t e = t->fedge[s0 + i], m = ids[i], c = (uint32_t)(2 * t->nedges + s0 + i);
        double tf[3], dm[3], sq[3];
        memcpy(tf, mt + 3 * e, sizeof tf);
        if (t->fidx[s0 + i] != t->edge_v[2 * e])
            for (int d = 0; d < 3; d++)
                tf[d] = -tf[d];
        vx_v3_cross(nn + 3 * m, tf, sq);
        int sq_ok = vx_v3_unit(sq) == 0;
        vx_v3_sub(cp, np + 3 * m, dm);
        project_dir(dm, nn + 3 * m, dm);
        double along = vx_v3_dot(dm, tf);
        int chord_ok = vx_v3_norm(dm) > 0 && fabs(along) < 1 - 1e-9 && /* not along it */
                       (!sq_ok || vx_v3_dot(dm, sq) > 0);
        if (!chord_ok && sq_ok) memcpy(dm, sq, sizeof dm);
        dir_curve(np + 3 * m, dm, cp, cdir + 3 * i, cvs + 12 * c);
    }
}

void vx_gregory_build(const vx_gregory_topo *t, const double *pos, vx_gpatch_set *s)
{
    /* Node positions and normals, vertex fan directions, midpoint tangents,
     * curve control points. */
    size_t maxk = 0;
    for (uint32_t f = 0; f < t->nfaces; f++)
        if (t->fstart[f + 1] - t->fstart[f] > maxk) maxk = t->fstart[f + 1] - t->fstart[f];
    double *np = malloc(3 * t->nnodes * sizeof *np), *nn = malloc(3 * t->nnodes * sizeof *nn);
    double *cvs = malloc(12 * t->ncurves * sizeof *cvs);
    double *vdir = malloc((3 * (size_t)t->fan_off[t->nverts] + 1) * sizeof *vdir);
    double *mt = malloc((3 * t->nedges + 1) * sizeof *mt);
    double *cdir = malloc((3 * maxk + 1) * sizeof *cdir);
    uint32_t *ids = malloc((maxk + 1) * sizeof *ids);
    if (!np || !nn || !cvs || !vdir || !mt || !cdir || !ids) {
        /* callers size-check first; keep the set defined */
        memset(s->cp, 0, s->npatches * VX_GPATCH_POINTS * 3 * sizeof *s->cp);
        goto done;
    }
    memcpy(np, pos, 3 * t->nverts * sizeof *np);
    vertex_normals(t, pos, nn);
    for (size_t v = 0; v < t->nverts; v++)
        if (t->fan_kind[v] != FAN_NONE)
            fan_dirs(pos + 3 * v, nn + 3 * v, pos, t->fan_nb + t->fan_off[v],
                     t->fan_off[v + 1] - t->fan_off[v], t->fan_kind[v] == FAN_CLOSED,
                     vdir + 3 * (size_t)t->fan_off[v]);
    for (uint32_t e = 0; e < t->nedges; e++) {
        if (!t->split) {
            edge_curve(t, pos, nn, vdir, e, cvs + 12 * e);
            continue;
        }
        double cv[12];
        edge_curve(t, pos, nn, vdir, e, cv);
        split_curve(cv, cvs + 24 * e, cvs + 24 * e + 12);
        mid_node_frame(t, e, cvs, np, nn, mt);
    }
    if (t->split)
        for (uint32_t f = 0; f < t->nfaces; f++)
            face_centre(t, pos, f, np, nn, mt, cdir, ids, cvs);
    for (uint32_t c = 0; c < t->ncurves; c++)
        place_curve(t, c, cvs + 12 * c, s);
    for (uint32_t c = 0; c < t->ncurves; c++)
        correct_curve(t, c, cvs + 12 * c, nn + 3 * t->curve_node[2 * c],
                      nn + 3 * t->curve_node[2 * c + 1], s);
    for (size_t p = 0; p < t->npatches; p++) {
        memcpy(s->corner_key + 4 * p, t->pnode + 4 * p, 4 * sizeof *s->corner_key);
        s->face[p] = t->pface[p];
    }
done:
    free(np);
    free(nn);
    free(cvs);
    free(vdir);
    free(mt);
    free(cdir);
    free(ids);
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
