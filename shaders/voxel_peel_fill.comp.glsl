#version 450 core
// Fill (seed 000 §2.2, "voxelization as ray casting"), src/voxel/peel.c: one
// invocation per pixel column walks the peeled layers front to back. No data
// goes back to the CPU between peeling and this pass. A layer is a key
// (voxel_peel.frag.glsl: the first voxel centre at or beyond the crossing,
// ib, from bit u_shift up; the facing in bit 0), in increasing order until
// the first empty slot; its multiplicity is its count when coincident
// crossings were counted, else 1.
//
// Crossings are counted from the centre towards +ray as the CPU reference
// does (ray cast from each centre): the state at centre i is the total of
// all layers minus the layers with ib <= i (a layer at exactly the centre
// has ib = i and counts as passed: the half-open [entry, exit) tie rule).
// Orientation: a crossing that is counter-clockwise in the window (facing
// bit 1) faces +ray (the window axes are a cyclic permutation of the grid
// axes): it is an exit, +1, so a closed outward mesh has winding +1 inside.
layout(local_size_x = 64) in;
layout(binding = 0) uniform usampler2DArray u_keys;
layout(binding = 1) uniform usampler2DArray u_counts;
layout(std430, binding = 0) buffer Bits { uint bits[]; };
layout(std430, binding = 1) buffer Stat { uint coincident; uint most_layers; };
layout(location = 0) uniform ivec2 u_size;  // image width, height in pixels
layout(location = 1) uniform int u_nlayers;
layout(location = 2) uniform int u_mode;    // 0: nonzero, 1: parity
layout(location = 3) uniform int u_axis;    // ray axis; 0 writes whole words, 1 and 2 atomicOr
layout(location = 4) uniform ivec4 u_grid;  // nx, ny, words per row wx, slab rows
layout(location = 5) uniform ivec2 u_ray;   // voxels along the ray n, first slab row k0 (axis 2)
layout(location = 6) uniform int u_shift;   // a key's ib = key >> u_shift
layout(location = 7) uniform int u_counted; // u_counts holds multiplicities

const uint EMPTY = 0xffffffffu;

// Multiplicity of layer l (fragments with its key).
int crossings(ivec2 p, int l)
{
    return u_counted != 0 ? int(texelFetch(u_counts, ivec3(p, l), 0).r) : 1;
}

int g_base = 0, g_word = 0;
uint g_acc = 0u;

// Axis 0: the column is one x row of the slab; words are produced in order.
void put_word(int w)
{
    while (g_word < w) {
        bits[g_base + g_word] = g_acc;
        g_acc = 0u;
        g_word++;
    }
}

void set_range_x(int a, int b)
{
    while (a < b) {
        int w = a >> 5;
        put_word(w);
        int lo = a & 31, hi = min(b - (w << 5), 32);
        uint m = (hi == 32 ? 0xffffffffu : ((1u << hi) - 1u)) & ~((1u << lo) - 1u);
        g_acc |= m;
        a = (w << 5) + hi;
    }
}

void set_voxel(int x, int y, int z)
{
    atomicOr(bits[(z * u_grid.y + y) * u_grid.z + (x >> 5)], 1u << (x & 31));
}

void set_range(ivec2 p, int a, int b)
{
    if (u_axis == 0) {
        set_range_x(a, b);
    } else if (u_axis == 1) { // window (z in slab, x), ray y
        for (int i = a; i < b; i++) set_voxel(p.y, i, p.x);
    } else { // window (x, y), ray z over the whole grid: keep this slab's rows
        a = max(a, u_ray.y);
        b = min(b, u_ray.y + u_grid.w);
        for (int i = a; i < b; i++) set_voxel(p.x, p.y, i - u_ray.y);
    }
}

void main()
{
    uint id = gl_GlobalInvocationID.y * (gl_NumWorkGroups.x * 64u) + gl_GlobalInvocationID.x;
    if (id >= uint(u_size.x) * uint(u_size.y)) return;
    ivec2 p = ivec2(int(id % uint(u_size.x)), int(id / uint(u_size.x)));
    int n = u_ray.x;

    int wtot = 0, ctot = 0, nl = 0;
    for (; nl < u_nlayers; nl++) {
        uint k = texelFetch(u_keys, ivec3(p, nl), 0).r;
        if (k == EMPTY) break;
        int m = crossings(p, nl);
        ctot += m;
        wtot += (k & 1u) != 0u ? m : -m;
    }
    if (nl > 0) atomicMax(most_layers, uint(nl));

    g_base = (p.y * u_grid.y + p.x) * u_grid.z;
    g_word = 0;
    g_acc = 0u;
    int w = wtot, par = ctot & 1, i0 = 0;
    for (int l = 0; l < nl && i0 < n; l++) {
        uint k = texelFetch(u_keys, ivec3(p, l), 0).r;
        int m = crossings(p, l);
        int ib = clamp(int(k >> uint(u_shift)), i0, n);
        bool inside = u_mode == 1 ? par != 0 : w != 0;
        if (inside) set_range(p, i0, ib);
        i0 = ib;
        w -= (k & 1u) != 0u ? m : -m;
        par ^= m & 1;
    }
    bool inside = u_mode == 1 ? par != 0 : w != 0;
    if (inside && i0 < n) set_range(p, i0, n);
    if (u_axis == 0) put_word(u_grid.z);
}
