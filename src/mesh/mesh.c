/* Mesh type, triangulated view and load-time analysis. */
#include "mesh/mesh.h"

#include <math.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "util/vec3.h"

vx_mesh *vx_mesh_new(void)
{
    return calloc(1, sizeof(vx_mesh));
}

void vx_mesh_free(vx_mesh *m)
{
    if (!m) return;
    if (m->tri != m->face_idx) free(m->tri);
    free(m->face_idx);
    free(m->face_start);
    free(m->pos);
    free(m->patch_idx);
    free(m->net);
    free(m);
}

uint32_t vx_mesh_face_size(const vx_mesh *m, size_t f)
{
    return m->face_start ? m->face_start[f + 1] - m->face_start[f] : 3;
}

const uint32_t *vx_mesh_face(const vx_mesh *m, size_t f)
{
    return m->face_idx + (m->face_start ? m->face_start[f] : 3 * f);
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

static uint64_t mix(uint64_t x)
{
    x ^= x >> 33;
    x *= 0xff51afd7ed558ccdull;
    x ^= x >> 33;
    x *= 0xc4ceb9fe1a85ec53ull;
    return x ^ (x >> 33);
}

/* The bits of position p with -0 read as +0 (one place, two spellings). */
static void pos_key(const double *p, uint64_t b[3])
{
    for (int k = 0; k < 3; k++) {
        double x = p[k] + 0.0;
        memcpy(&b[k], &x, sizeof x);
    }
}

uint32_t *vx_mesh_weld(const vx_mesh *m)
{
    size_t cap = 16;
    while (cap < 2 * m->nverts)
        cap <<= 1;
    uint32_t *slot = malloc(cap * sizeof *slot), *canon = malloc(m->nverts * sizeof *canon + 1);
    if (!slot || !canon) {
        free(slot);
        free(canon);
        return NULL;
    }
    memset(slot, 0xff, cap * sizeof *slot);
    for (size_t v = 0; v < m->nverts; v++) {
        uint64_t b[3], o[3];
        pos_key(m->pos + 3 * v, b);
        size_t at = (size_t)(mix(b[0] ^ mix(b[1] ^ mix(b[2])))) & (cap - 1);
        for (;; at = (at + 1) & (cap - 1)) {
            if (slot[at] == UINT32_MAX) {
                slot[at] = (uint32_t)v;
                canon[v] = (uint32_t)v;
                break;
            }
            pos_key(m->pos + 3 * (size_t)slot[at], o);
            if (!memcmp(o, b, sizeof b)) {
                canon[v] = slot[at];
                break;
            }
        }
    }
    free(slot);
    return canon;
}

/* Appends edge (lo, hi, net) to *net (*n of them, room for *cap): 0, or -1
 * without memory. */
static int push_net(vx_mesh_edge **net, size_t *n, size_t *cap, uint32_t lo, uint32_t hi, int32_t d)
{
    if (*n == *cap) {
        size_t c = *cap ? 2 * *cap : 64;
        vx_mesh_edge *e = realloc(*net, c * sizeof *e);
        if (!e) return -1;
        *net = e;
        *cap = c;
    }
    (*net)[(*n)++] = (vx_mesh_edge){lo, hi, d};
    return 0;
}

/* Counts boundary (used once), non-manifold (used 3+ times) and
 * misoriented (used twice, both times the same way: the faces either side
 * disagree on their orientation) undirected edges into out[0], out[1],
 * out[2], with vertex v read as canon[v] (canon NULL: as itself); with net
 * not NULL, the edges whose uses do not cancel into *net (malloc'd, *nnet
 * of them; past keep of them, none: *net NULL and *nnet keep + 1). Edges are bucketed by their
 * lower vertex (CSR: 4 bytes per edge plus 4 per vertex), then each small bucket is sorted: a
 * quarter of the memory of sorting 64-bit edge keys, which matters at 10^7 triangles. An edge whose
 * two ends weld into one is not an edge. */
static int count_edges(const vx_mesh *m, size_t nedges, const uint32_t *canon, size_t out[3],
                       vx_mesh_edge **net, size_t *nnet, size_t keep, vx_err *err)
{
#define V(x) (canon ? canon[x] : (x))
    out[0] = out[1] = out[2] = 0;
    if (nedges >= UINT32_MAX)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu edges is too many", nedges);
    /* each entry is the other end << 1 | the way the face goes along it */
    if (m->nverts >= (size_t)1 << 31)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu vertices is too many", m->nverts);
    uint32_t *start = calloc(m->nverts + 1, sizeof *start);
    uint32_t *nbr = malloc(nedges * sizeof *nbr + 1);
    if (!start || !nbr) {
        free(start);
        free(nbr);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %zu edges", nedges);
    }
    for (size_t f = 0; f < m->nfaces; f++) {
        const uint32_t *v = vx_mesh_face(m, f);
        uint32_t n = vx_mesh_face_size(m, f);
        for (uint32_t k = 0; k < n; k++) {
            uint32_t a = V(v[k]), b = V(v[(k + 1) % n]);
            if (a != b) start[a < b ? a : b]++;
        }
    }
    for (size_t i = 1; i <= m->nverts; i++)
        start[i] += start[i - 1];
    /* start[v] holds the end of v's bucket; filling backwards leaves it at
     * the bucket's beginning. */
    for (size_t f = 0; f < m->nfaces; f++) {
        const uint32_t *v = vx_mesh_face(m, f);
        uint32_t n = vx_mesh_face_size(m, f);
        for (uint32_t k = 0; k < n; k++) {
            uint32_t a = V(v[k]), b = V(v[(k + 1) % n]);
            if (a == b) continue;
            if (a < b)
                nbr[--start[a]] = b << 1;
            else
                nbr[--start[b]] = a << 1 | 1u;
        }
    }
    size_t cap = 0;
    int rc = 0;
    if (net) {
        *net = NULL;
        *nnet = 0;
    }
    for (size_t v = 0; v < m->nverts && !rc; v++) {
        uint32_t *e = nbr + start[v];
        size_t n = start[v + 1] - start[v];
        if (n > 1) qsort(e, n, sizeof *e, cmp_u32);
        for (size_t i = 0; i < n;) {
            size_t j = i, back = 0; /* entries with the way bit: hi -> lo */
            for (; j < n && e[j] >> 1 == e[i] >> 1; j++)
                back += e[j] & 1;
            if (j - i == 1)
                out[0]++;
            else if (j - i > 2)
                out[1]++;
            else if (e[i] == e[i + 1])
                out[2]++;
            int32_t d = (int32_t)(j - i - back) - (int32_t)back;
            if (net && d && *nnet == keep) { /* too many to keep */
                free(*net);
                *net = NULL;
                *nnet = keep + 1;
            }
            if (net && d && *nnet < keep && push_net(net, nnet, &cap, (uint32_t)v, e[i] >> 1, d))
                rc = -1;
            i = j;
        }
    }
    free(start);
    free(nbr);
    if (rc) {
        free(*net);
        *net = NULL;
        *nnet = 0;
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the boundary edges");
    }
    return 0;
#undef V
}

int vx_mesh_check_indices(const vx_mesh *m, vx_err *err)
{
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (m->tri[i] >= m->nverts)
            return vx_err_set(err, VX_EINTERNAL, "mesh_invalid",
                              "triangle %zu uses vertex %u of %zu", i / 3, m->tri[i], m->nverts);
    return 0;
}

/* 2 x the signed area of (a, b, c) in the plane of projection. */
static double orient2(const double *a, const double *b, const double *c)
{
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
}

/* Whether p lies in the counter-clockwise triangle (a, b, c), its edges
 * included. */
static int in_triangle(const double *p, const double *a, const double *b, const double *c)
{
    return orient2(a, b, p) >= 0 && orient2(b, c, p) >= 0 && orient2(c, a, p) >= 0;
}

/* Face v[0..n) as the n - 2 triangles of a fan from v[0], into out. */
static void fan(const uint32_t *v, uint32_t n, uint32_t *out)
{
    for (uint32_t k = 1; k + 1 < n; k++) {
        out[3 * (k - 1)] = v[0];
        out[3 * (k - 1) + 1] = v[k];
        out[3 * (k - 1) + 2] = v[k + 1];
    }
}

/* Face v[0..n) (n >= 4) as n - 2 triangles into out: a fan where the face
 * is convex in the plane its Newell normal is most along (no turn to the
 * right, none straight back), else ear clipping there (up to VX_MESH_EAR_MAX vertices;
 * a fan beyond), so that no triangle covers what lies outside a concave
 * face. Scratch: q 2 n doubles, nx 2 n ints. */
static void triangulate(const double *pos, size_t nverts, const uint32_t *v, uint32_t n,
                        uint32_t *out, double *q, int *nx)
{
    if (n > VX_MESH_EAR_MAX) return fan(v, n, out);
    for (uint32_t i = 0; i < n; i++)
        if (v[i] >= nverts) return fan(v, n, out); /* refused by vx_mesh_check_indices */
    double N[3] = {0, 0, 0};
    for (uint32_t i = 0; i < n; i++) {
        const double *a = pos + 3 * (size_t)v[i], *b = pos + 3 * (size_t)v[(i + 1) % n];
        N[0] += (a[1] - b[1]) * (a[2] + b[2]);
        N[1] += (a[2] - b[2]) * (a[0] + b[0]);
        N[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    int ax = fabs(N[0]) >= fabs(N[1]) && fabs(N[0]) >= fabs(N[2]) ? 0
             : fabs(N[1]) >= fabs(N[2])                           ? 1
                                                                  : 2;
    /* the other two axes, in the order that makes the face counter-clockwise */
    int u = (ax + 1) % 3, w = (ax + 2) % 3;
    if (N[ax] < 0) {
        int t = u;
        u = w;
        w = t;
    }
    for (uint32_t i = 0; i < n; i++) {
        const double *p = pos + 3 * (size_t)v[i];
        q[2 * i] = p[u];
        q[2 * i + 1] = p[w];
    }
    int convex = 1;
    for (uint32_t i = 0; i < n && convex; i++) {
        /* every turn to the left, or straight on (not back: a spike) */
        const double *a = q + 2 * i, *b = q + 2 * ((i + 1) % n), *c = q + 2 * ((i + 2) % n);
        double o = orient2(a, b, c);
        convex =
            o > 0 || (o == 0 && (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]) >= 0);
    }
    if (convex || !(N[ax] != 0)) return fan(v, n, out);
    /* ear clipping on the ring (nx next, pv previous), with a budget of
     * 4 n^2 containment tests: past it (a face no simple polygon would
     * need it for) the rest of the ring is a fan */
    int *pv = nx + n;
    uint64_t budget = 4 * (uint64_t)n * n;
    for (uint32_t i = 0; i < n; i++) {
        nx[i] = (int)((i + 1) % n);
        pv[i] = (int)((i + n - 1) % n);
    }
    /* What a corner must be to be cut, raised after a whole turn finds
     * none: 0 an ear (a left turn with no other vertex in its triangle;
     * one at a corner's position, as a hole's bridge repeats them, does
     * not count), 1 an ear or a flat one (collinear corners), 2 any left
     * turn, 3 any corner (a face that crosses itself). */
    uint32_t left = n, t = 0, miss = 0;
    int i = 0, level = 0;
    while (left > 3) {
        int a = pv[i], c = nx[i];
        const double *A = q + 2 * a, *B = q + 2 * i, *C = q + 2 * c;
        double o = orient2(A, B, C);
        int ear = level >= 3 || (level == 1 ? o >= 0 : o > 0);
        for (int k = nx[c]; level < 2 && ear && k != a && budget; k = nx[k], budget--) {
            const double *K = q + 2 * k;
            if (in_triangle(K, A, B, C) && !(K[0] == A[0] && K[1] == A[1]) &&
                !(K[0] == B[0] && K[1] == B[1]) && !(K[0] == C[0] && K[1] == C[1]))
                ear = 0;
        }
        if (!budget) break;
        if (ear) {
            out[3 * t] = v[a];
            out[3 * t + 1] = v[i];
            out[3 * t + 2] = v[c];
            t++;
            nx[a] = c;
            pv[c] = a;
            left--;
            miss = 0;
            level = 0;
            i = a;
        } else {
            if (++miss >= left) {
                miss = 0;
                level++;
            }
            i = c;
        }
    }
    for (int k = nx[i]; nx[k] != i; k = nx[k]) { /* the ring left: 3 vertices, or more */
        out[3 * t] = v[i];
        out[3 * t + 1] = v[k];
        out[3 * t + 2] = v[nx[k]];
        t++;
    }
}

int vx_mesh_analyze(vx_mesh *m, vx_err *err)
{
    /* Triangulated view: a fan per convex face, ear clipping for the rest. */
    if (m->face_start && !m->tri) {
        size_t nt = 0;
        for (size_t f = 0; f < m->nfaces; f++)
            nt += vx_mesh_face_size(m, f) - 2;
        m->tri = malloc(3 * nt * sizeof(uint32_t) + 1);
        if (!m->tri)
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %zu triangles",
                              nt);
        double q[2 * VX_MESH_EAR_MAX];
        int nx[2 * VX_MESH_EAR_MAX];
        size_t t = 0;
        for (size_t f = 0; f < m->nfaces; f++) {
            const uint32_t *v = vx_mesh_face(m, f);
            uint32_t n = vx_mesh_face_size(m, f);
            if (n == 3) {
                memcpy(m->tri + 3 * t, v, 3 * sizeof *v);
            } else {
                triangulate(m->pos, m->nverts, v, n, m->tri + 3 * t, q, nx);
            }
            t += n - 2;
        }
        m->ntris = nt;
    } else if (!m->face_start) {
        m->tri = m->face_idx;
        m->ntris = m->nfaces;
    }

    /* The box of the vertices the faces and patches use: one no face uses
     * (left over in an OBJ, say) would stretch every grid made from it. */
    uint8_t *used = calloc(m->nverts + 1, 1);
    if (!used) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the analysis");
    for (size_t i = 0; i < 3 * m->ntris; i++)
        if (m->tri[i] < m->nverts) used[m->tri[i]] = 1;
    for (size_t i = 0; i < 16 * m->npatches; i++)
        if (m->patch_idx[i] < m->nverts) used[m->patch_idx[i]] = 1;
    for (int a = 0; a < 3; a++) {
        m->bbox_min[a] = INFINITY;
        m->bbox_max[a] = -INFINITY;
    }
    for (size_t i = 0; i < m->nverts; i++)
        for (int a = 0; a < 3 && used[i]; a++) {
            double x = m->pos[3 * i + a];
            if (x < m->bbox_min[a]) m->bbox_min[a] = x;
            if (x > m->bbox_max[a]) m->bbox_max[a] = x;
        }
    free(used);
    for (int a = 0; a < 3; a++)
        if (m->bbox_min[a] > m->bbox_max[a]) m->bbox_min[a] = m->bbox_max[a] = 0; /* none used */

    m->faces_by_size[0] = m->faces_by_size[1] = m->faces_by_size[2] = 0;
    size_t nedges = 0;
    for (size_t f = 0; f < m->nfaces; f++) {
        uint32_t n = vx_mesh_face_size(m, f);
        m->faces_by_size[n == 3 ? 0 : n == 4 ? 1 : 2]++;
        nedges += n;
    }

    m->degenerate_tris = 0;
    for (size_t t = 0; t < m->ntris; t++) {
        const double *a = m->pos + 3 * m->tri[3 * t], *b = m->pos + 3 * m->tri[3 * t + 1],
                     *c = m->pos + 3 * m->tri[3 * t + 2];
        double u[3], v[3], n[3];
        vx_v3_sub(b, a, u);
        vx_v3_sub(c, a, v);
        vx_v3_cross(u, v, n);
        if (n[0] == 0 && n[1] == 0 && n[2] == 0) m->degenerate_tris++;
    }

    size_t c[3];
    free(m->net);
    m->net = NULL;
    m->nnet = 0;
    m->net_known = 0;
    /* whether any edge's uses do not cancel (keep 0: nnet 1 if one does) */
    if (count_edges(m, nedges, NULL, c, &m->net, &m->nnet, 0, err)) return -1;
    m->boundary_edges = c[0];
    m->nonmanifold_edges = c[1];
    m->boundary_edges_welded = c[0];
    m->misoriented_edges = c[2];
    /* welding merges edges, adding their nets: none stays none */
    m->net_known = !m->nnet;
    if (!m->nnet) return 0;
    m->nnet = 0;
    uint32_t *canon = vx_mesh_weld(m);
    if (!canon)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to weld %zu vertices",
                          m->nverts);
    int rc = count_edges(m, nedges, canon, c, &m->net, &m->nnet, VX_MESH_NET_KEEP, err);
    free(canon);
    if (rc) return rc;
    if (m->boundary_edges) { /* a closed mesh with odd non-manifold edges keeps its counts */
        m->boundary_edges_welded = c[0];
        m->misoriented_edges = c[2]; /* a seam of split vertices hid some */
    }
    if (m->nnet > VX_MESH_NET_KEEP) /* not kept: found again when asked */
        m->nnet = 0;
    else
        m->net_known = 1;
    return 0;
}

