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
// The fragment's w is the interpolated one clamped to its triangle's w range
// (wr[], in the order of the index buffer drawn; u_base = the draw's first
// triangle there). A triangle seen nearly edge-on projects to a sliver whose
// interpolation plane is ill-conditioned: unclamped, a pixel it covers may
// get any w, far outside the triangle, and then stands beyond planes it
// never reaches (a streak down the rest of the column; issue 14). Clamped,
// the error stays within the triangle, a face with one w (on a plane) keeps
// that w exactly, and each fragment has one w for every plane, so the
// incremental sum adds and subtracts it consistently.
layout(location = 2) uniform vec2 u_planes; // w of the two planes
layout(location = 4) uniform int u_mode;
layout(location = 5) uniform uint u_base;
layout(location = 6) uniform int u_count; // parity: every surface counts +1
layout(std430, binding = 3) readonly buffer WRange { vec2 wr[]; };

in float v_w;
layout(location = 0) out float o_val;

void main()
{
    vec2 r = wr[u_base + uint(gl_PrimitiveID)];
    float w = clamp(v_w, r.x, r.y);
    // Tie rule [entry, exit): a surface exactly on a plane is not beyond it
    // (the GL near plane would keep it).
    if (w - u_planes.x <= 0.0) discard;
    if (u_mode == 2 && w - u_planes.y > 0.0) discard;
    bool leaves = gl_FrontFacing;
    float sgn = leaves || u_count != 0 ? 1.0 : -1.0;
    o_val = u_mode == 1 ? sgn : -sgn;
}
