#version 450 core
// Test shader (tests/unit/test_gl.c): a 2-D dispatch writes 3 * its linear
// invocation index, so the test can check indexing across rows of groups.
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer Out { uint v[]; };
layout(location = 0) uniform uint u_n;

void main()
{
    uint row = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    uint i = gl_GlobalInvocationID.y * row + gl_GlobalInvocationID.x;
    if (i < u_n) v[i] = i * 3u;
}
