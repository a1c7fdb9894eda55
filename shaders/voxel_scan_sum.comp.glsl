#version 450 core
// Prefix sums of the crossing counts (src/voxel/scan.c, voxel_scan.frag):
// one invocation per x row of the slab adds the delta slots from the row's
// end down (w(i) = tail + sum_{j >= i} d[j], the crossings beyond the centre
// of voxel i) and writes the row's bits in the voxel.h layout, whole words,
// no atomics. It leaves the delta row and the tail at zero for the next
// slab (the buffers are cleared once).
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer Delta { uint delta[]; };
layout(std430, binding = 1) buffer Tail { int tail[]; };
layout(std430, binding = 2) buffer Bits { uint bits[]; };
layout(location = 0) uniform ivec4 u_grid; // nx, ny, words per bit row wx, slab rows
layout(location = 1) uniform ivec2 u_delta; // uints per delta row, mode (0 nonzero, 1 parity)

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    if (id >= uint(u_grid.y) * uint(u_grid.w)) return;
    int row = int(id), n = u_grid.x, dx = u_delta.x;
    int base = row * dx, bbase = row * u_grid.z;
    int w = tail[row];
    if (w != 0) tail[row] = 0;
    uint acc = 0u;
    bool parity = u_delta.y == 1;
    for (int q = dx - 1; q >= 0; q--) {
        uint word = delta[base + q];
        int d0 = 0, d1 = 0;
        if (word != 0u) {
            delta[base + q] = 0u;
            d0 = (int(word << 16)) >> 16;
            d1 = int(word - uint(d0)) >> 16;
        }
        int i = 2 * q + 1;
        if (i < n) {
            w += d1;
            if (parity ? (w & 1) != 0 : w != 0) acc |= 1u << (i & 31);
            // i odd: never the first bit of a word
        }
        i = 2 * q;
        w += d0;
        if (parity ? (w & 1) != 0 : w != 0) acc |= 1u << (i & 31);
        if ((i & 31) == 0) {
            bits[bbase + (i >> 5)] = acc;
            acc = 0u;
        }
    }
}