int vx_mesh_net_edges(const vx_mesh *m, vx_mesh_edge **out, size_t *n, vx_err *err)
{
    *out = NULL;
    *n = 0;
    if (m->net_known) {
        if (!m->nnet) return 0;
        *out = malloc(m->nnet * sizeof **out);
        if (!*out)
            return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the boundary");
        memcpy(*out, m->net, m->nnet * sizeof **out);
        *n = m->nnet;
        return 0;
    }
    size_t nedges = 0, c[3];
    for (size_t f = 0; f < m->nfaces; f++)
        nedges += vx_mesh_face_size(m, f);
    uint32_t *canon = vx_mesh_weld(m);
    if (!canon)
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to weld %zu vertices",
                          m->nverts);
    int rc = count_edges(m, nedges, canon, c, out, n, SIZE_MAX - 1, err);
    free(canon);
    return rc;
}

#define COST_BASE (UINT64_C(16) << 20)

/* The patch count on the first line of a .bpt file, or UINT64_MAX. */
static uint64_t bpt_declared_patches(const char *path)
{
    FILE *f = path ? fopen(path, "rb") : NULL;
    if (!f) return UINT64_MAX;
    char line[64];
    uint64_t n = UINT64_MAX;
    if (fgets(line, sizeof line, f)) {
        const char *p = line;
        if (!strncmp(p, "\xef\xbb\xbf", 3)) p += 3;
        while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n')
            p++;
        if (*p >= '0' && *p <= '9') {
            n = 0;
            for (; *p >= '0' && *p <= '9'; p++)
                if (n < UINT64_C(1) << 40) n = n * 10 + (uint64_t)(*p - '0');
        }
    }
    fclose(f);
    return n;
}

