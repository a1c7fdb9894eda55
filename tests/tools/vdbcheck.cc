// vdbcheck FILE.vdb VOXELS.raw8 NX NY NZ [COUNTS.raw8 NSAMPLES]: checks the
// one grid of a voxelize .vdb against a reference built here the simple
// way, voxel by voxel through an accessor, from the raw8 voxels (and the
// per-voxel sample counts for a coverage grid):
//   bool "voxels": same active voxels and values;
//   fog "density"/"coverage": same active voxels and values;
//   level set "surface": the exact distance from each voxel centre to the
//     nearest voxel of the other state (outside the grid: unset), searched
//     voxel by voxel, active where under 3 voxels, negative exactly at the
//     set voxels.
// The file, whose topology, leaf buffers and delayed-load metadata the
// daemon writes on all threads, must also be byte for byte what
// OpenVDB's own io::File writes for the grid read back (but for the
// header's random UUID).
// Exit 0 when equal, 1 with a message on the first difference.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <cstdlib>
#include <unistd.h>
#include <string>
#include <vector>

#include <openvdb/openvdb.h>
#include <openvdb/tools/Diagnostics.h>

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
        file.open(/*delayLoad=*/false);
        const uint32_t compression = file.compression();
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        if (grids->size() != 1) return fprintf(stderr, "vdbcheck: %zu grids\n", grids->size()), 1;
        openvdb::GridBase::Ptr g = (*grids)[0];
        uint64_t set = 0, covered = 0;
        for (size_t i = 0; i < n; i++) {
            set += raw[i] != 0;
            covered += !counts.empty() && counts[i];
        }
        // The whole file as io::File writes the grid read back: the header
        // (its UUID aside), the grid's metadata (delayed-load metadata and
        // statistics included), topology and leaf buffers.
        {
            char tmp[] = "/tmp/vdbcheck-XXXXXX";
            const int fd = mkstemp(tmp);
            if (fd < 0) return fprintf(stderr, "vdbcheck: no temporary file\n"), 1;
            close(fd);
            openvdb::io::File out(tmp);
            out.setCompression(compression);
            out.write(*grids);
            const std::vector<unsigned char> want = slurp(tmp), bytes = slurp(argv[1]);
            unlink(tmp);
            // magic 8, version 4, library version 8, grid offsets 1, then the UUID's 36
            const size_t uuid = 21, uuid_end = uuid + 36;
            size_t d = 0;
            while (d < want.size() && d < bytes.size() &&
                   (want[d] == bytes[d] || (d >= uuid && d < uuid_end)))
                d++;
            if (d != want.size() || d != bytes.size())
                return fprintf(stderr,
                               "vdbcheck: the file is not what OpenVDB's io::File writes for its "
                               "grid: %zu against %zu bytes, first difference at byte %zu\n",
                               bytes.size(), want.size(), d),
                       1;
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
        // The band: at every voxel centre within 3 voxels of a voxel of the
        // other state (outside the grid: unset), the distance to the
        // nearest such voxel's cube, negative at set voxels; elsewhere
        // inactive, with the voxel's sign.
        const double h = f->transform().voxelSize()[0];
        auto state = [&](int i, int j, int k) {
            return i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz &&
                   raw[at(openvdb::Coord(i, j, k))] != 0;
        };
        // (|d| - 1/2)^2: a voxel cube d voxels away along one axis
        auto g1 = [](int d) {
            double e = std::abs(d) - 0.5;
            return e > 0 ? e * e : 0.0;
        };
        auto facc = f->getConstAccessor();
        uint64_t band = 0;
        for (int k = -4; k < nz + 4; k++)
            for (int j = -4; j < ny + 4; j++)
                for (int i = -4; i < nx + 4; i++) {
                    const bool s = state(i, j, k);
                    double best = 1e30;
                    for (int dz = -3; dz <= 3; dz++)
                        for (int dy = -3; dy <= 3; dy++)
                            for (int dx = -3; dx <= 3; dx++) {
                                if (state(i + dx, j + dy, k + dz) == s) continue;
                                best = std::min(best, g1(dx) + g1(dy) + g1(dz));
                            }
                    const double d = std::sqrt(best);
                    const openvdb::Coord c(i, j, k);
                    const float v = facc.getValue(c);
                    if ((v < 0) != s) return fail("sign is not the voxel's", i, j, k);
                    const bool on = d < 3;
                    band += on;
                    if (facc.isValueOn(c) != on) return fail("band membership differs", i, j, k);
                    if (on && std::fabs(std::fabs(v) - d * h) > 1e-6 * h)
                        return fail("distance differs", i, j, k);
                    if (!on && std::fabs(std::fabs(v) - 3 * h) > 1e-6 * h)
                        return fail("outside the band, not 3 voxels", i, j, k);
                }
        if (f->activeVoxelCount() != band)
            return fprintf(stderr, "vdbcheck: band of %llu voxels, want %llu\n",
                           (unsigned long long)f->activeVoxelCount(), (unsigned long long)band),
                   1;
        // OpenVDB's own diagnostics of a narrow-band level set: value and
        // class type, transform, background, tiles, finite values, range
        // and inactive values (not the 9th, |grad| near 1 by central
        // differences, which features a voxel or two thick fail)
        const std::string diag = openvdb::tools::checkLevelSet(*f, 8);
        if (!diag.empty())
            return fprintf(stderr, "vdbcheck: OpenVDB's checkLevelSet: %s\n", diag.c_str()), 1;
        // 3 voxels: the float nearest 3 h from above (checkLevelSet's own
        // check is in double, background >= 3 h)
        const float bg = f->background();
        if (!std::isfinite(bg) || (double)bg < 3 * h || (double)std::nextafter(bg, 0.0f) >= 3 * h)
            return fprintf(stderr, "vdbcheck: background %.9g, want 3 voxels (%.17g)\n", bg, 3 * h),
                   1;
        return 0;
    } catch (const std::exception &e) {
        fprintf(stderr, "vdbcheck: %s\n", e.what());
        return 1;
    }
}
