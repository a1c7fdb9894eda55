// Gregory tessellation benchmark (issue #5, seed 001): voxeld's one-pass
// GPU tessellation against OpenSubdiv 3.5 on the CPU, in the same run.
//
//   gregory_bench rate MESH.obj N...    vertices/s (positions + normals) of the
//                                       GPU pass vs OpenSubdiv's limit evaluation
//                                       (adaptive PatchTable + PatchMap +
//                                       EvaluateBasis, one thread) of as many points
//   gregory_bench seed                  seed 001 table 3.2: a 3x3 quad mesh at
//                                       6x6 ... 96x96, 10 generations, vs uniform
//                                       Catmull-Clark (RefineUniform + PrimvarRefiner)
//   gregory_bench frames MESH.obj N     re-tessellation time per deformation frame
//   [--runs R] best of R runs (default 3)
#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/osd/bufferDescriptor.h>
#include <opensubdiv/osd/cpuPatchTable.h>
#include <opensubdiv/osd/ompEvaluator.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

extern "C" {
#include "gl/gl.h"
#include "gregory/gregory.h"
#include "gregory/tess.h"
#include "mesh/mesh.h"
}

using namespace OpenSubdiv;
using clk = std::chrono::steady_clock;
static double ms_since(clk::time_point t)
{
    return std::chrono::duration<double, std::milli>(clk::now() - t).count();
}

static int g_runs = 3;

static vx_mesh *load(const char *path)
{
    vx_err err;
    vx_mesh *m = vx_mesh_read_path(path, nullptr, &err);
    if (!m) {
        fprintf(stderr, "%s: %s\n", path, err.message);
        exit(1);
    }
    return m;
}

static void die(const vx_err &e)
{
    fprintf(stderr, "error: %s: %s\n", e.code, e.message);
    exit(1);
}

// ---- OpenSubdiv side ----

struct V3 {
    float p[3];
    void Clear(void * = nullptr) { p[0] = p[1] = p[2] = 0; }
    void AddWithWeight(const V3 &s, float w)
    {
        p[0] += w * s.p[0];
        p[1] += w * s.p[1];
        p[2] += w * s.p[2];
    }
};

static Far::TopologyRefiner *osd_refiner(const vx_mesh *m, std::vector<int> &nv,
                                         std::vector<int> &idx)
{
    nv.resize(m->nfaces);
    idx.clear();
    for (size_t f = 0; f < m->nfaces; f++) {
        nv[f] = (int)vx_mesh_face_size(m, f);
        const uint32_t *v = vx_mesh_face(m, f);
        idx.insert(idx.end(), v, v + nv[f]);
    }
    Far::TopologyDescriptor d;
    d.numVertices = (int)m->nverts;
    d.numFaces = (int)m->nfaces;
    d.numVertsPerFace = nv.data();
    d.vertIndicesPerFace = idx.data();
    Sdc::Options o;
    o.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    return Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Create(
        d, Far::TopologyRefinerFactory<Far::TopologyDescriptor>::Options(Sdc::SCHEME_CATMARK, o));
}

// What both limit evaluations start from: the adaptive refinement (level
// 3, Gregory basis end caps), its patch table, the refined and local
// points, and the ptex face count.
struct LimitSetup {
    Far::TopologyRefiner *r = nullptr;
    Far::PatchTable *pt = nullptr;
    std::vector<V3> verts;
    int nptex = 0;
    explicit LimitSetup(const vx_mesh *m)
    {
        std::vector<int> nv, idx;
        r = osd_refiner(m, nv, idx);
        const int level = 3;
        r->RefineAdaptive(Far::TopologyRefiner::AdaptiveOptions(level));
        Far::PatchTableFactory::Options po(level);
        po.endCapType = Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS;
        pt = Far::PatchTableFactory::Create(*r, po);
        int nref = r->GetNumVerticesTotal(), nloc = pt->GetNumLocalPoints();
        verts.resize((size_t)(nref + nloc));
        for (size_t i = 0; i < m->nverts; i++)
            for (int c = 0; c < 3; c++)
                verts[i].p[c] = (float)m->pos[3 * i + c];
        Far::PrimvarRefiner pr(*r);
        V3 *src = verts.data();
        for (int l = 1; l <= r->GetMaxLevel(); l++) {
            V3 *dst = src + r->GetLevel(l - 1).GetNumVertices();
            pr.Interpolate(l, src, dst);
            src = dst;
        }
        if (nloc) pt->ComputeLocalPointValues(verts.data(), verts.data() + nref);
        nptex = Far::PtexIndices(*r).GetNumFaces();
    }
    ~LimitSetup()
    {
        delete pt;
        delete r;
    }
};

