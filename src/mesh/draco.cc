/* Draco reader and writer: a C++ shim over libdraco behind the C API of
 * mesh.h. Nothing thrown inside (std::bad_alloc from the vectors libdraco
 * fills, anything else) may cross into C, so every entry point catches all. */
#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <new>
#include <vector>

#include <sys/stat.h>

#include "draco/compression/decode.h"
#include "draco/compression/encode.h"
#include "draco/core/decoder_buffer.h"
#include "draco/core/encoder_buffer.h"
#include "draco/io/gltf_encoder.h"
#include "draco/mesh/mesh.h"
#include "mesh/alloc_cap.h"

extern "C" {
#include "mesh/mesh.h"
#include "util/fsutil.h"
#include "util/log.h"
}

namespace
{

/* Draco must have the whole encoding in memory; refuse anything that could
 * not be a mesh the daemon would accept anyway before reading it all. */
constexpr size_t kMaxDracoFile = size_t(1) << 30;

struct MeshDeleter {
    void operator()(vx_mesh *m) const { vx_mesh_free(m); }
};
using MeshPtr = std::unique_ptr<vx_mesh, MeshDeleter>;

/* The largest file the limits can justify: a generous 128 bytes per vertex
 * and per triangle covers uncompressed sequential encodings with several
 * attributes. Only when both limits are set; otherwise the hard cap. */
size_t file_bound(const vx_mesh_limits *lim)
{
    if (!lim || !lim->max_vertices || !lim->max_triangles) return kMaxDracoFile;
    size_t n = lim->max_vertices + lim->max_triangles;
    if (n > (kMaxDracoFile - (1 << 20)) / 128) return kMaxDracoFile;
    return (size_t(1) << 20) + 128 * n;
}

/* Reads f to the end into data; fails past `bound` bytes. Returns 0, or -1
 * with err set. */
int slurp(FILE *f, size_t bound, std::vector<char> &data, vx_err *err)
{
    size_t used = 0;
    /* A regular file's size is known: one allocation, no doubling copies
     * (the peak would be 1.5 times the file). */
    struct stat st;
    off_t here = ftello(f);
    size_t first = size_t(1) << 16;
    if (fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode) && here >= 0 && st.st_size >= here)
        first = std::min(size_t(st.st_size - here), bound) + 1;
    data.resize(first);
    for (;;) {
        if (used == data.size()) {
            /* The buffer is one byte over the bound at most: enough to tell. */
            if (used > bound)
                return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                                  "Draco file larger than %zu bytes (the limit)", bound);
            data.resize(std::min(data.size() * 2, bound + 1));
        }
        size_t got = std::fread(data.data() + used, 1, data.size() - used, f);
        used += got;
        if (got == 0) {
            if (std::ferror(f))
                return vx_err_set(err, VX_EIO, "mesh_io", "read error: %s", std::strerror(errno));
            break;
        }
    }
    if (used > bound)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "Draco file is %zu bytes, more than %zu (the limit)", used, bound);
    data.resize(used);
    return 0;
}

/* libdraco also sizes tables from counts deep in the data, where no header
 * check reaches: a texture-coordinate predictor's orientation count (up to
 * 2^31 bits, then read in a loop of as many steps: 27 s and 200 MB for a
 * 2.7 KB file of 372 faces, found by fuzz_draco). The decode runs under a
 * vx::AllocCap (alloc_cap.h) and reports a trip as draco_corrupt. */
using vx::AllocCap;

/* A cursor over the header bytes: every read checks the bytes left. */
struct Cursor {
    const unsigned char *p, *end;
    bool u8(unsigned &v)
    {
        if (p == end) return false;
        v = *p++;
        return true;
    }
    bool u16(unsigned &v)
    {
        if (end - p < 2) return false;
        v = unsigned(p[0]) | unsigned(p[1]) << 8;
        p += 2;
        return true;
    }
    bool u32(uint64_t &v)
    {
        if (end - p < 4) return false;
        v = uint64_t(p[0]) | uint64_t(p[1]) << 8 | uint64_t(p[2]) << 16 | uint64_t(p[3]) << 24;
        p += 4;
        return true;
    }
    /* libdraco's varint: 7 bits a byte, low bits first; a uint32 takes five
     * bytes at most. */
    bool varint(uint64_t &v)
    {
        v = 0;
        for (int i = 0; i < 5; i++) {
            if (p == end) return false;
            unsigned b = *p++;
            v |= uint64_t(b & 0x7f) << (7 * i);
            if (!(b & 0x80)) return v <= UINT32_MAX;
        }
        return false;
    }
    /* A count: uint32 in the oldest bitstreams, varint from `since` on. */
    bool count(unsigned version, unsigned since, uint64_t &v)
    {
        return version < since ? u32(v) : varint(v);
    }
    bool skip(uint64_t n)
    {
        if (uint64_t(end - p) < n) return false;
        p += n;
        return true;
    }
};

