#version 450 core
// Slicing voxelizer (seed 003 §3.1): front faces pure red, back faces pure
// blue. Only the blue channel matters, so one channel is written:
//   mode 0 (parity, depth test on, R8 target): 1 for a back face, 0 for a
//          front face beyond plane 0; the nearest surface wins.
//   mode 1 (nonzero, additive blending, R32F target): +1 for a back face,
//          -1 for a front face beyond plane 0; the sum over every surface
//          beyond the plane is the winding number of the ray from the
//          voxel centre.
//   mode 2 (nonzero, incremental): the negated sign of the surfaces in the
//          slab (plane 0, plane 1], added onto a copy of plane 0's sum.
// "Back" is relative to the viewer looking along +w. Window x, y are grid
// u, v, so a triangle wound counter-clockwise in the window has its normal
// along +w, away from the viewer: GL calls it front-facing (glFrontFace
// GL_CCW), the seed calls it a back face (the ray leaves the solid there).
layout(location = 4) uniform int u_mode;

in float v_d0, v_d1;
layout(location = 0) out float o_val;

void main()
{
    // Tie rule [entry, exit): a surface exactly on a plane is not beyond it
    // (the GL near plane would keep it).
    if (v_d0 <= 0.0) discard;
    if (u_mode == 2 && v_d1 > 0.0) discard;
    bool leaves = gl_FrontFacing;
    float sgn = leaves ? 1.0 : -1.0;
    o_val = u_mode == 0 ? (leaves ? 1.0 : 0.0) : u_mode == 1 ? sgn : -sgn;
}
