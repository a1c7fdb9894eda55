// OpenVDB writer (io.h). The one C++ file of the library: OpenVDB's heavy
// templates are instantiated here only, behind a C API that never lets an
// exception cross into C.
//
// The tree is built a leaf at a time from the bit grid, in parallel: an
// OpenVDB leaf is 8^3 voxels whose masks are 8 words of 64 bits, word x
// holding bit 8 y + z of the leaf's (x, y, z). Each leaf gathers its 64
// bytes (one per (y, z) row, bits x) from the grid and transposes them;
// a full leaf becomes an active tile, an empty one is left out. A level
// set's leaves are its band (band.h), made in parallel from the bit grid's
// rows, or from a merged bool tree's rows a few z slabs at a time.
#include <algorithm>
#include <array>
#include <atomic>
#include <cfloat>
#include <cmath>
#include <limits>
#include <cstdio>
#include <cstring>
#include <cerrno>
#include <exception>
#include <fstream>
#include <functional>
#include <memory>
#include <mutex>
#include <set>
#include <stdexcept>
#include <sstream>
#include <string>
#include <tuple>
#include <type_traits>
#include <unordered_map>
#include <vector>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Count.h>
#include <openvdb/tools/Prune.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include "util/cpu.h"

extern "C" {
#include "voxel/band.h"
#include "voxel/io.h"
}

namespace
{

std::once_flag init_once;

template <typename GridT> void set_meta(GridT &grid, const vx_bitgrid *g, const vx_vdb_meta *m)
{
    const vx_grid &gr = g->grid;
    if (m) {
        if (m->method) grid.insertMeta("method", openvdb::StringMetadata(m->method));
        if (m->inside) grid.insertMeta("inside", openvdb::StringMetadata(m->inside));
        if (m->fill) grid.insertMeta("fill", openvdb::StringMetadata(m->fill));
        if (m->mesh) grid.insertMeta("mesh", openvdb::StringMetadata(m->mesh));
        grid.insertMeta("supersample", openvdb::Int32Metadata(m->supersample));
        grid.insertMeta("threshold", openvdb::Int32Metadata(m->threshold));
        if (m->samples) grid.insertMeta("samples", openvdb::StringMetadata(m->samples));
    }
    grid.insertMeta("voxel_size", openvdb::DoubleMetadata(gr.h));
    grid.insertMeta(
        "origin", openvdb::Vec3DMetadata(openvdb::Vec3d(gr.origin[0], gr.origin[1], gr.origin[2])));
    grid.insertMeta("dims",
                    openvdb::Vec3IMetadata(openvdb::Vec3i(gr.dims[0], gr.dims[1], gr.dims[2])));
}

// Index (i,j,k) is the voxel centre origin + (i + 1/2, j + 1/2, k + 1/2) h.
openvdb::math::Transform::Ptr transform_of(const vx_grid &gr)
{
    openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(gr.h);
    xf->postTranslate(openvdb::Vec3d(gr.origin[0] + 0.5 * gr.h, gr.origin[1] + 0.5 * gr.h,
                                     gr.origin[2] + 0.5 * gr.h));
    return xf;
}

// Writes many strings of a few KiB to a file stream in blocks of 256 KiB:
// std::filebuf hands every write of 1 KiB or more to the kernel at once,
// and a system call per 18 KiB chunk of leaves cost more than the bytes
// (7.6 MB in 427 writes: 5 ms, in 256 KiB blocks 1.5 ms).
class Batch
{
    static constexpr size_t BLOCK = 256 << 10;
    std::ostream &os_;
    std::unique_ptr<char[]> &buf_;
    size_t n_ = 0;

