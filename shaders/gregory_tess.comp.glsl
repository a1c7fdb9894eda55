#version 450 core
// Gregory patch tessellation (src/gregory/tess.c, seed 001): one invocation
// per grid row of a patch (2-D dispatch flattened to one index over all
// rows of the chunk), the patch found from the index. Evaluates exactly the formulas
// of src/gregory/patch.c (vx_gpatch_eval): position and the unit normal
// dS/du x dS/dv, with the corner blend limits and the diagonal approach at
// degenerate points.
layout(local_size_x = 64) in;
// 64 floats per patch: the 20 points relative to the patch's first point
// (float derivatives without the cancellation of large coordinates), then
// that point relative to the output origin, then one pad.
layout(std430, binding = 0) readonly buffer CP { float cp[]; };
layout(std430, binding = 1) readonly buffer Info { uvec4 info[]; }; // N, first row, first vertex, 0
layout(std430, binding = 2) writeonly buffer Out { vec2 outv[]; }; // 6 floats per vertex, as 3 vec2 (fewer stores)
layout(location = 0) uniform uint u_nrows;    // grid rows of the chunk
layout(location = 1) uniform uint u_npatches;
layout(location = 2) uniform uint u_n;        // divisions of every patch, or 0: they differ

vec3 P(uint base, int slot)
{
    uint o = base + uint(3 * slot);
    return vec3(cp[o], cp[o + 1u], cp[o + 2u]);
}

void bern(float t, out vec4 b, out vec4 d)
{
    float s = 1.0 - t;
    b = vec4(s * s * s, 3.0 * t * s * s, 3.0 * t * t * s, t * t * t);
    d = vec4(-3.0 * s * s, 3.0 * s * s - 6.0 * t * s, 6.0 * t * s - 3.0 * t * t, 3.0 * t * t);
}

void eval_raw(uint base, float u, float v, out vec3 pos, out vec3 du, out vec3 dv)
{
    vec4 bu, dbu, bv, dbv;
    bern(u, bu, dbu);
    bern(v, bv, dbv);
    pos = vec3(0.0);
    du = vec3(0.0);
    dv = vec3(0.0);
    for (int j = 0; j < 4; j++) {
        vec3 row = vec3(0.0), rowd = vec3(0.0);
        for (int i = 0; i < 4; i++) {
            vec3 q = P(base, 4 * j + i);
            row += bu[i] * q;
            rowd += dbu[i] * q;
        }
        pos += bv[j] * row;
        du += bv[j] * rowd;
        dv += dbv[j] * row;
    }
    // Interior points: replace P_ij0 (used above) by the blend Q_ij.
    for (int k = 0; k < 4; k++) {
        int i = 1 + (k & 1), j = 1 + (k >> 1);
        vec3 p0 = P(base, 4 * j + i), p1 = P(base, 16 + k);
        float wu = i == 1 ? u : 1.0 - u, dwu = i == 1 ? 1.0 : -1.0;
        float wv = j == 1 ? v : 1.0 - v, dwv = j == 1 ? 1.0 : -1.0;
        float s = wu + wv;
        vec3 q, qu, qv;
        if (s <= 0.0) {
            q = 0.5 * (p0 + p1);
            qu = vec3(0.0);
            qv = vec3(0.0);
        } else {
            q = (wu * p0 + wv * p1) / s;
            qu = dwu * wv * (p0 - p1) / (s * s);
            qv = dwv * wu * (p1 - p0) / (s * s);
        }
        float w = bu[i] * bv[j];
        vec3 dq = q - p0;
        pos += w * dq;
        du += dbu[i] * bv[j] * dq + w * qu;
        dv += bu[i] * dbv[j] * dq + w * qv;
    }
}

// Sine of the angle between a and b; n = unit a x b (when nonzero).
float cross_unit(vec3 a, vec3 b, out vec3 n)
{
    float ma = max(max(abs(a.x), abs(a.y)), abs(a.z));
    float mb = max(max(abs(b.x), abs(b.y)), abs(b.z));
    a /= max(ma, 1e-37);
    b /= max(mb, 1e-37);
    vec3 c = cross(a, b);
    float l = length(c), la = length(a), lb = length(b);
    n = l > 0.0 ? c / l : vec3(0.0, 0.0, 1.0);
    return la > 0.0 && lb > 0.0 ? l / (la * lb) : 0.0;
}

// The patch of chunk row k: directly when every patch of the chunk has u_n
// divisions, else by binary search over the patches' first rows.
uint find_patch(uint k)
{
    if (u_n > 0u) return k / (u_n + 1u);
    uint lo = 0u, hi = u_npatches - 1u;
    while (lo < hi) {
        uint mid = (lo + hi + 1u) >> 1;
        if (info[mid].y <= k) lo = mid; else hi = mid - 1u;
    }
    return lo;
}

