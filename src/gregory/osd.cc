// The approximate-cc construction and its distance to the Catmull-Clark
// limit surface, through OpenSubdiv Far patch tables (osd.h). No exception
// crosses into C.
#include <algorithm>
#include <array>
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
#include "util/stop.h"
}

using namespace OpenSubdiv;
using vx_osd::Point;

namespace
{

// The quad mesh the patches live on (osd.h): its topology, and the
// refiner that makes it from the input when the input is not all quads.
struct QuadMesh {
    size_t nin = 0;                           // input vertices
    int nverts = 0;                           // quad mesh vertices
    std::unique_ptr<Far::TopologyRefiner> r1; // input refined once, or null
    std::vector<int> idx;                     // 4 per quad
    std::vector<uint32_t> parent;             // the input face of each quad
    int nquads() const { return (int)(idx.size() / 4); }

    // The quad mesh's vertex positions from the input's (3 * nin doubles).
    void positions(const double *in, std::vector<Point> &out) const
    {
        std::vector<Point> src(nin);
        for (size_t i = 0; i < nin; i++)
            memcpy(src[i].p, in + 3 * i, sizeof src[i].p);
        if (!r1) {
            out.swap(src);
            return;
        }
        out.resize((size_t)nverts);
        Far::PrimvarRefinerReal<double>(*r1).Interpolate(1, src, out);
    }
};

// True when two quads of m have the same four vertices (a double-sided
// sheet). OpenSubdiv 3.5's Gregory end caps of such a quad index points
// that do not exist; refined once, its quads no longer share all corners.
bool twin_quads(const vx_mesh *m)
{
    std::vector<std::array<uint32_t, 4>> k(m->nfaces);
    for (size_t f = 0; f < m->nfaces; f++) {
        std::copy(m->face_idx + 4 * f, m->face_idx + 4 * f + 4, k[f].begin());
        std::sort(k[f].begin(), k[f].end());
    }
    std::sort(k.begin(), k.end());
    return std::adjacent_find(k.begin(), k.end()) != k.end();
}

int quad_mesh(const vx_mesh *m, QuadMesh &q, vx_err *err)
{
    if (m->nverts > (size_t)INT_MAX / 8 || m->nfaces > (size_t)INT_MAX / 8)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "%zu vertices is too many for OpenSubdiv", m->nverts);
    q.nin = m->nverts;
    bool quads = true;
    for (size_t f = 0; f < m->nfaces && quads; f++)
        quads = vx_mesh_face_size(m, f) == 4;
    if (quads && !twin_quads(m)) {
        q.nverts = (int)m->nverts;
        q.idx.assign(m->face_idx, m->face_idx + 4 * m->nfaces);
        q.parent.resize(m->nfaces);
        for (size_t f = 0; f < m->nfaces; f++)
            q.parent[f] = (uint32_t)f;
        return 0;
    }
    q.r1.reset(vx_osd::refiner_new(m, err));
    if (!q.r1) return -1;
    q.r1->RefineUniform(Far::TopologyRefiner::UniformOptions(1));
    const Far::TopologyLevel &l1 = q.r1->GetLevel(1);
    q.nverts = l1.GetNumVertices();
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

