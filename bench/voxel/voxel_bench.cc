// Voxelization benchmark: voxeld's GPU voxelizer against OpenVDB's
// meshToVolume then its interior mask on the same mesh and grid, in one
// run, two ways: the interior band filled (meshToVolume(..., 1, FLT_MAX))
// and as its docs intend, a narrow band (1, 1) whose interior tiles
// sdfInteriorMask turns into the mask (the peer the ratios use); plus the
// seed tables (000 Table 1, 003 Table 1).
//
//   voxel_bench compare MESH.obj[:SUBDIV] RES... [--method peel|slice|scan|cpu|auto] [--runs N]
//                                  [--no-filled]  (best of N for voxeld and the narrow band,
//                                   worst in brackets; the filled band once, unless skipped)
//   voxel_bench seed000 MESH.obj                     (peel/fill ms at 128, 256 for 1, 4, 16, 64x
//   faces) voxel_bench seed003 MESH.obj... [--res 512] [--shifts N]
//                                  (mean surface-voxel distance, supersample off/on; with
//                                   --shifts, also on N grids shifted by sub-voxel offsets)
//
// MESH:SUBDIV splits every triangle into 4, SUBDIV times (to reach ~1M faces).
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/MeshToVolume.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <string>
#include <thread>
#include <vector>

extern "C" {
#include "gl/gl.h"
#include "mesh/mesh.h"
#include "voxel/voxel.h"
}

using clk = std::chrono::steady_clock;
static double ms_since(clk::time_point t)
{
    return std::chrono::duration<double, std::milli>(clk::now() - t).count();
}

struct Mesh {
    std::vector<double> pos;   // 3 per vertex
    std::vector<uint32_t> tri; // 3 per triangle
    std::string name;
};

static Mesh load(const std::string &spec)
{
    std::string path = spec;
    int subdiv = 0;
    size_t colon = spec.rfind(':');
    if (colon != std::string::npos && colon + 1 < spec.size() &&
        isdigit((unsigned char)spec[colon + 1])) {
        path = spec.substr(0, colon);
        subdiv = atoi(spec.c_str() + colon + 1);
    }
    vx_err err;
    vx_mesh *m = vx_mesh_read_path(path.c_str(), nullptr, &err);
    if (!m) {
        fprintf(stderr, "%s: %s\n", path.c_str(), err.message);
        exit(1);
    }
    Mesh out;
    out.pos.assign(m->pos, m->pos + 3 * m->nverts);
    out.tri.assign(m->tri, m->tri + 3 * m->ntris);
    vx_mesh_free(m);
    for (int s = 0; s < subdiv; s++) { // 1 -> 4 midpoint split, shared midpoints
        std::map<uint64_t, uint32_t> mid;
        std::vector<uint32_t> nt;
        nt.reserve(out.tri.size() * 4);
        auto midpoint = [&](uint32_t a, uint32_t b) {
            uint64_t key = a < b ? (uint64_t)a << 32 | b : (uint64_t)b << 32 | a;
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            uint32_t id = (uint32_t)(out.pos.size() / 3);
            for (int k = 0; k < 3; k++)
                out.pos.push_back(0.5 * (out.pos[3 * a + k] + out.pos[3 * b + k]));
            mid[key] = id;
            return id;
        };
        for (size_t t = 0; t < out.tri.size(); t += 3) {
            uint32_t a = out.tri[t], b = out.tri[t + 1], c = out.tri[t + 2];
            uint32_t ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
            uint32_t add[12] = {a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca};
            nt.insert(nt.end(), add, add + 12);
        }
        out.tri.swap(nt);
    }
    const char *base = strrchr(path.c_str(), '/');
    out.name = (base ? base + 1 : path.c_str()) +
               (subdiv ? std::string("x") + std::to_string(1 << (2 * subdiv)) : "");
    return out;
}

