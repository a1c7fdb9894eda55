#version 450 core
// Surface fill (src/voxel/peel.c, VX_FILL_SURFACE): every voxel whose closed
// box the triangle touches, by the separating-axis triangle/box test
// (Akenine-Moller 2001), one invocation per triangle of the list (the CPU
// keeps the triangles whose work would be too large for one invocation).
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer Bits { uint bits[]; };
layout(std430, binding = 1) readonly buffer Pos { float pos[]; };
layout(std430, binding = 2) readonly buffer Idx { uint idx[]; };
layout(std430, binding = 3) readonly buffer List { uint list[]; };
layout(location = 0) uniform uint u_ntri;
layout(location = 1) uniform ivec4 u_grid; // nx, ny, wx, slab rows
layout(location = 2) uniform int u_k0;
layout(location = 3) uniform float u_hs;   // half box size: 0.5 + a small margin

vec3 vtx(uint i) { return vec3(pos[3u * i], pos[3u * i + 1u], pos[3u * i + 2u]); }

bool axis_test(vec3 a, vec3 v0, vec3 v1, vec3 v2)
{
    float p0 = dot(a, v0), p1 = dot(a, v1), p2 = dot(a, v2);
    float r = u_hs * (abs(a.x) + abs(a.y) + abs(a.z));
    return !(min(p0, min(p1, p2)) > r || max(p0, max(p1, p2)) < -r);
}

bool tri_box(vec3 c, vec3 v0, vec3 v1, vec3 v2, vec3 n)
{
    v0 -= c;
    v1 -= c;
    v2 -= c;
    vec3 e[3] = vec3[3](v1 - v0, v2 - v1, v0 - v2);
    for (int i = 0; i < 3; i++) {
        if (!axis_test(vec3(0.0, -e[i].z, e[i].y), v0, v1, v2)) return false;
        if (!axis_test(vec3(e[i].z, 0.0, -e[i].x), v0, v1, v2)) return false;
        if (!axis_test(vec3(-e[i].y, e[i].x, 0.0), v0, v1, v2)) return false;
    }
    vec3 lo = min(v0, min(v1, v2)), hi = max(v0, max(v1, v2));
    if (any(greaterThan(lo, vec3(u_hs))) || any(lessThan(hi, vec3(-u_hs)))) return false;
    return axis_test(n, v0, v1, v2);
}

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    if (id >= u_ntri) return;
    uint t = list[id];
    vec3 a = vtx(idx[3u * t]), b = vtx(idx[3u * t + 1u]), c = vtx(idx[3u * t + 2u]);
    vec3 n = cross(b - a, c - b);
    float m = u_hs - 0.5;
    // voxel i (box [i, i+1]) can touch [lo, hi] when ceil(lo) - 1 <= i <= floor(hi)
    // (clamped before int(): a vertex may lie far outside the grid)
    vec3 gmax = vec3(u_grid.x, u_grid.y, u_k0 + u_grid.w) + 2.0;
    ivec3 lo = ivec3(ceil(clamp(min(a, min(b, c)) - m, vec3(-2.0), gmax))) - 1;
    ivec3 hi = ivec3(floor(clamp(max(a, max(b, c)) + m, vec3(-2.0), gmax)));
    lo = max(lo, ivec3(0, 0, u_k0));
    hi = min(hi, ivec3(u_grid.x - 1, u_grid.y - 1, u_k0 + u_grid.w - 1));
    // Walk rows across the two axes other than the one the normal is
    // closest to; along that one only the voxels near the plane (widened by
    // one voxel for rounding). The CPU path in peel.c does the same.
    int d = abs(n.x) >= abs(n.y) ? (abs(n.x) >= abs(n.z) ? 0 : 2) : (abs(n.y) >= abs(n.z) ? 1 : 2);
    int a1 = (d + 1) % 3, a2 = (d + 2) % 3;
    float rad = u_hs * (abs(n.x) + abs(n.y) + abs(n.z)), dd = dot(n, a);
    ivec3 r;
    for (r[a2] = lo[a2]; r[a2] <= hi[a2]; r[a2]++)
        for (r[a1] = lo[a1]; r[a1] <= hi[a1]; r[a1]++) {
            int t0 = lo[d], t1 = hi[d];
            if (n[d] != 0.0) {
                float rest = n[a1] * (float(r[a1]) + 0.5) + n[a2] * (float(r[a2]) + 0.5);
                float x0 = (dd - rest - rad) / n[d], x1 = (dd - rest + rad) / n[d];
                float l = float(lo[d]) - 2.0, h = float(hi[d]) + 2.0;
                t0 = max(t0, int(floor(clamp(min(x0, x1) - 0.5, l, h))) - 1);
                t1 = min(t1, int(ceil(clamp(max(x0, x1) - 0.5, l, h))) + 1);
            }
            for (r[d] = t0; r[d] <= t1; r[d]++)
                if (tri_box(vec3(r) + 0.5, a, b, c, n))
                    atomicOr(bits[((r.z - u_k0) * u_grid.y + r.y) * u_grid.z + (r.x >> 5)],
                             1u << (r.x & 31));
        }
}
