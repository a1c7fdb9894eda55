// OpenVDB writer (io.h). The one C++ file of the library: OpenVDB's heavy
// templates are instantiated here only, behind a C API that never lets an
// exception cross into C.
#include <cmath>
#include <cstdio>
#include <exception>
#include <mutex>
#include <string>

#include <openvdb/openvdb.h>

extern "C" {
#include "voxel/io.h"
}

namespace
{

std::once_flag init_once;

template <typename GridT> void set_meta(GridT &grid, const vx_bitgrid *g, const vx_vdb_meta *m)
{
    const vx_grid &gr = g->grid;
    if (m) {
        if (m->method) grid.insertMeta("method", openvdb::StringMetadata(m->method));
        if (m->inside) grid.insertMeta("inside", openvdb::StringMetadata(m->inside));
        if (m->fill) grid.insertMeta("fill", openvdb::StringMetadata(m->fill));
        if (m->mesh) grid.insertMeta("mesh", openvdb::StringMetadata(m->mesh));
        grid.insertMeta("supersample", openvdb::Int32Metadata(m->supersample));
        grid.insertMeta("threshold", openvdb::Int32Metadata(m->threshold));
        if (m->samples) grid.insertMeta("samples", openvdb::StringMetadata(m->samples));
    }
    grid.insertMeta("voxel_size", openvdb::DoubleMetadata(gr.h));
    grid.insertMeta(
        "origin", openvdb::Vec3DMetadata(openvdb::Vec3d(gr.origin[0], gr.origin[1], gr.origin[2])));
    grid.insertMeta("dims",
                    openvdb::Vec3IMetadata(openvdb::Vec3i(gr.dims[0], gr.dims[1], gr.dims[2])));
    // Index (i,j,k) is the voxel centre origin + (i + 1/2, j + 1/2, k + 1/2) h.
    openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(gr.h);
    xf->postTranslate(openvdb::Vec3d(gr.origin[0] + 0.5 * gr.h, gr.origin[1] + 0.5 * gr.h,
                                     gr.origin[2] + 0.5 * gr.h));
    grid.setTransform(xf);
}

int progress(const vx_voxel_io *io, int k, int nz, vx_err *err)
{
    if (!io || !io->progress || (k & 7)) return 0;
    return io->progress(io->ud, 0.8 * k / nz, err) ? -1 : 0;
}

// Builds grids (build(grids) returns 0, or -1 with err set) and writes them
// to path through path.tmp and a rename, inside one try: no exception
// crosses into C, and a failed write leaves no file behind.
template <typename Build> int write_grids(const char *path, vx_err *err, Build build)
{
    std::string tmp = std::string(path) + ".tmp";
    try {
        std::call_once(init_once, [] { openvdb::initialize(); });
        openvdb::GridPtrVec grids;
        if (build(grids)) return -1;
        openvdb::io::File file(tmp);
        file.write(grids);
        file.close();
        if (std::rename(tmp.c_str(), path) != 0) {
            std::remove(tmp.c_str());
            return vx_err_set(err, VX_EIO, "io_error", "rename %s failed", tmp.c_str());
        }
        return 0;
    } catch (const std::bad_alloc &) {
        std::remove(tmp.c_str());
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the OpenVDB grid");
    } catch (const std::exception &e) {
        std::remove(tmp.c_str());
        return vx_err_set(err, VX_EIO, "io_error", "OpenVDB: %s", e.what());
    }
}

} // namespace

extern "C" uint64_t vx_voxel_vdb_bytes(const int dims[3], int coverage)
{
    // A leaf holds 512 voxels: a value mask (64 B) plus a bool mask (64 B)
    // or 512 floats (2 KiB), ~100 B of node overhead; the file buffer is
    // about the same again (compression works per leaf).
    uint64_t n = (uint64_t)dims[0] * (uint64_t)dims[1] * (uint64_t)dims[2];
    uint64_t leaves = n / 512 + 1;
    return leaves * (coverage ? 2300 : 240) * 2;
}

extern "C" int vx_voxel_write_vdb(const vx_bitgrid *g, int coverage, const vx_vdb_meta *meta,
                                  const char *path, const vx_voxel_io *io, vx_err *err)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    if (coverage && !g->counts)
        return vx_err_set(err, VX_EINTERNAL, "internal_error",
                          "coverage output without sample counts");
    int rc = write_grids(path, err, [&](openvdb::GridPtrVec &grids) {
        if (coverage) {
            openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
            grid->setName("coverage");
            grid->setGridClass(openvdb::GRID_FOG_VOLUME);
            auto acc = grid->getAccessor();
            for (int k = 0; k < nz; k++) {
                if (progress(io, k, nz, err)) return -1;
                for (int j = 0; j < ny; j++) {
                    const uint8_t *c = g->counts + ((size_t)k * ny + j) * nx;
                    for (int i = 0; i < nx; i++)
                        if (c[i])
                            acc.setValueOn(openvdb::Coord(i, j, k), c[i] / float(g->nsamples));
                }
            }
            set_meta(*grid, g, meta);
            grids.push_back(grid);
        } else {
            openvdb::BoolGrid::Ptr grid = openvdb::BoolGrid::create(false);
            grid->setName("voxels");
            auto acc = grid->getAccessor();
            for (int k = 0; k < nz; k++) {
                if (progress(io, k, nz, err)) return -1;
                for (int j = 0; j < ny; j++) {
                    const uint32_t *w = g->bits + ((size_t)k * ny + j) * g->wx;
                    for (size_t x = 0; x < g->wx; x++) {
                        // skip empty words: most of a grid is outside or
                        // runs of inside, and setValueOn is the cost here
                        for (uint32_t b = w[x]; b; b &= b - 1) {
                            int i = (int)(x * 32) + __builtin_ctz(b);
                            acc.setValueOn(openvdb::Coord(i, j, k), true);
                        }
                    }
                }
            }
            // Interior leaves that are entirely on become tiles: smaller files.
            grid->tree().prune();
            set_meta(*grid, g, meta);
            grids.push_back(grid);
        }
        return 0;
    });
    if (rc) return -1;
    if (io && io->progress && io->progress(io->ud, 1.0, err)) return -1;
    return 0;
}

extern "C" int vx_voxel_write_vdb_float(const float *v, const int dims[3], const double origin[3],
                                        double h, const char *name, const char *mesh,
                                        const char *path, vx_err *err)
{
    return write_grids(path, err, [&](openvdb::GridPtrVec &grids) {
        openvdb::FloatGrid::Ptr grid = openvdb::FloatGrid::create(0.0f);
        grid->setName(name);
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        auto acc = grid->getAccessor();
        const int nx = dims[0], ny = dims[1], nz = dims[2];
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < ny; j++) {
                const float *row = v + ((size_t)k * ny + j) * nx;
                for (int i = 0; i < nx; i++)
                    if (std::fabs(row[i]) >= 1e-4f) acc.setValueOn(openvdb::Coord(i, j, k), row[i]);
            }
        if (mesh) grid->insertMeta("mesh", openvdb::StringMetadata(mesh));
        grid->insertMeta("voxel_size", openvdb::DoubleMetadata(h));
        grid->insertMeta("dims", openvdb::Vec3IMetadata(openvdb::Vec3i(nx, ny, nz)));
        openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(h);
        xf->postTranslate(openvdb::Vec3d(origin[0], origin[1], origin[2]));
        grid->setTransform(xf);
        grids.push_back(grid);
        return 0;
    });
}