constexpr unsigned version_of(unsigned major, unsigned minor)
{
    return major << 8 | minor;
}

/* Walks one metadata block (entries, then named sub-blocks) without keeping
 * it. libdraco sizes an entry's buffer from its declared length before
 * reading it and recurses once per level, so both are checked here first. */
bool skip_metadata(Cursor &c, int depth)
{
    uint64_t n, len;
    unsigned nlen;
    if (depth > 16 || !c.varint(n)) return false;
    for (uint64_t i = 0; i < n; i++)
        if (!c.u8(nlen) || !c.skip(nlen) || !c.varint(len) || len == 0 || !c.skip(len))
            return false;
    if (!c.varint(n)) return false;
    for (uint64_t i = 0; i < n; i++)
        if (!c.u8(nlen) || !c.skip(nlen) || !skip_metadata(c, depth + 1)) return false;
    return true;
}

int corrupt(vx_err *err, const char *what)
{
    return vx_err_set(err, VX_EINVAL, "draco_corrupt", "not a valid Draco mesh: %s", what);
}

/* Skips the file's metadata (per-attribute blocks, then the geometry's);
 * nullptr when done, else what is wrong. */
const char *skip_file_metadata(Cursor &c)
{
    uint64_t natt, id;
    if (!c.varint(natt)) return "truncated metadata";
    for (uint64_t i = 0; i < natt; i++)
        if (!c.varint(id) || !skip_metadata(c, 0)) return "corrupt metadata";
    if (!skip_metadata(c, 0)) return "corrupt metadata";
    return nullptr;
}

/* Refuses declared counts over the mesh limits. */
int check_limits(uint64_t faces, uint64_t points, const vx_mesh_limits *lim, vx_err *err)
{
    if (lim && lim->max_triangles && faces > lim->max_triangles)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the header declares %llu triangles, more than %zu (the limit)",
                          (unsigned long long)faces, lim->max_triangles);
    if (lim && lim->max_vertices && points > lim->max_vertices)
        return vx_err_set(err, VX_ETOOBIG, "mesh_too_big",
                          "the header declares %llu vertices, more than %zu (the limit)",
                          (unsigned long long)points, lim->max_vertices);
    return 0;
}

} // namespace

/* Edgebreaker entropy-codes its connectivity and the attributes; the
 * densest encoding libdraco writes of a real mesh (a regular grid at
 * -cl 10) carries about 40 faces per byte of the whole file. A declared
 * face count beyond this many per byte left is not a real encoding. */
#define DRACO_FACES_PER_BYTE 2048
/* Non-position attributes with seams (texture coordinates, normals,
 * colours...) that an edgebreaker mesh may carry. */
#define DRACO_MAX_ATTRIBUTE_SETS 32

/* libdraco's own peak, measured with AllocCap's counter: 78 bytes a face
 * with its vertices for a mesh of positions (edgebreaker, 2 million faces),
 * 152 with texture coordinates and normals; 2 bytes per file byte at most
 * for the sequential method's entropy-coded buffers. About twice that. */
extern "C" uint64_t vx_draco_decode_bound(const vx_draco_header *h, uint64_t file_size)
{
    return 2 * file_size + (96 + 64 * uint64_t(h->attribute_sets)) * h->faces +
           96 * (h->points + h->extra_points) + (uint64_t(4) << 20);
}