// A vx_mesh view of a Mesh (all triangles).
static vx_mesh *as_vx(Mesh &m)
{
    vx_mesh *v = vx_mesh_new();
    v->nverts = m.pos.size() / 3;
    v->pos = (double *)malloc(m.pos.size() * sizeof(double));
    memcpy(v->pos, m.pos.data(), m.pos.size() * sizeof(double));
    v->nfaces = m.tri.size() / 3;
    v->face_idx = (uint32_t *)malloc(m.tri.size() * sizeof(uint32_t));
    memcpy(v->face_idx, m.tri.data(), m.tri.size() * sizeof(uint32_t));
    vx_err err;
    vx_mesh_analyze(v, &err);
    return v;
}

// OpenVDB's mesh adapter over our triangles, in index space of the grid
// (index (i,j,k) = the centre of voxel (i,j,k)).
struct Adapter {
    const Mesh *m;
    vx_grid g;
    size_t polygonCount() const { return m->tri.size() / 3; }
    size_t pointCount() const { return m->pos.size() / 3; }
    size_t vertexCount(size_t) const { return 3; }
    void getIndexSpacePoint(size_t n, size_t v, openvdb::Vec3d &p) const
    {
        const double *q = &m->pos[3 * m->tri[3 * n + v]];
        for (int k = 0; k < 3; k++)
            p[k] = (q[k] - g.origin[k]) / g.h - 0.5;
    }
};

static openvdb::math::Transform::Ptr xform(const vx_grid &g)
{
    auto t = openvdb::math::Transform::createLinearTransform(g.h);
    t->postTranslate(
        openvdb::Vec3d(g.origin[0] + 0.5 * g.h, g.origin[1] + 0.5 * g.h, g.origin[2] + 0.5 * g.h));
    return t;
}

struct VdbResult {
    double ms;
    openvdb::BoolGrid::Ptr mask;
};

// narrow: interior band width 1 (tiles carry the interior), else filled.
static VdbResult vdb_interior(const Mesh &m, const vx_grid &g, bool narrow)
{
    Adapter a{&m, g};
    auto t0 = clk::now();
    auto sdf = openvdb::tools::meshToVolume<openvdb::FloatGrid>(
        a, *xform(g), 1.0f, narrow ? 1.0f : std::numeric_limits<float>::max());
    auto mask = openvdb::tools::sdfInteriorMask(*sdf, 0.0f);
    return {ms_since(t0), mask};
}

// |ours|, |vdb| and |both| inside the grid box.
static double iou(const vx_bitgrid &ours, const openvdb::BoolGrid &mask, uint64_t *vdb_count)
{
    const int *d = ours.grid.dims;
    uint64_t both = 0, nv = 0;
    openvdb::CoordBBox box(openvdb::Coord(0, 0, 0), openvdb::Coord(d[0] - 1, d[1] - 1, d[2] - 1));
    for (auto it = mask.cbeginValueOn(); it; ++it) {
        openvdb::CoordBBox b;
        it.getBoundingBox(b);
        b.intersect(box);
        if (b.empty()) continue;
        for (int k = b.min().z(); k <= b.max().z(); k++)
            for (int j = b.min().y(); j <= b.max().y(); j++)
                for (int i = b.min().x(); i <= b.max().x(); i++) {
                    nv++;
                    both += vx_bitgrid_get(&ours, i, j, k);
                }
    }
    uint64_t no = vx_bitgrid_count(&ours);
    if (vdb_count) *vdb_count = nv;
    return no + nv - both ? (double)both / (double)(no + nv - both) : 1.0;
}

static vx_method parse_method(const char *s)
{
    return !strcmp(s, "peel")    ? VX_METHOD_PEEL
           : !strcmp(s, "slice") ? VX_METHOD_SLICE
           : !strcmp(s, "scan")  ? VX_METHOD_SCAN
           : !strcmp(s, "cpu")   ? VX_METHOD_CPU
                                 : VX_METHOD_AUTO;
}

