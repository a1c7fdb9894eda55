#version 450 core
// Gregory patch tessellation (src/gregory/tess.c, seed 001): one invocation
// per grid vertex; gl_WorkGroupID.y is the patch within the chunk, x * 64 +
// local id the vertex of its (N + 1)^2 grid. Evaluates exactly the formulas
// of src/gregory/patch.c (vx_gpatch_eval): position and the unit normal
// dS/du x dS/dv, with the corner blend limits and the diagonal approach at
// degenerate points.
layout(local_size_x = 64) in;
// 64 floats per patch: the 20 points relative to the patch's first point
// (float derivatives without the cancellation of large coordinates), then
// that point relative to the output origin, then one pad.
layout(std430, binding = 0) readonly buffer CP { float cp[]; };
layout(std430, binding = 1) readonly buffer Info { uvec2 info[]; }; // N, first grid vertex
layout(std430, binding = 2) writeonly buffer Out { float outv[]; }; // 6 per vertex

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
    vec3 c = cross(a, b);
    float l = length(c), la = length(a), lb = length(b);
    n = l > 0.0 ? c / l : vec3(0.0, 0.0, 1.0);
    return la > 0.0 && lb > 0.0 ? l / (la * lb) : 0.0;
}

void main()
{
    uint pid = gl_WorkGroupID.y;
    uvec2 pi = info[pid];
    uint n = pi.x, w = n + 1u, k = gl_GlobalInvocationID.x;
    if (k >= w * w) return;
    uint base = pid * 64u;
    float u = float(k % w) / float(n), v = float(k / w) / float(n);
    vec3 pos, du, dv, nrm;
    eval_raw(base, u, v, pos, du, dv);
    if (cross_unit(du, dv, nrm) <= 1e-5) {
        // A collapsed edge or corner: approach along the diagonal towards the
        // centre (float: from 1e-4, where the CPU starts at 1e-7).
        bool found = false;
        for (float t = 1e-4; t < 0.1 && !found; t *= 10.0) {
            vec3 p;
            eval_raw(base, u + (0.5 - u) * t, v + (0.5 - v) * t, p, du, dv);
            found = cross_unit(du, dv, nrm) > 1e-5;
        }
        if (!found) nrm = vec3(0.0, 0.0, 1.0);
    }
    pos += vec3(cp[base + 60u], cp[base + 61u], cp[base + 62u]);
    uint o = 6u * (pi.y + k);
    outv[o] = pos.x;
    outv[o + 1u] = pos.y;
    outv[o + 2u] = pos.z;
    outv[o + 3u] = nrm.x;
    outv[o + 4u] = nrm.y;
    outv[o + 5u] = nrm.z;
}