  public:
    explicit Batch(std::ostream &os) : os_(os), buf_(block()) {}
    static std::unique_ptr<char[]> &block()
    {
        static thread_local std::unique_ptr<char[]> b(new char[BLOCK]);
        return b;
    }
    void write(const std::string &s)
    {
        if (s.size() >= BLOCK) {
            flush();
            os_.write(s.data(), (std::streamsize)s.size());
            return;
        }
        if (n_ + s.size() > BLOCK) flush();
        std::memcpy(buf_.get() + n_, s.data(), s.size());
        n_ += s.size();
    }
    // Writes what is held (the caller's last call: nothing is written
    // when the Batch goes).
    void flush()
    {
        const size_t n = n_;
        n_ = 0;
        if (n) os_.write(buf_.get(), (std::streamsize)n);
    }
};

// What the archive below asks of a grid it writes itself (ParallelGrid).
class Prepared
{
  public:
    virtual ~Prepared() = default;
    // Writes every leaf's buffer into memory, on all threads, for
    // writeBuffers to append; for a float grid, fills dl with what OpenVDB's
    // own archive writer computes for the grid's delayed-load metadata
    // (each leaf's mask compression kind and the size of its compressed
    // values), taken from the bytes written, and returns 1 (0 for a grid
    // OpenVDB writes none for). os: the grid's compression set.
    virtual int prepare(std::ostream &os, openvdb::io::DelayedLoadMetadata &dl) const = 0;
    // Bytes the tree's memUsage leaves out for leaves made without values.
    virtual uint64_t unloaded_bytes() const = 0;
    // Puts into g the statistics GridBase::addStatsMetadata would (active
    // voxels' bounding box and count, memory, this with every leaf holding
    // its values), found by prepare as it wrote the leaves. After prepare.
    virtual void stats_metadata(openvdb::GridBase &g) const = 0;
};

// A grid (bool or float) whose topology and leaf buffers are written from
// every thread, in tree order: the topology is the root's and each upper
// internal node's own header (masks and tile values, written here as their
// writeTopology writes them), then each lower internal node's (its masks
// and tile values through OpenVDB's calls, then its leaves' masks copied:
// most of the bytes); the buffers are each leaf's writeBuffers (a bool
// leaf's copied). A node's bytes depend only on the node and on the
// stream's compression and background, so the lower internal nodes and
// chunks of leaves are written into memory in parallel and appended in
// order: the bytes of Tree::writeTopology and Tree::writeBuffers (vdbcheck
// compares them with those, on the grid read back).
//
// With on_ set, a leaf may be made without values (LeafNode's
// PartialCreate: its mask only): it holds on_ at its active voxels and the
// background elsewhere (a 0/1 fog grid: its 80 MB of floats at 1024^3 were
// most of its writer's time, made, faulted in and freed). Such a leaf's
// buffer is its value mask, then what writeCompressedValues writes for its
// values, which depends only on how many are active: OpenVDB's own bytes
// for each count (tails_for, made once a process from a scratch leaf) are
// reused for every leaf of that count. With a values hook (set_values: a
// level set's band), such a leaf's values are made by the hook as it is
// written, and written as LeafNode::writeBuffers writes them.
template <typename GridT> class ParallelGrid final : public GridT, public Prepared
{
    using TreeT = typename GridT::TreeType;
    using RootT = typename TreeT::RootNodeType;
    using UpperT = typename RootT::ChildNodeType;
    using LowerT = typename UpperT::ChildNodeType;
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename GridT::ValueType;
    const bool by_mask_;
    const ValueT on_;

  public:
    // values(leaf, v): the SIZE values of a leaf made without them
    using Values = std::function<void(const LeafT &, ValueT *)>;

  private:
    Values values_;
    std::shared_ptr<void> values_data_; // what values_ reads, held with the grid
    uint64_t values_bytes_ = 0;
    mutable std::vector<std::string> buffers_; // prepared: the buffers section, in chunks

    // What addStatsMetadata's traversals find (tools::countActiveVoxels,
    // tools::memUsage, evalActiveVoxelBoundingBox: 3.3 ms in place of a 22
    // ms bool write at 1024^3, of which the write saves about 1: the rest
    // moves to the topology's first touch of the nodes), and the bytes
    // leaves made without values leave out of the memory.
    struct Stats {
        uint64_t count = 0, mem = 0, unloaded = 0;
        openvdb::CoordBBox bbox; // empty: as evalActiveVoxelBoundingBox resets it
        void add(const Stats &o)
        {
            count += o.count;
            mem += o.mem;
            unloaded += o.unloaded;
            bbox.expand(o.bbox);
        }
    };
    mutable std::unique_ptr<Stats> stats_; // prepared

    // A leaf's part: its active voxels' bounding box from its mask's words
    // (word x, bit 8 y + z), which evalActiveBoundingBox finds voxel by voxel.
    void leaf_stats(const LeafT &leaf, Stats &st) const
    {
        const typename LeafT::NodeMaskType &m = leaf.getValueMask();
        st.count += leaf.onVoxelCount();
        st.mem += leaf.memUsage();
        if (unloaded(leaf)) st.unloaded += LeafT::SIZE * sizeof(ValueT);
        uint64_t any = 0;
        int x0 = -1, x1 = -1;
        for (int x = 0; x < 8; x++)
            if (const uint64_t w = m.template getWord<uint64_t>((openvdb::Index)x)) {
                x0 = x0 < 0 ? x : x0;
                x1 = x;
                any |= w;
            }
        if (!any) return;
        unsigned zs = 0;
        int y0 = -1, y1 = -1;
        for (int y = 0; y < 8; y++)
            if (const unsigned b = (unsigned)(any >> (8 * y)) & 0xffu) {
                y0 = y0 < 0 ? y : y0;
                y1 = y;
                zs |= b;
            }
        const openvdb::Coord o = leaf.origin();
        st.bbox.expand(openvdb::CoordBBox(o + openvdb::Coord(x0, y0, __builtin_ctz(zs)),
                                          o + openvdb::Coord(x1, y1, 31 - __builtin_clz(zs))));
    }

    // An internal node's part and its children's, but for the leaves:
    // MemUsageOp's bytes, ActiveVoxelCountOp's tiles, and the tiles' boxes.
    template <typename NodeT> static void node_stats(const NodeT &node, Stats &st)
    {
        using ChildT = typename NodeT::ChildNodeType;
        st.mem += NodeT::NUM_VALUES * sizeof(typename NodeT::UnionType) +
                  node.getChildMask().memUsage() + node.getValueMask().memUsage() +
                  sizeof(openvdb::Coord);
        tiles_stats(node, st);
        if constexpr (!std::is_same<ChildT, LeafT>::value)
            for (auto it = node.cbeginChildOn(); it; ++it)
                node_stats(*it, st);
    }

    template <typename NodeT> static void tiles_stats(const NodeT &node, Stats &st)
    {
        using ChildT = typename NodeT::ChildNodeType;
        for (auto it = node.cbeginValueOn(); it; ++it) {
            st.count += ChildT::NUM_VOXELS;
            st.bbox.expand(it.getCoord(), ChildT::DIM);
        }
    }

    // What writeCompressedValues writes for the values of a leaf made
    // without them, by its active count: OpenVDB's own bytes for a scratch
    // leaf holding on at that many voxels and background elsewhere, under
    // one (compression, background, on, half). Made once a process, on the
    // first write that needs them (each write's threads made them again:
    // 1,022 of them, 3-5 ms of a fog write at 1024^3); the last few kept.
    using Tails = std::vector<std::string>;
    static std::shared_ptr<const Tails> tails_for(uint32_t compression, const ValueT &background,
                                                  const ValueT &on, bool half)
    {
        struct Made {
            uint32_t compression;
            ValueT background, on;
            bool half;
            std::shared_ptr<const Tails> tails;
        };
        static std::mutex lock;
        static std::vector<Made> made; // newest last
        std::lock_guard<std::mutex> hold(lock);
        for (const Made &m : made)
            if (m.compression == compression && m.half == half &&
                std::memcmp(&m.background, &background, sizeof(ValueT)) == 0 &&
                std::memcmp(&m.on, &on, sizeof(ValueT)) == 0)
                return m.tails;
        std::shared_ptr<Tails> t = std::make_shared<Tails>(LeafT::SIZE + 1);
        std::unique_ptr<LeafT> scratch(new LeafT(openvdb::Coord(0), background));
        ValueT *d = scratch->buffer().data();
        for (openvdb::Index n = 0; n <= LeafT::SIZE; n++) {
            typename LeafT::NodeMaskType mask;
            for (openvdb::Index i = 0; i < LeafT::SIZE; i++) {
                if (i < n) mask.setOn(i);
                d[i] = i < n ? on : background;
            }
            std::ostringstream ss;
            openvdb::io::setDataCompression(ss, compression);
            openvdb::io::setGridBackgroundValuePtr(ss, &background);
            openvdb::io::writeCompressedValues(ss, d, LeafT::SIZE, mask,
                                               typename LeafT::NodeMaskType(), half);
            (*t)[n] = ss.str();
        }
        if (made.size() == 4) made.erase(made.begin());
        made.push_back(Made{compression, background, on, half, t});
        return t;
    }

    // Appends what write(ss, i) puts into a fresh memory stream (the
    // compression and background of os) for i in [0, n), on all threads, a
    // window of chunks at a time, in order.
    template <typename Write>
    static void in_parallel(std::ostream &os, size_t n, size_t chunk, Write write)
    {
        const uint32_t compression = openvdb::io::getDataCompression(os);
        const void *background = openvdb::io::getGridBackgroundValuePtr(os);
        const size_t window = 64 * chunk;
        std::vector<std::string> out(window / chunk);
        for (size_t w0 = 0; w0 < n; w0 += window) {
            const size_t w1 = std::min(n, w0 + window);
            const size_t nc = (w1 - w0 + chunk - 1) / chunk;
            tbb::parallel_for(size_t(0), nc, [&](size_t c) {
                std::ostringstream ss;
                openvdb::io::setDataCompression(ss, compression);
                openvdb::io::setGridBackgroundValuePtr(ss, background);
                const size_t a = w0 + c * chunk, b = std::min(w1, a + chunk);
                for (size_t i = a; i < b; i++)
                    write(ss, i);
                out[c] = ss.str();
            });
            Batch batch(os);
            for (size_t c = 0; c < nc; c++)
                batch.write(out[c]);
            batch.flush();
        }
    }

    // The leaves are in the heap where the threads that made them put
    // them, not in tree order: each one met is a cache miss (60% of
    // bool_bytes' time) unless asked for AHEAD leaves before.
    static constexpr size_t AHEAD = 8;
    static void prefetch(const LeafT *leaf)
    {
        const char *p = reinterpret_cast<const char *>(leaf);
        for (size_t at = 0; at < sizeof(LeafT) && at < 4 * 64; at += 64)
            __builtin_prefetch(p + at);
    }

    template <typename T> static void put(std::ostream &os, const T &v)
    {
        os.write(reinterpret_cast<const char *>(&v), sizeof v);
    }

    // A leaf's value mask as NodeMask::save writes it (its words).
    static void copy_mask(char *p, const typename LeafT::NodeMaskType &m)
    {
        for (openvdb::Index w = 0; w < LeafT::NodeMaskType::WORD_COUNT; w++) {
            const uint64_t word = m.template getWord<uint64_t>(w);
            std::memcpy(p + 8 * w, &word, 8);
        }
    }
    static constexpr size_t MASK_BYTES = LeafT::NodeMaskType::WORD_COUNT * 8;
    static_assert(sizeof(typename LeafT::NodeMaskType::Word) == 8, "64-bit mask words");

    // An internal node's own part of InternalNode::writeTopology: its child
    // and value masks, then its values (a tile's, 0 under a child) as
    // writeCompressedValues writes them.
    template <typename NodeT>
    static void node_header(std::ostream &os, const NodeT &node, bool half)
    {
        node.getChildMask().save(os);
        node.getValueMask().save(os);
        std::unique_ptr<ValueT[]> values(new ValueT[NodeT::NUM_VALUES]);
        std::fill(values.get(), values.get() + NodeT::NUM_VALUES, openvdb::zeroVal<ValueT>());
        for (auto v = node.cbeginValueAll(); v; ++v)
            values[v.pos()] = *v;
        openvdb::io::writeCompressedValues(os, values.get(), NodeT::NUM_VALUES, node.getValueMask(),
                                           node.getChildMask(), half);
    }

    // InternalNode::writeTopology of a lower node: its header, then each
    // leaf's writeTopology (its value mask), here copied into one write
    // rather than a stream write a leaf.
    static void lower_topology(std::ostream &os, const LowerT &node, bool half)
    {
        node_header(os, node, half);
        std::vector<const LeafT *> leaves;
        leaves.reserve(node.getChildMask().countOn());
        for (auto c = node.cbeginChildOn(); c; ++c)
            leaves.push_back(&*c);
        std::string masks(leaves.size() * MASK_BYTES, '\0');
        char *p = &masks[0];
        for (size_t i = 0; i < leaves.size(); i++, p += MASK_BYTES) {
            if (i + AHEAD < leaves.size()) prefetch(leaves[i + AHEAD]);
            copy_mask(p, leaves[i]->getValueMask());
        }
        os.write(masks.data(), (std::streamsize)masks.size());
    }

    // The leaf's writeBuffers: its own, or for a leaf made without values
    // its mask and the bytes of its values' count (tails).
    void write_leaf(std::ostream &os, const LeafT &leaf, const Tails *tails, bool half) const
    {
        if (!unloaded(leaf)) return leaf.writeBuffers(os, half);
        if constexpr (!std::is_same<ValueT, bool>::value)
            if (values_) {
                ValueT v[LeafT::SIZE];
                values_(leaf, v);
                leaf.getValueMask().save(os);
                openvdb::io::writeCompressedValues(os, v, LeafT::SIZE, leaf.getValueMask(),
                                                   typename LeafT::NodeMaskType(), half);
                return;
            }
        const std::string &t = (*tails)[leaf.getValueMask().countOn()];
        leaf.getValueMask().save(os);
        os.write(t.data(), (std::streamsize)t.size());
    }

    bool unloaded(const LeafT &leaf) const
    {
        if constexpr (std::is_same<ValueT, bool>::value) // a bool leaf always holds its values
            return false;
        else
            return by_mask_ && leaf.buffer().empty();
    }

    std::vector<const LeafT *> leaves() const
    {
        std::vector<const LeafT *> out;
        out.reserve(this->constTree().leafCount());
        this->constTree().getNodes(out);
        return out;
    }

  public:
    explicit ParallelGrid(const ValueT &background)
        : GridT(background), by_mask_(false), on_(background)
    {
    }
    // leaves made without values hold on at their active voxels
    ParallelGrid(const ValueT &background, const ValueT &on)
        : GridT(background), by_mask_(true), on_(on)
    {
    }

    // Leaves made without values get theirs from values (made without
    // them: a grid of the two-value constructor), which reads data; bytes:
    // data's size, counted in memUsage.
    void set_values(Values values, std::shared_ptr<void> data, uint64_t bytes)
    {
        values_ = std::move(values);
        values_data_ = std::move(data);
        values_bytes_ = bytes;
    }

    openvdb::Index64 memUsage() const override { return GridT::memUsage() + values_bytes_; }

    void writeTopology(std::ostream &os) const override
    {
        const bool half = this->saveFloatAsHalf();
        const RootT &root = this->constTree().root();
        put(os, int32_t(1)); // TreeBase::writeTopology: the buffer count
        // RootNode::writeTopology
        put(os, half ? openvdb::io::truncateRealToHalf(root.background()) : root.background());
        openvdb::io::setGridBackgroundValuePtr(os, &root.background());
        openvdb::Index tiles = 0;
        for (auto it = root.cbeginValueAll(); it; ++it)
            tiles++;
        const openvdb::Index children = root.childCount();
        put(os, tiles);
        put(os, children);
        if (tiles == 0 && children == 0) return;
        for (auto it = root.cbeginValueAll(); it; ++it) {
            put(os, it.getCoord());
            put(os, *it);
            put(os, bool(it.isValueOn()));
        }
        std::vector<const LowerT *> lower;
        for (auto it = root.cbeginChildOn(); it; ++it) {
            put(os, it.getCoord());
            // InternalNode::writeTopology of the upper node
            const UpperT &up = *it;
            node_header(os, up, half);
            lower.clear();
            for (auto c = up.cbeginChildOn(); c; ++c)
                lower.push_back(&*c);
            in_parallel(os, lower.size(), 1,
                        [&](std::ostream &ss, size_t i) { lower_topology(ss, *lower[i], half); });
        }
    }

    void writeBuffers(std::ostream &os) const override
    {
        if (buffers_.empty()) { // not prepared: written by Archive's own writer
            openvdb::io::DelayedLoadMetadata dl;
            prepare(os, dl);
        }
        Batch batch(os);
        for (std::string &c : buffers_) {
            batch.write(c);
            std::string().swap(c);
        }
        batch.flush();
        buffers_.clear();
        stats_.reset();
    }

    // Leaves a..b of a bool grid: LeafNode<bool>::writeBuffers' bytes
    // (its value mask, origin and values), copied, not three stream writes
    // a leaf.
    std::string bool_bytes(const std::vector<const LeafT *> &all, size_t a, size_t b,
                           Stats &st) const
    {
        constexpr size_t B = 2 * MASK_BYTES + 3 * sizeof(int32_t);
        std::string bytes((b - a) * B, '\0');
        char *p = &bytes[0];
        for (size_t i = a; i < b; i++, p += B) {
            if (i + AHEAD < b) prefetch(all[i + AHEAD]);
            const LeafT &leaf = *all[i];
            const int32_t xyz[3] = {leaf.origin().x(), leaf.origin().y(), leaf.origin().z()};
            copy_mask(p, leaf.getValueMask());
            std::memcpy(p + MASK_BYTES, xyz, sizeof xyz);
            std::memcpy(p + MASK_BYTES + sizeof xyz, leaf.buffer().data(), MASK_BYTES);
            leaf_stats(leaf, st);
        }
        return bytes;
    }

    // Leaves a..b of a float grid (write_leaf's bytes), and where each
    // leaf's end: leaves made without values copied (a mask and its
    // count's tail, from tails: null for a grid without such leaves), a
    // chunk with others through a stream.
    std::string value_bytes(const std::vector<const LeafT *> &all, size_t a, size_t b,
                            const Tails *tails, bool half, uint32_t compression,
                            const ValueT *background, std::vector<size_t> &ends, Stats &st) const
    {
        bool direct = by_mask_ && !values_;
        for (size_t i = a; i < b && direct; i++)
            direct = unloaded(*all[i]);
        if (!direct) {
            std::ostringstream ss;
            openvdb::io::setDataCompression(ss, compression);
            openvdb::io::setGridBackgroundValuePtr(ss, background);
            for (size_t i = a; i < b; i++) {
                write_leaf(ss, *all[i], tails, half);
                ends[i - a] = (size_t)ss.tellp();
                leaf_stats(*all[i], st);
            }
            return ss.str();
        }
        size_t at = 0;
        for (size_t i = a; i < b; i++) {
            if (i + AHEAD < b) prefetch(all[i + AHEAD]);
            ends[i - a] = at += MASK_BYTES + (*tails)[all[i]->getValueMask().countOn()].size();
        }
        std::string bytes(at, '\0');
        char *p = &bytes[0];
        for (size_t i = a; i < b; i++) {
            const std::string &t = (*tails)[all[i]->getValueMask().countOn()];
            copy_mask(p, all[i]->getValueMask());
            std::memcpy(p + MASK_BYTES, t.data(), t.size());
            p += MASK_BYTES + t.size();
            leaf_stats(*all[i], st);
        }
        return bytes;
    }

    // The delayed-load record of the leaves from a whose bytes s holds
    // (each ending at ends): a leaf's bytes are its value mask,
    // writeCompressedValues' kind byte, the inactive values and selection
    // mask that kind names, then the values as written (the size
    // OpenVDB's writeCompressedValuesSize gives, and 8 bytes of count).
    static void delayed_load(const std::string &s, size_t a, const std::vector<size_t> &ends,
                             bool sized, openvdb::io::DelayedLoadMetadata &dl)
    {
        namespace io = openvdb::io;
        size_t at = 0;
        for (size_t k = 0; k < ends.size(); k++) {
            const size_t end = ends[k];
            const int8_t kind = (int8_t)s.at(at + MASK_BYTES);
            size_t head = MASK_BYTES + 1;
            if (kind == io::NO_MASK_AND_ONE_INACTIVE_VAL || kind == io::MASK_AND_ONE_INACTIVE_VAL)
                head += sizeof(ValueT);
            if (kind == io::MASK_AND_TWO_INACTIVE_VALS) head += 2 * sizeof(ValueT);
            if (kind == io::MASK_AND_NO_INACTIVE_VALS || kind == io::MASK_AND_ONE_INACTIVE_VAL ||
                kind == io::MASK_AND_TWO_INACTIVE_VALS)
                head += MASK_BYTES;
            if (end - at < head) throw std::runtime_error("a leaf's buffer is short");
            dl.setMask(a + k, kind);
            if (sized) dl.setCompressedSize(a + k, end - at - head);
            at = end;
        }
    }

    int prepare(std::ostream &os, openvdb::io::DelayedLoadMetadata &dl) const override
    {
        namespace io = openvdb::io;
        constexpr bool has_dl = std::is_floating_point<ValueT>::value;
        const std::vector<const LeafT *> all = leaves();
        const bool half = this->saveFloatAsHalf();
        const uint32_t compression = io::getDataCompression(os);
        const bool sized = compression & (io::COMPRESS_BLOSC | io::COMPRESS_ZIP);
        const ValueT &background = this->constTree().background();
        if (has_dl && !all.empty()) {
            dl.resizeMask(all.size());
            if (sized) dl.resizeCompressedSize(all.size());
        }
        const size_t chunk = 128, nc = (all.size() + chunk - 1) / chunk;
        buffers_.assign(nc, std::string());
        std::vector<Stats> part(nc);
        std::shared_ptr<const Tails> tails;
        if constexpr (!std::is_same<ValueT, bool>::value)
            if (by_mask_ && !values_) tails = tails_for(compression, background, on_, half);
        tbb::parallel_for(size_t(0), nc, [&](size_t c) {
            const size_t a = c * chunk, b = std::min(all.size(), a + chunk);
            if constexpr (std::is_same<ValueT, bool>::value) {
                buffers_[c] = bool_bytes(all, a, b, part[c]);
            } else {
                std::vector<size_t> ends(b - a);
                buffers_[c] = value_bytes(all, a, b, tails.get(), half, compression, &background,
                                          ends, part[c]);
                if (has_dl) delayed_load(buffers_[c], a, ends, sized, dl);
            }
        });
        stats_.reset(new Stats);
        for (const Stats &p : part)
            stats_->add(p);
        const RootT &root = this->constTree().root();
        stats_->mem += sizeof(TreeT) + sizeof(RootT);
        tiles_stats(root, *stats_);
        for (auto it = root.cbeginChildOn(); it; ++it)
            node_stats(*it, *stats_);
        return has_dl;
    }

    uint64_t unloaded_bytes() const override
    {
        uint64_t n = 0;
        if (by_mask_)
            for (const LeafT *leaf : leaves())
                n += unloaded(*leaf) ? LeafT::SIZE * sizeof(ValueT) : 0;
        return n;
    }

    void stats_metadata(openvdb::GridBase &g) const override
    {
        if (!stats_) throw std::logic_error("grid statistics asked for before prepare");
        using openvdb::GridBase;
        for (const char *name : {GridBase::META_FILE_BBOX_MIN, GridBase::META_FILE_BBOX_MAX,
                                 GridBase::META_FILE_MEM_BYTES, GridBase::META_FILE_VOXEL_COUNT})
            g.removeMeta(name);
        g.insertMeta(GridBase::META_FILE_BBOX_MIN,
                     openvdb::Vec3IMetadata(stats_->bbox.min().asVec3i()));
        g.insertMeta(GridBase::META_FILE_BBOX_MAX,
                     openvdb::Vec3IMetadata(stats_->bbox.max().asVec3i()));
        g.insertMeta(GridBase::META_FILE_MEM_BYTES,
                     openvdb::Int64Metadata((int64_t)(stats_->mem + stats_->unloaded)));
        g.insertMeta(GridBase::META_FILE_VOXEL_COUNT,
                     openvdb::Int64Metadata((int64_t)stats_->count));
    }
};

openvdb::FloatGrid::Ptr make_float_grid(float background)
{
    return std::make_shared<ParallelGrid<openvdb::FloatGrid>>(background);
}

// OpenVDB's archive format as io::File writes it (seekable, with grid
// offsets), into a stream of ours. io::File::write does not look at its
// stream after writing, so a full disk gave a short file and no error; this
// stream throws on any failed write, flush or close.
//
// A ParallelGrid is written by write_grid below: Archive::writeGrid's steps
// in its order, but the leaf buffers are written (on all threads) before
// the grid's metadata, and the delayed-load metadata OpenVDB puts there is
// taken from them. Archive::writeGrid computes it by compressing every leaf
// once more, apart from the write (45 ms of a 150 ms fog write at 1024^3).
// vdbcheck compares the whole file with what io::File writes for the grid
// read back.
class CheckedArchive final : public openvdb::io::Archive
{
    // Archive::writeGrid's steps for a prepared grid.
    void write_grid(openvdb::io::GridDescriptor &gd, const openvdb::GridBase::ConstPtr &grid,
                    const Prepared &prep, std::ostream &os) const
    {
        namespace io = openvdb::io;
        struct Restore { // the file's stream metadata, as Archive::writeGrid leaves it
            std::ostream &os;
            io::StreamMetadata::Ptr was;
            ~Restore() { io::setStreamMetadataPtr(os, was, /*transfer=*/false); }
        } restore{os, io::getStreamMetadataPtr(os)};
        io::StreamMetadata::Ptr meta(restore.was ? new io::StreamMetadata(*restore.was)
                                                 : new io::StreamMetadata);
        meta->setHalfFloat(grid->saveFloatAsHalf());
        meta->gridMetadata() = static_cast<const openvdb::MetaMap &>(*grid);
        io::setStreamMetadataPtr(os, meta, /*transfer=*/false);
        gd.writeHeader(os);
        const std::streampos offsets = os.tellp();
        gd.writeStreamPos(os);
        gd.setGridPos(os.tellp());
        setGridCompression(os, *grid);

        const openvdb::GridBase::Ptr copy = openvdb::ConstPtrCast<openvdb::GridBase>(
            grid->copyGrid()); // shallow: the metadata written
        io::DelayedLoadMetadata dl;
        if (prep.prepare(os, dl)) copy->insertMeta(openvdb::GridBase::META_FILE_DELAYED_LOAD, dl);
        if (io::getWriteGridStatsMetadata(os)) {
            prep.stats_metadata(*copy);
            copy->insertMeta(
                openvdb::GridBase::META_FILE_COMPRESSION,
                openvdb::StringMetadata(io::compressionToString(io::getDataCompression(os))));
        }
        copy->writeMeta(os);
        grid->writeTransform(os);
        grid->writeTopology(os);
        gd.setBlockPos(os.tellp());
        grid->writeBuffers(os);
        gd.setEndPos(os.tellp());
        os.seekp(offsets, std::ios_base::beg);
        gd.writeStreamPos(os);
        gd.seekToEnd(os);
    }

