#version 450 core
// Depth peeling (seed 000 §2.1), src/voxel/peel.c. Pass L keeps, per pixel,
// the nearest crossing strictly beyond layer L-1. Fragments exactly at layer
// L-1 are the crossings of that layer: each adds to the layer's count (and
// to its count of +x-facing crossings), so coincident surfaces (two faces
// at the same depth) are all counted instead of one being lost.
noperspective in float v_t;
layout(location = 0) out float o_t;
layout(binding = 0) uniform sampler2DArray u_layers;
layout(binding = 0, r32ui) uniform coherent uimage2DArray u_counts;
layout(location = 2) uniform int u_prev;    // index of layer L-1, -1 in the first pass
layout(location = 3) uniform vec2 u_depth;  // depth = (t - u_depth.x) * u_depth.y, in [0,1]

void main()
{
    if (u_prev >= 0) {
        ivec3 p = ivec3(ivec2(gl_FragCoord.xy), u_prev);
        float prev = texelFetch(u_layers, p, 0).r;
        if (v_t < prev) discard;
        if (v_t == prev) {
            // Counted here rather than in pass L-1: there only the winner of
            // the depth test would survive. Low 16 bits: crossings, high 16
            // bits: crossings seen front-facing (CCW in the window).
            imageAtomicAdd(u_counts, p, gl_FrontFacing ? 0x10001u : 1u);
            discard;
        }
    }
    o_t = v_t;
    // u_depth.y is a power of two and u_depth.x an integer: for a mesh inside
    // the grid the mapping is exact, so distinct crossings never tie.
    gl_FragDepth = (v_t - u_depth.x) * u_depth.y;
}
