#version 450 core
// Slicing voxelizer (seed 003 §3.2, src/voxel/slice.c): an orthographic view
// along +w. Positions are already in the grid frame (voxel edge 1, grid
// origin at 0), normalised in double on the CPU. (u, v, w) is a cyclic
// permutation of (x, y, z), so the handedness and thus the facing of every
// triangle is the same for all three stepping axes.
layout(location = 0) in vec3 a_pos;

layout(location = 0) uniform ivec3 u_perm;  // grid axes that become u, v, w
// window = (u, v) * u_ndc.xz + u_ndc.yw in NDC; a power-of-two viewport
// makes it (grid units - tile corner) * ss exactly (src/voxel/xing.h)
layout(location = 1) uniform vec4 u_ndc;
layout(location = 3) uniform vec2 u_zmap;   // depth: z_ndc = (w - x) * y - 1

invariant gl_Position;

void main()
{
    float u = a_pos[u_perm.x], v = a_pos[u_perm.y], w = a_pos[u_perm.z];
    // The depth map covers the whole mesh: nothing is clipped; the seed's
    // near plane is the fragment shader's test on the crossing.
    gl_Position = vec4(u * u_ndc.x + u_ndc.y, v * u_ndc.z + u_ndc.w, (w - u_zmap.x) * u_zmap.y - 1.0,
                       1.0);
}
