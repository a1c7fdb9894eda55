#version 450 core
// Slicing voxelizer (seed 003 §3.2, src/voxel/slice.c): an orthographic view
// along +w. Positions are already in the grid frame (voxel edge 1, grid
// origin at 0), normalised in double on the CPU. (u, v, w) is a cyclic
// permutation of (x, y, z), so the handedness and thus the facing of every
// triangle is the same for all three stepping axes.
layout(location = 0) in vec3 a_pos;

layout(location = 0) uniform ivec3 u_perm;  // grid axes that become u, v, w
layout(location = 1) uniform vec4 u_rect;   // image region: u0, v0, width, height (voxels)
layout(location = 2) uniform vec2 u_planes; // w of two planes: v_d0 = w - x, v_d1 = w - y
layout(location = 3) uniform vec2 u_zmap;   // depth: z_ndc = (w - x) * y - 1

// Signed distances to the planes, subtracted per vertex before
// interpolation: a face lying exactly on a plane interpolates to exactly 0,
// and the same plane always gives the same value for the same fragment.
out float v_d0, v_d1;

void main()
{
    float u = a_pos[u_perm.x], v = a_pos[u_perm.y], w = a_pos[u_perm.z];
    v_d0 = w - u_planes.x;
    v_d1 = w - u_planes.y;
    // The map covers the whole mesh: nothing is clipped; the seed's near
    // plane is the fragment shader's test on v_d0.
    gl_Position = vec4(2.0 * (u - u_rect.x) / u_rect.z - 1.0, 2.0 * (v - u_rect.y) / u_rect.w - 1.0,
                       (w - u_zmap.x) * u_zmap.y - 1.0, 1.0);
}