    // Archive::write's steps, each grid through write_grid where it can
    // be; false (nothing written) for grids it leaves to Archive::write:
    // names that are empty or not unique (Archive::write suffixes them),
    // a shared tree (an instance), a float grid whose class drops ZIP
    // compression (Archive sizes its delayed-load metadata with it all the
    // same).
    bool write_own(std::ostream &os, const openvdb::GridPtrVec &grids) const
    {
        namespace io = openvdb::io;
        std::set<std::string> names;
        std::set<const openvdb::TreeBase *> trees;
        bool own = true;
        for (const openvdb::GridBase::Ptr &g : grids) {
            const openvdb::GridClass cls = g ? g->getGridClass() : openvdb::GRID_UNKNOWN;
            own = own && g && dynamic_cast<const Prepared *>(g.get()) && !g->getName().empty() &&
                  names.insert(g->getName()).second && trees.insert(&g->constBaseTree()).second &&
                  (g->isType<openvdb::BoolGrid>() ||
                   (cls != openvdb::GRID_LEVEL_SET && cls != openvdb::GRID_FOG_VOLUME) ||
                   !(compression() & io::COMPRESS_ZIP));
        }
        if (!own) { // Archive's writer would read a leaf made without values
            for (const openvdb::GridBase::Ptr &g : grids)
                if (auto *p = dynamic_cast<const Prepared *>(g.get()))
                    if (p->unloaded_bytes())
                        throw std::logic_error("a grid of leaves without values for Archive");
            return false;
        }
        io::StreamMetadata::Ptr meta = io::getStreamMetadataPtr(os);
        if (!meta) {
            meta.reset(new io::StreamMetadata);
            io::setStreamMetadataPtr(os, meta, /*transfer=*/false);
        }
        io::setDataCompression(os, compression());
        io::setWriteGridStatsMetadata(os, isGridStatsMetadataEnabled());
        writeHeader(os, /*seekable=*/true);
        openvdb::MetaMap().writeMeta(os);
        const int32_t count = (int32_t)grids.size();
        os.write(reinterpret_cast<const char *>(&count), sizeof count);
        for (const openvdb::GridBase::Ptr &g : grids) {
            io::GridDescriptor gd(g->getName(), g->type(), g->saveFloatAsHalf());
            write_grid(gd, g, *dynamic_cast<const Prepared *>(g.get()), os);
            io::setDataCompression(os, compression());
        }
        return true;
    }