static uint64_t draco_cost(const char *path, uint64_t bytes, const vx_mesh_limits *lim)
{
    vx_draco_header h = {0};
    h.faces = 2048 * bytes + 64;
    if (lim && lim->max_triangles && h.faces > lim->max_triangles) h.faces = lim->max_triangles;
    h.points = 3 * h.faces;
    h.attribute_sets = 4;
    FILE *f = path ? fopen(path, "rb") : NULL;
    if (f) {
        /* The header and any metadata: a window at the start is enough but
         * for unusually large metadata, which falls back to the bound. */
        static const size_t window = 64 * 1024;
        unsigned char *buf = malloc(window);
        size_t n = buf ? fread(buf, 1, window, f) : 0;
        vx_draco_header d;
        vx_err err;
        int rc = buf ? vx_draco_check_header(buf, n, bytes, lim, &d, &err) : 1;
        free(buf);
        fclose(f);
        if (rc < 0) return bytes + COST_BASE; /* refused at the header */
        if (rc == 0) h = d;
    }
    return bytes + vx_draco_decode_bound(&h, bytes) + 32 * (h.faces + h.points + h.extra_points) +
           (UINT64_C(12) << 20);
}

/* The formats of mesh/import.cc: the file, the decode bound (the glTF
 * parse is held to it), and the vx_mesh made from it with its analysis,
 * from the declared counts of a window at the start of the file (glTF: of
 * the whole JSON). */
