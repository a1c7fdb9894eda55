#version 450 core
// Slicing voxelizer (seed 003 §3.3-3.4, src/voxel/slice.c): turns a batch of
// rendered slices into the bit layout of voxel.h (x fastest, 32 per word)
// and, with supersampling, per-voxel sample counts, on the GPU, so that the
// slices never travel to the CPU one by one.
//
// Supersample 2 (seed 003 §3.4): every voxel sees 2 x 2 pixels in each of
// two planes (layers 2s and 2s + 1, at w = k + 1/4 and k + 3/4): 8 samples;
// the voxel is set when at least u_threshold of them are inside.
layout(local_size_x = 64) in;

layout(std430, binding = 0) buffer Bits { uint bits[]; };
layout(std430, binding = 1) buffer Counts { uint counts[]; };
// The batch's images, copied from the colour target by a pixel pack (plain
// loads here are much cheaper than texelFetch on llvmpipe): R8 bytes (parity:
// 255 = back face) with rows padded to 4 bytes, or R32F (nonzero: the sum).
layout(std430, binding = 2) readonly buffer Img { uint img[]; };

layout(location = 0) uniform ivec3 u_perm;   // grid axes of u, v, w
layout(location = 1) uniform ivec4 u_rect;   // tile: u0, v0, width, height (voxels)
layout(location = 2) uniform ivec2 u_slices; // w of the batch's first slice, slice count
layout(location = 3) uniform ivec3 u_dims;   // grid nx, ny, nz
layout(location = 4) uniform ivec2 u_chunk;  // k0 of the chunk (SSBO holds k >= k0), wx
layout(location = 5) uniform int u_ss;       // 1 or 2
layout(location = 6) uniform int u_mode;     // 1 nonzero (sum != 0), 2 parity (count odd)
layout(location = 7) uniform int u_threshold;
layout(location = 8) uniform int u_counts;   // nonzero: write the counts buffer
layout(location = 9) uniform int u_packx;    // u is grid x: one invocation per 32 voxels
layout(location = 10) uniform ivec2 u_img;   // row stride in pixels, rows per layer

// A pixel's sum: the winding number beyond it (nonzero), or the number of
// surfaces beyond it (parity: inside when odd). Small integers, exact in
// float.
bool inside_sum(float s)
{
    return u_mode == 2 ? (int(round(s)) & 1) != 0 : abs(s) > 0.5;
}

uint pixel_index(int x, int y, int layer)
{
    return (uint(layer) * uint(u_img.y) + uint(y)) * uint(u_img.x) + uint(x);
}

// Inside bits of the n <= 32 pixels x0 .. x0 + n - 1 of one row.
uint row_bits(int x0, int y, int layer, int n)
{
    uint i = pixel_index(x0, y, layer), r = 0u;
    for (int q = 0; q < n; q++)
        if (inside_sum(uintBitsToFloat(img[i + uint(q)]))) r |= 1u << q;
    return n == 32 ? r : r & ((1u << n) - 1u);
}

void put_count(uint row, int x, int c)
{
    uint idx = row * uint(u_dims.x) + uint(x);
    atomicOr(counts[idx >> 2], uint(c) << ((idx & 3u) * 8u));
}

bool inside_index(uint i)
{
    return inside_sum(uintBitsToFloat(img[i]));
}

