// Included (#include "voxel_xing", src/gl/program.c) by the voxelizer
// fragment shaders: where the fragment's ray crosses its triangle, decided
// the same way in every brick of one lattice (src/voxel/xing.h).
//
// The rasterizer's positions are the lattice's units snapped to 1/256 voxel
// less the brick's integer index, and window coordinates are those times
// powers of two: its fixed-point coverage test sees a brick as an integer
// translate of the whole grid. The crossing is not the varying the
// rasterizer would interpolate (that starts from where the triangle sits in
// the window, which differs between bricks) but computed here in double
// from the lattice's unsnapped units (p - origin) / h, the same numbers in
// every brick, and the lattice index of the pixel's centre, then snapped
// to 2^-20 voxel along the ray; only the last step subtracts the brick's
// index, exactly.
//
// Vertex positions (3 doubles as RG32UI texels a vertex) and the triangles
// drawn (RGB32UI, one texel each: the element buffer) as texture buffers.
layout(binding = 6) uniform usamplerBuffer u_xing_pos;
layout(binding = 7) uniform usamplerBuffer u_xing_tri;
layout(location = 14) uniform dvec3 u_xing_index; // the brick's lattice index
layout(location = 15) uniform int u_xing_base;    // the draw's first triangle in u_xing_tri

// Vertex v in the lattice's units (p - origin) / h, unsnapped.
dvec3 xing_vertex(uint v)
{
    int i = 3 * int(v);
    return dvec3(packDouble2x32(texelFetch(u_xing_pos, i).xy),
                 packDouble2x32(texelFetch(u_xing_pos, i + 1).xy),
                 packDouble2x32(texelFetch(u_xing_pos, i + 2).xy));
}

// Closest point to x of the segment p -> q (2-D, relative coordinates) as
// (squared distance, parameter along the segment).
dvec2 xing_seg(dvec2 p, dvec2 q, dvec2 x)
{
    dvec2 d = q - p;
    double dd = dot(d, d), s = dd > 0.0 ? clamp(dot(x - p, d) / dd, 0.0, 1.0) : 0.0;
    dvec2 r = x - p - s * d;
    return dvec2(dot(r, r), s);
}

// The crossing of the fragment's triangle with the ray along grid axis
// ax.x through the brick's (pu, pv) along axes ax.y, ax.z ((ax.x, ax.y, ax.z)
// a cyclic permutation of (0, 1, 2)), in a frame scaled by ss (1, or 2
// where supersampling puts its sample planes at the half-integers of the
// doubled frame; pu, pv in it). Returns ib, the first sample centre at or
// beyond the crossing t snapped to 2^-20 voxel, less the brick's index: the
// crossing lies beyond centres i < ib (the half-open [entry, exit) rule),
// clamped to +-2^29. frac in (0, 1] places the unsnapped t between centres
// ib - 1 and ib, for ordering crossings only.
//
// The rasterizer covers the triangle with its corners snapped to 1/256
// voxel, so the ray may pass just outside the exact triangle (within about
// 1/256 voxel of an edge), where the crossing really belongs to a
// neighbour. Inside, t is the exact triangle's. Outside, the plane
// extended is what a smooth neighbour would give, but a sliver seen
// edge-on has a plane steep enough to put it voxels away (a streak down
// the column, issue 14), and the two faces of a fold would part; so the
// extension is kept within XING_REACH of the triangle's nearest point's t.
const double XING_REACH = 1.0 / 64.0;

int xing(ivec3 ax, double pu, double pv, double ss, out float frac)
{
    uvec3 tri = texelFetch(u_xing_tri, u_xing_base + gl_PrimitiveID).xyz;
    dvec3 a = xing_vertex(tri.x) * ss;
    precise dvec3 e1 = xing_vertex(tri.y) * ss - a, e2 = xing_vertex(tri.z) * ss - a;
    // the pixel centre in the lattice (integers and halves), from a
    dvec3 idx = u_xing_index * ss;
    precise dvec2 x = dvec2((idx[ax.y] + pu) - a[ax.y], (idx[ax.z] + pv) - a[ax.z]);
    dvec2 p1 = dvec2(e1[ax.y], e1[ax.z]), p2 = dvec2(e2[ax.y], e2[ax.z]);
    double t1 = e1[ax.x], t2 = e2[ax.x];
    precise double det = p1.x * p2.y - p1.y * p2.x;
    precise double bb = (x.x * p2.y - x.y * p2.x) / det, bc = (p1.x * x.y - p1.y * x.x) / det;
    precise double dt = bb * t1 + bc * t2;
    if (det == 0.0 || bb < 0.0 || bc < 0.0 || bb + bc > 1.0) {
        dvec2 s0 = xing_seg(dvec2(0.0), p1, x), s1 = xing_seg(p1, p2, x),
              s2 = xing_seg(p2, dvec2(0.0), x);
        precise double near = s0.y * t1;
        if (s1.x < s0.x) near = t1 + s1.y * (t2 - t1);
        if (s2.x < min(s0.x, s1.x)) near = (1.0 - s2.y) * t2;
        double reach = XING_REACH * ss;
        dt = det == 0.0 ? near : clamp(dt, near - reach, near + reach);
    }
    // The crossing snapped to 2^-20 voxel (VX_GRID_XING_SNAP), so that a
    // face on a plane of centres is exactly on it on any lattice, a tie
    // decided half-open: s in those units of the frame, exact in double,
    // centres at sh + k * sv.
    precise double t = a[ax.x] + dt;
    double sv = 1048576.0 / ss, sh = 524288.0 / ss;
    double cu = ceil((roundEven(t * sv) - sh) / sv);
    frac = float(min(t - 0.5 - (cu - 1.0), 1.0));
    return int(clamp(cu - idx[ax.x], -536870912.0, 536870912.0));
}
