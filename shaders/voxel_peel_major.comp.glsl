#version 450 core
// Robust mode (src/voxel/peel.c): per voxel majority (2 of 3) of the parity
// voxelizations along x, y and z, 32 voxels per invocation, written into a.
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer A { uint a[]; };
layout(std430, binding = 1) readonly buffer B { uint b[]; };
layout(std430, binding = 2) readonly buffer C { uint c[]; };
layout(location = 0) uniform uint u_n;

void main()
{
    uint i = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    if (i >= u_n) return;
    uint x = a[i], y = b[i], z = c[i];
    a[i] = (x & y) | (x & z) | (y & z);
}
