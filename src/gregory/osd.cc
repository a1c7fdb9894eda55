// The approximate-cc construction and its distance to the Catmull-Clark
// limit surface, through OpenSubdiv Far patch tables (osd.h). No exception
// crosses into C.
#include <climits>
#include <cmath>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>

#include "gregory/osd_internal.hh"

extern "C" {
#include "gregory/osd.h"
}

using namespace OpenSubdiv;
using vx_osd::Point;

namespace
{

// The quad mesh the patches live on (osd.h).
struct QuadMesh {
    std::vector<Point> pos;
    std::vector<int> idx;         // 4 per quad
    std::vector<uint32_t> parent; // the input face of each quad
    int nquads() const { return (int)(idx.size() / 4); }
};

int quad_mesh(const vx_mesh *m, QuadMesh &q, vx_err *err)
{
    if (m->nverts > (size_t)INT_MAX / 8 || m->nfaces > (size_t)INT_MAX / 8)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "%zu vertices is too many for OpenSubdiv", m->nverts);
    bool quads = true;
    for (size_t f = 0; f < m->nfaces && quads; f++)
        quads = vx_mesh_face_size(m, f) == 4;
    if (quads) {
        q.pos.resize(m->nverts);
        for (size_t i = 0; i < m->nverts; i++)
            memcpy(q.pos[i].p, m->pos + 3 * i, sizeof q.pos[i].p);
        q.idx.assign(m->face_idx, m->face_idx + 4 * m->nfaces);
        q.parent.resize(m->nfaces);
        for (size_t f = 0; f < m->nfaces; f++)
            q.parent[f] = (uint32_t)f;
        return 0;
    }
    std::unique_ptr<Far::TopologyRefiner> r(vx_osd::refiner_new(m, err));
    if (!r) return -1;
    r->RefineUniform(Far::TopologyRefiner::UniformOptions(1));
    const Far::TopologyLevel &l1 = r->GetLevel(1);
    std::vector<Point> src(m->nverts);
    for (size_t i = 0; i < m->nverts; i++)
        memcpy(src[i].p, m->pos + 3 * i, sizeof src[i].p);
    q.pos.resize((size_t)l1.GetNumVertices());
    Far::PrimvarRefinerReal<double>(*r).Interpolate(1, src, q.pos);
    int nq = l1.GetNumFaces();
    q.idx.resize(4 * (size_t)nq);
    q.parent.resize((size_t)nq);
    // Far numbers the child faces of a face consecutively, in face order.
    size_t child = 0;
    for (size_t f = 0; f < m->nfaces; f++)
        for (uint32_t k = 0; k < vx_mesh_face_size(m, f); k++)
            q.parent[child++] = (uint32_t)f;
    for (int f = 0; f < nq; f++) {
        Far::ConstIndexArray fv = l1.GetFaceVertices(f);
        for (int k = 0; k < 4; k++)
            q.idx[4 * (size_t)f + (size_t)k] = fv[k];
    }
    return 0;
}

// A patch table of the quad mesh at an isolation level, with the points its
// patches index (refined vertices of every level, then the local points).
struct Patches {
    std::unique_ptr<Far::TopologyRefiner> refiner;
    std::unique_ptr<Far::PatchTable> table;
    std::unique_ptr<Far::PatchMap> map;
    std::vector<Point> points;

    // Position on the patch of quad f at (u, v) of the quad; false where
    // there is no patch.
    bool eval(int f, double u, double v, double out[3]) const
    {
        const Far::PatchTable::PatchHandle *h = map->FindPatch(f, u, v);
        if (!h) return false;
        double w[20];
        table->EvaluateBasis(*h, u, v, w);
        Far::ConstIndexArray cv = table->GetPatchVertices(*h);
        out[0] = out[1] = out[2] = 0;
        for (int i = 0; i < cv.size() && i < 20; i++) {
            if (cv[i] < 0) continue; // a phantom point: its weight was folded
            const double *p = points[(size_t)cv[i]].p;
            for (int a = 0; a < 3; a++)
                out[a] += w[i] * p[a];
        }
        return true;
    }
};