  public:
    void write_file(const std::string &path, const openvdb::GridPtrVec &grids) const
    {
        // many small writes: through a buffer of 1 MiB, kept by the thread
        // (a new one would fault in each page again), not the 8 KiB default
        static thread_local std::unique_ptr<char[]> buf(new char[1 << 20]);
        std::ofstream os;
        os.rdbuf()->pubsetbuf(buf.get(), 1 << 20);
        os.exceptions(std::ios_base::failbit | std::ios_base::badbit);
        os.open(path, std::ios_base::out | std::ios_base::binary | std::ios_base::trunc);
        if (!write_own(os, grids)) Archive::write(os, grids, /*seekable=*/true, openvdb::MetaMap());
        os.flush();
        os.close();
    }
};

// Frees a grid's tree when grid holds the last reference to it: its leaves
// on the calling thread, then the rest. OpenVDB's Tree::clear deletes the
// leaves on all threads, but they were made on all threads, each in its
// thread's malloc arena, and glibc's free of another arena's block waits on
// that arena's lock: 6-12 ms for spot's 40,000 bool leaves at 1024^3,
// against 1.5-4 ms on one thread.
void release(openvdb::GridBase::Ptr &grid)
{
    auto leaves_of = [](auto &tree) {
        std::vector<typename std::remove_reference<decltype(tree)>::type::LeafNodeType *> leaves;
        leaves.reserve(tree.leafCount()); // stealNodes then cannot throw with leaves taken
        tree.stealNodes(leaves);
        for (auto *leaf : leaves)
            delete leaf;
    };
    try {
        if (grid.use_count() == 1) {
            if (grid->isType<openvdb::BoolGrid>())
                leaves_of(openvdb::gridPtrCast<openvdb::BoolGrid>(grid)->tree());
            else if (grid->isType<openvdb::FloatGrid>())
                leaves_of(openvdb::gridPtrCast<openvdb::FloatGrid>(grid)->tree());
        }
    } catch (const std::exception &) { // no memory for the list: the tree frees them
    }
    grid.reset();
}

} // namespace

// The grids of a .vdb written, kept for the caller to free (io.h).
struct vx_vdb_tree {
    openvdb::GridPtrVec grids;
};

extern "C" uint64_t vx_vdb_tree_bytes(const vx_vdb_tree *t)
{
    uint64_t n = 0;
    for (const openvdb::GridBase::Ptr &grid : t->grids)
        n += grid->memUsage();
    return n;
}

extern "C" void vx_vdb_tree_free(vx_vdb_tree *t)
{
    if (!t) return;
    for (openvdb::GridBase::Ptr &grid : t->grids)
        release(grid);
    delete t;
}

namespace
{

// Builds grids (build(grids) returns 0, or -1 with err set) and writes them
// to path through path.tmp and a rename, inside one try: no exception
// crosses into C, and a failed write leaves no file behind. Then frees
// them, or with keep (not NULL) leaves them in *keep for the caller to free
// later (NULL when the write failed).
template <typename Build>
int write_grids(const char *path, vx_vdb_tree **keep, vx_err *err, Build build)
{
    std::string tmp = std::string(path) + ".tmp";
    if (keep) *keep = nullptr;
    try {
        std::call_once(init_once, [] { openvdb::initialize(); });
        std::unique_ptr<vx_vdb_tree> made(new vx_vdb_tree);
        openvdb::GridPtrVec &grids = made->grids;
        if (build(grids)) return -1;
        CheckedArchive().write_file(tmp, grids);
        if (std::rename(tmp.c_str(), path) != 0) {
            int e_no = errno;
            std::remove(tmp.c_str());
            return vx_err_set(err, VX_EIO, "io_error", "renaming %s failed: %s",
                              tmp.substr(tmp.rfind('/') + 1).c_str(), strerror(e_no));
        }
        if (keep)
            *keep = made.release();
        else
            vx_vdb_tree_free(made.release());
        return 0;
    } catch (const std::bad_alloc &) {
        std::remove(tmp.c_str());
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the OpenVDB grid");
    } catch (const std::ios_base::failure &e) {
        int e_no = errno;
        std::remove(tmp.c_str());
        return vx_err_set(err, VX_EIO, "io_error", "writing the .vdb failed: %s",
                          e_no ? strerror(e_no) : "a stream error");
    } catch (const std::exception &e) {
        std::remove(tmp.c_str());
        return vx_err_set(err, VX_EIO, "io_error", "OpenVDB: %s", e.what());
    }
}

enum { LEAF_EMPTY = 0, LEAF_PART = 1, LEAF_FULL = 2 };

// A leaf's 512 bits in NodeMask order: w[x] bit 8 y + z = voxel (X + x,
// Y + y, Z + z) of the leaf at (X, Y, Z); voxels outside the grid are 0.
//
// The leaf's 64 row bytes b[8 y + z] (bit x) are transposed into the 8
// words: with AVX2 by movemask (bit 7 of each byte, then each byte doubled),
// 16 instructions in place of 64 multiplies.
void transpose_leaf(const uint8_t b[64], uint64_t w[8])
{
    for (int x = 0; x < 8; x++) {
        uint64_t word = 0;
        for (int q = 0; q < 8; q++) {
            uint64_t v;
            memcpy(&v, b + 8 * q, 8); // byte n = row (y = q, z = n)
            // bit x of each of the 8 bytes, gathered into one byte (bit n = byte n)
            uint64_t t = (((v >> x) & 0x0101010101010101ull) * 0x0102040810204080ull) >> 56;
            word |= t << (8 * q);
        }
        w[x] = word;
    }
}

#if defined(__x86_64__)
__attribute__((target("avx2"))) void transpose_leaf_avx2(const uint8_t b[64], uint64_t w[8])
{
    __m256i lo = _mm256_loadu_si256(reinterpret_cast<const __m256i *>(b));
    __m256i hi = _mm256_loadu_si256(reinterpret_cast<const __m256i *>(b + 32));
    for (int x = 7; x >= 0; x--) {
        w[x] = (uint64_t)(uint32_t)_mm256_movemask_epi8(lo) |
               (uint64_t)(uint32_t)_mm256_movemask_epi8(hi) << 32;
        lo = _mm256_add_epi8(lo, lo);
        hi = _mm256_add_epi8(hi, hi);
    }
}
#endif

// The words of partial leaf xl of a row of leaves, from its rows
// (classify_leaves') bytes; xmask: the bits of the leaf inside the grid.
void leaf_words(const uint8_t *const rows[64], int xl, unsigned xmask, uint64_t w[8])
{
    alignas(32) uint8_t b[64]; // b[8 y + z]: bit x
    for (int y = 0; y < 8; y++)
        for (int z = 0; z < 8; z++)
            b[8 * y + z] = (uint8_t)(rows[8 * z + y][xl] & xmask);
#if defined(__x86_64__)
    if (vx_cpu_avx2()) return transpose_leaf_avx2(b, w);
#endif
    transpose_leaf(b, w);
}

// The OR and AND of nrows rows' first lx bytes, into any and all. With
// AVX2 128 bytes at a time in registers (the grid read at memory speed: the
// scalar form loads and stores any and all again for every row).
#if defined(__x86_64__)
__attribute__((target("avx2"))) void or_and_rows_avx2(const uint8_t *const rows[64], int nrows,
                                                      int lx, uint8_t *any, uint8_t *all)
{
    int xl = 0;
    for (; xl + 128 <= lx; xl += 128) {
        __m256i a[4], l[4];
        for (int v = 0; v < 4; v++) {
            a[v] = _mm256_setzero_si256();
            l[v] = _mm256_set1_epi8(-1);
        }
        for (int r = 0; r < nrows; r++)
            for (int v = 0; v < 4; v++) {
                const __m256i x =
                    _mm256_loadu_si256(reinterpret_cast<const __m256i *>(rows[r] + xl + 32 * v));
                a[v] = _mm256_or_si256(a[v], x);
                l[v] = _mm256_and_si256(l[v], x);
            }
        for (int v = 0; v < 4; v++) {
            _mm256_storeu_si256(reinterpret_cast<__m256i *>(any + xl + 32 * v), a[v]);
            _mm256_storeu_si256(reinterpret_cast<__m256i *>(all + xl + 32 * v), l[v]);
        }
    }
    for (; xl + 32 <= lx; xl += 32) {
        __m256i a = _mm256_setzero_si256(), l = _mm256_set1_epi8(-1);
        for (int r = 0; r < nrows; r++) {
            const __m256i x = _mm256_loadu_si256(reinterpret_cast<const __m256i *>(rows[r] + xl));
            a = _mm256_or_si256(a, x);
            l = _mm256_and_si256(l, x);
        }
        _mm256_storeu_si256(reinterpret_cast<__m256i *>(any + xl), a);
        _mm256_storeu_si256(reinterpret_cast<__m256i *>(all + xl), l);
    }
    for (; xl < lx; xl++) {
        uint8_t a = 0, l = 0xff;
        for (int r = 0; r < nrows; r++) {
            a |= rows[r][xl];
            l &= rows[r][xl];
        }
        any[xl] = a;
        all[xl] = l;
    }
}
#endif

void or_and_rows(const uint8_t *const rows[64], int nrows, int lx, uint8_t *any, uint8_t *all)
{
#if defined(__x86_64__)
    if (vx_cpu_avx2()) return or_and_rows_avx2(rows, nrows, lx, any, all);
#endif
    memset(any, 0, (size_t)lx);
    memset(all, 0xff, (size_t)lx);
    for (int r = 0; r < nrows; r++) {
        const uint8_t *row = rows[r];
        int xl = 0;
        for (; xl + 8 <= lx; xl += 8) { // eight leaves a word
            uint64_t x, a, l;
            memcpy(&x, row + xl, 8);
            memcpy(&a, any + xl, 8);
            memcpy(&l, all + xl, 8);
            a |= x;
            l &= x;
            memcpy(any + xl, &a, 8);
            memcpy(all + xl, &l, 8);
        }
        for (; xl < lx; xl++) {
            any[xl] |= row[xl];
            all[xl] &= row[xl];
        }
    }
}

// The kinds of a row of leaves (Y = 8 yl, Z = 8 zl; kind[xl] for X = 8 xl):
// LEAF_EMPTY, LEAF_PART or LEAF_FULL, from the leaves' rows ORed and ANDed,
// so that only partial leaves need leaf_words' transposes. scratch: 3 lx
// bytes, the last lx of them zero; rows[8 z + y]: the leaves' rows (Y + y,
// Z + z), scratch's zeros for rows outside the grid.
void classify_leaves(const vx_bitgrid *g, int yl, int zl, uint8_t *scratch, uint8_t *kind,
                     const uint8_t *rows[64])
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    const int lx = (nx + 7) / 8;
    uint8_t *any = scratch, *all = scratch + lx, *zero = scratch + 2 * lx;
    const uint8_t *in[64];
    int nrows = 0;
    for (int z = 0; z < 8; z++)
        for (int y = 0; y < 8; y++) {
            const int j = 8 * yl + y, k = 8 * zl + z;
            const uint8_t *row =
                j < ny && k < nz ? (const uint8_t *)(g->bits + ((size_t)k * ny + j) * g->wx) : zero;
            rows[8 * z + y] = row;
            if (row != zero) in[nrows++] = row;
        }
    or_and_rows(in, nrows, lx, any, all);
    if (nrows < 64) // voxels outside the grid are 0
        memset(all, 0, (size_t)lx);
    if (nx & 7) { // the last leaf is cut by the grid's end
        any[lx - 1] &= (uint8_t)((1u << (nx & 7)) - 1u);
        all[lx - 1] = 0;
    }
    for (int xl = 0; xl < lx; xl++)
        kind[xl] = !any[xl] ? LEAF_EMPTY : all[xl] == 0xff ? LEAF_FULL : LEAF_PART;
}

