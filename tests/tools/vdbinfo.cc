// vdbinfo FILE.vdb: JSON facts about an OpenVDB file for shell and unit
// tests, read back through OpenVDB itself (not our writer's assumptions):
// {"grids":[{"name","type","active_voxels","bbox":[[i,j,k],[i,j,k]],
//   "transform":{"linear","voxel_size":[..],"translation":[..]},
//   "value_sum","metadata":{..}}]}. translation = world position of index
// (0,0,0). Exit status 1 when the file cannot be read.
#include <cstdio>
#include <string>

#include <openvdb/openvdb.h>

static std::string esc(const std::string &s)
{
    std::string o;
    for (char c : s) {
        if (c == '"' || c == '\\') o += '\\';
        if ((unsigned char)c < 0x20) continue;
        o += c;
    }
    return o;
}

static std::string meta_json(const openvdb::Metadata &m)
{
    char b[256];
    const std::string t = m.typeName();
    if (t == "string") return "\"" + esc(m.str()) + "\"";
    if (t == "int32" || t == "int64" || t == "bool")
        return m.str() == "true" ? "1" : m.str() == "false" ? "0" : m.str();
    if (t == "double") {
        snprintf(b, sizeof b, "%.17g", static_cast<const openvdb::DoubleMetadata &>(m).value());
        return b;
    }
    if (t == "float") {
        snprintf(b, sizeof b, "%.9g", static_cast<const openvdb::FloatMetadata &>(m).value());
        return b;
    }
    if (t == "vec3d") {
        auto v = static_cast<const openvdb::Vec3DMetadata &>(m).value();
        snprintf(b, sizeof b, "[%.17g,%.17g,%.17g]", v[0], v[1], v[2]);
        return b;
    }
    if (t == "vec3i") {
        auto v = static_cast<const openvdb::Vec3IMetadata &>(m).value();
        snprintf(b, sizeof b, "[%d,%d,%d]", v[0], v[1], v[2]);
        return b;
    }
    return "\"" + esc(m.str()) + "\"";
}

template <typename GridT> static double value_sum(const GridT &g)
{
    double s = 0;
    for (auto it = g.cbeginValueOn(); it; ++it)
        s += double(*it) * double(it.getVoxelCount());
    return s;
}

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "usage: vdbinfo FILE.vdb\n");
        return 2;
    }
    openvdb::initialize();
    try {
        openvdb::io::File file(argv[1]);
        file.open();
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        printf("{\"grids\":[");
        for (size_t n = 0; n < grids->size(); n++) {
            const openvdb::GridBase::Ptr &g = (*grids)[n];
            openvdb::CoordBBox bb = g->evalActiveVoxelBoundingBox();
            const openvdb::math::Transform &xf = g->transform();
            openvdb::Vec3d vs = xf.voxelSize(), t = xf.indexToWorld(openvdb::Vec3d(0, 0, 0));
            double sum = 0;
            if (auto b = openvdb::gridPtrCast<openvdb::BoolGrid>(g))
                sum = value_sum(*b);
            else if (auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(g))
                sum = value_sum(*f);
            printf("%s{\"name\":\"%s\",\"type\":\"%s\",\"active_voxels\":%llu,"
                   "\"bbox\":[[%d,%d,%d],[%d,%d,%d]],"
                   "\"transform\":{\"linear\":%s,\"voxel_size\":[%.17g,%.17g,%.17g],"
                   "\"translation\":[%.17g,%.17g,%.17g]},\"value_sum\":%.17g,\"metadata\":{",
                   n ? "," : "", esc(g->getName()).c_str(), g->valueType().c_str(),
                   (unsigned long long)g->activeVoxelCount(), bb.min().x(), bb.min().y(),
                   bb.min().z(), bb.max().x(), bb.max().y(), bb.max().z(),
                   xf.isLinear() ? "true" : "false", vs[0], vs[1], vs[2], t[0], t[1], t[2], sum);
            int first = 1;
            for (auto it = g->beginMeta(); it != g->endMeta(); ++it) {
                printf("%s\"%s\":%s", first ? "" : ",", esc(it->first).c_str(),
                       meta_json(*it->second).c_str());
                first = 0;
            }
            printf("}}");
        }
        printf("]}\n");
    } catch (const std::exception &e) {
        fprintf(stderr, "vdbinfo: %s: %s\n", argv[1], e.what());
        return 1;
    }
    return 0;
}
