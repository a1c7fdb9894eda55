#version 450 core
// The faces sample pattern's count (src/voxel/faces.c): a voxel's count is
// its centre and the six samples just inside its faces that are inside,
// read from the seven sample grids of one z slab, each with the voxel
// grid's layout (rows x ny x wx words), one after another in G: the
// centres, then the lower and upper face samples along x, y and z.
// One invocation per output word (32 voxels along x, the voxel.h layout)
// adds the seven sample words bit-sliced (full adders: three count bits per
// voxel), writes the word of voxels whose count reaches the threshold
// (compared bit-sliced too), and the 32 counts as bytes, x fastest, rows
// back to back, four at a time (a 4-bit slice spread to bytes by a multiply). A uint of counts
// that this word covers whole is stored; one it shares with the neighbouring
// word (nx not a multiple of 4) is ORed into the buffer the host cleared.
layout(local_size_x = 64) in;
layout(std430, binding = 0) readonly buffer G { uint g[]; };
layout(std430, binding = 1) writeonly buffer Bits { uint bits[]; };
layout(std430, binding = 2) coherent buffer Counts { uint counts[]; };
layout(location = 0) uniform ivec4 u_grid; // nx, ny, wx, slab rows
layout(location = 1) uniform int u_threshold; // 1..7

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    uint nx = uint(u_grid.x), ny = uint(u_grid.y), wx = uint(u_grid.z);
    uint slab = ny * wx * uint(u_grid.w);
    if (id >= slab) return;
    uint w = id % wx, row = id / wx; // row = z * ny + y within the slab
    uint s0 = g[id], s1 = g[slab + id], s2 = g[2u * slab + id], s3 = g[3u * slab + id],
         s4 = g[4u * slab + id], s5 = g[5u * slab + id], s6 = g[6u * slab + id];
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
        if (((u_threshold >> i) & 1) == 0) {
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