    // Sets the points from the quad mesh's vertex positions.
    void positions(const std::vector<Point> &qpos)
    {
        int nref = refiner->GetNumVerticesTotal();
        std::copy(qpos.begin(), qpos.end(), points.begin());
        Far::PrimvarRefinerReal<double> pr(*refiner);
        Point *src = points.data();
        for (int l = 1; l <= refiner->GetMaxLevel(); l++) {
            Point *dst = src + refiner->GetLevel(l - 1).GetNumVertices();
            pr.Interpolate(l, src, dst);
            src = dst;
        }
        if (table->GetNumLocalPoints())
            table->GetLocalPointStencilTable<double>()->UpdateValues(points.data(),
                                                                     points.data() + nref);
    }

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

// The topology part: refiner, patch table, patch map (positions later).
int make_patches(const QuadMesh &q, int isolation, Patches &pt, vx_err *err)
{
    std::vector<int> sizes((size_t)q.nquads(), 4);
    pt.refiner.reset(vx_osd::refiner_new(q.nverts, q.nquads(), sizes.data(), q.idx.data(), err));
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
    pt.points.resize((size_t)pt.refiner->GetNumVerticesTotal() +
                     (size_t)pt.table->GetNumLocalPoints());
    // Every end-cap point must be an affine combination of refined
    // vertices; a table that is not (a topology OpenSubdiv mishandles) is
    // refused rather than read out of bounds.
    if (const Far::StencilTableReal<double> *st = pt.table->GetLocalPointStencilTable<double>()) {
        const int nref = pt.refiner->GetNumVerticesTotal();
        const std::vector<Far::Index> &ci = st->GetControlIndices();
        const std::vector<double> &cw = st->GetWeights();
        const std::vector<int> &sz = st->GetSizes();
        bool ok = ci.size() == cw.size();
        for (size_t i = 0, at = 0; ok && i < sz.size(); at += (size_t)sz[i++]) {
            double sum = 0;
            ok = sz[i] >= 0 && at + (size_t)sz[i] <= ci.size();
            for (size_t j = at; ok && j < at + (size_t)sz[i]; j++) {
                ok = ci[j] >= 0 && ci[j] < nref && std::isfinite(cw[j]);
                sum += cw[j];
            }
            ok = ok && std::fabs(sum - 1) < 1e-6;
        }
        if (!ok)
            return vx_err_set(err, VX_EUNPROC, "osd_patches",
                              "OpenSubdiv's end-cap points for this mesh are not combinations "
                              "of its vertices (an unusual topology)");
    }
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

} // namespace

// Everything about the patches that does not depend on the positions.
struct vx_gregory_cc_plan {
    QuadMesh q;
    Patches pt;
    std::vector<int> arr, idx; // where each quad's patch is in the table
    // Regular patches: the Bézier net as weights of the patch's 16 points,
    // 16 x 16 per patch, at bez[16 * 16 * bez_at[f]].
    std::vector<double> bez;
    std::vector<int> bez_at;
    std::vector<Point> qpos; // scratch
};

namespace
{

int plan_new(const vx_mesh *m, vx_gregory_cc_plan &p, vx_err *err)
{
    if (quad_mesh(m, p.q, err) || make_patches(p.q, 0, p.pt, err)) return -1;
    int nq = p.q.nquads();
    // The patch of each quad (isolation 0: exactly one each).
    p.arr.assign((size_t)nq, -1);
    p.idx.assign((size_t)nq, -1);
    const Far::PatchTable &t = *p.pt.table;
    for (int a = 0; a < t.GetNumPatchArrays(); a++) {
        Far::PatchDescriptor::Type type = t.GetPatchArrayDescriptor(a).GetType();
        if (type != Far::PatchDescriptor::GREGORY_BASIS && type != Far::PatchDescriptor::REGULAR)
            return vx_err_set(err, VX_EUNPROC, "osd_patches", "OpenSubdiv made patches of type %d",
                              (int)type);
        for (int i = 0; i < t.GetNumPatches(a); i++) {
            int f = t.GetPatchParam(a, i).GetFaceId();
            if (f < 0 || f >= nq || p.arr[(size_t)f] >= 0 || t.GetPatchParam(a, i).GetDepth() != 0)
                return vx_err_set(err, VX_EUNPROC, "osd_patches",
                                  "OpenSubdiv did not make one patch for quad %d", f);
            p.arr[(size_t)f] = a;
            p.idx[(size_t)f] = i;
        }
    }
    for (int f = 0; f < nq; f++)
        if (p.arr[(size_t)f] < 0)
            return vx_err_set(err, VX_EUNPROC, "osd_patches",
                              "no patch for quad %d (a non-manifold or isolated vertex?)", f);
    // A B-spline patch (boundary ones with folded phantom points) is a
    // bicubic polynomial: its values at 16 parameters give its Bézier net
    // exactly, so the net is a fixed linear map of the patch's points.
    double inv[4][4];
    bernstein_inverse(inv);
    p.bez_at.assign((size_t)nq, -1);
    int nreg = 0;
    for (int f = 0; f < nq; f++)
        if (t.GetPatchArrayDescriptor(p.arr[(size_t)f]).GetType() == Far::PatchDescriptor::REGULAR)
            p.bez_at[(size_t)f] = nreg++;
    p.bez.assign((size_t)nreg * 256, 0.0);
    for (int f = 0; f < nq; f++) {
        // ~4 us a quad: the job's time limit reaches in (util/stop.h)
        if ((f & 1023) == 0 && vx_stop_poll(err)) return -1;
        if (p.bez_at[(size_t)f] < 0) continue;
        double *w = &p.bez[256 * (size_t)p.bez_at[(size_t)f]];
        for (int b = 0; b < 4; b++)
            for (int a = 0; a < 4; a++) {
                double u = a / 3.0, v = b / 3.0, ws[20];
                const Far::PatchTable::PatchHandle *h = p.pt.map->FindPatch(f, u, v);
                if (!h || t.GetPatchVertices(*h).size() != 16)
                    return vx_err_set(err, VX_EUNPROC, "osd_patches",
                                      "OpenSubdiv's patch of quad %d is not a 16-point one", f);
                t.EvaluateBasis(*h, u, v, ws);
                for (int j = 0; j < 4; j++)
                    for (int i = 0; i < 4; i++)
                        for (int c = 0; c < 16; c++)
                            w[16 * (4 * j + i) + c] += inv[i][a] * inv[j][b] * ws[c];
            }
    }
    return 0;
}

void plan_eval(vx_gregory_cc_plan &p, const double *pos, vx_gpatch_set *s)
{
    p.q.positions(pos, p.qpos);
    p.pt.positions(p.qpos);
    const Far::PatchTable &t = *p.pt.table;
    for (int f = 0; f < p.q.nquads(); f++) {
        double *cp = s->cp + (size_t)f * VX_GPATCH_POINTS * 3;
        int arr = p.arr[(size_t)f];
        if (t.GetPatchArrayDescriptor(arr).GetType() == Far::PatchDescriptor::GREGORY_BASIS) {
            Far::ConstIndexArray cv = t.GetPatchVertices(arr, p.idx[(size_t)f]);
            for (int k = 0; k < 20; k++)
                memcpy(cp + 3 * gregory_slot[k], p.pt.points[(size_t)cv[k]].p, 3 * sizeof(double));
        } else {
            Far::ConstIndexArray cv = t.GetPatchVertices(arr, p.idx[(size_t)f]);
            const double *w = &p.bez[256 * (size_t)p.bez_at[(size_t)f]];
            for (int k = 0; k < 16; k++) {
                double *o = cp + 3 * k;
                o[0] = o[1] = o[2] = 0;
                for (int c = 0; c < 16; c++) {
                    if (cv[c] < 0) continue; // a phantom point: its weight was folded
                    const double *q = p.pt.points[(size_t)cv[c]].p;
                    for (int a = 0; a < 3; a++)
                        o[a] += w[16 * k + c] * q[a];
                }
            }
            static const int inner[4][2] = {{5, 16}, {6, 17}, {9, 18}, {10, 19}};
            for (int k = 0; k < 4; k++)
                memcpy(cp + 3 * inner[k][1], cp + 3 * inner[k][0], 3 * sizeof(double));
        }
        for (int k = 0; k < 4; k++)
            s->corner_key[4 * (size_t)f + (size_t)k] = (uint32_t)p.q.idx[4 * (size_t)f + (size_t)k];
        s->face[f] = p.q.parent[(size_t)f];
    }
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
    std::vector<Point> qpos;
    q.positions(m->pos, qpos);
    pt.positions(qpos);
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

extern "C" vx_gregory_cc_plan *vx_gregory_cc_plan_new(const vx_mesh *m, vx_err *err)
{
    vx_gregory_cc_plan *p = nullptr;
    try {
        p = new vx_gregory_cc_plan();
        if (plan_new(m, *p, err) == 0) return p;
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patches");
    } catch (...) {
        vx_err_set(err, VX_EINTERNAL, "osd_failed", "OpenSubdiv failed");
    }
    delete p;
    return nullptr;
}

extern "C" size_t vx_gregory_cc_plan_patches(const vx_gregory_cc_plan *p)
{
    return (size_t)p->q.nquads();
}

extern "C" int vx_gregory_cc_plan_eval(vx_gregory_cc_plan *p, const double *pos, vx_gpatch_set *s,
                                       vx_err *err)
{
    if (s->npatches != (size_t)p->q.nquads())
        return vx_err_set(err, VX_EINVAL, "patch_mismatch", "a set of %zu patches for %d quads",
                          s->npatches, p->q.nquads());
    try {
        plan_eval(*p, pos, s);
        return 0;
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patches");
    } catch (...) {
        return vx_err_set(err, VX_EINTERNAL, "osd_failed", "OpenSubdiv failed");
    }
}

extern "C" void vx_gregory_cc_plan_free(vx_gregory_cc_plan *p)
{
    delete p;
}

extern "C" int vx_gregory_build_approx_cc(const vx_mesh *m, vx_gpatch_set **out, vx_err *err)
{
    *out = nullptr;
    vx_gregory_cc_plan *p = vx_gregory_cc_plan_new(m, err);
    if (!p) return -1;
    vx_gpatch_set *s = vx_gpatch_set_new(vx_gregory_cc_plan_patches(p));
    int rc = s ? vx_gregory_cc_plan_eval(p, m->pos, s, err)
               : vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the patches");
    vx_gregory_cc_plan_free(p);
    if (rc) {
        vx_gpatch_set_free(s);
        return -1;
    }
    *out = s;
    return 0;
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
