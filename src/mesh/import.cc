/* STL and glTF 2.0 readers behind the C API of mesh.h (vx_import_read_*),
 * sharing the gather and weld; OFF and PLY go to mesh/off.c and
 * mesh/ply.c from here.
 *
 * No file is read by a library that sizes its work from the file's claims
 * before checking them: vx_declared_check checks the declared counts and
 * bounds first, and the decode runs under a vx::AllocCap of
 * vx_declared_decode_bound. STL is parsed here. glTF and glb are parsed by
 * tinygltf (Debian's libtinygltf-dev, the implementation compiled into
 * this file with its file system and image decoding left out, so no
 * external buffer or image can be opened), and the scene is walked here
 * with every index and byte range checked again.
 *
 * assimp read these formats before; its importers leaked (STL), read past
 * their buffers (PLY), crashed (OFF) and, for glTF, overwrote heap blocks
 * on fuzzed files (fuzz_gltf), which the daemon could only contain by
 * importing in a forked child. */
/* <fstream> first: tinygltf 2.7's writers still name std::ofstream when
 * TINYGLTF_NO_FS leaves it out (they are never called here). */
#include <fstream>

#define TINYGLTF_IMPLEMENTATION
#define TINYGLTF_NO_FS
#define TINYGLTF_NO_STB_IMAGE
#define TINYGLTF_NO_STB_IMAGE_WRITE
#define TINYGLTF_NO_EXTERNAL_IMAGE
#include <tiny_gltf.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <strings.h>
#include <sys/stat.h>

#include "mesh/alloc_cap.h"

extern "C" {
#include "mesh/mesh.h"
#include "mesh/text.h"
#include "util/log.h"
}

