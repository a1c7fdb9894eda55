#version 450 core
// Crossing counts (src/voxel/scan.c): one draw of every triangle of the slab,
// orthographic along x as peel's first pass (voxel_peel.vert: pixel centres
// are voxel centres), no depth test, no culling, no colour output. Each
// fragment is one crossing of the pixel's ray, found by xing()
// (voxel_xing.glsl: the same in every brick of a lattice); it adds its sign
// to a per-voxel delta counter.
//
// As in voxel_peel_fill.comp and the CPU reference, crossings are counted
// from each centre towards +x: voxel i sees the crossings with t > i + 0.5,
// the half-open [entry, exit) tie rule (a crossing exactly at a centre is
// already passed). A crossing at t counts for voxels i < ib, ib = ceil(t -
// 0.5) (xing()): it goes to slot ib - 1 (the last voxel it counts for), to the row's
// tail counter when it counts for the whole row (ib >= n: beyond the grid
// end), and nowhere when ib <= 0 (before the first centre). The sum pass
// adds the slots from the row's end down: w(i) = tail + sum_{j >= i} d[j].
//
// Sign: counter-clockwise in the window faces +x (the window axes are a
// cyclic permutation of the grid axes): an exit, +1, as in peel's nonzero.
// Parity uses the same sums: a signed sum of crossings has the parity of
// their number.
//
// Block bits: one bit per 32 slots (one output word) tells the sum pass
// which blocks received a crossing; the others are one state throughout.
//
// Delta storage: two signed 16-bit fields per uint (slot 2q in the low half,
// 2q+1 in the high half). atomicAdd adds s * 65536^half mod 2^32; carries and
// borrows between the halves are harmless because the word is decoded as a
// signed-digit number (voxel_scan_sum.comp), exact while every field stays
// in [-32768, 32767]. The first atomic that would leave that range is seen
// here from the old value (fields move by one per crossing, in the order the
// atomics are applied) and raises the overflow flag: the host then reports
// too_many_crossings (auto falls back to peel).
#include "voxel_xing"

layout(std430, binding = 0) coherent buffer Delta { uint delta[]; };
layout(std430, binding = 1) coherent buffer Tail { int tail[]; };
layout(std430, binding = 2) coherent buffer Flag { uint overflow; };
layout(std430, binding = 3) coherent buffer Blocks { uint blocks[]; };
// nx, image width (ny), uints per delta row, uints per row of block bits
layout(location = 2) uniform ivec4 u_grid;
layout(location = 3) uniform int u_k0; // the slab's first z row (window y = z - u_k0)

void main()
{
    ivec2 p = ivec2(gl_FragCoord.xy);
    int row = p.y * u_grid.y + p.x, n = u_grid.x;
    int s = gl_FrontFacing ? 1 : -1;
    float frac;
    int ib = xing(ivec3(0, 1, 2), double(gl_FragCoord.x), double(gl_FragCoord.y) + double(u_k0),
                  1.0lf, frac);
    if (ib <= 0) return;
    if (ib >= n) {
        atomicAdd(tail[row], s);
        return;
    }
    int slot = ib - 1, sh = (slot & 1) << 4;
    uint old = atomicAdd(delta[row * u_grid.z + (slot >> 1)], uint(s) << sh);
    int d0 = (int(old << 16)) >> 16; // low field, sign-extended
    int d = sh == 0 ? d0 : int(old - uint(d0)) >> 16;
    if ((s > 0 && d == 32767) || (s < 0 && d == -32768)) atomicOr(overflow, 1u);
    // One bit per 32 voxels (one word of the output) that holds a count:
    // the sum pass reads only those blocks' counters.
    atomicOr(blocks[row * u_grid.w + (slot >> 10)], 1u << ((slot >> 5) & 31));
}