// Counts-based fog leaf: value count / nsamples, active where count > 0.
template <typename LeafT> int coverage_leaf(const vx_bitgrid *g, int X, int Y, int Z, LeafT *&out)
{
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    int on = 0, full = 0;
    float vals[512];
    bool act[512];
    for (int x = 0; x < 8; x++)
        for (int y = 0; y < 8; y++)
            for (int z = 0; z < 8; z++) {
                const int i = X + x, j = Y + y, k = Z + z, n = 64 * x + 8 * y + z;
                int c = i < nx && j < ny && k < nz ? g->counts[((size_t)k * ny + j) * nx + i] : 0;
                vals[n] = c ? (float)c / (float)g->nsamples : 0.0f;
                act[n] = c > 0;
                on += c > 0;
                full += c == g->nsamples;
            }
    if (!on) return LEAF_EMPTY;
    if (full == 512) return LEAF_FULL;
    out = new LeafT(openvdb::Coord(X, Y, Z), 0.0f, false);
    float *d = out->buffer().data();
    for (int n = 0; n < 512; n++) {
        d[n] = vals[n];
        if (act[n]) out->getValueMask().setOn((openvdb::Index)n);
    }
    return LEAF_PART;
}

// A leaf holds 512 voxels: a value mask (64 B) plus a bool mask (64 B) or
// 512 floats (2 KiB), ~100 B of node overhead; the file buffer is about the
// same again (compression works per leaf). A 0/1 fog leaf is made without
// its floats (its buffer, ~150 B, is held from prepare to the write). A
// level set's band is up to 3 leaves a partial leaf (~1.7 on spot), each
// made without floats (~100 B) with a byte a voxel for them (512 B and its
// index entry), and a buffer of at most its 512 floats (2.2 KiB with its
// masks): 1,500 B a leaf, doubled, holds both.
uint64_t leaf_bytes(vx_vdb_class cls, int coverage)
{
    return coverage ? 2300 : cls == VX_VDB_LEVEL_SET ? 3 * 1500 : 240;
}

// Bytes a tree of the grid g's dims with `partial` leaves of part_bytes
// each and `full` leaf tiles holds, with its internal nodes (one of 16^3
// children per 128^3 voxels, ~64 KiB each), and its file buffer about as
// much again.
uint64_t tree_bytes(const vx_bitgrid *g, uint64_t partial, uint64_t full, uint64_t part_bytes)
{
    const uint64_t lx = (g->grid.dims[0] + 7) / 8, ly = (g->grid.dims[1] + 7) / 8,
                   lz = (g->grid.dims[2] + 7) / 8;
    const uint64_t nodes = lx * ly * lz / 4096 + 1;
    return (partial * part_bytes + full * 64 + nodes * 65536) * 2;
}

// Whether node (a leaf or an internal node) holds one value in one state, as
// tools::prune tells with tolerance 0 (it then takes the values' median:
// the same number).
template <typename NodeT>
bool is_constant(const NodeT &node, typename NodeT::ValueType &value, bool &state)
{
    using ValueT = typename NodeT::ValueType;
    if constexpr (std::is_same<ValueT, bool>::value) {
        return node.isConstant(value, state, false);
    } else {
        ValueT hi;
        return node.isConstant(value, hi, state, openvdb::zeroVal<ValueT>());
    }
}

// at: the index of voxel (0,0,0) in the tree (multiples of 8: a brick).
//
// The tree is made a lower internal node (16^3 leaves of the tree's index
// space) at a time, each node whole before the tree takes it: no leaf or
// tile goes through the root's map, and what tools::prune did after (a
// constant leaf or lower node becomes a tile of its parent) is done as each
// node is finished, by the thread that made it. A task makes a row of lower
// nodes along x (it reads whole grid rows, as classify_leaves does: nodes
// side by side in x share the rows' cache lines). Rows are made on all
// threads, in 8 rounds of 2 of each node's 16 z slabs (progress between).
// make(X, Y, Z, w, leaf) returns the kind of the leaf at (X, Y, Z) and
// makes it (leaf) when partial. by_bits: the kinds come from the bit grid
// (classify_leaves), and make is asked for partial leaves only, given
// their words w (leaf_words); else w is null.
template <typename TreeT, typename MakeLeaf>
int build_tree(const vx_bitgrid *g, TreeT &tree, const typename TreeT::ValueType &on,
               const openvdb::Coord &at, const vx_voxel_io *io, double span, vx_err *err,
               bool by_bits, MakeLeaf make)
{
    using RootT = typename TreeT::RootNodeType;
    using UpperT = typename RootT::ChildNodeType;
    using LowerT = typename UpperT::ChildNodeType;
    using LeafT = typename TreeT::LeafNodeType;
    using ValueT = typename TreeT::ValueType;
    using Tile = std::tuple<openvdb::Coord, ValueT, bool>;
    const int nx = g->grid.dims[0], ny = g->grid.dims[1], nz = g->grid.dims[2];
    const int lx = (nx + 7) / 8, ly = (ny + 7) / 8, lz = (nz + 7) / 8;
    // grid leaf l is tree leaf l + a, in lower node (l + a) >> 4 (b to e)
    const int ax = at.x() >> 3, ay = at.y() >> 3, az = at.z() >> 3;
    const int bx = ax >> 4, by = ay >> 4, bz = az >> 4;
    const int ex = (ax + lx - 1) >> 4, ey = (ay + ly - 1) >> 4, ez = (az + lz - 1) >> 4;
    const int rows = (ey - by + 1) * (ez - bz + 1), per_row = ex - bx + 1;
    constexpr int ROUNDS = 8, SLABS = 16 / ROUNDS;
    const ValueT bg = tree.background();
    struct Row { // a row's nodes while made, then what the tree takes
        std::vector<std::unique_ptr<LowerT>> making, nodes;
        std::vector<Tile> tiles; // nodes of one value
    };
    std::vector<Row> made((size_t)rows);
    for (int round = 0; round < ROUNDS; round++) {
        if (io && io->progress && io->progress(io->ud, span * round / ROUNDS, err)) return -1;
        tbb::parallel_for(
            tbb::blocked_range<int>(0, rows, 1), [&](const tbb::blocked_range<int> &r) {
                std::vector<uint8_t> scratch(by_bits ? 4 * (size_t)lx : 0);
                uint8_t *kinds = scratch.data() + 3 * (size_t)lx;
                const uint8_t *leaf_rows[64];
                for (int t = r.begin(); t < r.end(); t++) {
                    const int cy = by + t % (ey - by + 1), cz = bz + t / (ey - by + 1);
                    const int yl0 = std::max(0, 16 * cy - ay),
                              yl1 = std::min(ly, 16 * cy + 16 - ay);
                    const int z0 = 16 * cz + SLABS * round - az;
                    const int zl0 = std::max(0, z0), zl1 = std::min(lz, z0 + SLABS);
                    Row &row = made[(size_t)t];
                    if (row.making.empty()) row.making.resize((size_t)per_row);
                    for (int zl = zl0; zl < zl1; zl++) {
                        for (int yl = yl0; yl < yl1; yl++) {
                            if (by_bits)
                                classify_leaves(g, yl, zl, scratch.data(), kinds, leaf_rows);
                            for (int xl = 0; xl < lx; xl++) {
                                LeafT *leaf = nullptr;
                                int kind;
                                if (!by_bits) {
                                    kind = make(8 * xl, 8 * yl, 8 * zl, nullptr, leaf);
                                } else if ((kind = kinds[xl]) == LEAF_PART) {
                                    uint64_t w[8];
                                    leaf_words(
                                        leaf_rows, xl,
                                        nx - 8 * xl >= 8 ? 0xffu : (1u << (nx - 8 * xl)) - 1u, w);
                                    make(8 * xl, 8 * yl, 8 * zl, w, leaf);
                                }
                                if (kind == LEAF_EMPTY) continue;
                                std::unique_ptr<LeafT> owned(leaf);
                                const openvdb::Coord xyz =
                                    openvdb::Coord(8 * xl, 8 * yl, 8 * zl) + at;
                                std::unique_ptr<LowerT> &node =
                                    row.making[(size_t)(((xl + ax) >> 4) - bx)];
                                if (!node) node.reset(new LowerT(xyz, bg, false));
                                if (kind == LEAF_FULL) {
                                    node->addTile(LowerT::coordToOffset(xyz), on, true);
                                } else {
                                    leaf->setOrigin(xyz);
                                    node->addLeaf(owned.release());
                                }
                            }
                        }
                    }
                    if (round < ROUNDS - 1) continue;
                    // the row is whole: what tools::prune made of its nodes
                    for (std::unique_ptr<LowerT> &node : row.making) {
                        if (!node) continue;
                        ValueT v;
                        bool state;
                        // (a leaf made from bits has on and off voxels)
                        if (!by_bits)
                            for (auto it = node->beginChildOn(); it; ++it)
                                if (is_constant(*it, v, state)) node->addTile(it.pos(), v, state);
                        if (is_constant(*node, v, state))
                            row.tiles.emplace_back(node->origin(), v, state);
                        else
                            row.nodes.push_back(std::move(node));
                        node.reset();
                    }
                }
            });
    }
    RootT &root = tree.root();
    auto upper = [&](const openvdb::Coord &c) {
        UpperT *up = root.template probeNode<UpperT>(c);
        if (!up) {
            std::unique_ptr<UpperT> u(new UpperT(c, bg, false));
            root.addChild(u.get());
            up = u.release();
        }
        return up;
    };
    for (Row &row : made) {
        for (std::unique_ptr<LowerT> &node : row.nodes) {
            upper(node->origin())->addChild(node.get());
            node.release();
        }
        for (const Tile &c : row.tiles)
            upper(std::get<0>(c))
                ->addTile(UpperT::coordToOffset(std::get<0>(c)), std::get<1>(c), std::get<2>(c));
    }
    // and the last step of tools::prune: upper nodes of one value become root tiles
    std::vector<Tile> tops;
    for (auto it = root.beginChildOn(); it; ++it) {
        ValueT v;
        bool state;
        if (is_constant(*it, v, state)) tops.emplace_back(it.getCoord(), v, state);
    }
    for (const Tile &c : tops)
        root.addTile(std::get<0>(c), std::get<1>(c), std::get<2>(c));
    root.eraseBackgroundTiles();
    return 0;
}