namespace
{

struct FormatInfo {
    const char *name, *hint, *corrupt, *no_faces;
};

const FormatInfo *info(vx_mesh_format fmt)
{
    static const FormatInfo stl{"STL", "stl", "stl_corrupt", "stl_no_faces"};
    static const FormatInfo gltf{"glTF", "gltf", "gltf_corrupt", "gltf_no_faces"};
    static const FormatInfo glb{"glTF", "glb", "gltf_corrupt", "gltf_no_faces"};
    switch (fmt) {
    case VX_MESH_STL:
        return &stl;
    case VX_MESH_GLTF:
        return &gltf;
    case VX_MESH_GLB:
        return &glb;
    default:
        return nullptr;
    }
}

struct MeshDeleter {
    void operator()(vx_mesh *m) const { vx_mesh_free(m); }
};
using MeshPtr = std::unique_ptr<vx_mesh, MeshDeleter>;

/* What the node walk gathers: positions and polygons, all in one mesh. */
struct Gather {
    std::vector<double> pos;
    std::vector<uint32_t> idx, start;
    size_t ntris = 0;
    std::vector<char> sparse_ok; /* per glTF accessor: its sparse indices checked */
    const vx_mesh_limits *lim;
    const FormatInfo *fi;
    vx_err *err;
};

int too_big(Gather &g, const char *what, size_t n, size_t limit)
{
    return vx_err_set(g.err, VX_ETOOBIG, "mesh_too_big",
                      "the %s file has more than %zu %s (the "
                      "limit), at least %zu",
                      g.fi->name, limit, what, n);
}

/* Merges vertices with equal positions (a triangle soup's corners); a
 * coordinate -0 is written +0 first (the same place, and runs of equal
 * positions are found by their bits). */
void weld(Gather &g)
{
    for (double &x : g.pos)
        x += 0.0;
    size_t nv = g.pos.size() / 3;
    std::vector<uint32_t> order(nv), remap(nv);
    for (size_t i = 0; i < nv; i++)
        order[i] = uint32_t(i);
    const double *p = g.pos.data();
    std::sort(order.begin(), order.end(), [p](uint32_t a, uint32_t b) {
        const double *x = p + 3 * size_t(a), *y = p + 3 * size_t(b);
        if (x[0] != y[0]) return x[0] < y[0];
        if (x[1] != y[1]) return x[1] < y[1];
        if (x[2] != y[2]) return x[2] < y[2];
        return a < b;
    });
    /* Each run of equal positions maps to its lowest index. */
    std::vector<char> keep(nv, 0);
    for (size_t i = 0; i < nv;) {
        size_t j = i;
        while (j < nv &&
               !std::memcmp(p + 3 * size_t(order[i]), p + 3 * size_t(order[j]), 3 * sizeof(double)))
            j++;
        for (size_t k = i; k < j; k++)
            remap[order[k]] = order[i];
        keep[order[i]] = 1;
        i = j;
    }
    std::vector<uint32_t> newid(nv);
    size_t out = 0;
    for (size_t i = 0; i < nv; i++)
        if (keep[i]) {
            newid[i] = uint32_t(out);
            std::memmove(g.pos.data() + 3 * out, p + 3 * i, 3 * sizeof(double));
            out++;
        }
    g.pos.resize(3 * out);
    for (auto &v : g.idx)
        v = newid[remap[v]];
}

/* Moves what g gathered into a new vx_mesh (malloc'd arrays). */
vx_mesh *to_mesh(Gather &g)
{
    MeshPtr m(vx_mesh_new());
    if (!m) throw std::bad_alloc();
    size_t nv = g.pos.size() / 3, nf = g.start.size();
    bool all_tris = g.idx.size() == 3 * nf;
    m->pos = static_cast<double *>(std::malloc(g.pos.size() * sizeof(double) + 1));
    m->face_idx = static_cast<uint32_t *>(std::malloc(g.idx.size() * sizeof(uint32_t) + 1));
    if (!m->pos || !m->face_idx) throw std::bad_alloc();
    std::memcpy(m->pos, g.pos.data(), g.pos.size() * sizeof(double));
    std::memcpy(m->face_idx, g.idx.data(), g.idx.size() * sizeof(uint32_t));
    if (!all_tris) {
        m->face_start = static_cast<uint32_t *>(std::malloc((nf + 1) * sizeof(uint32_t)));
        if (!m->face_start) throw std::bad_alloc();
        std::memcpy(m->face_start, g.start.data(), nf * sizeof(uint32_t));
        m->face_start[nf] = uint32_t(g.idx.size());
    }
    m->nverts = nv;
    m->nfaces = nf;
    return m.release();
}

/* ---- STL, without assimp ---------------------------------------------
 * assimp 5.2's STL importer leaks the mesh and node it allocated (2.4 KB)
 * whenever it throws on a malformed ASCII file, so every bad upload grew
 * the daemon (and fuzz_stl ran a leak scan per input: 100 inputs/s). STL
 * is read here: binary (the 84-byte header, then 50 bytes a triangle: a
 * normal, three vertices, an attribute word; vx_declared_check holds the
 * count to the size, bytes after the last triangle being ignored) or ASCII (`solid` NAME, then per
 * facet `facet normal x y z` `outer loop` three `vertex x y z` `endloop` `endfacet`, ended by
 * `endsolid` (or the end of the file); several solids may follow each
 * other; keywords in any case, as exporters write them, after an optional
 * UTF-8 byte order mark). Normals are ignored, so they may be any three
 * tokens (MSVC's printf wrote NaN as -1.#IND00);
 * corners are welded by position (weld). */

/* A whitespace-separated token reader over the file. */
struct Tokens {
    /* The longest number token read: a double's shortest round trip takes
     * at most 24 characters, so a longer one is refused, not cut short. */
    static constexpr size_t max_number = 63;
    const char *p, *end;
    size_t line = 1;     /* of the last token read */
    size_t long_len = 0; /* a number token over max_number seen: its length */
    /* The next token into [*s, *s + *len); false at the end. */
    bool next(const char **s, size_t *len)
    {
        while (p < end && std::isspace(static_cast<unsigned char>(*p))) {
            if (*p == '\n') line++;
            p++;
        }
        if (p == end) return false;
        *s = p;
        while (p < end && !std::isspace(static_cast<unsigned char>(*p)))
            p++;
        *len = size_t(p - *s);
        return true;
    }
    /* Whether [s, s + len) is the keyword word, in any case. */
    static bool word_is(const char *s, size_t len, const char *word)
    {
        return len == std::strlen(word) && !strncasecmp(s, word, len);
    }
    bool is(const char *word)
    {
        const char *s;
        size_t len;
        return next(&s, &len) && word_is(s, len, word);
    }
    /* Skips one token; false at the end. */
    bool any()
    {
        const char *s;
        size_t len;
        return next(&s, &len);
    }
    /* The next token as a number; false at the end or when it is not one
     * (long_len set when it was too long to be read). */
    bool number(double *v)
    {
        const char *s;
        size_t len;
        char buf[max_number + 1];
        if (!next(&s, &len)) return false;
        if (len > max_number) {
            long_len = len;
            return false;
        }
        std::memcpy(buf, s, len);
        buf[len] = 0;
        char *e = vx_mesh_parse_double(buf, v); /* decimal, as OBJ's: no hex */
        return e && *e == 0;
    }
    void skip_line()
    {
        while (p < end && *p != '\n')
            p++;
    }
};

int stl_fail(Gather &g, const char *what, size_t line)
{
    return vx_err_set(g.err, VX_EINVAL, "stl_corrupt", "not a valid STL file: line %zu: %s", line,
                      what);
}

/* Adds one triangle's corners; checks them and the limits. */
int stl_triangle(Gather &g, const double c[9])
{
    for (int k = 0; k < 9; k++)
        if (!std::isfinite(c[k]))
            return vx_err_set(g.err, VX_EINVAL, "stl_corrupt",
                              "not a valid STL file: triangle %zu has a NaN or infinite "
                              "coordinate",
                              g.start.size());
    if (g.lim && g.lim->max_triangles && g.start.size() + 1 > g.lim->max_triangles)
        return too_big(g, "triangles", g.start.size() + 1, g.lim->max_triangles);
    uint32_t base = uint32_t(g.pos.size() / 3);
    g.pos.insert(g.pos.end(), c, c + 9);
    g.start.push_back(uint32_t(g.idx.size()));
    g.idx.insert(g.idx.end(), {base, base + 1, base + 2});
    return 0;
}

/* count: vx_declared_check's (the header's, held to the size; or the
 * size's, where the header says 0); bytes after the last triangle are not
 * read. */
int stl_binary(Gather &g, const unsigned char *data, uint64_t count)
{
    g.pos.reserve(9 * size_t(count));
    for (uint64_t t = 0; t < count; t++) {
        const unsigned char *q = data + 84 + 50 * size_t(t) + 12; /* past the normal */
        double c[9];
        for (int k = 0; k < 9; k++) {
            const unsigned char *b = q + 4 * k;
            uint32_t u =
                uint32_t(b[0]) | uint32_t(b[1]) << 8 | uint32_t(b[2]) << 16 | uint32_t(b[3]) << 24;
            float f;
            std::memcpy(&f, &u, 4);
            c[k] = f;
        }
        if (stl_triangle(g, c)) return -1;
    }
    return 0;
}

int stl_ascii(Gather &g, const unsigned char *data, size_t n)
{
    size_t bom = n >= 3 && !std::memcmp(data, "\xef\xbb\xbf", 3) ? 3 : 0;
    Tokens t{reinterpret_cast<const char *>(data) + bom, reinterpret_cast<const char *>(data) + n};
    const char *s;
    size_t len;
    bool any = false;
    while (t.next(&s, &len)) {
        if (!Tokens::word_is(s, len, "solid"))
            return stl_fail(g, any ? "text after endsolid that is not a solid" : "no \"solid\"",
                            t.line);
        any = true;
        t.skip_line(); /* the solid's name */
        for (;;) {
            if (!t.next(&s, &len)) return 0; /* a missing endsolid is forgiven */
            size_t at = t.line;
            if (Tokens::word_is(s, len, "endsolid")) {
                t.skip_line();
                break;
            }
            if (!Tokens::word_is(s, len, "facet"))
                return stl_fail(g, "expected facet or endsolid", at);
            double c[9];
            if (!t.is("normal") || !t.any() || !t.any() || !t.any() || !t.is("outer") ||
                !t.is("loop"))
                return stl_fail(g, "a facet without its normal and outer loop", at);
            for (int v = 0; v < 3; v++)
                if (!t.is("vertex") || !t.number(&c[3 * v]) || !t.number(&c[3 * v + 1]) ||
                    !t.number(&c[3 * v + 2])) {
                    if (!t.long_len)
                        return stl_fail(g, "a facet without three vertices of three numbers", at);
                    /* said as such, on the number's own line: "without three
                     * numbers" sent users looking for a missing one */
                    char what[96];
                    std::snprintf(what, sizeof what, "a number %zu characters long (at most %zu)",
                                  t.long_len, Tokens::max_number);
                    return stl_fail(g, what, t.line);
                }
            if (!t.is("endloop") || !t.is("endfacet"))
                return stl_fail(g, "a facet without endloop and endfacet after three vertices", at);
            if (stl_triangle(g, c)) return -1;
        }
    }
    return any ? 0 : stl_fail(g, "no \"solid\"", 1);
}

vx_mesh *read_stl(const unsigned char *data, size_t n, const FormatInfo *fi,
                  const vx_mesh_limits *lim, vx_err *err)
{
    vx_mesh_declared d;
    if (vx_declared_check(VX_MESH_STL, data, n, n, lim, &d, err)) return nullptr;
    Gather g;
    g.lim = lim;
    g.fi = fi;
    g.err = err;
    /* The declared check told the two apart: an exact binary size wins. */
    if (d.exact ? stl_binary(g, data, d.triangles) : stl_ascii(g, data, n)) return nullptr;
    if (g.start.empty()) {
        vx_err_set(err, VX_EUNPROC, fi->no_faces, "the %s file has no faces", fi->name);
        return nullptr;
    }
    weld(g);
    if (lim && lim->max_vertices && g.pos.size() / 3 > lim->max_vertices) {
        too_big(g, "vertices", g.pos.size() / 3, lim->max_vertices);
        return nullptr;
    }
    MeshPtr m(to_mesh(g));
    if (vx_mesh_analyze(m.get(), err)) return nullptr;
    return m.release();
}

/* ---- glTF 2.0 through tinygltf ----------------------------------------- */

/* Images carry nothing a mesh needs: accepted and not decoded. */
bool skip_image(tinygltf::Image *, const int, std::string *, std::string *, int, int,
                const unsigned char *, int, void *)
{
    return true;
}

int gl_corrupt(Gather &g, const char *what, int i)
{
    return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt, "not a valid %s file: %s %d is malformed",
                      g.fi->name, what, i);
}