// Stepping along x or y: grid x runs along the batch's slices (dx = 2) or
// the image's rows (dx = 1). One invocation gathers the voxels of one output
// word, so a word costs one atomic (a word may straddle two batches). The
// samples are walked with a running pixel index: no per-voxel index math.
void pack_run(uint n)
{
    int dx = u_perm.x == 0 ? 0 : u_perm.y == 0 ? 1 : 2;
    int d1 = dx == 0 ? 1 : 0, d2 = dx == 2 ? 1 : 2;
    ivec3 ext = ivec3(u_rect.z, u_rect.w, u_slices.y);
    ivec3 org = ivec3(u_rect.x, u_rect.y, u_slices.x);
    int x_lo = org[dx], x_hi = org[dx] + ext[dx];
    int nruns = ((x_hi - 1) >> 5) - (x_lo >> 5) + 1;
    uint m = n / uint(nruns);
    int wi = (x_lo >> 5) + int(n % uint(nruns));
    ivec3 loc = ivec3(0);
    loc[d1] = int(m % uint(ext[d1]));
    loc[d2] = int(m / uint(ext[d1]));
    if (loc[d2] >= ext[d2]) return;
    ivec3 g;
    g[u_perm.x] = org.x + loc.x;
    g[u_perm.y] = org.y + loc.y;
    g[u_perm.z] = org.z + loc.z;
    uint row = uint(g.z - u_chunk.x) * uint(u_dims.y) + uint(g.y);
    int xs = max(32 * wi, x_lo), xe = min(32 * wi + 32, x_hi);
    loc[dx] = xs - org[dx];
    uint rowpx = uint(u_img.x), layerpx = uint(u_img.x) * uint(u_img.y);
    uint ss = uint(u_ss);
    uint i = (uint(loc.z) * ss * uint(u_img.y) + uint(loc.y) * ss) * rowpx + uint(loc.x) * ss;
    uint step = (dx == 0 ? 1u : dx == 1 ? rowpx : layerpx) * ss;
    uint word = 0u;
    for (int x = xs; x < xe; x++, i += step) {
        int c;
        if (u_ss == 1) {
            c = inside_index(i) ? 1 : 0;
        } else {
            c = 0;
            for (uint l = 0u; l < 2u; l++)
                for (uint b = 0u; b < 2u; b++) {
                    uint q = i + l * layerpx + b * rowpx;
                    c += (inside_index(q) ? 1 : 0) + (inside_index(q + 1u) ? 1 : 0);
                }
        }
        if (u_counts != 0 && c > 0) put_count(row, x, c);
        if (c >= u_threshold) word |= 1u << (x & 31);
    }
    if (word != 0u) atomicOr(bits[row * uint(u_chunk.y) + uint(wi)], word);
}

// Stepping along z: 32 voxels of one row (one output word) per invocation.
void pack_word(int t, int tv, int s)
{
    int x0 = 32 * t, n = min(32, u_rect.z - x0);
    int k = u_slices.x + s, y = u_rect.y + tv;
    uint row = uint(k - u_chunk.x) * uint(u_dims.y) + uint(y);
    uint word = 0u;
    if (u_ss == 1) {
        word = row_bits(x0, tv, s, n);
    } else {
        // 8 samples per voxel: per voxel q, pixels 2q and 2q + 1 of two
        // rows in two layers.
        uint cnt[8] = uint[8](0u, 0u, 0u, 0u, 0u, 0u, 0u, 0u); // 4 bits per voxel
        for (int l = 0; l < 2; l++)
            for (int b = 0; b < 2; b++) {
                int y2 = 2 * tv + b, layer = 2 * s + l;
                uint lo = row_bits(2 * x0, y2, layer, min(32, 2 * n));
                uint hi = n > 16 ? row_bits(2 * x0 + 32, y2, layer, 2 * n - 32) : 0u;
                // voxel q's two samples are bits 2q, 2q + 1: add them into
                // nibble q (max 8 fits in 4 bits)
                uint pl = (lo & 0x55555555u) + ((lo >> 1) & 0x55555555u);
                uint ph = (hi & 0x55555555u) + ((hi >> 1) & 0x55555555u);
                // pl: 2-bit sums of voxels 0..15; spread to nibbles
                for (int q = 0; q < 8; q++) {
                    cnt[q] += ((pl >> (4 * q)) & 3u) | (((pl >> (4 * q + 2)) & 3u) << 16);
                }
                for (int q = 0; q < 8; q++) {
                    cnt[q] += (((ph >> (4 * q)) & 3u) << 8) | (((ph >> (4 * q + 2)) & 3u) << 24);
                }
            }
        // cnt[q] bytes: voxel q (byte 0), q + 8 (byte 2 << ... ) -- unpacked below
        for (int q = 0; q < n; q++) {
            int c;
            if (q < 16)
                c = int((cnt[(q >> 1)] >> ((q & 1) * 16)) & 0xffu);
            else
                c = int((cnt[((q - 16) >> 1)] >> (8 + (q & 1) * 16)) & 0xffu);
            if (c == 0) continue;
            if (u_counts != 0) put_count(row, u_rect.x + x0 + q, c);
            if (c >= u_threshold) word |= 1u << q;
        }
    }
    // u0 is a multiple of 32 here, so this invocation owns a whole word.
    if (word != 0u) bits[row * uint(u_chunk.y) + uint((u_rect.x >> 5) + t)] = word;
}

void main()
{
    uint n = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x +
             gl_GlobalInvocationID.x;
    if (u_packx == 0) {
        pack_run(n);
        return;
    }
    uint per_row = uint(u_rect.z + 31) / 32u;
    uint per_slice = per_row * uint(u_rect.w);
    if (n >= per_slice * uint(u_slices.y)) return;
    int s = int(n / per_slice), tv = int(n % per_slice / per_row), t = int(n % per_row);
    pack_word(t, tv, s);
}
