// Uniform Catmull-Clark subdivision through OpenSubdiv Far (catmull_clark.h).
// No exception crosses into C.
#include <climits>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include "gregory/osd_internal.hh"

extern "C" {
#include "gregory/catmull_clark.h"
}

using namespace OpenSubdiv;

namespace vx_osd
{

Far::TopologyRefiner *refiner_new(const vx_mesh *m, vx_err *err)
{
    if (m->nverts > (size_t)INT_MAX || m->nfaces > (size_t)INT_MAX) {
        vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "OpenSubdiv indexes with int: %zu vertices",
                   m->nverts);
        return nullptr;
    }
    std::vector<int> sizes(m->nfaces);
    size_t n = 0;
    for (size_t f = 0; f < m->nfaces; f++) {
        sizes[f] = (int)vx_mesh_face_size(m, f);
        n += (size_t)sizes[f];
    }
    if (n > (size_t)INT_MAX) {
        vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu face corners is too many for OpenSubdiv",
                   n);
        return nullptr;
    }
    std::vector<Far::Index> idx(n);
    for (size_t i = 0; i < n; i++)
        idx[i] = (Far::Index)m->face_idx[i];
    // OpenSubdiv refuses more than VALENCE_LIMIT faces or edges around a
    // vertex (a boundary vertex has one edge more than faces) or vertices in
    // a face, and says only that it failed: name the vertex or face.
    std::vector<uint32_t> valence(m->nverts);
    for (size_t i = 0; i < n; i++)
        if (++valence[m->face_idx[i]] >= (uint32_t)Vtr::VALENCE_LIMIT) {
            vx_err_set(err, VX_EUNPROC, "osd_topology",
                       "vertex %u has %d or more faces around it: OpenSubdiv takes fewer",
                       m->face_idx[i] + 1, Vtr::VALENCE_LIMIT);
            return nullptr;
        }
    for (size_t f = 0; f < m->nfaces; f++)
        if (sizes[f] > Vtr::VALENCE_LIMIT) {
            vx_err_set(err, VX_EUNPROC, "osd_topology",
                       "face %zu has %d vertices, over OpenSubdiv's limit of %d", f + 1, sizes[f],
                       Vtr::VALENCE_LIMIT);
            return nullptr;
        }
    return refiner_new((int)m->nverts, (int)m->nfaces, sizes.data(), idx.data(), err);
}

Far::TopologyRefiner *refiner_new(int nverts, int nfaces, const int *sizes, const int *idx,
                                  vx_err *err)
{
    Far::TopologyDescriptor d;
    d.numVertices = nverts;
    d.numFaces = nfaces;
    d.numVertsPerFace = sizes;
    d.vertIndicesPerFace = idx;
    Sdc::Options so;
    so.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    typedef Far::TopologyRefinerFactory<Far::TopologyDescriptor> Factory;
    Far::TopologyRefiner *r = Factory::Create(d, Factory::Options(Sdc::SCHEME_CATMARK, so));
    if (!r)
        vx_err_set(err, VX_EUNPROC, "osd_topology",
                   "OpenSubdiv cannot take the mesh's topology (%d faces)", nfaces);
    return r;
}

} // namespace vx_osd

extern "C" uint64_t vx_cc_quads(const vx_mesh *m, int levels)
{
    uint64_t corners = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        corners += vx_mesh_face_size(m, f);
    return levels < 1 ? 0 : corners << (2 * (levels - 1));
}