static uint64_t import_cost(const char *path, vx_mesh_format fmt, uint64_t bytes,
                            const vx_mesh_limits *lim)
{
    vx_mesh_declared d = {0};
    size_t window = fmt == VX_MESH_GLTF ? (size_t)bytes : 64 * 1024;
    if (fmt == VX_MESH_GLB) window = 1 << 20;
    if (window > bytes) window = (size_t)bytes;
    FILE *f = path ? fopen(path, "rb") : NULL;
    unsigned char *buf = f ? malloc(window + 1) : NULL;
    size_t n = buf ? fread(buf, 1, window, f) : 0;
    vx_err err;
    int rc = buf ? vx_declared_check(fmt, buf, n, bytes, lim, &d, &err) : 1;
    free(buf);
    if (f) fclose(f);
    if (rc < 0) return bytes + COST_BASE; /* refused at the header */
    if (rc > 0) { /* the header runs past the window: what the bytes allow */
        uint64_t t = bytes / 2;
        if (lim && lim->max_triangles && t > lim->max_triangles) t = lim->max_triangles;
        d.vertices = d.indices = 3 * t;
        d.faces = d.triangles = t;
    }
    /* glTF: cJSON's tree of the JSON in the header check (up to 40 bytes a
     * JSON byte); the mesh: positions, faces, the fan and the edge table. */
    uint64_t json = fmt == VX_MESH_GLTF ? 40 * bytes : fmt == VX_MESH_GLB ? 40 * (uint64_t)n : 0;
    return bytes + json + vx_declared_decode_bound(fmt, bytes, &d) + 32 * d.vertices +
           8 * d.indices + 8 * d.faces + 48 * d.triangles + COST_BASE;
}

