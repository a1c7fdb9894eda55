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

layout(binding = 0) uniform sampler2DArray u_img;
layout(std430, binding = 0) buffer Bits { uint bits[]; };
layout(std430, binding = 1) buffer Counts { uint counts[]; };

layout(location = 0) uniform ivec3 u_perm;   // grid axes of u, v, w
layout(location = 1) uniform ivec4 u_rect;   // tile: u0, v0, width, height (voxels)
layout(location = 2) uniform ivec2 u_slices; // w of the batch's first slice, slice count
layout(location = 3) uniform ivec3 u_dims;   // grid nx, ny, nz
layout(location = 4) uniform ivec2 u_chunk;  // k0 of the chunk (SSBO holds k >= k0), wx
layout(location = 5) uniform int u_ss;       // 1 or 2
layout(location = 6) uniform int u_mode;     // 0 parity (value 1 = back face), 1 nonzero
layout(location = 7) uniform int u_threshold;
layout(location = 8) uniform int u_counts;   // nonzero: write the counts buffer
layout(location = 9) uniform int u_packx;    // u is grid x: one invocation per 32 voxels

bool inside_at(ivec3 p)
{
    float s = texelFetch(u_img, p, 0).r;
    return u_mode == 0 ? s > 0.5 : abs(s) > 0.5;
}

int samples_at(int tu, int tv, int s)
{
    if (u_ss == 1) return inside_at(ivec3(tu, tv, s)) ? 1 : 0;
    int c = 0;
    for (int l = 0; l < 2; l++)
        for (int b = 0; b < 2; b++)
            for (int a = 0; a < 2; a++)
                c += inside_at(ivec3(2 * tu + a, 2 * tv + b, 2 * s + l)) ? 1 : 0;
    return c;
}

// Voxel (tu, tv) of the tile on slice s: its count, and its bit if set.
void store(int tu, int tv, int s, inout uint word)
{
    int c = samples_at(tu, tv, s);
    ivec3 g;
    g[u_perm.x] = u_rect.x + tu;
    g[u_perm.y] = u_rect.y + tv;
    g[u_perm.z] = u_slices.x + s;
    uint row = uint(g.z - u_chunk.x) * uint(u_dims.y) + uint(g.y);
    if (u_counts != 0 && c > 0) {
        uint idx = row * uint(u_dims.x) + uint(g.x);
        atomicOr(counts[idx >> 2], uint(c) << ((idx & 3u) * 8u));
    }
    if (c >= u_threshold) {
        if (u_packx != 0)
            word |= 1u << (g.x & 31);
        else
            atomicOr(bits[row * uint(u_chunk.y) + uint(g.x >> 5)], 1u << (g.x & 31));
    }
}

void main()
{
    uint n = gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x +
             gl_GlobalInvocationID.x;
    uint per_row = u_packx != 0 ? uint(u_rect.z + 31) / 32u : uint(u_rect.z);
    uint per_slice = per_row * uint(u_rect.w);
    if (n >= per_slice * uint(u_slices.y)) return;
    int s = int(n / per_slice), tv = int(n % per_slice / per_row), t = int(n % per_row);
    if (u_packx == 0) {
        uint unused = 0u;
        store(t, tv, s, unused);
        return;
    }
    // u0 is a multiple of 32 here, so this invocation owns a whole word.
    uint word = 0u;
    int end = min(32 * t + 32, u_rect.z);
    for (int tu = 32 * t; tu < end; tu++)
        store(tu, tv, s, word);
    if (word != 0u) {
        ivec3 g;
        g[u_perm.y] = u_rect.y + tv;
        g[u_perm.z] = u_slices.x + s;
        uint row = uint(g.z - u_chunk.x) * uint(u_dims.y) + uint(g.y);
        bits[row * uint(u_chunk.y) + uint((u_rect.x >> 5) + t)] = word;
    }
}