/* Where element 0 of count elements of elem bytes at off in view starts,
 * and (*stride) the view's stride; NULL unless they fit the view and the
 * view its buffer. */
const unsigned char *span(const tinygltf::Model &mo, int view, size_t off, size_t count,
                          size_t elem, size_t *stride)
{
    if (view < 0 || size_t(view) >= mo.bufferViews.size() || !count) return nullptr;
    const tinygltf::BufferView &bv = mo.bufferViews[size_t(view)];
    if (bv.buffer < 0 || size_t(bv.buffer) >= mo.buffers.size()) return nullptr;
    const std::vector<unsigned char> &buf = mo.buffers[size_t(bv.buffer)].data;
    size_t st = bv.byteStride ? bv.byteStride : elem;
    if (st < elem || bv.byteOffset > buf.size() || bv.byteLength > buf.size() - bv.byteOffset)
        return nullptr;
    if (off > bv.byteLength || elem > bv.byteLength - off ||
        count - 1 > (bv.byteLength - off - elem) / st)
        return nullptr;
    *stride = st;
    return buf.data() + bv.byteOffset + off;
}

/* The component of the given type at p as a double (normalized integers
 * mapped as glTF says: unsigned to [0, 1], signed to [-1, 1]). */
double component(const unsigned char *p, int type, bool normalized)
{
    switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
        int8_t v;
        std::memcpy(&v, p, 1);
        return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return normalized ? *p / 255.0 : *p;
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
        int16_t v;
        std::memcpy(&v, p, 2);
        return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
        uint16_t v;
        std::memcpy(&v, p, 2);
        return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
        uint32_t v;
        std::memcpy(&v, p, 4);
        return normalized ? v / 4294967295.0 : v;
    }
    default: { /* FLOAT */
        float v;
        std::memcpy(&v, p, 4);
        return v;
    }
    }
}

