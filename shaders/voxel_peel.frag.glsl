#version 450 core
// Depth peeling (seed 000 §2.1), src/voxel/peel.c, several layers per pass.
//
// A crossing's key is its depth's float bits shifted left by one with the
// facing in bit 0: keys order like depths, and a front and a back face at
// one depth are two keys. Pass P owns the key slots [base, base + k) of its
// pixel. A fragment whose key is not beyond the last slot of the previous
// pass was peeled before and is discarded; the others are inserted with an
// atomic-min cascade: each slot keeps the smaller of what it held and what
// arrives and hands the larger on. A key meeting itself is a coincident
// crossing: it is dropped (the slots hold distinct keys, in increasing
// order) and flagged so that a last pass counts every key's fragments. A
// key handed on past slot k means the pixel has more layers than the pass
// holds: that fragment is the only one not discarded, so the pass's
// occlusion query reports a sample exactly when another pass is needed.
//
// Count pass (u_count = 1): each fragment finds its key among the pixel's
// u_nslots slots (binary search) and adds one to that slot's count.
noperspective in float v_t;
layout(binding = 0, r32ui) uniform coherent uimage2DArray u_keys;
layout(binding = 1, r32ui) uniform coherent uimage2DArray u_counts;
layout(std430, binding = 0) buffer Stat { uint coincident; };
layout(location = 2) uniform ivec2 u_pass;  // first slot of this pass, slots in this pass
layout(location = 3) uniform vec2 u_depth;  // depth = (t - u_depth.x) * u_depth.y, in [0,1]
layout(location = 4) uniform int u_count;
layout(location = 5) uniform int u_nslots;

const uint EMPTY = 0xffffffffu;

void main()
{
    ivec2 px = ivec2(gl_FragCoord.xy);
    // u_depth.y is a power of two and u_depth.x an integer at or below the
    // mesh: for a mesh inside the grid the mapping is exact, so distinct
    // crossings never share a key. Depths are >= 0, so their bits order
    // like their values and fit in 31 bits.
    float depth = clamp((v_t - u_depth.x) * u_depth.y, 0.0, 1.0);
    uint key = (floatBitsToUint(depth) << 1) | (gl_FrontFacing ? 1u : 0u);
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