namespace
{

using vx_osd::Point;

// Area-weighted vertex normals of a quad mesh (the fallback where the limit
// tangents are parallel).
// Twice face f's vector area (Newell's method) into n.
void face_area(const Far::TopologyLevel &lv, const std::vector<Point> &pos, int f, double n[3])
{
    Far::ConstIndexArray fv = lv.GetFaceVertices(f);
    n[0] = n[1] = n[2] = 0;
    for (int k = 0; k < fv.size(); k++) {
        const double *a = pos[fv[k]].p, *b = pos[fv[(k + 1) % fv.size()]].p;
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
}

void face_normals(const Far::TopologyLevel &lv, const std::vector<Point> &pos,
                  std::vector<double> &acc)
{
    acc.assign(3 * pos.size(), 0.0);
    for (int f = 0; f < lv.GetNumFaces(); f++) {
        double n[3];
        face_area(lv, pos, f, n);
        Far::ConstIndexArray fv = lv.GetFaceVertices(f);
        for (int k = 0; k < fv.size(); k++)
            for (int c = 0; c < 3; c++)
                acc[3 * fv[k] + c] += n[c];
    }
}

// Where the area-weighted normal vanishes too (faces that cancel: a sheet
// with both sides, a fold): the normal of vertex v's largest face, else +z,
// so that every normal written is of unit length (glTF requires it).
void lone_normal(const Far::TopologyLevel &lv, const std::vector<Point> &pos, int v, double n[3])
{
    double best = 0;
    n[0] = n[1] = 0;
    n[2] = 1;
    Far::ConstIndexArray vf = lv.GetVertexFaces(v);
    for (int k = 0; k < vf.size(); k++) {
        double f[3];
        face_area(lv, pos, vf[k], f);
        double l = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
        if (std::isfinite(l) && l > best) {
            best = l;
            memcpy(n, f, sizeof f);
        }
    }
}

// The first edge of the base mesh that three or more faces share (the
// same face repeated too), or -1. OpenSubdiv's limit evaluation sizes its
// buffers by the most edges at a vertex, and a refined vertex on such an
// edge has more faces than that: it wrote past them (heap corruption,
// from 19 faces on one edge a crash).
int nonmanifold_edge(const Far::TopologyLevel &lv)
{
    for (int e = 0; e < lv.GetNumEdges(); e++)
        if (lv.GetEdgeFaces(e).size() > 2) return e;
    return -1;
}

int refine(const vx_mesh *m, int levels, int limit, vx_mesh **out, float **normals, vx_err *err)
{
    std::unique_ptr<Far::TopologyRefiner> r(vx_osd::refiner_new(m, err));
    if (!r) return -1;
    const int bad = nonmanifold_edge(r->GetLevel(0));
    if (bad >= 0 && limit) {
        Far::ConstIndexArray ev = r->GetLevel(0).GetEdgeVertices(bad);
        return vx_err_set(err, VX_EUNPROC, "osd_topology",
                          "the edge from vertex %d to vertex %d borders %d faces: limit positions "
                          "need every edge to border at most two (limit: false subdivides it)",
                          ev[0] + 1, ev[1] + 1, r->GetLevel(0).GetEdgeFaces(bad).size());
    }
    Far::TopologyRefiner::UniformOptions uo(levels);
    uo.fullTopologyInLastLevel = true; // PrimvarRefiner::Limit needs it
    r->RefineUniform(uo);

    std::vector<Point> a(m->nverts), b;
    for (size_t i = 0; i < m->nverts; i++)
        for (int k = 0; k < 3; k++)
            a[i].p[k] = m->pos[3 * i + (size_t)k];
    Far::PrimvarRefinerReal<double> pr(*r);
    for (int l = 1; l <= levels; l++) {
        b.resize((size_t)r->GetLevel(l).GetNumVertices());
        pr.Interpolate(l, a, b);
        a.swap(b);
    }
    const Far::TopologyLevel &last = r->GetLevel(levels);
    size_t nv = (size_t)last.GetNumVertices(), nf = (size_t)last.GetNumFaces();
    // Limit tangents give the normals; with an edge of three or more faces
    // the faces' areas do.
    std::vector<Point> lim, t1, t2;
    if (bad < 0) {
        lim.resize(nv);
        t1.resize(nv);
        t2.resize(nv);
        pr.Limit(a, lim, t1, t2);
        if (limit) a.swap(lim);
    }

    std::vector<float> nv3(3 * nv);
    std::vector<double> acc;
    for (size_t i = 0; i < nv; i++) {
        double n[3] = {0, 0, 0}, len = 0, scale = 0;
        if (bad < 0) {
            const double *u = t1[i].p, *v = t2[i].p;
            n[0] = u[1] * v[2] - u[2] * v[1];
            n[1] = u[2] * v[0] - u[0] * v[2];
            n[2] = u[0] * v[1] - u[1] * v[0];
            len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            scale = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]) *
                    std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
        }
        if (bad >= 0 || !(len > 1e-12 * scale) || !std::isfinite(len)) {
            if (acc.empty()) face_normals(last, a, acc);
            memcpy(n, &acc[3 * i], sizeof n);
            len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            if (!(len > 0) || !std::isfinite(len)) {
                lone_normal(last, a, (int)i, n);
                len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
            }
        }
        for (int k = 0; k < 3; k++)
            nv3[3 * i + (size_t)k] = len > 0 ? (float)(n[k] / len) : 0.0f;
    }
    vx_mesh *o = vx_mesh_new();
    float *nrm = (float *)malloc(3 * nv * sizeof(float) + 1);
    if (o) {
        o->pos = (double *)malloc(3 * nv * sizeof(double) + 1);
        o->face_start = (uint32_t *)malloc((nf + 1) * sizeof(uint32_t));
        o->face_idx = (uint32_t *)malloc(4 * nf * sizeof(uint32_t) + 1);
    }
    if (!o || !nrm || !o->pos || !o->face_start || !o->face_idx) {
        vx_mesh_free(o);
        free(nrm);
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %zu vertices", nv);
    }
    o->nverts = nv;
    o->nfaces = nf;
    for (size_t i = 0; i < nv; i++)
        memcpy(o->pos + 3 * i, a[i].p, sizeof a[i].p);
    size_t c = 0;
    o->face_start[0] = 0;
    for (size_t f = 0; f < nf; f++) {
        Far::ConstIndexArray fv = last.GetFaceVertices((Far::Index)f);
        for (int k = 0; k < fv.size(); k++)
            o->face_idx[c++] = (uint32_t)fv[k];
        o->face_start[f + 1] = (uint32_t)c;
    }
    memcpy(nrm, nv3.data(), nv3.size() * sizeof(float));
    if (vx_mesh_analyze(o, err)) {
        vx_mesh_free(o);
        free(nrm);
        return -1;
    }
    *out = o;
    *normals = nrm;
    return 0;
}

} // namespace

extern "C" int vx_cc_refine(const vx_mesh *m, int levels, int limit, vx_mesh **out, float **normals,
                            vx_err *err)
{
    *out = nullptr;
    *normals = nullptr;
    if (levels < 1 || levels > VX_CC_MAX_LEVELS)
        return vx_err_set(err, VX_EUNPROC, "invalid_params", "levels must be in [1, %d], got %d",
                          VX_CC_MAX_LEVELS, levels);
    try {
        return refine(m, levels, limit, out, normals, err);
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %d levels", levels);
    } catch (...) {
        return vx_err_set(err, VX_EINTERNAL, "osd_failed", "OpenSubdiv failed");
    }
}
