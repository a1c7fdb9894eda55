#version 450 core
// Slicing voxelizer (seed 003 §3.2, src/voxel/slice.c): an orthographic view
// along +w from the slice's plane. Positions are already in the grid frame
// (voxel edge 1, grid origin at 0), normalised in double on the CPU.
// (u, v, w) is a cyclic permutation of (x, y, z), so the handedness and thus
// the facing of every triangle is the same for all three stepping axes.
layout(location = 0) in vec3 a_pos;

layout(location = 0) uniform ivec3 u_perm;  // grid axes that become u, v, w
layout(location = 1) uniform vec4 u_rect;   // image region: u0, v0, width, height (voxels)
layout(location = 2) uniform float u_plane; // w of the near clip plane (grid units)
layout(location = 3) uniform float u_depth; // w range beyond the plane mapped onto [0, 1]

out float v_d; // w - plane: the fragment shader enforces the strict side of the tie rule

void main()
{
    float u = a_pos[u_perm.x], v = a_pos[u_perm.y], w = a_pos[u_perm.z];
    v_d = w - u_plane;
    // The GL near plane (z_ndc = -1) lies on the slice plane: everything in
    // front of it is clipped, as in the seed where the view point moves.
    gl_Position = vec4(2.0 * (u - u_rect.x) / u_rect.z - 1.0, 2.0 * (v - u_rect.y) / u_rect.w - 1.0,
                       2.0 * v_d / u_depth - 1.0, 1.0);
}