size_t comp_bytes(int type)
{
    switch (type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
        return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT:
        return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT:
        return 4;
    default:
        return 0;
    }
}

/* Accessor ai's elements as doubles into out (ncomp a row), sparse
 * substitutions applied: unsigned integer scalars (index) or VEC3s of
 * float or KHR_mesh_quantization's (signed or unsigned) bytes and shorts
 * (positions); with pick, only elements pick[0..npick)
 * (sorted, each below the count: the vertices a primitive uses, as many
 * primitives may index a few of one shared accessor; decoding it whole
 * for each made a file of 10^5 primitives over 10^6 vertices take hours),
 * the sparse part found by binary search (its indices strictly increase,
 * checked once per accessor: g.sparse_ok). */
/* What an accessor is read as: indices (unsigned scalars), positions and
 * morph target deltas (VEC3), skin joints and weights (VEC4), inverse bind
 * matrices (float MAT4, column-major). */
enum class Want { index = 1, vec3 = 3, vec4 = 4, mat4 = 16 };

int read_accessor(Gather &g, const tinygltf::Model &mo, int ai, Want want, const uint32_t *pick,
                  size_t npick, std::vector<double> &out)
{
    const int ncomp = int(want);
    if (ai < 0 || size_t(ai) >= mo.accessors.size()) return gl_corrupt(g, "accessor", ai);
    const tinygltf::Accessor &a = mo.accessors[size_t(ai)];
    size_t cb = comp_bytes(a.componentType);
    const bool uint_type = a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE ||
                           a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ||
                           a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
    bool ok_type = false;
    switch (want) {
    case Want::index:
        ok_type = a.type == TINYGLTF_TYPE_SCALAR && uint_type;
        break;
    case Want::vec3:
        ok_type = a.type == TINYGLTF_TYPE_VEC3 && cb &&
                  a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
        break;
    case Want::vec4:
        ok_type = a.type == TINYGLTF_TYPE_VEC4 && cb &&
                  a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT;
        break;
    case Want::mat4:
        ok_type = a.type == TINYGLTF_TYPE_MAT4 && a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT;
        break;
    }
    if (!ok_type || !a.count) return gl_corrupt(g, "accessor", ai);
    size_t elem = cb * size_t(ncomp), stride = 0, n = pick ? npick : a.count;
    /* no bufferView: zeros, then the sparse values (declared.c) */
    const unsigned char *p =
        a.bufferView < 0 ? nullptr : span(mo, a.bufferView, a.byteOffset, a.count, elem, &stride);
    if (!p && a.bufferView >= 0) return gl_corrupt(g, "accessor", ai);
    auto put = [&](size_t row, const unsigned char *q) {
        for (int c = 0; c < ncomp; c++)
            out[row * size_t(ncomp) + size_t(c)] =
                component(q + size_t(c) * cb, a.componentType, a.normalized);
    };
    out.assign(n * size_t(ncomp), 0.0);
    for (size_t r = 0; p && r < n; r++)
        put(r, p + (pick ? size_t(pick[r]) : r) * stride);
    if (!a.sparse.isSparse) return 0;
    const auto &sp = a.sparse;
    size_t icb = comp_bytes(sp.indices.componentType), ist = 0, vst = 0;
    if (sp.count < 1 || size_t(sp.count) > a.count || !icb || sp.indices.byteOffset < 0 ||
        sp.values.byteOffset < 0 || sp.indices.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT ||
        sp.indices.componentType == TINYGLTF_COMPONENT_TYPE_BYTE ||
        sp.indices.componentType == TINYGLTF_COMPONENT_TYPE_SHORT)
        return gl_corrupt(g, "sparse accessor", ai);
    const unsigned char *ip =
        span(mo, sp.indices.bufferView, size_t(sp.indices.byteOffset), size_t(sp.count), icb, &ist);
    const unsigned char *vp =
        span(mo, sp.values.bufferView, size_t(sp.values.byteOffset), size_t(sp.count), elem, &vst);
    if (!ip || !vp) return gl_corrupt(g, "sparse accessor", ai);
    /* Sparse parts are tightly packed, whatever the view's stride says. */
    const size_t ns = size_t(sp.count);
    auto at = [&](size_t k) { return component(ip + k * icb, sp.indices.componentType, false); };
    if (g.sparse_ok.size() < mo.accessors.size()) g.sparse_ok.resize(mo.accessors.size());
    if (!g.sparse_ok[size_t(ai)]) {
        for (size_t k = 0; k < ns; k++)
            if (!(at(k) < double(a.count)) || (k && !(at(k) > at(k - 1))))
                return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                                  "not a valid %s file: sparse accessor %d's indices are not "
                                  "strictly increasing below its count",
                                  g.fi->name, ai);
        g.sparse_ok[size_t(ai)] = 1;
    }
    if (!pick) {
        for (size_t k = 0; k < ns; k++)
            put(size_t(at(k)), vp + k * elem);
        return 0;
    }
    for (size_t r = 0; r < n; r++) {
        size_t lo = 0, hi = ns; /* the first sparse index >= pick[r] */
        while (lo < hi) {
            size_t mid = lo + (hi - lo) / 2;
            if (at(mid) < double(pick[r]))
                lo = mid + 1;
            else
                hi = mid;
        }
        if (lo < ns && at(lo) == double(pick[r])) put(r, vp + lo * elem);
    }
    return 0;
}

