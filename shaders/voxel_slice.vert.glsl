#version 450 core
// Slicing voxelizer (seed 003 §3.2, src/voxel/slice.c): an orthographic view
// along +w. Positions are already in the grid frame (voxel edge 1, grid
// origin at 0), normalised in double on the CPU. (u, v, w) is a cyclic
// permutation of (x, y, z), so the handedness and thus the facing of every
// triangle is the same for all three stepping axes.
layout(location = 0) in vec3 a_pos;

layout(location = 0) uniform ivec3 u_perm;  // grid axes that become u, v, w
layout(location = 1) uniform vec4 u_rect;   // image region: u0, v0, width, height (voxels)
layout(location = 3) uniform vec2 u_zmap;   // depth: z_ndc = (w - x) * y - 1

// w itself, interpolated once per fragment; the fragment shader clamps it
// to the triangle's own w range and compares it with the planes.
out float v_w;

void main()
{
    float u = a_pos[u_perm.x], v = a_pos[u_perm.y], w = a_pos[u_perm.z];
    v_w = w;
    // The map covers the whole mesh: nothing is clipped; the seed's near
    // plane is the fragment shader's test on v_d0.
    gl_Position = vec4(2.0 * (u - u_rect.x) / u_rect.z - 1.0, 2.0 * (v - u_rect.y) / u_rect.w - 1.0,
                       (w - u_zmap.x) * u_zmap.y - 1.0, 1.0);
}