openvdb::BoolGrid::Ptr bool_grid(const vx_bitgrid *g, const openvdb::Coord &at,
                                 const vx_voxel_io *io, double span, vx_err *err)
{
    openvdb::BoolGrid::Ptr grid = std::make_shared<ParallelGrid<openvdb::BoolGrid>>(false);
    using LeafT = openvdb::BoolGrid::TreeType::LeafNodeType;
    int rc = build_tree(g, grid->tree(), true, at, io, span, err, true,
                        [](int X, int Y, int Z, const uint64_t *w, LeafT *&out) {
                            out = new LeafT(openvdb::Coord(X, Y, Z), false, false);
                            uint64_t *buf = out->buffer().data();
                            for (int x = 0; x < 8; x++) {
                                out->getValueMask().template getWord<uint64_t>(x) = w[x];
                                buf[x] = w[x];
                            }
                            return (int)LEAF_PART;
                        });
    if (rc) return nullptr;
    grid->setTransform(transform_of(g->grid));
    return grid;
}

openvdb::FloatGrid::Ptr fog_grid(const vx_bitgrid *g, const openvdb::Coord &at,
                                 const vx_voxel_io *io, double span, vx_err *err)
{
    using LeafT = openvdb::FloatGrid::TreeType::LeafNodeType;
    int rc;
    openvdb::FloatGrid::Ptr grid;
    if (g->counts) {
        grid = make_float_grid(0.0f);
        rc = build_tree(g, grid->tree(), 1.0f, at, io, span, err, false,
                        [g](int X, int Y, int Z, const uint64_t *, LeafT *&out) {
                            return coverage_leaf(g, X, Y, Z, out);
                        });
    } else { // leaves of masks only, their values made as they are written
        grid = std::make_shared<ParallelGrid<openvdb::FloatGrid>>(0.0f, 1.0f);
        rc = build_tree(g, grid->tree(), 1.0f, at, io, span, err, true,
                        [](int X, int Y, int Z, const uint64_t *w, LeafT *&out) {
                            out = new LeafT(openvdb::PartialCreate(), openvdb::Coord(X, Y, Z), 0.0f,
                                            false);
                            for (int x = 0; x < 8; x++)
                                out->getValueMask().template getWord<uint64_t>(x) = w[x];
                            return (int)LEAF_PART;
                        });
    }
    if (rc) return nullptr;
    grid->setTransform(transform_of(g->grid));
    grid->setGridClass(openvdb::GRID_FOG_VOLUME);
    return grid;
}

// OpenVDB's signedFloodFill on the inactive tiles of a level set's
// internal nodes and root, their signs taken from each child's first and
// last voxel as it takes them (first_neg, last_neg: whether that voxel's
// value is negative), for a tree whose leaves hold no values. NodeT: an
// internal node, its children done first.
template <typename NodeT, typename FirstNeg, typename LastNeg>
void flood_node(NodeT &node, float inside, float outside, FirstNeg first_neg, LastNeg last_neg)
{
    using openvdb::Index;
    const typename NodeT::NodeMaskType &cm = node.getChildMask();
    const typename NodeT::UnionType *table = node.getTable();
    const Index first = cm.findFirstOn();
    if (first >= NodeT::NUM_VALUES) {
        const float v = table[0].getValue() < 0 ? inside : outside;
        for (Index n = 0; n < NodeT::NUM_VALUES; n++)
            node.addTile(n, v, false);
        return;
    }
    constexpr Index D = 1 << NodeT::LOG2DIM;
    bool xin = first_neg(*table[first].getChild()), yin, zin;
    for (Index x = 0; x != D; x++) {
        const Index x00 = x << (2 * NodeT::LOG2DIM);
        if (cm.isOn(x00)) xin = last_neg(*table[x00].getChild());
        yin = xin;
        for (Index y = 0; y != D; y++) {
            const Index xy0 = x00 + (y << NodeT::LOG2DIM);
            if (cm.isOn(xy0)) yin = last_neg(*table[xy0].getChild());
            zin = yin;
            for (Index z = 0; z != D; z++) {
                const Index xyz = xy0 + z;
                if (cm.isOn(xyz))
                    zin = last_neg(*table[xyz].getChild());
                else
                    node.addTile(xyz, zin ? inside : outside, false);
            }
        }
    }
}

// The level set of rows (band.h): the narrow band, values -d h at set
// voxels and d h at unset ones, the inactive voxels of a leaf -3h or 3h by
// their state; the inactive tiles -3h or 3h as OpenVDB's signedFloodFill
// gives them, then pruneLevelSet. The leaves are made without values
// (their masks only): each keeps a byte a voxel, its level and (bit 4) its
// state, from which the writer makes its floats (512 bytes in place of 2
// KiB a leaf, and no pass over the floats to flood-fill them).
// hold(zl0, zl1) makes the rows that z slabs zl0..zl1 (z = 8 zl) read
// held; progress moves from f0 to f1.
template <typename Hold>
openvdb::FloatGrid::Ptr band_grid(vx_band_rows &rows, const openvdb::Coord &at, double h, Hold hold,
                                  const vx_voxel_io *io, double f0, double f1, vx_err *err)
{
    using LeafT = openvdb::FloatGrid::TreeType::LeafNodeType;
    using Code = std::array<uint8_t, LeafT::SIZE>; // a voxel's level | its state << 7
    // 3 voxels, rounded up as a float: checkLevelSet wants the background
    // at least 3 voxels in double, and (float)(3 h) is below it for h 0.01
    float bg = (float)(VX_BAND_HALF * h);
    if ((double)bg < VX_BAND_HALF * h && bg < std::numeric_limits<float>::max())
        bg = std::nextafter(bg, std::numeric_limits<float>::infinity());
    auto grid = std::make_shared<ParallelGrid<openvdb::FloatGrid>>(bg, bg);
    const int ny = rows.dims[1], nz = rows.dims[2];
    const int W = vx_band_columns(&rows);
    std::array<float, 2 * 16> dist; // [l | state << 4]: the value of level l
    dist.fill(0.0f);
    for (int l = 0; l <= VX_BAND_LEVELS; l++) {
        dist[(size_t)l] = l ? (float)(0.5 * std::sqrt((double)vx_band_q[l]) * h) : bg;
        dist[(size_t)l + 16] = -dist[(size_t)l];
    }
    // slabs zl from -1 and y chunks from y = -8: the band reaches 3 voxels out
    const int zl_end = (nz + VX_BAND_HALF - 1) / 8 + 1;
    const int chunks = (ny + VX_BAND_HALF + 8 + VX_BAND_TY - 1) / VX_BAND_TY;
    const int per_round = std::max(1, 16 / chunks);
    struct Task { // owns its leaves until the tree takes them
        std::vector<LeafT *> leaves;
        std::vector<Code> codes;
        ~Task()
        {
            for (LeafT *l : leaves)
                delete l;
        }
    };
    struct Codes { // the leaves' codes, held with the grid
        std::vector<std::vector<Code>> blocks;
        std::unordered_map<const LeafT *, const Code *> of;
    };
    auto codes = std::make_shared<Codes>();
    uint64_t code_bytes = 0;
    std::vector<Task> tasks((size_t)per_round * chunks);
    for (int zl0 = -1; zl0 < zl_end; zl0 += per_round) {
        const int zl1 = std::min(zl_end - 1, zl0 + per_round - 1);
        if (io && io->progress &&
            io->progress(io->ud, f0 + (f1 - f0) * (zl0 + 1) / (zl_end + 1), err))
            return nullptr;
        if (hold(zl0, zl1)) return nullptr;
        const int n = (zl1 - zl0 + 1) * chunks;
        tbb::parallel_for(tbb::blocked_range<int>(0, n, 1), [&](const tbb::blocked_range<int> &r) {
            static thread_local std::vector<uint64_t> scratch;
            static thread_local std::vector<uint8_t> need, lev;
            static thread_local std::vector<std::array<int, 3>> found;
            scratch.resize(vx_band_scratch_bytes(&rows) / 8);
            need.resize((size_t)W);
            lev.resize((size_t)8 * VX_BAND_TY * W * 64);
            const size_t zs = (size_t)VX_BAND_TY * W * 64, ys = (size_t)W * 64;
            for (int t = r.begin(); t < r.end(); t++) {
                const int z0 = 8 * (zl0 + t / chunks), y0 = -8 + VX_BAND_TY * (t % chunks);
                vx_band_task(&rows, z0, y0, scratch.data(), need.data(), lev.data());
                // the leaves holding band voxels: (column, y and x in it)
                found.clear();
                for (int p = 0; p < W; p++) {
                    if (!need[(size_t)p]) continue;
                    for (int yy = 0; yy < VX_BAND_TY; yy += 8)
                        for (int xx = 0; xx < 64; xx += 8) {
                            const uint8_t *l0 = lev.data() + ((size_t)yy * W + p) * 64 + xx;
                            uint64_t any = 0;
                            for (int z = 0; z < 8; z++)
                                for (int y = 0; y < 8; y++) {
                                    uint64_t v;
                                    memcpy(&v, l0 + z * zs + y * ys, 8);
                                    any |= v;
                                }
                            if (any) found.push_back({p, yy, xx});
                        }
                }
                Task &task = tasks[(size_t)t];
                task.leaves.reserve(found.size());
                task.codes.resize(found.size());
                for (size_t f = 0; f < found.size(); f++) {
                    const int p = found[f][0], yy = found[f][1], xx = found[f][2];
                    const uint8_t *l0 = lev.data() + ((size_t)yy * W + p) * 64 + xx;
                    const int X = 64 * (p - 1) + xx, Y = y0 + yy;
                    uint8_t *c = task.codes[f].data();
                    uint64_t mask[8] = {0};
                    for (int y = 0; y < 8; y++)
                        for (int z = 0; z < 8; z++) {
                            const unsigned set = vx_band_byte(&rows, X, Y + y, z0 + z);
                            for (int x = 0; x < 8; x++) {
                                const unsigned l = l0[z * zs + y * ys + x];
                                c[64 * x + 8 * y + z] = (uint8_t)(l | (set >> x & 1u) << 4);
                                mask[x] |= (uint64_t)(l != 0) << (8 * y + z);
                            }
                        }
                    LeafT *leaf = new LeafT(openvdb::PartialCreate(), openvdb::Coord(X, Y, z0) + at,
                                            bg, false);
                    for (int x = 0; x < 8; x++)
                        leaf->getValueMask().template getWord<uint64_t>((openvdb::Index)x) =
                            mask[x];
                    task.leaves.push_back(leaf);
                }
            }
        });
        for (int t = 0; t < n; t++) {
            Task &task = tasks[(size_t)t];
            if (task.leaves.empty()) continue;
            codes->blocks.push_back(std::move(task.codes));
            const Code *c = codes->blocks.back().data();
            for (size_t i = 0; i < task.leaves.size(); i++) {
                codes->of.emplace(task.leaves[i], c + i);
                grid->tree().addLeaf(task.leaves[i]);
            }
            code_bytes += task.leaves.size() * (sizeof(Code) + 4 * sizeof(void *));
            task.leaves.clear();
            task.codes = std::vector<Code>();
        }
    }
    const Codes &cs = *codes;
    auto code_of = [&cs](const LeafT &leaf) -> const Code & { return *cs.of.at(&leaf); };
    // inactive tiles: a leaf's first or last voxel's sign is its state
    auto leaf_first = [&](const LeafT &l) { return (code_of(l)[0] & 16u) != 0; };
    auto leaf_last = [&](const LeafT &l) { return (code_of(l)[LeafT::SIZE - 1] & 16u) != 0; };
    using TreeT = openvdb::FloatTree;
    using RootT = TreeT::RootNodeType;
    using UpperT = RootT::ChildNodeType;
    using LowerT = UpperT::ChildNodeType;
    std::vector<LowerT *> lower;
    std::vector<UpperT *> upper;
    grid->tree().getNodes(lower);
    grid->tree().getNodes(upper);
    tbb::parallel_for(size_t(0), lower.size(),
                      [&](size_t i) { flood_node(*lower[i], -bg, bg, leaf_first, leaf_last); });
    // a lower node's first and last voxel: its first or last slot's
    auto node_end = [&](const LowerT &node, openvdb::Index n) {
        return node.getChildMask().isOn(n) ? (n ? leaf_last(*node.getTable()[n].getChild())
                                                : leaf_first(*node.getTable()[n].getChild()))
                                           : node.getTable()[n].getValue() < 0;
    };
    tbb::parallel_for(size_t(0), upper.size(), [&](size_t i) {
        flood_node(
            *upper[i], -bg, bg, [&](const LowerT &c) { return node_end(c, 0); },
            [&](const LowerT &c) { return node_end(c, LowerT::NUM_VALUES - 1); });
    });
    // the root: inside tiles between children of one z line whose facing
    // ends are inside
    auto upper_end = [&](const UpperT &node, openvdb::Index n) {
        return node.getChildMask().isOn(n)
                   ? node_end(*node.getTable()[n].getChild(), n ? LowerT::NUM_VALUES - 1 : 0)
                   : node.getTable()[n].getValue() < 0;
    };
    RootT &root = grid->tree().root();
    std::vector<const UpperT *> tops;
    for (auto it = root.cbeginChildOn(); it; ++it)
        tops.push_back(&*it);
    for (size_t i = 1; i < tops.size(); i++) {
        const openvdb::Coord a = tops[i - 1]->origin(), b = tops[i]->origin(), d = b - a;
        if (d[0] != 0 || d[1] != 0 || d[2] == (int)UpperT::DIM) continue;
        if (!upper_end(*tops[i - 1], UpperT::NUM_VALUES - 1) || !upper_end(*tops[i], 0)) continue;
        for (openvdb::Coord c = a + openvdb::Coord(0, 0, UpperT::DIM); c[2] != b[2];
             c[2] += UpperT::DIM)
            root.addTile(c, -bg, false);
    }
    openvdb::tools::pruneLevelSet(grid->tree());
    grid->set_values(
        [codes, dist](const LeafT &leaf, float *v) {
            const Code &c = *codes->of.at(&leaf);
            for (size_t n = 0; n < LeafT::SIZE; n++)
                v[n] = dist[c[n]];
        },
        codes, code_bytes);
    grid->setGridClass(openvdb::GRID_LEVEL_SET);
    return grid;
}

