#version 450 core
// Slicing voxelizer (seed 003 §3.1): front faces pure red, back faces pure
// blue. Only the blue channel matters, so one channel is written:
//   mode 0 (parity, depth test on, R8 target): 1 for a back face, 0 for a
//          front face; the nearest surface beyond the plane wins.
//   mode 1 (nonzero, additive blending, R32F target): +1 for a back face,
//          -1 for a front face; the sum over every surface beyond the plane
//          is the winding number of the ray from the voxel centre.
// "Back" is relative to the viewer looking along +w. Window x, y are grid
// u, v, so a triangle wound counter-clockwise in the window has its normal
// along +w, away from the viewer: GL calls it front-facing (glFrontFace
// GL_CCW), the seed calls it a back face (the ray leaves the solid there).
layout(location = 4) uniform int u_mode;

in float v_d;
layout(location = 0) out float o_val;

void main()
{
    // Tie rule [entry, exit): a surface exactly on the plane is not beyond
    // it. The GL near plane keeps w == plane, so drop it here.
    if (v_d <= 0.0) discard;
    bool leaves = gl_FrontFacing;
    o_val = u_mode == 0 ? (leaves ? 1.0 : 0.0) : (leaves ? 1.0 : -1.0);
}