// Limit positions (and normals when `normals`) at (n+1)^2 points of every
// ptex face; returns points evaluated and the time of the evaluation loop
// (the patch table and refined points are built before, outside it).
static size_t osd_limit(const vx_mesh *m, int n, bool normals, double *ms, double *setup_ms)
{
    auto t0 = clk::now();
    LimitSetup L(m);
    Far::PatchTable *pt = L.pt;
    const std::vector<V3> &verts = L.verts;
    Far::PatchMap pm(*pt);
    int nptex = L.nptex;
    *setup_ms = ms_since(t0);
    double best = 1e300, sink = 0;
    size_t count = 0;
    for (int run = 0; run < g_runs; run++) {
        auto t1 = clk::now();
        count = 0;
        float w[20], wu[20], wv[20];
        for (int f = 0; f < nptex; f++)
            for (int j = 0; j <= n; j++)
                for (int i = 0; i <= n; i++) {
                    float s = (float)i / n, t = (float)j / n;
                    const Far::PatchTable::PatchHandle *h = pm.FindPatch(f, s, t);
                    if (!h) continue;
                    Far::ConstIndexArray cv = pt->GetPatchVertices(*h);
                    float p[3] = {0, 0, 0}, du[3] = {0, 0, 0}, dv[3] = {0, 0, 0};
                    if (normals) {
                        pt->EvaluateBasis(*h, s, t, w, wu, wv);
                        for (int k = 0; k < cv.size(); k++) {
                            const float *q = verts[cv[k]].p;
                            for (int c = 0; c < 3; c++) {
                                p[c] += w[k] * q[c];
                                du[c] += wu[k] * q[c];
                                dv[c] += wv[k] * q[c];
                            }
                        }
                        float nx = du[1] * dv[2] - du[2] * dv[1],
                              ny = du[2] * dv[0] - du[0] * dv[2],
                              nz = du[0] * dv[1] - du[1] * dv[0];
                        float l = std::sqrt(nx * nx + ny * ny + nz * nz);
                        sink += l > 0 ? nx / l : 0;
                    } else {
                        pt->EvaluateBasis(*h, s, t, w);
                        for (int k = 0; k < cv.size(); k++)
                            for (int c = 0; c < 3; c++)
                                p[c] += w[k] * verts[cv[k]].p[c];
                    }
                    sink += p[0];
                    count++;
                }
        best = std::min(best, ms_since(t1));
    }
    if (sink == 12345.678) printf(" ");
    *ms = best;
    return count;
}