// A bool tree's set voxels as rows for band_grid (grid index 0 at tree
// index 0), held a few z slabs at a time: its leaves and active tiles are
// listed by z slab once, and hold(zl0, zl1) fills rows 8 zl0 - 8 to
// 8 zl1 + 16 from them.
struct TreeRows {
    using LeafT = openvdb::BoolTree::LeafNodeType;
    int dims[3];
    size_t wx;
    std::vector<std::vector<const LeafT *>> leaves; // by z slab
    std::vector<std::vector<openvdb::CoordBBox>> tiles;
    std::vector<uint32_t> buf;

    TreeRows(const openvdb::BoolTree &tree, const int d[3])
    {
        memcpy(dims, d, sizeof dims);
        wx = ((size_t)dims[0] + 31) / 32;
        const int lz = (dims[2] + 7) / 8;
        leaves.resize((size_t)lz);
        tiles.resize((size_t)lz);
        for (auto it = tree.cbeginLeaf(); it; ++it) {
            const int zl = it->origin().z() >> 3;
            if (zl >= 0 && zl < lz) leaves[(size_t)zl].push_back(&*it);
        }
        const openvdb::CoordBBox box(openvdb::Coord(0),
                                     openvdb::Coord(dims[0] - 1, dims[1] - 1, dims[2] - 1));
        auto it = tree.cbeginValueOn();
        it.setMaxDepth(openvdb::BoolTree::ValueOnCIter::LEAF_DEPTH - 1);
        for (; it; ++it) {
            if (!it.isTileValue()) continue;
            openvdb::CoordBBox bb;
            it.getBoundingBox(bb);
            bb.intersect(box);
            if (bb.empty()) continue;
            for (int zl = bb.min().z() >> 3; zl <= bb.max().z() >> 3; zl++)
                tiles[(size_t)zl].push_back(bb);
        }
    }

    static size_t window_bytes(const int d[3])
    {
        return (size_t)24 * d[1] * (((size_t)d[0] + 31) / 32) * 4;
    }

    int hold(vx_band_rows &rows, int zl0, int zl1)
    {
        const int k0 = std::max(0, 8 * zl0 - 8), k1 = std::min(dims[2], 8 * zl1 + 16);
        const size_t rw = wx, plane = (size_t)dims[1] * rw;
        buf.assign(k1 > k0 ? (size_t)(k1 - k0) * plane : 0, 0u);
        auto set = [&](int i, int j, int k) {
            buf[(size_t)(k - k0) * plane + (size_t)j * rw + (size_t)(i >> 5)] |= 1u << (i & 31);
        };
        for (int zl = k0 >> 3; zl < (k1 + 7) >> 3; zl++) {
            for (const LeafT *leaf : leaves[(size_t)zl]) {
                const openvdb::Coord o = leaf->origin();
                for (auto v = leaf->getValueMask().beginOn(); v; ++v) {
                    const int n = (int)v.pos();
                    const int i = o.x() + (n >> 6), j = o.y() + ((n >> 3) & 7), k = o.z() + (n & 7);
                    if (i < dims[0] && j < dims[1] && k >= k0 && k < k1) set(i, j, k);
                }
            }
            for (const openvdb::CoordBBox &bb : tiles[(size_t)zl])
                for (int k = std::max(bb.min().z(), std::max(k0, 8 * zl));
                     k <= std::min(bb.max().z(), std::min(k1 - 1, 8 * zl + 7)); k++)
                    for (int j = bb.min().y(); j <= bb.max().y(); j++) {
                        // bits x0..x1 of the row, a word at a time
                        uint32_t *row = buf.data() + (size_t)(k - k0) * plane + (size_t)j * rw;
                        const int x0 = bb.min().x(), x1 = bb.max().x();
                        for (int w = x0 >> 5; w <= x1 >> 5; w++) {
                            const int a = std::max(x0 - 32 * w, 0), b = std::min(x1 - 32 * w, 31);
                            row[w] |=
                                (uint32_t)((((uint64_t)2 << b) - 1) & ~(((uint64_t)1 << a) - 1));
                        }
                    }
        }
        rows.bits = buf.data();
        rows.k0 = k0;
        rows.k1 = k1;
        return 0;
    }
};

} // namespace

// OpenVDB's ScaleMap refuses h^3 under 3 Tolerance<double> (3e-15); the
// scale it checks is taken back from the map's matrix, translation and all,
// and may be an ulp or two under h: a margin of 1e-6 on h^3 keeps clear.
extern "C" int vx_vdb_voxel_size_ok(double h)
{
    return h > 0 && std::isfinite(h) &&
           h * h * h >= 3.0 * openvdb::math::Tolerance<double>::value() * (1 + 1e-6);
}

extern "C" double vx_vdb_min_voxel_size(void)
{
    double h = std::cbrt(3.0 * openvdb::math::Tolerance<double>::value() * (1 + 1e-6));
    while (!vx_vdb_voxel_size_ok(h))
        h = std::nextafter(h, HUGE_VAL);
    return h;
}

extern "C" double vx_vdb_max_voxel_size(int cls)
{
    return cls == VX_VDB_LEVEL_SET ? (double)FLT_MAX / VX_BAND_HALF : HUGE_VAL;
}

extern "C" uint64_t vx_voxel_vdb_bytes(const int dims[3], vx_vdb_class cls, int coverage)
{
    uint64_t n = (uint64_t)dims[0] * (uint64_t)dims[1] * (uint64_t)dims[2];
    uint64_t leaves = n / 512 + 1;
    // A 0/1 fog grid's leaves hold masks only, as bool ones do; a level
    // set's band follows the partial leaves, known from the grid
    // (vx_voxel_vdb_grid_bytes): here the topology, as for bool.
    if ((cls == VX_VDB_FOG || cls == VX_VDB_LEVEL_SET) && !coverage) cls = VX_VDB_BOOL;
    return leaves * leaf_bytes(cls, coverage) * 2;
}

