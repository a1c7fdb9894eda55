#version 450 core
// Prefix sums of the crossing counts (src/voxel/scan.c, voxel_scan.frag):
// one invocation per x row of the slab walks the row's output words from
// the end down, carrying w = tail + sum_{j >= i} d[j] (the crossings beyond
// the centre of voxel i), and writes whole words in the voxel.h layout, no
// atomics. A word whose block bit is clear received no crossing: it is all
// inside or all outside and its counters are not read, so the pass costs
// O(words + touched blocks), not O(voxels). Counters, block bits and the
// tail are left at zero for the next slab (the buffers are cleared once).
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer Delta { uint delta[]; };
layout(std430, binding = 1) buffer Tail { int tail[]; };
layout(std430, binding = 2) buffer Bits { uint bits[]; };
layout(std430, binding = 3) buffer Blocks { uint blocks[]; };
layout(location = 0) uniform ivec4 u_grid; // nx, ny, words per bit row wx, slab rows
// uints per delta row, mode (0 nonzero, 1 parity), uints per row of block bits
layout(location = 1) uniform ivec3 u_delta;

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    if (id >= uint(u_grid.y) * uint(u_grid.w)) return;
    int row = int(id), n = u_grid.x, dx = u_delta.x, wx = u_grid.z;
    int base = row * dx, bbase = row * wx, mbase = row * u_delta.z;
    int w = tail[row];
    if (w != 0) tail[row] = 0;
    bool parity = u_delta.y == 1;
    uint mword = 0u;
    for (int wi = wx - 1; wi >= 0; wi--) {
        if (wi == wx - 1 || (wi & 31) == 31) {
            mword = blocks[mbase + (wi >> 5)];
            if (mword != 0u) blocks[mbase + (wi >> 5)] = 0u;
        }
        int nb = min(n - (wi << 5), 32); // voxels in this word
        if (((mword >> (wi & 31)) & 1u) == 0u) {
            bool in_ = parity ? (w & 1) != 0 : w != 0;
            bits[bbase + wi] = in_ ? (nb == 32 ? 0xffffffffu : (1u << nb) - 1u) : 0u;
            continue;
        }
        // Touched: counters are visited from the top down; the voxels
        // between two nonzero counters share one state and are set as a run.
        uint acc = 0u;
        int top = nb; // bits [top, nb) are done
        for (int q = min((wi << 4) + 15, dx - 1); q >= (wi << 4); q--) {
            uint word = delta[base + q];
            if (word == 0u) continue;
            delta[base + q] = 0u;
            int d0 = (int(word << 16)) >> 16; // signed-digit decode (voxel_scan.frag)
            int d1 = int(word - uint(d0)) >> 16;
            int b = (2 * q) & 31; // the word's voxels are b and b + 1
            // bits [b + 2, top) have the current state
            if ((parity ? (w & 1) != 0 : w != 0) && b + 2 < top)
                acc |= (top == 32 ? 0xffffffffu : (1u << top) - 1u) & ~((2u << (b + 1)) - 1u);
            if (b + 1 < nb) {
                w += d1;
                if (parity ? (w & 1) != 0 : w != 0) acc |= 2u << b;
            }
            w += d0;
            if (parity ? (w & 1) != 0 : w != 0) acc |= 1u << b;
            top = b;
        }
        if ((parity ? (w & 1) != 0 : w != 0) && top > 0)
            acc |= top == 32 ? 0xffffffffu : (1u << top) - 1u;
        bits[bbase + wi] = acc;
    }
}