// The same limit evaluation through OpenSubdiv's own multi-threaded
// evaluator (Osd::OmpEvaluator, the one Debian's libosdCPU 3.5 has: it is
// built without TBB) on `threads` threads: positions and both derivatives
// of every point in one EvalPatches call over prepared patch coordinates
// (FindPatch is set-up, as our layout is), then the normals from the
// derivatives on the same threads. Returns points; *ms the best run.
static size_t osd_omp(const vx_mesh *m, int n, int threads, double *ms)
{
    LimitSetup L(m);
    Far::PatchTable *pt = L.pt;
    const std::vector<V3> &verts = L.verts;
    Far::PatchMap pm(*pt);
    int nptex = L.nptex;
    std::vector<Osd::PatchCoord> pc;
    pc.reserve((size_t)nptex * (n + 1) * (n + 1));
    for (int f = 0; f < nptex; f++)
        for (int j = 0; j <= n; j++)
            for (int i = 0; i <= n; i++) {
                float s = (float)i / n, t = (float)j / n;
                const Far::PatchTable::PatchHandle *h = pm.FindPatch(f, s, t);
                if (h) pc.push_back(Osd::PatchCoord(*h, s, t));
            }
    Osd::CpuPatchTable *cpt = Osd::CpuPatchTable::Create(pt);
    size_t np = pc.size();
    std::vector<float> P(3 * np), Du(3 * np), Dv(3 * np), N(3 * np);
    Osd::BufferDescriptor sd(0, 3, 3), od(0, 3, 3);
    Osd::OmpEvaluator::SetNumThreads(threads);
    double best = 1e300;
    for (int run = 0; run < g_runs; run++) {
        auto t1 = clk::now();
        Osd::OmpEvaluator::EvalPatches(&verts[0].p[0], sd, P.data(), od, Du.data(), od, Dv.data(),
                                       od, (int)np, pc.data(), cpt->GetPatchArrayBuffer(),
                                       cpt->GetPatchIndexBuffer(), cpt->GetPatchParamBuffer());
#pragma omp parallel for num_threads(threads) schedule(static)
        for (long k = 0; k < (long)np; k++) {
            const float *a = &Du[3 * k], *b = &Dv[3 * k];
            float x = a[1] * b[2] - a[2] * b[1], y = a[2] * b[0] - a[0] * b[2],
                  z = a[0] * b[1] - a[1] * b[0], l = std::sqrt(x * x + y * y + z * z);
            float inv = l > 0 ? 1 / l : 0;
            N[3 * k] = x * inv, N[3 * k + 1] = y * inv, N[3 * k + 2] = z * inv;
        }
        best = std::min(best, ms_since(t1));
    }
    if (N[0] == 12345.678f) printf(" ");
    *ms = best;
    delete cpt;
    return np;
}

// Uniform Catmull-Clark to `level`: topology + positions, and positions
// alone (the topology reused); returns the vertices of the last level.
static size_t osd_uniform(const vx_mesh *m, int level, int gens, double *full_ms, double *prim_ms)
{
    std::vector<int> nv, idx;
    size_t nverts = 0;
    auto t0 = clk::now();
    Far::TopologyRefiner *keep = nullptr;
    for (int g = 0; g < gens; g++) {
        Far::TopologyRefiner *r = osd_refiner(m, nv, idx);
        r->RefineUniform(Far::TopologyRefiner::UniformOptions(level));
        std::vector<V3> verts(r->GetNumVerticesTotal());
        for (size_t i = 0; i < m->nverts; i++)
            for (int c = 0; c < 3; c++)
                verts[i].p[c] = (float)m->pos[3 * i + c];
        Far::PrimvarRefiner pr(*r);
        V3 *src = verts.data();
        for (int l = 1; l <= level; l++) {
            V3 *dst = src + r->GetLevel(l - 1).GetNumVertices();
            pr.Interpolate(l, src, dst);
            src = dst;
        }
        nverts = (size_t)r->GetLevel(level).GetNumVertices();
        if (g == 0)
            keep = r;
        else
            delete r;
    }
    *full_ms = ms_since(t0);
    std::vector<V3> verts(keep->GetNumVerticesTotal());
    auto t1 = clk::now();
    for (int g = 0; g < gens; g++) {
        for (size_t i = 0; i < m->nverts; i++)
            for (int c = 0; c < 3; c++)
                verts[i].p[c] = (float)m->pos[3 * i + c];
        Far::PrimvarRefiner pr(*keep);
        V3 *src = verts.data();
        for (int l = 1; l <= level; l++) {
            V3 *dst = src + keep->GetLevel(l - 1).GetNumVertices();
            pr.Interpolate(l, src, dst);
            src = dst;
        }
    }
    *prim_ms = ms_since(t1);
    delete keep;
    return nverts;
}

// ---- voxeld side ----

struct Greg {
    vx_gregory_topo *topo = nullptr;
    vx_gpatch_set *set = nullptr;
    vx_gtess_layout *layout = nullptr;
    std::vector<float> grid;
    double origin[3];
    ~Greg()
    {
        vx_gregory_layout_free(layout);
        vx_gpatch_set_free(set);
        vx_gregory_topo_free(topo);
    }
};

static void greg_setup(Greg &g, const vx_mesh *m, int n, int weld)
{
    vx_err err;
    g.topo = vx_gregory_topo_new(m, &err);
    if (!g.topo) die(err);
    g.set = vx_gpatch_set_new(vx_gregory_topo_npatches(g.topo));
    vx_gregory_build(g.topo, m->pos, g.set);
    uint32_t *nd = vx_gregory_divisions(g.set, n, 0, &err);
    g.layout = vx_gregory_layout_new(g.set, nd, weld, &err);
    free(nd);
    if (!g.layout) die(err);
    g.grid.resize(6 * g.layout->voff[g.set->npatches]);
    for (int c = 0; c < 3; c++)
        g.origin[c] = 0.5 * (m->bbox_min[c] + m->bbox_max[c]);
}