extern "C" uint64_t vx_voxel_vdb_grid_bytes(const vx_bitgrid *g, vx_vdb_class cls)
{
    if (g->counts || cls != VX_VDB_LEVEL_SET)
        return vx_voxel_vdb_bytes(g->grid.dims, cls, g->counts != 0);
    const int lx = (g->grid.dims[0] + 7) / 8, ly = (g->grid.dims[1] + 7) / 8,
              lz = (g->grid.dims[2] + 7) / 8;
    std::atomic<uint64_t> partial{0}, full{0};
    tbb::parallel_for(tbb::blocked_range<int>(0, lz), [&](const tbb::blocked_range<int> &r) {
        uint64_t p = 0, f = 0;
        std::vector<uint8_t> scratch(4 * (size_t)lx);
        uint8_t *kinds = scratch.data() + 3 * (size_t)lx;
        const uint8_t *rows[64];
        for (int zl = r.begin(); zl < r.end(); zl++)
            for (int yl = 0; yl < ly; yl++) {
                classify_leaves(g, yl, zl, scratch.data(), kinds, rows);
                for (int xl = 0; xl < lx; xl++) {
                    p += kinds[xl] == LEAF_PART;
                    f += kinds[xl] == LEAF_FULL;
                }
            }
        partial += p;
        full += f;
    });
    // Partial leaves as a band of up to 3 float leaves a leaf, full ones as
    // tiles.
    return tree_bytes(g, partial, full, leaf_bytes(cls, 0));
}

extern "C" int vx_voxel_write_vdb(const vx_bitgrid *g, vx_vdb_class cls, const vx_vdb_meta *meta,
                                  const char *path, const vx_voxel_io *io, vx_err *err)
{
    return vx_voxel_write_vdb_at(g, nullptr, cls, meta, path, io, err);
}

extern "C" int vx_voxel_write_vdb_at(const vx_bitgrid *g, const int at_[3], vx_vdb_class cls,
                                     const vx_vdb_meta *meta, const char *path,
                                     const vx_voxel_io *io, vx_err *err)
{
    const openvdb::Coord at = at_ ? openvdb::Coord(at_[0], at_[1], at_[2]) : openvdb::Coord(0);
    int rc =
        write_grids(path, io ? io->vdb_keep : nullptr, err, [&](openvdb::GridPtrVec &grids) -> int {
            openvdb::GridBase::Ptr out;
            if (cls == VX_VDB_BOOL) {
                openvdb::BoolGrid::Ptr b = bool_grid(g, at, io, 0.8, err);
                if (!b) return -1;
                b->setName("voxels");
                set_meta(*b, g, meta);
                out = b;
            } else if (cls == VX_VDB_FOG) {
                openvdb::FloatGrid::Ptr f = fog_grid(g, at, io, 0.8, err);
                if (!f) return -1;
                f->setName(g->counts ? "coverage" : "density");
                set_meta(*f, g, meta);
                out = f;
            } else {
                // The narrow band (3 voxels each side) of the exact signed
                // distance to the boundary between set and unset voxels.
                vx_band_rows rows = {{g->grid.dims[0], g->grid.dims[1], g->grid.dims[2]},
                                     g->wx,
                                     g->bits,
                                     0,
                                     g->grid.dims[2]};
                openvdb::FloatGrid::Ptr ls = band_grid(
                    rows, at, g->grid.h, [](int, int) { return 0; }, io, 0.0, 0.8, err);
                if (!ls) return -1;
                ls->setName("surface");
                ls->setTransform(transform_of(g->grid));
                set_meta(*ls, g, meta);
                out = ls;
            }
            if (at_) out->insertMeta("brick_offset", openvdb::Vec3IMetadata(openvdb::Vec3i(at_)));
            if (io && io->progress && io->progress(io->ud, 0.85, err)) return -1;
            grids.push_back(out);
            return 0;
        });
    if (rc) return -1;
    if (io && io->progress && io->progress(io->ud, 1.0, err)) return -1;
    return 0;
}

extern "C" int vx_voxel_write_vdb_float(const float *v, const int dims[3], const double origin[3],
                                        double h, const char *name, const char *mesh,
                                        const char *path, vx_err *err)
{
    return write_grids(path, nullptr, err, [&](openvdb::GridPtrVec &grids) {
        openvdb::FloatGrid::Ptr grid = make_float_grid(0.0f);
        grid->setName(name);
        grid->setGridClass(openvdb::GRID_FOG_VOLUME);
        auto acc = grid->getAccessor();
        const int nx = dims[0], ny = dims[1], nz = dims[2];
        for (int k = 0; k < nz; k++)
            for (int j = 0; j < ny; j++) {
                const float *row = v + ((size_t)k * ny + j) * nx;
                for (int i = 0; i < nx; i++)
                    if (std::fabs(row[i]) >= 1e-4f) acc.setValueOn(openvdb::Coord(i, j, k), row[i]);
            }
        if (mesh) grid->insertMeta("mesh", openvdb::StringMetadata(mesh));
        grid->insertMeta("voxel_size", openvdb::DoubleMetadata(h));
        grid->insertMeta("dims", openvdb::Vec3IMetadata(openvdb::Vec3i(nx, ny, nz)));
        openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(h);
        xf->postTranslate(openvdb::Vec3d(origin[0], origin[1], origin[2]));
        grid->setTransform(xf);
        grids.push_back(grid);
        return 0;
    });
}

namespace
{
// A ParallelGrid sharing grid's tree, with its metadata and transform.
template <typename GridT> openvdb::GridBase::Ptr as_parallel(GridT &grid)
{
    auto p = std::make_shared<ParallelGrid<GridT>>(grid.background());
    static_cast<openvdb::MetaMap &>(*p) = static_cast<const openvdb::MetaMap &>(grid);
    p->setTree(grid.treePtr());
    p->setTransform(grid.transformPtr());
    // (setSaveFloatAsHalf writes the "is_saved_as_half_float" metadata, which
    // a grid of ours has only when it is true)
    if (grid.saveFloatAsHalf()) p->setSaveFloatAsHalf(true);
    return p;
}
} // namespace

// The merge of brick files (io.h): one grid, bool or float as the first
// brick's, whose tree takes each brick's nodes by OpenVDB's own Tree::merge
// (the bricks are disjoint, so nodes move over, nothing is combined); the
// final prune turns uniform interior into tiles.
struct vx_vdb_merge {
    openvdb::GridBase::Ptr grid;
    uint64_t leaves = 0;
};

extern "C" vx_vdb_merge *vx_vdb_merge_new(vx_err *err)
{
    try {
        std::call_once(init_once, [] { openvdb::initialize(); });
        return new vx_vdb_merge;
    } catch (const std::exception &) {
        vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the merge");
        return nullptr;
    }
}

extern "C" void vx_vdb_merge_free(vx_vdb_merge *m)
{
    delete m;
}

extern "C" uint64_t vx_vdb_merge_bytes(const vx_vdb_merge *m)
{
    return m->grid ? (uint64_t)m->grid->memUsage() : 0;
}

extern "C" int vx_vdb_merge_add(vx_vdb_merge *m, const char *path, vx_err *err)
{
    try {
        openvdb::io::File file(path);
        file.open(false);
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        if (!grids || grids->size() != 1)
            return vx_err_set(err, VX_EIO, "io_error", "%s: not one grid", path);
        openvdb::GridBase::Ptr g = grids->front();
        if (!m->grid) {
            m->grid = g;
            return 0;
        }
        if (g->type() != m->grid->type())
            return vx_err_set(err, VX_EINTERNAL, "internal", "%s: a %s brick among %s ones", path,
                              g->type().c_str(), m->grid->type().c_str());
        if (auto b = openvdb::GridBase::grid<openvdb::BoolGrid>(m->grid))
            b->tree().merge(openvdb::gridPtrCast<openvdb::BoolGrid>(g)->tree(),
                            openvdb::MERGE_ACTIVE_STATES);
        else if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(m->grid))
            f->tree().merge(openvdb::gridPtrCast<openvdb::FloatGrid>(g)->tree(),
                            openvdb::MERGE_ACTIVE_STATES);
        else
            return vx_err_set(err, VX_EINTERNAL, "internal", "%s: grid type %s", path,
                              g->type().c_str());
        return 0;
    } catch (const std::bad_alloc &) {
        return vx_err_set(err, VX_EINTERNAL, "out_of_memory", "no memory for the merged grid");
    } catch (const std::exception &e) {
        return vx_err_set(err, VX_EIO, "io_error", "OpenVDB: %s: %s", path, e.what());
    }
}

extern "C" uint64_t vx_vdb_merge_level_set_bytes(const vx_vdb_merge *m, const int dims[3])
{
    auto b = m->grid ? openvdb::GridBase::grid<openvdb::BoolGrid>(m->grid) : nullptr;
    return b ? (uint64_t)b->tree().leafCount() * leaf_bytes(VX_VDB_LEVEL_SET, 0) +
                   TreeRows::window_bytes(dims)
             : 0;
}

extern "C" int vx_vdb_merge_write(vx_vdb_merge *m, vx_vdb_class cls, const vx_grid *grid,
                                  const vx_vdb_meta *meta, const char *path, const vx_voxel_io *io,
                                  vx_err *err)
{
    if (!m->grid) return vx_err_set(err, VX_EINTERNAL, "internal", "no bricks to merge");
    vx_bitgrid whole_ = {};
    whole_.grid = *grid;
    const vx_bitgrid *whole = &whole_;
    return write_grids(path, nullptr, err, [&](openvdb::GridPtrVec &grids) -> int {
        openvdb::GridBase::Ptr out;
        if (auto b = openvdb::GridBase::grid<openvdb::BoolGrid>(m->grid)) {
            openvdb::tools::prune(b->tree());
            if (cls == VX_VDB_LEVEL_SET) {
                TreeRows tr(b->tree(), whole->grid.dims);
                vx_band_rows rows = {
                    {whole->grid.dims[0], whole->grid.dims[1], whole->grid.dims[2]},
                    tr.wx,
                    nullptr,
                    0,
                    0};
                openvdb::FloatGrid::Ptr ls = band_grid(
                    rows, openvdb::Coord(0), whole->grid.h,
                    [&](int zl0, int zl1) { return tr.hold(rows, zl0, zl1); }, io, 0.0, 0.8, err);
                if (!ls) return -1;
                m->grid.reset();
                ls->setName("surface");
                set_meta(*ls, whole, meta);
                out = ls;
            } else {
                b->setName("voxels");
                set_meta(*b, whole, meta);
                out = b;
            }
        } else {
            auto f = openvdb::gridPtrCast<openvdb::FloatGrid>(m->grid);
            openvdb::tools::prune(f->tree());
            f->setName(m->grid->getName()); // the bricks' "coverage" or "density"
            f->setGridClass(openvdb::GRID_FOG_VOLUME);
            set_meta(*f, whole, meta);
            out = f;
        }
        out->setTransform(transform_of(whole->grid));
        // The bricks' own metadata (the last brick's offset) is not the grid's.
        out->removeMeta("brick_offset");
        // a grid read from a brick, written on all threads as ours are
        if (!dynamic_cast<const Prepared *>(out.get())) {
            if (auto b = openvdb::GridBase::grid<openvdb::BoolGrid>(out))
                out = as_parallel(*b);
            else if (auto f = openvdb::GridBase::grid<openvdb::FloatGrid>(out))
                out = as_parallel(*f);
        }
        if (io && io->progress && io->progress(io->ud, 0.85, err)) return -1;
        grids.push_back(out);
        return 0;
    });
}