/* A 4x4 column-major transform. */
struct Mat {
    double m[16];
    static Mat identity()
    {
        Mat r{};
        r.m[0] = r.m[5] = r.m[10] = r.m[15] = 1;
        return r;
    }
    Mat operator*(const Mat &b) const
    {
        Mat r{};
        for (int c = 0; c < 4; c++)
            for (int row = 0; row < 4; row++)
                for (int k = 0; k < 4; k++)
                    r.m[4 * c + row] += m[4 * k + row] * b.m[4 * c + k];
        return r;
    }
    double det3() const
    {
        return m[0] * (m[5] * m[10] - m[9] * m[6]) - m[4] * (m[1] * m[10] - m[9] * m[2]) +
               m[8] * (m[1] * m[6] - m[5] * m[2]);
    }
};

/* A node's local transform: its matrix, or T * R * S. */
Mat local(const tinygltf::Node &n)
{
    Mat t = Mat::identity();
    if (n.matrix.size() == 16) {
        std::copy(n.matrix.begin(), n.matrix.end(), t.m);
        return t;
    }
    Mat r = Mat::identity(), s = Mat::identity();
    if (n.translation.size() == 3)
        for (int i = 0; i < 3; i++)
            t.m[12 + i] = n.translation[size_t(i)];
    if (n.rotation.size() == 4) {
        double x = n.rotation[0], y = n.rotation[1], z = n.rotation[2], w = n.rotation[3];
        double len = std::sqrt(x * x + y * y + z * z + w * w);
        if (len > 0) x /= len, y /= len, z /= len, w /= len;
        double q[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),
                       2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                       2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y)};
        for (int c = 0; c < 3; c++)
            for (int row = 0; row < 3; row++)
                r.m[4 * c + row] = q[3 * c + row];
    }
    if (n.scale.size() == 3)
        for (int i = 0; i < 3; i++)
            s.m[5 * i] = n.scale[size_t(i)];
    return t * r * s;
}

/* The per-vertex skinning matrices of the nu vertices pick (or the first
 * nu) of primitive pr: sum over JOINTS_n/WEIGHTS_n of weight * joints[j]
 * (a joint's world transform times its inverse bind matrix), the weights
 * normalised to sum 1; a vertex of no weight keeps its position. */
int skin_matrices(Gather &g, const tinygltf::Model &mo, const tinygltf::Primitive &pr, int mi,
                  const std::vector<Mat> &joints, const uint32_t *pick, size_t nu,
                  std::vector<Mat> &out)
{
    out.assign(nu, Mat{});
    std::vector<double> wsum(nu, 0.0), jv, wv;
    for (int set = 0;; set++) {
        auto ja = pr.attributes.find("JOINTS_" + std::to_string(set));
        auto wa = pr.attributes.find("WEIGHTS_" + std::to_string(set));
        if (ja == pr.attributes.end() || wa == pr.attributes.end()) break;
        /* one joint set a vertex (the picks index POSITION's elements) */
        for (int a : {ja->second, wa->second})
            if (a < 0 || size_t(a) >= mo.accessors.size() ||
                mo.accessors[size_t(a)].count !=
                    mo.accessors[size_t(pr.attributes.at("POSITION"))].count)
                return gl_corrupt(g, "skin accessor (not one element a vertex)", a);
        if (read_accessor(g, mo, ja->second, Want::vec4, pick, nu, jv) ||
            read_accessor(g, mo, wa->second, Want::vec4, pick, nu, wv))
            return -1;
        for (size_t u = 0; u < nu; u++)
            for (int k = 0; k < 4; k++) {
                double w = wv[4 * u + size_t(k)], j = jv[4 * u + size_t(k)];
                if (w == 0) continue;
                if (!(w > 0) || !(j >= 0 && j < double(joints.size())) || j != std::floor(j))
                    return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                                      "not a valid %s file: mesh %d names joint %.0f with weight "
                                      "%g (its skin has %zu joints)",
                                      g.fi->name, mi, j, w, joints.size());
                const Mat &m = joints[size_t(j)];
                for (int e = 0; e < 16; e++)
                    out[u].m[e] += w * m.m[e];
                wsum[u] += w;
            }
    }
    for (size_t u = 0; u < nu; u++) {
        if (wsum[u] > 0)
            for (double &e : out[u].m)
                e /= wsum[u];
        else
            out[u] = Mat::identity();
    }
    return 0;
}

/* One primitive, its positions through t (with joints, a skin's matrices
 * per joint: through each vertex's blend of them instead), its morph
 * targets' POSITION deltas added first with weights (the node's or the
 * mesh's default weights); triangles, strips and fans become triangles
 * (winding reversed where the transform mirrors), points and lines are
 * skipped. */