// One invocation per grid row (patch, v): llvmpipe pays tens of nanoseconds
// per invocation, so each one walks its row, with the v-only sums of the
// tensor product done once per row.
void main()
{
    uint k = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (k >= u_nrows) return;
    uint pid = find_patch(k);
    uvec4 pi = info[pid];
    uint n = pi.x, w = n + 1u, j = k - pi.y;
    uint base = pid * 64u;
    float v = float(j) / float(n);
    vec4 bv, dbv;
    bern(v, bv, dbv);
    // A_i = sum_j B_j(v) P_ij and its v-derivative, interior points left out.
    vec3 A[4], Av[4];
    for (int i = 0; i < 4; i++) {
        bool mid = i == 1 || i == 2;
        vec3 p0 = P(base, i), p1 = P(base, 4 + i), p2 = P(base, 8 + i), p3 = P(base, 12 + i);
        A[i] = bv.x * p0 + bv.w * p3 + (mid ? vec3(0.0) : bv.y * p1 + bv.z * p2);
        Av[i] = dbv.x * p0 + dbv.w * p3 + (mid ? vec3(0.0) : dbv.y * p1 + dbv.z * p2);
    }
    vec3 p0s[4], p1s[4];
    for (int q = 0; q < 4; q++) {
        int i = 1 + (q & 1), jj = 1 + (q >> 1);
        p0s[q] = P(base, 4 * jj + i);
        p1s[q] = P(base, 16 + q);
    }
    vec3 org = vec3(cp[base + 60u], cp[base + 61u], cp[base + 62u]);
    uint o = 3u * (pi.z + j * w);
    for (uint i = 0u; i <= n; i++, o += 3u) {
        float u = float(i) / float(n);
        vec4 bu, dbu;
        bern(u, bu, dbu);
        vec3 pos = bu.x * A[0] + bu.y * A[1] + bu.z * A[2] + bu.w * A[3];
        vec3 du = dbu.x * A[0] + dbu.y * A[1] + dbu.z * A[2] + dbu.w * A[3];
        vec3 dv = bu.x * Av[0] + bu.y * Av[1] + bu.z * Av[2] + bu.w * Av[3];
        for (int q = 0; q < 4; q++) {
            int ii = 1 + (q & 1), jj = 1 + (q >> 1);
            float wu = ii == 1 ? u : 1.0 - u, dwu = ii == 1 ? 1.0 : -1.0;
            float wv = jj == 1 ? v : 1.0 - v, dwv = jj == 1 ? 1.0 : -1.0;
            // s is 0 only at the patch corner this point belongs to, where
            // its Bernstein weights (and their derivatives times them) are
            // 0: clamping keeps the terms finite and 0 there, no branch.
            float is = 1.0 / max(wu + wv, 1e-6);
            vec3 qq = (wu * p0s[q] + wv * p1s[q]) * is;
            vec3 d = (p0s[q] - p1s[q]) * (is * is);
            vec3 qu = (dwu * wv) * d;
            vec3 qv = -(dwv * wu) * d;
            float bi = ii == 1 ? bu.y : bu.z, dbi = ii == 1 ? dbu.y : dbu.z;
            float bj = jj == 1 ? bv.y : bv.z, dbj = jj == 1 ? dbv.y : dbv.z;
            pos += (bi * bj) * qq;
            du += (dbi * bj) * qq + (bi * bj) * qu;
            dv += (bi * dbj) * qq + (bi * bj) * qv;
        }
        // the tangents scale with the mesh: each to its largest component
        // first, so that the products neither overflow nor underflow (the
        // normal and the angle test do not change)
        float mu = max(max(abs(du.x), abs(du.y)), abs(du.z));
        float mv = max(max(abs(dv.x), abs(dv.y)), abs(dv.z));
        du /= max(mu, 1e-37);
        dv /= max(mv, 1e-37);
        vec3 nrm = cross(du, dv);
        float l2 = dot(nrm, nrm);
        nrm *= inversesqrt(l2);
        // sine of the tangents' angle <= 1e-5 (as cross_unit), without roots
        if (!(l2 > 1e-10 * dot(du, du) * dot(dv, dv))) {
            // A collapsed edge or corner: approach along the diagonal towards
            // the centre (float: from 1e-4, where the CPU starts at 1e-7).
            bool found = false;
            for (float t = 1e-4; t < 0.1 && !found; t *= 10.0) {
                vec3 p;
                eval_raw(base, u + (0.5 - u) * t, v + (0.5 - v) * t, p, du, dv);
                found = cross_unit(du, dv, nrm) > 1e-5;
            }
            if (!found) nrm = vec3(0.0, 0.0, 1.0);
        }
        pos += org;
        outv[o] = pos.xy;
        outv[o + 1u] = vec2(pos.z, nrm.x);
        outv[o + 2u] = nrm.yz;
    }
}