extern "C" int vx_draco_check_header(const unsigned char *data, size_t n, uint64_t file_size,
                                     const vx_mesh_limits *lim, vx_draco_header *h, vx_err *err)
{
    Cursor c{data, data + n};
    *h = vx_draco_header{};
    /* Bytes of the file after the cursor (the window may end earlier). */
    auto left = [&]() { return file_size - uint64_t(c.p - data); };
    /* A read that fails inside the window but before the end of the file
     * needs more of it. */
    auto short_read = [&](const char *what) {
        if (n < file_size) return 1;
        return corrupt(err, what);
    };
    unsigned major, minor, type, method, flags;
    if (n < 5 || std::memcmp(data, "DRACO", 5)) return corrupt(err, "no DRACO magic");
    c.p += 5;
    if (!c.u8(major) || !c.u8(minor) || !c.u8(type) || !c.u8(method) || !c.u16(flags))
        return short_read("truncated header");
    h->major = major;
    h->minor = minor;
    h->method = method;
    /* A point cloud is named only under a version libdraco writes point
     * clouds in (1.0 to 1.3, 2.0 to 2.3): junk after the magic whose third
     * byte is 0 is corrupt, not a point cloud. */
    if (type == 0 && (major == 1 || major == 2) && minor <= 3)
        return vx_err_set(err, VX_EUNPROC, "draco_point_cloud",
                          "the Draco file holds a point cloud, not a mesh");
    /* Mesh bitstreams libdraco reads: 1.0 to 1.3 and 2.0 to 2.2. */
    unsigned v = version_of(major, minor);
    if (!((major == 1 && minor <= 3) || (major == 2 && minor <= 2)))
        return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                          "unsupported Draco bitstream version %u.%u (1.0 to 2.2 are read)", major,
                          minor);
    if (type != 1)
        return vx_err_set(err, VX_EINVAL, "draco_corrupt", "unknown Draco geometry type %u", type);
    if (method > 1)
        return vx_err_set(err, VX_EINVAL, "draco_corrupt", "unknown Draco encoding method %u",
                          method);
    if (v >= version_of(1, 3) && (flags & 0x8000)) {
        const char *bad = skip_file_metadata(c);
        if (bad) return short_read(bad);
    }
    uint64_t faces, points;
    if (method == 0) { /* sequential */
        if (!c.count(v, version_of(2, 2), faces) || !c.count(v, version_of(2, 2), points))
            return short_read("truncated connectivity header");
        /* At least one byte per face index, as libdraco checks too; every
         * point is used by a face. */
        if (faces > left() / 3)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                              "the header declares %llu faces, more than %llu bytes can hold",
                              (unsigned long long)faces, (unsigned long long)left());
        if (points > 3 * faces)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                              "the header declares %llu points for %llu faces",
                              (unsigned long long)points, (unsigned long long)faces);
    } else { /* edgebreaker */
        unsigned traversal, natt;
        uint64_t new_verts = 0, verts, symbols, splits;
        if (!c.u8(traversal)) return short_read("truncated connectivity header");
        if (traversal > 2)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt", "unknown edgebreaker traversal %u",
                              traversal);
        const unsigned since = version_of(2, 0);
        if (v < version_of(2, 2) && !c.count(v, since, new_verts))
            return short_read("truncated connectivity header");
        if (!c.count(v, since, verts) || !c.count(v, since, faces) || !c.u8(natt) ||
            !c.count(v, since, symbols) || !c.count(v, since, splits))
            return short_read("truncated connectivity header");
        uint64_t max_faces = DRACO_FACES_PER_BYTE * left() + 64;
        if (faces > max_faces)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                              "the header declares %llu faces in %llu bytes of data: more than "
                              "any encoding holds",
                              (unsigned long long)faces, (unsigned long long)left());
        /* A symbol makes one face; a split or a new vertex needs a face;
         * every vertex is a corner of a face. */
        if (symbols > faces || splits > faces || verts > 3 * faces || new_verts > 3 * faces)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                              "inconsistent counts in the header: %llu faces, %llu symbols, "
                              "%llu vertices, %llu splits",
                              (unsigned long long)faces, (unsigned long long)symbols,
                              (unsigned long long)verts, (unsigned long long)splits);
        /* Each set costs libdraco a corner table of its own. */
        if (natt > DRACO_MAX_ATTRIBUTE_SETS)
            return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                              "%u attribute connectivity sets, more than %d", natt,
                              DRACO_MAX_ATTRIBUTE_SETS);
        points = verts;
        h->extra_points = splits + new_verts;
        h->attribute_sets = natt;
    }
    h->faces = faces;
    h->points = points;
    return check_limits(faces, points, lim, err);
}

