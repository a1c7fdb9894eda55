/* STL and glTF 2.0 readers behind the C API of mesh.h (vx_assimp_read_*):
 * glTF through assimp, STL read here sharing the gather and weld (assimp's
 * STL importer leaked on malformed files); OFF and PLY go to mesh/off.c
 * and mesh/ply.c from here (assimp's importers for them crashed on fuzzed
 * files).
 *
 * libdraco 1.5.5 (Debian 12) has STL, PLY and glTF decoders, but its STL
 * decoder reads binary files only (and refuses the many binary files whose
 * header starts with "solid "), its PLY reader copies past the end of the
 * buffer for truncated binary data and has no big-endian, and its glTF
 * decoder reads .gltf only from a path, opening external URIs itself. So
 * assimp reads these, from memory, with an I/O system that opens nothing
 * (no external buffer or image can be read), after vx_declared_check has
 * checked the declared counts, and under a vx::AllocCap of
 * vx_declared_decode_bound; in a child process (util/child.h), because
 * assimp 5.2's glTF importer wrote past its heap blocks on fuzzed files
 * (fuzz_gltf, after 5 x 10^5 runs: an allocator chunk header overwritten
 * inside libassimp), which in the daemon would corrupt every thread's
 * heap. The child hands the mesh back through a memfd. */
#include <algorithm>
#include <cerrno>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <assimp/IOStream.hpp>
#include <assimp/IOSystem.hpp>
#include <assimp/Importer.hpp>
#include <assimp/scene.h>

#include "mesh/alloc_cap.h"

extern "C" {
#include "mesh/mesh.h"
#include "util/child.h"
#include "util/fsutil.h"
#include "util/log.h"
}

namespace
{

/* Opens nothing: assimp reads the file from memory (its own MemoryIOSystem
 * serves that name) and any other name it asks for is refused. */
class NoFiles : public Assimp::IOSystem
{
  public:
    bool Exists(const char *) const override { return false; }
    char getOsSeparator() const override { return '/'; }
    Assimp::IOStream *Open(const char *, const char *) override { return nullptr; }
    void Close(Assimp::IOStream *s) override { delete s; }
};

struct FormatInfo {
    const char *name, *hint, *corrupt, *no_faces;
    bool weld;
};

const FormatInfo *info(vx_mesh_format fmt)
{
    static const FormatInfo stl{"STL", "stl", "stl_corrupt", "stl_no_faces", true};
    static const FormatInfo gltf{"glTF", "gltf", "gltf_corrupt", "gltf_no_faces", true};
    static const FormatInfo glb{"glTF", "glb", "gltf_corrupt", "gltf_no_faces", true};
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

int add_mesh(Gather &g, const aiMesh *am, const aiMatrix4x4 &t)
{
    size_t base = g.pos.size() / 3;
    if (base + am->mNumVertices > UINT32_MAX)
        return too_big(g, "vertices", base + am->mNumVertices, UINT32_MAX);
    if (g.lim && g.lim->max_vertices && base + am->mNumVertices > g.lim->max_vertices)
        return too_big(g, "vertices", base + am->mNumVertices, g.lim->max_vertices);
    for (unsigned v = 0; v < am->mNumVertices; v++) {
        aiVector3D p = t * am->mVertices[v];
        if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
            return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                              "not a valid %s file: vertex %u has a NaN or infinite coordinate",
                              g.fi->name, v);
        g.pos.insert(g.pos.end(), {double(p.x), double(p.y), double(p.z)});
    }
    for (unsigned f = 0; f < am->mNumFaces; f++) {
        const aiFace &face = am->mFaces[f];
        if (face.mNumIndices < 3) continue; /* points and lines */
        g.start.push_back(uint32_t(g.idx.size()));
        for (unsigned k = 0; k < face.mNumIndices; k++) {
            if (face.mIndices[k] >= am->mNumVertices)
                return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                                  "not a valid %s file: face %u uses vertex %u of %u", g.fi->name,
                                  f, face.mIndices[k], am->mNumVertices);
            g.idx.push_back(uint32_t(base + face.mIndices[k]));
        }
        g.ntris += face.mNumIndices - 2;
        if (g.lim && g.lim->max_triangles && g.ntris > g.lim->max_triangles)
            return too_big(g, "triangles", g.ntris, g.lim->max_triangles);
        if (g.idx.size() > UINT32_MAX / 2) return too_big(g, "face corners", g.idx.size(), 0);
    }
    return 0;
}

