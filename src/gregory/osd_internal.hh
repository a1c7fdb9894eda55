// OpenSubdiv glue shared by catmull_clark.cc and osd.cc (C++ only, private
// to src/gregory): the refiner built from a vx_mesh, and a double-precision
// vertex primvar.
#ifndef VX_GREGORY_OSD_INTERNAL_HH
#define VX_GREGORY_OSD_INTERNAL_HH

#include <opensubdiv/far/topologyRefiner.h>

extern "C" {
#include "mesh/mesh.h"
#include "util/err.h"
}

namespace vx_osd
{

// A point for Far's primvar templates (PrimvarRefiner, stencils, patches).
struct Point {
    double p[3];
    void Clear(void * = nullptr) { p[0] = p[1] = p[2] = 0; }
    void AddWithWeight(const Point &s, double w)
    {
        p[0] += w * s.p[0];
        p[1] += w * s.p[1];
        p[2] += w * s.p[2];
    }
};

// A Catmull-Clark refiner of m's faces (boundaries VTX_BOUNDARY_EDGE_ONLY,
// see catmull_clark.h); owned by the caller, NULL with err on failure.
// May throw std::bad_alloc.
OpenSubdiv::Far::TopologyRefiner *refiner_new(const vx_mesh *m, vx_err *err);
// The same from nfaces faces of sizes[f] vertices, indices face after face.
OpenSubdiv::Far::TopologyRefiner *refiner_new(int nverts, int nfaces, const int *sizes,
                                              const int *idx, vx_err *err);

} // namespace vx_osd

#endif