namespace
{

/* Checks that buf holds a triangular mesh (not a point cloud). */
int check_geometry_type(draco::DecoderBuffer &buf, vx_err *err)
{
    /* Works on a copy of the buffer: the position stays at the start. */
    auto type = draco::Decoder::GetEncodedGeometryType(&buf);
    if (!type.ok())
        return vx_err_set(err, VX_EINVAL, "draco_corrupt", "not a valid Draco file: %s",
                          type.status().error_msg());
    if (type.value() == draco::POINT_CLOUD)
        return vx_err_set(err, VX_EUNPROC, "draco_point_cloud",
                          "the Draco file holds a point cloud, not a mesh");
    if (type.value() != draco::TRIANGULAR_MESH)
        return vx_err_set(err, VX_EINVAL, "draco_corrupt", "unknown Draco geometry type %d",
                          int(type.value()));
    return 0;
}

/* Decodes buf under an AllocCap sized from the header; fails when the cap
 * trips, else leaves the outcome in decoded and status. */
int decode_capped(draco::DecoderBuffer &buf, const vx_draco_header &hd, size_t size,
                  std::unique_ptr<draco::Mesh> &decoded, draco::Status &status, vx_err *err)
{
    draco::Decoder dec;
    AllocCap cap(vx_draco_decode_bound(&hd, size));
    try {
        auto res = dec.DecodeMeshFromBuffer(&buf);
        status = res.status();
        if (res.ok()) decoded = std::move(res).value();
    } catch (const std::bad_alloc &) {
        if (!cap.tripped()) throw;
    }
    if (cap.tripped())
        return vx_err_set(err, VX_EINVAL, "draco_corrupt",
                          "corrupt Draco mesh: decoding it would take more than %llu bytes of "
                          "memory for %llu faces",
                          (unsigned long long)cap.limit(), (unsigned long long)hd.faces);
    return 0;
}

/* The decoded mesh's numeric three-component POSITION attribute, with the
 * counts checked against the limits; nullptr on error. */
const draco::PointAttribute *check_decoded(const draco::Mesh &dm, const vx_mesh_limits *lim,
                                           vx_err *err)
{
    size_t np = dm.num_points(), nf = dm.num_faces();
    if (nf == 0) {
        vx_err_set(err, VX_EUNPROC, "draco_no_faces", "the Draco mesh has no faces");
        return nullptr;
    }
    const draco::PointAttribute *pa = dm.GetNamedAttribute(draco::GeometryAttribute::POSITION);
    if (!pa || pa->num_components() < 3) {
        vx_err_set(err, VX_EUNPROC, "draco_no_positions",
                   "the Draco mesh has no three-component POSITION attribute");
        return nullptr;
    }
    /* Numbers only: converting bools reads arbitrary bytes as bool (found
     * by fuzz_draco; undefined behaviour). */
    draco::DataType dt = pa->data_type();
    if (dt <= draco::DT_INVALID || dt == draco::DT_BOOL || dt >= draco::DT_TYPES_COUNT) {
        vx_err_set(err, VX_EUNPROC, "draco_no_positions",
                   "the Draco mesh's POSITION attribute is not numeric (data type %d)", int(dt));
        return nullptr;
    }
    if (lim && lim->max_vertices && np > lim->max_vertices) {
        vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu vertices, more than %zu (the limit)", np,
                   lim->max_vertices);
        return nullptr;
    }
    if (lim && lim->max_triangles && nf > lim->max_triangles) {
        vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu triangles, more than %zu (the limit)", nf,
                   lim->max_triangles);
        return nullptr;
    }
    if (nf > UINT32_MAX / 3) {
        vx_err_set(err, VX_ETOOBIG, "mesh_too_big", "%zu triangles", nf);
        return nullptr;
    }
    return pa;
}

/* Copies the positions and faces of dm into m (allocated), checking every
 * position and point index. */
int copy_mesh(const draco::Mesh &dm, const draco::PointAttribute *pa, vx_mesh *m, vx_err *err)
{
    size_t np = dm.num_points(), nf = dm.num_faces();
    m->pos = static_cast<double *>(std::malloc(3 * np * sizeof(double) + 1));
    m->face_idx = static_cast<uint32_t *>(std::malloc(3 * nf * sizeof(uint32_t)));
    if (!m->pos || !m->face_idx) throw std::bad_alloc();
    for (size_t i = 0; i < np; i++) {
        draco::AttributeValueIndex avi = pa->mapped_index(draco::PointIndex(uint32_t(i)));
        double *v = m->pos + 3 * i;
        /* The decoder validated the mapping; checked again because a bad
         * index here would read out of bounds, not just give a wrong mesh. */
        if (avi.value() >= pa->size() || !pa->ConvertValue<double>(avi, 3, v))
            return vx_err_set(err, VX_EINVAL, "draco_corrupt", "vertex %zu has no position", i);
        if (!std::isfinite(v[0]) || !std::isfinite(v[1]) || !std::isfinite(v[2]))
            return vx_err_set(err, VX_EINVAL, "draco_nan",
                              "vertex %zu has a NaN or infinite coordinate", i);
    }
    for (size_t f = 0; f < nf; f++) {
        const draco::Mesh::Face &face = dm.face(draco::FaceIndex(uint32_t(f)));
        for (int k = 0; k < 3; k++) {
            uint32_t p = face[k].value();
            if (p >= np)
                return vx_err_set(err, VX_EINVAL, "draco_corrupt", "face %zu uses point %u of %zu",
                                  f, p, np);
            m->face_idx[3 * f + k] = p;
        }
    }
    m->nverts = np;
    m->nfaces = nf;
    return 0;
}