int add_primitive(Gather &g, const tinygltf::Model &mo, const tinygltf::Primitive &pr, const Mat &t,
                  int mi, const std::vector<double> *weights = nullptr,
                  const std::vector<Mat> *joints = nullptr)
{
    int mode = pr.mode < 0 ? TINYGLTF_MODE_TRIANGLES : pr.mode;
    if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
        mode != TINYGLTF_MODE_TRIANGLE_FAN)
        return 0;
    auto at = pr.attributes.find("POSITION");
    if (at == pr.attributes.end()) return gl_corrupt(g, "mesh (a primitive without POSITION)", mi);
    if (at->second < 0 || size_t(at->second) >= mo.accessors.size())
        return gl_corrupt(g, "accessor", at->second);
    std::vector<double> pos, ix;
    size_t nv = mo.accessors[size_t(at->second)].count, base = g.pos.size() / 3;
    if (nv > UINT32_MAX) return too_big(g, "vertices", nv, UINT32_MAX);
    if (pr.indices >= 0) {
        if (read_accessor(g, mo, pr.indices, Want::index, nullptr, 0, ix)) return -1;
    } else {
        ix.resize(nv);
        for (size_t v = 0; v < nv; v++)
            ix[v] = double(v);
    }
    for (double i : ix)
        if (!(i >= 0 && i < double(nv)))
            return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                              "not a valid %s file: mesh %d uses vertex %.0f of %zu", g.fi->name,
                              mi, i, nv);
    // The vertices the primitive uses, each once, in accessor order, and
    // only they are decoded: many primitives may each index a few vertices
    // of one shared accessor.
    std::vector<uint32_t> used;
    if (pr.indices >= 0) {
        used.reserve(ix.size());
        for (double i : ix)
            used.push_back(uint32_t(i));
        std::sort(used.begin(), used.end());
        used.erase(std::unique(used.begin(), used.end()), used.end());
        for (double &i : ix)
            i = double(std::lower_bound(used.begin(), used.end(), uint32_t(i)) - used.begin());
    }
    const size_t nu = pr.indices >= 0 ? used.size() : nv;
    if (read_accessor(g, mo, at->second, Want::vec3, pr.indices >= 0 ? used.data() : nullptr, nu,
                      pos))
        return -1;
    if (base + nu > UINT32_MAX) return too_big(g, "vertices", base + nu, UINT32_MAX);
    if (g.lim && g.lim->max_vertices && base + nu > g.lim->max_vertices)
        return too_big(g, "vertices", base + nu, g.lim->max_vertices);
    const uint32_t *pick = pr.indices >= 0 ? used.data() : nullptr;
    for (size_t k = 0; weights && k < pr.targets.size() && k < weights->size(); k++) {
        const double w = (*weights)[k];
        auto tp = pr.targets[k].find("POSITION");
        if (w == 0 || tp == pr.targets[k].end()) continue;
        if (tp->second < 0 || size_t(tp->second) >= mo.accessors.size() ||
            mo.accessors[size_t(tp->second)].count != nv)
            return gl_corrupt(g, "morph target accessor", tp->second);
        std::vector<double> d;
        if (read_accessor(g, mo, tp->second, Want::vec3, pick, nu, d)) return -1;
        for (size_t i = 0; i < 3 * nu; i++)
            pos[i] += w * d[i];
    }
    std::vector<Mat> vm;
    if (joints && skin_matrices(g, mo, pr, mi, *joints, pick, nu, vm)) return -1;
    for (size_t u = 0; u < nu; u++) {
        const double *p = &pos[3 * u];
        const Mat &tv = joints ? vm[u] : t;
        double q[3];
        for (int r = 0; r < 3; r++)
            q[r] = tv.m[r] * p[0] + tv.m[4 + r] * p[1] + tv.m[8 + r] * p[2] + tv.m[12 + r];
        if (!std::isfinite(q[0]) || !std::isfinite(q[1]) || !std::isfinite(q[2]))
            return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                              "not a valid %s file: a vertex of mesh %d has a NaN or infinite "
                              "coordinate",
                              g.fi->name, mi);
        g.pos.insert(g.pos.end(), {q[0], q[1], q[2]});
    }
    const bool flip_all = t.det3() < 0;
    size_t ntri = mode == TINYGLTF_MODE_TRIANGLES ? ix.size() / 3
                  : ix.size() >= 3                ? ix.size() - 2
                                                  : 0;
    for (size_t k = 0; k < ntri; k++) {
        size_t c[3];
        if (mode == TINYGLTF_MODE_TRIANGLES)
            c[0] = 3 * k, c[1] = 3 * k + 1, c[2] = 3 * k + 2;
        else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP)
            c[0] = k, c[1] = k + 1 + k % 2, c[2] = k + 2 - k % 2;
        else
            c[0] = k + 1, c[1] = k + 2, c[2] = 0;
        /* skinned: each vertex has its own transform; the triangle turns
         * where most of its corners' transforms mirror */
        bool flip = flip_all;
        if (joints)
            flip = (vm[size_t(ix[c[0]])].det3() < 0) + (vm[size_t(ix[c[1]])].det3() < 0) +
                       (vm[size_t(ix[c[2]])].det3() < 0) >=
                   2;
        if (flip) std::swap(c[1], c[2]);
        g.start.push_back(uint32_t(g.idx.size()));
        for (size_t j : c)
            g.idx.push_back(uint32_t(base + size_t(ix[j])));
        g.ntris++;
        if (g.lim && g.lim->max_triangles && g.ntris > g.lim->max_triangles)
            return too_big(g, "triangles", g.ntris, g.lim->max_triangles);
        if (g.idx.size() > UINT32_MAX / 2) return too_big(g, "face corners", g.idx.size(), 0);
    }
    return 0;
}

/* Node ni's world transform: its ancestors' local transforms and its own
 * (parent: each node's parent or -1; the graph was checked acyclic). */
Mat world_of(const tinygltf::Model &mo, const std::vector<int> &parent, int ni)
{
    Mat t = Mat::identity();
    for (int k = 0; ni >= 0 && k <= 256; k++, ni = parent[size_t(ni)])
        t = local(mo.nodes[size_t(ni)]) * t;
    return t;
}

/* Each skin's joint matrices, made once per model (many nodes may use one
 * skin: made per node, a file of n nodes on an n-joint skin took n^2). */
struct Skins {
    std::vector<int> parent; /* each node's parent, or -1; made at the first skin */
    std::vector<std::vector<Mat>> joints;
};