uint64_t vx_mesh_parse_cost(const char *path, vx_mesh_format fmt, uint64_t bytes,
                            const vx_mesh_limits *lim)
{
    switch (fmt) {
    case VX_MESH_STL:
    case VX_MESH_PLY:
    case VX_MESH_GLTF:
    case VX_MESH_GLB:
    case VX_MESH_OFF:
        return import_cost(path, fmt, bytes, lim);
    case VX_MESH_DRACO:
        return draco_cost(path, bytes, lim);
    case VX_MESH_BPT: {
        uint64_t np = bytes / 32, declared = bpt_declared_patches(path);
        if (declared < np) np = declared;
        if (lim && lim->max_triangles && np > lim->max_triangles / 128)
            np = lim->max_triangles / 128;
        return np * 6656 + bytes / 6 * 40 + COST_BASE;
    }
    default:
        return 8 * bytes + COST_BASE; /* OBJ, and what the sniffer could not tell */
    }
}

FILE *vx_mesh_open(const char *path, vx_err *err)
{
    FILE *f = fopen(path, "rb");
    if (!f) vx_err_set(err, VX_EIO, "mesh_io", "cannot open %s: %s", path, strerror(errno));
    return f;
}

int vx_mesh_face_repeat(const uint32_t *v, size_t n, uint32_t *scratch, uint32_t *rep)
{
    if (n <= 16) {
        for (size_t i = 0; i < n; i++)
            for (size_t j = i + 1; j < n; j++)
                if (v[i] == v[j]) {
                    *rep = v[i];
                    return 1;
                }
        return 0;
    }
    /* Long n-gons: sort a copy instead of the quadratic scan. */
    memcpy(scratch, v, n * sizeof *v);
    qsort(scratch, n, sizeof *scratch, cmp_u32);
    for (size_t i = 1; i < n; i++)
        if (scratch[i] == scratch[i - 1]) {
            *rep = scratch[i];
            return 1;
        }
    return 0;
}
