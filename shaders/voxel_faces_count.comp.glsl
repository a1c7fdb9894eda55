#version 450 core
// The faces sample pattern's count (src/voxel/faces.c): a voxel's count is
// its centre and the centres of its six faces inside, read from the four
// sample grids of one z slab:
//   g0  the grid itself                       rows     x ny     x wx words
//   g1  moved half a voxel against x (nx + 1)  rows     x ny     x wx1
//   g2  moved against y (ny + 1 rows)          rows     x (ny+1) x wx
//   g3  moved against z (one more z row)       (rows+1) x ny     x wx
// One invocation per output word (32 voxels along x, the voxel.h layout)
// adds the seven sample words bit-sliced (full adders: three count bits per
// voxel), writes the word of voxels whose count reaches the threshold
// (compared bit-sliced too), and the 32 counts as bytes, x fastest, rows
// back to back, four at a time (a 4-bit slice spread to bytes by a multiply). A uint of counts
// that this word covers whole is stored; one it shares with the neighbouring
// word (nx not a multiple of 4) is ORed into the buffer the host cleared.
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer G0 { uint g0[]; };
layout(std430, binding = 1) readonly buffer G1 { uint g1[]; };
layout(std430, binding = 2) readonly buffer G2 { uint g2[]; };
layout(std430, binding = 3) readonly buffer G3 { uint g3[]; };
layout(std430, binding = 4) writeonly buffer Bits { uint bits[]; };
layout(std430, binding = 5) coherent buffer Counts { uint counts[]; };
layout(location = 0) uniform ivec4 u_grid; // nx, ny, wx, slab rows
layout(location = 1) uniform ivec2 u_par;  // words per row of g1, threshold (1..7)

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    uint nx = uint(u_grid.x), ny = uint(u_grid.y), wx = uint(u_grid.z);
    uint wx1 = uint(u_par.x);
    if (id >= ny * wx * uint(u_grid.w)) return;
    uint w = id % wx, row = id / wx; // row = z * ny + y within the slab
    uint y = row % ny, z = row / ny;
    uint x0 = g1[row * wx1 + w], xn = w + 1u < wx1 ? g1[row * wx1 + w + 1u] : 0u;
    uint r2 = (z * (ny + 1u) + y) * wx + w;
    // the centre, the lower and upper face along x, along y, along z
    uint s0 = g0[id], s1 = x0, s2 = (x0 >> 1) | (xn << 31), s3 = g2[r2], s4 = g2[r2 + wx],
         s5 = g3[id], s6 = g3[id + ny * wx];
    // 7 one-bit numbers per lane -> c2 c1 c0
    uint a0 = s0 ^ s1 ^ s2, a1 = (s0 & s1) | (s2 & (s0 ^ s1));
    uint b0 = s3 ^ s4 ^ s5, b1 = (s3 & s4) | (s5 & (s3 ^ s4));
    uint c0 = a0 ^ b0 ^ s6, d1 = (a0 & b0) | (s6 & (a0 ^ b0));
    uint c1 = a1 ^ b1 ^ d1, c2 = (a1 & b1) | (d1 & (a1 ^ b1));

    uint n = min(nx - w * 32u, 32u), valid = n == 32u ? 0xffffffffu : (1u << n) - 1u;
    c0 &= valid;
    c1 &= valid;
    c2 &= valid;
    // count >= threshold, bit-sliced from the top count bit down
    uint eq = 0xffffffffu, ge = 0u;
    for (int i = 2; i >= 0; i--) {
        uint x = i == 2 ? c2 : (i == 1 ? c1 : c0);
        if (((u_par.y >> i) & 1) == 0) {
            ge |= eq & x;
            eq &= ~x;
        } else {
            eq &= x;
        }
    }
    uint set = (ge | eq) & valid;
    // counts: 4 voxels per uint, each 4-bit slice of c0..c2 spread to bytes
    uint first = row * nx + w * 32u, last = first + n - 1u;
    for (uint u = first >> 2; u <= last >> 2; u++) {
        int b0 = int(u * 4u) - int(first); // this word's voxel in the uint's byte 0
        uint n0 = (b0 >= 0 ? c0 >> b0 : c0 << -b0) & 15u;
        uint n1 = (b0 >= 0 ? c1 >> b0 : c1 << -b0) & 15u;
        uint n2 = (b0 >= 0 ? c2 >> b0 : c2 << -b0) & 15u;
        uint v = ((n0 * 0x204081u) & 0x01010101u) | (((n1 * 0x204081u) & 0x01010101u) << 1) |
                 (((n2 * 0x204081u) & 0x01010101u) << 2);
        if (u * 4u >= first && u * 4u + 3u <= last)
            counts[u] = v;
        else
            atomicOr(counts[u], v);
    }
    bits[id] = set;
}
