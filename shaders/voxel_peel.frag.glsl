#version 450 core
// Depth peeling (seed 000 §2.1), src/voxel/peel.c, several layers per pass.
//
// A crossing's key orders crossings along the ray and says where it lies:
// the first voxel centre at or beyond it, ib (xing(), voxel_xing.glsl: the
// same in every brick of a lattice), clamped to [0, n], in the high bits
// (from bit u_key.x), then where it lies between two centres (or how far
// beyond the grid it is), then the facing in bit 0. Pass P owns the key
// slots [base, base + k) of its pixel. A fragment whose key is not beyond
// the last slot of the previous pass was peeled before and is discarded;
// the others are inserted with an atomic-min cascade: each slot keeps the
// smaller of what it held and what arrives and hands the larger on. A key
// meeting itself is a coincident crossing: it is dropped (the slots hold
// distinct keys, in increasing order) and flagged so that a last pass
// counts every key's fragments. A key handed on past slot k means the
// pixel has more layers than the pass holds: that fragment is the only one
// not discarded, so the pass's occlusion query reports a sample exactly
// when another pass is needed.
//
// Count pass (u_count = 1): each fragment finds its key among the pixel's
// u_nslots slots (binary search) and adds one to that slot's count.
#include "voxel_xing"

layout(binding = 0, r32ui) uniform coherent uimage2DArray u_keys;
layout(binding = 1, r32ui) uniform coherent uimage2DArray u_counts;
layout(std430, binding = 0) buffer Stat { uint coincident; };
layout(location = 0) uniform ivec3 u_axes;  // ray axis, window x axis, window y axis
layout(location = 2) uniform ivec2 u_pass;  // first slot of this pass, slots in this pass
layout(location = 3) uniform ivec2 u_key;   // ib's first key bit, voxels along the ray n
layout(location = 4) uniform int u_count;
layout(location = 5) uniform int u_nslots;
layout(location = 6) uniform ivec2 u_off;   // grid index of the window's pixel (0, 0)

const uint EMPTY = 0xffffffffu;

void main()
{
    ivec2 px = ivec2(gl_FragCoord.xy);
    float frac;
    int ib = xing(u_axes, double(gl_FragCoord.x) + double(u_off.x),
                  double(gl_FragCoord.y) + double(u_off.y), 1.0lf, frac);
    int n = u_key.y, sb = u_key.x - 1; // sub-order bits
    uint smax = (1u << sb) - 1u, sub;
    if (ib < 0) sub = smax - uint(min(-ib, int(smax)));
    else if (ib > n) sub = uint(min(ib - n, int(smax)));
    else sub = min(uint(frac * float(1u << sb)), smax);
    uint key = (uint(clamp(ib, 0, n)) << u_key.x) | (sub << 1) | (gl_FrontFacing ? 1u : 0u);
    if (u_count != 0) {
        int lo = 0, hi = u_nslots - 1;
        while (lo < hi) {
            int mid = (lo + hi) >> 1;
            if (imageLoad(u_keys, ivec3(px, mid)).r < key) lo = mid + 1;
            else hi = mid;
        }
        imageAtomicAdd(u_counts, ivec3(px, lo), 1u);
        discard;
    }
    if (u_pass.x > 0 && key <= imageLoad(u_keys, ivec3(px, u_pass.x - 1)).r) discard;
    uint v = key;
    for (int i = 0; i < u_pass.y; i++) {
        uint old = imageAtomicMin(u_keys, ivec3(px, u_pass.x + i), v);
        if (old == EMPTY) discard;
        if (old == v) {
            coincident = 1u;
            discard;
        }
        v = max(old, v);
    }
}
