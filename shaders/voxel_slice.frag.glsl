#version 450 core
// Slicing voxelizer (seed 003 §3.1): front faces pure red, back faces pure
// blue, summed by additive blending into one R32F channel:
//   mode 1: +1 for a back face, -1 for a front face beyond plane 0 (with
//          u_count, +1 for every face); the sum over every surface beyond
//          the plane is the winding number of the ray from the voxel
//          centre (parity: the number of crossings).
//   mode 2 (incremental): the negated value of the surfaces in the slab
//          (plane 0, plane 1], added onto a copy of plane 0's sum.
// "Back" is relative to the viewer looking along +w. Window x, y are grid
// u, v, so a triangle wound counter-clockwise in the window has its normal
// along +w, away from the viewer: GL calls it front-facing (glFrontFace
// GL_CCW), the seed calls it a back face (the ray leaves the solid there).
//
// Where the fragment's ray crosses its triangle is xing()'s answer
// (voxel_xing.glsl: computed from the triangle's vertices, the same in
// every brick of a lattice; a triangle seen nearly edge-on keeps its
// crossing within its own w range) as the first plane at or beyond the
// crossing, ib, in the frame scaled by ss where plane j sits at j + 1/2:
// beyond plane j exactly when ib > j, so each fragment has one answer for
// every plane and the incremental sum adds and subtracts it consistently.
// Tie rule [entry, exit): a surface exactly on a plane is not beyond it
// (the GL near plane would keep it).
#include "voxel_xing"

layout(location = 0) uniform ivec3 u_perm;  // grid axes that become u, v, w
layout(location = 2) uniform ivec2 u_planes; // mode 1: plane x; mode 2: planes x < y
layout(location = 4) uniform int u_mode;
layout(location = 6) uniform int u_count;   // parity: every surface counts +1
layout(location = 7) uniform ivec2 u_off;   // scaled grid units of window (0, 0)
layout(location = 8) uniform int u_ss;

layout(location = 0) out float o_val;

void main()
{
    float frac;
    int ib = xing(ivec3(u_perm.z, u_perm.x, u_perm.y), double(gl_FragCoord.x) + double(u_off.x),
                  double(gl_FragCoord.y) + double(u_off.y), double(u_ss), frac);
    if (ib <= u_planes.x) discard;
    if (u_mode == 2 && ib > u_planes.y) discard;
    bool leaves = gl_FrontFacing;
    float sgn = leaves || u_count != 0 ? 1.0 : -1.0;
    o_val = u_mode == 1 ? sgn : -sgn;
}