// GPU pass: best of runs; *wall_ms adds the read-back (the whole call).
// The tessellation pass on engine e, best of runs: one-shot (a fresh
// tessellator every call, as a job's first frame; *wall_ms = the whole call
// with buffer set-up and read-back) and steady (*steady_ms: buffers kept, as
// for deformation frames). The CPU engine has no buffers: its pass is the
// whole call.
static double greg_tess(vx_gl *gl, Greg &g, vx_gtess_engine e, double *wall_ms, double *steady_ms)
{
    double best = 1e300, best_wall = 1e300, best_steady = 1e300;
    vx_err err;
    for (int run = 0; run < g_runs; run++) {
        double ms;
        auto t0 = clk::now();
        vx_gtess *t = vx_gtess_new_on(gl, g.layout, e, &err);
        if (!t || vx_gtess_run(t, g.set, g.origin, g.grid.data(), &ms, &err)) die(err);
        vx_gtess_free(t);
        best_wall = std::min(best_wall, ms_since(t0));
        best = std::min(best, ms);
    }
    vx_gtess *t = vx_gtess_new_on(gl, g.layout, e, &err);
    if (!t) die(err);
    for (int run = -1; run < g_runs; run++) { /* run -1: first touch of the buffers */
        double ms;
        if (vx_gtess_run(t, g.set, g.origin, g.grid.data(), &ms, &err)) die(err);
        if (run >= 0) best_steady = std::min(best_steady, ms);
    }
    vx_gtess_free(t);
    *wall_ms = best_wall;
    *steady_ms = best_steady;
    return best;
}

static int cmd_rate(vx_gl *gl, int argc, char **argv)
{
    vx_mesh *m = load(argv[0]);
    printf("| mesh | N | points | voxeld GPU pass M vert/s (ms), fresh buffers | buffers kept | "
           "fresh incl. set-up + read-back M/s | voxeld CPU engine M vert/s (ms), whole call | "
           "OpenSubdiv OmpEvaluator 2 threads pos+normal M/s | "
           "OpenSubdiv Far 1 thread pos+normal M/s | pos only M/s | "
           "engine auto runs | its ratio vs OmpEvaluator 2 threads | vs Far 1 thread |\n");
    printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (int a = 1; a < argc; a++) {
        int n = atoi(argv[a]);
        Greg g;
        greg_setup(g, m, n, 0);
        double wall, steady, ms = greg_tess(gl, g, VX_GTESS_GPU, &wall, &steady);
        double cwall, csteady;
        greg_tess(gl, g, VX_GTESS_CPU, &cwall, &csteady);
        double pts = (double)g.layout->voff[g.set->npatches];
        double oms_n, oms_p, oms_2, setup;
        size_t on = osd_limit(m, n, true, &oms_n, &setup);
        size_t op = osd_limit(m, n, false, &oms_p, &setup);
        size_t o2 = osd_omp(m, n, 2, &oms_2);
        double ours = pts / ms / 1e3, osdn = (double)on / oms_n / 1e3,
               osdp = (double)op / oms_p / 1e3, osd2 = (double)o2 / oms_2 / 1e3;
        double cpu = pts / cwall / 1e3;
        vx_err err;
        vx_gtess *t = vx_gtess_new(gl, g.layout, &err);
        if (!t) die(err);
        bool on_cpu = !strcmp(vx_gtess_engine_name(t), "cpu");
        vx_gtess_free(t);
        /* auto's engine: the CPU one as a whole call, the GPU's fresh pass */
        double runs = on_cpu ? cpu : ours;
        const char *name = strrchr(argv[0], '/') ? strrchr(argv[0], '/') + 1 : argv[0];
        double st = pts / steady / 1e3;
        printf("| %s | %d | %.0f | %.1f (%.2f) | %.1f (%.2f) | %.1f | %.1f (%.2f) | %.1f | %.1f | "
               "%.1f | %s | %.2fx | %.2fx |\n",
               name, n, pts, ours, ms, st, steady, pts / wall / 1e3, cpu, cwall, osd2, osdn, osdp,
               on_cpu ? "cpu" : "gpu", runs / osd2, runs / osdn);
        fflush(stdout);
    }
    vx_mesh_free(m);
    return 0;
}