/* Skin si's joint matrices: each joint's world transform times its
 * inverse bind matrix (identity without them); kept in sc. */
int skin_joints(Gather &g, const tinygltf::Model &mo, int si, Skins &sc,
                const std::vector<Mat> **res)
{
    if (si < 0 || size_t(si) >= mo.skins.size()) return gl_corrupt(g, "skin", si);
    if (sc.joints.size() < mo.skins.size()) sc.joints.resize(mo.skins.size());
    std::vector<Mat> &out = sc.joints[size_t(si)];
    *res = &out;
    if (!out.empty()) return 0;
    const tinygltf::Skin &sk = mo.skins[size_t(si)];
    if (sk.joints.empty()) return gl_corrupt(g, "skin (no joints)", si);
    if (sc.parent.empty()) {
        sc.parent.assign(mo.nodes.size(), -1);
        for (size_t i = 0; i < mo.nodes.size(); i++)
            for (int c : mo.nodes[i].children)
                if (c >= 0 && size_t(c) < sc.parent.size()) sc.parent[size_t(c)] = int(i);
    }
    const std::vector<int> &parent = sc.parent;
    std::vector<double> ibm;
    if (sk.inverseBindMatrices >= 0) {
        /* a matrix a joint, the first ones only: an accessor of zeros
         * (no bufferView) has nothing that bounds its count */
        const int ia = sk.inverseBindMatrices;
        if (size_t(ia) >= mo.accessors.size()) return gl_corrupt(g, "accessor", ia);
        if (mo.accessors[size_t(ia)].count < sk.joints.size())
            return gl_corrupt(g, "skin (fewer inverse bind matrices than joints)", si);
        std::vector<uint32_t> first(sk.joints.size());
        for (size_t k = 0; k < first.size(); k++)
            first[k] = uint32_t(k);
        if (read_accessor(g, mo, ia, Want::mat4, first.data(), first.size(), ibm)) return -1;
    }
    out.resize(sk.joints.size());
    for (size_t k = 0; k < sk.joints.size(); k++) {
        int j = sk.joints[k];
        if (j < 0 || size_t(j) >= mo.nodes.size()) return gl_corrupt(g, "skin (a joint)", si);
        Mat b = Mat::identity();
        if (!ibm.empty()) std::copy(&ibm[16 * k], &ibm[16 * k] + 16, b.m);
        out[k] = world_of(mo, parent, j) * b;
    }
    return 0;
}

int walk(Gather &g, const tinygltf::Model &mo, int ni, const Mat &parent, int depth,
         std::vector<char> &seen, Skins &sc)
{
    if (ni < 0 || size_t(ni) >= mo.nodes.size() || seen[size_t(ni)] || depth > 256)
        return gl_corrupt(g, "node", ni);
    seen[size_t(ni)] = 1;
    const tinygltf::Node &n = mo.nodes[size_t(ni)];
    Mat t = parent * local(n);
    if (n.mesh >= 0) {
        if (size_t(n.mesh) >= mo.meshes.size()) return gl_corrupt(g, "node", ni);
        const tinygltf::Mesh &me = mo.meshes[size_t(n.mesh)];
        /* morph weights: the node's, else the mesh's defaults */
        const std::vector<double> *w = !n.weights.empty() ? &n.weights : &me.weights;
        /* a skinned mesh is placed by its joints alone: the node's own
         * transform is ignored (glTF 2.0, Skins) */
        const std::vector<Mat> *joints = nullptr;
        if (n.skin >= 0 && skin_joints(g, mo, n.skin, sc, &joints)) return -1;
        for (const auto &pr : me.primitives)
            if (add_primitive(g, mo, pr, t, n.mesh, w, joints)) return -1;
    }
    for (int c : n.children)
        if (walk(g, mo, c, t, depth + 1, seen, sc)) return -1;
    return 0;
}

/* A file without scenes (the spec allows one, "a library"): every root
 * node (one no node names as a child) as the scene's nodes would be, and,
 * with no nodes at all, every mesh as it is. */
int walk_library(Gather &g, const tinygltf::Model &mo)
{
    std::vector<char> child(mo.nodes.size(), 0), seen(mo.nodes.size(), 0);
    Skins sc;
    for (const auto &n : mo.nodes)
        for (int c : n.children)
            if (c >= 0 && size_t(c) < child.size()) child[size_t(c)] = 1;
    for (size_t i = 0; i < mo.nodes.size(); i++)
        if (!child[i] && walk(g, mo, int(i), Mat::identity(), 0, seen, sc)) return -1;
    if (mo.nodes.empty())
        for (size_t mi = 0; mi < mo.meshes.size(); mi++)
            for (const auto &pr : mo.meshes[mi].primitives)
                if (add_primitive(g, mo, pr, Mat::identity(), int(mi), &mo.meshes[mi].weights))
                    return -1;
    return 0;
}

/* A tinygltf message as ASCII without controls and on one line, so that it
 * can go into a JSON answer whatever bytes the file put into it. */
void ascii_only(const std::string &in, char *out, size_t n)
{
    size_t o = 0;
    for (size_t i = 0; i < in.size() && o + 1 < n; i++)
        out[o++] = in[i] >= 0x20 && in[i] < 0x7f ? in[i] : ' ';
    while (o && out[o - 1] == ' ')
        o--;
    out[o] = 0;
}