vx_mesh *decode(const std::vector<char> &data, const vx_mesh_limits *lim, vx_err *err)
{
    /* The declared counts decide what libdraco allocates before it reads
     * any data: check them first. */
    vx_draco_header hd;
    if (vx_draco_check_header(reinterpret_cast<const unsigned char *>(data.data()), data.size(),
                              data.size(), lim, &hd, err))
        return nullptr;
    draco::DecoderBuffer buf;
    buf.Init(data.data(), data.size());
    if (check_geometry_type(buf, err)) return nullptr;
    std::unique_ptr<draco::Mesh> decoded;
    draco::Status status;
    if (decode_capped(buf, hd, data.size(), decoded, status, err)) return nullptr;
    if (!status.ok() || !decoded) {
        vx_err_set(err, VX_EINVAL, "draco_corrupt", "corrupt or truncated Draco mesh: %s",
                   status.error_msg());
        return nullptr;
    }
    const draco::Mesh &dm = *decoded;
    const draco::PointAttribute *pa = check_decoded(dm, lim, err);
    if (!pa) return nullptr;

    MeshPtr m(vx_mesh_new());
    if (!m) throw std::bad_alloc();
    if (copy_mesh(dm, pa, m.get(), err)) return nullptr;
    if (vx_mesh_analyze(m.get(), err)) return nullptr;
    return m.release();
}

vx_mesh *read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err)
{
    try {
        std::vector<char> data;
        if (slurp(f, file_bound(lim), data, err)) return nullptr;
        return decode(data, lim, err);
    } catch (const std::bad_alloc &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to decode the Draco mesh");
    } catch (...) {
        vx_err_set(err, VX_EINTERNAL, "draco_internal", "libdraco failed unexpectedly");
    }
    return nullptr;
}

/* Adds a float attribute with one value per point (identity mapping). */
void add_float3(draco::Mesh &dm, draco::GeometryAttribute::Type type, size_t n, const double *d,
                const float *f)
{
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, 3, draco::DT_FLOAT32, false, sizeof(float) * 3, 0);
    int id = dm.AddAttribute(ga, true, uint32_t(n));
    draco::PointAttribute *att = dm.attribute(id);
    for (size_t i = 0; i < n; i++) {
        float v[3];
        for (int a = 0; a < 3; a++)
            v[a] = d ? float(d[3 * i + a]) : f[3 * i + a];
        att->SetAttributeValue(draco::AttributeValueIndex(uint32_t(i)), v);
    }
}

int write_file(const char *path, const char *data, size_t size, vx_err *err)
{
    FILE *f = std::fopen(path, "wb");
    if (!f)
        return vx_err_set(err, VX_EIO, "io_error", "cannot create %s: %s", vx_path_base(path),
                          std::strerror(errno));
    struct stat st;
    /* Only a regular file is removed after a failure, never a device. */
    bool regular = fstat(fileno(f), &st) == 0 && S_ISREG(st.st_mode);
    errno = 0;
    bool ok = std::fwrite(data, 1, size, f) == size;
    int e = errno;
    if (std::fclose(f) && ok) {
        ok = false;
        e = errno;
    }
    if (ok) return 0;
    if (regular) std::remove(path);
    VX_ERROR("mesh.write_failed", "errno=%d", e);
    return vx_err_set(err, VX_EIO, "io_error", "cannot write %s: %s", vx_path_base(path),
                      std::strerror(e ? e : EIO));
}