int walk(Gather &g, const aiScene *sc, const aiNode *n, const aiMatrix4x4 &parent, int depth)
{
    if (depth > 256)
        return vx_err_set(g.err, VX_EINVAL, g.fi->corrupt,
                          "not a valid %s file: nodes nested too deep", g.fi->name);
    aiMatrix4x4 t = parent * n->mTransformation;
    for (unsigned i = 0; i < n->mNumMeshes; i++)
        if (n->mMeshes[i] < sc->mNumMeshes && add_mesh(g, sc->mMeshes[n->mMeshes[i]], t)) return -1;
    for (unsigned i = 0; i < n->mNumChildren; i++)
        if (walk(g, sc, n->mChildren[i], t, depth + 1)) return -1;
    return 0;
}

/* Merges vertices with equal positions (a triangle soup's corners). */
void weld(Gather &g)
{
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
 * count to the size) or ASCII (`solid` NAME, then per facet `facet normal
 * x y z` `outer loop` three `vertex x y z` `endloop` `endfacet`, ended by
 * `endsolid` (or the end of the file); several solids may follow each
 * other). Normals are ignored;
 * corners are welded by position (weld). */

/* A whitespace-separated token reader over the file. */
struct Tokens {
    const char *p, *end;
    size_t line = 1; /* of the last token read */
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
    bool is(const char *word)
    {
        const char *s;
        size_t len;
        return next(&s, &len) && len == std::strlen(word) && !std::memcmp(s, word, len);
    }
    bool number(double *v)
    {
        const char *s;
        size_t len;
        char buf[64];
        if (!next(&s, &len) || len >= sizeof buf) return false;
        std::memcpy(buf, s, len);
        buf[len] = 0;
        char *e;
        *v = std::strtod(buf, &e);
        return *e == 0;
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

/* vx_declared_check held 84 + 50 * count to the size (d.exact). */
int stl_binary(Gather &g, const unsigned char *data)
{
    uint32_t count = uint32_t(data[80]) | uint32_t(data[81]) << 8 | uint32_t(data[82]) << 16 |
                     uint32_t(data[83]) << 24;
    g.pos.reserve(9 * size_t(count));
    for (uint32_t t = 0; t < count; t++) {
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
    Tokens t{reinterpret_cast<const char *>(data), reinterpret_cast<const char *>(data) + n};
    const char *s;
    size_t len;
    bool any = false;
    while (t.next(&s, &len)) {
        if (!(len == 5 && !std::memcmp(s, "solid", 5)))
            return stl_fail(g, any ? "text after endsolid that is not a solid" : "no \"solid\"",
                            t.line);
        any = true;
        t.skip_line(); /* the solid's name */
        for (;;) {
            if (!t.next(&s, &len)) return 0; /* a missing endsolid is forgiven */
            size_t at = t.line;
            if (len == 8 && !std::memcmp(s, "endsolid", 8)) {
                t.skip_line();
                break;
            }
            if (!(len == 5 && !std::memcmp(s, "facet", 5)))
                return stl_fail(g, "expected facet or endsolid", at);
            double nrm[3], c[9];
            if (!t.is("normal") || !t.number(&nrm[0]) || !t.number(&nrm[1]) || !t.number(&nrm[2]) ||
                !t.is("outer") || !t.is("loop"))
                return stl_fail(g, "a facet without its normal and outer loop", at);
            for (int v = 0; v < 3; v++)
                if (!t.is("vertex") || !t.number(&c[3 * v]) || !t.number(&c[3 * v + 1]) ||
                    !t.number(&c[3 * v + 2]))
                    return stl_fail(g, "a facet without three vertices of three numbers", at);
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
    if (d.exact ? stl_binary(g, data) : stl_ascii(g, data, n)) return nullptr;
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

/* An assimp message as ASCII without controls, so that it can go into a
 * JSON answer whatever bytes the file put into it. */
void ascii_only(const char *in, char *out, size_t n)
{
    size_t o = 0;
    for (; in && *in && o + 1 < n; in++)
        out[o++] = *in >= 0x20 && *in < 0x7f ? *in : '?';
    out[o] = 0;
}

/* quiet: no logging (a forked child must not take the log's lock). */
vx_mesh *import(const unsigned char *data, size_t n, const FormatInfo *fi, vx_mesh_format fmt,
                const vx_mesh_limits *lim, int quiet, vx_err *err)
{
    vx_mesh_declared d;
    if (vx_declared_check(fmt, data, n, n, lim, &d, err)) return nullptr;
    Assimp::Importer imp;
    imp.SetIOHandler(new NoFiles);
    Gather g;
    g.lim = lim;
    g.fi = fi;
    g.err = err;
    int rc = -1;
    char why[120] = "";
    uint64_t peak = 0;
    {
        vx::AllocCap cap(vx_declared_decode_bound(fmt, n, &d));
        try {
            const aiScene *sc = imp.ReadFileFromMemory(data, n, 0, fi->hint);
            if (sc && sc->mRootNode)
                rc = walk(g, sc, sc->mRootNode, aiMatrix4x4(), 0);
            else
                ascii_only(imp.GetErrorString(), why, sizeof why);
            /* assimp may fail without saying why (found by fuzz_gltf). */
            if ((!sc || !sc->mRootNode) && !why[0])
                std::snprintf(why, sizeof why, "assimp made no scene of it");
        } catch (const std::bad_alloc &) {
            if (!cap.tripped()) throw;
        }
        peak = cap.peak();
        if (cap.tripped()) {
            imp.FreeScene();
            vx_err_set(err, VX_EINVAL, fi->corrupt,
                       "not a valid %s file: decoding it would take more than %llu bytes of "
                       "memory for %llu declared faces",
                       fi->name, (unsigned long long)cap.limit(), (unsigned long long)d.faces);
            return nullptr;
        }
        imp.FreeScene();
    }
    if (!quiet)
        VX_DEBUG("mesh.assimp_peak", "format=%s bytes=%zu peak=%llu", fi->hint, n,
                 (unsigned long long)peak);
    if (rc && !why[0]) return nullptr; /* err set by the walk */
    if (why[0]) {
        vx_err_set(err, VX_EINVAL, fi->corrupt, "not a valid %s file: %s", fi->name, why);
        return nullptr;
    }
    if (g.start.empty()) {
        vx_err_set(err, VX_EUNPROC, fi->no_faces, "the %s file has no faces", fi->name);
        return nullptr;
    }
    if (fi->weld) weld(g);
    MeshPtr m(to_mesh(g));
    if (vx_mesh_analyze(m.get(), err)) return nullptr;
    return m.release();
}

/* ---- assimp in a child process ------------------------------------------ */

/* What the child sends back through the pipe; the arrays follow in the
 * memfd: pos (3 nverts doubles), face_idx (nidx), face_start (nfaces + 1,
 * only when not all faces are triangles). */
struct IsoHeader {
    uint64_t nverts, nfaces, nidx;
    int all_tris;
};

struct IsoCall {
    const unsigned char *data;
    size_t n;
    const FormatInfo *fi;
    vx_mesh_format fmt;
    const vx_mesh_limits *lim;
    int fd;
};

int iso_child(void *ud, void *out, size_t out_size, vx_err *err)
{
    (void)out_size;
    IsoCall *c = static_cast<IsoCall *>(ud);
    IsoHeader *h = static_cast<IsoHeader *>(out);
    /* Tests: an importer that dies (as a heap the importer corrupted makes
     * the allocator abort) must cost the caller nothing but this file. */
    if (getenv("VX_TEST_IMPORTER_ABORT")) abort();
    vx_mesh *m = nullptr;
    try {
        m = import(c->data, c->n, c->fi, c->fmt, c->lim, 1, err);
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to read the %s file",
                   c->fi->name);
    } catch (...) {
        vx_err_set(err, VX_EINVAL, c->fi->corrupt, "not a valid %s file: assimp failed",
                   c->fi->name);
    }
    if (!m) return -1;
    h->nverts = m->nverts;
    h->nfaces = m->nfaces;
    h->all_tris = m->face_start == nullptr;
    h->nidx = h->all_tris ? 3 * m->nfaces : m->face_start[m->nfaces];
    int bad =
        vx_write_all(c->fd, m->pos, m->nverts * 3 * sizeof(double)) ||
        vx_write_all(c->fd, m->face_idx, h->nidx * sizeof(uint32_t)) ||
        (!h->all_tris && vx_write_all(c->fd, m->face_start, (m->nfaces + 1) * sizeof(uint32_t)));
    vx_mesh_free(m);
    if (bad) return vx_err_set(err, VX_EINTERNAL, "child_failed", "cannot hand the mesh back");
    return 0;
}

/* Reads n bytes at *off of fd into dst. */
bool read_at(int fd, void *dst, size_t n, off_t *off)
{
    char *p = static_cast<char *>(dst);
    while (n) {
        ssize_t k = pread(fd, p, n, *off);
        if (k <= 0) {
            if (k < 0 && errno == EINTR) continue;
            return false;
        }
        p += k;
        n -= size_t(k);
        *off += k;
    }
    return true;
}

vx_mesh *import_isolated(const unsigned char *data, size_t n, const FormatInfo *fi,
                         vx_mesh_format fmt, const vx_mesh_limits *lim, vx_err *err)
{
    /* Our own checks of the file run here, in this process (and under the
     * fuzzers' eyes); only assimp and the walk of its scene run apart. */
    vx_mesh_declared d;
    if (vx_declared_check(fmt, data, n, n, lim, &d, err)) return nullptr;
    int fd = memfd_create("voxeld-mesh", MFD_CLOEXEC);
    if (fd < 0) {
        vx_err_set(err, VX_EINTERNAL, "child_failed", "cannot make a memfd: %s",
                   std::strerror(errno));
        return nullptr;
    }
    IsoCall c = {data, n, fi, fmt, lim, fd};
    IsoHeader h = {};
    if (vx_child_call(iso_child, &c, &h, sizeof h, nullptr, nullptr, 100, err)) {
        close(fd);
        /* Killed or crashed: the file is what made assimp fail. */
        if (err && !std::strcmp(err->code, "child_failed"))
            vx_err_set(err, VX_EINVAL, fi->corrupt,
                       "not a valid %s file: the importer failed on it", fi->name);
        return nullptr;
    }
    MeshPtr m(vx_mesh_new());
    off_t off = 0;
    bool ok = m && h.nverts <= SIZE_MAX / 24 && h.nidx <= SIZE_MAX / 8 && h.nfaces < SIZE_MAX / 8;
    if (ok) {
        m->nverts = size_t(h.nverts);
        m->nfaces = size_t(h.nfaces);
        m->pos = static_cast<double *>(std::malloc(m->nverts * 3 * sizeof(double) + 1));
        m->face_idx = static_cast<uint32_t *>(std::malloc(size_t(h.nidx) * sizeof(uint32_t) + 1));
        if (!h.all_tris)
            m->face_start =
                static_cast<uint32_t *>(std::malloc((m->nfaces + 1) * sizeof(uint32_t)));
        ok = m->pos && m->face_idx && (h.all_tris || m->face_start) &&
             read_at(fd, m->pos, m->nverts * 3 * sizeof(double), &off) &&
             read_at(fd, m->face_idx, size_t(h.nidx) * sizeof(uint32_t), &off) &&
             (h.all_tris || read_at(fd, m->face_start, (m->nfaces + 1) * sizeof(uint32_t), &off));
    }
    close(fd);
    if (!ok) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the %s mesh", fi->name);
        return nullptr;
    }
    /* What the child sent is checked as any input: face offsets in order,
     * indices in range. */
    for (size_t f = 0; !h.all_tris && f < m->nfaces; f++)
        if (m->face_start[f] > m->face_start[f + 1] || m->face_start[m->nfaces] != h.nidx) {
            vx_err_set(err, VX_EINTERNAL, "mesh_invalid", "the %s importer gave bad faces",
                       fi->name);
            return nullptr;
        }
    for (size_t i = 0; i < size_t(h.nidx); i++)
        if (m->face_idx[i] >= m->nverts) {
            vx_err_set(err, VX_EINTERNAL, "mesh_invalid", "the %s importer gave a bad index",
                       fi->name);
            return nullptr;
        }
    if (vx_mesh_analyze(m.get(), err)) return nullptr;
    return m.release();
}

} // namespace

extern "C" vx_mesh *vx_assimp_read_mem(const unsigned char *data, size_t n, vx_mesh_format fmt,
                                       const vx_mesh_limits *lim, vx_err *err)
{
    /* assimp's OFF and PLY importers crashed on fuzzed files. */
    if (fmt == VX_MESH_OFF) return vx_off_read_mem(data, n, lim, err);
    if (fmt == VX_MESH_PLY) return vx_ply_read_mem(data, n, lim, err);
    const FormatInfo *fi = info(fmt);
    if (!fi) {
        vx_err_set(err, VX_EINTERNAL, "mesh_format", "format %d is not read by assimp", int(fmt));
        return nullptr;
    }
    try {
        if (fmt == VX_MESH_STL) return read_stl(data, n, fi, lim, err);
        return import_isolated(data, n, fi, fmt, lim, err);
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to read the %s file", fi->name);
    } catch (...) {
        vx_err_set(err, VX_EINVAL, fi->corrupt, "not a valid %s file: assimp failed", fi->name);
    }
    return nullptr;
}

extern "C" vx_mesh *vx_assimp_read_path(const char *path, vx_mesh_format fmt,
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
        m = vx_assimp_read_mem(data, n, fmt, lim, err);
    std::free(data);
    return m;
}