vx_mesh *read_gltf(const unsigned char *data, size_t n, const FormatInfo *fi, vx_mesh_format fmt,
                   const vx_mesh_limits *lim, vx_err *err)
{
    vx_mesh_declared d;
    if (vx_declared_check(fmt, data, n, n, lim, &d, err)) return nullptr;
    if (n > UINT32_MAX) { /* tinygltf takes a 32-bit length; glb's own limit */
        vx_err_set(err, VX_EINVAL, fi->corrupt, "not a valid %s file: over 4 GiB", fi->name);
        return nullptr;
    }
    Gather g;
    g.lim = lim;
    g.fi = fi;
    g.err = err;
    char why[160] = "";
    int rc = -1;
    {
        vx::AllocCap cap(vx_declared_decode_bound(fmt, n, &d));
        try {
            tinygltf::TinyGLTF loader;
            loader.SetImageLoader(skip_image, nullptr);
            tinygltf::Model mo;
            std::string e, w;
            bool ok = fmt == VX_MESH_GLB
                          ? loader.LoadBinaryFromMemory(&mo, &e, &w, data, unsigned(n))
                          : loader.LoadASCIIFromString(
                                &mo, &e, &w, reinterpret_cast<const char *>(data), unsigned(n), "");
            if (!ok) {
                ascii_only(e.empty() ? std::string("tinygltf could not load it") : e, why,
                           sizeof why);
            } else {
                /* "scene" absent reads as -1 (then the first scene, or
                 * with none the library); one that names no scene is a
                 * broken reference, as a node's would be */
                int si = mo.defaultScene >= 0 ? mo.defaultScene : 0;
                if (mo.defaultScene < -1 ||
                    (mo.defaultScene >= 0 && size_t(mo.defaultScene) >= mo.scenes.size())) {
                    snprintf(why, sizeof why, "scene %d does not exist (the file has %zu)",
                             mo.defaultScene, mo.scenes.size());
                } else if (mo.scenes.empty()) {
                    rc = walk_library(g, mo);
                } else {
                    std::vector<char> seen(mo.nodes.size(), 0);
                    Skins sc;
                    rc = 0;
                    for (int r : mo.scenes[size_t(si)].nodes)
                        if ((rc = walk(g, mo, r, Mat::identity(), 0, seen, sc))) break;
                }
            }
        } catch (const std::bad_alloc &) {
            if (!cap.tripped()) throw;
        }
        if (cap.tripped()) {
            vx_err_set(err, VX_EINVAL, fi->corrupt,
                       "not a valid %s file: decoding it would take more than %llu bytes of "
                       "memory for %llu declared faces",
                       fi->name, (unsigned long long)cap.limit(), (unsigned long long)d.faces);
            return nullptr;
        }
        VX_DEBUG("mesh.gltf_peak", "format=%s bytes=%zu peak=%llu", fi->hint, n,
                 (unsigned long long)cap.peak());
    }
    if (why[0]) {
        vx_err_set(err, VX_EINVAL, fi->corrupt, "not a valid %s file: %s", fi->name, why);
        return nullptr;
    }
    if (rc) return nullptr; /* err set by the walk */
    if (g.start.empty()) {
        vx_err_set(err, VX_EUNPROC, fi->no_faces, "the %s file has no faces", fi->name);
        return nullptr;
    }
    weld(g);
    MeshPtr m(to_mesh(g));
    if (vx_mesh_analyze(m.get(), err)) return nullptr;
    return m.release();
}

} // namespace

extern "C" vx_mesh *vx_import_read_mem(const unsigned char *data, size_t n, vx_mesh_format fmt,
                                       const vx_mesh_limits *lim, vx_err *err)
{
    if (fmt == VX_MESH_OFF) return vx_off_read_mem(data, n, lim, err);
    if (fmt == VX_MESH_PLY) return vx_ply_read_mem(data, n, lim, err);
    const FormatInfo *fi = info(fmt);
    if (!fi) {
        vx_err_set(err, VX_EINTERNAL, "mesh_format", "format %d is not read here", int(fmt));
        return nullptr;
    }
    try {
        if (fmt == VX_MESH_STL) return read_stl(data, n, fi, lim, err);
        return read_gltf(data, n, fi, fmt, lim, err);
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to read the %s file", fi->name);
    } catch (...) {
        vx_err_set(err, VX_EINVAL, fi->corrupt, "not a valid %s file: the reader failed", fi->name);
    }
    return nullptr;
}

extern "C" vx_mesh *vx_import_read_path(const char *path, vx_mesh_format fmt,
                                        const vx_mesh_limits *lim, vx_err *err)
{
    FILE *f = vx_mesh_open(path, err);
    if (!f) return nullptr;
    struct stat st;
    if (fstat(fileno(f), &st) || !S_ISREG(st.st_mode) || st.st_size < 0) {
        std::fclose(f);
        vx_err_set(err, VX_EIO, "mesh_io", "cannot read %s: not a regular file", path);
        return nullptr;
    }
    size_t n = size_t(st.st_size);
    unsigned char *data = static_cast<unsigned char *>(std::malloc(n + 1));
    if (!data) {
        std::fclose(f);
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for a %zu-byte file", n);
        return nullptr;
    }
    size_t got = std::fread(data, 1, n, f);
    int e = std::ferror(f) ? errno : 0;
    std::fclose(f);
    vx_mesh *m = nullptr;
    if (got != n)
        vx_err_set(err, VX_EIO, "mesh_io", "cannot read %s: %s", path,
                   e ? std::strerror(e) : "short read");
    else
        m = vx_import_read_mem(data, n, fmt, lim, err);
    std::free(data);
    return m;
}