/* Fills dm with m's triangulated view, positions and optional normals. */
int build_mesh(const vx_mesh *m, const vx_mesh_write_opts *o, draco::Mesh &dm, vx_err *err)
{
    /* The triangulated view; a mesh of triangles not yet analysed has it
     * in face_idx already. */
    const uint32_t *tri = m->tri ? m->tri : m->face_start ? nullptr : m->face_idx;
    size_t ntris = m->tri ? m->ntris : m->nfaces;
    if (!tri && m->nfaces)
        return vx_err_set(err, VX_EINTERNAL, "mesh_not_analyzed",
                          "the mesh has no triangulated view (vx_mesh_analyze)");
    dm.set_num_points(uint32_t(m->nverts));
    add_float3(dm, draco::GeometryAttribute::POSITION, m->nverts, m->pos, nullptr);
    if (o && o->normals)
        add_float3(dm, draco::GeometryAttribute::NORMAL, m->nverts, nullptr, o->normals);
    dm.SetNumFaces(ntris);
    for (size_t t = 0; t < ntris; t++) {
        draco::Mesh::Face face;
        for (int k = 0; k < 3; k++)
            face[k] = draco::PointIndex(tri[3 * t + k]);
        dm.SetFace(draco::FaceIndex(uint32_t(t)), face);
    }
    return 0;
}

/* True when Draco's edgebreaker would take too long on dm: its corner
 * table (CornerTable::ComputeOppositeCorners) takes time of the order of
 * the sum of the squared face counts at each vertex, and many faces on one
 * edge (a surface repeated) made 720,000 triangles take 10 s against 1 s
 * for the rest of the job. */
bool crowded(const draco::Mesh &dm)
{
    std::vector<uint32_t> deg(dm.num_points());
    for (draco::FaceIndex f(0); f < dm.num_faces(); ++f)
        for (int k = 0; k < 3; k++)
            deg[dm.face(f)[k].value()]++;
    double sum = 0;
    for (uint32_t d : deg)
        sum += (double)d * d;
    const double corners = 3.0 * dm.num_faces();
    return sum > 64 * corners && sum > (double)(1 << 26);
}

int write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err)
{
    int bits = o && o->draco_quantization_bits ? o->draco_quantization_bits : 16;
    if (bits < 1 || bits > 30)
        return vx_err_set(err, VX_EUNPROC, "invalid_params",
                          "Draco quantisation must be 1 to 30 bits, got %d", bits);
    draco::Mesh dm;
    if (build_mesh(m, o, dm, err)) return -1;

    draco::Encoder enc;
    /* the sequential coding: a larger file, in time linear in the faces */
    if (crowded(dm)) enc.SetEncodingMethod(draco::MESH_SEQUENTIAL_ENCODING);
    enc.SetAttributeQuantization(draco::GeometryAttribute::POSITION, bits);
    /* Draco's own default for normals: well under a degree of error. */
    enc.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, 10);
    draco::EncoderBuffer out;
    draco::Status st = enc.EncodeMeshToBuffer(dm, &out);
    if (!st.ok())
        return vx_err_set(err, VX_EIO, "draco_encode", "Draco encoding failed: %s", st.error_msg());
    return write_file(path, out.data(), out.size(), err);
}

/* glb through libdraco's glTF encoder (uncompressed: plain accessors that
 * every glTF reader takes; positions as float32). */
int write_glb(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path, vx_err *err)
{
    draco::Mesh dm;
    if (build_mesh(m, o, dm, err)) return -1;
    draco::GltfEncoder enc;
    draco::EncoderBuffer out;
    draco::Status st = enc.EncodeToBuffer(dm, &out);
    if (!st.ok())
        return vx_err_set(err, VX_EIO, "glb_encode", "glb encoding failed: %s", st.error_msg());
    return write_file(path, out.data(), out.size(), err);
}

} // namespace

extern "C" vx_mesh *vx_draco_read_file(FILE *f, const vx_mesh_limits *lim, vx_err *err)
{
    return read_file(f, lim, err);
}

extern "C" vx_mesh *vx_draco_read_path(const char *path, const vx_mesh_limits *lim, vx_err *err)
{
    FILE *f = vx_mesh_open(path, err);
    if (!f) return nullptr;
    vx_mesh *m = read_file(f, lim, err);
    std::fclose(f);
    return m;
}

extern "C" int vx_draco_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path,
                                   vx_err *err)
{
    try {
        return write_path(m, o, path, err);
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to encode the Draco mesh");
    } catch (...) {
        return vx_err_set(err, VX_EIO, "draco_encode", "libdraco failed unexpectedly");
    }
}

extern "C" int vx_glb_write_path(const vx_mesh *m, const vx_mesh_write_opts *o, const char *path,
                                 vx_err *err)
{
    try {
        return write_glb(m, o, path, err);
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory to encode the glb");
    } catch (...) {
        return vx_err_set(err, VX_EIO, "glb_encode", "libdraco's glTF encoder failed");
    }
}