static bool ours(vx_gl *gl, vx_mesh *vm, const vx_grid &g, vx_method method, int supersample,
                 vx_bitgrid *out, vx_voxelize_stats *st, double *ms,
                 vx_samples samples = VX_SAMPLES_CUBE)
{
    vx_voxelize_desc d{};
    d.grid = g;
    d.method = method;
    d.inside = VX_INSIDE_NONZERO;
    d.supersample = supersample;
    d.samples = samples;
    vx_err err;
    auto t0 = clk::now();
    int rc = vx_voxelize(gl, vm, &d, out, st, &err);
    *ms = ms_since(t0);
    if (rc) fprintf(stderr, "voxelize: %s: %s\n", err.code, err.message);
    return rc == 0;
}

// Seed 003 Table 1 on grid g: mean distance from the centres of surface
// voxels (inside, with an outside 6-neighbour or on the grid border) to the
// mesh, in voxel edges: mt[0] without supersampling, mt[1..3] supersampled
// (seed 003's 2x2x2 pattern, slice) with threshold 1, 2, 4, mt[4..5] the
// faces pattern (centre + 6 face centres, scan) with threshold 1, 2.
// Returns nonzero when voxelizing fails.
enum { SEED003_COLS = 6 };
static int seed003_means(vx_gl *gl, Mesh &m, vx_mesh *vm, const vx_grid &g, double mt[SEED003_COLS],
                         uint64_t *nsurf)
{
    // Unsigned distance to the mesh (exact near the surface), in world units.
    Adapter a{&m, g};
    auto udf = openvdb::tools::meshToVolume<openvdb::FloatGrid>(
        a, *xform(g), 3.0f, 3.0f, openvdb::tools::UNSIGNED_DISTANCE_FIELD);
    auto acc = udf->getConstAccessor();
    const int *d = g.dims;
    auto mean = [&](auto inside, uint64_t *count) {
        double sum = 0;
        uint64_t n = 0;
        for (int k = 0; k < d[2]; k++)
            for (int j = 0; j < d[1]; j++)
                for (int i = 0; i < d[0]; i++) {
                    if (!inside(i, j, k)) continue;
                    bool surf = i == 0 || j == 0 || k == 0 || i == d[0] - 1 || j == d[1] - 1 ||
                                k == d[2] - 1 || !inside(i - 1, j, k) || !inside(i + 1, j, k) ||
                                !inside(i, j - 1, k) || !inside(i, j + 1, k) ||
                                !inside(i, j, k - 1) || !inside(i, j, k + 1);
                    if (!surf) continue;
                    sum += std::fabs(acc.getValue(openvdb::Coord(i, j, k))) / g.h;
                    n++;
                }
        if (count) *count = n;
        return n ? sum / n : 0.0;
    };
    vx_bitgrid plain{}, super{}, faces{};
    vx_voxelize_stats st{};
    double ms;
    if (!ours(gl, vm, g, VX_METHOD_SLICE, 1, &plain, &st, &ms) ||
        !ours(gl, vm, g, VX_METHOD_SLICE, 2, &super, &st, &ms) ||
        !ours(gl, vm, g, VX_METHOD_AUTO, 2, &faces, &st, &ms, VX_SAMPLES_FACES))
        return 1;
    mt[0] = mean([&](int i, int j, int k) { return vx_bitgrid_get(&plain, i, j, k) != 0; }, nsurf);
    const int thr[5] = {1, 2, 4, 1, 2};
    for (int t = 0; t < 5; t++) {
        const vx_bitgrid &c = t < 3 ? super : faces;
        mt[t + 1] =
            mean([&](int i, int j,
                     int k) { return c.counts[((size_t)k * d[1] + j) * d[0] + i] >= thr[t]; },
                 nullptr);
    }
    vx_bitgrid_free(&plain);
    vx_bitgrid_free(&super);
    vx_bitgrid_free(&faces);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: see the top of bench/voxel/voxel_bench.cc\n");
        return 2;
    }
    openvdb::initialize();
    std::string mode = argv[1];
    std::vector<std::string> meshes;
    std::vector<int> res;
    vx_method method = VX_METHOD_AUTO;
    int runs = 3, res003 = 512, shifts = 0;
    bool filled = true;
    for (int i = 2; i < argc; i++) {
        if (!strcmp(argv[i], "--no-filled"))
            filled = false;
        else if (!strcmp(argv[i], "--method") && i + 1 < argc)
            method = parse_method(argv[++i]);
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--res") && i + 1 < argc)
            res003 = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--shifts") && i + 1 < argc)
            shifts = atoi(argv[++i]);
        else if (isdigit((unsigned char)argv[i][0]))
            res.push_back(atoi(argv[i]));
        else
            meshes.push_back(argv[i]);
    }
    vx_err err;
    vx_gl_desc gd{}; // zero = automatic device order
    vx_gl *gl = vx_gl_new(&gd, &err);
    if (!gl) {
        fprintf(stderr, "GL: %s\n", err.message);
        return 1;
    }
    printf("GL: %s; OpenVDB %s; %d CPUs\n", vx_gl_get_info(gl)->renderer,
           openvdb::getLibraryVersionString(),
           (int)std::max(1u, std::thread::hardware_concurrency()));

    if (mode == "compare") {
        printf(
            "| mesh | triangles | grid | voxeld ms (%s) | OpenVDB narrow band ms | speed-up | "
            "OpenVDB filled ms | speed-up | IoU (narrow) | IoU (filled) | inside voxeld | inside "
            "OpenVDB narrow |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
            method == VX_METHOD_PEEL    ? "peel"
            : method == VX_METHOD_SLICE ? "slice"
            : method == VX_METHOD_SCAN  ? "scan"
            : method == VX_METHOD_CPU   ? "cpu"
                                        : "auto");
        for (auto &spec : meshes) {
            Mesh m = load(spec);
            vx_mesh *vm = as_vx(m);
            for (int r : res) {
                vx_grid g;
                vx_grid_from_resolution(vm, r, 0, &g, &err);
                double best = 1e30, worst = 0, ms = 0;
                vx_bitgrid out{};
                vx_voxelize_stats st{};
                bool ok = true;
                for (int k = 0; k < runs + 1 && ok; k++) { // first run warms up (shader JIT)
                    vx_bitgrid_free(&out);
                    ok = ours(gl, vm, g, method, 1, &out, &st, &ms);
                    if (k) best = std::min(best, ms), worst = std::max(worst, ms);
                }
                if (!ok) continue;
                double vbest = 1e30, vworst = 0;
                uint64_t nv = 0, nf = 0;
                double u = 0;
                for (int k = 0; k < runs; k++) {
                    VdbResult v = vdb_interior(m, g, true);
                    vbest = std::min(vbest, v.ms);
                    vworst = std::max(vworst, v.ms);
                    if (k == 0) u = iou(out, *v.mask, &nv);
                }
                double uf = 0, fms = 0;
                if (filled) {
                    VdbResult f = vdb_interior(m, g, false);
                    uf = iou(out, *f.mask, &nf);
                    fms = f.ms;
                }
                // the filled band's columns, "-" when skipped (--no-filled)
                char fms_s[64] = "- | -", uf_s[32] = "-";
                if (filled) {
                    snprintf(fms_s, sizeof fms_s, "%.1f | %.1fx", fms, fms / best);
                    snprintf(uf_s, sizeof uf_s, "%.5f", uf);
                }
                printf(
                    "| %s | %zu | %dx%dx%d | %.1f (%.1f) | %.1f (%.1f) | %.1fx | %s | %.5f | %s | "
                    "%llu | %llu |\n",
                    m.name.c_str(), m.tri.size() / 3, g.dims[0], g.dims[1], g.dims[2], best, worst,
                    vbest, vworst, vbest / best, fms_s, u, uf_s,
                    (unsigned long long)vx_bitgrid_count(&out), (unsigned long long)nv);
                fflush(stdout);
                vx_bitgrid_free(&out);
            }
            vx_mesh_free(vm);
        }
    } else if (mode == "seed000") {
        printf("| faces | res | depth peeling ms (GPU) | fill ms (GPU) | total ms (wall) | layers "
               "| passes |\n|---|---|---|---|---|---|---|\n");
        for (auto &spec : meshes)
            for (int sub = 0; sub <= 3; sub++) {
                Mesh m = load(spec + ":" + std::to_string(sub));
                vx_mesh *vm = as_vx(m);
                for (int r : {128, 256}) {
                    vx_grid g;
                    vx_grid_from_resolution(vm, r, 0, &g, &err);
                    double best = 1e30, ms;
                    vx_voxelize_stats st{}, bst{};
                    for (int k = 0; k < runs + 1; k++) {
                        vx_bitgrid out{};
                        if (!ours(gl, vm, g, VX_METHOD_PEEL, 1, &out, &st, &ms)) break;
                        if (k && ms < best) best = ms, bst = st;
                        vx_bitgrid_free(&out);
                    }
                    printf("| %zu | %d^3 | %.1f | %.2f | %.1f | %d | %d |\n", m.tri.size() / 3, r,
                           bst.gpu_peel_ms, bst.gpu_fill_ms, best, bst.layers, bst.passes);
                    fflush(stdout);
                }
                vx_mesh_free(vm);
            }
    } else if (mode == "seed003") {
        printf(
            "| model | res | grid shift (voxels) | mean distance, no supersampling | 2x2x2 (seed), "
            "threshold 1 | threshold 2 | threshold 4 | faces, threshold 1 | faces, threshold 2 | "
            "surface voxels (no supersampling) |\n|---|---|---|---|---|---|---|---|---|---|\n");
        for (auto &spec : meshes) {
            Mesh m = load(spec);
            vx_mesh *vm = as_vx(m);
            vx_grid g0;
            vx_grid_from_resolution(vm, res003, 1, &g0, &err);
            double avg[SEED003_COLS] = {0, 0, 0, 0, 0, 0};
            for (int sh = 0; sh <= shifts; sh++) {
                // Shift 0: the API's grid (bbox faces on cell boundaries, which puts
                // the flat faces of CAD models at the worst phase). Others: the grid
                // moved by a sub-voxel offset per axis (golden-ratio sequence), one
                // more voxel per axis so it still covers the mesh.
                vx_grid g = g0;
                double off[3] = {0, 0, 0};
                if (sh) {
                    for (int a = 0; a < 3; a++) {
                        off[a] = std::fmod(0.5 + sh * (0.6180339887 + 0.1 * a), 1.0);
                        g.origin[a] -= off[a] * g.h;
                        g.dims[a] += 1;
                    }
                }
                double mt[SEED003_COLS];
                uint64_t nsurf = 0;
                if (seed003_means(gl, m, vm, g, mt, &nsurf)) return 1;
                printf("| %s | %d^3 | %s | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f | %llu |\n",
                       m.name.c_str(), res003,
                       sh ? (std::to_string(off[0]).substr(0, 4) + ", " +
                             std::to_string(off[1]).substr(0, 4) + ", " +
                             std::to_string(off[2]).substr(0, 4))
                                .c_str()
                          : "0 (API grid)",
                       mt[0], mt[1], mt[2], mt[3], mt[4], mt[5], (unsigned long long)nsurf);
                fflush(stdout);
                if (sh)
                    for (int t = 0; t < SEED003_COLS; t++)
                        avg[t] += mt[t] / shifts;
            }
            if (shifts)
                printf("| %s | %d^3 | mean of %d shifts | %.3f | %.3f | %.3f | %.3f | %.3f | %.3f "
                       "| |\n",
                       m.name.c_str(), res003, shifts, avg[0], avg[1], avg[2], avg[3], avg[4],
                       avg[5]);
            vx_mesh_free(vm);
        }
    }
    vx_gl_free(gl);
    return 0;
}