// A 3x3 quad mesh over [0,3]^2 with a bump (the seed's test surface).
static vx_mesh *grid3(void)
{
    vx_mesh *m = vx_mesh_new();
    m->nverts = 16;
    m->pos = (double *)malloc(48 * sizeof(double));
    for (int j = 0; j < 4; j++)
        for (int i = 0; i < 4; i++) {
            double *p = m->pos + 3 * (4 * j + i);
            p[0] = i;
            p[1] = j;
            p[2] = (i == 1 || i == 2) && (j == 1 || j == 2) ? 1.0 : 0.0;
        }
    m->nfaces = 9;
    m->face_start = (uint32_t *)malloc(10 * sizeof(uint32_t));
    m->face_idx = (uint32_t *)malloc(36 * sizeof(uint32_t));
    for (int f = 0; f < 9; f++) {
        int i = f % 3, j = f / 3;
        uint32_t q[4] = {(uint32_t)(4 * j + i), (uint32_t)(4 * j + i + 1),
                         (uint32_t)(4 * j + i + 5), (uint32_t)(4 * j + i + 4)};
        memcpy(m->face_idx + 4 * f, q, sizeof q);
        m->face_start[f] = 4 * f;
    }
    m->face_start[9] = 36;
    vx_err err;
    if (vx_mesh_analyze(m, &err)) die(err);
    return m;
}

static int cmd_seed(vx_gl *gl)
{
    vx_mesh *m = grid3();
    const int gens = 10;
    printf("| division | vertices | Catmull-Clark (OpenSubdiv, topology + positions) | "
           "OpenSubdiv positions only | Gregory voxeld (control points + tessellation + weld) | "
           "Gregory CPU eval (vx_gpatch_eval) | seed CC | seed Gregory |\n");
    printf("|---|---|---|---|---|---|---|---|\n");
    static const char *seed_cc[] = {"8.7", "43.9", "237.6", "1489.6", "13208.6"};
    static const char *seed_gr[] = {"3.2", "18.1", "106.8", "744", "6930.1"};
    for (int level = 1; level <= 5; level++) {
        int div = 3 << level, n = div / 3;
        double full = 1e300, prim = 1e300, ours = 1e300, cpu = 1e300;
        size_t cc_verts = 0;
        for (int run = 0; run < g_runs; run++) {
            double f, p;
            cc_verts = osd_uniform(m, level, gens, &f, &p);
            full = std::min(full, f);
            prim = std::min(prim, p);
        }
        Greg g;
        greg_setup(g, m, n, 1);
        std::vector<double> pos(3 * g.layout->nverts);
        std::vector<float> nrm(3 * g.layout->nverts);
        vx_err err0;
        vx_gtess *tess = vx_gtess_new(gl, g.layout, &err0);
        if (!tess) die(err0);
        for (int run = 0; run < g_runs; run++) {
            auto t0 = clk::now();
            for (int k = -1; k < gens; k++) { /* k = -1: warm-up (shader build, caches) */
                if (k == 0) t0 = clk::now();
                vx_err err;
                double ms;
                vx_gregory_build(g.topo, m->pos, g.set);
                if (vx_gtess_run(tess, g.set, g.origin, g.grid.data(), &ms, &err)) die(err);
                vx_gregory_gather(g.layout, g.grid.data(), g.origin, pos.data(), nrm.data(),
                                  nullptr);
            }
            ours = std::min(ours, ms_since(t0));
        }
        vx_gtess_free(tess);
        for (int run = 0; run < g_runs; run++) {
            auto t1 = clk::now();
            double sink = 0;
            for (int k = 0; k < gens; k++) {
                vx_gregory_build(g.topo, m->pos, g.set);
                for (size_t p = 0; p < g.set->npatches; p++)
                    for (int j = 0; j <= n; j++)
                        for (int i = 0; i <= n; i++) {
                            double x[3], nn[3];
                            vx_gpatch_eval(g.set->cp + p * 60, (double)i / n, (double)j / n, x, nn);
                            sink += x[0] + nn[0];
                        }
            }
            cpu = std::min(cpu, ms_since(t1));
            if (sink == 12345.678) printf(" ");
        }
        printf("| %dx%d | %zu (CC %zu) | %.2f ms | %.2f ms | %.2f ms | %.2f ms | %s ms | %s ms |\n",
               div, div, g.layout->nverts, cc_verts, full, prim, ours, cpu, seed_cc[level - 1],
               seed_gr[level - 1]);
        fflush(stdout);
    }
    vx_mesh_free(m);
    return 0;
}

