/* AllocCap: a per-thread ceiling on operator new, for decoders whose
 * libraries size their tables from counts in the file (libdraco, tinygltf).
 *
 * While an AllocCap lives, its thread's operator new allocations are
 * counted (malloc_usable_size, frees subtracted) and one that would pass
 * the cap throws std::bad_alloc (returns nullptr for nothrow) before
 * anything is spent. The global operator new and delete are replaced in
 * alloc_cap.cc; outside a cap they are malloc and free. C++ only, any
 * thread (the state is thread-local). */
#ifndef VX_ALLOC_CAP_H
#define VX_ALLOC_CAP_H

#include <cstdint>

namespace vx
{

class AllocCap
{
  public:
    /* Starts counting this thread's allocations against cap bytes. */
    explicit AllocCap(uint64_t cap);
    /* Stops counting. */
    ~AllocCap();
    AllocCap(const AllocCap &) = delete;
    AllocCap &operator=(const AllocCap &) = delete;
    /* True once an allocation was refused. */
    bool tripped() const;
    /* The cap, and the most bytes held at once so far. */
    uint64_t limit() const;
    uint64_t peak() const;
};

} // namespace vx

#endif