int make_patches(const QuadMesh &q, int isolation, Patches &pt, vx_err *err)
{
    std::vector<int> sizes((size_t)q.nquads(), 4);
    pt.refiner.reset(
        vx_osd::refiner_new((int)q.pos.size(), q.nquads(), sizes.data(), q.idx.data(), err));
    if (!pt.refiner) return -1;
    Far::PatchTableFactory::Options po((unsigned)isolation);
    po.SetEndCapType(Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
    po.SetPatchPrecision<double>();
    po.generateVaryingTables = false;
    // Smooth boundary corners get true (end-cap) patches, not the legacy
    // sharp regular ones that would leave the limit surface.
    po.generateLegacySharpCornerPatches = false;
    pt.refiner->RefineAdaptive(po.GetRefineAdaptiveOptions());
    pt.table.reset(Far::PatchTableFactory::Create(*pt.refiner, po));
    if (!pt.table)
        return vx_err_set(err, VX_EUNPROC, "osd_patches", "OpenSubdiv made no patch table");
    int nref = pt.refiner->GetNumVerticesTotal();
    pt.points.resize((size_t)nref + (size_t)pt.table->GetNumLocalPoints());
    std::copy(q.pos.begin(), q.pos.end(), pt.points.begin());
    Far::PrimvarRefinerReal<double> pr(*pt.refiner);
    Point *src = pt.points.data();
    for (int l = 1; l <= pt.refiner->GetMaxLevel(); l++) {
        Point *dst = src + pt.refiner->GetLevel(l - 1).GetNumVertices();
        pr.Interpolate(l, src, dst);
        src = dst;
    }
    if (pt.table->GetNumLocalPoints())
        pt.table->GetLocalPointStencilTable<double>()->UpdateValues(pt.points.data(),
                                                                    pt.points.data() + nref);
    pt.map.reset(new Far::PatchMap(*pt.table));
    return 0;
}

// OpenSubdiv's Gregory basis point 5c + k (corner c in 0..3; k: P, Ep, Em,
// Fp, Fm) → our slot. Ep runs towards corner c+1, Em towards corner c-1;
// Fp is the interior point that acts on Ep's edge, Fm on Em's. On the edge
// v = 0 (corner 0 → 1) our k = 0 points act, on u = 1 (1 → 2) the k = 1
// points, on v = 1 the k = 0 points, on u = 0 the k = 1 points (gregory.h).
const int gregory_slot[20] = {
    0,  1,  4,  5,  16, // corner 0 (0,0): P00, P10, P01, Fp on v=0 → P110, Fm on u=0 → P111
    3,  7,  2,  17, 6,  // corner 1 (1,0): P30, P31, P20, Fp on u=1 → P211, Fm on v=0 → P210
    15, 14, 11, 10, 19, // corner 2 (1,1): P33, P23, P32, Fp on v=1 → P220, Fm on u=1 → P221
    12, 8,  13, 18, 9,  // corner 3 (0,1): P03, P02, P13, Fp on u=0 → P121, Fm on v=1 → P120
};

// Inverse of the 4x4 Bernstein matrix sampled at t = 0, 1/3, 2/3, 1
// (M[a][i] = B_i(a/3)): Bézier points from 4 samples of a cubic.
void bernstein_inverse(double inv[4][4])
{
    double m[4][8];
    for (int a = 0; a < 4; a++) {
        double t = a / 3.0, s = 1 - t, b[4] = {s * s * s, 3 * t * s * s, 3 * t * t * s, t * t * t};
        for (int i = 0; i < 4; i++) {
            m[a][i] = b[i];
            m[a][4 + i] = a == i;
        }
    }
    for (int c = 0; c < 4; c++) { // Gauss-Jordan with partial pivoting
        int p = c;
        for (int r = c + 1; r < 4; r++)
            if (std::fabs(m[r][c]) > std::fabs(m[p][c])) p = r;
        for (int k = 0; k < 8; k++)
            std::swap(m[c][k], m[p][k]);
        double d = m[c][c];
        for (int k = 0; k < 8; k++)
            m[c][k] /= d;
        for (int r = 0; r < 4; r++)
            if (r != c) {
                double f = m[r][c];
                for (int k = 0; k < 8; k++)
                    m[r][k] -= f * m[c][k];
            }
    }
    for (int a = 0; a < 4; a++)
        for (int i = 0; i < 4; i++)
            inv[a][i] = m[a][4 + i];
}

int build(const vx_mesh *m, vx_gpatch_set **out, vx_err *err)
{
    QuadMesh q;
    if (quad_mesh(m, q, err)) return -1;
    Patches pt;
    if (make_patches(q, 0, pt, err)) return -1;
    int nq = q.nquads();
    // The patch of each quad (isolation 0: exactly one each).
    std::vector<int> arr((size_t)nq, -1), idx((size_t)nq, -1);
    const Far::PatchTable &t = *pt.table;
    for (int a = 0; a < t.GetNumPatchArrays(); a++)
        for (int p = 0; p < t.GetNumPatches(a); p++) {
            int f = t.GetPatchParam(a, p).GetFaceId();
            if (f < 0 || f >= nq || arr[(size_t)f] >= 0 || t.GetPatchParam(a, p).GetDepth() != 0)
                return vx_err_set(err, VX_EUNPROC, "osd_patches",
                                  "OpenSubdiv did not make one patch for quad %d", f);
            arr[(size_t)f] = a;
            idx[(size_t)f] = p;
        }
    for (int f = 0; f < nq; f++)
        if (arr[(size_t)f] < 0)
            return vx_err_set(err, VX_EUNPROC, "osd_patches",
                              "no patch for quad %d (a non-manifold or isolated vertex?)", f);
    vx_gpatch_set *s = vx_gpatch_set_new((size_t)nq);
    if (!s) return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for %d patches", nq);
    double inv[4][4];
    bernstein_inverse(inv);
    for (int f = 0; f < nq; f++) {
        double *cp = s->cp + (size_t)f * VX_GPATCH_POINTS * 3;
        Far::PatchDescriptor::Type type = t.GetPatchArrayDescriptor(arr[(size_t)f]).GetType();
        if (type == Far::PatchDescriptor::GREGORY_BASIS) {
            Far::ConstIndexArray cv = t.GetPatchVertices(arr[(size_t)f], idx[(size_t)f]);
            for (int k = 0; k < 20; k++)
                memcpy(cp + 3 * gregory_slot[k], pt.points[(size_t)cv[k]].p, 3 * sizeof(double));
        } else if (type == Far::PatchDescriptor::REGULAR) {
            // A B-spline patch (boundary ones with folded phantom points) is a
            // bicubic polynomial: 16 samples give its Bézier net exactly.
            double smp[4][4][3];
            for (int b = 0; b < 4; b++)
                for (int a = 0; a < 4; a++)
                    pt.eval(f, a / 3.0, b / 3.0, smp[b][a]);
            for (int j = 0; j < 4; j++)
                for (int i = 0; i < 4; i++)
                    for (int c = 0; c < 3; c++) {
                        double v = 0;
                        for (int b = 0; b < 4; b++)
                            for (int a = 0; a < 4; a++)
                                v += inv[i][a] * inv[j][b] * smp[b][a][c];
                        cp[3 * (4 * j + i) + c] = v;
                    }
            static const int inner[4][2] = {{5, 16}, {6, 17}, {9, 18}, {10, 19}};
            for (int k = 0; k < 4; k++)
                memcpy(cp + 3 * inner[k][1], cp + 3 * inner[k][0], 3 * sizeof(double));
        } else {
            vx_gpatch_set_free(s);
            return vx_err_set(err, VX_EUNPROC, "osd_patches",
                              "OpenSubdiv made a patch of type %d for quad %d", (int)type, f);
        }
        for (int k = 0; k < 4; k++)
            s->corner_key[4 * (size_t)f + (size_t)k] = (uint32_t)q.idx[4 * (size_t)f + (size_t)k];
        s->face[f] = q.parent[(size_t)f];
    }
    *out = s;
    return 0;
}

double distance(const vx_mesh *m, const vx_gpatch_set *s, int n, int isolation, vx_err *err)
{
    if (n < 2) n = 2;
    QuadMesh q;
    if (quad_mesh(m, q, err)) return -1;
    if ((size_t)q.nquads() != s->npatches) {
        vx_err_set(err, VX_EINVAL, "patch_mismatch", "%zu patches for %d quads: not this mesh's",
                   s->npatches, q.nquads());
        return -1;
    }
    Patches pt;
    if (make_patches(q, isolation, pt, err)) return -1;
    double diag = 0, worst = 0;
    for (int a = 0; a < 3; a++)
        diag += (m->bbox_max[a] - m->bbox_min[a]) * (m->bbox_max[a] - m->bbox_min[a]);
    diag = std::sqrt(diag);
    for (int f = 0; f < q.nquads(); f++)
        for (int b = 0; b < n; b++)
            for (int a = 0; a < n; a++) {
                double u = (double)a / (n - 1), v = (double)b / (n - 1), ref[3], ours[3];
                if (!pt.eval(f, u, v, ref)) {
                    vx_err_set(err, VX_EUNPROC, "osd_patches", "no limit patch on quad %d", f);
                    return -1;
                }
                vx_gpatch_eval(s->cp + (size_t)f * VX_GPATCH_POINTS * 3, u, v, ours, nullptr);
                double d = std::sqrt((ours[0] - ref[0]) * (ours[0] - ref[0]) +
                                     (ours[1] - ref[1]) * (ours[1] - ref[1]) +
                                     (ours[2] - ref[2]) * (ours[2] - ref[2]));
                if (d > worst) worst = d;
            }
    return diag > 0 ? worst / diag : worst;
}

} // namespace

extern "C" int vx_gregory_build_approx_cc(const vx_mesh *m, vx_gpatch_set **out, vx_err *err)
{
    *out = nullptr;
    try {
        return build(m, out, err);
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patches");
    } catch (...) {
        return vx_err_set(err, VX_EINTERNAL, "osd_failed", "OpenSubdiv failed");
    }
}

static double guarded_distance(const vx_mesh *m, const vx_gpatch_set *s, int n, int isolation,
                               vx_err *err)
{
    try {
        return distance(m, s, n, isolation, err);
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the limit surface");
    } catch (...) {
        vx_err_set(err, VX_EINTERNAL, "osd_failed", "OpenSubdiv failed");
    }
    return -1;
}

extern "C" double vx_gregory_cc_distance(const vx_mesh *m, const vx_gpatch_set *s,
                                         int samples_per_patch, vx_err *err)
{
    return guarded_distance(m, s, samples_per_patch, 6, err);
}

extern "C" double vx_gregory_cc_mismatch(const vx_mesh *m, const vx_gpatch_set *s,
                                         int samples_per_patch, vx_err *err)
{
    return guarded_distance(m, s, samples_per_patch, 0, err);
}