static int cmd_frames(vx_gl *gl, const char *path, int n)
{
    vx_mesh *m = load(path);
    Greg g;
    greg_setup(g, m, n, 1);
    std::vector<double> moved(3 * m->nverts), pos(3 * g.layout->nverts);
    std::vector<float> nrm(3 * g.layout->nverts);
    const int frames = 40;
    vx_err err0;
    vx_gtess *tess = vx_gtess_new(gl, g.layout, &err0);
    if (!tess) die(err0);
    double build = 0, tess_ms = 0, gather = 0, gpu = 0, best_frame = 1e300;
    for (int k = 0; k < frames; k++) {
        for (size_t v = 0; v < m->nverts; v++) {
            const double *p = m->pos + 3 * v;
            moved[3 * v] = p[0] + 0.05 * std::sin(0.3 * k + 4 * p[1]);
            moved[3 * v + 1] = p[1];
            moved[3 * v + 2] = p[2] + 0.05 * std::cos(0.2 * k + 3 * p[0]);
        }
        vx_err err;
        double ms;
        auto t0 = clk::now();
        vx_gregory_build(g.topo, moved.data(), g.set);
        auto t1 = clk::now();
        if (vx_gtess_run(tess, g.set, g.origin, g.grid.data(), &ms, &err)) die(err);
        auto t2 = clk::now();
        vx_gregory_gather(g.layout, g.grid.data(), g.origin, pos.data(), nrm.data(), nullptr);
        if (k > 0) best_frame = std::min(best_frame, ms_since(t0));
        if (k > 0) { /* frame 0 warms the shader cache */
            build += std::chrono::duration<double, std::milli>(t1 - t0).count();
            tess_ms += std::chrono::duration<double, std::milli>(t2 - t1).count();
            gather += ms_since(t2);
            gpu += ms;
        }
    }
    int f = frames - 1;
    printf("| mesh | N | patches | vertices | control points ms | pass ms | tessellate call ms | "
           "weld gather ms | frame ms (mean) | best frame ms "
           "|\n|---|---|---|---|---|---|---|---|---|---|\n");
    const char *name = strrchr(path, '/') ? strrchr(path, '/') + 1 : path;
    printf("| %s | %d | %zu | %zu | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f |\n", name, n,
           g.set->npatches, g.layout->nverts, build / f, gpu / f, tess_ms / f, gather / f,
           (build + tess_ms + gather) / f, best_frame);
    vx_gtess_free(tess);
    vx_mesh_free(m);
    return 0;
}

int main(int argc, char **argv)
{
    std::vector<char *> args;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            g_runs = atoi(argv[++i]);
        else
            args.push_back(argv[i]);
    }
    if (args.empty()) {
        fprintf(stderr, "usage: gregory_bench rate MESH N... | seed | frames MESH N [--runs R]\n");
        return 2;
    }
    vx_err err;
    vx_gl_desc d = {};
    vx_gl *gl = vx_gl_new(&d, &err);
    if (!gl) die(err);
    const vx_gl_info *info = vx_gl_get_info(gl);
    printf("GL: %s (%s)\n\n", info->renderer, info->device_kind);
    int rc = 2;
    std::string cmd = args[0];
    if (cmd == "rate" && args.size() >= 3)
        rc = cmd_rate(gl, (int)args.size() - 1, args.data() + 1);
    else if (cmd == "seed")
        rc = cmd_seed(gl);
    else if (cmd == "frames" && args.size() == 3)
        rc = cmd_frames(gl, args[1], atoi(args[2]));
    else
        fprintf(stderr, "bad arguments\n");
    vx_gl_free(gl);
    return rc;
}
