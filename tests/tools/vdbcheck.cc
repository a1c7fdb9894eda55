// vdbcheck FILE.vdb VOXELS.raw8 NX NY NZ [COUNTS.raw8 NSAMPLES]: checks the
// one grid of a voxelize .vdb against a reference built here the simple
// way, voxel by voxel through an accessor, from the raw8 voxels (and the
// per-voxel sample counts for a coverage grid):
//   bool "voxels": same active voxels and values;
//   fog "density"/"coverage": same active voxels and values;
//   level set "surface": the same narrow band as OpenVDB's
//     topologyToLevelSet of the reference BoolGrid, and negative exactly at
//     the set voxels.
// Exit 0 when equal, 1 with a message on the first difference.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <openvdb/openvdb.h>
#include <openvdb/tools/TopologyToLevelSet.h>

static std::vector<unsigned char> slurp(const char *p)
{
    std::vector<unsigned char> v;
    FILE *f = fopen(p, "rb");
    if (!f) return v;
    int c;
    while ((c = getc(f)) != EOF)
        v.push_back((unsigned char)c);
    fclose(f);
    return v;
}

static int fail(const char *what, int i, int j, int k)
{
    fprintf(stderr, "vdbcheck: %s at (%d,%d,%d)\n", what, i, j, k);
    return 1;
}

template <typename GridT, typename Want>
static int compare(const GridT &grid, int nx, int ny, int nz, uint64_t want_active, Want want)
{
    auto acc = grid.getConstAccessor();
    for (int k = 0; k < nz; k++)
        for (int j = 0; j < ny; j++)
            for (int i = 0; i < nx; i++) {
                openvdb::Coord c(i, j, k);
                bool on;
                typename GridT::ValueType v;
                want(c, on, v);
                if (acc.isValueOn(c) != on) return fail("active state differs", i, j, k);
                if (on && !(acc.getValue(c) == v)) return fail("value differs", i, j, k);
            }
    if (grid.activeVoxelCount() != want_active) {
        fprintf(stderr, "vdbcheck: %llu active voxels, want %llu\n",
                (unsigned long long)grid.activeVoxelCount(), (unsigned long long)want_active);
        return 1;
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc != 6 && argc != 8) {
        fprintf(stderr, "usage: vdbcheck FILE.vdb VOXELS.raw8 NX NY NZ [COUNTS.raw8 NSAMPLES]\n");
        return 2;
    }
    openvdb::initialize();
    const int nx = atoi(argv[3]), ny = atoi(argv[4]), nz = atoi(argv[5]);
    std::vector<unsigned char> raw = slurp(argv[2]), counts;
    const size_t n = (size_t)nx * ny * nz;
    int nsamples = 0;
    if (argc == 8) counts = slurp(argv[6]), nsamples = atoi(argv[7]);
    if (raw.size() != n || (argc == 8 && counts.size() != n)) {
        fprintf(stderr, "vdbcheck: raw files are not %zu bytes\n", n);
        return 1;
    }
    auto at = [&](const openvdb::Coord &c) {
        return (size_t)c.x() + nx * ((size_t)c.y() + ny * c.z());
    };
    try {
        openvdb::io::File file(argv[1]);
        file.open();
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        if (grids->size() != 1) return fprintf(stderr, "vdbcheck: %zu grids\n", grids->size()), 1;
        openvdb::GridBase::Ptr g = (*grids)[0];
        // The reference: voxel by voxel.
        openvdb::BoolGrid::Ptr ref = openvdb::BoolGrid::create(false);
        ref->setTransform(g->transform().copy());
        uint64_t set = 0, covered = 0;
        {
            auto acc = ref->getAccessor();
            for (int k = 0; k < nz; k++)
                for (int j = 0; j < ny; j++)
                    for (int i = 0; i < nx; i++) {
                        openvdb::Coord c(i, j, k);
                        if (raw[at(c)]) acc.setValueOn(c, true), set++;
                        if (!counts.empty() && counts[at(c)]) covered++;
                    }
        }
        if (auto b = openvdb::gridPtrCast<openvdb::BoolGrid>(g)) {
            if (b->getName() != "voxels") return fprintf(stderr, "vdbcheck: bool grid name\n"), 1;
            return compare(*b, nx, ny, nz, set, [&](const openvdb::Coord &c, bool &on, bool &v) {
                on = v = raw[at(c)] != 0;
            });
        }
        auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(g);
        if (!f) return fprintf(stderr, "vdbcheck: neither bool nor float\n"), 1;
        if (f->getGridClass() == openvdb::GRID_FOG_VOLUME) {
            if (!counts.empty())
                return compare(*f, nx, ny, nz, covered,
                               [&](const openvdb::Coord &c, bool &on, float &v) {
                                   on = counts[at(c)] > 0;
                                   v = (float)counts[at(c)] / (float)nsamples;
                               });
            return compare(*f, nx, ny, nz, set, [&](const openvdb::Coord &c, bool &on, float &v) {
                on = raw[at(c)] != 0;
                v = 1.0f;
            });
        }
        if (f->getGridClass() != openvdb::GRID_LEVEL_SET)
            return fprintf(stderr, "vdbcheck: float grid of class %s\n",
                           openvdb::GridBase::gridClassToString(f->getGridClass()).c_str()),
                   1;
        openvdb::FloatGrid::Ptr want = openvdb::tools::topologyToLevelSet(*ref, 3, 0, 0, 0);
        auto wacc = want->getConstAccessor();
        auto facc = f->getConstAccessor();
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < ny; j++)
                for (int i = 0; i < nx; i++) {
                    openvdb::Coord c(i, j, k);
                    if ((facc.getValue(c) < 0) != (raw[at(c)] != 0))
                        return fail("sign is not the voxel's", i, j, k);
                }
        for (auto it = want->cbeginValueOn(); it; ++it)
            if (!facc.isValueOn(it.getCoord()) ||
                std::fabs(facc.getValue(it.getCoord()) - *it) > 1e-6f)
                return fail("band differs", it.getCoord().x(), it.getCoord().y(),
                            it.getCoord().z());
        if (f->activeVoxelCount() != want->activeVoxelCount())
            return fprintf(stderr, "vdbcheck: band of %llu voxels, want %llu\n",
                           (unsigned long long)f->activeVoxelCount(),
                           (unsigned long long)want->activeVoxelCount()),
                   1;
        return 0;
    } catch (const std::exception &e) {
        fprintf(stderr, "vdbcheck: %s\n", e.what());
        return 1;
    }
}
